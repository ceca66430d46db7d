"""The live readout: read every element, estimate the pose, write a timestamped line; pace, count (the tare: host.rest).

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

from fitgen.base.errors import InputError

from host.adc import AdcArray, DeviceSilent, ErrorCounts
from host.clock import REAL_CLOCK
from host.temperature import BEYOND_DEGC

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


UNCOMPENSATED = ("not compensated for temperature: the thermistor read none (is it connected? does its chip's --pga "
                 "read its divider's reference?)")
FAR_OUTSIDE = ("estimated outside the pose box the model was fitted in by more than its width: another sensor than "
               "the model's? a built unit needs its own calibration (docs/calibration.md)")
TEMP_BEYOND = "at a temperature the compensation was not fitted near, where it is extrapolated"
FAR_HELD = ("estimated outside the pose box the model was fitted in by more than its width, from a read held up "
            "between its conversions (a loaded machine, or I2C retries): a sensor that moved meanwhile gives readings "
            "of two poses, which no pose gives")
# a read that took this many times the quickest, and this much longer (s), was held up between its conversions
HELD_FACTOR, HELD_MARGIN = 3.0, 0.02


def held_up(took, quickest):
    """Whether a read that took ``took`` s was held up between its conversions, the quickest so far taking
    ``quickest`` (arrays element by element; a read not timed, NaN, was not)."""
    return took > np.maximum(HELD_FACTOR * quickest, quickest + HELD_MARGIN)
# ReadoutStats' counts of samples whose estimates are off while the run goes on: each said at its first sample
# (Readout.warn) and in the summary
WARNED = {"uncompensated": UNCOMPENSATED, "temp_beyond": TEMP_BEYOND,
          "far": FAR_OUTSIDE, "far_held": FAR_HELD}


@dataclass
class ReadoutStats:
    samples: int = 0
    elapsed: float = 0.0
    late: int = 0  # samples that started later than the pace by more than a period
    clipped: int = 0  # samples with an input at its converter's full scale
    outside: int = 0  # samples with an input outside the model's fitted domain (status > 0)
    far: int = 0  # samples estimated outside the model's fitted pose box by more than its width
    far_held: int = 0  # ... from a read held up between its conversions (not counted in far)
    # samples a temperature compensation was given for and the thermistor read none (in T_RANGE: outside it, a fault)
    uncompensated: int = 0
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


def _wait(clock, until: float, stop, end: float | None) -> bool:
    """Sleep until ``until`` in slices, so that a stop or the run's ``end`` ends the wait; False when one did."""
    while (now := clock.monotonic()) < until:
        if stop() or (end is not None and now >= end):
            return False
        clock.sleep(min(WAIT_SLICE, until - now) if end is None else min(WAIT_SLICE, until - now, end - now))
    return not stop() and (end is None or clock.monotonic() < end)


WAIT_SLICE = 0.1  # s: how late a Ctrl-C during a slow --rate's wait is seen


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
    start; then per sample ``{"t", "raw", "temp", "out", "status", "read_s"}``: the ADC volts before any
    correction, the temperature (null without a thermometer), the estimates, the status and the seconds the
    elements' read took (null where not timed), by which a replay tells a read held up between its conversions.
    """

    def __init__(self, sink, header: dict):
        self.sink = sink
        sink.write(json.dumps({"run": 1, **header}) + "\n")

    def write(self, t: float, raw, temp: float, out, status: int, read_s: float = math.nan) -> None:
        self.sink.write(json.dumps({"t": t, "raw": [float(x) for x in raw], "temp": _num(temp),
                                    "out": [float(x) for x in out], "status": int(status),
                                    "read_s": _num(read_s)}) + "\n")


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
        self._quickest = math.inf  # s: the quickest read so far, what a read takes

    def step(self) -> None:
        began = self.clock.monotonic()
        raw = self.array.read_volts()
        took = self.clock.monotonic() - began
        self._quickest = quickest = min(self._quickest, took)
        held = bool(held_up(took, quickest))
        temp = self.thermometer.read() if self.thermometer is not None else math.nan
        comp, v = self.corrections(raw, temp)
        out, status = self.engine.estimate(v)
        t = self.clock.time()
        self.corrections.observe(t, comp, out, status)
        if self._write is not None:
            self._write(self.fmt.line(t, v, out, status))
        if self.record is not None:
            self.record.write(t, raw, temp, out, status, took)
        st = self.stats
        st.samples += 1
        if status:
            st.outside += 1
        far = False
        if status >= 0 and self._far_cols:
            est = np.asarray(out, dtype=float)[self._far_cols]
            far = bool(np.any((est < self._far_lo) | (est > self._far_hi)))
            if far:  # a read held up is not the model's fault, nor another sensor's
                self._count(*(("far_held", f" ({took * 1e3:.0f} ms where a read takes {quickest * 1e3:.0f} ms)")
                              if held else ("far",)))
        if self.array.clipped.any():
            st.clipped += 1
        if self.corrections.tempcomp is not None:
            self._check_temperature(temp)
        if self.observer is not None:
            self._publish(t, raw, v, out, status, temp, far, held)

    def _check_temperature(self, temp: float) -> None:
        """Count a sample the compensation did not apply to, or applied outside its range."""
        if not math.isfinite(temp):
            self._count("uncompensated", f": {self.thermometer.fault()}" if self.thermometer is not None else "")
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

    def _publish(self, t, raw, v, out, status, temp, far=False, held=False) -> None:
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
            "held": held,
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

