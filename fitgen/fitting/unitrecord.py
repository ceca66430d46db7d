"""What identify tells and keeps (fitgen.fitting.identify finds it): the identification in words, the unit file with
its posterior record, and what it reads from a capture's meta (the rows' noise, the units). What it says of the
capture itself, the rows that stand out and the refusals, is fitgen.fitting.verdict's."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from fitgen.base.errors import InputError, is_finite_number
from fitgen.fitting.capturecheck import MAX_STAGE_ERROR, MIN_DISTINCT, MIN_ROWS, distinct_poses, is_stage_error
from fitgen.fitting.capturezero import zero_found, zero_line
from fitgen.fitting.identify import PINNABLE, RIG, RIG_ERROR, ZERO_ERROR, Identification, tilting
from fitgen.physics.dataset import row_degc, thermistor_degc
from fitgen.physics.pose import POSE_NAMES, REST_LIFT_MM, box_problem, off_skin
from fitgen.physics.sensor import Sensor, preset_names
from fitgen.physics.simulate import recorded_spec, sensor_record_problem
from fitgen.physics.units import STIFFENING, UnitSpace

SPAN_NOTE_DEGC = 0.5  # a capture's rows this far apart in temperature: identify says so
MORE_SAMPLES = 8  # identify's report: what rows of this many times the samples would pin (16 -> 128)


def describe_direction(space: UnitSpace, v: np.ndarray, top: int = 4) -> str:
    """A direction in prior spreads as its largest components: '0.71 magnet.log_polarization - 0.70 e1.log_gain'."""
    order = np.argsort(np.abs(v))[::-1][:top]
    scale = np.abs(v[order[0]])
    parts = [f"{v[i] / scale:+.2f} {space.names[i]}" for i in order if abs(v[i]) >= 0.1 * scale]
    return " ".join(parts).lstrip("+")


def report(ident: Identification, samples: int | None = None) -> str:
    """The identification in words and tables: fit, parameters, what was determined and what was not;
    ``samples``: the capture's samples per row, when its meta says."""
    sp = ident.space
    n, N = ident.problem.readings.shape
    lines = [f"identify: {n} rows x {N} elements; residual chi-square {ident.chi2:.1f} on {ident.dof:.1f} degrees of "
             f"freedom (reduced {ident.reduced_chi2:.2f}; 1 when the physics explains the rows to the noise)"]
    rest = int(np.sum(off_skin(ident.problem.poses)))
    hint = f"; a row with the stage lifted {REST_LIFT_MM:g} mm (fitgen schedule adds it) pins the rest readings"
    lines.append(f"rows off the skin (the magnet at rest, free of the rig's error): {rest}" + ("" if rest else hint))
    if ident.zero is not None:
        lines.append(zero_line(*ident.zero))
    if STIFFENING not in sp.names and np.any(ident.problem.poses[:, 2] < 0):
        # it hides: the unit's other parameters bend to it and the chi-square barely moves (bench/stiffening.py)
        lines.append("the magnet is taken to follow the stage linearly (the drawing's [tolerances] stiffening is 0): "
                     "an elastomer that stiffens as it is pressed would put the magnet's height off without raising "
                     "the chi-square; give the drawing stiffening = 0.01 unless the elastomer is known to be linear "
                     "over the travel (docs/calibration.md)")
    lines.append("")
    lines.append("| what the capture determines | value | standard error |")
    lines.append("| --- | --- | --- |")
    for name, (val, se) in ident.derived().items():
        lines.append(f"| {name} | {val:.5g} | {se:.2g} |")
    lines += [""] + what_pins_more(ident, samples)
    sd, prior = ident.sd, sp.prior_sd
    lines += ["", "| parameter | value | standard error | prior spread | share of the prior left |", "| --- | --- | --- | --- | --- |"]
    share = sp.in_spreads(sd)
    for i, name in enumerate(sp.names):
        left = f"{share[i]:.2f}" if sp.free[i] else "fixed"
        lines.append(f"| {name} | {ident.theta[i]:.4g} | {sd[i]:.2g} | {prior[i]:.2g} | {left} |")
    det, free = int(np.sum(ident.info_eig >= 1.0)), int(np.sum(sp.free))
    lines += ["", f"determined by the capture (information >= the prior's): {det} of {free} directions; "
                  f"left to the prior: {free - det}"]
    if free < sp.size:
        lines.append(f"fixed at the drawing (spread 0 in the sensor file's [tolerances]): {sp.size - free} parameters")
    g = ident.gauge.shape[1]
    every = "every pose" if tilting(ident.problem.poses) else "every three-axis pose"
    lines.append(f"no capture can separate ({g} directions: the same readings at {every}; the unit file takes the "
                 "prior's split):")
    for v in ident.gauge.T:
        lines.append(f"  {describe_direction(sp, v)}")
    if ident.starved:
        # the dense design moves dx, dy and dz (and tilts where the capture does): said so where this one does not
        unmoved = [n for j, n in enumerate(POSE_NAMES[:3]) if np.ptp(ident.problem.poses[:, j]) == 0]
        lines.append("this capture leaves to the prior (a dense capture over dx, dy and dz would not" +
                     (f"; this one does not move {' or '.join(unmoved)}, which the poses below do" if unmoved else "")
                     + "):")
        for v, poses, gain in ident.starved:
            where = "; ".join(pose_words(ident, p) for p in poses)
            lines.append(f"  {describe_direction(sp, v)}: poses that pin it: {where}")
    # the rest of what is left to the prior: directions no one pose pins, which rows add up to (the count adds up)
    rest = free - det - g - len(ident.starved)
    if rest > 0:
        lines.append(f"{'and ' if ident.starved else 'this capture leaves '}{rest} more direction{'s' * (rest > 1)} to "
                     "the prior that no one pose of a capture over the same axes pins: more rows, or more samples per "
                     "row, add to what it knows of them")
    elif not ident.starved:
        lines.append("this capture leaves nothing else to the prior that a capture over the same axes could pin")
    return "\n".join(lines) + "\n"


