"""Fixed-point plans of a model for cores without an FPU (Cortex-M0): integer ADC codes in, int32 out.

:func:`build_fixed` turns a :class:`~fitgen.equations.model.Model` into a
:class:`~fitgen.equations.fixedmodel.FixedModel` (the number format and the operations are described
there): the Q format of every value, its range proven by interval arithmetic over the code domain,
and a bound on its error against exact arithmetic. :func:`plan_at` and :func:`sensor_input_scale`
give the input scale (the value of one ADC code) when the user names none.

Q formats are chosen in evaluation order, each the finest that keeps its value inside its
budget (|x| <= 2^31 - 1 for int32 values, |x| <= 2^62 for int64 values and for the int64
products before a shift) over the whole code domain. The proof is interval arithmetic on the
exact integers (Python ints): every operation of the plan is monotone in each operand (a product
over an interval box takes its extremes at the box's corners; a square is handled as one),
so each value's interval holds every value the C can compute from clamped codes.
"""

from __future__ import annotations

import math
from fractions import Fraction

from fitgen import __version__
from fitgen.base.errors import InputError
from fitgen.equations.fixedmodel import INT32_MAX, INT32_MIN, FixedModel, FixedOp, FixedOutput, rshr
from fitgen.equations.model import Model
from fitgen.equations.terms import DISPLACEMENTS

BUDGET = {32: INT32_MAX, 64: 2**62}
MAX_SHIFT = 62
# exponent text -> (C name suffix, how it is computed)
POWER_CODE = {"1": "P1", "2": "P2", "3": "P3", "4": "P4", "-1": "M1", "-2": "M2", "-3": "M3", "-4": "M4"}
# a power's operands: P2 = P1^2, P3 = P2 * P1, P4 = P2^2, M1 = 1/P1, M2 = M1^2, M3 = M2 * M1, M4 = M2^2
_RECIPE = {"P2": ("P1", "P1"), "P3": ("P2", "P1"), "P4": ("P2", "P2"),
           "M2": ("M1", "M1"), "M3": ("M2", "M1"), "M4": ("M2", "M2")}
_POWER_ORDER = ("P1", "P2", "P3", "P4", "M1", "M2", "M3", "M4")
_EXPONENT_OF = {"P1": 1, "P2": 2, "P3": 3, "P4": 4, "M1": -1, "M2": -2, "M3": -3, "M4": -4}
# a domain bound within this many codes of a whole code is taken as that code
SNAP = Fraction(1, 10**6)


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
        lo, hi = max(lo, INT32_MIN), min(hi, INT32_MAX)
        if lo > hi:
            raise InputError(f"input v{k + 1}: its domain [{model.input_min[k]!r}, {model.input_max[k]!r}] "
                             f"holds no whole ADC code at LSB {float(lsb)!r}, offset {float(off)!r}")
        cmin.append(lo)
        cmax.append(hi)
    return cmin, cmax


