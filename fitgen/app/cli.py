"""The ``fitgen`` command: a thin layer that parses arguments and calls the library."""

from __future__ import annotations

import math
import sys
from pathlib import Path

from fitgen import __version__
from fitgen.app.calibrate_cli import add_calibration_commands, cmd_identify, cmd_schedule
from fitgen.app.cliutil import Parser, check_not_empty, check_written, command_main, count, finite
from fitgen.app.outputkind import check_output_kind
from fitgen.app.options import accuracy_of, fit_settings, model_and_target, noise_of, sensor_file_of, sensor_of
from fitgen.base.parse import MAX_NOISE, parse_names
from fitgen.base.progress import shown_while
from fitgen.base.errors import InputError
from fitgen.c.targets import CYCLE_TARGETS, TARGETS
from fitgen.equations.terms import FAMILIES
from fitgen.physics.pose import POSE_NAMES
from fitgen.physics.sensor import TRANSFERS
from fitgen.physics.simulate import MAX_POSES

FAMILY_CHOICES = ("auto", *FAMILIES)


def cmd_simulate(args) -> int:
    from fitgen.app.report import posterior_note, simulate_notes
    from fitgen.fitting.fit import rows_needed
    from fitgen.physics.posesource import choose_poses
    from fitgen.physics.simulate import simulate

    sensor = sensor_of(args)
    # a sensor file (a unit's, say) is named in the meta, so that fit finds it to hold out on
    unit_info = sensor_file_of(args)
    poses, source = choose_poses(grid=args.grid, random=args.random, poses=args.poses, ranges=args.ranges,
                                 scene=args.scene, seed=args.seed, sensor=sensor,
                                 min_rows=rows_needed(sensor.n_elements))  # a scene's grid that a fit can carry
    noise = noise_of(args.noise, sensor, most=MAX_NOISE)  # readings of more overflow
    if args.labels == "magnet" and args.unit is None and sensor.is_drawing:
        raise InputError("--labels magnet is for a built unit (--unit SEED, or a unit's file as --sensor): on the "
                         "drawing the stage moves the magnet one to one, so the labels are the same")
    unit, beside, replaced = None, [], None
    if args.unit is not None:
        from fitgen.app.replaced import drawn_unit_over
        from fitgen.physics.units import unit_beside

        drawing = sensor
        sensor, unit, text, unit_info = unit_beside(drawing, args.unit, args.output)
        beside = [(unit, text)]  # written with the data or not at all: a refusal keeps an earlier run's
        replaced = drawn_unit_over(unit, text, args.output, args.sensor)
    from fitgen.base.progress import Progress

    with Progress("simulate", 3) as bar:  # seen on a terminal when many poses take seconds
        bar.update(0, f"{len(poses):,} poses")
        ds = simulate(sensor, poses, noise=noise, adc_bits=args.adc_bits,
                      seed=args.seed, provenance={**source, **unit_info}, labels=args.labels)
        bar.update(1, "writing")
        ds.save(args.output, beside=beside)
        bar.update(1, "written; elements' linear range")  # the field once more: seconds on a million rows
        said = simulate_notes(sensor, poses, args.labels, args.sensor, args.adc_bits, source, replaced)
    if unit is not None:
        print(f"wrote unit {sensor.name} (a unit of {drawing.name}) to {unit}", file=sys.stderr)
    notes = "".join(f"note: {n}\n" for n in said + posterior_note(args.sensor if args.unit is None else None))
    print(f"wrote {ds.n_rows} rows x {len(ds.columns)} columns ({sensor.name}, {sensor.transfer}) to {args.output}\n"
          + notes, end="", file=sys.stderr)
    return 0


