"""Verification of generated C against the Python evaluation: vectors, comparison, report."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from fitgen.codegen import float_domain
from fitgen.fixedpoint import INT32_MAX, INT32_MIN, FixedModel
from fitgen.model import Model
from fitgen.precision import U_DOUBLE, U_FLOAT, error_bound

from .compiled import CompiledModel

# double: a few roundings at the scale of the terms (the formula of fitgen.precision, times 4)
DOUBLE_SLACK = 4.0


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

    @property
    def ok(self) -> bool:
        return not self.failures

    def table(self) -> str:
        lines = [f"{self.precision}/{self.style}: {self.n_vectors} vectors, status mismatches "
                 f"{self.status_mismatches}, non-finite outputs {self.nonfinite_outputs}",
                 "| output | max abs error | bound (max) | worst error / bound |" +
                 (" C - numpy model (LSB) |" if self.max_lsb_diff is not None else ""),
                 "| --- | --- | --- | --- |" + (" --- |" if self.max_lsb_diff is not None else "")]
        for j, name in enumerate(self.outputs):
            lines.append(f"| {name} | {self.max_error[j]:.3g} | {self.max_bound[j]:.3g} | {self.max_ratio[j]:.3g} |" +
                         (f" {int(self.max_lsb_diff[j])} |" if self.max_lsb_diff is not None else ""))
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


def compare(model: Model, compiled: CompiledModel, inputs: np.ndarray) -> VerifyResult:
    """Run ``inputs`` through the C and through Python; check status, finiteness and the error bound."""
    precision = compiled.precision
    if precision == "float":
        # the C takes float inputs and clamps into the float-rounded domain: so does the reference
        inputs = inputs.astype(np.float32).astype(float)
        lo, hi = float_domain(model)
        ref_model = Model(lo, hi, model.equations, model.input_units, model.fit_info)
        u, slack = U_FLOAT, 1.0
    else:
        ref_model, u, slack = model, U_DOUBLE, DOUBLE_SLACK
    # double with fma: Python rounds each term once too, so the answers stay bit-identical
    ref, ref_status = ref_model.predict(inputs, with_status=True, fma=compiled.fma and precision == "double")
    out, status = compiled.predict(inputs)
    failures: list[str] = []
    mism = _status_mismatches(status, ref_status, "Python", failures)
    nonfinite = int(np.sum(~np.isfinite(out)))
    if nonfinite:
        failures.append(f"{nonfinite} non-finite outputs")
    ok_rows = ref_status >= 0
    bound = np.zeros_like(ref)
    bound[ok_rows] = slack * (error_bound(ref_model, inputs[ok_rows], u)
                              + error_bound(ref_model, inputs[ok_rows], U_DOUBLE))
    err = np.abs(out - ref)
    err[~np.isfinite(err)] = np.inf
    bad_nf = ~ok_rows & np.any(out != 0, axis=1)
    if np.any(bad_nf):
        failures.append(f"{int(bad_nf.sum())} non-finite inputs did not give zero outputs")
    ratio = _bound_ratio(err, bound, ok_rows, f"the {precision} error bound", model.output_names, failures)
    return VerifyResult(precision, compiled.style, len(inputs), model.output_names,
                        err[ok_rows].max(axis=0), bound[ok_rows].max(axis=0), ratio.max(axis=0), mism,
                        nonfinite, failures)


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


def compare_fixed(model: Model, compiled: CompiledModel, codes: np.ndarray) -> VerifyResult:
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
    return VerifyResult("fixed", compiled.style, len(codes), model.output_names, err.max(axis=0),
                        bound.max(axis=0), ratio.max(axis=0), mism, 0, failures, lsb_diff.max(axis=0))


def verify(model: Model, precision: str, style: str, *, cc: str = "gcc", runner: str = "", prefix: str = "tm",
           n_random: int = 2000, extra_inputs: np.ndarray | None = None, cflags: list[str] | None = None,
           seed: int = 0, fma: bool = False, input_lsb: float | None = None,
           input_offset: float | None = None) -> VerifyResult:
    """Generate, compile and check the C of ``model``. Fixed point: ``style`` is only a label (the
    fixed header is straight-line code) and ``extra_inputs`` (values) are turned into their nearest codes."""
    if precision == "fixed":
        with CompiledModel(model, "fixed", style, prefix, cc=cc, runner=runner, cflags=cflags,
                           input_lsb=input_lsb, input_offset=input_offset) as cm:
            codes, _ = make_code_vectors(cm.fixed, n_random, seed)
            if extra_inputs is not None:
                codes = np.vstack([codes, cm.fixed.codes_of(extra_inputs)])
            return compare_fixed(model, cm, codes)
    inputs, _ = make_vectors(model, n_random, seed)
    if extra_inputs is not None:
        inputs = np.vstack([inputs, extra_inputs])
    with CompiledModel(model, precision, style, prefix, cc=cc, runner=runner, cflags=cflags, fma=fma) as cm:
        return compare(model, cm, inputs)
