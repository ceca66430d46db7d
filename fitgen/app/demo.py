"""``fitgen demo``: the main job end to end on the paper sensor, each stage printed as it goes."""

from __future__ import annotations

import time
from contextlib import contextmanager
from pathlib import Path

from fitgen.base.errors import InputError
from fitgen.base.fileio import check_folder, foreign_files, make_folder, write_atomic


MARK = ".fitgen-demo"  # in the demo's folder: a folder the demo wrote, which it may write over again
AXES, SAMPLES = ("dx", "dy", "dz"), 16  # the simulated stage's axes, and the samples averaged per captured row


def _own_folder(out: Path) -> None:
    """InputError where ``out`` holds files that no earlier demo wrote: the demo writes capture.csv, schedule.csv,
    check.csv and more, the names a project of one's own uses (docs/calibration.md), over what is there."""
    try:
        held = sorted(p.name for p in out.iterdir())
    except OSError:  # none yet (or no folder: check_folder and make_folder say what it is)
        return
    if held and MARK not in held and not _unmarked_demo(out, held):
        raise foreign_files(str(out), held, "earlier demo", "the demo writes capture.csv, schedule.csv, check.csv and "
                            "more there", "give a new or empty folder (--out)")


def _unmarked_demo(out: Path, held: list) -> bool:
    """Whether ``out`` is a folder a demo wrote before it marked its folders: its paper-model.json fitted on the
    paper-sim.csv beside it (a model of one's own of that name is not the demo's)."""
    import json

    try:
        data = json.loads((out / "paper-model.json").read_text())["fit"]["dataset"]
    except (OSError, ValueError, KeyError, TypeError):
        return False
    return isinstance(data, str) and Path(data).name == "paper-sim.csv" and "paper-sim.csv" in held


def _stage(title: str) -> float:
    print(f"\n== {title}", flush=True)
    return time.monotonic()


