"""What a capture must be before a unit is identified from it: enough rows and poses, readings an ADC can give,
not saturated, and readings that follow the stage (an indenter that never reached the skin reads the rest in
every row). Each refusal is one line that names the cause."""

from __future__ import annotations

import numpy as np

from fitgen.base.errors import InputError, shown
from fitgen.physics.pose import off_skin
from fitgen.physics.sensor import TRAVEL_MAX

MIN_ROWS = 10
MIN_DISTINCT = 6
FARTHEST = TRAVEL_MAX  # mm: a label beyond this is no displacement of the skin from first contact
MAX_CLIPPED = 0.1  # share of clipped readings above which a capture is refused
PRESSED = 0.3  # mm: a row pressed this deep moves the magnet far past the noise (a zero a little high is allowed
# for by identify's zero error: rows at dz 0 may miss the skin)
REST_LIKE = 5.0  # noise sd: a row in contact within this of the rest rows' readings reads as at rest
STILL_SHARE = 0.25  # pressed rows that read as at rest, above which the zero is above the skin


def distinct_poses(poses) -> int:
    """How many distinct poses the rows ``poses`` (n, 5) visit, to a micrometre (a stage's labels)."""
    return len(np.unique(np.round(np.asarray(poses, dtype=float), 6), axis=0))


def element_noise(noise, n: int, what: str, positive: bool = True) -> np.ndarray:
    """``noise`` (one figure, or one per element) as ``n`` figures; InputError unless each is finite and > 0
    (``positive``) or >= 0."""
    try:  # a text is no figure, though numpy reads "0.001" as one
        if isinstance(noise, (str, bytes)):
            raise TypeError
        arr = np.asarray(noise, dtype=float)
    except (TypeError, ValueError, OverflowError):
        raise InputError(f"{what} must be a number, or one per element, got {shown(noise)}") from None
    if arr.shape not in ((), (n,)):
        raise InputError(f"{what} gives {arr.size} figures for {n} elements: give one, or one per element")
    if not np.all(np.isfinite(arr) & ((arr > 0) if positive else (arr >= 0))):
        raise InputError(f"{what} must be finite and {'> 0' if positive else '>= 0'}, got {shown(noise)}")
    return np.broadcast_to(arr, (n,)).copy()


