"""Verification of generated C against the Python evaluation: vectors, comparison, report."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from fitgen.c.codegen import check_magnitudes, float_domain
from fitgen.equations.fixedmodel import INT32_MAX, INT32_MIN, FixedModel
from fitgen.equations.model import Model
from fitgen.equations.rounding import U_DOUBLE, U_FLOAT, error_bound

from fitgen.c.compiled import CompiledModel

# double: a few roundings at the scale of the terms (the formula of fitgen.equations.rounding, times 4)
DOUBLE_SLACK = 4.0
# rounding may add at most this share of the model's own held-out max error (docs/deployed-accuracy.md)
MAX_SHARE = 0.05
# an a-priori bound more than this many times the measured worst case is reported as loose
LOOSE_BOUND = 10.0
# random vectors at most: 10^6 took 2.5 GB and 2 minutes for one float build; a typo's 10^11 would be 6 TB
MAX_VECTORS = 100_000


@dataclass
class HeldOutCheck:
    """Rounding's share on held-out readings: the C's largest deviation from the double model over
    the model's own held-out max error, per output."""

    deviation: np.ndarray
    model_max: np.ndarray
    max_share: float

    @property
    def share(self) -> np.ndarray:
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(self.deviation == 0, 0.0, self.deviation / self.model_max)


def add_held_out_options(parser) -> None:
    """The options of the rounding's-share check, shared by `tactile-host verify` and `tactile-hil`."""
    parser.add_argument("--max-share", type=float, metavar="S",
                        help="fail when rounding adds more than this share of the model's held-out max error "
                             f"(default {MAX_SHARE:g})")
    parser.add_argument("--sensor", help="the model's sensor (preset or TOML) for its held-out poses (default: the "
                                         "preset the model file names)")
    parser.add_argument("--no-held-out", action="store_true", help="skip the held-out rounding check")


def check_vectors(n: int, flag: str = "--vectors") -> int:
    """``n`` if it is a count of random vectors, 0..MAX_VECTORS; else InputError naming ``flag``."""
    from fitgen.base.errors import InputError

    if not 0 <= n <= MAX_VECTORS:
        raise InputError(f"{flag} must be a whole number from 0 to {MAX_VECTORS:,}, got {n}")
    return n


def data_inputs(model: Model, path: str) -> np.ndarray:
    """The readings of dataset ``path`` (``--data``); InputError unless they are as many, in the units, as
    ``model`` takes."""
    from fitgen.base.errors import InputError
    from fitgen.equations.model import check_input_units
    from fitgen.physics.dataset import load_dataset

    ds = load_dataset(path, min_rows=1)
    if ds.n_inputs != model.n_inputs:
        raise InputError(f"dataset {path} has {ds.n_inputs} inputs; the model takes {model.n_inputs}")
    check_input_units(model, ds.meta.get("units"), f"dataset {path}'s readings")
    return ds.inputs


def held_out_from_args(model: Model, args) -> tuple[np.ndarray, np.ndarray] | None:
    """The noise-free held-out (readings, truth) those options ask for; None when skipped or not to be had."""
    from fitgen.base.errors import InputError
    from fitgen.fitting.holdout import clean_readings, fitted_sensor
    from fitgen.physics.sensor import load_sensor

    if args.no_held_out:
        given = [flag for flag, value in (("--sensor", args.sensor), ("--max-share", args.max_share))
                 if value is not None]
        if given:
            raise InputError(f"{given[0]} is the held-out check's: with --no-held-out it would be ignored")
        return None
    args.max_share = MAX_SHARE if args.max_share is None else args.max_share  # None: not given (see above)
    if not 0 < args.max_share <= 1:  # as tradeoff's
        raise InputError(f"--max-share must be a share in (0, 1] of the model's held-out max error, got "
                         f"{args.max_share:g}")
    if args.sensor and not isinstance(model.fit_info.get("held_out"), dict):
        raise InputError(f"--sensor {args.sensor}: the model file has no held_out record to simulate on it again "
                         "(`fitgen fit` writes one when it knows the sensor); leave --sensor out")
    # another sensor's readings would measure rounding against errors that are not the model's
    sensor = (fitted_sensor(load_sensor(args.sensor), model, "its held-out check on this one would not be the "
                            "model's (give the one it was fitted on, or leave --sensor out)", given=args.sensor)
              if args.sensor else None)
    return clean_readings(model, sensor)


