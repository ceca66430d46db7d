"""The calibration commands of ``fitgen``: ``identify`` (a built unit's physics from a capture), ``schedule`` (the
capture's poses) and ``check`` (a calibrated model on a check capture of its unit, fitgen.app.check_cli); thin
layers over fitgen.fitting.identify, fitgen.fitting.schedule and fitgen.fitting.check."""

from __future__ import annotations

import os
import sys

from fitgen.app.cliutil import count, finite
from fitgen.app.options import noise_of, sensor_file_of, sensor_of
from fitgen.base.fileio import write_all
from fitgen.base.errors import InputError
from fitgen.base.parse import MAX_NOISE, MAX_ROW_SAMPLES, parse_positive
from fitgen.physics.sensor import TRANSFERS

from fitgen.app.captureinput import at_t0, not_levels
from fitgen.app.check_cli import cmd_check


def cmd_identify(args) -> int:
    from shlex import quote

    from fitgen.app import plots
    from fitgen.app.replaced import replaced_unit, unit_output
    from fitgen.base.progress import Progress
    from fitgen.fitting import identify as idf, unitrecord as rec, verdict
    from fitgen.fitting.capturezero import lifted_rows, stage_zero
    from fitgen.fitting.holdout import drawing_rest_spread
    from fitgen.physics.dataset import load_capture
    from fitgen.physics.units import require_drawing
    from host.temperature import load_tempcomp
    from host.tempunit import capture_note

    if args.noise is not None and not args.noise > 0:  # identify weighs each reading by it
        raise InputError(f"--noise must be a finite number > 0, got {args.noise:g}")
    if args.noise is not None and args.noise > MAX_NOISE:  # said now, not by the unit file's write after the solve
        raise InputError(f"--noise {args.noise:g} is no sensor's reading noise (at most {MAX_NOISE:g}, in the "
                         "readings' units: V or mT)")
    folder = plots.require(args.plot) if args.plot else None
    not_levels(args.capture)
    ds = load_capture(args.capture)
    sha = ds.sha256  # the capture's as written, before a compensation
    temperature = rec.capture_temperature(ds.meta, ds.n_rows)
    span = ""
    tc = load_tempcomp(args.temp_comp) if args.temp_comp else None
    if tc is not None:
        ds, temperature = at_t0(ds, tc, args.temp_comp, args.capture, "identify")
    elif span := rec.temperature_span_line(ds.meta, ds.n_rows):  # before a refusal, which it may explain
        print(f"identify: {span}", file=sys.stderr)
    for line in filter(None, (rec.unfinished_line(ds.meta, ds.n_rows, args.capture, ds.poses()),
                              rec.check_capture_line(ds.meta, args.capture))):
        print(f"identify: {line}", file=sys.stderr)
    args.sensor, said = rec.drawing_for(args.sensor, ds.meta, args.capture)  # the one the capture's schedule names
    unit_output(args.output, args.sensor, ds.meta)
    if not ds.target_names:
        raise InputError(f"{args.capture} has readings but no pose columns (dx,dy,dz,...): identify needs each row's "
                         "stage displacement from the zero, as tactile-host capture writes it")
    rec.check_transfer(args.transfer, ds.meta, args.capture)
    drawing = sensor_of(args) if args.transfer else rec.in_capture_units(sensor_of(args), ds.meta)
    require_drawing(drawing)  # a unit file given as --sensor: refused before the notes on it
    # a compensation fitted on another unit than the one the capture (at t0) is of
    if tc is not None and (note := capture_note(ds, tc, drawing_rest_spread(drawing), f"--temp-comp {args.temp_comp}",
                                                args.capture)):
        print(f"identify: {note}", file=sys.stderr)
    noise, source = rec.row_noise(ds.meta, drawing, args.noise)
    args.rig_error, args.zero_error, stage = rec.stage_errors(args.rig_error, args.zero_error, ds.meta, args.capture)
    zero = stage_zero(ds.meta, args.capture)  # recorded, so that fitgen check tells a zero reused from one set anew
    if said:  # once the options and the meta have passed: a refusal is one line
        print(f"identify: {said}", file=sys.stderr)
    if zero and zero["zeros"] > 1:
        print(f"identify: note: the capture's rows were taken from {zero['zeros']} zeros (a run set it again: the "
              "controller was reset, or the stage moved, since the zero was taken, and the same numbers after a "
              "reset need not be the same place), and identify allows for one zero's error shared by every row: "
              "rows from another zero may stand out; capture them again from one zero if they do", file=sys.stderr)
    for line in verdict.lifted_rows_line(ds.poses(), args.rig_error, args.zero_error):  # before a refusal naming one
        print(f"identify: {line}", file=sys.stderr)

    def solve(title: str, lifted: tuple = ()) -> idf.Identification:
        with Progress(title, 4) as bar:
            return idf.identify(drawing, ds.inputs, ds.poses(), noise, rig_error=args.rig_error,
                                zero_error=args.zero_error, reach=rec.stage_reach(ds.meta, args.capture),
                                progress=lambda i, n, note: bar.update(i - bar.done, note), lifted=lifted)

    ident = solve("identify")
    if (rows := lifted_rows(ident)) and args.zero_error > 0:  # a zero set above first contact: rows that read at rest
        again = solve("rows the stage lifted", rows)
        ident, rows = (again, ()) if again.explained else (ident, rows)
    with Progress("what to blame", drawing.n_elements) as bar:  # moves only when the capture is refused

        def trial(i, n, note):
            bar.total = n  # the ring's turns and the pairs count too when they are tried
            bar.update(1, note)

        try:
            verdict.check_explained(ident, args.capture, drawing.name, source, trial, lifted=rows)
        except InputError as exc:
            hint = "" if args.transfer else rec.units_hint(drawing, ds.inputs, ds.poses(), ds.meta)
            text = f"{hint}; read as {drawing.units}, {exc}" if hint else str(exc)
            if span:  # drift the physics does not model reads as rows that stand out
                head, sep, tail = text.rpartition("; nothing written")
                text = (head if sep else text) + ("; the rows' temperatures spread (the note above): give --temp-comp "
                                                  "before deleting rows") + sep + tail
            raise InputError(_with_map(text, getattr(exc, "order", None), ds.meta.get("adc"))) from None
    unit_noise, unit_source = rec.device_noise(ds.meta, drawing, args.noise)
    files = rec.unit_files(ident, args.output, {"capture": str(args.capture), "capture_sha256": sha,
                                                "drawing_spec": args.sensor, **temperature,
                                                **({"capture_zero": zero} if zero else {})}, unit_noise)
    if folder is not None:  # drawn first, then written with the unit's files: a failure leaves none of them
        files.append((folder / "identify.png", plots.identification_png(ident)))
    replaced = replaced_unit(*files[0], sha, args.capture)
    unit, post, *png = write_all(files)
    print(f"reading noise per row: {source}; rig error {args.rig_error:g} mm per row, zero error "
          f"{ident.problem.zero_error:g} mm{stage}", file=sys.stderr)
    print(rec.report(ident, rec.samples_per_row(ds.meta)), end="")
    print(f"wrote {unit} (the unit at the maximum a posteriori) and {post} (every parameter's standard error and "
          "the posterior)", file=sys.stderr)
    print(f"the unit's reading noise per sample: {unit_noise:.3g} {drawing.units} ({unit_source}), in {unit}: the "
          "twin's fit adds it in expectation and holds out with it", file=sys.stderr)
    if replaced:
        # a copied project folder's twin records the original's path: check refuses only a twin that leads here
        print(f"identify: note: {unit} held {replaced}, now replaced: a twin fitted on it no longer matches "
              f"this file (fitgen check refuses one whose record names it); simulate --sensor {unit} and fit again",
              file=sys.stderr)
    if png:
        print(f"plot: {png[0]}", file=sys.stderr)
    with Progress("a looser stage?", 4) as bar:  # each moves only when the chi-square sits high
        field = verdict.looser_stage_line(ident, lambda i, n, note: bar.update(i - bar.done, note))
    with Progress("a field the stage carries?", 4) as bar:
        field = field or verdict.field_line(ident, lambda i, n, note: bar.update(i - bar.done, note))
    # a cause every row shares first: under it, the rows that stand out may not
    notes = (verdict.taken_lifted_line(ident, ds.poses()) + verdict.held_line(ident) + field
             + verdict.outlier_lines(ident, args.capture)
             + verdict.low_residual_line(ident, source) + verdict.far_zero_line(ident))
    print("".join(f"identify: {ln}\n" for ln in notes), end="", file=sys.stderr)
    # unit.toml's twin is twin.json beside it; another unit file's its own (a batch in one folder: none replaces one)
    twin = str(unit.with_name("twin" if unit.name == "unit.toml" else unit.name.removesuffix(".toml")
                              .removesuffix(".unit") + ".twin"))
    print(f"next: fitgen simulate --sensor {quote(str(unit))} --grid paper-sim --random 5000 -o {quote(twin + '.csv')}"
          f", then fitgen fit {quote(twin + '.csv')} -o {quote(twin + '.json')} (the unit's own equations, tilt "
          "included)", file=sys.stderr)
    return 0


