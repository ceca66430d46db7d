"""Replay: a recorded run (``read``/``view --record``) re-estimated with another model or other corrections.

The record holds the ADC volts before any correction and the temperature of every sample, and its
first line the model and the corrections in force (tare, auto-zero settings and starting zero,
temperature compensation). Replaying with the same model and corrections repeats the readout's
arithmetic in the same order (Python engine), so it reproduces the recorded estimates exactly;
with another model, auto-zero on or off, or another compensation, it reports how the estimates move.
"""

from __future__ import annotations

import io
import json
import math
import time
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from fitgen.base.errors import InputError
from fitgen.base.fileio import read_text, write_atomic
from fitgen.c.codegen import check_magnitudes
from fitgen.equations.model import Model, check_input_units, load_model, model_from_dict
from fitgen.physics.sensor import MAX_VOLTS

from host.autozero import AutoZero, AutoZeroSettings
from host.readout import FAR_HELD, FAR_OUTSIDE, Corrections, RunRecord, held_up
from host.temperature import load_tempcomp, tempcomp_from_dict
from host.tempunit import model_note

BLOCK = 2048  # samples estimated at once: the model's per-call overhead spread, the memory bounded


@dataclass
class Run:
    header: dict
    t: np.ndarray
    raw: np.ndarray
    temp: np.ndarray
    out: np.ndarray
    status: np.ndarray
    torn: int = 0  # the number of a last line cut short by a stop, dropped (0: none)
    read_s: np.ndarray | None = None  # per sample, s the elements' read took (NaN: not recorded, as older runs)

    @property
    def n_inputs(self) -> int:
        return int(self.raw.shape[1])


def load_run(path) -> Run:
    origin = f"run {path}"
    text = read_text(path, "run record")
    numbered = [(i, ln) for i, ln in enumerate(text.splitlines(), start=1) if ln.strip()]
    whole = text.rstrip(" \t").endswith("\n")  # a stop cuts a line short before its newline; one after it is damage
    lines = [ln for _, ln in numbered]
    try:
        header = json.loads(lines[0]) if lines else None
    except ValueError:
        header = None
    if not isinstance(header, dict) or header.get("run") != 1:
        raise InputError(f"{origin}: not a run record (its first line must be the run's header; record one with "
                         "tactile-host read --record RUN.jsonl)")
    n, outputs = header.get("n_inputs"), header.get("outputs", [])
    if type(n) is not int or n < 1 or not isinstance(outputs, list) or not all(isinstance(o, str) for o in outputs):
        raise InputError(f"{origin}: its header's n_inputs ({n!r}) or outputs ({outputs!r}) are not as tactile-host "
                         "read writes them (a whole number >= 1; a list of names)")
    t, raw, temp, out, status, took, torn = [], [], [], [], [], [], 0
    m = len(outputs)
    for k, (i, ln) in enumerate(numbered[1:], start=2):
        try:
            rec = json.loads(ln)
            row = [float(x) for x in rec["raw"]]
            o = [float(x) for x in rec["out"]]
            tt, st = float(rec["t"]), int(rec["status"])
            tp = math.nan if rec.get("temp") is None else float(rec["temp"])
            rs = math.nan if rec.get("read_s") is None else float(rec["read_s"])
        except (ValueError, KeyError, TypeError, OverflowError):  # a number past a float's range too
            if k == len(lines) and not whole:
                torn = i  # a last line cut short by a stop: dropped, and said
                break
            raise InputError(f"{origin}: line {i} is not a sample") from None
        if len(row) != n or len(o) != m:
            raise InputError(f"{origin}: line {i} has {len(row)} readings and {len(o)} outputs; the header says {n} "
                             f"and {m}")
        # what read writes: a clock's time, ADC volts, a temperature or null (a NaN time or 1e308 V had replayed)
        if not (math.isfinite(tt) and all(abs(x) <= MAX_VOLTS for x in row) and not math.isinf(tp)
                and not rs < 0 and not math.isinf(rs)):
            raise InputError(f"{origin}: line {i} is not a sample read records (its time must be finite, its "
                             f"readings ADC volts within +-{MAX_VOLTS:g}, its temperature a number or null, its "
                             "read's seconds a number >= 0 or null)")
        t.append(tt), raw.append(row), temp.append(tp), out.append(o), status.append(st), took.append(rs)
    if not t:
        raise InputError(f"{origin}: no samples")
    return Run(header, np.array(t), np.array(raw), np.array(temp), np.array(out), np.array(status), torn,
               np.array(took))


