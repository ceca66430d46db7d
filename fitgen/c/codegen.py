"""From a fitted :class:`Model` to a header-only C99 estimator, through jinja2 templates.

The templates see only a :class:`CModel`: numbers already turned into round-trip
literals and names already checked as C identifiers.
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import jinja2
import numpy as np

from fitgen import __version__
from fitgen.c.cgen import GCC_FP, c_real, fp_guard, identifier, nonfinite_test, prefix_identifier
from fitgen.c.targets import check_model, check_precision
from fitgen.base.errors import InputError
from fitgen.base.fileio import write_in_folder
from fitgen.equations.floatrange import float_domain
from fitgen.equations.model import Model
from fitgen.equations.rounding import PRECISIONS
from fitgen.equations.terms import DISPLACEMENTS, EXPONENTS, monomial_factors

STYLES = ("table", "unrolled")
# C enum names of the exponent kinds, in EXPONENTS order
EXP_CODE = {"1": "P1", "2": "P2", "3": "P3", "4": "P4", "-1": "M1", "-2": "M2", "-3": "M3", "-4": "M4",
            "1/2": "R2", "1/3": "R3", "1/4": "R4"}
# Largest sum of |coefficient * term| allowed anywhere in the domain. float: far enough
# below FLT_MAX (3.4e38) that no partial sum can overflow. double: past 1e15 a sum in
# mm or deg keeps no correct digit (eps 2.2e-16); such a model is refused as absurd.
_LIMIT = {"double": 1e15, "float": 1e30}
_FLOAT_MAX = float(np.finfo(np.float32).max)
# a refinement's normal equations: a step's Cholesky takes their square roots, never their squares, and solves
# for the step's own scale, so overflow (not cancellation) is what bounds them
_REFINE_LIMIT = {"double": 1e150, "float": 1e30}
Literals = tuple[str, ...]  # C literals of reals (cgen.c_real), one per input, component, element or term


@dataclass(frozen=True)
class CTerm:
    element: int  # 0-based input index, -1 for a bare displacement term, the monomial's index for a harmonic one
    exp: str  # exponent code (P1..R4), "" for a bare displacement term, "HARM" for a harmonic monomial
    mult: int  # 0 none, 1 dx, 2 dy, 3 dz
    coef: str  # C literal
    text: str  # canonical term text, for comments


@dataclass(frozen=True)
class CHarmonic:
    name: str  # symbol, a C identifier (hc1, hs1, ...)
    terms: tuple[tuple[int, str], ...]  # (0-based input, weight literal) for the nonzero weights


@dataclass(frozen=True)
class CMonomial:
    factors: tuple[str, ...]  # symbols multiplied left to right
    text: str


@dataclass(frozen=True)
class COutput:
    name: str
    index: int
    unit: str
    intercept: str
    terms: tuple[CTerm, ...]
    d_slot: int  # 1..3 when this output is dx, dy or dz (its value feeds d-terms), else 0


@dataclass(frozen=True)
class CRefine:
    """The refinement's tables as literals (fitgen.equations.refine)."""

    steps: int
    cbrt: bool
    degree: int
    centre: Literals
    scale: Literals
    lo: Literals
    hi: Literals
    weights: Literals
    intercepts: Literals
    prior: tuple[Literals, ...]
    starts: tuple[int, ...]  # element k's terms: starts[k] .. starts[k + 1] - 1
    monos: tuple[tuple[int, ...], ...]  # the monomials a step computes (fitgen.equations.refine.Refinement.monomials)
    table: tuple[tuple[int, ...], ...]  # per term: monomial, then per component (power, derivative's monomial or NONE)
    terms: Literals  # per term, its coefficient
    factors: tuple[tuple[tuple[int, int], ...], ...]  # per monomial, its (component, power) with power > 0
    powers: Literals  # each power 0 .. 8, as a real
    none: int


@dataclass(frozen=True)
class CModel:
    prefix: str
    upper: str
    precision: str
    style: str
    n_inputs: int
    outputs: tuple[COutput, ...]
    input_min: Literals
    input_max: Literals
    needed: tuple[tuple[str, ...], ...]  # per input: exponent codes to compute, in EXPONENTS order
    kinds: tuple[str, ...]  # exponent codes some input needs
    model_hash: str
    version: str
    uses_d: bool
    input_units: str
    fma: bool  # each term added by fma(): one rounding instead of two
    harmonics: tuple[CHarmonic, ...] = ()  # the ring's harmonics the monomials use (hr is always computed)
    monomials: tuple[CMonomial, ...] = ()  # harmonic monomials, in order of first use
    refine: CRefine | None = None
    far: tuple = ()  # per output, (low, high) literals past which it lies far outside the fitted pose box, or None