def _with_map(text: str, order, spec) -> str:
    """A refusal that names the channels' order, with the capture's --adc map rewritten to read in it where a
    spec can say so."""
    from host.channelmap import reordered_spec

    fixed = reordered_spec(spec, order) if order is not None else None
    end = "; nothing written"
    if fixed is None or not text.endswith(end):
        return text
    return (text[:-len(end)] + f"; if the channels are the cause, capture again with --adc {fixed} (the capture's "
            f"map, {spec}, with its inputs in that order)" + end)


def samples_of(args, drawing) -> tuple[int, float, dict]:
    """``--samples`` and ``--noise``: the samples per row and the single-sample noise the schedule is made for, and
    what the schedule's meta records of a noise record they came from. ``--samples`` is a count, or the record
    ``tactile-host noise -o`` wrote: its recommendation and, unless ``--noise`` is given, its measured noise."""
    noise = drawing.noise if args.noise is None else noise_of(args.noise, drawing, most=MAX_NOISE)
    if args.noise is not None and not noise > 0:  # the option's, not the file's
        raise InputError(f"--noise must be a finite number > 0, got {args.noise} (the schedule weighs each reading by "
                         "it)")
    if not args.samples.lower().endswith(".json"):
        if os.path.exists(args.samples):  # a file, but no record: "not a whole number" would not say what is wanted
            raise InputError(f"--samples {args.samples}: a count, or the .json record tactile-host noise -o writes; "
                             "this file is neither")
        return parse_positive(args.samples, "--samples", integer=True, most=MAX_ROW_SAMPLES), noise, {}
    import numpy as np

    from host.noiserun import told

    samples, single = told(args.samples)
    if single.size != drawing.n_elements:
        raise InputError(f"{args.samples} records {single.size} elements, the sensor {drawing.name} has "
                         f"{drawing.n_elements}: a record of another sensor")
    if args.noise is None:
        if drawing.units != "V":
            raise InputError(f"{args.samples} measured volts and the schedule is for {drawing.units} (--transfer "
                             "raw): give --noise in mT as well, or schedule for gmr")
        noise = float(np.sqrt(np.mean(single ** 2)))
    return samples, noise, {"samples_from": str(args.samples), "noise_per_sample": noise}


