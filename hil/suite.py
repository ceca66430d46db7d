"""The HIL suite: the same vectors through a device and through Python, calibration flashing, and fuzzing.

Each check talks to a :class:`host.device.Device` and returns a :class:`Check`; ``run_suite``
runs them in order and stops early only when the device stops answering.
"""

from __future__ import annotations

import contextlib
import statistics
import time
import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from xml.sax.saxutils import escape, quoteattr

import numpy as np

from fitgen.c.calblob import to_blob
from fitgen.base.errors import InputError
from fitgen.base.fileio import write_atomic
from fitgen.equations.model import Equation, Model
from fitgen.base.progress import Progress
from host import protocol as P
from hil.fuzz import fuzz_frames
from host.device import Device, DeviceError, NoAnswer
from fitgen.c.verify import MAX_SHARE, VerifyResult, compare, compare_fixed, held_out_check, make_code_vectors, make_vectors


@dataclass
class Check:
    name: str
    ok: bool
    detail: str
    seconds: float = 0.0
    figures: dict = field(default_factory=dict)


@dataclass
class SuiteResult:
    url: str
    checks: list[Check]
    seconds: float = 0.0  # the whole suite, wall time (its checks, and the synchronisation before them)

    @property
    def ok(self) -> bool:
        return all(c.ok for c in self.checks)

    def table(self) -> str:
        lines = [f"HIL suite on {self.url}: {len(self.checks)} checks in {self.seconds:.1f} s",
                 "| check | result | seconds | detail |", "| --- | --- | --- | --- |"]
        lines += [f"| {c.name} | {'pass' if c.ok else 'FAIL'} | {c.seconds:.1f} | {c.detail} |" for c in self.checks]
        return "\n".join(lines)

    def junit(self) -> str:
        fails = sum(not c.ok for c in self.checks)
        total = self.seconds or sum(c.seconds for c in self.checks)
        out = ['<?xml version="1.0" encoding="UTF-8"?>',
               f'<testsuite name="tactile-hil" tests="{len(self.checks)}" failures="{fails}" errors="0" '
               f'time="{total:.3f}">']
        for c in self.checks:
            out.append(f'  <testcase classname="hil" name={quoteattr(c.name)} time="{c.seconds:.3f}">')
            if c.ok:
                out.append(f"    <system-out>{escape(c.detail)}</system-out>")
            else:
                out.append(f"    <failure message={quoteattr(c.detail)}/>")
            out.append("  </testcase>")
        out.append("</testsuite>")
        return "\n".join(out) + "\n"

    def write_junit(self, path: str | Path) -> Path:
        return write_atomic(path, self.junit())


