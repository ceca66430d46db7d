"""A check capture: what a model delivers on a unit at stage poses never used to calibrate it, against what the
unit's identification predicts at those very poses. The prediction reads units drawn from the twin's posterior
(the model's own sensor alone when it has none) at the capture's labels moved by the stage's error, with the rows'
own reading noise, and estimates them as the device does: both sides carry the same errors, so a twin that does
not describe the unit (a knock, a slip of the sensor on the bed, another unit's file) stands out, and one that
does reads within the spread of the draws."""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from fitgen.base.errors import InputError, shown
from fitgen.equations.model import Model, check_input_units
from fitgen.fitting.capturecheck import MAX_STAGE_ERROR, check_error, element_noise
from fitgen.fitting.holdout import POSTERIOR_UNITS, device_precision, estimator, posterior_units, unit_posterior
from fitgen.fitting.identify import RIG_ERROR, ZERO_ERROR
from fitgen.fitting.capturezero import stage_zero, zero_found, zero_record, zero_words
from fitgen.fitting.unitrecord import row_noise, schedule_stage
from fitgen.physics.pose import POSE_NAMES, check_rows, edge_margin, inner_box, off_skin, within_box
from fitgen.physics.simulate import rig_poses
from fitgen.physics.transfer import readings, sensor_hashes

DRAWS = 5  # the stage's error and the rows' noise drawn this many times per unit
SEED = 2031
FIGURES = ("max", "rms")
TOO_FAR = 1.5  # a measured max or RMS this many times the greatest drawn one: the twin does not describe the unit
NO_BOX = ("the model has no held-out record (a fit with --held-out 0, or straight on a capture without --sensor), "
          "so it names no pose box it was fitted in, and a check cannot tell where it makes a claim")
SAME_ZERO = 0.005  # mm: machine coordinates this close are one zero (a zero copied as printed keeps 6 digits)


@dataclass
class Check:
    """The errors a model made on a check capture (``measured``) and the same figures predicted there (``drawn``:
    one per unit and draw), per output: max and rms of estimate - label over the rows in contact."""

    outputs: tuple[str, ...]
    rows: int
    precision: str
    measured: dict
    drawn: dict  # output -> figure -> (units * DRAWS,) array
    units: int
    draws: int
    rig_error: float
    identified: bool  # the units were drawn from an identification's posterior (else the model's sensor alone)
    zero_error: float = 0.0  # mm rms per axis: the check capture's zero off the calibration's, one draw per draw
    zero_said: str = ""  # why that zero error (fitgen check's line)
    rig_said: str = ""  # where the rig error came from (fitgen check's line)
    outside: int = 0  # rows in contact left out: outside the pose box the model was fitted in, or near its edge
    margin: float = 0.0  # mm: how far inside that box's edges a row must lie (fitgen.physics.pose.inner_box)

    def predicted(self, output: str, figure: str) -> tuple[float, float, float]:
        """The median, least and greatest of the drawn ``figure`` of ``output``."""
        v = self.drawn[output][figure]
        return float(np.median(v)), float(v.min()), float(v.max())

    def beyond(self, output: str, figure: str = "max") -> float:
        """The measured figure over the greatest drawn one: above 1, no draw erred as much."""
        return self.measured[output][figure] / max(self.predicted(output, figure)[2], 1e-300)

    def worst(self, output: str) -> tuple[str, float]:
        """The figure of ``output`` that lies farthest beyond its draws', and how far (:meth:`beyond`)."""
        return max(((f, self.beyond(output, f)) for f in FIGURES), key=lambda fb: fb[1])

    def failed(self) -> list[str]:
        """The outputs whose measured max or RMS lies TOO_FAR beyond every draw's: the max catches a row that errs
        alone, the RMS an error every row shares (a zero or a sensor moved), which a few rows' stage errors hide
        in the max."""
        return [o for o in self.outputs if self.worst(o)[1] > TOO_FAR]


def _figures(err: np.ndarray) -> dict:
    return {"max": np.abs(err).max(axis=0), "rms": np.sqrt(np.mean(err ** 2, axis=0))}