def term_magnitudes(model: Model) -> dict[str, float]:
    """Upper bound of |intercept| + sum |coefficient * term| over the input domain, per output.

    Interval arithmetic on the clamped inputs: |v|^p is largest at the domain's end farthest
    from 0 for p > 0, and at its lower end (> 0 by the model's rule) for p < 0; d-terms use
    the bound of the displacement output they multiply.
    """
    lo, hi = model.input_min, model.input_max
    bound_d: dict[str, float] = {}
    bound_h = model.harmonics.bounds(lo, hi) if model.harmonics is not None else {}
    out = {}
    with np.errstate(over="ignore"):  # absurd coefficients reach inf: check_magnitudes says so in one line
        for eq in model.equations:
            total = abs(eq.intercept)
            for t, c in zip(eq.terms, eq.coefficients):
                mag = 1.0
                if t.harm:
                    for f in monomial_factors(t.harm):
                        mag *= bound_h[f]
                if t.element:
                    a, b = lo[t.element - 1], hi[t.element - 1]
                    num, _, den = t.exponent.partition("/")
                    p = float(num) / float(den or 1)
                    mag = max(abs(a), abs(b)) ** p if p > 0 else a ** p
                if t.mult:
                    mag *= bound_d[t.mult]
                total += abs(c) * mag
            out[eq.name] = total
            if eq.name in DISPLACEMENTS:
                bound_d[eq.name] = total
    return out


def check_magnitudes(model: Model, precision: str) -> None:
    """InputError when an output's terms, or the refinement's steps, can reach beyond what ``precision``
    (float, double) sums safely."""
    for name, mag in term_magnitudes(model).items():
        if not mag <= _LIMIT[precision]:
            raise InputError(f"output {name}: its terms reach {mag:.3g} in the input domain, over the {precision} "
                             f"limit {_LIMIT[precision]:g} (absurd coefficients, or a sum that could overflow)")
    if model.refine is not None:
        mag = model.refine.magnitude(np.maximum(np.abs(model.input_min), np.abs(model.input_max)))
        if not mag <= _REFINE_LIMIT[precision]:
            raise InputError(f"refine: its steps reach {mag:.3g} over its pose box, over the {precision} limit "
                             f"{_REFINE_LIMIT[precision]:g} (absurd weights, prior or forward coefficients)")


def build_cmodel(model: Model, precision: str = "double", style: str = "table", prefix: str = "tm",
                 fma: bool = False) -> CModel:
    if precision not in PRECISIONS:
        raise InputError(f"precision must be one of {', '.join(PRECISIONS)}, got {precision!r}")
    if precision == "fixed":
        raise InputError("fixed point has its own plan: use fitgen.equations.fixedpoint.build_fixed")
    if style not in STYLES:
        raise InputError(f"style must be one of {', '.join(STYLES)}, got {style!r}")
    prefix = prefix_identifier(prefix)
    if precision == "float" and (problem := model.float_problem()):
        raise InputError(problem)
    check_magnitudes(model, precision)
    domain = float_domain(model) if precision == "float" else (model.input_min, model.input_max)
    outs = []
    needed = [set() for _ in range(model.n_inputs)]
    monomials: list[str] = []
    for i, eq in enumerate(model.equations):
        terms = []
        for t, c in zip(eq.terms, eq.coefficients):
            if t.harm:
                if t.harm not in monomials:
                    monomials.append(t.harm)
                terms.append(CTerm(monomials.index(t.harm), "HARM", 0, c_real(c, precision), t.text))
                continue
            if t.element:
                needed[t.element - 1].add(t.exponent)
            terms.append(CTerm(t.element - 1, EXP_CODE[t.exponent] if t.element else "",
                               DISPLACEMENTS.index(t.mult) + 1 if t.mult else 0, c_real(c, precision), t.text))
        d_slot = DISPLACEMENTS.index(eq.name) + 1 if eq.name in DISPLACEMENTS else 0
        outs.append(COutput(identifier(eq.name, "output name"), i, eq.unit, c_real(eq.intercept, precision),
                            tuple(terms), d_slot))
    return CModel(
        prefix=prefix,
        upper=prefix.upper(),
        precision=precision,
        style=style,
        n_inputs=model.n_inputs,
        outputs=tuple(outs),
        input_min=tuple(c_real(x, precision) for x in domain[0]),
        input_max=tuple(c_real(x, precision) for x in domain[1]),
        needed=tuple(tuple(EXP_CODE[e] for e in EXPONENTS if e in need) for need in needed),
        kinds=tuple(EXP_CODE[e] for e in EXPONENTS if any(e in need for need in needed)),
        model_hash=model.sha256,
        version=__version__,
        uses_d=any(e.uses_d for e in model.equations),
        input_units=model.input_units if model.input_units in ("mT", "V", "codes") else "units",
        fma=bool(fma),
        harmonics=_c_harmonics(model, monomials, precision),
        monomials=tuple(CMonomial(tuple(monomial_factors(h)), h) for h in monomials),
        refine=_c_refine(model, precision),
        far=tuple(None if b is None else _far_literals(*b, precision) for b in model.far_per_output()),
    )