def what_pins_more(ident: Identification, samples: int | None = None) -> list[str]:
    """A table: the standard errors of what the capture determines had one part of the unit (or where the stage
    was) been known exactly, beside this capture's: what a maker would gain by measuring it; then what rows of
    MORE_SAMPLES times the ``samples`` per row would pin."""
    prob = ident.problem
    rows = [("nothing more (this capture)", ident.cov)]
    for words, part in PINNABLE:
        if part == RIG and prob.rig_error == 0 and prob.zero_error == 0:
            continue  # the capture already took its stage as exact
        try:
            rows.append((words, ident.pinned(part)))
        except ValueError:
            continue  # fixed at the drawing already (spread 0)
    lines = ["| standard error, had this been known exactly | offset x [mm] | offset y [mm] | offset z [mm] | "
             "sensitivity, worst element |", "| --- | --- | --- | --- | --- |"]
    for words, cov in rows:
        *offset, worst = _offsets_worst(ident, cov)
        lines.append(f"| {words} | " + " | ".join(f"{se:.2g}" for se in offset) + f" | {100 * worst:.2g} % |")
    # the rig's error binds three of a row's directions; averaging lowers the noise along the rest
    more = _offsets_worst(ident, ident.posterior_for(replace(prob, noise=prob.noise / np.sqrt(MORE_SAMPLES))))
    rows = f"{MORE_SAMPLES * samples} samples instead of {samples}" if samples else f"{MORE_SAMPLES}x the samples"
    lines.append(f"the same poses, rows of {rows} (if the noise averages down that far: "
                 f"tactile-host noise tells; docs/calibration.md): offset {more[0]:.2g} / {more[1]:.2g} / "
                 f"{more[2]:.2g} mm, worst element {100 * more[3]:.2g} %")
    return lines


def _offsets_worst(ident: Identification, cov: np.ndarray) -> tuple[float, float, float, float]:
    """The standard errors of the magnet's offset (x, y, z) and of the worst element's relative sensitivity."""
    d = list(ident.derived(cov).values())
    return d[0][1], d[1][1], d[2][1], max(se / val for val, se in d[3:])


# --- captures and files ---------------------------------------------------------------------------