def check(model: Model, inputs: np.ndarray, labels: np.ndarray, sensor, row_noise, *, posterior: dict | None = None,
          rig_error: float = RIG_ERROR, zero_error: float = 0.0, zero: np.ndarray | None = None,
          precision: str = "float", units: int = POSTERIOR_UNITS, draws: int = DRAWS, seed: int = SEED) -> Check:
    """:class:`Check` of ``model`` on a capture's ``inputs`` (n, N) at stage ``labels`` (n, 5), the rows' reading
    noise ``row_noise`` (per element or one number): predicted on ``units`` units drawn from ``posterior`` (an
    identified unit's record) or on ``sensor`` alone, each read ``draws`` times at the labels moved by ``rig_error``
    (mm rms per axis) and by one ``zero_error`` draw shared by its rows (mm rms per axis: a zero set anew, or the
    error of ``zero``), with that noise, estimated in ``precision``. ``zero`` (mm, 3): where the capture's zero sat
    from first contact, where known (the calibration's, reused, as identify found it): the rows in contact stand at
    their labels plus it, and are judged there. Rows off the skin are left out, and so are rows (by their labels)
    outside the pose box the model was fitted in (its held-out record's), where it makes no claim, or so near its
    edge that the stage's errors may carry them out (fitgen.physics.pose.inner_box): a model errs fast past its box,
    and one draw that carried a row there would set the greatest predicted error for the whole check."""
    check_error("rig error", rig_error)
    check_error("zero error", zero_error)
    # a sensor in other units reads the draws through the model wrongly, and wide draws pass any capture
    check_input_units(model, sensor.units, f"sensor {sensor.name}'s readings ({sensor.transfer} transfer)")
    inputs, labels = check_rows(inputs, labels, "the check capture")
    noise = element_noise(row_noise, inputs.shape[1], "the rows' reading noise", positive=False)
    keep = ~off_skin(labels)
    inputs, labels = inputs[keep], labels[keep]
    if not len(labels):
        raise InputError("every row of the check capture is lifted off the skin: no contact pose to check")
    if not model.pose_box:  # every row would count as inside, where a model errs by millimetres "as predicted"
        raise InputError(NO_BOX)
    box = inner_box(model.pose_box, rig_error, zero_error)
    inside = within_box(labels, box)
    margin = edge_margin(rig_error, zero_error)
    if not inside.any():
        raise InputError(f"none of the check capture's {len(labels)} rows in contact lies in the pose box the model "
                         f"was fitted in ({box_words(model.pose_box)}), {margin:.2g} mm inside its edges (the "
                         "stage's error): check it at fitgen schedule --check's poses")
    inputs, labels = inputs[inside], labels[inside].copy()
    if zero is not None:  # after the box, which holds a scene's held components at the labels' own values
        labels[:, :3] += zero
    fn = estimator(model, precision, sensor)
    if isinstance(fn, str):
        raise InputError(f"the model cannot run in {precision}: {fn}")
    outputs = tuple(o for o in model.output_names if o in POSE_NAMES)
    cols = [model.output_names.index(o) for o in outputs]
    truth = labels[:, [POSE_NAMES.index(o) for o in outputs]]
    measured = {o: {f: float(v[j]) for f, v in _figures(fn(inputs)[:, cols] - truth).items()}
                for j, o in enumerate(outputs)}
    pool = posterior_units(posterior, sensor, units) if posterior is not None else [sensor]
    rng = np.random.default_rng(seed)
    sims = []
    for unit in pool:
        for _ in range(draws):
            zero = rng.normal(0.0, zero_error, 3) if zero_error > 0 else None  # none drawn: the same stream as before
            y = readings(unit, rig_poses(labels, rig_error, rng, zero), adc_bits=0, noise=noise, rng=rng)
            sims.append(_figures(fn(y)[:, cols] - truth))
    drawn = {o: {f: np.array([s[f][j] for s in sims]) for f in FIGURES} for j, o in enumerate(outputs)}
    return Check(outputs, len(labels), precision, measured, drawn, len(pool), draws, float(rig_error),
                 posterior is not None, float(zero_error), outside=int(np.sum(~inside)), margin=margin)