def run_demo(out: Path) -> int:
    from fitgen.physics.observe import observe
    from fitgen.physics.scenes import PRESETS
    from fitgen.physics.sensor import load_sensor
    from fitgen.fitting.family import fit_auto
    from fitgen.fitting.fit import FitSettings, fit_model
    from fitgen.base.progress import Progress
    from fitgen.fitting.holdout import N_POSES, box_of, deployed_errors, fitted_held_out, held_out_set, uncalibrated
    from fitgen.app.report import format_report
    from fitgen.physics.simulate import DEFAULT_RANGES, PAPER_GRIDS, grid_poses, pose_rng, random_poses, simulate

    check_folder(out, "--out")
    _own_folder(out)
    make_folder(out)
    write_atomic(out / MARK, "fitgen demo wrote this folder and writes over its files on every run\n")
    sensor = load_sensor("paper")
    print(f"fitgen demo: sensor 'paper' ({sensor.n_elements} GMR elements, magnet "
          f"{sensor.magnet.diameter:g} x {sensor.magnet.height:g} mm, {sensor.magnet.polarization:g} T), "
          f"files in {out}/")

    t = _stage("1. simulate the paper's grid (paper-sim, 1,875 poses)")
    train = simulate(sensor, grid_poses(PAPER_GRIDS["paper-sim"]), provenance={"grid": "paper-sim"})
    train.save(out / "paper-sim.csv")
    print(f"   {train.n_rows} rows -> {out / 'paper-sim.csv'} ({time.monotonic() - t:.2f} s)")

    _stage("2. observability of the paper layout (Jacobian SVD, Cramer-Rao bounds)")
    report = observe(sensor, PRESETS["full"].ranges)
    for line in report.verdicts():
        print("   " + line)

    t = _stage("3. the paper's procedure: stepwise AIC fit of dx, dy, dz, then thx, thy (from eq. 1, 17 kinds "
               "of candidates), noise-free data, exact arithmetic")
    with _fitting(1) as progress:
        paper_model = fit_model(train, settings=FitSettings.exact(), progress=progress)
    paper_model.fit_info["dataset"] = str(out / "paper-sim.csv")
    paper_model.save(out / "paper-model.json")
    print(f"   model -> {out / 'paper-model.json'} ({time.monotonic() - t:.1f} s)")
    test = simulate(sensor, random_poses(2000, DEFAULT_RANGES, pose_rng(2026)), provenance={"random": 2000})
    test.save(out / "random-2000.csv")
    text = format_report(paper_model, train, "paper-sim (training grid), beside the paper's simulation", paper=True)
    text += "\n" + format_report(paper_model, test, "2,000 random poses never used in fitting", paper=True)
    write_atomic(out / "paper-report.md", text)
    _print_comparison(paper_model, train, test)
    print(f"   full report -> {out / 'paper-report.md'}")

    t = _stage(f"4. the device's model: fitted for the sensor's noise ({sensor.noise:g} {sensor.units} rms) and "
               "float arithmetic, candidates as `fitgen fit` chooses them (family auto), judged as deployed")
    with _fitting() as progress:
        model, family = fit_auto(train, None, FitSettings(), sensor, progress=progress)
    model.fit_info["family"] = family
    print(f"   candidates: family {family['name']} ({family['why']})")
    model.fit_info["dataset"] = str(out / "paper-sim.csv")
    held = held_out_set(sensor, box_of(train.poses()), model.output_names)
    model.fit_info["held_out"] = {**held.spec, "errors": deployed_errors(model, held, sensor)}
    unc = uncalibrated(model, sensor, box_of(train.poses()))
    if unc is not None:
        model.fit_info["held_out"]["uncalibrated"] = unc
    model.save(out / "device-model.json")
    write_atomic(out / "device-report.md", format_report(model, test, "2,000 random poses never used in fitting"))
    print(f"   model -> {out / 'device-model.json'}, report -> {out / 'device-report.md'} "
          f"({time.monotonic() - t:.1f} s)")
    _print_deployed(paper_model, model, deployed_errors(paper_model, held, sensor, ("double", "float")),
                    model.fit_info["held_out"]["errors"], held.spec)
    if blind := [c for c in ("thx", "thy") if c in report.unresolved()]:
        print(f"   {' and '.join(blind)}: one ring cannot tell a small tilt from a slide near rest (step 2), so a "
              "tilt of a few degrees there reads as a slide of hundredths of a mm and its error is the layout's "
              "limit, not the fit's (docs/observe.md; the tilted-axes layout sees it, docs/layouts.md)")
    if unc is not None:
        print(f"   on {unc['units']} units built within the drawing's tolerances, flashed uncalibrated (median max "
              "error with noise): " + ", ".join(f"{o} {v['noisy_max']:.3g}" for o, v in unc["errors"].items())
              + " mm / deg; step 8 calibrates one")

    _stage("5. C code generation of the device's model, verified against Python by gcc")
    held_clean = (held.clean, held.truth)
    status = _codegen_stage(model, out, held_clean)

    _stage("6. reference firmware on an emulated Cortex-M4 (QEMU mps2-an386), HIL suite")
    status = max(status, _hil_stage(model, out, held_clean))

    t = _stage("7. a model in volts for the live view (the gmr transfer an ADC sees, fitted for its noise)")
    volts = sensor.with_transfer("gmr")
    vtrain = simulate(volts, grid_poses(PAPER_GRIDS["paper-sim"]), provenance={"grid": "paper-sim"})
    vtrain.save(out / "paper-sim-volts.csv")
    with _fitting() as progress:
        vmodel, vfamily = fit_auto(vtrain, None, FitSettings(), volts, progress=progress)
    vmodel.fit_info["family"] = vfamily
    vmodel.fit_info["dataset"] = str(out / "paper-sim-volts.csv")
    with Progress("   held-out", 1) as hbar:  # as `fitgen fit` records it: verify and report measure against it
        vmodel.fit_info["held_out"] = fitted_held_out(vmodel, volts, vtrain, N_POSES,
                                                      note=lambda text: hbar.update(0, text))
        hbar.update()
    vmodel.save(out / "model-volts.json")
    print(f"   model -> {out / 'model-volts.json'} (family {vfamily['name']}, noise {volts.noise:g} V rms; "
          f"{time.monotonic() - t:.1f} s)")
    print("   watch it live (a simulated sensor sliding and pressed; open the address it prints):")
    print(f"   tactile-host view --model {out / 'model-volts.json'} --adc ads1115@0x48:0-3,ads1115@0x49:0-3 "
          "--simulate motion --auto-zero")

    _stage("8. a built unit (drawn within the paper drawing's tolerances), calibrated from a 40-pose capture through "
           "a simulated G-code stage: schedule, capture, identify, the twin's fit")
    _unit_stage(out, vmodel)
    return status