def cmd_observe(args) -> int:
    from fitgen.app.report import travel_notes
    from fitgen.physics.observe import observe
    from fitgen.physics.scenes import load_scene, preset_sizes
    from fitgen.physics.simulate import parse_ranges

    if args.sensor_pos and args.sensor:
        raise InputError("give the sensor once (positional or --sensor)")
    args.sensor = args.sensor_pos or args.sensor or "paper"
    sensor, scene = sensor_of(args), load_scene(args.scene)
    ranges = parse_ranges(args.ranges, scene.ranges)
    # the bounds scale with it: 1e308 gave "inf mm" at every pose (as a sensor file's noise, capped as simulate's)
    noise = None if args.noise is None else noise_of(args.noise, sensor, most=MAX_NOISE)
    if noise is not None and not noise > 0:
        raise InputError("--noise must be > 0 for observe: without noise every pose component is resolved to 0, "
                         "resolvable or not")
    report = observe(sensor, ranges, scene.outputs, noise=noise, accuracy=accuracy_of(args.accuracy),
                     scenes=preset_sizes())
    print(f"sensor {sensor.name} ({sensor.n_elements} elements, {sensor.transfer}), scene {scene.name}")
    print(report.text(), end="")
    print("".join(f"note: {n}\n" for n in travel_notes(sensor, f"scene {scene.name}", ranges)), end="", file=sys.stderr)
    for c in report.unresolved():
        print(f"warning: scene {scene.name} asks for {c}, which sensor {sensor.name} cannot resolve to "
              f"{report.accuracy[c]:g} {'deg' if c.startswith('th') else 'mm'} everywhere in its box", file=sys.stderr)
    return 0


def cmd_fit(args) -> int:
    from fitgen.app.replaced import replaced_model
    from fitgen.app.report import fit_notes, fit_summary
    from fitgen.base.progress import Progress
    from fitgen.fitting.family import auto_compares, fit_device
    from fitgen.physics.dataset import load_dataset, numbered_as_in, refuse_huge, rows_on_the_skin
    from fitgen.physics.scenes import scene_outputs
    from fitgen.physics.simulate import check_sensor_file, dataset_sensor

    settings = fit_settings(args)
    # numbered as in the file: before lifted rows are left out
    loaded = refuse_huge(shown_while("fit", f"reading {args.data}", lambda: load_dataset(args.data)))
    check_sensor_file(loaded.meta, args.sensor, str(args.data), Path(args.data).resolve().parent)  # a unit file gone or changed: said, not fitted without
    edited = loaded.meta.get("dataset_sha256") not in (None, loaded.sha256)  # rows changed since the meta was written
    ds, lifted = rows_on_the_skin(loaded, f"{args.data}: every row is lifted off the skin, so no contact pose to fit")
    recorded = ds.meta.get("units")
    if args.units is not None and recorded not in (None, args.units):
        raise InputError(f"--units {args.units}, but {args.data}'s meta says its readings are in {recorded}")
    ds.meta["units"] = args.units or recorded or "mT"
    sensor = dataset_sensor(ds.meta, args.sensor, ds.n_inputs)
    forgot, sensor = (sensor.name, None) if edited and sensor is not None and not args.sensor else (None, sensor)
    # --scene, or the scene the dataset was simulated for, names the outputs
    if args.scene and args.outputs:
        raise InputError("give --outputs or --scene, not both (the scene names the outputs)")
    scene = args.scene or (None if args.outputs else ds.meta.get("scene_spec"))  # --outputs over the data's scene
    if args.force and scene is None:
        raise InputError("--force applies to a scene's outputs (--scene, or the scene the data were simulated for): "
                         + ("--outputs names them here" if args.outputs else f"{args.data} names no scene")
                         + ", so it would be ignored")
    if scene is not None:
        outputs = scene_outputs(scene, ds, args.data, sensor, args.force,
                                recorded=None if args.scene else ds.meta.get("scene_outputs"), noise=settings.noise)
    else:
        outputs = ds.target_names if args.outputs is None else parse_names(args.outputs, POSE_NAMES, "--outputs")
    if (args.true_d or args.no_d_terms) and not ({"thx", "thy"} & set(outputs) and {"dx", "dy", "dz"} <= set(outputs)):
        raise InputError(f"{'--true-d' if args.true_d else '--no-d-terms'} shapes the rotations' d-terms, which a fit "
                         f"of thx or thy with dx, dy and dz has, not this one ({', '.join(outputs)}): it would be "
                         "ignored")
    if lifted:  # said once the options have passed: a refusal is one line
        print(f"left out {lifted} row(s) lifted off the skin: they read the magnet at rest, which serves identify; "
              "their labels are no contact pose", file=sys.stderr)
    if forgot:
        print(f"note: {args.data}'s rows are not the ones its meta was written for (edited, or another file's "
              f"meta): its sensor {forgot} is not taken to hold out on or to compare families (give --sensor "
              "to); its units and noise are still taken from it", file=sys.stderr)
    unit_file = args.sensor or ds.meta.get("sensor_file")
    auto, hold = auto_compares(args.family, settings), int(bool(args.held_out) and sensor is not None)
    steps = len(outputs) + (ds.n_inputs if settings.refine else 0)  # the equations, then the forward model's
    bar = Progress("fit", (per_fit := steps * (2 if auto and sensor is not None else 1)) + hold)
    progress = bar.per_item(lambda name, step, aic, n_terms: f"{name}: step {step}, {n_terms} terms, AIC {aic:.1f}")
    with bar, numbered_as_in(loaded):  # the first note shows at once: the rows' products take seconds when many
        bar.update(0, f"{len(ds.inputs):,} rows: the candidate terms' products")
        model = fit_device(ds, outputs, settings, sensor, args.family, held_out=args.held_out, unit_file=unit_file,
                           progress=progress, note=lambda text: bar.update(0, f"held-out: {text}"),
                           again=lambda f: bar.grow(per_fit, "rounding would matter on the device: fitted again for "
                                                    f"{f:g} unit roundoffs"))
        bar.update(hold)
    model.fit_info["dataset"] = str(args.data)
    if lifted:
        model.fit_info["rows_off_skin_left_out"] = lifted
    replaced = replaced_model(args.output, model)
    model.save(args.output)
    print(fit_summary(model, args.held_out), end="", file=sys.stderr)
    if replaced:
        print(f"note: {replaced}", file=sys.stderr)
    print("".join(f"note: {n}\n" for n in fit_notes(model, ds, args.data, args.units or recorded, sensor)), end="", file=sys.stderr)
    print(f"wrote {args.output}", file=sys.stderr)
    return 0