def box_words(box: dict) -> str:
    return ", ".join(f"{k} {lo:g}" + (f"..{hi:g}" if hi != lo else " (held)") for k, (lo, hi) in box.items())


def _words(zero: dict) -> str:
    return " ".join(f"{k}{v:g}" for k, v in sorted(zero["machine_mm"].items()))


def _stage_error(value, where: str, flag: str = "--zero-error") -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 <= value <= MAX_STAGE_ERROR:
        raise InputError(f"{where} must be 0..{MAX_STAGE_ERROR:g} mm, got {shown(value)}; repair it, or give {flag}")
    return float(value)


def check_rig(posterior: dict | None, meta: dict, capture, unit_file) -> tuple[float, str]:
    """The rig error (mm rms per axis) a check capture with ``meta`` is predicted with, and where it came from: the
    one its schedule was made for where `fitgen schedule --check` was told it (``rig_error_given``, which
    `tactile-host capture` passes on in ``schedule_stage``), else the one the unit was identified with (its
    ``posterior``), else RIG_ERROR. A schedule's default says nothing of the stage, so it does not override the
    identification's."""
    made = schedule_stage(meta)
    if made.get("rig_error_given") is True and "rig_error" in made:
        return (_stage_error(made["rig_error"], f"{capture}'s meta: schedule_stage.rig_error", "--rig-error"),
                "as the check capture's schedule was made for")
    if posterior and "rig_error" in posterior:
        return (_stage_error(posterior["rig_error"], f"{unit_file}'s posterior: rig_error", "--rig-error"),
                "as the unit was identified with")
    return RIG_ERROR, "the default: neither the unit's file nor the check capture's schedule records one"


def check_zero(posterior: dict | None, meta: dict, capture) -> tuple[float, str, np.ndarray | None]:
    """The zero error (mm rms per axis) a check capture with ``meta`` is predicted with, why, and where its zero sat
    from first contact where known (mm, 3, else None). Its stage moved from the calibration capture's zero (the same
    machine coordinates on a homed machine, with the same axis map, which ``posterior`` records as ``capture_zero``,
    and each capture's rows from that one zero), or records no stage zero (said so): that zero, where identify
    found it (``zero_found``), and its standard error. From another zero, set by hand: that zero's own error (as
    its schedule was made for, else the calibration's) and the found zero's, in quadrature, the unit being read from
    first contact; the two zeros' errors for a posterior without ``zero_found``, whose unit may not be."""
    found = zero_found(posterior, "the unit's posterior:")
    mine = stage_zero(meta, capture)
    theirs = (posterior or {}).get("capture_zero")
    if mine is None or not isinstance(theirs, dict):
        which = ("the check capture records no stage zero" if mine is None else "the model's sensor has no "
                 "posterior: not a unit identify wrote" if posterior is None else "the unit's posterior records "
                 "no stage zero")
        return _reused(found, f"the calibration's zero taken as reused ({which}; give --zero-error 0.02 for a zero "
                              "set anew by hand)", posterior)
    zeros = {"check capture": mine["zeros"], "calibration capture": theirs.get("zeros", 1)}
    theirs = zero_record(theirs.get("machine_mm"), theirs.get("homed"), theirs.get("axes"),
                         "the unit's posterior (capture_zero; give --zero-error to check without it):")
    keys = set(mine["machine_mm"]) | set(theirs["machine_mm"])
    same = (mine["axes"] == theirs["axes"] and set(mine["machine_mm"]) == set(theirs["machine_mm"])
            and all(abs(mine["machine_mm"][k] - theirs["machine_mm"][k]) <= SAME_ZERO for k in keys))
    mixed = [f"the {which}'s rows were taken from {n} zeros" for which, n in zeros.items()
             if isinstance(n, int) and n > 1]
    if same and mine["homed"] and theirs["homed"] and not mixed:
        return _reused(found, f"the calibration's zero, reused ({_words(mine)} on a homed machine)", posterior)
    ours = _stage_error((posterior or {}).get("zero_error", ZERO_ERROR), "the unit's posterior: zero_error")
    made = schedule_stage(meta)
    new = _stage_error(made.get("zero_error", ours), f"{capture}'s meta: schedule_stage.zero_error")
    if mixed:  # a run set the zero again (a controller reset): some rows are from another zero
        why = f"{' and '.join(mixed)}, a run having set it again"
    elif mine["axes"] != theirs["axes"]:
        why = f"its axis map {mine['axes']} is not the calibration's {theirs['axes']}"
    elif not same:
        why = f"{_words(mine)}, the calibration's {_words(theirs)}"
    else:
        why = (f"{_words(mine)} as the calibration's, but on a machine not homed, whose coordinates do not tell one "
               "zero from another; give --zero-error 0 if the controller was not reset since")
    if found is not None:
        known = _spread(found[1])
        error = min(float(np.hypot(new, known)), MAX_STAGE_ERROR)
        return error, (f"a zero set anew ({why}): its own error, {new:g} mm, and that of the zero identify found, "
                       f"{known:.2g} mm, in quadrature"), None
    error = min(float(np.hypot(ours, new)), MAX_STAGE_ERROR)
    return error, f"a zero set anew ({why}): its error and the calibration's, {new:g} and {ours:g} mm, in quadrature", \
        None