def cmd_schedule(args) -> int:
    import numpy as np

    from fitgen.base.progress import Progress
    from fitgen.fitting.schedule import schedule, schedule_record, write_schedule
    from fitgen.physics.simulate import parse_ranges

    if args.seed and args.check is None:
        raise InputError("--seed goes with --check (the D-optimal schedule draws nothing at random)")
    if args.check is not None and args.n is not None:
        raise InputError(f"--n goes with the D-optimal schedule; --check {args.check} says how many check poses")
    args.n = 40 if args.n is None else args.n
    drawing = sensor_of(args)
    axes = tuple(a.strip() for a in args.axes.split(",") if a.strip())
    samples, noise, told = samples_of(args, drawing)
    # recorded so that fitgen check can tell a check stage's error the user gave from the default
    given = {"rig_error_given": args.rig_error is not None}
    if args.rig_error is None:
        from fitgen.fitting.identify import RIG_ERROR
        args.rig_error = RIG_ERROR
    if args.check is not None:
        return _check_schedule(args, drawing, axes, samples, given)

    def step(done, total, note):
        bar.total = total
        bar.update(done - bar.done, note)

    with Progress("schedule", args.n) as bar:
        poses, info = schedule(drawing, args.n, axes=axes, ranges=parse_ranges(args.limits, {}),
                               noise=noise / np.sqrt(samples) if noise > 0 else None,  # none: the file's blamed
                               rig_error=args.rig_error, zero_error=args.zero_error, progress=step)
    # the drawing's file and hash: capture passes them on, and identify takes that drawing unless told
    own = sensor_file_of(args)
    write_schedule(args.output, poses, axes, schedule_record(info, drawing, samples, **given, **told, **own))
    rest = (f"; {info['rest_rows']} at rest, lifted {info['rest_lift_mm']:g} mm off the skin" if info["rest_rows"]
            else "")
    if told:
        print(f"made for {samples} samples per row (told by {args.samples}) and {noise:.3g} {drawing.units} rms per "
              "sample", file=sys.stderr)
    print(f"wrote {len(poses)} poses ({info['distinct_poses']} distinct, {','.join(axes)}{rest}) to {args.output}",
          file=sys.stderr)
    left = (f"; {info['beyond_linear_range']} of its grid poses left out, past {100 * info['linear_share']:g} % of an "
            "element's linear range" if info["beyond_linear_range"] else "")
    print(f"within {_box(info)} from first contact (the sensor's travel within --limits{left}{_pressed(info)}): "
          "give the stage room for them and their approach (--stage-limits)", file=sys.stderr)
    return 0