class DeviceEvaluator:
    """A device seen as ``fitgen.c.verify.compare`` sees a compiled model: precision, style, fma, predict."""

    def __init__(self, device: Device, precision: str, style: str, fma: bool = False, progress=None):
        self.device, self.precision, self.style, self.fma, self.progress = device, precision, style, fma, progress

    def predict(self, inputs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        status, out = eval_rows(self.device, inputs, self.progress)
        return np.asarray(out, dtype=float), np.asarray(status)


def eval_rows(dev: Device, rows: np.ndarray, progress: Progress | None = None, chunk: int = 64):
    """``dev.eval`` of ``rows``, ``chunk`` at a time when a ``progress`` bar moves with them (a slow board's
    thousand vectors take seconds)."""
    if progress is None:
        return dev.eval(rows)
    parts = []
    for start in range(0, len(rows), chunk):
        parts.append(dev.eval(rows[start:start + chunk]))
        progress.update(len(rows[start:start + chunk]))
    return (np.concatenate([p[0] for p in parts]), np.vstack([p[1] for p in parts])) if parts else dev.eval(rows)


def flash_variant(model: Model) -> Model:
    """A second calibration for the flash checks: the same terms, coefficients scaled by 1.001 and
    intercepts moved, so that its hash and its answers differ from the compiled-in model's. Harmonic
    terms and a refinement are left out: the blob format has neither (the firmware's interpreter
    evaluates powers only)."""
    eqs = tuple(Equation(e.name, e.intercept + 0.01, tuple(t for t in e.terms if not t.harm),
                         tuple(c * 1.001 for t, c in zip(e.terms, e.coefficients) if not t.harm))
                for e in model.equations)
    return dataclasses.replace(model, equations=eqs, fit_info=dict(model.fit_info), refine=None)


def _verify_detail(res: VerifyResult) -> str:
    worst = float(np.max(res.max_ratio)) if len(res.max_ratio) else 0.0
    text = f"{res.n_vectors} vectors, max error " + ", ".join(
        f"{n} {e:.3g}" for n, e in zip(res.outputs, res.max_error)) + f"; worst error/bound {worst:.3g}"
    return text if res.ok else text + "; " + "; ".join(res.failures)


def check_info(dev: Device, model: Model) -> Check:
    """The counts and model hash are the model's; a loaded calibration (the Uno's outlives a reset) is reset first."""
    info, was = dev.info(refresh=True), ""
    if info.cal_source != 0:
        was = f"; a loaded calibration (model {info.model_hash[:12]}) was active: reset to the compiled-in model"
        dev.reset_calibration()
        info = dev.info(refresh=True)
    problems = []
    if info.n_inputs != model.n_inputs or info.n_outputs != len(model.equations):
        problems.append(f"device takes {info.n_inputs} inputs and gives {info.n_outputs} outputs, "
                        f"the model {model.n_inputs} and {len(model.equations)}")
    if info.model_hash != model.sha256:
        problems.append(f"device runs model {info.model_hash[:12]}, not {model.sha256[:12]}")
    detail = (f"protocol {info.protocol_version}, firmware {info.firmware_version}, {info.precision}, "
              f"{info.style_name}, model {info.model_hash[:12]}, sensor {info.sensor_id}")
    return Check("info", not problems, ("; ".join(problems) or detail) + was)


def check_eval(dev: Device, model: Model, inputs: np.ndarray, name: str, fma: bool = False, progress=None) -> Check:
    info = dev.info()
    res = compare(model, DeviceEvaluator(dev, info.precision, info.style_name, fma, progress), inputs)
    return Check(name, res.ok, _verify_detail(res), figures={"max_error": res.max_error.tolist(),
                                                            "worst_ratio": float(np.max(res.max_ratio))})


class FixedDeviceEvaluator:
    """A fixed-point device seen as ``fitgen.c.verify.compare_fixed`` sees a compiled model."""

    style = "unrolled"  # the fixed-point header's one form

    def __init__(self, device: Device, fixed, progress=None):
        self.device, self.fixed, self.progress = device, fixed, progress

    def predict_codes(self, codes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        status, out = eval_rows(self.device, codes, self.progress)
        return np.asarray(out, dtype=np.int64), np.asarray(status)


def check_eval_fixed(dev: Device, model: Model, fixed, codes: np.ndarray, name: str, progress=None) -> Check:
    res = compare_fixed(model, FixedDeviceEvaluator(dev, fixed, progress), codes)
    lsb = int(np.max(res.max_lsb_diff))
    detail = _verify_detail(res) + f"; largest difference from the numpy integer model {lsb} LSB"
    return Check(name, res.ok, detail, figures={"max_error": res.max_error.tolist(),
                                                "worst_ratio": float(np.max(res.max_ratio)),
                                                "max_lsb_diff": lsb})


def check_held_out(dev: Device, model: Model, held_out: tuple[np.ndarray, np.ndarray], max_share: float,
                   fixed=None, progress=None) -> Check:
    """The device on noise-free held-out readings: rounding may add at most ``max_share`` of the
    model's own held-out max error (a fixed-point device gets the readings' ADC codes, and is
    compared with double on the codes' values)."""
    readings, truth = held_out
    c_inputs = None
    if fixed is not None:
        codes = fixed.codes_of(readings)
        out = fixed.to_real(FixedDeviceEvaluator(dev, fixed, progress).predict_codes(codes)[0])
        c_inputs = fixed.code_values(codes)
    else:
        info = dev.info()
        sent = readings.astype(np.float32).astype(float) if info.precision == "float" else readings
        out = DeviceEvaluator(dev, info.precision, info.style_name, progress=progress).predict(sent)[0]
    failures: list[str] = []
    chk = held_out_check(model, out, readings, truth, max_share, failures, c_inputs)
    detail = f"{len(readings)} held-out readings; rounding's share " + ", ".join(
        f"{n} {x:.1%}" for n, x in zip(model.output_names, chk.share)) + f" (at most {max_share:.0%})"
    return Check("held-out accuracy", not failures, detail + ("; " + "; ".join(failures) if failures else ""),
                 figures={"share": chk.share.tolist(), "deviation": chk.deviation.tolist(),
                          "model_max_error": chk.model_max.tolist()})


READ_FAILED = 0x40000000  # STREAM_SAMPLE status bit of a failed read (docs/protocol.md)


def check_stream(dev: Device, n: int = 5, period_ms: int = 10) -> Check:
    """STREAM ``n`` samples: every read succeeds, simulated inputs lie in the domain, and each sample's outputs are
    what the device's own EVAL gives for its inputs. Reports when the first and the last sample arrived after the
    request (under ``emulate --suite``, the first STREAM after boot: the firmware sets up its ADCs on it)."""
    arrivals: list[float] = []
    samples = dev.stream(period_ms, n, timeout=60.0, arrivals=arrivals)
    failed = [s.status for s in samples if s.status > 0 and s.status & READ_FAILED]
    inputs = np.array([np.asarray(s.inputs) for s in samples])
    status, out = dev.eval(inputs)
    same = np.array_equal(np.asarray(out), np.array([np.asarray(s.outputs) for s in samples])) and \
        np.array_equal(np.asarray(status), [s.status for s in samples])
    info = dev.info(refresh=True)
    source = (f"inputs from {len(info.adc_chips)} ADC chips, I2C counts "
              + ", ".join(f"{k} {v}" for k, v in info.adc_counts.items()) if info.adc_chips else "simulated inputs")
    # simulated inputs sweep the domain from within: a status is a domain misread (the Uno's, from RAM once)
    outside = [s.status for s in samples if s.status] if not info.adc_chips else []
    problems = ([f"{len(failed)} reads failed (first status 0x{failed[0]:08x})"] if failed else []) + \
        ([] if same else ["a sample's outputs differ from EVAL of its inputs"]) + \
        ([f"{len(outside)} simulated samples outside the model's domain (first status 0x{outside[0]:08x})"]
         if outside else [])
    timing = f"the first {arrivals[0]:.3f} s and the last {arrivals[-1]:.3f} s after the request"
    return Check("stream", not problems, "; ".join(problems) or f"{n} samples at {period_ms} ms, {timing}; {source}",
                 figures={"samples": n, "adc_counts": info.adc_counts, "first_sample_s": arrivals[0],
                          "last_sample_s": arrivals[-1]})


def check_fixed_refuses_blobs(dev: Device, model: Model, sensor_id: str) -> Check:
    """A fixed-point build has no blob interpreter: CAL_BEGIN must be refused and the model kept."""
    blob = to_blob(model, "float", sensor_id)
    try:
        dev.load_calibration(blob)
    except DeviceError as exc:
        kept = dev.info(refresh=True).model_hash == model.sha256
        ok = exc.code == P.ErrorCode.CAL_INVALID and kept
        return Check("flash (fixed point)", ok, f"blob refused with {P.error_name(exc.code)}; "
                     f"compiled-in model {'kept' if kept else 'LOST'}")
    return Check("flash (fixed point)", False, "a fixed-point build accepted a float calibration blob")


def check_timing(dev: Device, model: Model, n_single: int = 200, n_batch: int = 400, fixed=None,
                 batches: int = 1) -> Check:
    """Round trip of one-vector EVALs (median) and throughput of batched EVALs (the median over ``batches``
    timings of one ``n_batch``-vector EVAL)."""
    rng = np.random.default_rng(5)
    n = max(n_single, n_batch)
    if fixed is not None:
        x = rng.integers(np.array(fixed.code_min), np.array(fixed.code_max) + 1, (n, model.n_inputs))
    else:
        x = model.input_min + (model.input_max - model.input_min) * rng.random((n, model.n_inputs))
    rtt = []
    for row in x[:n_single]:
        t0 = time.perf_counter()
        dev.eval(row[None])
        rtt.append(time.perf_counter() - t0)
    rates = []
    for _ in range(batches):
        t0 = time.perf_counter()
        dev.eval(x[:n_batch])
        rates.append(n_batch / (time.perf_counter() - t0))
    rate = statistics.median(rates)
    med = statistics.median(rtt) * 1e3
    return Check("timing", True, f"round trip median {med:.2f} ms (min {min(rtt) * 1e3:.2f}), "
                 f"throughput {rate:,.0f} estimates/s batched (on the host's clock: through an emulator, its "
                 "pace, not the chip's)",
                 figures={"rtt_ms_median": med, "rtt_ms_min": min(rtt) * 1e3, "per_s": rate})


def check_flash(dev: Device, model: Model, new: Model, inputs: np.ndarray, sensor_id: str) -> Check:
    """Load a new calibration, read it back, and find the device answering with it."""
    info = dev.info()
    blob = to_blob(new, info.precision, sensor_id)
    answered = dev.load_calibration(blob)
    back = dev.read_calibration()
    info = dev.info(refresh=True)
    problems = []
    if back != blob:
        problems.append(f"read-back differs ({len(back)} bytes back for {len(blob)} sent)")
    if answered != new.sha256 or info.model_hash != new.sha256 or info.cal_source != 1:
        problems.append(f"device reports model {info.model_hash[:12]} (source {info.cal_source}), "
                        f"flashed {new.sha256[:12]}")
    res = compare(new, DeviceEvaluator(dev, info.precision, "table"), inputs)
    if not res.ok:
        problems.append("EVAL after flash: " + "; ".join(res.failures))
    harmonic = sum(bool(t.harm) for e in model.equations for t in e.terms)
    dropped = f" (a variant without the model's {harmonic} harmonic terms: a blob carries powers only)" * bool(harmonic)
    return Check("flash", not problems, "; ".join(problems) or
                 f"{len(blob)} bytes flashed and read back{dropped}; EVAL on {len(inputs)} vectors agrees with the new "
                 "model", figures={"blob_bytes": len(blob)})


def fit_store(model: Model, room: int, precision: str, sensor_id: str) -> Model:
    """``model`` with the first k terms of each equation, k the largest whose blob fits ``room`` bytes."""
    k = max(len(e.terms) for e in model.equations)
    while k > 0:
        eqs = tuple(Equation(e.name, e.intercept, e.terms[:k], e.coefficients[:k]) for e in model.equations)
        trimmed = dataclasses.replace(model, equations=eqs, fit_info=dict(model.fit_info))
        if len(to_blob(trimmed, precision, sensor_id)) <= room:
            return trimmed
        k -= 1
    raise ValueError(f"no calibration of this model fits a {room}-byte store")


def check_flash_too_big(dev: Device, model: Model, new: Model, room: int, sensor_id: str) -> Check:
    """A blob larger than the device's store: CAL_BEGIN refused, and the compiled-in model still answers."""
    from host.device import FlashFailed, flash_model

    size = len(to_blob(new, dev.info().precision, sensor_id))
    try:
        flash_model(dev, new, "the flash variant", sensor_id=sensor_id)
    except (FlashFailed, InputError) as exc:  # InputError: the store's refusal, said as the model's fault
        info = dev.info(refresh=True)
        kept = info.model_hash == model.sha256 and info.cal_source == 0
        said = f"{size}-byte" in str(exc) and f"{room}-byte" in str(exc)
        return Check("flash too big", kept and said, f"{str(exc).splitlines()[0]}; compiled-in model "
                     f"{'kept' if kept else 'LOST'}", figures={"blob_bytes": size, "store_bytes": room})
    return Check("flash too big", False, f"a {size}-byte blob was taken by a {room}-byte store")


def check_corrupt_flash(dev: Device, new: Model, inputs: np.ndarray, sensor_id: str) -> Check:
    """Corrupt, truncated and out-of-order transfers: each refused, the calibration before them kept."""
    info = dev.info()
    blob = to_blob(new, info.precision, sensor_id)
    before = dev.read_calibration()
    refused = []
    problems = []

    def expect_refusal(what, fn, codes):
        try:
            fn()
        except DeviceError as exc:
            if exc.code not in codes:
                problems.append(f"{what}: refused with {P.error_name(exc.code)}, expected "
                                f"{' or '.join(P.error_name(c) for c in codes)}")
            refused.append(what)
            return
        problems.append(f"{what}: accepted")

    bad = bytearray(blob)
    bad[len(bad) // 2] ^= 0x40
    expect_refusal("flipped byte", lambda: dev.load_calibration(bytes(bad)), {P.ErrorCode.CAL_CRC, P.ErrorCode.CAL_INVALID})
    # a blob whose CRC is right but whose content is not: a format version this firmware does not know
    forged = bytearray(blob)
    forged[4:6] = (99).to_bytes(2, "little")
    forged[-4:] = P.crc32(bytes(forged[:-4])).to_bytes(4, "little")
    expect_refusal("unknown format version", lambda: dev.load_calibration(bytes(forged)), {P.ErrorCode.CAL_INVALID})

    def truncated():
        dev.request(P.MsgType.CAL_BEGIN, P.pack_cal_begin(len(blob), P.crc32(blob)))
        dev.request(P.MsgType.CAL_DATA, P.pack_cal_data(0, blob[:100]))
        dev.request(P.MsgType.CAL_COMMIT, b"")

    expect_refusal("interrupted transfer", truncated, {P.ErrorCode.CAL_SEQUENCE})

    def out_of_order():
        dev.request(P.MsgType.CAL_BEGIN, P.pack_cal_begin(len(blob), P.crc32(blob)))
        dev.request(P.MsgType.CAL_DATA, P.pack_cal_data(100, blob[100:200]))

    expect_refusal("chunk out of order", out_of_order, {P.ErrorCode.CAL_SEQUENCE})
    after = dev.read_calibration()
    if after != before:
        problems.append("the active calibration changed")
    res = compare(new, DeviceEvaluator(dev, info.precision, "table"), inputs)
    if not res.ok:
        problems.append("EVAL after the refused transfers: " + "; ".join(res.failures))
    return Check("corrupt flash", not problems, "; ".join(problems) or
                 f"{len(refused)} bad transfers refused ({', '.join(refused)}); the old calibration still answers")


def sync(dev: Device, token: bytes, timeout: float | None = None) -> bool:
    """PING with a token no fuzz frame carries and read until its echo: every frame sent before has
    then been answered, so no stale reply is left to be taken for the next request's."""
    seq = dev.next_seq()
    dev.send(P.MsgType.PING, seq, token)
    t_end = time.monotonic() + (dev.timeout if timeout is None else timeout)
    while time.monotonic() < t_end:
        frame = dev.receive(max(0.0, t_end - time.monotonic()))
        if frame is not None and frame.type == (P.MsgType.PING | P.REPLY) and frame.payload == token:
            return True
    return False


def check_fuzz(dev: Device, n_frames: int, batch: int = 50, seed: int = 0, progress: Progress | None = None) -> Check:
    """Send ``n_frames`` bad or random frames in batches; after each batch the device must answer PING."""
    frames = fuzz_frames(n_frames, seed)
    rng_token = np.random.default_rng(seed + 1)
    sent = 0
    for start in range(0, len(frames), batch):
        chunk = frames[start:start + batch]
        dev.send_raw(b"".join(chunk))
        sent += len(chunk)
        # the token is 24 bytes; fuzz PINGs echo random payloads, so none can match it by chance
        if not sync(dev, b"hil-sync" + rng_token.bytes(16), timeout=max(dev.timeout, 10.0)):
            return Check("fuzz", False, f"device stopped answering after {sent} fuzz frames")
        if progress:
            progress.update(len(chunk))
    dev.reset_calibration()
    return Check("fuzz", True, f"{sent} random or mutated frames; the device answered PING after every {batch}",
                 figures={"frames": sent})


def run_suite(dev: Device, model: Model, *, url: str = "", n_vectors: int = 1000, data: np.ndarray | None = None,
              n_fuzz: int = 10_000, flash: bool = True, sensor_id: str = "paper", fma: bool = False,
              seed: int = 0, verbose: bool = True, input_lsb: float | None = None,
              input_offset: float | None = None, held_out: tuple[np.ndarray, np.ndarray] | None = None,
              max_share: float = MAX_SHARE, mul_bits: int | None = None) -> SuiteResult:
    """Every check in turn against the device at ``url`` that runs ``model`` compiled in.

    ``held_out``: noise-free held-out (readings, truth) for the rounding's-share check
    (fitgen.fitting.holdout.clean_readings); without it that check is not run.

    A fixed-point device (INFO precision 2) gets ADC codes, compared with the numpy model of its
    integer arithmetic (``input_lsb``/``input_offset`` as given to codegen; default: the ADS1115s' code the device
    reports reading, else the model's sensor), planned for the core's multiply width ``mul_bits``
    (fitgen.c.targets: 16 for the Uno; default: as the device's firmware version says).
    """
    t_suite = time.perf_counter()
    checks: list[Check] = []
    fixed = None
    info = dev.info(refresh=True)
    if info.precision == "fixed":
        from fitgen.equations.fixedpoint import build_fixed
        from fitgen.equations.inputscale import default_input_scale
        from hil.firmware import NARROW_TAG, reported_lsb

        if mul_bits is None:
            mul_bits = 16 if info.firmware_version.endswith(NARROW_TAG) else 32
        if input_lsb is None and info.adc_chips:
            input_lsb, input_offset = reported_lsb(info), 0.0
        lsb, offset, _ = default_input_scale(model) if input_lsb is None else (input_lsb, input_offset or 0.0, "")
        fixed = build_fixed(model, lsb, offset if input_offset is None else input_offset, mul_bits)
        inputs, _ = make_code_vectors(fixed, n_vectors, seed)
        if data is not None:
            inputs = np.vstack([inputs, fixed.codes_of(data)])
    else:
        inputs, _ = make_vectors(model, n_vectors, seed)
        if data is not None:
            inputs = np.vstack([inputs, data])

    def evaluate(subset, name):  # a bar on a terminal: thousands of vectors take seconds on a slow board
        with Progress(name, len(subset)) as prog:
            if fixed is not None:
                return step(check_eval_fixed, dev, model, fixed, subset, name, progress=prog)
            return step(check_eval, dev, model, subset, name, fma, progress=prog)

    def step(fn, *args, **kw):
        t0, lost, name = time.perf_counter(), None, fn.__name__.removeprefix("check_").replace("_", " ")
        try:
            c = fn(*args, **kw)
        except DeviceError as exc:
            # a refusal is this check's failure (a device built for another model refuses its calibration);
            # the other checks still run and the table says which failed
            c = Check(name, False, str(exc))
        except NoAnswer as exc:  # the device stopped: this check failed, and the table so far is the suite's
            lost, c = exc, Check(name, False, f"{exc}; the checks after it were not run")
        c.seconds = time.perf_counter() - t0
        checks.append(c)
        if kw.get("progress") is not None:
            kw["progress"].close()  # the bar's line cleared before the check's
        if verbose:
            print(f"  {c.name}: {'pass' if c.ok else 'FAIL'} ({c.seconds:.1f} s)", flush=True)
        if lost is not None:
            raise lost
        return c

    if not sync(dev, b"hil-start" + bytes(np.random.default_rng().bytes(16))):
        raise NoAnswer(f"{url or 'the device'} does not answer PING")
    try:
        step(check_info, dev, model)  # resets a loaded calibration first
        evaluate(inputs, "eval")
        running = dev.info().model_hash
        if held_out is not None and running != model.sha256:
            # its differences are another model's, not rounding's: say that rather than blame the arithmetic
            checks.append(Check("held-out accuracy", False, f"not measured: the device runs model {running[:12]}, not "
                                f"{model.sha256[:12]} (info)"))
            if verbose:
                print("  held-out accuracy: FAIL (not measured: another model)", flush=True)
        elif held_out is not None:
            with Progress("held-out accuracy", len(held_out[0])) as prog:
                step(check_held_out, dev, model, held_out, max_share, fixed, progress=prog)
        step(check_stream, dev)
        step(check_timing, dev, model, fixed=fixed)
        if flash and fixed is not None:
            step(check_fixed_refuses_blobs, dev, model, sensor_id)
        elif flash:
            new = flash_variant(model)
            few = inputs[: min(len(inputs), 300)]
            room = dev.cal_capacity()
            try:
                if len(to_blob(new, dev.info().precision, sensor_id)) > room:
                    # a store smaller than the blob (the Uno's EEPROM): refused, then the checks on the terms it
                    # takes
                    step(check_flash_too_big, dev, model, new, room, sensor_id)
                    new = fit_store(new, room, dev.info().precision, sensor_id)
                step(check_flash, dev, model, new, few, sensor_id)
                step(check_corrupt_flash, dev, new, few, sensor_id)
            except BaseException:  # Ctrl-C or a lost device mid-way: the suite's variant must not outlive it
                with contextlib.suppress(Exception):  # (an EEPROM keeps it across resets); the first error stands
                    dev.reset_calibration()
                raise
            dev.reset_calibration()
        if n_fuzz:
            with Progress("fuzz frames", n_fuzz) as prog:
                step(check_fuzz, dev, n_fuzz, seed=seed, progress=prog)
            evaluate(inputs[: min(len(inputs), 300)], "eval after fuzz")
    except NoAnswer as exc:  # lost between checks; a check's own loss is in the table already
        if not (checks and checks[-1].detail.endswith("were not run")):
            checks.append(Check("device", False, f"{exc}; the checks after it were not run"))
    return SuiteResult(url, checks, time.perf_counter() - t_suite)