ROW_NOISE_KEY = "row_noise"  # a capture's meta: per element, the measured noise of its averaged rows
SAMPLES_KEY = "samples_per_row"
SAMPLE_NOISE_KEY = "sample_noise"  # a capture's meta: per element, one sample's measured noise
SIMULATED_NOISE_KEY = "noise"  # fitgen simulate's meta: the noise each row was made with, as fitgen fit reads it


def samples_per_row(meta: dict) -> int | None:
    """The samples a capture averaged per row, when its meta says (a whole number >= 1)."""
    samples = meta.get(SAMPLES_KEY)
    return samples if isinstance(samples, int) and samples >= 1 else None


def _measured(meta: dict, key: str, n: int) -> list[float] | None:
    """A capture's per-element noise figures under ``key``, when its meta holds ``n`` finite ones > 0."""
    values = meta.get(key)
    ok = isinstance(values, list) and len(values) == n and all(
        isinstance(x, (int, float)) and not isinstance(x, bool) and np.isfinite(x) and x > 0 for x in values)
    return values if ok else None


def row_noise(meta: dict, sensor: Sensor, noise: float | None = None,
              option: str = "--noise") -> tuple[np.ndarray, str]:
    """The reading noise of a capture's rows, per element, and where it came from: ``noise`` (the device's
    single-sample noise) over sqrt(samples per row), else the noise the capture measured, else the noise a
    simulated capture was made with (``fitgen simulate --noise``), else the sensor file's over sqrt(samples).
    ``option``: the command's option that gives ``noise``, for the words ('': it has none)."""
    n = sensor.n_elements
    samples = samples_per_row(meta) or 1
    # a capture without its meta (a rig's own logger): rows averaged over 16 would be weighed 4x too loosely
    told = f": {option} takes the rows' own" if option else ""
    over = f"over sqrt({samples}) samples" + ("" if samples_per_row(meta) else
                                              f" (no meta names the samples per row{told})")
    if noise is not None:
        return np.full(n, noise / np.sqrt(samples)), f"--noise {noise:g} {over}"
    units = f" {meta['units']}" if isinstance(meta.get("units"), str) else ""
    measured = _measured(meta, ROW_NOISE_KEY, n)
    if measured is not None:
        return (np.asarray(measured, dtype=float),
                f"measured by the capture (median over the elements {np.median(measured):.3g}{units})")
    simulated = meta.get(SIMULATED_NOISE_KEY)
    if (isinstance(simulated, (int, float)) and not isinstance(simulated, bool) and np.isfinite(simulated)
            and simulated > 0):  # noise-free rows fall through: identify weighs rows by a noise > 0
        return np.full(n, float(simulated)), f"the noise the rows were simulated with ({simulated:g}{units})"
    return (np.full(n, sensor.noise / np.sqrt(samples)),
            f"sensor {sensor.name}'s {sensor.noise:g} {over}")


def device_noise(meta: dict, sensor: Sensor, noise: float | None = None) -> tuple[float, str]:
    """The unit's single-sample reading noise in ``sensor``'s units, and where it came from: ``noise`` (the
    device's, given), else what the capture measured (the rms over the elements of one sample's spread,
    ``sample_noise`` in its meta), else the drawing's."""
    if noise is not None:
        return float(noise), "--noise"
    measured = _measured(meta, SAMPLE_NOISE_KEY, sensor.n_elements)
    if measured is not None:
        return float(np.sqrt(np.mean(np.square(measured)))), "measured by the capture"
    return sensor.noise, f"the drawing {sensor.name}'s"