def cmd_predict(args) -> int:
    import numpy as np

    from fitgen.app.report import predict_notes
    from fitgen.base.fileio import write_atomic
    from fitgen.c.codegen import check_magnitudes
    from fitgen.equations.model import check_input_units
    from fitgen.physics.dataset import estimates_csv, load_inputs_and_labels, load_meta

    args.precision = args.precision or ("fixed" if args.codes else None)  # codes are what fixed point takes
    model, target = model_and_target(args)
    inputs, labels = shown_while("predict", f"reading {args.data}",
                                 lambda: load_inputs_and_labels(args.data, model.n_inputs))
    check_input_units(model, load_meta(args.data).get("units"), f"{args.data}'s readings", f"model {args.model}")
    if args.precision == "fixed":
        from fitgen.c.fixedc import plan_line
        from fitgen.equations.inputscale import plan_at

        fm, source = plan_at(model, args.input_lsb, args.input_offset, target.mul_bits if target else 32)
        with np.errstate(over="ignore", invalid="ignore"):  # a huge reading is a row the C refuses: status -1
            pred, status = fm.predict_codes(inputs) if args.codes else fm.predict_values(inputs)
        pred = fm.to_real(pred) if args.codes else pred
        print(f"fixed point: {'ADC codes as given' if args.codes else 'values rounded to ADC codes'}, input LSB "
              f"{fm.input_lsb:.6g} {model.input_units} from {source}, offset {fm.input_offset:g}; "
              f"plan: {plan_line(fm)}", file=sys.stderr)
    else:
        if args.codes or args.input_offset is not None or (args.input_lsb is not None and args.precision != "float"):
            raise InputError("--codes and --input-offset apply to --precision fixed only, --input-lsb to fixed and "
                             "float")
        if args.input_lsb is not None:  # readings from codes as a device's float code computes them
            if not (math.isfinite(args.input_lsb) and args.input_lsb > 0):
                raise InputError(f"--input-lsb must be a finite number > 0, got {args.input_lsb!r}")
            with np.errstate(over="ignore"):  # past float's range: inf, refused below in one line
                lsb = np.float32(args.input_lsb)
            if not np.finfo(np.float32).tiny <= lsb < np.inf:
                raise InputError(f"--input-lsb {args.input_lsb!r} is beyond a float's normal range: no device's float "
                                 "holds it")
            with np.errstate(over="ignore", invalid="ignore"):  # codes past float's range: inf, status -1 as in C
                codes = inputs / args.input_lsb
                off = np.abs(codes - np.rint(codes))[np.isfinite(codes)].max(initial=0.0)  # an infinite code's: none
                inputs = (np.rint(codes).astype(np.float32) * lsb).astype(float)
            apart = "" if not off > 0.05 else ("; they are not whole codes (a tared ReadPose's lines): rounded, they "
                                               "are not what the board computed; leave --input-lsb out for them")
            print(f"float: readings rounded to codes of {float(lsb):.9g} {model.input_units} and taken as the "
                  f"float code * LSB a device computes (an Arduino's ReadPose){apart}", file=sys.stderr)
        check_magnitudes(model, args.precision)  # as codegen: the C's outputs are always finite
        with np.errstate(over="ignore"):  # a reading beyond float's range is inf, as the C's conversion makes it
            pred, status = model.predict(inputs, with_status=True, precision=args.precision)
    shown_while("predict", f"writing {args.output}",
                lambda: write_atomic(args.output, estimates_csv(model.output_names, pred, status)))
    notes = predict_notes(model, pred, status, args.precision, labels)
    print(f"wrote {len(pred)} estimate{'s' * (len(pred) != 1)} to {args.output}"
          + (f" ({'; '.join(notes)})" if notes else ""),
          file=sys.stderr)
    return 0