def _box(info: dict) -> str:
    """A schedule's pose box in words, each axis in its unit: 'dx -1.5..1.5 mm, ..., thx -5..5 deg'."""
    from fitgen.physics.pose import POSE_NAMES, POSE_UNITS

    return ", ".join(f"{a} {lo:g}..{hi:g} {POSE_UNITS[POSE_NAMES.index(a)]}" for a, (lo, hi) in info["ranges"].items())


def _pressed(info: dict) -> str:
    """The schedule line's clause when its rows in contact are pressed below first contact, or when they stand at
    first contact on a stage that lifts some off the skin (--axes without dz); else ''."""
    from fitgen.physics.pose import contact_top, lift_odds

    rig, zero = info["rig_error"], info["zero_error"]
    stage = f"a stage off by {rig:g} mm rms, zeroed within {zero:g} mm,"
    press = contact_top(rig, zero)
    if "dz" not in info["ranges"] and press < 0:
        return (f"; every row at first contact (dz 0, which --axes does not move), where {stage} lifts about one in "
                f"{1.0 / lift_odds(0.0, rig, zero):,.0f} off the skin: with dz among --axes the rows are pressed to "
                f"{press:g} mm")
    top = info["ranges"].get("dz", (0.0, 0.0))[1]
    if top >= 0:
        return ""
    return f"; rows in contact pressed at least {-top:g} mm, which {stage} does not lift off the skin"


def _check_schedule(args, drawing, axes, samples: int, given: dict) -> int:
    """``schedule --check N``: random poses in the working box, for a check capture."""
    from fitgen.fitting.schedule import check_schedule, schedule_record, write_schedule
    from fitgen.physics.simulate import parse_ranges

    poses, info = check_schedule(drawing, args.check, axes=axes, ranges=parse_ranges(args.limits, {}), seed=args.seed,
                                 rig_error=args.rig_error, zero_error=args.zero_error)
    own = sensor_file_of(args)
    write_schedule(args.output, poses, axes, schedule_record(info, drawing, samples, **given, **own))
    margin = (f", {info['edge_margin']:g} mm inside the working box's edges, which the stage's error could carry "
              "a row past" if info["edge_margin"] else "")
    print(f"wrote {len(poses)} random check poses ({_box(info)} from first contact{margin}, seed {args.seed}"
          f"{_pressed(info)}) to {args.output}: capture them as for the calibration (tactile-host capture "
          "--poses), then fitgen check MODEL CHECK.csv", file=sys.stderr)
    return 0