def no_held_out_note(model: Model) -> str:
    """Why a check without held-out readings (:func:`held_out_from_args` gave None) measured no rounding's share."""
    from fitgen.fitting.holdout import names_held_out_set

    rec = model.fit_info.get("held_out")
    if not isinstance(rec, dict):
        return ("note: rounding's share not measured: the model file has no held_out record (`fitgen fit` writes "
                "one when it knows the sensor)")
    if not names_held_out_set(rec):
        return ("note: rounding's share not measured: the model file's held_out record names no held-out set (its "
                "box, poses and seed, which `fitgen fit` writes)")
    return ("note: rounding's share not measured: the sensor the model file's held_out record names is not known "
            "here (give its file with --sensor)")


def held_out_check(model: Model, c_outputs: np.ndarray, readings: np.ndarray, truth: np.ndarray,
                   max_share: float, failures: list[str], c_inputs: np.ndarray | None = None) -> HeldOutCheck:
    """Compare the C's outputs on noise-free held-out ``readings`` with the double model; a failure
    line per output whose deviation exceeds ``max_share`` of the model's held-out max error.

    ``c_inputs``: the values the C actually took, when not the readings (a fixed-point build takes
    ADC codes): the double model is evaluated on them, so that the share is the arithmetic's and the
    input quantisation, like the noise, stays in the deployed error."""
    own = model.predict(readings)
    ref = own if c_inputs is None else model.predict(c_inputs)
    chk = HeldOutCheck(np.abs(c_outputs - ref).max(axis=0), np.abs(own - truth).max(axis=0), max_share)
    for j, name in enumerate(model.output_names):
        if chk.share[j] > max_share:
            failures.append(f"rounding adds {chk.share[j]:.1%} of {name}'s held-out max error "
                            f"({chk.deviation[j]:.3g} of {chk.model_max[j]:.3g}), over the {max_share:.0%} allowed")
    return chk


def make_vectors(model: Model, n_random: int = 2000, seed: int = 0) -> tuple[np.ndarray, list[str]]:
    """Inputs and a kind per row: random in the domain, its edges and corners, outside it,
    near zero, huge, and non-finite."""
    rng = np.random.default_rng(seed)
    lo, hi = model.input_min, model.input_max
    n_in = model.n_inputs
    mid = (lo + hi) / 2
    rows, kinds = [], []

    def add(block, kind):
        block = np.atleast_2d(block)
        rows.append(block)
        kinds.extend([kind] * len(block))

    add(lo + (hi - lo) * rng.random((n_random, n_in)), "random")
    add(np.vstack([lo, hi, mid]), "edge")
    for k in range(n_in):
        for val in (lo[k], hi[k], np.nextafter(lo[k], -np.inf), np.nextafter(hi[k], np.inf)):
            r = mid.copy()
            r[k] = val
            add(r, "edge")
    add(np.where(rng.random((64, n_in)) < 0.5, lo, hi), "corner")
    width = hi - lo
    add(lo - width * rng.uniform(0.01, 2.0, (200, n_in)), "outside")
    add(hi + width * rng.uniform(0.01, 2.0, (200, n_in)), "outside")
    for val in (0.0, -0.0, 1e-30, -1e-30, 1e-8, 1e30, -1e30, 3.0e38):
        r = mid.copy()
        r[rng.integers(n_in)] = val
        add(r, "extreme")
        add(np.full(n_in, val), "extreme")
    for val in (np.nan, np.inf, -np.inf):
        for k in range(n_in):
            r = mid.copy()
            r[k] = val
            add(r, "nonfinite")
    return np.vstack(rows), kinds


