"""The ``fitgen`` command: a thin layer that parses arguments and calls the library."""

from __future__ import annotations

import sys
from pathlib import Path

from fitgen import __version__
from fitgen.app.cliutil import EXIT_CHECK_FAILED, Parser, run
from fitgen.base.parse import parse_assignments
from fitgen.base.errors import InputError
from fitgen.equations.terms import FAMILIES
from fitgen.physics.pose import POSE_NAMES

FAMILY_CHOICES = ("auto", *FAMILIES)


def _sensor(args):
    from fitgen.physics.sensor import load_sensor

    sensor = load_sensor(args.sensor)
    if getattr(args, "transfer", None):
        sensor = sensor.with_transfer(args.transfer)
    return sensor


def _noise(value: str, sensor) -> float:
    if value == "sensor":
        return sensor.noise
    try:
        noise = float(value)
    except ValueError:
        raise InputError(f"--noise must be a number or 'sensor', got {value!r}") from None
    if not noise >= 0:
        raise InputError(f"--noise must be >= 0, got {value}")
    return noise


def cmd_simulate(args) -> int:
    from fitgen.physics.dataset import load_poses
    from fitgen.physics.simulate import grid_poses, parse_grid, parse_ranges, pose_rng, random_poses, simulate

    from pathlib import Path

    sensor = _sensor(args)
    # a sensor file (a unit's, say) is named in the meta, so that fit finds it to hold out on
    unit_info = {"sensor_file": str(Path(args.sensor).resolve())} if Path(args.sensor).is_file() else {}
    if args.unit is not None:
        from fitgen.physics.sensor import load_sensor
        from fitgen.physics.units import draw_unit, unit_path, write_unit

        unit, _ = draw_unit(sensor, args.unit)
        path = write_unit(unit_path(args.output), unit, sensor.name,
                          {"seed": args.unit, "source": "drawn within the drawing's tolerances (fitgen simulate --unit)"})
        # simulated with the file as written, so that the data and the file agree to the last bit
        unit_info = {"sensor_file": str(path.resolve()), "unit_seed": args.unit, "drawing": sensor.name}
        sensor = load_sensor(path).with_transfer(sensor.transfer)
        print(f"wrote unit {sensor.name} (a unit of {unit_info['drawing']}) to {path}", file=sys.stderr)
    chosen = [x for x in (args.grid, args.random, args.poses) if x is not None]
    if len(chosen) > 1 and not (len(chosen) == 2 and args.poses is None and not args.scene):
        raise InputError("give one of --grid, --random, --poses (or --grid with --random: the grid, then random poses)")
    if args.scene and (args.grid or args.poses or args.ranges):
        raise InputError("--scene sets the poses: give it with --random N or alone, not with --grid, --poses, --ranges")
    scene_info = {}
    if args.scene:
        from fitgen.physics.scenes import load_scene

        scene = load_scene(args.scene)
        scene_info = {"scene": scene.name, "scene_spec": args.scene, "scene_outputs": list(scene.outputs)}
    if args.scene and args.random is None:
        poses, source = scene.poses(), {"scene_grid_levels": scene.levels}
    elif args.scene:
        poses = random_poses(args.random, scene.ranges, pose_rng(args.seed))
        source = {"random": args.random}
    elif args.poses:
        poses, source = load_poses(args.poses), {"poses_file": str(args.poses)}
    elif args.random is not None:
        poses = random_poses(args.random, parse_ranges(args.ranges), pose_rng(args.seed))
        source = {"random": args.random, "ranges": args.ranges}
        if args.grid:
            # a rig's sweep and random presses between its levels: the grid's poses first
            import numpy as np

            poses, source = np.vstack([grid_poses(parse_grid(args.grid)), poses]), {**source, "grid": args.grid}
    else:
        grid = args.grid or "paper-sim"
        poses, source = grid_poses(parse_grid(grid)), {"grid": grid}
    ds = simulate(sensor, poses, noise=_noise(args.noise, sensor), adc_bits=args.adc_bits,
                  seed=args.seed, provenance={**source, **scene_info, **unit_info}, labels=args.labels)
    ds.save(args.output)
    print(f"wrote {ds.n_rows} rows x {len(ds.columns)} columns ({sensor.name}, {sensor.transfer}) to {args.output}",
          file=sys.stderr)
    return 0