def drawing_for(given: str | None, meta: dict, capture="the capture") -> tuple[str, str]:
    """The drawing identify takes for a capture with ``meta`` (``given``: --sensor, else the one its schedule was
    made for, as `fitgen schedule` recorded it and `tactile-host capture` passed it on, where its file is here
    unchanged; else paper), and a line saying so where that is not plain (else '')."""
    made = meta.get("schedule_drawing")
    if given is None and isinstance(made, dict) and (problem := sensor_record_problem(made)):  # not: file changed
        raise InputError(f"{capture}'s meta: schedule_drawing.{problem}; repair it, or give --sensor")
    recorded = recorded_spec(made)
    if given is not None:
        if recorded is not None and Path(given).name != Path(recorded).name:
            return given, f"note: the capture's schedule was made for {recorded}; identifying against --sensor {given}"
        return given, ""
    if recorded is not None:
        return recorded, ("" if recorded == "paper" else
                          f"the drawing: {recorded}, as the capture's schedule names it (--sensor to say another)")
    if isinstance(made, dict) and made.get("sensor") in preset_names() and "sensor_file" not in made:
        # the preset itself, as another fitgen drew it (a file of a preset's name is refused as any other file)
        return made["sensor"], (f"note: the capture's schedule was made for preset {made['sensor']} as another fitgen "
                                f"drew it; identifying against this one's (--sensor to say which)")
    if made == {}:  # emptied: nothing names a drawing, moved or not
        raise InputError(f"{capture}'s meta: schedule_drawing is empty (no sensor named); repair it, or give --sensor")
    if isinstance(made, dict):  # identified against another drawing, a unit would be as far off as the drawings
        where = f" ({made['sensor_file']})" if isinstance(made.get("sensor_file"), str) else ""
        raise InputError(f"the capture's schedule was made for sensor {made.get('sensor')}{where}, whose file is not "
                         "here as it was (moved without the capture, or changed since): give the drawing the unit was "
                         "built to as --sensor; nothing written")
    return "paper", ""


def schedule_stage(meta: dict) -> dict:
    """The stage a capture's schedule was made for, as `tactile-host capture` copies it into the meta
    (``schedule_stage``: rig_error, zero_error, rig_error_given); {} where it records none."""
    made = meta.get("schedule_stage")
    return made if isinstance(made, dict) else {}


def stage_errors(rig: float | None, zero: float | None, meta: dict, capture) -> tuple[float, float, str]:
    """The rig's and the zero's error identify takes for a capture with ``meta`` (mm rms per axis): ``rig`` and
    ``zero`` (--rig-error, --zero-error) where given, else those its schedule was made for (`fitgen schedule`
    recorded them, `tactile-host capture` passed them on as ``schedule_stage``), else RIG_ERROR and ZERO_ERROR; and
    where they came from, for the report. InputError naming ``capture``'s meta for a recorded one identify
    refuses (fitgen.fitting.capturecheck.check_error)."""
    made = schedule_stage(meta)
    out, recorded = [], []
    for value, key, flag, default in ((rig, "rig_error", "--rig-error", RIG_ERROR),
                                      (zero, "zero_error", "--zero-error", ZERO_ERROR)):
        if value is None and key in made:
            value = made[key]
            if not is_stage_error(value):
                raise InputError(f"{capture}'s meta: schedule_stage.{key} must be 0..{MAX_STAGE_ERROR:g} mm, got "
                                 f"{value!r}; repair it, or give {flag}")
            recorded.append(key.replace("_", " "))
        out.append(float(default if value is None else value))
    return out[0], out[1], (f" ({' and '.join(recorded)} as the capture's schedule was made for)" if recorded else "")


def stage_reach(meta: dict, capture) -> dict | None:
    """Where the stage that took a capture can set a pose ({pose name: (low, high)}, mm), as its meta records it:
    the box its schedule was made in (``schedule_stage.ranges``: the limits and travel `fitgen schedule` took) and
    the limits `tactile-host capture --stage` moved within, less the approach on its side; None where it records
    neither. InputError naming ``capture``'s meta for a record that is no pose box."""
    made, st = schedule_stage(meta), meta.get("stage") if isinstance(meta.get("stage"), dict) else {}
    reach: dict = {}
    for where, box, approach in (("schedule_stage.ranges", made.get("ranges"), {}),
                                 ("stage.limits_mm", st.get("limits_mm"), st.get("approach_mm"))):
        if box is None:
            continue
        if problem := box_problem(box):
            raise InputError(f"{capture}'s meta: {where} {problem}; repair it")
        approach = approach if isinstance(approach, dict) else {}
        for name, (lo, hi) in box.items():
            a = approach[name] if is_finite_number(approach.get(name)) else 0.0
            lo, hi = lo - min(a, 0.0), hi - max(a, 0.0)  # the last move starts at pose + approach
            was = reach.get(name, (lo, hi))
            reach[name] = (max(lo, was[0]), min(hi, was[1]))
    return reach or None