def _spread(cov: np.ndarray) -> float:
    """A zero's covariance (3, 3) as one error, mm rms per axis."""
    return float(np.sqrt(np.trace(cov) / 3))


def _reused(found, said: str, posterior: dict | None) -> tuple[float, str, np.ndarray | None]:
    """check_zero's answer for the calibration's zero reused: where identify ``found`` it, if it did."""
    if found is None:
        older = "" if posterior is None else "; the unit's posterior records no zero found (an exact stage's, or older)"
        return 0.0, said + older, None
    mean, cov = found
    return min(_spread(cov), MAX_STAGE_ERROR), (f"{said}: the rows stand at their labels plus where identify found "
                                                f"that zero, {zero_words(mean)} mm (standard error "
                                                f"{_spread(cov):.2g})"), mean


def check_capture(model: Model, ds, sensor, unit_file=None, *, rig_error: float | None = None,
                  zero_error: float | None = None, precision: str | None = None,
                  capture="the check capture", sha256: str | None = None) -> tuple[Check, str]:
    """:func:`check` of ``model`` on the check capture ``ds`` (a dataset), as fitgen check runs it: the rows' noise
    as its meta says (fitgen.fitting.unitrecord.row_noise), units drawn from the posterior of ``unit_file`` where it
    has one, the stage's error ``rig_error`` or else :func:`check_rig`'s, the zero's ``zero_error`` or else
    :func:`check_zero`'s, in ``precision`` or else the one the model was fitted for; and where the rows' noise came
    from. InputError where the capture (``sha256``: its file's, before a temperature compensation; default ``ds``'s)
    is the one the unit was identified on."""
    posterior = unit_posterior(unit_file, sensor) if unit_file and Path(unit_file).is_file() else None
    if "samples_per_row" not in ds.meta and ds.meta.get("generator") and \
            ds.meta.get("sensor_sha256") in sensor_hashes(sensor):
        raise InputError(f"{capture} was simulated (fitgen simulate) on the unit file the model was fitted on, not "
                         "captured on the unit: it can only agree with it, so it checks nothing; capture fitgen "
                         "schedule --check's poses")
    if posterior and posterior.get("capture_sha256") == (sha256 or ds.sha256):
        raise InputError(f"{capture} is the capture {unit_file} was identified on: its rows are not held out, so they "
                         "check nothing; capture fitgen schedule --check's poses")
    rig_said = said = "as given"
    zero = None
    if rig_error is None:
        rig_error, rig_said = check_rig(posterior, ds.meta, capture, unit_file)
    if zero_error is None:
        zero_error, said, zero = check_zero(posterior, ds.meta, capture)
    noise, source = row_noise(ds.meta, sensor, option="")  # check has no --noise
    result = check(model, ds.inputs, ds.poses(), sensor, noise, posterior=posterior, rig_error=rig_error,
                   zero_error=zero_error, zero=zero, precision=precision or device_precision(model))
    return replace(result, zero_said=said, rig_said=rig_said), source