def add_calibration_commands(command) -> None:
    """identify, schedule and check on ``command(name, func, help)``, fitgen.app.cli's maker of a subcommand."""
    i = command("identify", cmd_identify, "a built unit's physics from a short capture (its sensor file)")
    i.add_argument("capture", metavar="CAPTURE.csv", help="rows of readings with the stage's displacements (dx,dy,dz)")
    i.add_argument("--sensor", help="the drawing the unit was built to (preset or TOML; default: the one the "
                                    "capture's schedule was made for, else paper)")
    i.add_argument("--transfer", choices=TRANSFERS, help="override the transfer (default: the capture's units)")
    i.add_argument("--noise", type=finite, metavar="X",
                   help="the device's single-sample reading noise (default: what the capture measured or was "
                        "simulated with, else the sensor file's), divided by sqrt(samples per row)")
    i.add_argument("--rig-error", type=finite, metavar="MM",
                   help="the stage's own position error, mm rms per axis (default: the one the capture's schedule "
                        "was made for, else 0.01; a 3D printer 0.03)")
    i.add_argument("--zero-error", type=finite, metavar="MM",
                   help="how far the capture's zero may be from first contact, mm rms per axis, one error shared by "
                        "every row in contact (default: the one the capture's schedule was made for, else 0.02)")
    i.add_argument("--temp-comp", metavar="FILE.json", help="map the capture's readings from the temperature it "
                   "recorded to this compensation's t0 first: the unit at t0, as read --temp-comp sees it")
    i.add_argument("-o", "--output", required=True, metavar="UNIT.toml", help="the unit's sensor file to write")
    i.add_argument("--plot", metavar="DIR", help="also DIR/identify.png: the residuals by row, the sensitivities and "
                   "the magnet's offset against the prior (needs matplotlib)")

    sc = command("schedule", cmd_schedule, "the capture poses that pin a unit's parameters best (D-optimal)")
    sc.add_argument("--sensor", default="paper", help="the drawing (preset or TOML; default paper)")
    sc.add_argument("--transfer", choices=TRANSFERS, default="gmr",
                    help="the readings the capture takes (default gmr: volts, as tactile-host capture reads them)")
    sc.add_argument("--n", type=int, help="poses to capture (default 40)")
    sc.add_argument("--axes", default="dx,dy,dz", help="the axes the stage moves (default dx,dy,dz)")
    sc.add_argument("--limits", help="the stage's limits 'dx=-2:2 dz=-2:0 ...' (default: the sensor's [travel]); "
                    "with dz, a rest row lifts the stage 0.2 mm off the skin besides (docs/calibration.md)")
    sc.add_argument("--samples", default="16", help="samples per row (default 16), or NOISE.json: what it tells")
    sc.add_argument("--noise", help="single-sample reading noise (default: the sensor file's)")
    sc.add_argument("--rig-error", type=finite, metavar="MM",
                    help="the stage's own position error, mm rms per axis (default 0.01; a 3D printer 0.03); "
                         "recorded as given, so that fitgen check takes a check schedule's over the unit's")
    sc.add_argument("--zero-error", type=finite, default=0.02, metavar="MM",
                    help="how far the capture's zero may be from first contact, mm rms per axis (default 0.02): with "
                         "the rig's error, how deep rows in contact press so that none lifts off the skin")
    sc.add_argument("-o", "--output", required=True, metavar="SCHEDULE.csv", help="the poses, for capture --poses")
    sc.add_argument("--check", type=int, metavar="N",
                    help="N random poses in the working pose box instead, not D-optimal and no rest row: a check "
                         "capture of a calibrated unit, for fitgen check")
    sc.add_argument("--seed", type=count, default=0, help="with --check: the random poses' seed (default 0)")

    ch = command("check", cmd_check, "a calibrated model on a check capture of its unit, against what its "
                 "identification predicts at those poses")
    ch.add_argument("model", metavar="MODEL", help="model file (fitgen fit on the unit's twin)")
    ch.add_argument("capture", metavar="CHECK.csv",
                    help="a capture of the unit at poses never used to calibrate it (fitgen schedule --check)")
    ch.add_argument("--sensor", help="the unit's file (default: the one the model's held-out figures were made on)")
    ch.add_argument("--rig-error", type=finite, metavar="MM",
                    help="the stage's own position error, mm rms per axis (default: the one the check capture's "
                         "schedule was made for where fitgen schedule --check was given --rig-error, else the one the "
                         "unit was identified with, else 0.01; a 3D printer 0.03)")
    ch.add_argument("--zero-error", type=finite, metavar="MM",
                    help="how far the check capture's zero may be from the calibration's, mm rms per axis (default: "
                         "from the captures' stage records, 0 where the check moved from the calibration's zero on a "
                         "homed machine, both zeros' errors in quadrature where it moved from one set anew, which "
                         "widens the prediction and hides a sensor moved on its bed by as much; 0 without records)")
    ch.add_argument("--temp-comp", metavar="FILE.json",
                    help="take the check capture's rows from the temperatures it recorded to the compensation's t0, "
                         "which must be the one the unit was identified at (tactile-host capture --temperature fits one)")
    ch.add_argument("--precision", choices=("double", "float", "fixed"),
                    help="the arithmetic to estimate in (default: the one the model was fitted for)")
    ch.add_argument("--plot", metavar="DIR", help="also DIR/check.png: the measured errors beside the predicted ones "
                    "(needs matplotlib)")
