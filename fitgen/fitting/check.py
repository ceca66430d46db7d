"""A check capture: what a model delivers on a unit at stage poses never used to calibrate it, against what the
unit's identification predicts at those very poses. The prediction reads units drawn from the twin's posterior
(the model's own sensor alone when it has none) at the capture's labels moved by the stage's error, with the rows'
own reading noise, and estimates them as the device does: both sides carry the same errors, so a twin that does
not describe the unit (a knock, a slip of the sensor on the bed, another unit's file) stands out, and one that
does reads within the spread of the draws."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fitgen.base.errors import InputError
from fitgen.equations.model import Model
from fitgen.fitting.capturecheck import check_error
from fitgen.fitting.holdout import POSTERIOR_UNITS, device_precision, estimator, posterior_units, unit_posterior
from fitgen.fitting.identify import RIG_ERROR
from fitgen.fitting.unitrecord import row_noise
from fitgen.physics.pose import POSE_NAMES, off_skin
from fitgen.physics.simulate import rig_poses
from fitgen.physics.transfer import readings

DRAWS = 5  # the stage's error and the rows' noise drawn this many times per unit
SEED = 2031
FIGURES = ("max", "rms")
TOO_FAR = 1.5  # a measured max this many times the greatest drawn one: the twin does not describe the unit


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

    def predicted(self, output: str, figure: str) -> tuple[float, float, float]:
        """The median, least and greatest of the drawn ``figure`` of ``output``."""
        v = self.drawn[output][figure]
        return float(np.median(v)), float(v.min()), float(v.max())

    def beyond(self, output: str, figure: str = "max") -> float:
        """The measured figure over the greatest drawn one: above 1, no draw erred as much."""
        return self.measured[output][figure] / max(self.predicted(output, figure)[2], 1e-300)

    def failed(self) -> list[str]:
        """The outputs whose measured max lies TOO_FAR beyond every draw's."""
        return [o for o in self.outputs if self.beyond(o) > TOO_FAR]


def _figures(err: np.ndarray) -> dict:
    return {"max": np.abs(err).max(axis=0), "rms": np.sqrt(np.mean(err ** 2, axis=0))}


def check(model: Model, inputs: np.ndarray, labels: np.ndarray, sensor, row_noise, *, posterior: dict | None = None,
          rig_error: float = RIG_ERROR, zero_error: float = 0.0, precision: str = "float",
          units: int = POSTERIOR_UNITS, draws: int = DRAWS, seed: int = SEED) -> Check:
    """:class:`Check` of ``model`` on a capture's ``inputs`` (n, N) at stage ``labels`` (n, 5), the rows' reading
    noise ``row_noise`` (per element or one number): predicted on ``units`` units drawn from ``posterior`` (an
    identified unit's record) or on ``sensor`` alone, each read ``draws`` times at the labels moved by ``rig_error``
    (mm rms per axis) and, where the check capture's zero was set anew, by one ``zero_error`` draw shared by its rows
    (mm rms per axis), with that noise, estimated in ``precision``. Rows off the skin are left out."""
    check_error("rig error", rig_error)
    check_error("zero error", zero_error)
    inputs, labels = np.asarray(inputs, dtype=float), np.asarray(labels, dtype=float)
    keep = ~off_skin(labels)
    inputs, labels = inputs[keep], labels[keep]
    if not len(labels):
        raise InputError("every row of the check capture is lifted off the skin: no contact pose to check")
    fn = estimator(model, precision, sensor)
    if isinstance(fn, str):
        raise InputError(f"the model cannot run in {precision}: {fn}")
    outputs = tuple(o for o in model.output_names if o in POSE_NAMES)
    cols = [model.output_names.index(o) for o in outputs]
    truth = labels[:, [POSE_NAMES.index(o) for o in outputs]]
    measured = {o: {f: float(v[j]) for f, v in _figures(fn(inputs)[:, cols] - truth).items()}
                for j, o in enumerate(outputs)}
    noise = np.broadcast_to(np.asarray(row_noise, dtype=float), (inputs.shape[1],))
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
                 posterior is not None, float(zero_error))


def check_capture(model: Model, ds, sensor, unit_file=None, *, rig_error: float | None = None,
                  zero_error: float = 0.0, precision: str | None = None) -> tuple[Check, str]:
    """:func:`check` of ``model`` on the check capture ``ds`` (a dataset), as fitgen check runs it: the rows' noise
    as its meta says (fitgen.fitting.unitrecord.row_noise), units drawn from the posterior of ``unit_file`` where it
    has one, the stage's error ``rig_error`` or else the one the unit was identified with (RIG_ERROR without a
    record), the zero's ``zero_error`` (0: the calibration's zero, reused), in ``precision`` or else the one the model
    was fitted for; and where the rows' noise came from."""
    posterior = unit_posterior(unit_file, sensor) if unit_file and Path(unit_file).is_file() else None
    if rig_error is None:
        rig_error = (posterior or {}).get("rig_error", RIG_ERROR)
        if not isinstance(rig_error, (int, float)) or isinstance(rig_error, bool):
            raise InputError(f"{unit_file}'s posterior records a rig error of {rig_error!r}: give --rig-error")
    noise, source = row_noise(ds.meta, sensor)
    result = check(model, ds.inputs, ds.poses(), sensor, noise, posterior=posterior, rig_error=rig_error,
                   zero_error=zero_error, precision=precision or device_precision(model))
    return result, source