def cmd_observe(args) -> int:
    from fitgen.physics.observe import observe
    from fitgen.physics.scenes import load_scene
    from fitgen.physics.simulate import parse_ranges

    if args.sensor_pos and args.sensor:
        raise InputError("give the sensor once (positional or --sensor)")
    args.sensor = args.sensor_pos or args.sensor or "paper"
    sensor = _sensor(args)
    scene = load_scene(args.scene)
    ranges = parse_ranges(args.ranges) if args.ranges else scene.ranges
    noise = None if args.noise is None else _noise(args.noise, sensor)
    accuracy = parse_assignments(args.accuracy, POSE_NAMES, "--accuracy") if args.accuracy else None
    report = observe(sensor, ranges, scene.outputs, noise=noise, accuracy=accuracy)
    print(f"sensor {sensor.name} ({sensor.n_elements} elements, {sensor.transfer}), scene {scene.name}")
    print(report.text(), end="")
    for c in report.unresolved():
        print(f"warning: scene {scene.name} asks for {c}, which sensor {sensor.name} cannot resolve to "
              f"{report.accuracy[c]:g} {'deg' if c.startswith('th') else 'mm'} everywhere in its box", file=sys.stderr)
    return 0


def _settings(args):
    from fitgen.fitting.fit import FitSettings

    if args.k in ("aic", "bic"):
        k = 2.0 if args.k == "aic" else "bic"
    else:
        try:
            k = float(args.k)
        except ValueError:
            raise InputError(f"--k must be aic, bic or a number > 0, got {args.k!r}") from None
        if not k > 0 or k != k or k == float("inf"):
            raise InputError(f"--k must be a finite number > 0, got {args.k}")
    if args.max_terms is not None and args.max_terms < 1:
        raise InputError(f"--max-terms must be >= 1, got {args.max_terms}")
    noise = None
    if args.noise is not None:
        try:
            noise = float(args.noise)
        except ValueError:
            raise InputError(f"--noise must be a number >= 0 (reading noise rms, input units), got {args.noise!r}") \
                from None
        if not (noise >= 0 and noise != float("inf")):
            raise InputError(f"--noise must be a finite number >= 0, got {args.noise}")
    # --noise 0 alone is the paper's procedure (what R's step() computes): no rounding term either
    precision = args.precision or ("exact" if noise == 0 else "float")
    from fitgen.fitting.family import candidates
    from fitgen.equations.refine import MAX_STEPS

    # auto: fitgen.fitting.family chooses among what the precision can run
    family = candidates(precision)[0] if args.family == "auto" else args.family
    # the rest of --refine's checks (--refine-terms, the data) are fitgen.fitting.refine_fit.check_refinable's
    if not 0 <= args.refine <= MAX_STEPS:
        raise InputError(f"--refine takes 0 (none) to {MAX_STEPS} steps, got {args.refine}")
    if precision == "fixed":
        if args.refine:
            raise InputError("fixed point has no refinement (its Gauss-Newton steps run in float or double): "
                             "drop --refine, or fit for --precision float")
        if family not in candidates("fixed"):
            raise InputError(f"fixed point runs no roots and no harmonic terms, which --family {family} offers: "
                             f"use --family {' or '.join(candidates('fixed'))} (or auto)")
    return FitSettings.family(family, k=k, max_terms=args.max_terms, d_terms=not args.no_d_terms,
                              d_source="true" if args.true_d else "estimated", noise=noise,
                              precision=None if precision == "exact" else precision, refine=args.refine,
                              refine_terms=args.refine_terms)


def _outputs(spec):
    if spec is None:
        return None
    names = tuple(x.strip() for x in spec.split(",") if x.strip())
    bad = [n for n in names if n not in POSE_NAMES]
    if bad or not names:
        raise InputError(f"--outputs takes names from {','.join(POSE_NAMES)}, got {spec!r}")
    return names


def _scene_outputs(args, ds, sensor):
    """The outputs a scene asks for (--scene, or the scene the dataset was simulated for), after
    checking that ``sensor`` (the dataset's, or None when unknown) resolves them; None when no scene applies."""
    from fitgen.physics.scenes import load_scene, unresolved_warnings

    spec = args.scene or ds.meta.get("scene_spec")
    if spec is None:
        return None
    if args.outputs:
        raise InputError("give --outputs or a scene, not both (the scene names the outputs)")
    scene = load_scene(spec)
    missing = [o for o in scene.outputs if o not in ds.target_names]
    if missing:
        raise InputError(f"scene {scene.name} asks for {missing[0]}, which dataset {args.data} does not have")
    if not args.force:
        if sensor is None:
            raise InputError("give --sensor (to check that it resolves the scene's outputs) or --force")
        bad = unresolved_warnings(sensor, scene)
        if bad:
            raise InputError(f"scene {scene.name}: sensor {sensor.name} cannot resolve {bad[0]} "
                             f"Fit anyway with --force, or use a scene without it.")
    return scene.outputs