def play_times(t: np.ndarray, longest: float = 10.0) -> np.ndarray:
    """Seconds from the first sample at which to play each: the recorded gaps, except that a gap that runs
    backwards or is longer than ``longest`` times the median (the wall clock stepped: an NTP sync on a Pi without a
    real-time clock) is played as the median gap."""
    gaps = np.diff(np.asarray(t, dtype=float))
    if gaps.size == 0:
        return np.zeros(len(t))
    typical = float(np.median(gaps[gaps > 0])) if np.any(gaps > 0) else 0.0
    gaps = np.where((gaps < 0) | (gaps > longest * max(typical, 1e-3)), typical, gaps)
    return np.concatenate([[0.0], np.cumsum(gaps)])


@dataclass
class ReplayResult:
    t: np.ndarray
    raw: np.ndarray
    temp: np.ndarray
    v: np.ndarray
    out: np.ndarray
    status: np.ndarray
    recorded: np.ndarray
    outputs: tuple[str, ...]
    model_hash: str
    same_model: bool
    updates: list
    notes: list
    header: dict  # the re-estimation's run-record header: its model and the corrections at the start
    recorded_outputs: tuple = ()  # the names of the recorded estimates' columns (the run's header's)
    far: np.ndarray | None = None  # per sample: estimated far outside the model's fitted pose box (Model.far_outside)
    read_s: np.ndarray | None = None  # per sample: s its read took, as recorded (NaN: not)

    @cached_property
    def held(self) -> np.ndarray | None:
        """Per sample, whether its read was held up between its conversions (host.readout.held_up: against the
        quickest recorded read so far, as the readout kept it); None without recorded times."""
        if self.read_s is None:
            return None
        with np.errstate(invalid="ignore"):  # NaN, not timed: not held
            return held_up(self.read_s, np.fmin.accumulate(self.read_s))

    @property
    def exact(self) -> bool:
        return self.out.shape == self.recorded.shape and bool(np.array_equal(self.out, self.recorded))

    def sample(self, i: int) -> dict:
        """Sample ``i`` as the live view's hub takes it."""
        n_up = sum(1 for u in self.updates if u.t <= self.t[i])
        return {"t": float(self.t[i]), "v": self.v[i].tolist(), "raw": self.raw[i].tolist(),
                "out": {o: float(x) for o, x in zip(self.outputs, self.out[i])}, "status": int(self.status[i]),
                "far": bool(self.far is not None and self.far[i]), "held": bool(self.held is not None and self.held[i]),
                "temp": None if not math.isfinite(self.temp[i]) else float(self.temp[i]), "rate": None,
                "errors": None, "zero": {"updates": n_up, "last": self.updates[n_up - 1].describe() if n_up else None}}

    def report(self) -> str:
        lines = [f"replayed {len(self.t)} samples with model {self.model_hash[:12]}"
                 f"{' (the recording model)' if self.same_model else ''}; auto-zero updates {len(self.updates)}"]
        lines += [f"note: {n}" for n in self.notes]
        if self.far is not None:  # a read held up is not the model's fault, nor another sensor's, as read counts it
            held = self.far & self.held if self.held is not None else np.zeros(len(self.far), dtype=bool)
            for count, said in ((int(np.sum(self.far & ~held)), FAR_OUTSIDE), (int(np.sum(held)), FAR_HELD)):
                if count:
                    lines.append(f"warning: {count} of {len(self.t)} samples {said}")
        # the recorded columns' names: the run's header's, else (a header without them) the model's where as many
        rec = (tuple(self.recorded_outputs) if len(self.recorded_outputs) == self.recorded.shape[1]
               else self.outputs if self.out.shape == self.recorded.shape else ())
        shared = [o for o in self.outputs if o in rec]
        if self.exact:
            lines.append("estimates identical to the recorded ones")
        elif shared and len(self.out) == len(self.recorded):
            if rec != self.outputs:  # another model's outputs: the ones both have, by name
                lines.append(f"the recorded run has outputs {', '.join(rec)}: differences in {', '.join(shared)}")
            d = self.out[:, [self.outputs.index(o) for o in shared]] - self.recorded[:, [rec.index(o) for o in shared]]
            lines.append("| output | max abs difference | RMS difference |")
            lines.append("| --- | --- | --- |")
            for j, o in enumerate(shared):
                lines.append(f"| {o} | {np.abs(d[:, j]).max():.4g} | {np.sqrt(np.mean(d[:, j] ** 2)):.4g} |")
        else:
            lines.append("the recorded run has other outputs: no differences computed")
        return "\n".join(lines) + "\n"

    def play(self, publish, stop, hold: bool = False) -> int:
        """Each sample to ``publish`` at the run's recorded pace, until its end or ``stop()``; with ``hold``,
        then wait for ``stop()``. The number of samples published."""
        due, w0, played = play_times(self.t), time.monotonic(), 0
        for i in range(len(self.t)):
            while not stop() and (wait := due[i] - (time.monotonic() - w0)) > 0:
                time.sleep(min(wait, 0.2))  # in slices: Ctrl-C is seen during a long gap
            if stop():
                break
            publish(self.sample(i))
            played += 1
        while hold and not stop():
            time.sleep(0.2)
        return played

    def save(self, path) -> None:
        """The re-estimated run as a run record (replayable in its turn), written atomically."""
        buf = io.StringIO()
        rec = RunRecord(buf, self.header)
        for i in range(len(self.t)):
            rec.write(float(self.t[i]), self.raw[i], float(self.temp[i]), self.out[i], int(self.status[i]),
                      math.nan if self.read_s is None else float(self.read_s[i]))
        write_atomic(path, buf.getvalue())