def _far_literals(low: float, high: float, precision: str) -> tuple[str, str]:
    """The literals of one output's far bounds; in float rounded inward (low up, high down), so that a float
    estimate is below or above them exactly when it is below or above the double bounds predict compares with."""
    if precision == "float" and abs(low) <= _FLOAT_MAX and abs(high) <= _FLOAT_MAX:
        lo, hi = np.float32(low), np.float32(high)
        low = float(np.nextafter(lo, np.float32(np.inf)) if float(lo) < low else lo)
        high = float(np.nextafter(hi, np.float32(-np.inf)) if float(hi) > high else hi)
    return c_real(low, precision), c_real(high, precision)


NONE = 0xFFFF  # the refinement's "no derivative" index (TM_R_NONE)


def _c_refine(model: Model, precision: str) -> CRefine | None:
    r = model.refine
    if r is None:
        return None

    def lits(xs):
        return tuple(c_real(x, precision) for x in xs)

    starts = [0]
    for eq in r.forward:
        starts.append(starts[-1] + len(eq.exponents))
    monos = r.monomials
    if max(starts[-1], len(monos)) >= NONE:
        raise InputError(f"the refinement has {starts[-1]} forward terms and {len(monos)} monomials; "
                         f"its tables index fewer than {NONE}")
    exps = [e for eq in r.forward for e in eq.exponents]
    table = tuple((row[0],) + tuple(x for j in range(5) for x in (e[j], NONE if row[1 + j] < 0 else row[1 + j]))
                  for e, row in zip(exps, r.term_table()))
    return CRefine(r.steps, r.transform == "cbrt", r.degree, lits(r.centre), lits(r.scale), lits(r.pose_min),
                   lits(r.pose_max), lits(r.weights), lits(eq.intercept for eq in r.forward),
                   tuple(lits(row) for row in r.prior), tuple(starts), monos, table,
                   lits(c for eq in r.forward for c in eq.coefficients),
                   tuple(tuple((j, a) for j, a in enumerate(e) if a) for e in monos), lits(range(9)), NONE)


def _c_harmonics(model: Model, monomials: list[str], precision: str) -> tuple[CHarmonic, ...]:
    used = {f for h in monomials for f in monomial_factors(h)}
    if not monomials:
        return ()
    return tuple(CHarmonic(identifier(sym, "harmonic"), tuple((k, c_real(w, precision)) for k, w in enumerate(ws) if w != 0.0))
                 for sym, ws in model.harmonics.weights if sym in used)


def _env() -> jinja2.Environment:
    loader = jinja2.FileSystemLoader(str(resources.files("firmware_templates")))
    return jinja2.Environment(loader=loader, undefined=jinja2.StrictUndefined, autoescape=False,
                              keep_trailing_newline=True, trim_blocks=True, lstrip_blocks=True)