def cmd_report(args) -> int:
    from fitgen.app import plots
    from fitgen.base.fileio import write_all
    from fitgen.app.report import data_notes, format_report, sweep_sensor
    from fitgen.c.codegen import check_magnitudes
    from fitgen.equations.model import check_input_units, load_model
    from fitgen.physics.dataset import load_dataset, refuse_huge, rows_on_the_skin
    from fitgen.physics.sensor import load_sensor

    if args.plot and not args.data:  # every check before anything is written
        raise InputError("--plot needs --data (the rows to plot estimates for)")
    if args.paper and not args.data:  # the paper's figures stand beside the errors on the data
        raise InputError("--paper goes with --data (without it, it would be ignored)")
    folder = plots.require(args.plot) if args.plot else None  # made when the figures are written
    if args.sensor and folder is None:
        raise InputError("--sensor goes with --plot (the rotation sweep is drawn on it)")
    model = load_model(args.model)
    if args.sensor and not {"thx", "thy"} & set(model.output_names):
        raise InputError(f"--sensor draws the rotation sweep, and model {args.model} estimates no rotation "
                         f"({', '.join(model.output_names)}): leave --sensor out")
    sensor = sweep_sensor(load_sensor(args.sensor), model, args.sensor) if folder is not None and args.sensor else None
    read = shown_while("report", f"reading {args.data}", lambda: load_dataset(args.data)) if args.data else None
    ds, lifted = rows_on_the_skin(refuse_huge(read), f"{args.data}: every row is lifted off the skin, so no contact "
                                  "pose to report on") if read is not None else (None, 0)
    if ds is not None:
        check_input_units(model, ds.meta.get("units"), f"{args.data}'s readings", f"model {args.model}")
        check_magnitudes(model, "double")  # as predict: estimates of inf had made a table of them, status 0
    if lifted:
        print(f"left out {lifted} row(s) lifted off the skin: they read the magnet at rest, no contact pose to "
              "estimate", file=sys.stderr)
    if ds is not None and not set(model.output_names) & set(ds.target_names):
        raise InputError(f"{args.data}: no column of the model's outputs ({', '.join(model.output_names)}), "
                         "so no error to report")
    try:
        text = format_report(model, ds, title=f"Report for {args.model}", paper=args.paper)
    except InputError:
        raise
    except (KeyError, TypeError, ValueError, AttributeError, IndexError) as exc:  # the notes were edited by hand
        raise InputError(f"model file {args.model}: its fit notes are not as fitgen fit writes them "
                         f"({type(exc).__name__}: {exc})") from None
    if ds is not None:  # another sensor's errors would read as the model's own: said as predict says it
        print("".join(f"note: {n}\n" for n in data_notes(model, ds)), end="", file=sys.stderr)
    # the figures drawn first, then written with the report: a failure leaves none of them
    figures = plots.report_figures(model, ds, sensor) if folder is not None else {}
    files = [(args.output, text)] if args.output else []
    paths = write_all(files + [(folder / name, png) for name, png in figures.items()])
    if args.output:
        print(f"wrote {paths[0]}", file=sys.stderr)  # as every command that writes says
    else:
        print(text, end="")
    if figures:
        print("plots: " + ", ".join(str(p) for p in paths[-len(figures):]), file=sys.stderr)
    return 0