def check_capture(space, readings: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """Refuse captures no identification can use (InputError, one line); the mask of readings that are not
    clipped (a few clipped ones are left out, more than MAX_CLIPPED of them refuse the capture)."""
    n, N = readings.shape
    if N != space.drawing.n_elements:
        raise InputError(f"the capture has {N} readings per row; sensor {space.drawing.name} has "
                         f"{space.drawing.n_elements} elements: give the drawing the unit was built to (--sensor)")
    if n < MIN_ROWS:
        raise InputError(f"the capture has {n} rows; identify needs at least {MIN_ROWS} (fitgen schedule --n 40)")
    far = np.abs(poses[:, :3]).max(axis=0)
    if far.max() > FARTHEST:  # the magnet sits 11 mm above the board: no press moves the surface this far
        axis = "xyz"[int(np.argmax(far))]
        raise InputError(f"the capture's labels reach d{axis} = {far.max():g} mm, beyond any press of a sensor "
                         f"(identify takes labels within {FARTHEST:g} mm of the zero): labels in um, or machine "
                         "coordinates rather than mm from the zero at first contact?")
    if (distinct := distinct_poses(poses)) < MIN_DISTINCT:
        raise InputError(f"the capture visits {distinct} distinct pose(s); identify needs at least {MIN_DISTINCT} "
                         "(fitgen schedule)")
    d = space.drawing
    valid = np.ones(readings.shape, dtype=bool)
    if d.transfer == "gmr":
        # a reading on the ADC's rails is clipped (the element's own saturation is in the model: gain x 2 mT)
        g = d.gmr
        lsb = (g.adc_max - g.adc_min) / max(2**g.adc_bits - 1, 1)
        # past the rails by more than noise could put an unquantised reading: no reading of this ADC at all
        margin = max(2 * lsb, 0.05 * (g.adc_max - g.adc_min))
        beyond = (readings < g.adc_min - margin) | (readings > g.adc_max + margin)
        if beyond.any():
            i, k = np.argwhere(beyond)[0]
            raise InputError(f"row {i + 1}: v{k + 1} = {readings[i, k]:.6g} V lies outside the ADC's range "
                             f"({g.adc_min:g}..{g.adc_max:g} V, sensor {d.name}): readings in other units (mT: give "
                             "--transfer raw) or from another ADC than the sensor file's [transfer.gmr]")
        if np.ptp(readings) == 0:
            raise InputError(f"every reading is {readings[0, 0]:.6g} V: no sensor answers behind the ADC (its supply, "
                             "its wiring, the channel map)")
        valid = (readings < g.adc_max - 2 * lsb) & (readings > g.adc_min + 2 * lsb)
        stuck = np.nonzero(np.mean(~valid, axis=0) > 0.9)[0]  # one element on a rail, the others not: that element
        if len(stuck) == 1:
            k = int(stuck[0])
            others = float(np.mean(np.delete(~valid, k, axis=1)))
            raise InputError(f"v{k + 1} reads at the ADC's rail in {np.mean(~valid[:, k]):.0%} of the rows "
                             f"({np.median(readings[:, k]):.6g} V, range {g.adc_min:g}..{g.adc_max:g} V), the other "
                             f"elements in {others:.0%} of theirs: element {k + 1} does not respond or is not connected "
                             "(its supply, its amplifier, its channel in the channel map)")
        if np.mean(~valid) > MAX_CLIPPED:
            i, k = np.argwhere(~valid)[0]
            raise InputError(f"{np.mean(~valid):.0%} of the readings are saturated at the ADC's rails (row {i + 1}: "
                             f"v{k + 1} = {readings[i, k]:.6g} V, range {g.adc_min:g}..{g.adc_max:g} V): capture within "
                             "the linear range (fitgen schedule --limits), or lower the amplifier's gain")
    elif d.raw.adc_bits > 0:  # a quantised raw transfer's ADC clips at 0 and its full scale: those say nothing
        lsb = d.raw.full_scale / (2**d.raw.adc_bits - 1)
        valid = (readings < d.raw.full_scale - 2 * lsb) & (readings > 2 * lsb)
    return valid


def reads_at_rest(readings: np.ndarray, poses: np.ndarray, noise: np.ndarray) -> np.ndarray | None:
    """Per row: labelled in contact, yet within REST_LIKE noise sd of the rest rows' mean on every element (the
    magnet did not move: the indenter missed the skin, or left it). ``noise``: per element, a row's rms. None
    without rest rows to compare with."""
    off = off_skin(poses)
    if not off.any():
        return None
    sd = noise * np.sqrt(1.0 + 1.0 / off.sum())
    return ~off & (np.max(np.abs(readings - readings[off].mean(axis=0)) / sd, axis=1) < REST_LIKE)


def check_contact(readings: np.ndarray, poses: np.ndarray, noise: np.ndarray) -> None:
    """InputError when rows pressed PRESSED mm or more read as the rows off the skin (the rest rows,
    :func:`reads_at_rest`): a zero set well above first contact (the indenter met the skin only in the deepest rows,
    or never), or readings that are not the sensor's under the stage. No rest rows: nothing to compare with."""
    pressed = ~off_skin(poses) & (poses[:, 2] <= -PRESSED)
    at_rest = reads_at_rest(readings, poses, noise)
    if at_rest is None or not pressed.any():
        return
    still = at_rest[pressed]
    if still.mean() < STILL_SHARE:
        return
    depth = float(-poses[pressed][still, 2].min())
    if still.all():
        raise InputError(f"every row pressed {PRESSED:g} mm or more reads as the rows at rest (within {REST_LIKE:g} "
                         f"noise sd), down to dz={-depth:g}: the readings do not follow the stage; the indenter never "
                         f"reached the skin (the zero is more than {depth:g} mm above first contact: set it again, "
                         "docs/calibration.md), or the readings are not the sensor's under the stage")
    raise InputError(f"{int(still.sum())} of the {int(pressed.sum())} rows pressed {PRESSED:g} mm or more read as the "
                     f"rows at rest (within {REST_LIKE:g} noise sd), down to dz={-depth:g}: the zero is about {depth:g} "
                     "mm or more above first contact (set it again, docs/calibration.md)")


MAX_STAGE_ERROR = 0.5  # mm rms: a quarter of the pose box's half-width; a printer errs by 0.01-0.1


def is_stage_error(value) -> bool:
    """``value`` is a number 0..MAX_STAGE_ERROR mm, as a meta may record a rig's or zero's error."""
    return isinstance(value, (int, float)) and not isinstance(value, bool) and 0 <= value <= MAX_STAGE_ERROR


def check_error(name: str, value: float) -> None:
    """InputError unless a rig's or zero's error is 0..MAX_STAGE_ERROR mm: a stage that errs by more is not one
    to calibrate a +-2 mm sensor on (its rows would weigh next to nothing, and any unit would pass)."""
    if not 0 <= value <= MAX_STAGE_ERROR:
        raise InputError(f"the {name} must be 0..{MAX_STAGE_ERROR:g} mm (a printer's is 0.01-0.1), got {value:g}")