def in_capture_units(drawing: Sensor, meta: dict) -> Sensor:
    """``drawing`` in the transfer of the units a capture's meta names (V: gmr, mT: raw), else as it is."""
    units = meta.get("units")
    return drawing.with_transfer("gmr" if units == "V" else "raw") if units in ("V", "mT") else drawing


def check_transfer(transfer: str | None, meta: dict, capture) -> None:
    """InputError when ``--transfer`` contradicts the units a capture's meta names."""
    units = meta.get("units")
    if transfer is not None and units in ("V", "mT") and units != ("V" if transfer == "gmr" else "mT"):
        raise InputError(f"--transfer {transfer} reads {'V' if transfer == 'gmr' else 'mT'}, but {capture}'s meta says "
                         f"its readings are in {units}")


def units_hint(drawing: Sensor, readings: np.ndarray, poses: np.ndarray, meta: dict) -> str:
    """When a capture's meta does not give its units: '' if its readings fit the drawing best in the units they
    were read in, else the refusal's first cause, naming the other transfer (mT and V differ by a scale and the rails only, so the
    residual of the drawing in each, not the readings' size, tells them apart)."""
    from fitgen.physics.transfer import readings as drawn

    if meta.get("units") in ("V", "mT"):
        return ""
    other = drawing.with_transfer("raw" if drawing.transfer == "gmr" else "gmr")
    off = [float(np.sqrt(np.mean((readings - drawn(s, poses, adc_bits=0)) ** 2))) for s in (drawing, other)]
    if not off[1] * 2 < off[0]:
        return ""
    return (f"the capture's meta does not give its units (is its .meta.json, which also records the noise it "
            f"measured, left behind?): read as {drawing.units} they fit the drawing {off[0] / max(off[1], 1e-300):.3g}x "
            f"worse than as {other.units}: give --transfer {other.transfer}")


def pose_words(ident: Identification, pose: np.ndarray) -> str:
    """``dx=.. dy=.. dz=..``, and the tilts when the capture tilts."""
    return " ".join(f"{c}={v:g}" for c, v in zip(POSE_NAMES[:5 if tilting(ident.problem.poses) else 3], pose))



def capture_temperature(meta: dict, rows: int) -> dict:
    """``{"capture_degc": T}`` when a capture's meta holds its thermistor's readings (tactile-host capture with a
    temp= input): the median of its ``rows`` rows' where it records each's, else the one read as it started;
    else {}. The unit's readings are of that temperature, which a temperature compensation's t0 should be
    (host.temperature.capture_temperature_note)."""
    each = row_degc(meta, rows)
    t = round(float(np.median(each)), 4) if each is not None else thermistor_degc(meta)
    return {} if t is None else {"capture_degc": t}


def check_capture_line(meta: dict, capture) -> str:
    """A note when ``capture`` was taken on a check schedule (its meta's ``schedule_check``), else '': identified
    from, its rows could no longer check the twin."""
    if meta.get("schedule_check") is not True:
        return ""
    return (f"note: {capture} was captured on a check schedule (fitgen schedule --check): poses for fitgen check, at "
            "random in the working box with no rest row; a calibration captures fitgen schedule's poses, and a twin "
            "identified from these rows cannot be checked on them")


def unfinished_line(meta: dict, rows: int, capture, poses=None) -> str:
    """A note when ``capture`` holds fewer than the ``schedule_poses`` its meta records (`tactile-host capture`
    stopped early), or more, else ''; InputError saying so when it holds fewer rows than identify takes; '' where
    its ``poses`` are too few for identify, whose refusal says so alone (a refusal is one line)."""
    total = meta.get("schedule_poses")
    if type(total) is not int or rows == total:
        return ""
    stopped = (f"{capture} holds {rows} of the {total} poses of its schedule (its capture stopped early: the same "
               "capture command run again takes the rest)")
    if rows < min(total, MIN_ROWS):  # said as what it is, not after a note as a capture too short
        raise InputError(f"{stopped}; identify needs at least {MIN_ROWS} rows")
    if poses is not None and distinct_poses(poses) < MIN_DISTINCT:
        return ""
    if rows > total:  # no copies (load_capture): captures joined, or rows added by hand
        return (f"note: {capture} holds {rows} rows, more than the {total} poses of its schedule (a capture writes "
                "each once): identify takes every row as a measurement of its own")
    return (f"note: {stopped}; identified from these, the unit is known less well than the schedule was made for "
            "(its standard errors are wider)")


