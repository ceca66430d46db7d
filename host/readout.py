"""The live readout: read every element, estimate the pose, write a timestamped line; pace, tare, count.

One sample is ``Readout.step()``: the ADC array's volts (transient I2C errors retried with back-off inside it)
through the corrections (:class:`Corrections`: temperature compensation, then the tare's or the auto-zero's
offsets), through the engine, formatted as a CSV or JSON line and written in one piece; an observer (the live view)
and a run record (``--record``, for ``tactile-host replay``) may see each sample too. ``run`` repeats it at a rate or
as fast as the converters allow, until a count, a duration or a stop request (Ctrl-C), and returns the statistics
the summary line shows. A chip that stays silent raises ``DeviceSilent`` out of ``run`` with the statistics so far
attached (``exc.stats``).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field

import numpy as np

from fitgen.physics.dataset import load_dataset
from fitgen.base.errors import InputError
from fitgen.fitting.holdout import fitted_sensor_spec
from fitgen.physics.pose import POSE_NAMES, POSE_UNITS, contact_poses
from fitgen.physics.sensor import load_sensor
from fitgen.physics.simulate import DEFAULT_RANGES
from fitgen.physics.transfer import readings

from host.adc import AdcArray, DeviceSilent, ErrorCounts
from host.clock import REAL_CLOCK
from host.temperature import BEYOND_DEGC, CAPTURE_DEGC_TOL, T_RANGE, model_unit_degc

FORMATS = ("csv", "jsonl")


class LineFormat:
    """Lines of one sample: ``t`` (Unix time, s), v1..vN (V, after tare), the outputs, the status."""

    def __init__(self, kind: str, n_inputs: int, outputs: tuple[str, ...]):
        if kind not in FORMATS:
            raise InputError(f"format must be one of {', '.join(FORMATS)}, got {kind!r}")
        self.kind, self.n_inputs, self.outputs = kind, n_inputs, tuple(outputs)
        vf, of = "%.6f", "%.4f"
        if kind == "csv":
            self.header = ",".join(["t"] + [f"v{k}" for k in range(1, n_inputs + 1)] + list(outputs) + ["status"]) + "\n"
            self._fmt = ",".join(["%.6f"] + [vf] * n_inputs + [of] * len(outputs) + ["%d"]) + "\n"
        else:
            self.header = ""
            self._fmt = ('{"t":%.6f,"v":[' + ",".join([vf] * n_inputs) + "]," +
                         ",".join(f'"{o}":{of}' for o in outputs) + ',"status":%d}\n')

    def line(self, t: float, volts, outputs, status: int) -> str:
        return self._fmt % (t, *volts, *outputs, status)


UNCOMPENSATED = "not compensated for temperature: the thermistor read none (is it connected?)"
FAR_OUTSIDE = ("estimated outside the pose box the model was fitted in by more than its width: another sensor than "
               "the model's? a built unit needs its own calibration (docs/calibration.md)")
TEMP_OUTSIDE = (f"at a temperature outside {T_RANGE[0]:g}..{T_RANGE[1]:g} degC, where the compensation is "
                "extrapolated (a thermistor off its divider's range?)")
TEMP_BEYOND = "at a temperature the compensation was not fitted near, where it is extrapolated"
# ReadoutStats' counts of samples whose estimates are off while the run goes on: each said at its first sample
# (Readout.warn) and in the summary
WARNED = {"uncompensated": UNCOMPENSATED, "temp_outside": TEMP_OUTSIDE, "temp_beyond": TEMP_BEYOND,
          "far": FAR_OUTSIDE}


@dataclass
class ReadoutStats:
    samples: int = 0
    elapsed: float = 0.0
    late: int = 0  # samples that started later than the pace by more than a period
    clipped: int = 0  # samples with an input at its converter's full scale
    outside: int = 0  # samples with an input outside the model's fitted domain (status > 0)
    far: int = 0  # samples estimated outside the model's fitted pose box by more than its width
    uncompensated: int = 0  # samples a temperature compensation was given for and the thermistor read none
    temp_outside: int = 0  # samples whose temperature lies outside the range a compensation is checked over
    temp_beyond: int = 0  # samples more than BEYOND_DEGC past the temperatures a compensation was fitted at
    first: float = 0.0  # s (monotonic): when the first sample began
    last: float = 0.0  # and the last
    errors: ErrorCounts = field(default_factory=ErrorCounts)

    @property
    def rate(self) -> float:
        """Samples per second from the first sample's start to the last's: n - 1 intervals, not n samples over
        the run, which would count the last sample's pace twice (2 samples at --rate 1 read 2 Hz)."""
        span = self.last - self.first
        return (self.samples - 1) / span if self.samples > 1 and span > 0 else 0.0

    def summary(self) -> str:
        e = self.errors
        errs = (f"I2C errors {e.total} (nack {e.nack}, timeout {e.timeout}, stuck {e.stuck}, other {e.other}; "
                f"{e.retries} retries, {e.resets} resets)")
        pace = f" ({self.rate:.1f} Hz)" if self.samples > 1 else ""
        text = f"{self.samples} samples in {self.elapsed:.2f} s{pace}; {errs}"
        if self.late:
            text += f"; {self.late} late"
        if self.clipped:
            text += f"; {self.clipped} with a clipped input"
        if self.outside:
            text += f"; {self.outside} outside the model's domain"
        for kind, said in WARNED.items():
            if getattr(self, kind):
                text += f"; {getattr(self, kind)} {said}"
        return text


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