def _unit_stage(out: Path, drawing_model) -> None:
    import numpy as np

    from fitgen.fitting.capturezero import stage_zero
    from fitgen.fitting.family import fit_auto
    from fitgen.fitting.fit import FitSettings, fit_model
    from fitgen.fitting.holdout import N_POSES, fitted_held_out, held_out_set
    from fitgen.fitting.identify import identify
    from fitgen.fitting.unitrecord import device_noise, row_noise, save
    from fitgen.physics.dataset import load_dataset, rows_on_the_skin
    from fitgen.fitting.schedule import schedule, schedule_record, write_schedule
    from fitgen.physics.sensor import load_sensor
    from fitgen.physics.simulate import DEFAULT_RANGES, PAPER_GRIDS, grid_poses, pose_rng, random_poses, simulate
    from fitgen.physics.units import draw_unit, write_unit
    from host.capture import load_schedule
    from host.stagesim import simulated_stage_capture

    t = time.monotonic()
    drawing = load_sensor("paper").with_transfer("gmr")
    unit, theta = draw_unit(drawing, 7)
    write_unit(out / "unit-7.toml", unit, "paper", {"seed": 7, "source": "the demo's unit: its truth"})
    poses, info = schedule(drawing, 40, noise=drawing.noise / SAMPLES ** 0.5)
    # with the record `fitgen schedule` writes: identify and check on the demo's files read the drawing from it
    write_schedule(out / "schedule.csv", poses, AXES, schedule_record(info, drawing, SAMPLES, rig_error_given=False))
    cap = out / "capture.csv"
    for stale in (cap, Path(f"{cap}.meta.json")):
        stale.unlink(missing_ok=True)  # a fresh capture each run, not a resumed one
    res = simulated_stage_capture(unit, load_schedule(out / "schedule.csv"), cap, flavor="grbl", samples=SAMPLES,
                                  seed=7)
    print(f"   unit -> {out / 'unit-7.toml'}; {res.captured} poses captured through a simulated GRBL (backlash 0.03 mm, "
          f"repeatability 0.005 mm) -> {cap} ({time.monotonic() - t:.1f} s)")
    t = time.monotonic()
    ds = load_dataset(cap)
    noise, _ = row_noise(ds.meta, drawing)
    ident = identify(drawing, ds.inputs, ds.poses(), noise, rig_error=0.01)
    unit_noise, _ = device_noise(ds.meta, drawing)
    zero = stage_zero(ds.meta, cap)  # as fitgen identify keeps it: the check below tells it reused
    twin_file, _ = save(ident, out / "twin.toml", {"capture": str(cap), "drawing_spec": "paper",
                                                   **({"capture_zero": zero} if zero else {})}, unit_noise)
    d = ident.derived()
    sens = [v for k, (v, _) in d.items() if "sensitivity" in k]
    off = [v for k, (v, _) in d.items() if "magnet offset" in k]
    print(f"   identified -> {twin_file} ({time.monotonic() - t:.1f} s): residuals {ident.reduced_chi2 ** 0.5:.2f}x the "
          f"noise; magnet {off[0]:+.3f}, {off[1]:+.3f} mm off the ring's centre; sensitivities "
          f"{min(sens):.3f}..{max(sens):.3f} x the drawing's; {ident.gauge.shape[1]} combinations no capture separates")
    try:
        from fitgen.app.plots import identification

        from fitgen.fitting.identify import derived_at

        truth = derived_at(ident.space, theta)  # the demo knows its unit
        print(f"   its residuals and what the capture determines, with the unit's truth -> "
              f"{identification(ident, out / 'identify.png', truth)}")
    except InputError as exc:  # matplotlib is an extra: the demo goes on without the figure
        print(f"   (no figure: {exc})")
    t = time.monotonic()
    twin = load_sensor(str(twin_file))  # as `fitgen simulate --sensor twin.toml` reads it: report --sensor takes it
    train = simulate(twin, np.vstack([grid_poses(PAPER_GRIDS["paper-sim"]), random_poses(5000, DEFAULT_RANGES,
                                                                                          pose_rng(1))]))
    with _fitting() as progress:
        model, family = fit_auto(train, None, FitSettings(), twin, progress=progress)
    model.fit_info["family"] = family  # the family chosen, and the rounding noise where it was raised
    # as `fitgen fit` records it: with the unit file's path, so that verify and the HIL suite find the twin again
    model.fit_info["held_out"] = fitted_held_out(model, twin, train, N_POSES, Path(twin_file).resolve())
    model.save(out / "twin-model.json")
    skin = rows_on_the_skin(ds)[0]  # the capture's rows in contact: its rest rows lift the indenter off
    direct = fit_model(skin, ("dx", "dy", "dz"), FitSettings.family("no-roots"))
    print(f"   twin's model -> {out / 'twin-model.json'} ({time.monotonic() - t:.1f} s)")
    held = held_out_set(unit, DEFAULT_RANGES, model.output_names)
    says = model.fit_info["held_out"]["errors"]["float"]
    print(f"   held out on the unit's truth: {held.spec['poses']} random poses, noise {held.spec['noise']:g} V; max error "
          "with noise, float C")
    head = f"direct ({skin.n_rows} rows)"
    print(f"   {'output':6} {'drawing model':>14} {head:>17} {'twin':>9} {'twin file says':>15}")
    errs = {}
    for name, m in (("drawing", drawing_model), ("direct", direct), ("twin", model)):
        est = m.predict(held.noisy, precision="float")
        errs[name] = {o: float(np.abs(est[:, j] - held.noisy_truth[:, model.output_names.index(o)]).max())
                      for j, o in enumerate(m.output_names)}
    for o in model.output_names:
        unit_of = "mm" if o.startswith("d") else "deg"
        direct_cell = f"{errs['direct'][o]:17.3g}" if o in errs["direct"] else f"{'(no label)':>17}"
        print(f"   {o:6} {errs['drawing'][o]:14.3g} {direct_cell} {errs['twin'][o]:9.3g} "
              f"{says[o]['noisy_max']:15.3g}  {unit_of}")
    print("   the direct fit has no tilt labels (a three-axis stage); the twin's file: the median over units drawn "
          "from the identification's posterior (docs/calibration.md)")
    _check_stage(out, drawing, unit, {"twin's model": (model, twin, twin_file),
                                      "drawing's model": (drawing_model, drawing, None)})