class _Planner:
    def __init__(self):
        self.ops: list[FixedOp] = []
        self.by_name: dict[str, FixedOp] = {}

    def add(self, op: FixedOp) -> FixedOp:
        if not _fits(op.lo, op.hi, op.bits) or not _fits(op.wide_lo, op.wide_hi, 64):
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

    def mul(self, name: str, a: str, b: str, text: str) -> FixedOp:
        A, B = self.get(a), self.get(b)
        if a == b:
            sq = (A.lo * A.lo, A.hi * A.hi)
            wlo = 0 if A.lo <= 0 <= A.hi else min(sq)
            whi = max(sq)
        else:
            prods = [A.lo * B.lo, A.lo * B.hi, A.hi * B.lo, A.hi * B.hi]
            wlo, whi = min(prods), max(prods)
        s = 0
        while not _fits(rshr(wlo, s), rshr(whi, s), 32):
            s += 1
        f = A.frac_bits + B.frac_bits - s
        err = (math.ldexp(0.5, -f) if s > 0 else 0.0) + A.magnitude * B.error + (B.magnitude + B.error) * A.error
        lo, hi = rshr(wlo, s), rshr(whi, s)
        return self.add(FixedOp("mul", name, (a, b), 0, s, f, 32, lo, hi, wlo, whi, err,
                                math.ldexp(max(abs(lo), abs(hi)), -f), text))

    def recip(self, name: str, a: str, text: str, k: int) -> FixedOp:
        A = self.get(a)
        if A.lo <= 0:
            raise InputError(f"fixed point: v{k + 1}^-1 needs v{k + 1} > 0 over the code domain, "
                             f"but its lowest code gives {float(A.lo) * 2.0 ** -A.frac_bits!r} codes")
        n = 0
        while n < MAX_SHIFT and divr(1 << (n + 1), A.lo) <= INT32_MAX:
            n += 1
        num = 1 << n
        f = n - A.frac_bits
        lo, hi = divr(num, A.hi), divr(num, A.lo)
        amin = math.ldexp(A.lo, -A.frac_bits)
        if not A.error < amin:
            raise InputError(f"fixed point: v{k + 1} is too close to 0 for its reciprocal")  # pragma: no cover
        err = math.ldexp(0.5, -f) + A.error / (amin * (amin - A.error))
        return self.add(FixedOp("recip", name, (a,), num, 0, f, 32, lo, hi, num + A.lo // 2, num + A.hi // 2,
                                err, math.ldexp(hi, -f), text))


def build_fixed(model: Model, input_lsb: float, input_offset: float = 0.0) -> FixedModel:
    """The fixed-point plan of ``model`` for int32 ADC codes c with value input_offset + input_lsb * c.

    Refuses (InputError, one line) roots, domains that hold no code or reach v <= 0 where a
    negative power needs v > 0, and outputs whose range cannot be held in an int32 with an LSB
    of at most 1 unit.
    """
    try:
        lsb_f, off_f = float(input_lsb), float(input_offset)
    except (TypeError, ValueError):
        raise InputError(f"input LSB and offset must be numbers, got {input_lsb!r}, {input_offset!r}") from None
    if not (math.isfinite(lsb_f) and lsb_f > 0):
        raise InputError(f"the input LSB must be a finite number > 0, got {input_lsb!r}")
    if not math.isfinite(off_f):
        raise InputError(f"the input offset must be a finite number, got {input_offset!r}")
    if model.n_inputs > 30:
        raise InputError(f"the model has {model.n_inputs} inputs; the status bit mask holds at most 30")
    if model.refine is not None:
        raise InputError("fixed point has no refinement (its Gauss-Newton steps run in float or double): "
                         "fit without --refine for fixed point")
    for eq in model.equations:
        for t in eq.terms:
            if t.harm:
                raise InputError(f"fixed point has no harmonic terms (they divide by the readings' sum), but output "
                                 f"{eq.name} has {t.text}: fit with --family no-roots (or integer)")
            if t.exponent and "/" in t.exponent:
                raise InputError(f"fixed point takes integer powers only, but output {eq.name} has the root "
                                 f"{t.text}: fit with --family no-roots (or integer)")
    lsb, off = _exact(lsb_f), _exact(off_f)
    cmin, cmax = _code_bounds(model, lsb, off)
    o = off / lsb

    pl = _Planner()
    # which powers each input needs, closed under the recipes
    needed: dict[int, set[str]] = {}
    for eq in model.equations:
        for t in eq.terms:
            if t.element:
                needed.setdefault(t.element - 1, set()).add(POWER_CODE[t.exponent])
    for k in sorted(needed):
        need = needed[k]
        for code in ("P4", "P3", "M4", "M3", "M2"):
            if code in need:
                need.update(_RECIPE[code])
        if need & {"M2", "M3", "M4"}:
            need.add("M1")
        pl.input(k, cmin[k], cmax[k], o)
        for code in _POWER_ORDER[1:]:
            if code not in need:
                continue
            name = f"p{k + 1}_{code}"
            text = f"v{k + 1}^{_EXPONENT_OF[code]}"
            if code == "M1":
                pl.recip(name, f"u{k + 1}", text, k)
            else:
                a, b = (f"u{k + 1}" if c == "P1" else f"p{k + 1}_{c}" for c in _RECIPE[code])
                pl.mul(name, a, b, text)

    outputs = []
    d_name: dict[str, str] = {}
    for j, eq in enumerate(model.equations):
        # each term's operand (a power, v_k * d, or d) and its exact real coefficient (lsb^e folded in)
        operands, coefs = [], []
        for i, (t, c) in enumerate(zip(eq.terms, eq.coefficients)):
            c = _exact(c)
            if t.element and not t.mult:
                code = POWER_CODE[t.exponent]
                operands.append(f"u{t.element}" if code == "P1" else f"p{t.element}_{code}")
                coefs.append(c * lsb ** _EXPONENT_OF[code])
            elif t.element:
                name = f"vd{t.element}_{t.mult}"
                if name not in pl.by_name:
                    pl.mul(name, f"u{t.element}", d_name[t.mult], f"v{t.element}*{t.mult}")
                operands.append(name)
                coefs.append(c * lsb)
            else:
                operands.append(d_name[t.mult])
                coefs.append(c)
        ops_eq = _plan_output(pl, eq, j, operands, coefs)
        outputs.append(ops_eq)
        if eq.name in DISPLACEMENTS:
            d_name[eq.name] = f"o_{eq.name}"
    return FixedModel(model.n_inputs, lsb_f, off_f, model.input_units, tuple(cmin), tuple(cmax), tuple(pl.ops),
                      tuple(outputs), model.sha256, __version__, tuple(model.equations))