def _wait(clock, until: float, stop, end: float | None) -> bool:
    """Sleep until ``until`` in slices, so that a stop or the run's ``end`` ends the wait; False when one did."""
    while (now := clock.monotonic()) < until:
        if stop() or (end is not None and now >= end):
            return False
        clock.sleep(min(WAIT_SLICE, until - now) if end is None else min(WAIT_SLICE, until - now, end - now))
    return not stop() and (end is None or clock.monotonic() < end)


WAIT_SLICE = 0.1  # s: how late a Ctrl-C during a slow --rate's wait is seen


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


@dataclass
class Corrections:
    """From ADC volts to what the model takes: temperature compensation, then the zero offsets.

    ``offsets``: the tare's (fixed); ``autozero``: a :class:`host.autozero.AutoZero` whose zero starts
    at the tare's and follows drift at rest (then ``offsets`` is not used separately).
    """

    offsets: np.ndarray | None = None
    tempcomp: object = None  # host.temperature.TempComp
    autozero: object = None  # host.autozero.AutoZero

    def __call__(self, raw: np.ndarray, temp: float) -> tuple[np.ndarray, np.ndarray]:
        """(compensated readings before the zero, readings for the model)."""
        v = self.compensated(raw, temp)
        return v, self.zeroed(v)

    def compensated(self, raw: np.ndarray, temp: np.ndarray) -> np.ndarray:
        """Rows of readings compensated for their temperatures, the zero not yet taken off."""
        return self.tempcomp.apply(raw, temp) if self.tempcomp is not None else raw

    def zeroed(self, comp: np.ndarray) -> np.ndarray:
        """Compensated rows with the current zero taken off: what the model takes."""
        if self.autozero is not None:
            return self.autozero.correct(comp)
        return comp - self.offsets if self.offsets is not None else comp

    def observe(self, t: float, comp: np.ndarray, out: np.ndarray, status: int):
        if self.autozero is not None:
            return self.autozero.observe(t, comp, out, status)
        return None

    def describe(self) -> dict:
        az = self.autozero
        return {"tare": None if self.offsets is None else [float(x) for x in self.offsets],
                "temp_comp": None if self.tempcomp is None else self.tempcomp.to_dict(),
                "auto_zero": None if az is None else {
                    **{k: getattr(az.settings, k) for k in az.settings.__dataclass_fields__},
                    "reference": [float(x) for x in az.reference], "noise": az.noise,
                    "start": [float(x) for x in az.zero]}}


def _num(x: float):
    return float(x) if math.isfinite(x) else None


class RunRecord:
    """A run, sample by sample, at full precision (JSON lines): what ``tactile-host replay`` re-estimates.

    First line: ``{"run": 1, ...}`` with the model's hash, outputs and the corrections in force at the
    start; then per sample ``{"t", "raw", "temp", "out", "status"}``: the ADC volts before any
    correction, the temperature (null without a thermometer), the estimates and the status.
    """

    def __init__(self, sink, header: dict):
        self.sink = sink
        sink.write(json.dumps({"run": 1, **header}) + "\n")

    def write(self, t: float, raw, temp: float, out, status: int) -> None:
        self.sink.write(json.dumps({"t": t, "raw": [float(x) for x in raw], "temp": _num(temp),
                                    "out": [float(x) for x in out], "status": int(status)}) + "\n")


