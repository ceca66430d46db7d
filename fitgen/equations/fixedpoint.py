"""Fixed-point plans of a model for cores without an FPU (Cortex-M0, AVR): integer ADC codes in, int32 out.

:func:`build_fixed` turns a :class:`~fitgen.equations.model.Model` into a
:class:`~fitgen.equations.fixedmodel.FixedModel` (the number format and the operations are described
there): the Q format of every value, its range proven by interval arithmetic over the code domain,
and a bound on its error against exact arithmetic. For a core with a 16-bit multiply (an 8-bit AVR)
some outputs run on int16 operands and 16x16->32 products instead, or with byte-aligned shifts, where
every bound stays within its budget (fitgen.equations.fixednarrow chooses; this module plans).
fitgen.equations.inputscale gives the input scale (the value of one ADC code) when the user names none.

Q formats are chosen in evaluation order, each the finest that keeps its value inside its
budget (|x| <= 2^31 - 1 for int32 values, |x| <= 2^62 for int64 values and for the int64
products before a shift) over the whole code domain. The proof is interval arithmetic on the
exact integers (Python ints): every operation of the plan is monotone in each operand (a product
over an interval box takes its extremes at the box's corners; a square is handled as one),
so each value's interval holds every value the C can compute from clamped codes.
"""

from __future__ import annotations

import math
from decimal import Decimal  # formats codes past float's range
from fractions import Fraction

from fitgen import __version__
from fitgen.base.errors import InputError
from fitgen.equations.fixedmodel import (INT16_MAX, INT32_MAX, INT32_MIN, FixedModel, FixedOp, FixedOutput,
                                         rshr)
from fitgen.equations.model import MAX_INPUTS, Model

BUDGET = {16: INT16_MAX, 32: INT32_MAX, 64: 2**62}
MAX_SHIFT = {32: 30, 64: 62}  # the largest rounding shift of a product of that width
# exponent text -> (C name suffix, how it is computed)
POWER_CODE = {"1": "P1", "2": "P2", "3": "P3", "4": "P4", "-1": "M1", "-2": "M2", "-3": "M3", "-4": "M4"}
# a power's operands: P2 = P1^2, P3 = P2 * P1, P4 = P2^2, M1 = 1/P1, M2 = M1^2, M3 = M2 * M1, M4 = M2^2
_RECIPE = {"P2": ("P1", "P1"), "P3": ("P2", "P1"), "P4": ("P2", "P2"),
           "M2": ("M1", "M1"), "M3": ("M2", "M1"), "M4": ("M2", "M2")}
_POWER_ORDER = ("P1", "P2", "P3", "P4", "M1", "M2", "M3", "M4")
_EXPONENT_OF = {"P1": 1, "P2": 2, "P3": 3, "P4": 4, "M1": -1, "M2": -2, "M3": -3, "M4": -4}
# a domain bound within this many codes of a whole code is taken as that code
SNAP = Fraction(1, 10**6)
MIN_CODES = 16  # an input's domain must span at least this many ADC codes (4 bits) to be worth estimating from