@dataclass
class VerifyResult:
    precision: str
    style: str
    n_vectors: int
    outputs: tuple[str, ...]
    max_error: np.ndarray
    max_bound: np.ndarray
    max_ratio: np.ndarray  # measured error over bound, worst vector
    status_mismatches: int
    nonfinite_outputs: int
    failures: list[str] = field(default_factory=list)
    # fixed point only: the largest |C - numpy integer model| per output, in output LSBs
    max_lsb_diff: np.ndarray | None = None
    held_out: HeldOutCheck | None = None  # None: no held-out readings to measure rounding's share on

    @property
    def ok(self) -> bool:
        return not self.failures

    def tightness(self) -> np.ndarray:
        """The a-priori bound over the measured error, on the vector where they are closest (inf: exact)."""
        with np.errstate(divide="ignore"):
            return np.where(self.max_ratio > 0, 1.0 / self.max_ratio, np.inf)

    def table(self) -> str:
        lsb, ho = self.max_lsb_diff is not None, self.held_out
        build = self.precision if self.precision == "fixed" else f"{self.precision}/{self.style}"  # fixed: one form
        lines = [f"{build}: {self.n_vectors} vectors, status mismatches "
                 f"{self.status_mismatches}, non-finite outputs {self.nonfinite_outputs}",
                 "| output | max abs error | bound (max) | bound / error |" +
                 (" C - numpy model (LSB) |" if lsb else "") +
                 (" held-out deviation | double model's max error on those readings | rounding's share |"
                  if ho else ""),
                 "| --- | --- | --- | --- |" + (" --- |" if lsb else "") + (" --- | --- | --- |" if ho else "")]
        tight = self.tightness()
        for j, name in enumerate(self.outputs):
            t = "exact" if not np.isfinite(tight[j]) else f"{tight[j]:.3g}" + (" (loose)" if tight[j] > LOOSE_BOUND
                                                                               else "")
            lines.append(f"| {name} | {self.max_error[j]:.3g} | {self.max_bound[j]:.3g} | {t} |" +
                         (f" {int(self.max_lsb_diff[j])} |" if lsb else "") +
                         (f" {ho.deviation[j]:.3g} | {ho.model_max[j]:.3g} | {ho.share[j]:.1%} |" if ho else ""))
        loose = [n for n, t in zip(self.outputs, tight) if np.isfinite(t) and t > LOOSE_BOUND]
        if loose:
            lines.append(f"note: the a-priori bound is more than {LOOSE_BOUND:g}x the measured worst case for "
                         f"{', '.join(loose)}: there it says little; the held-out deviation is what counts")
        return "\n".join(lines)


def _status_mismatches(status: np.ndarray, ref_status: np.ndarray, ref_name: str, failures: list[str]) -> int:
    """Rows whose C status differs from the reference's; a failure line names the first."""
    mism = int(np.sum(status != ref_status))
    if mism:
        i = int(np.argmax(status != ref_status))
        failures.append(f"status differs on {mism} vectors (first: C {status[i]}, {ref_name} {ref_status[i]})")
    return mism


def _bound_ratio(err: np.ndarray, bound: np.ndarray, rows: np.ndarray, what: str, names, failures: list[str]):
    """Error over bound per output (0 where the error is 0 and outside ``rows``); a failure line when over 1."""
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(err == 0, 0.0, err / bound)
    ratio[~rows] = 0.0
    over = ratio > 1.0
    if np.any(over):
        i, j = np.argwhere(over)[0]
        failures.append(f"{int(over.sum())} outputs outside {what} "
                        f"(first: {names[j]} error {err[i, j]:.3g} > bound {bound[i, j]:.3g})")
    return ratio