def _check_stage(out: Path, drawing, unit, models: dict) -> None:
    """A check capture of the unit through the same stage, and `fitgen check` of each model on it: ``models`` maps a
    name to the model, the sensor it was fitted on and that sensor's unit file (None for the drawing)."""
    from fitgen.fitting.check import check_capture
    from fitgen.fitting.schedule import check_schedule, schedule_record, write_schedule
    from fitgen.physics.dataset import load_dataset
    from host.capture import load_schedule
    from host.stagesim import simulated_stage_capture

    t = time.monotonic()
    poses, info = check_schedule(drawing, 30, seed=7)
    write_schedule(out / "check-poses.csv", poses, AXES, schedule_record(info, drawing, SAMPLES, rig_error_given=False))
    cap = out / "check.csv"
    for stale in (cap, Path(f"{cap}.meta.json")):
        stale.unlink(missing_ok=True)
    simulated_stage_capture(unit, load_schedule(out / "check-poses.csv"), cap, flavor="grbl", samples=SAMPLES,
                            seed=8)
    ds = load_dataset(cap)
    print(f"   a check: 30 random poses in the working box, captured through the same stage -> {cap}; `fitgen check "
          f"MODEL {cap.name}`: each model's max error there, and the greatest that the sensor it was fitted on "
          "predicts (the twin: units from its identification's posterior):")
    for name, (model, sensor, unit_file) in models.items():
        c, _ = check_capture(model, ds, sensor, unit_file)
        said = ", ".join(f"{o} {c.measured[o]['max']:.3g} (up to {c.predicted(o, 'max')[2]:.3g})" for o in c.outputs)
        verdict = ("as predicted" if not c.failed() else
                   f"{max(c.worst(o)[1] for o in c.outputs):.2g}x the greatest: it does not describe this unit")
        print(f"   {name:16} {said}: {verdict}")
        if c.identified:
            print(f"   {'':16} zero error {c.zero_error:.3g} mm: {c.zero_said}")
    print(f"   ({time.monotonic() - t:.1f} s)")


def _codegen_stage(model, out: Path, held_out) -> int:
    import shutil

    from fitgen.c.codegen import write_header

    status = 0
    for precision, style in (("float", "table"), ("double", "table"), ("float", "unrolled")):
        folder = out / f"c-{precision}-{style}"
        header = write_header(model, folder, precision, style)
        line = f"   {precision:6} {style:8} -> {header}"
        if shutil.which("gcc") is None:
            print(line + ": not verified (gcc not found; install it: apt-get install gcc)")
            continue
        from fitgen.c.verify import verify

        res = verify(model, precision, style, n_random=2000, held_out=held_out)
        worst = ", ".join(f"{n} {e:.2g}" for n, e in zip(res.outputs, res.max_error))
        print(f"{line}: {res.n_vectors} vectors {'PASS' if res.ok else 'FAIL'} "
              f"(max |C - Python|: {worst}; worst error/bound {res.max_ratio.max():.2f}; rounding's share of the "
              f"held-out error at most {res.held_out.share.max():.1%})")
        if not res.ok:
            print("   " + "; ".join(res.failures))
            status = 1
    return status