def _recorded_model(run: Run) -> Model | None:
    data = run.header.get("model_file")
    return model_from_dict(data, "the run's model") if isinstance(data, dict) else None


def replay(run: Run, *, model: str | Model | None = None, auto_zero: bool | None = None,
           temp_comp: str | None = None, no_temp_comp: bool = False, progress=None) -> ReplayResult:
    """Re-estimate ``run``; ``auto_zero`` / temperature compensation None: as recorded. ``progress``: a
    fitgen.base.progress.Progress over the samples."""
    h, notes = run.header, []
    if isinstance(model, str):
        model = load_model(model)
    try:
        recorded = _recorded_model(run)
    except InputError:
        if model is None:
            raise
        recorded = None  # a model given replaces it
    if model is None:
        model = recorded
        if model is None:
            raise InputError("the run does not carry its model: give --model")
    if model.n_inputs != run.n_inputs:
        raise InputError(f"the model takes {model.n_inputs} inputs; the run has {run.n_inputs} readings per sample")
    units = recorded.input_units if recorded is not None else "V"  # tactile-host read records ADC volts
    check_input_units(model, units, "the run's readings")
    # the arithmetic the run was estimated in: the C engine's float is the float header's, emulated bit for bit
    precision = h.get("precision", "double") if h.get("precision") in ("double", "float") else "double"
    check_magnitudes(model, precision)  # as predict and codegen: estimates always finite
    same = model.sha256 == h.get("model")
    if temp_comp and no_temp_comp:
        raise InputError("give --temp-comp or --no-temp-comp, not both")
    try:
        moved = None if same or h.get("reference") is None else _own_rest(model, h, run.n_inputs, notes)
        corrections = _corrections(run, model, temp_comp, no_temp_comp, auto_zero, moved and moved[0])
    except InputError:  # already says what is wrong, with the option or the header field
        raise
    except (KeyError, TypeError, ValueError, AttributeError, OverflowError) as exc:  # a header edited by hand
        raise InputError(f"the run's header records corrections that are not as tactile-host read writes them "
                         f"({type(exc).__name__}: {exc})") from None
    header = {**{k: v for k, v in h.items() if k != "run"}, "model": model.sha256,
              **({} if moved is None else {"reference": moved[0].tolist(), "rest_source": moved[1]}),
              "outputs": list(model.output_names), **corrections.describe(), "model_file": model.to_dict()}
    v_all, out_all, st_all = _estimate(run, model, precision, corrections, progress)
    if not same:
        notes.append(f"the run was recorded with model {str(h.get('model'))[:12]}")
    if run.torn:
        notes.append(f"its last line (line {run.torn}) was cut short, as a stopped run leaves one: left out")
    now = None if corrections.tempcomp is None else corrections.tempcomp.to_dict()
    if (h.get("tare") is not None or h.get("auto_zero")) and now != h.get("temp_comp"):
        notes.append(f"the run's tare was taken {'through its' if h.get('temp_comp') else 'without a'} temperature "
                     f"compensation, and is replayed {'with another' if now else 'without one'}: away from the "
                     "compensation's t0 its offsets no longer map the rest onto the model's (a tare of its own, as "
                     "read --tare --temp-comp takes, would)")
    whose = f"--temp-comp {temp_comp}" if temp_comp else "the run's temperature compensation"
    if corrections.tempcomp is not None and (note := model_note(model, corrections.tempcomp, whose)):
        notes.append(note.removeprefix("note: "))  # another unit's, as read notes it
    az = corrections.autozero
    return ReplayResult(run.t, run.raw, run.temp, v_all, out_all, st_all, run.out,
                        tuple(model.output_names), model.sha256, same, [] if az is None else az.updates, notes,
                        header, tuple(o for o in h.get("outputs", ()) if isinstance(o, str)),
                        model.far_outside(out_all) & (st_all >= 0), run.read_s)