def compare(model: Model, compiled: CompiledModel, inputs: np.ndarray, held_out=None,
            max_share: float = MAX_SHARE) -> VerifyResult:
    """Run ``inputs`` through the C and through Python; check status, finiteness and the error bound;
    with ``held_out`` (noise-free readings, truth), rounding's share of the model's held-out error."""
    precision = compiled.precision
    if precision == "float":
        # the C takes float inputs and clamps into the float-rounded domain: so does the reference; a reading past
        # float's range is inf there as here (status -1 in both), a vector like any other, not numpy's warning
        with np.errstate(over="ignore"):
            inputs = inputs.astype(np.float32).astype(float)
        lo, hi = float_domain(model)
        ref_model = dataclasses.replace(model, input_min=lo, input_max=hi)
        u, slack = U_FLOAT, 1.0
    else:
        ref_model, u, slack = model, U_DOUBLE, DOUBLE_SLACK
    # double with fma: Python rounds each term once too, so the answers stay bit-identical
    fma = compiled.fma and precision == "double"
    refined = model.refine is not None
    # a refinement's iterations have no a-priori rounding bound: there the C must equal Python's
    # emulation of its own precision bit for bit (bound 0), and the held-out check measures rounding
    ref, ref_status = ref_model.predict(inputs, with_status=True, fma=fma, precision=precision if refined else "double")
    out, status = compiled.predict(inputs)
    failures: list[str] = []
    mism = _status_mismatches(status, ref_status, "Python", failures)
    nonfinite = int(np.sum(~np.isfinite(out)))
    if nonfinite:
        failures.append(f"{nonfinite} non-finite outputs")
    ok_rows = ref_status >= 0
    bound = np.zeros_like(ref)
    if not refined:
        bound[ok_rows] = slack * (error_bound(ref_model, inputs[ok_rows], u)
                                  + error_bound(ref_model, inputs[ok_rows], U_DOUBLE))
    err = np.abs(out - ref)
    err[~np.isfinite(err)] = np.inf
    bad_nf = ~ok_rows & np.any(out != 0, axis=1)
    if np.any(bad_nf):
        failures.append(f"{int(bad_nf.sum())} non-finite inputs did not give zero outputs")
    what = f"Python's {precision} emulation (bit for bit)" if refined else f"the {precision} error bound"
    ratio = _bound_ratio(err, bound, ok_rows, what, model.output_names, failures)
    chk = None
    if held_out is not None:
        readings, truth = held_out
        cin = readings.astype(np.float32).astype(float) if precision == "float" else readings
        chk = held_out_check(model, compiled.predict(cin)[0], readings, truth, max_share, failures)
    return VerifyResult(precision, compiled.style, len(inputs), model.output_names,
                        err[ok_rows].max(axis=0), bound[ok_rows].max(axis=0), ratio.max(axis=0), mism,
                        nonfinite, failures, held_out=chk)


def make_code_vectors(fm: FixedModel, n_random: int = 2000, seed: int = 0) -> tuple[np.ndarray, list[str]]:
    """Integer codes and a kind per row: random in the code domain, all its corners (up to 10 inputs,
    else 1024 random ones), its edges and one code past each, outside it (near and far), and the
    int32 extremes, 0 and -1 in each position and everywhere."""
    rng = np.random.default_rng(seed)
    lo, hi = np.array(fm.code_min, dtype=np.int64), np.array(fm.code_max, dtype=np.int64)
    n_in = fm.n_inputs
    mid = (lo + hi) // 2
    rows, kinds = [], []

    def add(block, kind):
        block = np.atleast_2d(np.asarray(block, dtype=np.int64))
        rows.append(block)
        kinds.extend([kind] * len(block))

    add(rng.integers(lo, hi + 1, (n_random, n_in)), "random")
    if n_in <= 10:
        bits = (np.arange(2**n_in)[:, None] >> np.arange(n_in)) & 1
    else:
        bits = rng.integers(0, 2, (1024, n_in))
    add(np.where(bits == 1, hi, lo), "corner")
    for k in range(n_in):
        for val in (lo[k], hi[k], lo[k] - 1, hi[k] + 1):
            r = mid.copy()
            r[k] = np.clip(val, INT32_MIN, INT32_MAX)
            add(r, "edge")
    width = hi - lo + 1
    near_lo = np.maximum(lo - (width * rng.uniform(0.01, 2.0, (200, n_in))).astype(np.int64) - 1, INT32_MIN)
    near_hi = np.minimum(hi + (width * rng.uniform(0.01, 2.0, (200, n_in))).astype(np.int64) + 1, INT32_MAX)
    add(near_lo, "outside")
    add(near_hi, "outside")
    add(rng.integers(INT32_MIN, INT32_MAX, (200, n_in), endpoint=True), "outside")
    for val in (INT32_MIN, INT32_MAX, 0, -1):
        for k in range(n_in):
            r = mid.copy()
            r[k] = val
            add(r, "extreme")
        add(np.full(n_in, val), "extreme")
    return np.vstack(rows), kinds