def cmd_fit(args) -> int:
    from fitgen.physics.dataset import load_dataset
    from fitgen.fitting.fit import fit_model
    from fitgen.base.progress import Progress
    from fitgen.app.report import deployed_table, fit_assumptions
    from fitgen.physics.simulate import dataset_sensor

    settings = _settings(args)
    ds = load_dataset(args.data)
    sensor = dataset_sensor(ds.meta, args.sensor)
    outputs = _scene_outputs(args, ds, sensor) or _outputs(args.outputs) or ds.target_names
    # --noise 0 is the paper's procedure: the paper's power kinds too, unless a family or fixed point is named
    auto = args.family == "auto" and (settings.noise != 0 or settings.precision == "fixed")
    steps = len(outputs) + (ds.n_inputs if settings.refine else 0)  # the equations, then the forward model's
    bar = Progress("fit", steps * (2 if auto and sensor is not None else 1))
    state = {"name": None}

    def progress(name, step, aic, n_terms):
        if state["name"] != name:
            if state["name"] is not None:
                bar.update()
            state["name"] = name
        bar.update(0, f"{name}: step {step}, {n_terms} terms, AIC {aic:.1f}")

    with bar:
        if auto:
            from fitgen.fitting.family import fit_auto

            model, family = fit_auto(ds, outputs, settings, sensor, progress=progress)
        else:
            model = fit_model(ds, outputs, settings, progress=progress, sensor=sensor)
            family = ({"name": args.family, "auto": False} if args.family != "auto" else
                      {"name": "all", "auto": True, "why": "--noise 0: the paper's procedure"})
    model.fit_info["family"] = family
    model.fit_info["dataset"] = str(args.data)
    if args.held_out and sensor is not None:
        from fitgen.fitting.holdout import box_of, evaluate
        from fitgen.fitting.identify import load_posterior

        unit_file = args.sensor or ds.meta.get("sensor_file")
        posterior = load_posterior(unit_file) if unit_file else None
        with Progress("held-out", 1) as hbar:
            hbar.update(0, f"{args.held_out} random poses, {model.fit_info['noise']['device'] or 0:g} noise"
                           + (", units from the identification's posterior" if posterior else ""))
            model.fit_info["held_out"] = evaluate(model, sensor, box_of(ds.poses()),
                                                  noise=model.fit_info["noise"]["device"], n=args.held_out,
                                                  posterior=posterior, labels=ds.meta.get("labels", "stage"))
            if unit_file and not sensor.is_drawing:
                model.fit_info["held_out"]["sensor_file"] = str(unit_file)
            hbar.update()
    model.save(args.output)
    for e in model.equations:
        i = model.fit_info["outputs"][e.name]
        err = i["model_training_error"]
        print(f"{e.name}: {len(e.terms)} terms, AIC {i['aic']:.2f}, training max error {err['max']:.4g} {e.unit}, "
              f"RMS {err['rms']:.4g}, condition {i['condition']:.3g}", file=sys.stderr)
    print(fit_assumptions(model.fit_info), file=sys.stderr)
    noise = model.fit_info["noise"]
    if noise["device"] is None and noise["data"] == 0:
        print("warning: the dataset was simulated without noise and names no sensor this fitgen knows: fitted "
              "without the device's noise (give --sensor FILE or --noise X)", file=sys.stderr)
    if "held_out" in model.fit_info:
        print(deployed_table(model), end="", file=sys.stderr)
    elif args.held_out:
        print("no held-out figures: the dataset names no sensor to simulate held-out poses with (give --sensor)",
              file=sys.stderr)
    print(f"wrote {args.output}", file=sys.stderr)
    return 0


