"""The tare's target and its offsets: the readings at rest a model expects (a sensor's physics, a dataset's rows at
rest, the model's own record), the checks that they are this sensor's and not another's, and the tare that maps a
unit's rest onto them (``tactile-host read --tare``, tm_pi's, the Arduino ReadPose's)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fitgen.physics.dataset import load_dataset
from fitgen.base.errors import InputError
from fitgen.fitting.holdout import fitted_sensor_spec
from fitgen.physics.pose import POSE_NAMES, POSE_UNITS, contact_poses
from fitgen.physics.sensor import load_sensor
from fitgen.physics.simulate import DEFAULT_RANGES
from fitgen.physics.transfer import readings

from host.adc import AdcArray
from host.temperature import CAPTURE_DEGC_TOL, model_unit_degc


def rest_reference(spec: str, n_inputs: int) -> np.ndarray:
    """The readings the model expects at rest: a dataset's rows at pose 0 (averaged), or a sensor's
    physics at pose 0 in its ``gmr`` transfer (volts)."""
    if spec.lower().endswith(".csv"):
        ds = load_dataset(spec, min_rows=1)
        if ds.meta.get("units", "V") != "V":
            raise InputError(f"--rest {spec}: its readings are in {ds.meta['units']}; the ADCs give volts (a dataset "
                             "in V: tactile-host capture, or fitgen simulate --transfer gmr)")
        # pose 0, or a schedule's rest row lifted off the skin (the magnet rests either way)
        at_rest = np.all(contact_poses(ds.poses()) == 0, axis=1)
        if not at_rest.any():
            raise InputError(f"--rest {spec}: the dataset has no row at rest (every pose column 0, or dz lifted "
                             "off the skin)")
        ref = ds.inputs[at_rest].mean(axis=0)
    else:
        sensor = load_sensor(spec).with_transfer("gmr")
        ref = readings(sensor, np.zeros(5), adc_bits=0)[0]
    if ref.size != n_inputs:
        raise InputError(f"--rest {spec}: gives {ref.size} rest readings; the model takes {n_inputs}")
    return ref


def model_rest(model, rest: str | None = None, required: bool = True) -> tuple[np.ndarray, str] | None:
    """The rest readings a tare maps onto for ``model``, and whose they are: ``rest`` (a sensor or a dataset, as
    --rest takes it), else the sensor file the model was fitted on where it is found here unchanged, else the rest
    the model recorded. InputError when the model reads them as a pose far from rest, and when there are none
    (None then, unless ``required``)."""
    own = None if rest else fitted_sensor_spec(model)
    if rest or own:
        reference = rest_reference(rest or own, model.n_inputs)
        target = f"--rest {rest}" if rest else f"{own} (the model's)"  # as read says it of its --sensor
    elif (reference := model.held_out_rest) is not None:
        target = "the model's own record"
    elif not required:
        return None
    else:
        raise InputError("the model records no rest readings and names no sensor file found here: give --rest, the "
                         "sensor file it was fitted on (a twin: the unit file identify wrote) or a dataset of this "
                         "sensor with rows at rest")
    check_rest_reference(model, reference, target, degc=rest_degc(rest or own))
    return reference, target


def measure(array: AdcArray, n: int, step=None) -> np.ndarray:
    """``n`` samples (n, N) in volts; ``step()`` after each (a progress bar's)."""
    if n < 1:
        raise InputError(f"the number of samples must be >= 1, got {n}")
    rows = []
    for _ in range(n):
        rows.append(array.read_volts())
        if step is not None:
            step()
    return np.vstack(rows)


REST_SHARE = 0.25  # of the fitted box's width: how far from rest a model may read the tare's target
REST_FLOOR = {"mm": 0.1, "deg": 0.5}  # ... and at least this, were a box's width 0
REST_DOMAIN_SHARE = 0.1  # of an input's fitted span: how far outside it the tare's target may lie


REST_ADVICE = ("give --rest the sensor file the model was fitted on (a unit's twin: the unit file identify wrote) "
               "or a dataset of this sensor's own with rows at rest")


def rest_degc(spec: str | None) -> float | None:
    """The temperature a dataset given as rest readings (--rest FILE.csv) was read at, as its meta records it (its
    rows' median, else as the capture started); None for a sensor file or a dataset that records none."""
    from fitgen.physics.dataset import load_meta, row_degc, thermistor_degc

    if not spec or not spec.lower().endswith(".csv"):
        return None
    try:
        meta = load_meta(spec)
    except (InputError, OSError):
        return None
    rows = meta.get("row_degc")
    each = row_degc(meta, len(rows)) if isinstance(rows, list) else None  # a damaged one: as none recorded
    return float(np.median(each)) if each is not None and each.size else thermistor_degc(meta)


def _another(model, degc: float | None) -> str:
    """What rest readings a model refuses are: another sensor's, or, read ``degc`` away from its unit's capture
    temperature, maybe its own at another temperature."""
    unit = model_unit_degc(model)[1] if degc is not None else None
    if unit is None or abs(degc - unit) <= CAPTURE_DEGC_TOL:
        return "they are another sensor's"
    return (f"they were read at {degc:.1f} degC and the model's unit at {unit:.1f} degC, so they are its rest drifted "
            "by the difference, or another sensor's")


def check_rest_reference(model, reference: np.ndarray, spec: str, advice: str = REST_ADVICE,
                         degc: float | None = None) -> None:
    """InputError when ``model``'s pose box stops short of rest by as much as below; when the rest readings
    ``reference`` (from ``spec``) lie outside its inputs by over REST_DOMAIN_SHARE of their span, or it reads them as
    a pose over REST_SHARE of its box's width from rest: another sensor's rest, which a tare would map every reading
    onto. ``advice``: what the message then tells to do; ``degc``: when they were read (:func:`rest_degc`)."""
    near = {c: (lo, hi, max(REST_SHARE * (hi - lo), REST_FLOOR[POSE_UNITS[POSE_NAMES.index(c)]]))
            for c, (lo, hi) in model.pose_box.items()}  # random poses' box stops short of 0: near it is rest too
    never = [f"{c} {lo:g}..{hi:g}" for c, (lo, hi, m) in near.items() if not lo - m <= 0 <= hi + m]
    if never:  # no rest in it to tare onto: not another sensor's, and no --rest mends it
        raise InputError(f"the model was fitted on poses that never rest ({', '.join(never)}): a tare needs one "
                         "fitted where the sensor rests: fit on such poses, or leave the tare out")
    ref = np.asarray(reference, dtype=float)
    span = model.input_max - model.input_min
    # the estimate of clamped inputs can look like rest (a two-ring model at the paper's rest: dz -0.28 mm), so the
    # readings themselves are held to the domain too, with room for a unit's own rest at its edge
    out = [k + 1 for k in np.flatnonzero(~((ref >= model.input_min - REST_DOMAIN_SHARE * span)
                                           & (ref <= model.input_max + REST_DOMAIN_SHARE * span)))]
    if out:
        raise InputError(f"the rest readings of {spec} lie outside the readings the model was fitted on (v"
                         f"{', v'.join(map(str, out))} beyond {REST_DOMAIN_SHARE:.0%} of their span): "
                         f"{_another(model, degc)}, and a tare onto them would bend every estimate; {advice}")
    est = np.asarray(model.predict(ref[None]), dtype=float)[0]
    box = {**DEFAULT_RANGES, **model.held_out_box}
    far = []
    for j, e in enumerate(model.equations):
        lo, hi = box[e.name]
        if not abs(est[j]) <= max(REST_SHARE * (hi - lo), REST_FLOOR[e.unit]):  # NaN too
            far.append(f"{e.name} {est[j]:.3g} {e.unit}")
    if far:
        raise InputError(f"the model reads the rest readings of {spec} as {', '.join(far)}, far from rest: "
                         f"{_another(model, degc)}, and a tare onto them would bend every estimate; {advice}")


TARE_UNIT_SHARE = 0.25  # of the rest readings' spread between units: a unit's own drift stays well under it
ANOTHER_UNIT = ("note: the tare's offsets reach {off} mV rms, and the rest readings of units built to the drawing of "
                "the model's unit spread by {between} mV rms (one unit's drift stays well under {limit} mV): is "
                "this the unit the model was fitted for? On another unit its estimates err as the drawing's model "
                "does on a unit (identify this one and fit its twin)")


def another_unit_limit(model) -> tuple[float, float] | None:
    """(how far the rest readings of units built to the drawing of ``model``'s unit spread, rms over the elements of
    Model.held_out_rest_spread, a twin's record; the tare offsets' rms past which :func:`another_unit_note` speaks:
    TARE_UNIT_SHARE of it), in V; None without the record."""
    return unit_limit(model.held_out_rest_spread)


def unit_limit(spread) -> tuple[float, float] | None:
    """(the rms over the elements of ``spread``, per element how far the rest readings of units built to one drawing
    spread; TARE_UNIT_SHARE of it, past which rest readings are more likely another unit's than this one's drifted),
    in V; None for None."""
    between = None if spread is None else float(np.sqrt(np.mean(np.square(spread))))
    return None if between is None else (between, TARE_UNIT_SHARE * between)


def another_unit_note(model, offsets) -> str:
    """A note when a tare's ``offsets`` (V) reach, in rms over the elements, :func:`another_unit_limit`: the sensor
    resting is then more likely another unit than this one drifted, and a tare maps any unit's rest onto the
    model's; '' otherwise, or without the record."""
    limits = another_unit_limit(model)
    off = float(np.sqrt(np.mean(np.square(offsets))))
    if limits is None or not off > limits[1]:
        return ""
    return ANOTHER_UNIT.format(off=f"{off * 1e3:.3g}", between=f"{limits[0] * 1e3:.3g}", limit=f"{limits[1] * 1e3:.2g}")


@dataclass
class Tare:
    measured: np.ndarray  # mean rest readings
    reference: np.ndarray
    spread: np.ndarray  # standard deviation of each element during the tare
    samples: int  # how many the tare averaged

    @property
    def offsets(self) -> np.ndarray:
        return self.measured - self.reference

    def noise_floor(self, lsb: np.ndarray) -> float:
        """The readings' noise for auto-zero (V rms): the median element's spread, at least the ADC's
        quantisation (the largest LSB / sqrt(12)), so that a noise-free simulation has a floor too."""
        return max(float(np.median(self.spread)), float(np.max(lsb)) / math.sqrt(12.0))

    def describe(self) -> str:
        mv = " ".join(f"{x * 1e3:+.2f}" for x in self.offsets)  # one sample has no spread: 0.00 would read as none
        spread = f"spread up to {self.spread.max() * 1e3:.2f} mV rms" if self.samples > 1 else "one sample: no spread"
        return f"tare: offsets [mV] {mv} ({spread})"


TARE_SAMPLES = 50  # samples a tare averages by default: read's, tm_pi's and the Arduino ReadPose's


def tare(array: AdcArray, reference: np.ndarray, n: int = TARE_SAMPLES, step=None, compensate=None) -> Tare:
    """Rest readings averaged over ``n`` samples; subtracting ``offsets`` maps them onto ``reference``.
    ``compensate`` (rows -> rows): the temperature compensation the readout applies before it takes the offsets
    off, applied to the tare's rows too, so that the offsets are the compensated rest's."""
    block = measure(array, n, step)
    if compensate is not None:
        block = compensate(block)
    return Tare(block.mean(axis=0), np.asarray(reference, dtype=float), block.std(axis=0), len(block))