def compare_fixed(model: Model, compiled: CompiledModel, codes: np.ndarray, held_out=None,
                  max_share: float = MAX_SHARE) -> VerifyResult:
    """Run integer ``codes`` through the fixed-point C; compare with the numpy integer model (exact, or
    1 LSB at most) and with the double model (within the plan's error bound plus the double's own)."""
    fm = compiled.fixed
    out, status = compiled.predict_codes(codes)
    ref_int, ref_status = fm.predict_codes(codes)
    failures: list[str] = []
    mism = _status_mismatches(status, ref_status, "numpy", failures)
    lsb_diff = np.abs(out - ref_int)
    if np.any(lsb_diff > 1):
        i, j = np.argwhere(lsb_diff > 1)[0]
        failures.append(f"{int((lsb_diff > 1).sum())} outputs differ from the numpy integer model by more than "
                        f"1 LSB (first: {fm.output_names[j]} C {out[i, j]}, numpy {ref_int[i, j]})")
    # the double model on the values of the clamped codes (its domain is the code domain's values)
    ref_model = fm.reference_model()
    values = fm.code_values(codes)
    ref = ref_model.predict(values)
    bound = fm.error_bound()[None, :] + DOUBLE_SLACK * error_bound(ref_model, values, U_DOUBLE)
    err = np.abs(fm.to_real(out) - ref)
    ratio = _bound_ratio(err, bound, np.ones(len(err), bool), "the fixed-point error bound", model.output_names,
                         failures)
    chk = None
    if held_out is not None:
        # the device reads ADC codes: the held-out readings rounded to codes, against double on those codes'
        # values (the rounding to codes stays in the deployed error, with the noise)
        readings, truth = held_out
        held_codes = fm.codes_of(readings)  # not ``codes``: the result counts the vectors compared above
        chk = held_out_check(model, compiled.predict(held_codes)[0], readings, truth, max_share, failures,
                             fm.code_values(held_codes))
    return VerifyResult("fixed", compiled.style, len(codes), model.output_names, err.max(axis=0),
                        bound.max(axis=0), ratio.max(axis=0), mism, 0, failures, lsb_diff.max(axis=0), chk)


def verify(model: Model, precision: str, style: str, *, cc: str = "gcc", runner: str = "", prefix: str = "tm",
           n_random: int = 2000, extra_inputs: np.ndarray | None = None, cflags: list[str] | None = None,
           seed: int = 0, fma: bool = False, input_lsb: float | None = None,
           input_offset: float | None = None, held_out: tuple[np.ndarray, np.ndarray] | None = None,
           max_share: float = MAX_SHARE) -> VerifyResult:
    """Generate, compile and check the C of ``model``. Fixed point: ``style`` is only a label (the
    fixed header is straight-line code) and ``extra_inputs`` (values) are turned into their nearest codes.
    ``held_out``: noise-free held-out (readings, truth) on which rounding may add at most ``max_share``
    of the model's own max error (fitgen.fitting.holdout.clean_readings gives them for a model file); fixed
    point is compared with double on its codes' values."""
    if precision == "fixed":
        with CompiledModel(model, "fixed", style, prefix, cc=cc, runner=runner, cflags=cflags,
                           input_lsb=input_lsb, input_offset=input_offset) as cm:
            codes, _ = make_code_vectors(cm.fixed, n_random, seed)
            if extra_inputs is not None:
                codes = np.vstack([codes, cm.fixed.codes_of(extra_inputs)])
            return compare_fixed(model, cm, codes, held_out, max_share)
    check_magnitudes(model, precision)  # before the vectors, which reach twice the domain's width past it
    inputs, _ = make_vectors(model, n_random, seed)
    if extra_inputs is not None:
        inputs = np.vstack([inputs, extra_inputs])
    with CompiledModel(model, precision, style, prefix, cc=cc, runner=runner, cflags=cflags, fma=fma) as cm:
        return compare(model, cm, inputs, held_out, max_share)