def cmd_predict(args) -> int:
    import numpy as np

    from fitgen.physics.dataset import parse_table
    from fitgen.base.fileio import read_text
    from fitgen.base.fileio import write_atomic
    from fitgen.equations.model import load_model

    model = load_model(args.model)
    names, table = parse_table(read_text(args.data, "dataset"), f"dataset {args.data}")
    cols = [f"v{k}" for k in range(1, model.n_inputs + 1)]
    missing = [c for c in cols if c not in names]
    if missing:
        raise InputError(f"dataset {args.data}: missing column {missing[0]} (the model takes {cols[0]}..{cols[-1]})")
    inputs = table[:, [names.index(c) for c in cols]]
    if args.precision == "fixed":
        from fitgen.equations.fixedpoint import plan_at

        fm, source = plan_at(model, args.input_lsb, args.input_offset)
        pred, status = fm.predict_codes(inputs) if args.codes else fm.predict_values(inputs)
        pred = fm.to_real(pred) if args.codes else pred
        print(f"fixed point: {'ADC codes as given' if args.codes else 'values rounded to ADC codes'}, input LSB "
              f"{fm.input_lsb:.6g} {model.input_units} from {source}, offset {fm.input_offset:g}", file=sys.stderr)
    else:
        if args.codes or args.input_lsb is not None or args.input_offset is not None:
            raise InputError("--codes, --input-lsb and --input-offset apply to --precision fixed only")
        pred, status = model.predict(inputs, with_status=True, precision=args.precision)
    header = ",".join(list(model.output_names) + ["status"])
    lines = [header] + [",".join(map(repr, row)) + f",{int(s)}" for row, s in zip(pred.tolist(), status)]
    write_atomic(args.output, "\n".join(lines) + "\n")
    clamped = int(np.sum(status > 0))
    print(f"wrote {len(pred)} estimates to {args.output}" + (f" ({clamped} rows clamped into the domain)"
                                                             if clamped else ""), file=sys.stderr)
    return 0


def cmd_report(args) -> int:
    from fitgen.physics.dataset import load_dataset
    from fitgen.base.fileio import write_atomic
    from fitgen.equations.model import load_model
    from fitgen.app.report import format_report

    model = load_model(args.model)
    ds = load_dataset(args.data) if args.data else None
    text = format_report(model, ds, title=f"Report for {args.model}", paper=args.paper)
    if args.output:
        write_atomic(args.output, text)
    else:
        print(text, end="")
    if args.plot:
        from fitgen.app import plots

        folder = Path(args.plot)
        if not folder.is_dir():
            try:
                folder.mkdir(parents=True)
            except OSError as exc:
                raise InputError(f"cannot create {folder}: {exc.strerror}") from None
        if ds is None:
            raise InputError("--plot needs --data (the rows to plot estimates for)")
        paths = plots.estimate_vs_target(model, ds, folder)
        if args.sensor:
            paths += _sweeps(model, args.sensor, folder)
        print("plots: " + ", ".join(str(p) for p in paths), file=sys.stderr)
    return 0


def _sweeps(model, sensor_spec, folder):
    import numpy as np

    from fitgen.app import plots
    from fitgen.physics.sensor import load_sensor
    from fitgen.physics.simulate import simulate

    sensor = load_sensor(sensor_spec)
    paths = []
    for j, name in enumerate(POSE_NAMES[3:], start=3):
        if name in model.output_names:
            values = np.round(np.arange(-5.0, 5.0 + 1e-9, 0.1), 10)
            poses = np.zeros((len(values), 5))
            poses[:, j] = values
            paths.append(plots.resolution_sweep(model, simulate(sensor, poses).inputs, values, name, folder))
    return paths


def cmd_identify(args) -> int:
    import numpy as np

    from fitgen.physics.dataset import load_dataset
    from fitgen.fitting.identify import CHI2_LIMIT, identify, report, row_noise, save
    from fitgen.base.progress import Progress

    ds = load_dataset(args.capture)
    drawing = _sensor(args)
    units = ds.meta.get("units")
    if not args.transfer and units in ("V", "mT"):
        drawing = drawing.with_transfer("gmr" if units == "V" else "raw")
    noise, source = row_noise(ds.meta, drawing, args.noise)
    with Progress("identify", 4) as bar:
        ident = identify(drawing, ds.inputs, ds.poses(), noise, rig_error=args.rig_error,
                         progress=lambda i, n, note: bar.update(1, note))
    if ident.reduced_chi2 > CHI2_LIMIT:
        rms = float(np.sqrt(ident.reduced_chi2))
        raise InputError(f"the physics does not explain {args.capture}: residuals {rms:.3g}x the reading noise "
                         f"({source}); another sensor than {drawing.name}, labels in other units, or a noise figure too "
                         "low; nothing written")
    print(f"reading noise per row: {source}; rig error {args.rig_error:g} mm", file=sys.stderr)
    print(report(ident), end="")
    from pathlib import Path

    spec = str(Path(args.sensor).resolve()) if Path(args.sensor).is_file() else args.sensor
    unit, post = save(ident, args.output, {"capture": str(args.capture), "capture_sha256": ds.sha256,
                                           "drawing_spec": spec})
    print(f"wrote {unit} (the unit at the maximum a posteriori) and {post} (every parameter's standard error and "
          "the posterior)", file=sys.stderr)
    return 0