class Readout:
    """One sample at a time: read, correct, estimate, format, write."""

    def __init__(self, array: AdcArray, engine, sink, fmt: LineFormat, *, clock=REAL_CLOCK,
                 offsets: np.ndarray | None = None, corrections: Corrections | None = None, thermometer=None,
                 observer=None, record: RunRecord | None = None, warn=None):
        if engine.n_inputs != array.n:
            raise InputError(f"the channel map reads {array.n} elements; the model takes {engine.n_inputs}")
        self.array, self.engine, self.sink, self.fmt, self.clock = array, engine, sink, fmt, clock
        self.corrections = corrections or Corrections(None if offsets is None else np.asarray(offsets, dtype=float))
        self.thermometer, self.observer, self.record, self.warn = thermometer, observer, record, warn
        self.stats = ReadoutStats(errors=array.counts)
        self._far_cols, self._far_lo, self._far_hi = engine.model.far_bounds()  # as fitgen predict counts them
        self._write = sink.write if sink is not None else None
        self._flush = getattr(sink, "flush", None)
        self._rate_t, self._rate_n, self.rate = None, 0, 0.0

    def step(self) -> None:
        raw = self.array.read_volts()
        temp = self.thermometer.read() if self.thermometer is not None else math.nan
        comp, v = self.corrections(raw, temp)
        out, status = self.engine.estimate(v)
        t = self.clock.time()
        self.corrections.observe(t, comp, out, status)
        if self._write is not None:
            self._write(self.fmt.line(t, v, out, status))
        if self.record is not None:
            self.record.write(t, raw, temp, out, status)
        st = self.stats
        st.samples += 1
        if status:
            st.outside += 1
        far = False
        if status >= 0 and self._far_cols:
            est = np.asarray(out, dtype=float)[self._far_cols]
            far = bool(np.any((est < self._far_lo) | (est > self._far_hi)))
            if far:
                self._count("far")
        if self.array.clipped.any():
            st.clipped += 1
        if self.corrections.tempcomp is not None:
            self._check_temperature(temp)
        if self.observer is not None:
            self._publish(t, raw, v, out, status, temp, far)

    def _check_temperature(self, temp: float) -> None:
        """Count a sample the compensation did not apply to, or applied outside its range."""
        if not math.isfinite(temp):
            self._count("uncompensated")
        elif not T_RANGE[0] <= temp <= T_RANGE[1]:
            self._count("temp_outside", f": {temp:.1f} degC")
        elif (fitted := self.corrections.tempcomp.fitted_range) is not None and \
                not fitted[0] - BEYOND_DEGC <= temp <= fitted[1] + BEYOND_DEGC:
            self._count("temp_beyond", f" ({temp:.1f} degC; fitted at {fitted[0]:g}..{fitted[1]:g})")

    def _count(self, kind: str, detail: str = "") -> None:
        """One more sample of a WARNED ``kind``; the first is said at once (``warn``): a run may last hours, and
        its estimates are off from then on, not at its end."""
        st = self.stats
        setattr(st, kind, getattr(st, kind) + 1)
        if getattr(st, kind) == 1 and self.warn is not None:
            self.warn(f"sample {st.samples} {WARNED[kind]}{detail}; the summary counts every such sample")

    def _publish(self, t, raw, v, out, status, temp, far=False) -> None:
        now = self.clock.monotonic()
        if self._rate_t is None:
            self._rate_t = now
        self._rate_n += 1
        if now - self._rate_t >= 1.0:
            self.rate, self._rate_t, self._rate_n = self._rate_n / (now - self._rate_t), now, 0
        az = self.corrections.autozero
        self.observer({
            "t": t, "v": [float(x) for x in v], "raw": [float(x) for x in raw],
            "out": {o: float(x) for o, x in zip(self.fmt.outputs, out)}, "status": int(status), "far": far,
            "temp": _num(temp),
            "rate": self.rate, "errors": {**self.array.counts.as_dict(), "total": self.array.counts.total},
            "zero": {"updates": 0 if az is None else len(az.updates),
                     "last": None if az is None or not az.updates else az.updates[-1].describe()}})

    def run(self, *, rate: float | None = None, count: int | None = None, duration: float | None = None,
            stop=lambda: False, flush_every: float = 0.0) -> ReadoutStats:
        """Samples until ``count``, ``duration`` (s) or ``stop()``; at ``rate`` Hz when given.

        Pacing keeps to a fixed grid (t0 + i/rate); a sample later than one period
        is counted as late and the grid restarts from it, so a stall never turns
        into a burst. ``flush_every``: seconds between flushes of the sink (0: each line).
        """
        if rate is not None and not (rate > 0 and math.isfinite(rate)):
            raise InputError(f"--rate must be a positive number of samples per second, got {rate}")
        clock = self.clock
        st = self.stats = ReadoutStats(errors=self.array.counts)
        period = 1.0 / rate if rate else 0.0
        t0 = clock.monotonic()
        next_t, last_flush = t0, t0
        try:
            while not stop():
                if count is not None and st.samples >= count:
                    break
                now = clock.monotonic()
                if duration is not None and now - t0 >= duration:
                    break
                if period:
                    if now < next_t and not _wait(clock, next_t, stop, None if duration is None else t0 + duration):
                        break  # stopped, or the duration ended, during the wait: no sample after it
                    if now - next_t > period:
                        st.late += 1
                        next_t = now
                    next_t += period
                started = clock.monotonic()
                self.step()  # a chip gone silent raises here: a sample never counted is no part of the pace
                st.first, st.last = (started if st.samples == 1 else st.first), started
                if self._flush is not None and clock.monotonic() - last_flush >= flush_every:
                    self._flush()
                    last_flush = clock.monotonic()
        except DeviceSilent as exc:
            st.elapsed = clock.monotonic() - t0
            exc.stats = st
            raise
        finally:
            if self._flush is not None:
                try:
                    self._flush()
                except (BrokenPipeError, ValueError):
                    pass
        st.elapsed = clock.monotonic() - t0
        return st

