"""A capture's zero, the stage displacement its labels call 0 (first contact, set by hand): where the stage's
record says it was in machine coordinates, where identify found it from first contact, and the rows a zero set
above first contact lifted off the skin."""

from __future__ import annotations

import numpy as np

from fitgen.base.errors import InputError, shown
from fitgen.fitting.capturecheck import reads_at_rest
from fitgen.physics.pose import POSE_NAMES


def stage_zero(meta: dict, capture) -> dict | None:
    """The zero a capture's stage moved from, as `tactile-host capture --stage` records it in its meta:
    :func:`zero_record`'s (the last run's) with ``zeros``, how many its runs moved from; or None when its meta
    records none (a stage moved by hand, an older capture)."""
    st = meta.get("stage")
    if not isinstance(st, dict) or "zero_machine_mm" not in st:
        return None
    runs = st.get("zeros_machine_mm")  # every zero its runs moved from: more than one after a controller reset
    zeros = len(runs) if isinstance(runs, list) and runs else 1
    return {**zero_record(st["zero_machine_mm"], st.get("zero_homed"), st.get("axes"), f"{capture}'s meta:"),
            "zeros": zeros}


def zero_record(zero, homed, axes, where: str) -> dict:
    """``{"machine_mm": {axis: mm}, "homed": bool, "axes": str}``: a stage's zero in machine coordinates, whether the
    machine was homed, and the axis map; InputError after ``where`` when they are not those."""
    import math

    if (not isinstance(zero, dict) or not zero or not isinstance(homed, bool) or not isinstance(axes, str)
            or not all(isinstance(k, str) and isinstance(v, (int, float)) and not isinstance(v, bool)
                       and math.isfinite(v) for k, v in zero.items())):
        raise InputError(f"{where} the stage's zero must be machine coordinates in mm, whether the machine was homed "
                         f"(true or false) and its axis map, got {shown(zero)}, {shown(homed)}, {shown(axes)}")
    return {"machine_mm": {k: float(v) for k, v in zero.items()}, "homed": homed, "axes": axes}


def zero_words(mean: np.ndarray) -> str:
    """A zero (mm, 3) as ``dx +0.0235, dy -0.0163, dz +0.0149``."""
    return ", ".join(f"{a} {v:+.4f}" for a, v in zip(POSE_NAMES, mean))


def zero_line(mean: np.ndarray, cov: np.ndarray) -> str:
    """The capture's zero as identify found it (:attr:`Identification.zero`), in words."""
    at = zero_words(mean)
    se = ", ".join(f"{v:.2g}" for v in np.sqrt(np.diag(cov)))
    return (f"the capture's zero (its labels' 0, set by hand) sat at {at} mm from the unit's first contact (standard "
            f"errors {se}): the unit is read from first contact, and fitgen check moves the labels of a check "
            "capture that reuses this zero by as much")


def zero_found(posterior: dict | None, where: str) -> tuple[np.ndarray, np.ndarray] | None:
    """A posterior's ``zero_found`` (identify's :attr:`Identification.zero`): (mean (3,), covariance (3, 3)), or
    None where it records none (identified without a zero's error, or before identify recorded it); InputError
    after ``where`` where it is not identify's."""
    found = (posterior or {}).get("zero_found")
    if found is None:
        return None
    try:
        mean, cov = np.asarray(found["mm"], dtype=float), np.asarray(found["covariance"], dtype=float)
        ok = (mean.shape == (3,) and cov.shape == (3, 3) and bool(np.isfinite(mean).all() and np.isfinite(cov).all())
              and np.allclose(cov, cov.T) and bool(np.all(np.diag(cov) >= 0)))
    except (TypeError, KeyError, ValueError):
        ok = False
    if not ok:
        raise InputError(f"{where} zero_found must be a zero (mm: 3 numbers) and its covariance (3 x 3), got "
                         f"{shown(found)}")
    return mean, cov


def lifted_rows(ident) -> tuple[int, ...]:
    """The rows of an identification (fitgen.fitting.identify.Identification) that the physics leaves unexplained
    which are labelled in contact yet read as the capture's rows off the skin (capturecheck.reads_at_rest): the stage
    lifted them past the skin's adhesion, its zero set above first contact. Empty where the rows are explained, or
    none reads so."""
    if ident.explained:
        return ()
    prob = ident.problem
    at_rest = reads_at_rest(prob.readings, prob.poses, prob.noise)
    return () if at_rest is None else tuple(int(i) for i in np.flatnonzero(at_rest))