def cmd_schedule(args) -> int:
    import json

    import numpy as np

    from fitgen.physics.dataset import meta_path
    from fitgen.base.fileio import write_atomic
    from fitgen.base.progress import Progress
    from fitgen.fitting.schedule import schedule, schedule_csv
    from fitgen.physics.simulate import parse_ranges

    drawing = _sensor(args)
    axes = tuple(a.strip() for a in args.axes.split(",") if a.strip())
    noise = None if args.noise is None else _noise(args.noise, drawing)
    with Progress("schedule", args.n) as bar:
        poses, info = schedule(drawing, args.n, axes=axes, ranges=parse_ranges(args.limits),
                               noise=(drawing.noise if noise is None else noise) / np.sqrt(args.samples),
                               rig_error=args.rig_error, progress=lambda i, n, note: bar.update(1, note))
    write_atomic(args.output, schedule_csv(poses, axes))
    write_atomic(meta_path(args.output), json.dumps({**info, "samples_per_row": args.samples}, indent=1) + "\n")
    print(f"wrote {len(poses)} poses ({info['distinct_poses']} distinct, {','.join(axes)}) to {args.output}",
          file=sys.stderr)
    return 0


def _finite(text: str) -> float:
    import argparse
    import math

    try:
        x = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not math.isfinite(x):
        raise argparse.ArgumentTypeError(f"{text!r} is not a finite number")
    return x


def cmd_codegen(args) -> int:
    from fitgen.c.codegen import write_header
    from fitgen.equations.model import load_model

    model = load_model(args.model)
    if args.precision == "fixed":
        from fitgen.c.codegen import render_fixed_header
        from fitgen.equations.fixedpoint import plan_at
        from fitgen.base.fileio import write_in_folder

        if args.fma:
            raise InputError("--fma does not apply to --precision fixed")
        fm, source = plan_at(model, args.input_lsb, args.input_offset)
        path = write_in_folder(args.output, f"{args.prefix}_model.h", render_fixed_header(fm, args.prefix))
        print(f"wrote {path} (fixed point, input LSB {fm.input_lsb:.6g} {model.input_units} from {source}, "
              f"offset {fm.input_offset:g}; {fm.summary()}; model {model.sha256[:12]})", file=sys.stderr)
        return 0
    if args.input_lsb is not None or args.input_offset is not None:
        raise InputError("--input-lsb and --input-offset apply to --precision fixed only")
    path = write_header(model, args.output, args.precision, args.style, args.prefix, args.fma)
    print(f"wrote {path} ({args.precision}, {args.style}{', fma' if args.fma else ''}, model {model.sha256[:12]})",
          file=sys.stderr)
    return 0


def cmd_tradeoff(args) -> int:
    from fitgen.base.progress import Progress
    from fitgen.physics.scenes import load_scene
    from fitgen.app.tradeoff import parse_knob_list, parse_target
    from fitgen.app.tradeoff_report import write_outputs
    from fitgen.c.tradeoff import grid_from, quick_grid, sweep

    knobs = {name: parse_knob_list(name, getattr(args, name)) for name in ("k", "max_terms", "family", "precision",
                                                                         "style", "refine")
             if getattr(args, name) is not None}
    if args.jobs < 1:
        raise InputError(f"--jobs must be >= 1, got {args.jobs}")
    sensor = _sensor(args)
    scene = load_scene(args.scene)
    target = parse_target(args.target, scene.outputs)
    grid = grid_from(**knobs) if args.full or knobs else quick_grid()
    if not grid:
        raise InputError("nothing to sweep: fixed point has no harmonics family and no refinement, and the refinement "
                         "is swept on the harmonics family only (pick other --family, --precision or --refine)")
    bar = Progress("tradeoff", len(grid))
    if not 0 < args.max_share < 1e6:
        raise InputError(f"--max-share must be a number > 0, got {args.max_share}")
    with bar:
        result = sweep(sensor, scene, grid, target=target, seed=args.seed, jobs=args.jobs,
                       progress=lambda note: bar.update(1, note), max_share=args.max_share)
    paths, text = write_outputs(result, args.output)
    print(text, end="")
    print("wrote " + ", ".join(str(p) for p in paths), file=sys.stderr)
    if result.over_share:
        print(f"FAIL: rounding adds more than {args.max_share:.0%} of the model's held-out max error at points "
              + ", ".join(str(i + 1) for i in result.over_share), file=sys.stderr)
        return EXIT_CHECK_FAILED
    return 0