def _fixed_far(fm) -> tuple:
    """Per output, the int32 bounds (low, high) of FixedModel.far in the output's Q format, or None: an
    integer out lies below x (a real) exactly when it lies below ceil(x), and above y exactly when above floor(y).
    A side no int32 can pass (its bound past the format's range) is None: that test is left out."""
    import math

    top = 2**31 - 1

    def side(x: float, frac_bits: int, rnd, below: bool):
        b = rnd(x * 2.0**frac_bits)
        if (b <= -top - 1) if below else (b >= top):
            return None
        return int(min(max(b, -top), top))

    return tuple(None if b is None else (side(b[0], o.frac_bits, math.ceil, True),
                                         side(b[1], o.frac_bits, math.floor, False))
                 for o, b in zip(fm.outputs, fm.far or (None,) * len(fm.outputs)))


def render_fixed_header(fm, prefix: str = "tm") -> str:
    """The text of ``<prefix>_model.h`` for a fixed-point plan (:class:`fitgen.equations.fixedmodel.FixedModel`)."""
    from fitgen.c.fixedc import avr_path, plan_line

    prefix = prefix_identifier(prefix)
    units = fm.input_units if fm.input_units in ("mT", "V", "codes") else "units"
    return _env().get_template("model_fixed.h.j2").render(
        m=fm, P=prefix, U=prefix.upper(), input_units=units, A=avr_path(fm), plan_line=plan_line(fm),
        far=_fixed_far(fm),
        input_lsb=c_real(fm.input_lsb, "double"), input_offset=c_real(fm.input_offset, "double"))


def render_header(model: Model, precision: str = "double", style: str = "table", prefix: str = "tm",
                  fma: bool = False, input_lsb: float | None = None, input_offset: float | None = None,
                  target: str | None = None) -> str:
    """The text of ``<prefix>_model.h``; ``fma`` sums each term with C99 fma()/fmaf().

    ``target``: a core of fitgen.c.targets.TARGETS; a precision it cannot run is an InputError. A float
    or double header does not depend on it: one header builds for every core (on AVR its tables go to
    flash); a fixed-point one is planned for the core's multiply (fitgen.equations.fixedpoint.build_fixed).

    ``precision="fixed"``: integer ADC codes in (value = input_offset + input_lsb * code; by
    default the scale of the model's sensor, see :func:`fitgen.equations.inputscale.default_input_scale`),
    int32 outputs out; ``style`` does not apply (the fixed header is straight-line code).
    """
    t = check_precision(target, precision)
    check_model(t, model)
    if precision == "fixed":
        from fitgen.equations.inputscale import plan_at

        if fma:
            raise InputError("--fma does not apply to fixed point (it has no floating-point multiply-add)")
        prefix_identifier(prefix)
        return render_fixed_header(plan_at(model, input_lsb, input_offset, t.mul_bits if t else 32)[0], prefix)
    if input_lsb is not None or input_offset is not None:
        raise InputError("an input LSB and offset apply to --precision fixed only")
    cm = build_cmodel(model, precision, style, prefix, fma)
    fp_before, fp_after = fp_guard(f"{cm.upper}_FP_SCOPE")
    nonfinite = nonfinite_test(f"{cm.prefix}_nonfinite", f"{cm.upper}_NONFINITE", precision, "0")
    return _env().get_template("model.h.j2").render(m=cm, exp_codes=[EXP_CODE[e] for e in EXPONENTS],
                                                     fp_before=fp_before, fp_after=fp_after, nonfinite=nonfinite)


def render_blob_interpreter() -> str:
    """The text of the firmware's ``cal.c`` (firmware/cal.c.j2): the blob interpreter, its clamp, powers and
    term sums rendered from the macros the table style is (table.j2), so that both round alike."""
    return _env().get_template("firmware/cal.c.j2").render(kinds=[EXP_CODE[e] for e in EXPONENTS], gcc_fp=GCC_FP)


OURS = (b" * Generated by fitgen ", "fitgen codegen")  # what every header it writes holds (its third line)


def write_header(model: Model, folder: str | Path, precision: str = "double", style: str = "table",
                 prefix: str = "tm", fma: bool = False, input_lsb: float | None = None,
                 input_offset: float | None = None, target: str | None = None, inputs=()) -> Path:
    """The header written into ``folder``, which is not one of ``inputs`` (the model's file)."""
    text = render_header(model, precision, style, prefix, fma, input_lsb, input_offset, target)
    return write_in_folder(folder, f"{prefix}_model.h", text, inputs, OURS)