def temperature_span_line(meta: dict, rows: int) -> str:
    """A note when a capture's ``rows`` rows were read SPAN_NOTE_DEGC or more apart in temperature (its meta's
    ``row_degc``), else ''."""
    each = row_degc(meta, rows)
    if each is None or each.max() - each.min() < SPAN_NOTE_DEGC:
        return ""
    return (f"note: the capture's rows were read from {each.min():.2f} to {each.max():.2f} degC, and its elements' "
            "offsets and gains drift with temperature, which the unit's physics does not model: --temp-comp TC.json "
            "(tactile-host capture --temperature fits one) takes each row from its own temperature to the "
            "compensation's t0")


def save(ident: Identification, path, provenance: dict, noise: float | None = None) -> tuple:
    """Write the unit file (the maximum a posteriori unit) and beside it ``<stem>.posterior.json``: every
    parameter with its standard error, the posterior covariance, what was determined and what not.
    ``provenance``: strings recorded in both (``capture``: the capture's file, whose hash the record keeps
    unless ``capture_sha256`` gives it)."""
    from fitgen.base.fileio import write_all

    files = unit_files(ident, path, provenance, noise)  # together: the unit file names its posterior's hash
    unit, post_path = write_all(files)
    return unit, post_path


def posterior_beside(unit_file) -> Path:
    """Where identify writes the posterior of the unit file ``unit_file``: beside the file itself, not a link."""
    from fitgen.base.fileio import real_file
    from fitgen.physics.units import beside_as

    return beside_as(real_file(unit_file), ".toml", ".posterior.json")


def unit_files(ident: Identification, path, provenance: dict, noise: float | None = None) -> list:
    """What :func:`save` writes, not written: ``[(path, the unit file's text), (<stem>.posterior.json, its text)]``;
    ``noise``: the unit's single-sample reading noise (:func:`device_noise`), else the drawing's."""
    import json
    from pathlib import Path

    from fitgen.base.texts import tomllib
    from fitgen.physics.sensor import parse_sensor
    from fitgen.physics.units import unit_toml

    path = Path(path)
    post_path = posterior_beside(path)
    spec = provenance.get("drawing_spec")
    if spec is not None and Path(spec).is_file():  # a sensor file: named so that it is found from anywhere
        provenance = {**provenance, "drawing_spec": str(Path(spec).resolve())}
    capture = provenance.get("capture")
    if capture is not None and "capture_sha256" not in provenance and Path(capture).is_file():
        # what `fitgen check` knows the capture by, to refuse it as a check of its own identification
        from fitgen.physics.dataset import load_dataset

        provenance = {**provenance, "capture_sha256": load_dataset(capture).sha256}
    unit = ident.unit(provenance.get("name", path.stem), f"identified from {provenance.get('capture', 'a capture')}")
    if noise is not None:  # the twin is simulated and fitted for the unit's own noise, not the drawing's
        unit = unit.with_noise(noise)
    prov = {"source": "fitgen identify", "posterior": post_path.name, "reduced_chi2": round(ident.reduced_chi2, 4),
            **{k: v for k, v in provenance.items() if isinstance(v, (str, int, float)) and k != "name"}}
    text = unit_toml(unit, ident.space.drawing.name, prov)
    record = {
        # the unit as its file reads back: a posterior beside another unit's file, or a unit edited by hand, is
        # refused (load_posterior) rather than widening figures with another unit's uncertainty
        "unit_sha256": parse_sensor(tomllib.loads(text), str(path)).sha256,
        "drawing": ident.space.drawing.name, "drawing_sha256": ident.space.drawing.sha256,
        "drawing_spec": provenance.get("drawing_spec", ident.space.drawing.name),
        "parameters": ident.space.names, "theta": ident.theta.tolist(), "sd": ident.sd.tolist(),
        "prior_sd": ident.space.prior_sd.tolist(), "covariance": ident.cov.tolist(),
        "chi2": ident.chi2, "dof": ident.dof, "rows": int(ident.problem.readings.shape[0]),
        "rig_error": ident.problem.rig_error, "zero_error": ident.problem.zero_error,
        # where the capture's zero sat from first contact: what a check capture that reuses it is off by
        **({"zero_found": {"mm": ident.zero[0].tolist(), "covariance": ident.zero[1].tolist()}} if ident.zero else {}),
        # rows labelled in contact that read at rest, taken as lifted off the skin (numbered as in the capture)
        **({"rows_taken_lifted": [i + 1 for i in ident.problem.lifted], "zero_lift": ident.problem.zero_lift}
           if ident.problem.lifted else {}),
        # readings a looser stage's unit put by a knee, held out by identify's last start ([row, element], from 1)
        **({"readings_held_out": (np.argwhere(ident.problem.held) + 1).tolist()}
           if ident.problem.held is not None else {}),
        "row_noise": ident.problem.noise.tolist(),
        "outlying_rows": [{"row": i + 1, "residual": r} for i, r in ident.outlying_rows()],
        "derived": {k: {"value": v, "se": s} for k, (v, s) in ident.derived().items()},
        "determined_directions": int(np.sum(ident.info_eig >= 1.0)),
        "no_capture_separates": [describe_direction(ident.space, v) for v in ident.gauge.T],
        "capture_starves": [{"direction": describe_direction(ident.space, v),
                             "poses": p[:, :5 if tilting(ident.problem.poses) else 3].tolist()}
                            for v, p, _ in ident.starved],
        **{k: v for k, v in provenance.items() if k != "name"}}
    return [(path, text), (post_path, json.dumps(record, indent=1) + "\n")]


