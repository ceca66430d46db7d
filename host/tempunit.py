"""Whose sensor a temperature compensation was fitted on: its rest readings at t0 (``fit.rest_v``) against the rest
of the unit a model or a capture is of. Units built to one drawing rest tens of millivolts apart, while one unit
drifts by a few; each unit drifts its own way, so another unit's coefficients correct this one's drift wrongly."""

from __future__ import annotations

import numpy as np

from fitgen.base.errors import InputError
from fitgen.physics.pose import contact_poses
from host.rest import model_rest, unit_limit

OTHER_UNIT = ("note: {option} was fitted on a sensor that rests {off} mV rms from {whose}, and the rest readings "
              "of units built to its drawing spread by {between} mV rms (one unit's drift stays well under {limit} "
              "mV): is it this unit's compensation? Each unit drifts its own way, and another's coefficients "
              "correct this one's wrongly (this unit's: tactile-host capture --temperature)")


def rest_note(tempcomp, rest, spread, option: str, whose: str, degc: float | None = None) -> str:
    """A note when ``tempcomp``'s rest readings (its fit.rest_v), taken from its t0 to ``degc`` (None: t0) by its
    own coefficients, lie from ``rest`` (V, ``whose``) past host.rest.unit_limit(``spread``) in rms over the
    elements; '' otherwise, or without either record."""
    theirs, limits = tempcomp.rest_v, unit_limit(spread)
    if theirs is None or limits is None or theirs.shape != np.shape(rest):
        return ""
    if degc is not None:
        theirs = tempcomp.reading_at(theirs, degc)
    off = float(np.sqrt(np.mean(np.square(theirs - np.asarray(rest, dtype=float)))))
    if not off > limits[1]:
        return ""
    return OTHER_UNIT.format(option=option, off=f"{off * 1e3:.3g}", whose=whose, between=f"{limits[0] * 1e3:.3g}",
                             limit=f"{limits[1] * 1e3:.2g}")


def model_note(model, tempcomp, option: str) -> str:
    """:func:`rest_note` against the rest readings of ``model``'s unit (a twin's: host.rest.model_rest, with the
    spread its fit recorded), at the temperature the unit was identified at where its file records one."""
    from fitgen.fitting.holdout import fitted_sensor_spec
    from fitgen.physics.sensor import load_sensor
    from host.temperature import unit_capture_degc

    if model.held_out_rest_spread is None or tempcomp.rest_v is None:
        return ""
    try:
        found = model_rest(model, required=False)
        spec = fitted_sensor_spec(model)
        degc = unit_capture_degc(load_sensor(spec).source) if spec else None
    except InputError:  # no rest of its own to compare: the readouts refuse or note that themselves
        return ""
    if found is None:
        return ""
    return rest_note(tempcomp, found[0], model.held_out_rest_spread, option, "the model's unit", degc)


def capture_note(ds, tempcomp, spread, option: str, capture: str) -> str:
    """:func:`rest_note` against the rows at rest of ``ds``, a capture already taken to ``tempcomp``'s t0."""
    at_rest = np.all(contact_poses(ds.poses()) == 0, axis=1)
    if not at_rest.any():
        return ""
    return rest_note(tempcomp, ds.inputs[at_rest].mean(axis=0), spread, option, f"{capture}'s rows at rest")