def cmd_demo(args) -> int:
    from fitgen.app.demo import run_demo

    return run_demo(Path(args.out))


def build_parser() -> Parser:
    p = Parser(prog="fitgen", description=__doc__)
    p.add_argument("--version", action="version", version=f"fitgen {__version__}")
    sub = p.add_subparsers(dest="command", required=True, parser_class=Parser)

    s = sub.add_parser("simulate", help="simulate element readings for a pose set")
    s.add_argument("--sensor", default="paper", help="preset name or sensor TOML (default: paper)")
    s.add_argument("--grid", help="paper-sim, paper-exp, or 'dx=-2:2:5 dz=0,-1 ...'")
    s.add_argument("--random", type=int, metavar="N",
                   help="N random poses in --ranges (with --grid: after the grid's poses)")
    s.add_argument("--ranges", help="box for --random: 'dx=-2:2 thx=-5:5 ...' (default: paper-sim box)")
    s.add_argument("--poses", metavar="FILE.csv", help="simulate the poses in this CSV")
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--noise", default="0", help="element noise rms in output units, or 'sensor' (default 0)")
    s.add_argument("--adc-bits", type=int, help="override the transfer's ADC bits (0: no quantisation)")
    s.add_argument("--transfer", choices=("raw", "gmr"), help="override the sensor file's transfer")
    s.add_argument("--scene", help="full, slide, press or a scene TOML: simulate its grid (or --random N in its box)")
    s.add_argument("--labels", choices=("stage", "magnet"), default="stage",
                   help="for a built unit: the displacements the poses and labels are, the stage's (what a capture "
                        "measures; default) or the magnet's")
    s.add_argument("--unit", type=int, metavar="SEED",
                   help="simulate a built unit of the sensor, drawn within its [tolerances] with this seed; its sensor "
                        "file is written beside the data (<stem>.unit.toml)")
    s.add_argument("-o", "--output", required=True, help="dataset CSV to write")
    s.set_defaults(func=cmd_simulate)

    o = sub.add_parser("observe", help="observability of each pose component (Jacobian SVD, Cramer-Rao)")
    o.add_argument("sensor_pos", nargs="?", metavar="SENSOR")
    o.add_argument("--sensor", help="preset name or sensor TOML (default: paper)")
    o.add_argument("--scene", help="full, slide, press or a scene TOML (default: full)")
    o.add_argument("--ranges", help="pose box 'dx=-2:2 ...' overriding the scene's")
    o.add_argument("--noise", help="element noise rms in output units (default: the sensor file's)")
    o.add_argument("--accuracy", help="required 1-sigma accuracy, e.g. 'dx=0.05 thx=0.5'")
    o.add_argument("--transfer", choices=("raw", "gmr"))
    o.set_defaults(func=cmd_observe)

    f = sub.add_parser("fit", help="choose and fit the estimate equations by stepwise AIC")
    f.add_argument("data", metavar="DATA.csv")
    f.add_argument("-o", "--output", required=True, help="model file (JSON) to write")
    f.add_argument("--outputs", help="comma-separated outputs to fit (default: every pose column of the data)")
    f.add_argument("--k", default="aic", help="penalty per term: aic (2), bic (log n) or a number")
    f.add_argument("--max-terms", type=int, help="cap on terms per equation")
    f.add_argument("--family", default="auto", choices=FAMILY_CHOICES,
                   help="candidates: all 11 power kinds, no-roots, integer (v^1..v^4 only), harmonics (all 11 "
                        "and monomials of the ring's harmonics up to degree 3; needs the sensor), or auto (default: "
                        "all or harmonics, whichever is more accurate on validation poses; all without a sensor)")
    f.add_argument("--no-d-terms", action="store_true", help="rotations without the displacement terms")
    f.add_argument("--true-d", action="store_true",
                   help="rotation d-terms from the true displacements instead of the fitted estimates")
    f.add_argument("--scene", help="fit only the outputs of this scene (default: the dataset's scene, if any)")
    f.add_argument("--sensor", help="the dataset's sensor, for its noise, the held-out poses and the scene check "
                                    "(default: the preset the dataset's meta names)")
    f.add_argument("--force", action="store_true", help="fit a scene's outputs even if the sensor cannot resolve them")
    f.add_argument("--noise", metavar="X",
                   help="reading noise rms (input units) the device will see, added in expectation (default: the "
                        "noise figure of the dataset's sensor; measured data carry their own). 0 alone: the data as "
                        "given and exact arithmetic, the paper's procedure (R's step())")
    f.add_argument("--precision", choices=("float", "double", "fixed", "exact"),
                   help="arithmetic the equations must survive on the device (default float; exact with --noise 0)")
    f.add_argument("--refine", type=int, default=0, metavar="STEPS",
                   help="after the equations, STEPS Gauss-Newton steps on a forward model (readings from the pose) "
                        "fitted to the same data, with the equations' estimate as prior (docs/refine.md; default 0: "
                        "none). Needs all five pose columns and data that vary in each")
    f.add_argument("--refine-terms", type=int, default=30, metavar="N",
                   help="cap on the forward model's terms per element (default 30)")
    f.add_argument("--held-out", type=int, default=2000, metavar="N",
                   help="random held-out poses in the data's box for the deployed-accuracy figures (default 2000; "
                        "0: none)")
    f.set_defaults(func=cmd_fit)

    i = sub.add_parser("identify", help="a built unit's physics from a short capture (its sensor file)")
    i.add_argument("capture", metavar="CAPTURE.csv", help="rows of readings with the stage's displacements (dx,dy,dz)")
    i.add_argument("--sensor", default="paper", help="the drawing the unit was built to (preset or TOML; default paper)")
    i.add_argument("--transfer", choices=("raw", "gmr"), help="override the transfer (default: the capture's units)")
    i.add_argument("--noise", type=_finite, metavar="X",
                   help="the device's single-sample reading noise (default: what the capture measured, else the "
                        "sensor file's), divided by sqrt(samples per row)")
    i.add_argument("--rig-error", type=_finite, default=0.01, metavar="MM",
                   help="the stage's own position error, mm rms per axis (default 0.01; a 3D printer 0.03)")
    i.add_argument("-o", "--output", required=True, metavar="UNIT.toml", help="the unit's sensor file to write")
    i.set_defaults(func=cmd_identify)

    sc = sub.add_parser("schedule", help="the capture poses that pin a unit's parameters best (D-optimal)")
    sc.add_argument("--sensor", default="paper", help="the drawing (preset or TOML; default paper)")
    sc.add_argument("--transfer", choices=("raw", "gmr"), default="gmr",
                    help="the readings the capture takes (default gmr: volts, as tactile-host capture reads them)")
    sc.add_argument("--n", type=int, default=40, help="poses to capture (default 40)")
    sc.add_argument("--axes", default="dx,dy,dz", help="the axes the stage moves (default dx,dy,dz)")
    sc.add_argument("--limits", help="the stage's limits 'dx=-2:2 dz=-2:0 ...' (default: the sensor's pose box)")
    sc.add_argument("--samples", type=int, default=16, help="samples the capture averages per row (default 16)")
    sc.add_argument("--noise", help="single-sample reading noise (default: the sensor file's)")
    sc.add_argument("--rig-error", type=_finite, default=0.01, metavar="MM", help="the stage's error, mm rms")
    sc.add_argument("-o", "--output", required=True, metavar="SCHEDULE.csv")
    sc.set_defaults(func=cmd_schedule)

    pr = sub.add_parser("predict", help="estimates for the rows of a dataset")
    pr.add_argument("model", metavar="MODEL")
    pr.add_argument("data", metavar="DATA.csv")
    pr.add_argument("-o", "--output", required=True, help="CSV of estimates (and status) to write")
    pr.add_argument("--precision", default="double", choices=("double", "float", "fixed"),
                    help="the arithmetic of the generated C, bit for bit: double (default) or float, as the "
                         "header computes them; fixed: the fixed-point header's integers (as real values), from "
                         "the v columns rounded to ADC codes as the ADC would, or taken as codes with --codes")
    pr.add_argument("--codes", action="store_true",
                    help="fixed: the v columns are the ADC codes the fixed header takes (whole numbers)")
    pr.add_argument("--input-lsb", type=_finite, metavar="X",
                    help="fixed: the input value of one ADC code, as for codegen (default: the model's sensor's ADC)")
    pr.add_argument("--input-offset", type=_finite, metavar="Y", help="fixed: the input value of code 0")
    pr.set_defaults(func=cmd_predict)

    r = sub.add_parser("report", help="terms, AIC trace and errors of a model")
    r.add_argument("model", metavar="MODEL")
    r.add_argument("--data", help="dataset to measure errors on (default: the fit's own figures only)")
    r.add_argument("--paper", action="store_true", help="show the seed paper's figures beside ours")
    r.add_argument("--plot", metavar="DIR", help="write estimate-vs-target PNGs here (needs matplotlib)")
    r.add_argument("--sensor", help="with --plot: also the 0.1-degree rotation sweep on this sensor")
    r.add_argument("-o", "--output", help="write the report here instead of stdout")
    r.set_defaults(func=cmd_report)

    c = sub.add_parser("codegen", help="generate the header-only C99 estimator of a model")
    c.add_argument("model", metavar="MODEL")
    c.add_argument("-o", "--output", required=True, metavar="DIR", help="folder for <prefix>_model.h")
    c.add_argument("--precision", default="double", choices=("double", "float", "fixed"),
                   help="fixed: integer ADC codes in, int32 outputs, no floating point (Cortex-M0)")
    c.add_argument("--style", default="table", choices=("table", "unrolled"))
    c.add_argument("--prefix", default="tm", help="C identifier prefix (default tm)")
    c.add_argument("--fma", action="store_true",
                   help="sum each term with fma(): fewer instructions on cores with fused multiply-add")
    c.add_argument("--input-lsb", type=_finite, metavar="X",
                   help="fixed: the input value of one ADC code (default: the model's sensor's ADC, "
                        "or 3.3/65535 for inputs in V)")
    c.add_argument("--input-offset", type=_finite, metavar="Y", help="fixed: the input value of code 0 (default 0)")
    c.set_defaults(func=cmd_codegen)

    t = sub.add_parser("tradeoff", help="accuracy against cost over penalty, cap, family, precision, style and "
                                        "refinement")
    t.add_argument("sensor", metavar="SENSOR", help="preset name or sensor TOML")
    t.add_argument("--scene", required=True, help="full, slide, press or a scene TOML")
    t.add_argument("--target", help="RMS error with noise to meet, e.g. 'dz=0.1 thx=2' "
                                    "(default: 0.1 mm and 1 deg for the scene's outputs)")
    t.add_argument("--full", action="store_true",
                   help="every combination of the knobs (207 points) instead of the quick subset")
    t.add_argument("--k", help="sweep only these penalties per term, e.g. aic,bic,6 (all: aic,bic,6)")
    t.add_argument("--max-terms", help="sweep only these caps, e.g. none,8 (all: none,20,8)")
    t.add_argument("--family", help="sweep only these families (all: all,no-roots,integer,harmonics; harmonics has "
                   "no fixed point)")
    t.add_argument("--precision", help="sweep only these precisions (all: double,float,fixed)")
    t.add_argument("--style", help="sweep only these code styles (all: table,unrolled; fixed point has one)")
    t.add_argument("--refine", help="sweep only these refinement step counts (all: 0,1; on the harmonics family, "
                                    "float and double, scenes with the whole pose; docs/refine.md)")
    t.add_argument("--seed", type=int, default=0, help="held-out poses and noise draws (default 0)")
    t.add_argument("--jobs", type=int, default=2, help="builds measured at once (default 2)")
    t.add_argument("--max-share", type=float, default=0.05, metavar="S",
                   help="fail (exit 1) when a point's rounding adds more than this share of its model's held-out "
                        "max error (default 0.05)")
    t.add_argument("--transfer", choices=("raw", "gmr"), help="override the sensor file's transfer")
    t.add_argument("-o", "--output", default="tradeoff-out", metavar="DIR",
                   help="folder for tradeoff.csv, .md, .png (default: tradeoff-out)")
    t.set_defaults(func=cmd_tradeoff)

    d = sub.add_parser("demo", help="the main job end to end on the paper sensor")
    d.add_argument("--out", default="demo-out", help="folder for the demo's files (default: demo-out)")
    d.set_defaults(func=cmd_demo)
    return p


def _main(argv) -> int:
    args = build_parser().parse_args(argv)
    if getattr(args, "adc_bits", None) is not None and not 0 <= args.adc_bits <= 32:
        raise InputError(f"--adc-bits must be 0..32, got {args.adc_bits}")
    return args.func(args)


def main(argv=None) -> int:
    sys.exit(run(_main, argv, "fitgen"))