def _estimate(run: Run, model: Model, precision: str, corrections: Corrections, progress):
    """(model inputs, estimates, statuses) of every sample, as the readout made them one at a time, in blocks:
    the model's arithmetic is row by row, so a block gives each row's bits; auto-zero sees every sample in
    order, and the block after an update starts again from the next sample with the new zero."""
    n = len(run.t)
    comp = corrections.compensated(run.raw, run.temp)
    v_all, out_all, st_all = np.empty_like(run.raw), np.empty((n, len(model.equations))), np.empty(n, dtype=int)
    az = corrections.autozero
    i = 0
    while i < n:
        j = min(n, i + BLOCK)
        v = corrections.zeroed(comp[i:j])
        out, status = model.predict(v, with_status=True, precision=precision)
        k = j
        if az is not None:
            for r in range(i, j):
                if corrections.observe(run.t[r], comp[r], out[r - i], int(status[r - i])) is not None:
                    k = r + 1  # the zero moved: the samples after this one are estimated again
                    break
        v_all[i:k], out_all[i:k], st_all[i:k] = v[:k - i], out[:k - i], status[:k - i]
        if progress is not None:
            progress.update(k - i)
        i = k
    return v_all, out_all, st_all


def _own_rest(model: Model, header: dict, n: int, notes: list) -> tuple[np.ndarray, str] | None:
    """The rest readings another model than the recording's tares onto (its own sensor's, as read --tare takes
    them), where they differ from the run's and the run took the recording model's own (its header's
    ``rest_source``; a rest the user chose with --rest is kept); None to keep the run's. InputError when
    the run's is kept and the model reads it as a pose far from rest: another sensor's model, which the tare
    would bend. With the rest readings, whose they are."""
    from host.rest import check_rest_reference, model_rest

    old = np.asarray(header["reference"], dtype=float)
    if old.shape != (n,):
        raise InputError(f"the run's header records {old.size} rest readings for {n} readings")
    source = header.get("rest_source")
    chosen = isinstance(source, str) and source.startswith("--rest ")  # read's --sensor is its sensor's own rest
    found = None if chosen else model_rest(model, required=False)
    if found is None:
        why = ("the run was tared onto the rest the user gave it" if chosen else "this model names no rest of its "
               "own to tare onto (the sensor file it was fitted on, found here, or a rest it records)")
        check_rest_reference(model, old, f"the run's tare ({source or 'its recording model'}'s rest)",
                             f"{why}: replay with a model of the sensor the run was read from")
        return None
    new, whose = found
    if np.array_equal(new, old):
        return None
    notes.append(f"the run's tare taken again onto the rest readings of {whose}, as read --tare takes them with this "
                 "model: the rest the run measured, less those")
    return new, whose