def divr(num, den):
    """round(num / den) for num >= 0, den > 0 (ties upward when den is even), as C's
    ``(num + den / 2) / den``."""
    return (num + den // 2) // den


def _fits(lo: int, hi: int, bits: int) -> bool:
    return -BUDGET[bits] <= lo and hi <= BUDGET[bits]


# --- building the plan ---------------------------------------------------------------------------


def _exact(x: float) -> Fraction:
    return Fraction(float(x))


def _float(q: Fraction) -> float:
    """q as a float; inf when it is too large for one (the caller refuses such a model)."""
    try:
        return float(q)
    except OverflowError:
        return math.inf if q > 0 else -math.inf


def _log2(q: Fraction) -> float:
    """log2 |q| for q != 0, also where |q| is beyond the range of a float."""
    return math.log2(abs(q.numerator)) - math.log2(q.denominator)


def _round(q: Fraction) -> int:
    """Nearest integer, ties upward (as the C's shifts)."""
    return math.floor(q + Fraction(1, 2))


def _code_bounds(model: Model, lsb: Fraction, off: Fraction) -> tuple[list[int], list[int]]:
    """Code domain: the codes whose values lie in the model's domain (rounded inward), a bound
    within SNAP of a whole code taken as that code, clipped to int32."""
    cmin, cmax = [], []
    for k in range(model.n_inputs):
        qlo = (_exact(model.input_min[k]) - off) / lsb
        qhi = (_exact(model.input_max[k]) - off) / lsb
        lo = _round(qlo) if abs(qlo - _round(qlo)) <= SNAP else math.ceil(qlo)
        hi = _round(qhi) if abs(qhi - _round(qhi)) <= SNAP else math.floor(qhi)
        if model.input_min[k] > 0 and off + lsb * lo <= 0:
            lo = math.floor(-off / lsb) + 1  # a positive domain keeps positive values (negative powers need them)
        if lo > hi:
            raise InputError(f"input v{k + 1}: its domain [{float(model.input_min[k])!r}, "
                             f"{float(model.input_max[k])!r}] holds no whole ADC code at LSB {float(lsb)!r}, "
                             f"offset {float(off)!r}")
        if hi - lo + 1 < MIN_CODES:
            raise InputError(f"input v{k + 1}: its domain [{float(model.input_min[k])!r}, "
                             f"{float(model.input_max[k])!r}] holds {hi - lo + 1} ADC code"
                             f"{'s' if hi - lo else ''} at LSB {float(lsb)!r}, fewer than {MIN_CODES}: every "
                             "reading would give one of a handful of poses (an LSB in the wrong unit?)")
        if lo < INT32_MIN or hi > INT32_MAX:
            raise InputError(f"input v{k + 1}: its domain [{float(model.input_min[k])!r}, "
                             f"{float(model.input_max[k])!r}] spans codes {Decimal(lo):.4g}..{Decimal(hi):.4g} at LSB "
                             f"{float(lsb)!r}, "
                             f"offset {float(off)!r}: beyond int32 (a larger LSB, or the offset at the domain)")
        cmin.append(lo)
        cmax.append(hi)
    return cmin, cmax


class _Planner:
    def __init__(self):
        self.ops: list[FixedOp] = []
        self.by_name: dict[str, FixedOp] = {}

    def add(self, op: FixedOp) -> FixedOp:
        if not _fits(op.lo, op.hi, op.bits) or not _fits(op.wide_lo, op.wide_hi, op.prod_bits):
            raise InputError(f"fixed point: {op.text} cannot be placed in {op.bits} bits")  # pragma: no cover
        self.ops.append(op)
        self.by_name[op.name] = op
        return op

    def get(self, name: str) -> FixedOp:
        return self.by_name[name]

    def input(self, k: int, cmin: int, cmax: int, o: Fraction) -> FixedOp:
        if o.denominator == 1:
            f = 0
        else:
            f = 0
            while f < 30:
                m = 1 << (f + 1)
                lo, hi = cmin * m + _round(o * m), cmax * m + _round(o * m)
                if not _fits(lo, hi, 32):
                    break
                f += 1
        m = 1 << f
        const = _round(o * m)
        lo, hi = cmin * m + const, cmax * m + const
        if not _fits(lo, hi, 32):
            raise InputError(f"input v{k + 1}: its codes plus the offset ({float(o)!r} codes) do not fit an int32")
        err = float(abs(Fraction(const, m) - o))
        mag = math.ldexp(max(abs(lo), abs(hi)), -f)
        return self.add(FixedOp("input", f"u{k + 1}", (), const, -f, f, 32, lo, hi, lo, hi, err, mag,
                                f"v{k + 1} in codes", k))

    def narrow(self, name: str) -> str:
        """The name of value ``name`` as an int16: itself when it is one, else its rounded copy (made once)."""
        A = self.get(name)
        if A.bits == 16:
            return name
        copy = f"{name}_16"
        if copy not in self.by_name:
            s = 0
            while not _fits(rshr(A.lo, s), rshr(A.hi, s), 16):
                s += 1
            f = A.frac_bits - s
            lo, hi = rshr(A.lo, s), rshr(A.hi, s)
            err = A.error + (math.ldexp(0.5, -f) if s > 0 else 0.0)
            self.add(FixedOp("narrow", copy, (name,), 0, s, f, 16, lo, hi, A.lo, A.hi, err,
                             math.ldexp(max(abs(lo), abs(hi)), -f), f"{A.text.split(' ')[0]} in 16 bits",
                             prod_bits=32))
        return copy

    def mul(self, name: str, a: str, b: str, text: str, bits: int = 32) -> FixedOp:
        """a * b rounded into ``bits`` (32, or 16): a 16x16->32 product when both are int16, else 32x32->64."""
        A, B = self.get(a), self.get(b)
        prod_bits = 32 if A.bits == B.bits == 16 else 64
        if a == b:
            sq = (A.lo * A.lo, A.hi * A.hi)
            wlo = 0 if A.lo <= 0 <= A.hi else min(sq)
            whi = max(sq)
        else:
            prods = [A.lo * B.lo, A.lo * B.hi, A.hi * B.lo, A.hi * B.hi]
            wlo, whi = min(prods), max(prods)
        s = 0
        while not _fits(rshr(wlo, s), rshr(whi, s), bits):
            s += 1
        f = A.frac_bits + B.frac_bits - s
        err = (math.ldexp(0.5, -f) if s > 0 else 0.0) + A.magnitude * B.error + (B.magnitude + B.error) * A.error
        lo, hi = rshr(wlo, s), rshr(whi, s)
        return self.add(FixedOp("mul", name, (a, b), 0, s, f, bits, lo, hi, wlo, whi, err,
                                math.ldexp(max(abs(lo), abs(hi)), -f), text, prod_bits=prod_bits))

    def recip(self, name: str, a: str, text: str, k: int, bits: int = 32) -> FixedOp:
        """round(2^N / a) into ``bits``: an int64 numerator for 32 bits, an int32 one for 16."""
        A = self.get(a)
        if A.lo <= 0:
            raise InputError(f"fixed point: v{k + 1}^-1 needs v{k + 1} > 0 over the code domain, "
                             f"but its lowest code gives {float(A.lo) * 2.0 ** -A.frac_bits!r} codes")
        prod_bits = 64 if bits == 32 else 32
        n = 0
        while (n < MAX_SHIFT[64] and divr(1 << (n + 1), A.lo) <= BUDGET[bits]
               and (bits == 32 or _fits(0, (1 << (n + 1)) + A.hi // 2, prod_bits))):
            n += 1
        num = 1 << n
        f = n - A.frac_bits
        lo, hi = divr(num, A.hi), divr(num, A.lo)
        amin = math.ldexp(A.lo, -A.frac_bits)
        if not A.error < amin:
            raise InputError(f"fixed point: v{k + 1} is too close to 0 for its reciprocal")  # pragma: no cover
        err = math.ldexp(0.5, -f) + A.error / (amin * (amin - A.error))
        return self.add(FixedOp("recip", name, (a,), num, 0, f, bits, lo, hi, num + A.lo // 2, num + A.hi // 2,
                                err, math.ldexp(hi, -f), text, prod_bits=prod_bits))


def _operand(t) -> str:
    """The name of the value a term multiplies (see :func:`_plan`)."""
    if t.element and not t.mult:
        code = POWER_CODE[t.exponent]
        return f"u{t.element}" if code == "P1" else f"p{t.element}_{code}"
    if t.element:
        return f"vd{t.element}_{t.mult}"
    return f"o_{t.mult}"


def _parts(name: str) -> tuple[str, ...]:
    """The values ``name`` is computed from (none for an input or an output)."""
    if name.startswith("vd"):
        k, d = name[2:].split("_")
        return (f"u{k}", f"o_{d}")
    if name.startswith("p"):
        k, code = name[1:].split("_")
        if code == "M1":
            return (f"u{k}",)
        return tuple(f"u{k}" if c == "P1" else f"p{k}_{c}" for c in _RECIPE[code])
    return ()


def _needs(model: Model, narrow: frozenset) -> tuple[set, set]:
    """(values needed as int32, values needed as int16): the terms' operands (int16 for the outputs in
    ``narrow``) and what they are computed from. A value only needed as an int16 is computed in 16 bits
    (a reciprocal from its int32 input); one needed both ways is computed in 32 bits and copied."""
    wide, half = set(), set()
    for eq in model.equations:
        for t in eq.terms:
            (half if eq.name in narrow else wide).add(_operand(t))
    stack = list(wide)
    while stack:
        for w in _parts(stack.pop()):
            if w not in wide:
                wide.add(w)
                stack.append(w)
    stack = [v for v in half if v not in wide]
    while stack:
        v = stack.pop()
        for w in _parts(v):
            if v.endswith("_M1"):
                wide.add(w)  # an input: always computed in 32 bits
            elif w not in half:
                half.add(w)
                if w not in wide:
                    stack.append(w)
    return wide, half


def _check_model(model: Model, input_lsb, input_offset) -> tuple[float, float]:
    try:
        lsb_f, off_f = float(input_lsb), float(input_offset)
    except (TypeError, ValueError):
        raise InputError(f"input LSB and offset must be numbers, got {input_lsb!r}, {input_offset!r}") from None
    if not (math.isfinite(lsb_f) and lsb_f > 0):
        raise InputError(f"the input LSB must be a finite number > 0, got {input_lsb!r}")
    if not math.isfinite(off_f):
        raise InputError(f"the input offset must be a finite number, got {input_offset!r}")
    if model.n_inputs > MAX_INPUTS:
        raise InputError(f"the model has {model.n_inputs} inputs; the status bit mask holds at most {MAX_INPUTS}")
    if refused := fixed_refusal(model):
        raise InputError(refused)
    return lsb_f, off_f


def fixed_refusal(model: Model) -> str:
    """Why fixed point cannot evaluate ``model`` (a refinement, a harmonic term, a root); '' when it can."""
    if model.refine is not None:
        return ("fixed point has no refinement (its Gauss-Newton steps run in float or double): fit without --refine "
                "for fixed point")
    for eq in model.equations:
        for t in eq.terms:
            if t.harm:
                return (f"fixed point has no harmonic terms (they divide by the readings' sum), but output {eq.name} "
                        f"has {t.text}: fit with --family no-roots (or integer)")
            if t.exponent and "/" in t.exponent:
                return (f"fixed point takes integer powers only, but output {eq.name} has the root {t.text}: fit "
                        "with --family no-roots (or integer)")
    return ""


def build_fixed(model: Model, input_lsb: float, input_offset: float = 0.0, mul_bits: int = 32) -> FixedModel:
    """The fixed-point plan of ``model`` for int32 ADC codes c with value input_offset + input_lsb * c.

    ``mul_bits``: the core's natural multiply. 32: every product 32x32->64 (Cortex-M, x86). 16 (an
    8-bit AVR): the outputs whose error bound stays within :func:`narrow_budget` computed with
    16x16->32 products and an int32 accumulator (fitgen.equations.fixednarrow), the rest as for 32.

    Refuses (InputError, one line) roots, domains that hold no code or reach v <= 0 where a
    negative power needs v > 0, and outputs whose range cannot be held in an int32 with an LSB
    of at most 1 unit.
    """
    if mul_bits not in (16, 32):
        raise InputError(f"the multiply width must be 16 or 32 bits, got {mul_bits!r}")
    lsb_f, off_f = _check_model(model, input_lsb, input_offset)
    lsb, off = _exact(lsb_f), _exact(off_f)
    cmin, cmax = _code_bounds(model, lsb, off)
    if mul_bits == 32:
        return _plan(model, lsb, off, cmin, cmax)
    from fitgen.equations.fixednarrow import plan_narrow

    return plan_narrow(model, lambda narrow, aligned: _plan(model, lsb, off, cmin, cmax, narrow, aligned))


def _plan(model: Model, lsb: Fraction, off: Fraction, cmin: list[int], cmax: list[int],
          narrow: frozenset = frozenset(), aligned: frozenset = frozenset()) -> FixedModel:
    """The plan with the outputs in ``narrow`` on int16 operands and an int32 accumulator, and the terms
    of the outputs in ``aligned`` shifted by whole bytes (fitgen.equations.fixednarrow)."""
    o = off / lsb
    pl = _Planner()
    wide, half = _needs(model, narrow)
    for k in sorted({int(v[1:].split("_")[0]) - 1 for v in wide | half if v[0] in "up"}):
        pl.input(k, cmin[k], cmax[k], o)
        for code in _POWER_ORDER[1:]:
            name = f"p{k + 1}_{code}"
            if name not in wide and name not in half:
                continue
            text = f"v{k + 1}^{_EXPONENT_OF[code]}"
            bits = 32 if name in wide else 16
            if code == "M1":
                pl.recip(name, f"u{k + 1}", text, k, bits)
            else:
                a, b = _parts(name)
                if bits == 16:
                    a, b = pl.narrow(a), pl.narrow(b)
                pl.mul(name, a, b, text, bits)

    outputs = []
    for j, eq in enumerate(model.equations):
        # each term's operand (a power, v_k * d, or d) and its exact real coefficient (lsb^e folded in)
        operands, coefs = [], []
        for t, c in zip(eq.terms, eq.coefficients):
            c = _exact(c)
            name = _operand(t)
            if t.element and t.mult and name not in pl.by_name:
                u, d = _parts(name)
                if name in wide:
                    pl.mul(name, u, d, f"v{t.element}*{t.mult}")
                else:
                    pl.mul(name, pl.narrow(u), pl.narrow(d), f"v{t.element}*{t.mult}", 16)
            operands.append(pl.narrow(name) if eq.name in narrow else name)
            if t.element and not t.mult:
                coefs.append(c * lsb ** _EXPONENT_OF[POWER_CODE[t.exponent]])
            elif t.element:
                coefs.append(c * lsb)
            else:
                coefs.append(c)
        outputs.append(_plan_output(pl, eq, j, operands, coefs, 32 if eq.name in narrow else 64,
                                    eq.name in aligned))
    lsb_f, off_f = float(lsb), float(off)
    return FixedModel(model.n_inputs, lsb_f, off_f, model.input_units, tuple(cmin), tuple(cmax), tuple(pl.ops),
                      tuple(outputs), model.sha256, __version__, tuple(model.equations), far=model.far_per_output())


def _plan_output(pl: _Planner, eq, j: int, operands: list[str], coefs: list[Fraction], acc_bits: int,
                 align: bool = False) -> FixedOutput:
    """The output's terms summed in an int64 accumulator with int32 coefficients (acc_bits 64), or in an
    int32 one with int16 coefficients on int16 operands (acc_bits 32); ``align``: each term's shift a
    multiple of 8 bits (its coefficient up to 7 bits coarser)."""
    ops_p = [pl.get(n) for n in operands]
    icpt = _exact(eq.intercept)
    bound = abs(float(icpt)) + sum(abs(_float(c)) * (p.magnitude + p.error) for c, p in zip(coefs, ops_p))
    top = 2.0**61 if acc_bits == 64 else 2.0**30  # half the accumulator's budget
    if not bound < top / 2:
        raise InputError(f"output {eq.name}: its terms reach {bound:.3g} {eq.unit} in the input domain; an int32 "
                         f"output would need an LSB over 1 {eq.unit} (fixed point limit)")
    # the accumulator: the finest Q format whose every partial sum provably stays within its budget
    # top / bound may pass float; an output 0 everywhere takes Q31, as an int32 in [-1, 1) would (Q100 had broken a
    # conversion by 1 << frac)
    f_acc = min(100, math.floor(math.log2(top) - math.log2(bound))) if bound > 0 else 31
    while True:
        plan = _try_accumulator(eq, j, ops_p, coefs, icpt, f_acc, acc_bits, align)
        if plan is not None:
            break
        f_acc -= 1
        if f_acc < 0:  # pragma: no cover - the bound above leaves f_acc >= 1
            raise InputError(f"output {eq.name}: no accumulator format holds its terms")
    acc_ops, acc_lo, acc_hi, acc_err = plan
    s = 0
    while not _fits(rshr(acc_lo, s), rshr(acc_hi, s), 32):
        s += 1
    f_out = f_acc - s
    unit = eq.unit
    if f_out < 0:
        reach = math.ldexp(max(abs(acc_lo), abs(acc_hi)), -f_acc)
        raise InputError(f"output {eq.name}: its terms reach {reach:.3g} {unit} in the input domain; an int32 "
                         f"output would need an LSB over 1 {unit} (fixed point limit)")
    for op in acc_ops:
        pl.add(op)
    lo, hi = rshr(acc_lo, s), rshr(acc_hi, s)
    err = acc_err + (math.ldexp(0.5, -f_out) if s > 0 else 0.0)
    pl.add(FixedOp("out", f"o_{eq.name}", (), 0, s, f_out, 32, lo, hi, acc_lo, acc_hi, err,
                   math.ldexp(max(abs(lo), abs(hi)), -f_out), f"{eq.name} [{unit}]", j, prod_bits=acc_bits))
    return FixedOutput(eq.name, unit, j, f_out, f_acc, err, lo, hi, len(eq.terms), acc_bits, align)


def _try_accumulator(eq, j, ops_p, coefs, icpt, f_acc, acc_bits, align=False):
    """The init and term operations of one output with the accumulator in Q(f_acc), or None when a
    partial sum could leave the accumulator's budget."""
    coef_bits, prod_bits = (32, 64) if acc_bits == 64 else (16, 32)
    out = []
    ic = _round(icpt * Fraction(2) ** f_acc)
    lo = hi = ic
    if not _fits(lo, hi, acc_bits):
        return None
    err = float(abs(Fraction(ic) / Fraction(2) ** f_acc - icpt))
    out.append(FixedOp("init", f"acc_{eq.name}_0", (), ic, 0, f_acc, acc_bits, lo, hi, lo, hi, err, 0.0,
                       f"{eq.name} intercept", j, prod_bits=acc_bits))
    for i, (p, c, t) in enumerate(zip(ops_p, coefs, eq.terms)):
        # the coefficient's Q format: the finest that fits its int, at most MAX_SHIFT bits of shift away
        if c == 0:
            fc = f_acc - p.frac_bits
        else:
            fc = math.floor(coef_bits - 1 - _log2(c)) + 1
            while abs(_round(c * Fraction(2) ** fc)) > BUDGET[coef_bits]:
                fc -= 1
            fc = min(fc, f_acc - p.frac_bits + MAX_SHIFT[prod_bits])
        if align:
            fc -= (fc + p.frac_bits - f_acc) % 8
        cq = _round(c * Fraction(2) ** fc)
        s = fc + p.frac_bits - f_acc
        prods = [cq * p.lo, cq * p.hi]
        wlo, whi = min(prods), max(prods)
        tlo, thi = rshr(wlo, s), rshr(whi, s)
        lo, hi = lo + tlo, hi + thi
        if not (_fits(wlo, whi, prod_bits) and _fits(lo, hi, acc_bits) and _fits(tlo, thi, acc_bits)):
            return None
        cerr = float(abs(Fraction(cq) / Fraction(2) ** fc - c))
        cmag = math.ldexp(abs(cq), -fc)
        err += (math.ldexp(0.5, -f_acc) if s > 0 else 0.0) + cmag * p.error + (p.magnitude + p.error) * cerr
        out.append(FixedOp("term", f"acc_{eq.name}_{i + 1}", (p.name,), cq, s, f_acc, acc_bits, lo, hi, wlo, whi,
                           err, math.ldexp(max(abs(tlo), abs(thi)), -f_acc), f"{eq.name} += {t.text}", j,
                           prod_bits=prod_bits))
    return out, lo, hi, err