def load_posterior(unit_path) -> dict | None:
    """The posterior record an identified unit file names (``[unit] posterior``), or None; InputError when
    it cannot be read or was written for another unit (another identification's, or the unit file edited)."""
    import json
    from pathlib import Path

    from fitgen.base.fileio import read_text, real_file
    from fitgen.base.texts import tomllib
    from fitgen.physics.relocate import relocated
    from fitgen.physics.sensor import load_sensor

    unit_path = Path(unit_path)
    try:
        doc = tomllib.loads(read_text(unit_path, "unit file"))
    except (InputError, ValueError):
        return None
    name = doc.get("unit", {}).get("posterior") if isinstance(doc.get("unit"), dict) else None
    if not isinstance(name, str):
        return None
    todo = "identify again, or delete the [unit] posterior line to use the unit without its uncertainty"
    path = real_file(unit_path).parent / name
    try:
        rec = json.loads(read_text(path, "posterior"))
    except (InputError, ValueError):
        why = "is missing" if not path.exists() else "cannot be read"
        raise InputError(f"unit file {unit_path}: its posterior {name} {why} (identify writes it beside the unit "
                         f"file): {todo}") from None
    if not (isinstance(rec, dict) and isinstance(rec.get("theta"), list) and isinstance(rec.get("covariance"), list)
            and isinstance(rec.get("drawing_spec"), str)  # and what check reads: of another type, it had read as none
            and isinstance(rec.get("capture_zero", {}), dict) and isinstance(rec.get("capture_sha256", ""), str)
            and _zero_found_ok(rec)):
        raise InputError(f"unit file {unit_path}: its posterior {name} is malformed (expected fitgen identify's): "
                         f"{todo}")
    if not isinstance(rec.get("unit_sha256"), str):  # identify always writes it: without it no unit is checked
        raise InputError(f"unit file {unit_path}: its posterior {name} does not name the unit it was written for "
                         f"(unit_sha256; expected fitgen identify's): {todo}")
    if rec["unit_sha256"] != load_sensor(unit_path).sha256:
        raise InputError(f"unit file {unit_path}: its posterior {name} was written for another unit (another "
                         f"identification's, or the unit file was edited since): {todo}")
    return relocated(rec, path.parent, "drawing_spec", "drawing_sha256")  # a drawing's file moved with the unit's


def _zero_found_ok(rec: dict) -> bool:
    """Whether a posterior record's ``zero_found``, if any, is identify's."""
    try:
        zero_found(rec, "")
    except InputError:
        return False
    return True
