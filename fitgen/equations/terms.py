"""Candidate terms of the estimate equations, as data, and the one place they are evaluated.

Canonical text (model files, reports, generated comments):
``v{k}^{e}`` with e in 1, 2, 3, 4, -1, -2, -3, -4, 1/2, 1/3, 1/4 (the paper's 11 kinds);
``dx``, ``dy``, ``dz`` and ``v{k}*dx``, ``v{k}*dy``, ``v{k}*dz`` (the 6 further kinds the
paper allows for the rotation outputs; d is the model's own displacement estimate);
``hc1^2*hs2*hr``: a monomial (degree <= 3) in the ring's harmonics (family ``harmonics``,
:class:`Harmonics`): hc_m, hs_m = sum_k cos|sin(m phi_k) v_k / sum_k v_k, hr = 1 / sum_k v_k.

Domain rule: inputs are clamped into the fitted domain [min_k, max_k] before any
power is taken (Python and C alike), and an element whose training readings are not
all > 0 is never offered a negative or fractional power, so those powers always see
an input >= min_k > 0. Harmonic terms need sum_k min_k > 0, so the ring's sum stays
>= that > 0 on clamped inputs.
"""

from __future__ import annotations

import itertools
import re
from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from fitgen.base.errors import InputError, RowError
from fitgen.equations.roots import cbrt
from fitgen.physics.pose import POSE_NAMES

# the paper's order: v, v^2, v^3, v^4, 1/v, 1/v^2, 1/v^3, 1/v^4, v^1/2, v^1/3, v^1/4
EXPONENTS: tuple[str, ...] = ("1", "2", "3", "4", "-1", "-2", "-3", "-4", "1/2", "1/3", "1/4")
DISPLACEMENTS: tuple[str, ...] = POSE_NAMES[:3]
ROTATIONS: tuple[str, ...] = POSE_NAMES[3:]

# candidate exponent families a user may restrict the scope to
FAMILIES = {
    "all": EXPONENTS,
    "no-roots": tuple(e for e in EXPONENTS if "/" not in e),
    # positive integer powers only: no division and no roots on the device
    "integer": ("1", "2", "3", "4"),
    # the paper's powers and monomials of the ring's harmonics (Harmonics)
    "harmonics": EXPONENTS,
}
HARMONIC_DEGREE = {"harmonics": 3}  # per family: highest degree of a harmonic monomial (0: none)
# the families every model of which fixed point can run: no roots, no harmonic terms (fitgen.equations.fixedpoint)
FIXED_FAMILIES = ("no-roots", "integer")


@dataclass(frozen=True, order=True)
class Term:
    """One regressor: v_k^e (``element``, ``exponent``), d (``mult``), or v_k * d.

    ``element`` is 1-based (0: no element); ``exponent`` is a text from EXPONENTS
    ("" when there is no element); ``mult`` is "", "dx", "dy" or "dz".
    """

    element: int = 0
    exponent: str = ""
    mult: str = ""
    harm: str = ""  # a canonical harmonic monomial, alone (element 0, no mult)

    def __post_init__(self):
        if self.harm:
            if self.element or self.exponent or self.mult or canonical_monomial(self.harm) != self.harm:
                raise InputError(f"invalid term {self!r}")
            return
        if self.element < 0 or (self.element == 0) != (self.exponent == ""):
            raise InputError(f"invalid term {self!r}")
        if self.exponent and self.exponent not in EXPONENTS:
            raise InputError(f"unknown exponent {self.exponent!r} (allowed: {', '.join(EXPONENTS)})")
        if self.mult and self.mult not in DISPLACEMENTS:
            raise InputError(f"unknown multiplier {self.mult!r}")
        if self.mult and self.element and self.exponent != "1":
            raise InputError("a displacement product takes v_k to the power 1 only")
        if not self.element and not self.mult:
            raise InputError("the intercept is not a term")

    @property
    def text(self) -> str:
        if self.harm:
            return self.harm
        if not self.element:
            return self.mult
        if self.mult:
            return f"v{self.element}*{self.mult}"
        return f"v{self.element}^{self.exponent}"

    @property
    def power(self) -> Fraction | None:
        return Fraction(self.exponent) if self.exponent else None

    @property
    def needs_positive(self) -> bool:
        """True for negative and fractional powers: they need an input > 0."""
        p = self.power
        return p is not None and (p < 0 or p.denominator != 1)

    def __str__(self) -> str:
        return self.text