def _hil_stage(model, out: Path, held_out) -> int:
    import shutil

    missing = [t for t in ("qemu-system-arm", "arm-none-eabi-gcc") if shutil.which(t) is None]
    if missing:
        print(f"   skipped: {' and '.join(missing)} not found; install them with: "
              "sudo apt-get install qemu-system-arm gcc-arm-none-eabi")
        return 0
    from hil.emulate import bench_instructions, start_target
    from hil.suite import run_suite
    from host.device import Device

    folder = out / "firmware-mps2"
    with start_target(model, "mps2", precision="float", style="table", workdir=folder) as emu:
        with Device.open(emu.url, timeout=5) as dev:
            cost = bench_instructions(dev)
            print(f"   firmware {folder / 'firmware.elf'}: flash {emu.size['flash']} bytes, RAM {emu.size['ram']} "
                  f"bytes; {cost['instructions']:.0f} instructions per estimate (float, table; QEMU -icount)")
            res = run_suite(dev, model, url=emu.url, n_vectors=1000, n_fuzz=10_000, verbose=False,
                            held_out=held_out)
    for c in res.checks:
        print(f"   {c.name:17} {'pass' if c.ok else 'FAIL'}  {c.detail}")
    print(f"   HIL suite on the emulated core: {'PASS' if res.ok else 'FAIL'}")
    return 0 if res.ok else 1


@contextmanager
def _fitting(families: int = 2):
    """The progress of a fit of the five outputs in ``families`` candidate families (fit_auto compares two), its
    line cleared when the fit ends (it stayed, reading as a fit stopped at its first step)."""
    from fitgen.base.progress import Progress

    with Progress("   fit", 5 * families) as bar:
        yield bar.per_item(lambda name, step, aic, n: f"{name}: step {step}, {n} terms, AIC {aic:.1f}")


def _print_deployed(paper_model, model, paper_errs: dict, errs: dict, spec: dict) -> None:
    print(f"   held out: {spec['poses']} random poses (seed {spec['seed']}); 'noise': the sensor's {spec['noise']:g} "
          f"{model.input_units} rms, {spec['noise_draws']} draws; 'float C': the float header's arithmetic")
    print(f"   {'':6} {'paper procedure':>44} {'device model':>44}")
    head = f"{'terms':>5} {'max':>8} {'RMS noise':>10} {'float C RMS':>11} {'share':>6}"
    print(f"   {'output':6} {head} {head}")
    for pe, e in zip(paper_model.equations, model.equations):
        cells = []
        for eq, er in ((pe, paper_errs), (e, errs)):
            d, f = er["double"][eq.name], er["float"][eq.name]
            cells.append(f"{len(eq.terms):5d} {d['max']:8.3g} {d['noisy_rms']:10.3g} {f['noisy_rms']:11.3g} "
                         f"{f['share']:6.1%}")
        print(f"   {e.name:6} {cells[0]} {cells[1]}")
    print("   max: double, noise-free; share: the float C's largest deviation from double over the model's max error")


def _print_comparison(model, train, test) -> None:
    from fitgen.app.report import PAPER_EXP_TERMS, PAPER_SIM_MAX_ERROR, errors_on

    ev_train, ev_test = errors_on(model, train), errors_on(model, test)
    print(f"   {'output':6} {'terms':>5} {'paper terms*':>12} {'max err (grid)':>15} {'paper max':>10} "
          f"{'max err (random)':>17} {'RMS (random)':>13}")
    for e in model.equations:
        print(f"   {e.name:6} {len(e.terms):5d} {str(PAPER_EXP_TERMS.get(e.name, '-')):>12} "
              f"{ev_train[e.name]['all']['max']:15.3g} {str(PAPER_SIM_MAX_ERROR.get(e.name, '-')):>10} "
              f"{ev_test[e.name]['all']['max']:17.3g} {ev_test[e.name]['all']['rms']:13.3g}")
    print("   * the paper's term counts are from its experiment (450 measured poses); "
          "errors in mm and deg. Why they differ: docs/paper-reproduction.md")