def cmd_codegen(args) -> int:
    from fitgen.c.codegen import OURS, render_fixed_header, write_header

    model, target = model_and_target(args)
    if args.precision == "fixed":
        from fitgen.app.report import rounding_note
        from fitgen.c.fixedc import plan_line
        from fitgen.equations.inputscale import plan_at
        from fitgen.base.fileio import write_in_folder

        if args.fma or args.style:  # fixed point has one layout and no floating point to fuse
            raise InputError(f"{'--fma' if args.fma else '--style'} does not apply to --precision fixed")
        fm, source = plan_at(model, args.input_lsb, args.input_offset, target.mul_bits if target else 32)
        path = write_in_folder(args.output, f"{args.prefix}_model.h", render_fixed_header(fm, args.prefix),
                               [args.model], OURS)
        print(f"wrote {path} (fixed point, input LSB {fm.input_lsb:.6g} {model.input_units} from {source}, "
              f"offset {fm.input_offset:g}; plan: {plan_line(fm)}; {fm.summary()}; model {model.sha256[:12]})"
              + ("" if (note := rounding_note(model, fm.input_lsb)) is None else f"\nnote: {note}"), file=sys.stderr)
        return 0
    if args.input_lsb is not None or args.input_offset is not None:
        from fitgen.fitting.holdout import device_precision

        raise InputError(f"--input-lsb and --input-offset apply to --precision fixed only, and this header is "
                         f"{args.precision}" + (" (the model was fitted for fixed point: give --precision fixed)"
                                                if device_precision(model) == "fixed" else ""))
    # a table evaluation keeps every power and harmonic monomial in arrays on the stack, past the Uno's 2 kB of RAM
    # for the default harmonics model (docs/arduino.md): arduino-build's default there too
    args.style = args.style or ("unrolled" if args.target == "uno" else "table")
    path = write_header(model, args.output, args.precision, args.style, args.prefix, args.fma, target=args.target,
                        inputs=[args.model])
    print(f"wrote {path} ({args.precision}, {args.style}{', fma' if args.fma else ''}, model {model.sha256[:12]})",
          file=sys.stderr)
    return 0


def cmd_tradeoff(args) -> int:
    from fitgen.app.tradeoff import run_tradeoff

    return run_tradeoff(args, sensor_of(args))