_TERM_RE = re.compile(r"^(?:v([1-9][0-9]*)(?:\^(-?[1-4](?:/[1-4])?)|\*(d[xyz]))|(d[xyz]))$")
_FACTOR_RE = re.compile(r"^(h[cs][1-9][0-9]?|hr)(?:\^([23]))?$")
MAX_HARMONIC_DEGREE = 3


def symbol_key(sym: str) -> tuple:
    """Order of harmonic symbols: hc1, hs1, hc2, hs2, ..., hr last."""
    return (1 << 20, 0) if sym == "hr" else (int(sym[2:]), sym[1] == "s")


def monomial_factors(text: str) -> list[str]:
    """The factors of a harmonic monomial, powers expanded, in the order they are multiplied."""
    out = []
    for part in text.split("*"):
        m = _FACTOR_RE.match(part)
        if not m:
            raise InputError(f"not a harmonic monomial: {text!r} (forms: hc1, hs2^2*hr, hc1*hs1*hc2)")
        out += [m.group(1)] * int(m.group(2) or 1)
    if len(out) > MAX_HARMONIC_DEGREE:
        raise InputError(f"harmonic monomial {text!r} has degree {len(out)} (at most {MAX_HARMONIC_DEGREE})")
    return sorted(out, key=symbol_key)


def monomial_text(factors) -> str:
    syms = sorted(set(factors), key=symbol_key)
    return "*".join(s if factors.count(s) == 1 else f"{s}^{factors.count(s)}" for s in syms)


def canonical_monomial(text: str) -> str:
    return monomial_text(monomial_factors(text))


def parse_term(text: str) -> Term:
    """The :class:`Term` of a canonical text; anything else is an InputError."""
    if isinstance(text, str) and text.strip().startswith("h"):
        return Term(harm=canonical_monomial(text.strip()))
    m = _TERM_RE.match(text.strip()) if isinstance(text, str) else None
    if not m:
        raise InputError(f"not a term: {text!r} (forms: v3^-2, v8^1/4, dx, v2*dz, hc1^2*hr)")
    if m.group(4):
        return Term(mult=m.group(4))
    if m.group(3):
        return Term(int(m.group(1)), "1", m.group(3))
    return Term(int(m.group(1)), m.group(2))