def _finite(values, what: str) -> None:
    """InputError when header ``values`` (None: not recorded) hold a number that is not finite: every estimate
    corrected by them would be NaN, replayed without a word."""
    if values is not None and not np.all(np.isfinite(values)):
        raise InputError(f"the run's header records {what} with a number that is not finite (edited by hand?): every "
                         "estimate corrected by it would be NaN")


def _corrections(run: Run, model: Model, temp_comp, no_temp_comp: bool, auto_zero, rest=None) -> Corrections:
    """The corrections to replay ``run`` with: a compensation file or the header's, its tare, its auto-zero; with
    ``rest``, the tare and auto-zero's zero taken onto those rest readings instead of the run's."""
    h, n = run.header, run.n_inputs
    tc = None
    if temp_comp:
        tc = load_tempcomp(temp_comp)
    elif not no_temp_comp and h.get("temp_comp"):
        tc = tempcomp_from_dict(h["temp_comp"], "the run's header: temp_comp")
    if tc is not None and (tc.n != n or tc.gain.shape != tc.offset.shape):
        raise InputError(f"{f'--temp-comp {temp_comp}' if temp_comp else 'the header temp_comp'} has {tc.n} "
                         f"elements; the run has {n} readings per sample")
    if tc is not None and not np.isfinite(run.temp).any():
        who = f"--temp-comp {temp_comp}" if temp_comp else "the run's header names a temperature compensation, but it"
        raise InputError(f"{who} needs the run's temperatures, and this run recorded none (it was read without a "
                         "thermistor: temp= in read's --adc)")
    tare = None if h.get("tare") is None else np.array(h["tare"], dtype=float)
    if tare is not None and tare.shape != (n,):
        raise InputError(f"the run's header records a tare of {tare.size} offsets for {n} readings")
    _finite(tare, "a tare")
    moved = 0.0 if rest is None else np.asarray(h["reference"], dtype=float) - rest  # the offsets onto ``rest``
    _finite(moved, "rest readings")
    tare = None if tare is None else tare + moved
    az_rec = h.get("auto_zero")
    use_az = bool(az_rec) if auto_zero is None else auto_zero
    az = None
    if use_az:
        ref, noise = h.get("reference"), h.get("noise")
        if ref is None or noise is None:
            who = "--auto-zero" if auto_zero else "the run's header asks for auto-zero, which"
            raise InputError(f"{who} needs the rest readings and the noise floor, which a run records only when it "
                             "was read with --tare or --auto-zero, and this one was not")
        settings = AutoZeroSettings(**{k: az_rec[k] for k in AutoZeroSettings.__dataclass_fields__ if k != "test"},
                                    test=az_rec.get("test", "sample")) if az_rec else AutoZeroSettings()
        start = np.asarray(az_rec["start"], dtype=float) + moved if az_rec else tare
        if start is not None and np.shape(start) != (n,):
            raise InputError(f"the run's header records an auto-zero start of {np.size(start)} offsets for {n} "
                             "readings")
        ref = np.array(ref, dtype=float) if rest is None else rest
        if ref.shape != (n,):
            raise InputError(f"the run's header records {ref.size} rest readings for {n} readings")
        _finite(start, "an auto-zero start")
        _finite(ref, "rest readings")
        floor = float(noise)
        if not (math.isfinite(floor) and floor >= 0):
            raise InputError(f"the run's header records a noise floor of {noise}, not a figure >= 0 (edited by hand?)")
        az = AutoZero.for_model(model, ref, floor, zero=start, settings=settings)
    return Corrections(tare, tc, az)