def _plan_output(pl: _Planner, eq, j: int, operands: list[str], coefs: list[Fraction]) -> FixedOutput:
    ops_p = [pl.get(n) for n in operands]
    icpt = _exact(eq.intercept)
    bound = abs(float(icpt)) + sum(abs(_float(c)) * (p.magnitude + p.error) for c, p in zip(coefs, ops_p))
    if not bound < 2.0**60:
        raise InputError(f"output {eq.name}: its terms reach {bound:.3g} {eq.unit} in the input domain; an int32 "
                         f"output would need an LSB over 1 {eq.unit} (fixed point limit)")
    # the accumulator: the finest Q format whose every partial sum provably stays within 2^62
    f_acc = min(100, math.floor(math.log2(2.0**61 / bound))) if bound > 0 else 100
    while True:
        plan = _try_accumulator(eq, j, ops_p, coefs, icpt, f_acc)
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
                   math.ldexp(max(abs(lo), abs(hi)), -f_out), f"{eq.name} [{unit}]", j))
    return FixedOutput(eq.name, unit, j, f_out, f_acc, err, lo, hi, len(eq.terms))


def _try_accumulator(eq, j, ops_p, coefs, icpt, f_acc):
    """The init and term operations of one output with the accumulator in Q(f_acc), or None when a
    partial sum could leave the int64 budget."""
    out = []
    ic = _round(icpt * Fraction(2) ** f_acc)
    lo = hi = ic
    if not _fits(lo, hi, 64):
        return None
    err = float(abs(Fraction(ic) / Fraction(2) ** f_acc - icpt))
    out.append(FixedOp("init", f"acc_{eq.name}_0", (), ic, 0, f_acc, 64, lo, hi, lo, hi, err, 0.0,
                       f"{eq.name} intercept", j))
    for i, (p, c, t) in enumerate(zip(ops_p, coefs, eq.terms)):
        # the coefficient's Q format: the finest that fits an int32, at most 62 bits of shift away
        if c == 0:
            fc = f_acc - p.frac_bits
        else:
            fc = math.floor(31 - _log2(c)) + 1
            while abs(_round(c * Fraction(2) ** fc)) > INT32_MAX:
                fc -= 1
            fc = min(fc, f_acc - p.frac_bits + MAX_SHIFT)
        cq = _round(c * Fraction(2) ** fc)
        s = fc + p.frac_bits - f_acc
        prods = [cq * p.lo, cq * p.hi]
        wlo, whi = min(prods), max(prods)
        tlo, thi = rshr(wlo, s), rshr(whi, s)
        lo, hi = lo + tlo, hi + thi
        if not (_fits(wlo, whi, 64) and _fits(lo, hi, 64) and _fits(tlo, thi, 64)):
            return None
        cerr = float(abs(Fraction(cq) / Fraction(2) ** fc - c))
        cmag = math.ldexp(abs(cq), -fc)
        err += (math.ldexp(0.5, -f_acc) if s > 0 else 0.0) + cmag * p.error + (p.magnitude + p.error) * cerr
        out.append(FixedOp("term", f"acc_{eq.name}_{i + 1}", (p.name,), cq, s, f_acc, 64, lo, hi, wlo, whi, err,
                           math.ldexp(max(abs(tlo), abs(thi)), -f_acc), f"{eq.name} += {t.text}", j))
    return out, lo, hi, err