@dataclass(frozen=True)
class Harmonics:
    """The ring's harmonics: per symbol (hc_m, hs_m) its weight on each input, in order.

    Weights are cos(m phi_k) and sin(m phi_k) of each element's azimuth phi_k, snapped to 0 below
    1e-12 so that exactly-zero weights are skipped alike by Python and C (an azimuth of NaN, an
    element on the axis, weighs 0); a symbol whose weights are all 0 is dropped. ``hr`` (1 / the
    ring's sum) needs no weights.
    """

    weights: tuple[tuple[str, tuple[float, ...]], ...]

    @classmethod
    def from_azimuths(cls, azimuth_rad) -> "Harmonics":
        phi = np.asarray(azimuth_rad, dtype=float)
        out = []
        for m in range(1, phi.size // 2 + 1):
            for kind, fn in (("c", np.cos), ("s", np.sin)):
                with np.errstate(invalid="ignore"):
                    w = fn(m * phi)
                w = np.where(np.isnan(w) | (np.abs(w) < 1e-12), 0.0, w)
                if np.any(w):
                    out.append((f"h{kind}{m}", tuple(float(x) for x in w)))
        return cls(tuple(out))

    @classmethod
    def from_dict(cls, data, n_inputs: int, origin: str) -> "Harmonics":
        if not isinstance(data, dict) or not data:
            raise InputError(f"{origin}: inputs.harmonics must map symbols to weights")
        out = []
        for sym, w in data.items():
            if not isinstance(sym, str) or not _FACTOR_RE.match(sym) or sym == "hr" or "^" in sym:
                raise InputError(f"{origin}: inputs.harmonics: {sym!r} is not a harmonic symbol (hc1, hs1, ...)")
            if (not isinstance(w, list) or len(w) != n_inputs
                    or not all(isinstance(x, (int, float)) and not isinstance(x, bool) and np.isfinite(x) for x in w)):
                raise InputError(f"{origin}: inputs.harmonics.{sym}: {n_inputs} finite weights expected")
            if not any(w):  # from_azimuths drops such a symbol: its sum has no term to start from (predict's TypeError)
                raise InputError(f"{origin}: inputs.harmonics.{sym}: every weight is 0, which no ring gives (its "
                                 "symbol is left out instead)")
            out.append((sym, tuple(float(x) for x in w)))
        return cls(tuple(sorted(out, key=lambda kv: symbol_key(kv[0]))))

    def to_dict(self) -> dict:
        return {sym: list(w) for sym, w in self.weights}

    @property
    def symbols(self) -> tuple[str, ...]:
        return tuple(sym for sym, _ in self.weights) + ("hr",)

    def values(self, v: np.ndarray) -> dict[str, np.ndarray]:
        """Each symbol's column for rows of (clamped) inputs, by the generated C's operations.

        sum = v1 + v2 + ... (left to right); hr = 1 / sum; h = (w1*v1 + w2*v2 + ...) * hr, zero
        weights skipped. Computed in v's dtype, so a float32 v gives the float C's roundings.
        """
        dt = v.dtype.type
        total = v[:, 0]
        for k in range(1, v.shape[1]):
            total = total + v[:, k]
        hr = dt(1.0) / total
        out = {"hr": hr}
        for sym, w in self.weights:
            acc = None
            for k, wk in enumerate(w):
                if wk != 0.0:
                    p = dt(wk) * v[:, k]
                    acc = p if acc is None else acc + p
            out[sym] = acc * hr
        return out

    def slopes(self, v: np.ndarray, vals: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """d(symbol) / d(v_k): (n, N) per symbol. dh/dv_k = (w_k - h) hr, d(hr)/dv_k = -hr^2."""
        hr = vals["hr"]
        out = {"hr": np.repeat((-hr * hr)[:, None], v.shape[1], axis=1)}
        for sym, w in self.weights:
            out[sym] = (np.asarray(w)[None, :] - vals[sym][:, None]) * hr[:, None]
        return out

    def bounds(self, lo: np.ndarray, hi: np.ndarray) -> dict[str, float]:
        """|symbol| at most this on the domain [lo, hi] (needs sum(lo) > 0)."""
        smin = float(np.sum(lo))
        big = np.maximum(np.abs(lo), np.abs(hi))
        out = {"hr": 1.0 / smin}
        with np.errstate(over="ignore"):  # weights past float's range: inf, which the caller refuses
            for sym, w in self.weights:
                out[sym] = float(np.sum(np.abs(w) * big)) / smin
        return out


def harmonic_monomials(symbols, degree: int) -> list[str]:
    """Every monomial of degree 1..``degree`` in the symbols, in a fixed order."""
    out = []
    for deg in range(1, degree + 1):
        for combo in itertools.combinations_with_replacement(sorted(symbols, key=symbol_key), deg):
            out.append(monomial_text(list(combo)))
    return out


def initial_terms(n_elements: int, exponents=EXPONENTS) -> list[Term]:
    """The paper's eq. 1 generalised to N elements: v_k^-1 and v_k^-2 for every k.

    For a family without both of those powers (e.g. ``integer``), the same shape from what it
    allows: its first two exponents in the paper's order (v_k and v_k^2 for ``integer``).
    """
    first = ("-1", "-2") if {"-1", "-2"} <= set(exponents) else tuple(e for e in EXPONENTS if e in exponents)[:2]
    return [Term(k, e) for k in range(1, n_elements + 1) for e in first]


def candidate_terms(n_elements: int, output: str, *, exponents=EXPONENTS, d_terms: bool = True,
                    positive: np.ndarray | None = None, harmonics: "Harmonics | None" = None,
                    harmonic_degree: int = 0) -> list[Term]:
    """The scope of one output, in a fixed order (power kinds in the paper's order, then elements).

    Rotation outputs also get dx, dy, dz and v_k*dx, v_k*dy, v_k*dz when ``d_terms``.
    ``positive[k-1]`` False removes element k's negative and fractional powers. With
    ``harmonics`` and ``harmonic_degree`` > 0, every monomial of the ring's harmonics up to
    that degree comes last.
    """
    out = []
    for e in exponents:
        for k in range(1, n_elements + 1):
            t = Term(k, e)
            if positive is not None and t.needs_positive and not positive[k - 1]:
                continue
            out.append(t)
    if output in ROTATIONS and d_terms:
        out += [Term(mult=d) for d in DISPLACEMENTS]
        out += [Term(k, "1", d) for d in DISPLACEMENTS for k in range(1, n_elements + 1)]
    if harmonics is not None and harmonic_degree > 0:
        out += [Term(harm=h) for h in harmonic_monomials(harmonics.symbols, harmonic_degree)]
    return out


def element_powers(v: np.ndarray, exponent: str) -> np.ndarray:
    """v ** exponent by the exact operations the generated C uses, so both round alike.

    v2 = v*v, v3 = v2*v, v4 = v2*v2, v^-e = 1/v^e, sqrt, sqrt(sqrt(v)) and the cube root of
    fitgen.equations.roots (never libm's or numpy's cbrt, whose bits differ between libraries and CPUs).
    """
    if exponent == "1/2":
        return np.sqrt(v)
    if exponent == "1/3":
        return cbrt(v)
    if exponent == "1/4":
        return np.sqrt(np.sqrt(v))
    e = int(exponent)
    m = abs(e)
    v2 = v * v
    p = v if m == 1 else v2 if m == 2 else v2 * v if m == 3 else v2 * v2
    return 1.0 / p if e < 0 else p


def _harmonic_values(terms, inputs, harmonics):
    if not any(t.harm for t in terms):
        return None
    if harmonics is None:
        raise InputError(f"term {next(t for t in terms if t.harm).text} needs the ring's harmonics")
    return harmonics.values(inputs)


def monomial_value(text: str, vals: dict[str, np.ndarray]) -> np.ndarray:
    """A harmonic monomial's column: its factors multiplied left to right, as the C does."""
    factors = monomial_factors(text)
    for f in factors:
        if f not in vals:
            raise InputError(f"harmonic monomial {text} needs {f}, which this ring does not have")
    out = vals[factors[0]]
    for f in factors[1:]:
        out = out * vals[f]
    return out


def design_matrix(terms: list[Term], inputs: np.ndarray, d: np.ndarray | None = None,
                  harmonics: Harmonics | None = None) -> np.ndarray:
    """Columns of the terms for rows of ``inputs`` (n, N) and displacement estimates ``d`` (n, 3).

    Inputs are used as given: clamping into the domain is the caller's (the model's) job.
    ``harmonics``: the ring's (:class:`Harmonics`), for harmonic terms.
    """
    n = inputs.shape[0]
    cols = np.empty((n, len(terms)))
    vals = _harmonic_values(terms, inputs, harmonics)
    # powers already computed, by (element, exponent): kept as views, never as copies
    cache: dict[tuple[int, str], np.ndarray] = {}
    for j, t in enumerate(terms):
        col = None
        if t.harm:
            cols[:, j] = monomial_value(t.harm, vals)
            continue
        if t.element:
            if t.element > inputs.shape[1]:
                raise InputError(f"term {t.text} needs input v{t.element}; the data has {inputs.shape[1]} inputs")
            key = (t.element, t.exponent)
            if key not in cache:
                cache[key] = element_powers(inputs[:, t.element - 1], t.exponent)
                if not t.mult:
                    cols[:, j] = cache[key]
                    cache[key] = cols[:, j]
                    continue
            col = cache[key]
        if t.mult:
            if d is None:
                raise InputError(f"term {t.text} needs the displacement estimates")
            dcol = d[:, DISPLACEMENTS.index(t.mult)]
            col = dcol if col is None else col * dcol
        cols[:, j] = col
    return cols


FIT_COLUMN_LIMIT = 1e150  # a column's square summed over a million rows stays within double's range


def finite_design_matrix(terms: list[Term], inputs: np.ndarray, d: np.ndarray | None, harmonics: Harmonics | None,
                         first_row: int, what: str = "") -> np.ndarray:
    """:func:`design_matrix` of data rows ``first_row`` + 1.. for a fit; InputError naming the first term and row
    that are not finite, or past what the fit's sums of squares hold (FIT_COLUMN_LIMIT: a reading too close to 0
    for a negative power), without numpy's warnings before it."""
    with np.errstate(all="ignore"):
        cols = design_matrix(terms, inputs, d, harmonics)
    bad = np.argwhere(~(np.abs(cols) <= FIT_COLUMN_LIMIT))
    if bad.size:
        r, c = bad[0]
        x = cols[r, c]
        size = ("not finite" if not np.isfinite(x) else
                f"{x:.3g}, past the {FIT_COLUMN_LIMIT:g} the fit's sums of squares hold,")
        raise RowError(f"candidate term {terms[c].text}{what} is {size} on data row ", first_row + int(r),
                       " (an input too close to 0?)")
    return cols


def element_power_slopes(v: np.ndarray, exponent: str) -> np.ndarray:
    """d(v ** exponent) / dv."""
    p = float(Fraction(exponent))
    return p * v ** (p - 1.0)


def design_jacobian(terms: list[Term], inputs: np.ndarray, d: np.ndarray | None = None,
                    d_jac: np.ndarray | None = None, harmonics: Harmonics | None = None) -> np.ndarray:
    """d(column j) / d(input k) for rows of ``inputs``: an array (n, N, len(terms)).

    ``d_jac`` (n, 3, N) is the gradient of each displacement estimate by the inputs, for the
    d-terms (the device computes d from the same noisy readings); None treats d as exact.
    """
    n, n_in = inputs.shape
    out = np.zeros((len(terms), n, n_in))  # term by term, each term's block contiguous: filled ~2x faster
    vals = _harmonic_values(terms, inputs, harmonics)
    slopes = None if vals is None else harmonics.slopes(inputs, vals)
    for j, t in enumerate(terms):
        if t.harm:
            factors = monomial_factors(t.harm)
            # product rule over the expanded factors
            for i in range(len(factors)):
                others = np.ones(n)
                for o, f in enumerate(factors):
                    if o != i:
                        others = others * vals[f]
                out[j] += others[:, None] * slopes[factors[i]]
            continue
        base = None
        if t.element:
            if t.element > n_in:
                raise InputError(f"term {t.text} needs input v{t.element}; the data has {n_in} inputs")
            slope = element_power_slopes(inputs[:, t.element - 1], t.exponent)
            base = element_powers(inputs[:, t.element - 1], t.exponent) if t.mult else None
        if not t.mult:
            out[j, :, t.element - 1] = slope
            continue
        if d is None:
            raise InputError(f"term {t.text} needs the displacement estimates")
        i = DISPLACEMENTS.index(t.mult)
        if d_jac is not None:
            out[j] = d_jac[:, i, :] if base is None else base[:, None] * d_jac[:, i, :]
        if base is not None:
            out[j, :, t.element - 1] += slope * d[:, i]
    return out.transpose(1, 2, 0)
