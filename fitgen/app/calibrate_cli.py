"""The calibration commands of ``fitgen``: ``identify`` (a built unit's physics from a capture) and ``schedule``
(the capture's poses); thin layers over fitgen.fitting.identify and fitgen.fitting.schedule."""

from __future__ import annotations

import sys
from pathlib import Path

from fitgen.base.fileio import write_all
from fitgen.app.options import noise_of, sensor_of
from fitgen.base.errors import InputError
from fitgen.base.parse import parse_positive


def cmd_identify(args) -> int:
    from fitgen.app import plots
    from fitgen.base.progress import Progress
    from fitgen.fitting import identify as idf, unitrecord as rec, verdict
    from fitgen.physics.dataset import load_dataset

    folder = plots.require(args.plot) if args.plot else None
    ds = load_dataset(args.capture)
    sha = ds.sha256  # the capture's as written, before a compensation
    temperature = rec.capture_temperature(ds.meta)
    if args.temp_comp:
        ds, temperature = _at_t0(ds, args.temp_comp, args.capture)
    args.sensor, said = rec.drawing_for(args.sensor, ds.meta)  # the one the capture's schedule was made for
    if said:
        print(said, file=sys.stderr)
    if not ds.target_names:
        raise InputError(f"{args.capture} has readings but no pose columns (dx,dy,dz,...): identify needs each row's "
                         "stage displacement from the zero, as tactile-host capture writes it")
    rec.check_transfer(args.transfer, ds.meta, args.capture)
    drawing = sensor_of(args) if args.transfer else rec.in_capture_units(sensor_of(args), ds.meta)
    noise, source = rec.row_noise(ds.meta, drawing, args.noise)
    with Progress("identify", 4) as bar:
        ident = idf.identify(drawing, ds.inputs, ds.poses(), noise, rig_error=args.rig_error,
                             zero_error=args.zero_error, progress=lambda i, n, note: bar.update(i - bar.done, note))
    with Progress("what to blame", drawing.n_elements) as bar:  # moves only when the capture is refused

        def trial(i, n, note):
            bar.total = n  # the ring's turns and the pairs count too when they are tried
            bar.update(1, note)

        try:
            verdict.check_explained(ident, args.capture, drawing.name, source, trial)
        except InputError as exc:
            hint = "" if args.transfer else rec.units_hint(drawing, ds.inputs, ds.poses(), ds.meta)
            text = f"{hint}; read as {drawing.units}, {exc}" if hint else str(exc)
            raise InputError(_with_map(text, getattr(exc, "order", None), ds.meta.get("adc"))) from None
    unit_noise, unit_source = rec.device_noise(ds.meta, drawing, args.noise)
    files = rec.unit_files(ident, args.output, {"capture": str(args.capture), "capture_sha256": sha,
                                                "drawing_spec": args.sensor, **temperature}, unit_noise)
    if folder is not None:  # drawn first, then written with the unit's files: a failure leaves none of them
        files.append((folder / "identify.png", plots.identification_png(ident)))
    unit, post, *png = write_all(files)
    print(f"reading noise per row: {source}; rig error {args.rig_error:g} mm per row, zero error "
          f"{args.zero_error:g} mm", file=sys.stderr)
    print(rec.report(ident, rec.samples_per_row(ds.meta)), end="")
    print(f"wrote {unit} (the unit at the maximum a posteriori) and {post} (every parameter's standard error and "
          "the posterior)", file=sys.stderr)
    print(f"the unit's reading noise per sample: {unit_noise:.3g} {drawing.units} ({unit_source}), in {unit}: the "
          "twin's fit adds it in expectation and holds out with it", file=sys.stderr)
    if png:
        print(f"plot: {png[0]}", file=sys.stderr)
    with Progress("a looser stage?", 4) as bar:  # each moves only when the chi-square sits high
        field = verdict.looser_stage_line(ident, lambda i, n, note: bar.update(i - bar.done, note))
    with Progress("a field the stage carries?", 4) as bar:
        field = field or verdict.field_line(ident, lambda i, n, note: bar.update(i - bar.done, note))
    # a cause every row shares first: under it, the rows that stand out may not
    notes = field + verdict.outlier_lines(ident, args.capture) + verdict.low_residual_line(ident, source)
    print("".join(f"identify: {ln}\n" for ln in notes), end="", file=sys.stderr)
    return 0


def _at_t0(ds, path: str, capture: str):
    """``ds``'s readings mapped to temperature compensation ``path``'s t0 from the temperature its capture recorded,
    and the unit file's record of it: the twin is then the unit at t0, as a readout with the compensation sees it."""
    from dataclasses import replace

    import numpy as np

    from fitgen.physics.dataset import thermistor_degc
    from host.temperature import load_tempcomp

    tc = load_tempcomp(path)
    degc = thermistor_degc(ds.meta)
    if degc is None:
        raise InputError(f"--temp-comp {path}: {capture} records no temperature (thermistor_degc: its channel map "
                         "had no thermistor, temp= in --adc), so there is nothing to compensate from")
    if ds.meta.get("units", "V") != "V" or tc.n != ds.n_inputs:
        raise InputError(f"--temp-comp {path} compensates {tc.n} elements in V; {capture} has {ds.n_inputs} in "
                         f"{ds.meta.get('units')}")
    out = replace(ds, inputs=tc.apply(ds.inputs, np.full(ds.n_rows, degc)))
    return out, {"capture_degc": tc.t0, "compensated_from_degc": degc}


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
    noise = drawing.noise if args.noise is None else noise_of(args.noise, drawing)
    if not args.samples.lower().endswith(".json"):
        return parse_positive(args.samples, "--samples", integer=True), noise, {}
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
    from fitgen.fitting.schedule import schedule, write_schedule
    from fitgen.physics.simulate import parse_ranges

    drawing = sensor_of(args)
    axes = tuple(a.strip() for a in args.axes.split(",") if a.strip())
    samples, noise, told = samples_of(args, drawing)

    def step(done, total, note):
        bar.total = total
        bar.update(done - bar.done, note)

    with Progress("schedule", args.n) as bar:
        poses, info = schedule(drawing, args.n, axes=axes, ranges=parse_ranges(args.limits, {}),
                               noise=noise / np.sqrt(samples), rig_error=args.rig_error, progress=step)
    # the drawing's file and hash: capture passes them on, and identify takes that drawing unless told
    own = {"sensor_file": str(Path(args.sensor).resolve())} if Path(args.sensor).is_file() else {}
    write_schedule(args.output, poses, axes, {**info, "samples_per_row": samples, **told, **own,
                                              "sensor_sha256": drawing.sha256, "transfer": drawing.transfer})
    rest = (f"; {info['rest_rows']} at rest, lifted {info['rest_lift_mm']:g} mm off the skin" if info["rest_rows"]
            else "")
    if told:
        print(f"made for {samples} samples per row (told by {args.samples}) and {noise:.3g} {drawing.units} rms per "
              "sample", file=sys.stderr)
    print(f"wrote {len(poses)} poses ({info['distinct_poses']} distinct, {','.join(axes)}{rest}) to {args.output}",
          file=sys.stderr)
    box = ", ".join(f"{a} {lo:g}..{hi:g}" for a, (lo, hi) in info["ranges"].items())
    left = (f"; {info['beyond_linear_range']} of its grid poses left out, past {100 * info['linear_share']:g} % of an "
            "element's linear range" if info["beyond_linear_range"] else "")
    print(f"within {box} mm from first contact (the sensor's travel within --limits{left}): give the stage "
          "room for them and their approach (--stage-limits)", file=sys.stderr)
    return 0