# --- the default input scale ----------------------------------------------------------------------


def default_input_scale(model: Model) -> tuple[float, float, str]:
    """(lsb, offset, where from) of the model's input codes when the user gives none.

    From the sensor the model was fitted for, when its fit notes' sensor hash is a preset's
    (the ADC of its transfer: lsb = (adc_max - adc_min) / (2^bits - 1), offset adc_min, as
    ``fitgen.physics.transfer.quantise`` codes it); otherwise, for inputs in V, the paper sensor's
    16-bit ADC over 0..3.3 V; otherwise an InputError asking for ``--input-lsb``.
    """
    from fitgen.physics.sensor import load_sensor, preset_names

    sha = model.fit_info.get("sensor_sha256") if isinstance(model.fit_info, dict) else None
    if isinstance(sha, str):
        for name in preset_names():
            base = load_sensor(name)
            for kind in ("gmr", "raw"):
                s = base.with_transfer(kind)
                if s.sha256 != sha:
                    continue
                if kind == "gmr" and s.gmr.adc_bits > 0:
                    g = s.gmr
                    return (g.adc_max - g.adc_min) / (2**g.adc_bits - 1), g.adc_min, f"sensor {name} ({kind} ADC)"
                if kind == "raw" and s.raw.adc_bits > 0:
                    return s.raw.full_scale / (2**s.raw.adc_bits - 1), 0.0, f"sensor {name} ({kind} ADC)"
    if model.input_units == "V":
        return 3.3 / 65535, 0.0, "default 16-bit ADC over 0..3.3 V"
    raise InputError(f"fixed point needs the value of one ADC code: give --input-lsb (in {model.input_units})")


def plan_at(model: Model, input_lsb: float | None = None, input_offset: float | None = None) -> tuple[FixedModel, str]:
    """The fixed-point plan at the given input scale, and where the scale came from.

    Without ``input_lsb``: the model's own (:func:`default_input_scale`; ``input_offset`` still
    overrides its offset). With it: that LSB and ``input_offset`` (default 0).
    """
    source = "--input-lsb"
    if input_lsb is None:
        input_lsb, default_offset, source = default_input_scale(model)
        input_offset = default_offset if input_offset is None else input_offset
    return build_fixed(model, input_lsb, input_offset or 0.0), source


FIXED_BITS = 16  # ADC bits assumed for fixed point when the sensor's transfer does not quantise


def sensor_input_scale(sensor) -> tuple[float, float, str]:
    """(lsb, offset, description) of the input codes for fixed point: the ADC of the sensor's
    transfer, or FIXED_BITS bits over its range when the transfer does not quantise."""
    if sensor.transfer == "gmr":
        g = sensor.gmr
        bits = g.adc_bits or FIXED_BITS
        lsb, offset, span = (g.adc_max - g.adc_min) / (2**bits - 1), g.adc_min, f"{g.adc_min:g}..{g.adc_max:g} V"
    else:
        r = sensor.raw
        bits = r.adc_bits or FIXED_BITS
        lsb, offset, span = r.full_scale / (2**bits - 1), 0.0, f"0..{r.full_scale:g} mT"
    src = "the transfer's ADC" if (sensor.gmr.adc_bits if sensor.transfer == "gmr" else sensor.raw.adc_bits) \
        else "assumed: the transfer has no ADC"
    return lsb, offset, f"{bits}-bit codes over {span} (LSB {lsb:.4g} {sensor.units}; {src})"