def cmd_demo(args) -> int:
    from fitgen.app.demo import run_demo

    return run_demo(Path(args.out))


def build_parser() -> Parser:
    p = Parser(prog="fitgen", description="A magnetic tactile sensor's estimate equations: simulate its readings, "
               "fit the equations, calibrate a built unit from a capture, and generate C (README.md; docs/)")
    p.add_argument("--version", action="version", version=f"fitgen {__version__}")
    sub = p.add_subparsers(dest="command", required=True, parser_class=Parser)

    def command(name, func, help_text):
        parser = sub.add_parser(name, help=help_text)
        parser.set_defaults(func=func)
        return parser

    s = command("simulate", cmd_simulate, "simulate element readings for a pose set")
    s.add_argument("--sensor", default="paper", help="preset name or sensor TOML (default: paper)")
    s.add_argument("--grid", help="paper-sim, paper-exp, or 'dx=-2:2:5 dz=0,-1 ...'")
    s.add_argument("--random", type=int, metavar="N",
                   help="N random poses in --ranges (with --grid: after the grid's poses)")
    s.add_argument("--ranges", help="box for --random: 'dx=-2:2 thx=-5:5 ...' (default: paper-sim box)")
    s.add_argument("--poses", metavar="FILE.csv", help="simulate the poses in this CSV")
    s.add_argument("--seed", type=count, default=0, help="seed of --random's poses and the noise (default 0)")
    s.add_argument("--noise", default="0", help="element noise rms in output units, or 'sensor' (default 0)")
    s.add_argument("--adc-bits", type=int, help="override the transfer's ADC bits (0: no quantisation)")
    s.add_argument("--transfer", choices=TRANSFERS, help="override the sensor file's transfer")
    s.add_argument("--scene", help="full, slide, press or a scene TOML: simulate its grid (or --random N in its box)")
    s.add_argument("--labels", choices=("stage", "magnet"), default="stage",
                   help="for a built unit: the displacements the poses and labels are, the stage's (what a capture "
                        "measures; default) or the magnet's")
    s.add_argument("--unit", type=int, metavar="SEED",
                   help="simulate a built unit of the sensor, drawn within its [tolerances] with this seed; its sensor "
                        "file is written beside the data (<stem>.unit.toml)")
    s.add_argument("-o", "--output", required=True, help="dataset CSV to write")

    o = command("observe", cmd_observe, "observability of each pose component (Jacobian SVD, Cramer-Rao)")
    o.add_argument("sensor_pos", nargs="?", metavar="SENSOR", help="the same as --sensor")
    o.add_argument("--sensor", help="preset name or sensor TOML (default: paper)")
    o.add_argument("--scene", help="full, slide, press or a scene TOML (default: full)")
    o.add_argument("--ranges", help="pose box 'dx=-2:2 ...' overriding the scene's")
    o.add_argument("--noise", help="element noise rms in output units (default: the sensor file's)")
    o.add_argument("--accuracy", help="required 1-sigma accuracy, e.g. 'dx=0.05 thx=0.5'")
    o.add_argument("--transfer", choices=TRANSFERS, help="override the sensor file's transfer")

    f = command("fit", cmd_fit, "choose and fit the estimate equations by stepwise AIC")
    f.add_argument("data", metavar="DATA.csv", help="readings and poses (fitgen simulate, tactile-host capture)")
    f.add_argument("-o", "--output", required=True, help="model file (JSON) to write")
    f.add_argument("--outputs", help="comma-separated outputs to fit (default: every pose column of the data)")
    f.add_argument("--k", default="aic", help="penalty per term: aic (2), bic (log n) or a number")
    f.add_argument("--max-terms", type=int, help="cap on terms per equation")
    f.add_argument("--family", default="auto", choices=FAMILY_CHOICES,
                   help="candidates: all 11 power kinds, no-roots, integer (v^1..v^4 only), harmonics (all 11 "
                        "and monomials of the ring's harmonics up to degree 3; needs the sensor), or auto (default: "
                        "all or harmonics, whichever is more accurate on validation poses; all without a sensor)")
    f.add_argument("--no-d-terms", action="store_true",
                   help="rotations without the displacement terms (not with --true-d)")
    f.add_argument("--true-d", action="store_true",
                   help="rotation d-terms from the true displacements instead of the fitted estimates")
    f.add_argument("--scene", help="fit only the outputs of this scene (default: the dataset's scene, if any)")
    f.add_argument("--sensor", help="the dataset's sensor, for its noise, the held-out poses and the scene check "
                                    "(default: the preset the dataset's meta names)")
    f.add_argument("--force", action="store_true", help="fit a scene's outputs (--scene, or the data's scene) even if "
                   "the sensor cannot resolve them")
    f.add_argument("--noise", metavar="X",
                   help="reading noise rms (input units) the device will see, added in expectation (default: what "
                        "a capture measured per sample, else the sensor's figure). 0 alone: the data as "
                        "given and exact arithmetic, the paper's procedure (R's step())")
    f.add_argument("--precision", choices=("float", "double", "fixed", "exact"),
                   help="arithmetic the equations must survive on the device (default float; exact with --noise 0)")
    f.add_argument("--refine", type=int, default=0, metavar="STEPS",
                   help="after the equations, STEPS Gauss-Newton steps on a forward model (readings from the pose) "
                        "fitted to the same data, with the equations' estimate as prior (docs/refine.md; default 0: "
                        "none). Needs all five pose columns and data that vary in each")
    f.add_argument("--refine-terms", type=int, metavar="N",
                   help="with --refine: cap on the forward model's terms per element (default 30)")
    f.add_argument("--units", choices=("mT", "V"), help="the readings' units when the data have no meta file "
                   "(default mT; V for volts from ADCs: what read, pi-build and arduino-build take)")
    f.add_argument("--held-out", type=count, default=2000, metavar="N",
                   help="random held-out poses in the data's box for the deployed-accuracy figures (default 2000; "
                        "0: none)")

    add_calibration_commands(command)

    pr = command("predict", cmd_predict, "estimates for the rows of a dataset")
    pr.add_argument("model", metavar="MODEL", help="model file (fitgen fit)")
    pr.add_argument("data", metavar="DATA.csv", help="the readings to estimate from (columns but the inputs and "
                    "poses go unused; every cell a number)")
    pr.add_argument("-o", "--output", required=True, help="CSV of estimates (and status) to write")
    pr.add_argument("--precision", choices=("double", "float", "fixed"),
                    help="the arithmetic of the generated C, bit for bit: double or float, as the header computes "
                         "them; fixed: the fixed-point header's integers (as real values), from the v columns rounded "
                         "to ADC codes as the ADC would, or taken as codes with --codes. Default as codegen's: "
                         "double (fixed with --codes), or on a --target without double the precision the model "
                         "was fitted for if it runs it")
    pr.add_argument("--codes", action="store_true",
                    help="fixed: the v columns are the ADC codes the fixed header takes (whole numbers)")
    pr.add_argument("--input-lsb", type=finite, metavar="X",
                    help="fixed: the input value of one ADC code, as for codegen (default: the model's sensor's ADC); "
                    "float: the v columns rounded to such codes and taken as float(code) * float(X), as a device's "
                    "float code (ReadPose) computes them")
    pr.add_argument("--input-offset", type=finite, metavar="Y", help="fixed: the input value of code 0")
    pr.add_argument("--target", choices=tuple(TARGETS), help="the core, as codegen --target: its default precision; "
                    "fixed: the plan it makes for that core (uno: 16x16->32 products where the error bound allows); "
                    "refuses a precision it cannot run")

    r = command("report", cmd_report, "terms, AIC trace and errors of a model")
    r.add_argument("model", metavar="MODEL", help="model file (fitgen fit)")
    r.add_argument("--data", help="dataset to measure errors on (default: the fit's own figures only)")
    r.add_argument("--paper", action="store_true", help="with --data: show the seed paper's figures beside ours")
    r.add_argument("--plot", metavar="DIR", help="write estimate-vs-target PNGs here (needs matplotlib)")
    r.add_argument("--sensor", help="with --plot: also the 0.1-degree rotation sweep on this sensor")
    r.add_argument("-o", "--output", help="write the report here instead of stdout")

    c = command("codegen", cmd_codegen, "generate the header-only C99 estimator of a model")
    c.add_argument("model", metavar="MODEL", help="model file (fitgen fit)")
    c.add_argument("-o", "--output", required=True, metavar="DIR", help="folder for <prefix>_model.h")
    c.add_argument("--precision", choices=("double", "float", "fixed"),
                   help="fixed: integer ADC codes in, int32 outputs, no floating point (Cortex-M0); default double, "
                        "or on a --target without double the precision the model was fitted for if it runs it")
    c.add_argument("--style", choices=("table", "unrolled"),
                   help="default table (unrolled with --target uno, as arduino-build); not with --precision fixed")
    c.add_argument("--prefix", default="tm", help="C identifier prefix (default tm)")
    c.add_argument("--fma", action="store_true",
                   help="sum each term with fma(): fewer instructions on cores with fused multiply-add")
    c.add_argument("--input-lsb", type=finite, metavar="X",
                   help="fixed: the input value of one ADC code (default: the model's sensor's ADC, "
                        "or 3.3/65535 for inputs in V)")
    c.add_argument("--input-offset", type=finite, metavar="Y", help="fixed: the input value of code 0 (default 0)")
    c.add_argument("--target", choices=tuple(TARGETS), help="the core the header is for (refuses a precision it "
                   "cannot run: uno takes float or fixed); the header builds for any core")

    t = command("tradeoff", cmd_tradeoff,
                "accuracy against cost over penalty, cap, family, precision, style and refinement")
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
    t.add_argument("--seed", type=count, default=0, help="held-out poses and noise draws (default 0)")
    t.add_argument("--jobs", type=int, default=2, help="builds measured at once (default 2)")
    t.add_argument("--max-share", type=float, default=0.05, metavar="S",
                   help="fail (exit 1) when a point's rounding adds more than this share of its model's held-out "
                        "max error (default 0.05)")
    t.add_argument("--transfer", choices=TRANSFERS, help="override the sensor file's transfer")
    t.add_argument("--core", choices=CYCLE_TARGETS, help="costs on this core: uno = cycles per estimate on the ATmega328P "
                   "(simavr), its fixed-point plan, float and fixed only (default: x86 instructions, Cortex-M flash)")
    t.add_argument("-o", "--output", default="tradeoff-out", metavar="DIR",
                   help="folder for tradeoff.csv, .md, .png (default: tradeoff-out)")

    d = command("demo", cmd_demo, "the main job end to end on the paper sensor")
    d.add_argument("-o", "--out", "--output", dest="out", default="demo-out", help="its folder (default: demo-out)")
    return p


def _check(args) -> None:
    """What argparse cannot check; an output file's folder before the work, not after it."""
    check_not_empty(args)
    if getattr(args, "adc_bits", None) is not None and not 0 <= args.adc_bits <= 32:
        raise InputError(f"--adc-bits must be 0..32, got {args.adc_bits}")
    for flag in ("held_out", "random"):  # said before the work, not after a fit
        n = getattr(args, flag, None)
        if n is not None and n > MAX_POSES:
            raise InputError(f"--{flag.replace('_', '-')} must be at most {MAX_POSES:,} poses, got {n}")
    # -o is a file for these; a folder for codegen and tradeoff
    check_written(args, files=(cmd_simulate, cmd_fit, cmd_predict, cmd_report, cmd_identify, cmd_schedule))
    check_output_kind(args)  # said before the work


def main(argv=None) -> int:
    command_main(build_parser, argv, "fitgen", _check)
