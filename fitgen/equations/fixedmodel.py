"""A fixed-point plan as data, and its integer arithmetic in numpy: integer ADC codes in, int32 out.

A :class:`FixedModel` (built by :func:`fitgen.equations.fixedpoint.build_fixed`) is a straight list of
integer operations (:class:`FixedOp`, one named value each, in evaluation order) with the Q format
(fraction bits) of every value, its proven range and a bound on its error against exact arithmetic.
The C template (``firmware_templates/model_fixed.h.j2``) and the numpy model
(:meth:`FixedModel.predict_codes`) both read that list, so they do the same integer arithmetic,
operation for operation.

Number format. Input k is an int32 ADC code c with value v = offset + lsb * c. The plan works
with u = c + offset/lsb (in codes; an int32 in Q(f_u), f_u = 0 when the offset is a whole
number of codes) and folds lsb^e into each coefficient, since v^e = lsb^e * u^e. A value X
in Q(f) is the integer round(X * 2^f); f may be negative.

Operations (every right shift rounds to nearest, ties upward: (x + 2^(s-1)) >> s with an
arithmetic shift, written in C through an unsigned bias so no implementation-defined shift
of a negative number occurs):

- ``input``  u = clamp(c) * 2^f_u + O                                   int32
- ``mul``    p = round((int64)a * b / 2^s)      (v^2, v^3, v^4, 1/v^2.., v_k * d)   int32
- ``recip``  p = round(2^N / a), a > 0           (1/v; 1/v^e are powers of it)    int32
- ``init``   acc = round(intercept * 2^f_acc)                           int64
- ``term``   acc += round((int64)C * p / 2^s)    (C: the coefficient in Q(f_c))   int64
- ``out``    out = round(acc / 2^s)              (Q(f_out), also the d of d-terms) int32

A plan for a core with a 16-bit multiply (``mul_bits`` 16, an 8-bit AVR) has, besides, int16 values
(``bits`` 16): ``narrow`` p16 = round(p / 2^s), an int32 value's rounded copy; a ``mul`` of two int16
values is a 16x16->32 product (``prod_bits`` 32) rounded into an int16; a ``recip`` into an int16 takes
an int32 numerator; an output whose accumulator is int32 (``acc_bits`` 32) sums int16 coefficients
times int16 values, each a 16x16->32 product. The formulas are the same; only the widths differ.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from fitgen import __version__
from fitgen.base.errors import InputError
from fitgen.equations.model import Model

INT16_MAX = 2**15 - 1
INT32_MAX = 2**31 - 1
INT32_MIN = -(2**31)


# --- the rounding shift, shared by the planner and the numpy model ------------------------------


def rshr(x, s: int):
    """Round-to-nearest (ties upward) right shift by ``s`` (> 0); ``s`` = 0 keeps ``x``; ``s`` < 0
    multiplies by 2^-s. Works on Python ints and numpy int64 arrays alike (>> is arithmetic)."""
    if s > 0:
        return (x + (1 << (s - 1))) >> s
    if s < 0:
        return x * (1 << -s)
    return x


# --- the plan ----------------------------------------------------------------------------------


@dataclass(frozen=True)
class FixedOp:
    """One integer value of the evaluation (see the module's table of kinds).

    ``args`` name earlier values; ``const`` is the offset (input), numerator 2^N (recip),
    intercept (init) or coefficient (term); ``shift`` is the rounding right shift (negative:
    an exact left shift; for ``input`` it is -f_u). ``lo``..``hi`` is the proven range of the
    value, ``wide_lo``..``wide_hi`` that of the int64 intermediate before the shift (the
    product, the numerator sum or the input's scaled code). ``error`` bounds
    |value * 2^-frac_bits - exact value| over the domain; ``magnitude`` is max |value| * 2^-frac_bits.
    """

    kind: str
    name: str
    args: tuple[str, ...]
    const: int
    shift: int
    frac_bits: int
    bits: int
    lo: int
    hi: int
    wide_lo: int
    wide_hi: int
    error: float
    magnitude: float
    text: str
    index: int = -1  # input: the input's index; out: the output's index
    prod_bits: int = 64  # width of the intermediate (wide_lo..wide_hi): 32 for a 16x16 product or an int32 sum


@dataclass(frozen=True)
class FixedOutput:
    name: str
    unit: str
    index: int
    frac_bits: int  # the int32 output is the value in Q(frac_bits)
    acc_frac_bits: int
    error_bound: float  # |to_real(out) - exact| over the domain, in the output's unit
    lo: int
    hi: int
    n_terms: int
    acc_bits: int = 64  # 32: int16 operands and coefficients, 16x16->32 products, an int32 accumulator
    aligned: bool = False  # every term's shift a multiple of 8 bits (an 8-bit core shifts whole bytes for free)


@dataclass(frozen=True)
class FixedModel:
    """The integer evaluation of a model: formats, proven ranges and error bounds."""

    n_inputs: int
    input_lsb: float
    input_offset: float
    input_units: str
    code_min: tuple[int, ...]
    code_max: tuple[int, ...]
    ops: tuple[FixedOp, ...]
    outputs: tuple[FixedOutput, ...]
    model_hash: str
    version: str = __version__
    equations: tuple = field(default=(), repr=False, compare=False)
    mul_bits: int = 32  # the core's multiply the plan is for: 32 (32x32->64 products) or 16 (fixedpoint.build_fixed)
    budget: tuple[float, ...] = ()  # mul_bits 16: per output, the error bound its 16-bit products were held within
    # per output, the bounds past which an estimate lies far outside the model's fitted pose box (Model.far_bounds),
    # None for an output the box does not name
    far: tuple = ()

    @property
    def output_names(self) -> tuple[str, ...]:
        return tuple(o.name for o in self.outputs)

    @property
    def out_frac_bits(self) -> tuple[int, ...]:
        return tuple(o.frac_bits for o in self.outputs)

    def op(self, name: str) -> FixedOp:
        """The operation that computes the value ``name`` (KeyError when none does)."""
        return {op.name: op for op in self.ops}[name]

    # --- evaluation ---------------------------------------------------------------------------

    def clamp_codes(self, codes) -> tuple[np.ndarray, np.ndarray]:
        """Codes (n, N) clamped into the code domain (int64), and the status per row."""
        c = np.asarray(codes)
        if c.ndim == 1:
            c = c[None, :]
        if c.ndim != 2 or c.shape[1] != self.n_inputs:
            raise InputError(f"the model takes {self.n_inputs} input codes per row, got shape {c.shape}")
        def where(bad) -> str:  # the first offending cell, as a user finds it in the CSV (rows from 1, v1..)
            r, k = np.argwhere(bad)[0]
            return f" (row {r + 1}, v{k + 1}: {float(c[r, k]):.17g})"

        if c.dtype.kind == "f":
            bad = ~np.isfinite(c) | (c != np.round(c))
            if np.any(bad):
                raise InputError("input codes must be whole numbers" + where(bad))
        elif c.dtype.kind not in "iu":
            raise InputError(f"input codes must be integers, got {c.dtype}")
        if c.size and (c.min() < INT32_MIN or c.max() > INT32_MAX):
            raise InputError("input codes must fit in an int32" + where((c < INT32_MIN) | (c > INT32_MAX)))
        c = c.astype(np.int64)
        lo, hi = np.array(self.code_min, dtype=np.int64), np.array(self.code_max, dtype=np.int64)
        bits = (1 << np.arange(self.n_inputs)).astype(np.int64)
        status = (((c < lo) | (c > hi)) * bits).sum(axis=1)
        return np.clip(c, lo, hi), status

    def predict_codes(self, codes, trace: bool = False, exact: bool = False):
        """(outputs (n, K) int64 in each output's Q format, status (n,)): exactly the C's integers.

        ``trace``: also a dict name -> (value, wide) for every operation (``wide``: the int64
        intermediate before the shift, or None), for checking the proven ranges. ``exact``: the
        same operations on Python integers (numpy object arrays, slow), which cannot wrap around:
        a check that the int64 evaluation never overflowed.
        """
        x, status = self.clamp_codes(codes)
        dtype = object if exact else np.int64
        x = x.astype(dtype)
        n = x.shape[0]
        vals: dict[str, np.ndarray] = {}
        wides: dict[str, np.ndarray | None] = {}
        out = np.zeros((n, len(self.outputs)), dtype=dtype)
        acc = np.zeros(n, dtype=dtype)
        for op in self.ops:
            wide = None
            if op.kind == "input":
                wide = x[:, op.index] * (1 << -op.shift) + op.const
                val = wide
            elif op.kind == "mul":
                wide = vals[op.args[0]] * vals[op.args[1]]
                val = rshr(wide, op.shift)
            elif op.kind == "narrow":
                wide = vals[op.args[0]]
                val = rshr(wide, op.shift)
            elif op.kind == "recip":
                a = vals[op.args[0]]
                wide = op.const + a // 2
                val = wide // a
            elif op.kind == "init":
                acc = np.full(n, op.const, dtype=dtype)
                val = acc
            elif op.kind == "term":
                wide = (op.const if exact else np.int64(op.const)) * vals[op.args[0]]
                acc = acc + rshr(wide, op.shift)
                val = acc
            elif op.kind == "out":
                val = rshr(acc, op.shift)
                out[:, op.index] = val
            else:  # pragma: no cover - the planner makes no other kind
                raise AssertionError(op.kind)
            vals[op.name] = val
            wides[op.name] = wide
        if trace:
            return out, status, {k: (vals[k], wides[k]) for k in vals}
        return out, status

    def to_real(self, out) -> np.ndarray:
        """Integer outputs (n, K) as real values in the outputs' units."""
        out = np.asarray(out)
        scale = np.array([math.ldexp(1.0, -o.frac_bits) for o in self.outputs])
        return out.astype(float) * scale

    def error_bound(self) -> np.ndarray:
        """Per output, the bound on |to_real(C) - exact value| anywhere in the domain (units of the output)."""
        return np.array([o.error_bound for o in self.outputs])

    # --- the double model it approximates -----------------------------------------------------

    def code_values(self, codes) -> np.ndarray:
        """Input values (double) of codes clamped into the domain: offset + lsb * code."""
        x, _ = self.clamp_codes(codes)
        return self.input_offset + self.input_lsb * x.astype(float)

    def reference_model(self) -> Model:
        """The double model with its domain moved to the code domain's values (what the C clamps to)."""
        lo = self.input_offset + self.input_lsb * np.array(self.code_min, dtype=float)
        hi = self.input_offset + self.input_lsb * np.array(self.code_max, dtype=float)
        return Model(lo, hi, self.equations, self.input_units)

    def codes_of(self, values) -> np.ndarray:
        """The nearest codes of input values (for feeding a model's data to the integer estimator)."""
        c = np.round((np.asarray(values, dtype=float) - self.input_offset) / self.input_lsb)
        return np.clip(c, INT32_MIN, INT32_MAX).astype(np.int64)

    def predict_values(self, values) -> tuple[np.ndarray, np.ndarray]:
        """(real outputs (n, K), status) for input values rounded to codes as the ADC rounds them."""
        out, status = self.predict_codes(self.codes_of(values))
        return self.to_real(out), status

    def summary(self) -> str:
        parts = [f"{o.name} Q{o.frac_bits} (LSB {math.ldexp(1.0, -o.frac_bits):.3g} {o.unit}, "
                 f"error <= {o.error_bound:.3g} {o.unit})" for o in self.outputs]
        return "; ".join(parts)
