"""Candidate terms of the estimate equations, as data, and the one place they are evaluated.

Canonical text (model files, reports, generated comments):
``v{k}^{e}`` with e in 1, 2, 3, 4, -1, -2, -3, -4, 1/2, 1/3, 1/4 (the paper's 11 kinds);
``dx``, ``dy``, ``dz`` and ``v{k}*dx``, ``v{k}*dy``, ``v{k}*dz`` (the 6 further kinds the
paper allows for the rotation outputs; d is the model's own displacement estimate).

Domain rule: inputs are clamped into the fitted domain [min_k, max_k] before any
power is taken (Python and C alike), and an element whose training readings are not
all > 0 is never offered a negative or fractional power, so those powers always see
an input >= min_k > 0.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from .errors import InputError

# the paper's order: v, v^2, v^3, v^4, 1/v, 1/v^2, 1/v^3, 1/v^4, v^1/2, v^1/3, v^1/4
EXPONENTS: tuple[str, ...] = ("1", "2", "3", "4", "-1", "-2", "-3", "-4", "1/2", "1/3", "1/4")
DISPLACEMENTS: tuple[str, ...] = ("dx", "dy", "dz")
ROTATIONS: tuple[str, ...] = ("thx", "thy")

# candidate exponent families a user may restrict the scope to
FAMILIES = {
    "all": EXPONENTS,
    "no-roots": tuple(e for e in EXPONENTS if "/" not in e),
    # positive integer powers only: no division and no roots on the device
    "integer": ("1", "2", "3", "4"),
}


@dataclass(frozen=True, order=True)
class Term:
    """One regressor: v_k^e (``element``, ``exponent``), d (``mult``), or v_k * d.

    ``element`` is 1-based (0: no element); ``exponent`` is a text from EXPONENTS
    ("" when there is no element); ``mult`` is "", "dx", "dy" or "dz".
    """

    element: int = 0
    exponent: str = ""
    mult: str = ""

    def __post_init__(self):
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


def parse_term(text: str) -> Term:
    """The :class:`Term` of a canonical text; anything else is an InputError."""
    m = _TERM_RE.match(text.strip()) if isinstance(text, str) else None
    if not m:
        raise InputError(f"not a term: {text!r} (forms: v3^-2, v8^1/4, dx, v2*dz)")
    if m.group(4):
        return Term(mult=m.group(4))
    if m.group(3):
        return Term(int(m.group(1)), "1", m.group(3))
    return Term(int(m.group(1)), m.group(2))


def initial_terms(n_elements: int, exponents=EXPONENTS) -> list[Term]:
    """The paper's eq. 1 generalised to N elements: v_k^-1 and v_k^-2 for every k.

    For a family without both of those powers (e.g. ``integer``), the same shape from what it
    allows: its first two exponents in the paper's order (v_k and v_k^2 for ``integer``).
    """
    first = ("-1", "-2") if {"-1", "-2"} <= set(exponents) else tuple(e for e in EXPONENTS if e in exponents)[:2]
    return [Term(k, e) for k in range(1, n_elements + 1) for e in first]


def candidate_terms(n_elements: int, output: str, *, exponents=EXPONENTS, d_terms: bool = True,
                    positive: np.ndarray | None = None) -> list[Term]:
    """The scope of one output, in a fixed order (power kinds in the paper's order, then elements).

    Rotation outputs also get dx, dy, dz and v_k*dx, v_k*dy, v_k*dz when ``d_terms``.
    ``positive[k-1]`` False removes element k's negative and fractional powers.
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
    return out


def element_powers(v: np.ndarray, exponent: str) -> np.ndarray:
    """v ** exponent by the exact operations the generated C uses, so both round alike.

    v2 = v*v, v3 = v2*v, v4 = v2*v2, v^-e = 1/v^e, sqrt, cbrt and sqrt(sqrt(v)).
    """
    if exponent == "1/2":
        return np.sqrt(v)
    if exponent == "1/3":
        return np.cbrt(v)
    if exponent == "1/4":
        return np.sqrt(np.sqrt(v))
    e = int(exponent)
    m = abs(e)
    v2 = v * v
    p = v if m == 1 else v2 if m == 2 else v2 * v if m == 3 else v2 * v2
    return 1.0 / p if e < 0 else p


def design_matrix(terms: list[Term], inputs: np.ndarray, d: np.ndarray | None = None) -> np.ndarray:
    """Columns of the terms for rows of ``inputs`` (n, N) and displacement estimates ``d`` (n, 3).

    Inputs are used as given: clamping into the domain is the caller's (the model's) job.
    """
    n = inputs.shape[0]
    cols = np.empty((n, len(terms)))
    # powers already computed, by (element, exponent): kept as views, never as copies
    cache: dict[tuple[int, str], np.ndarray] = {}
    for j, t in enumerate(terms):
        col = None
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


def element_power_slopes(v: np.ndarray, exponent: str) -> np.ndarray:
    """d(v ** exponent) / dv."""
    p = float(Fraction(exponent))
    return p * v ** (p - 1.0)


def design_jacobian(terms: list[Term], inputs: np.ndarray, d: np.ndarray | None = None,
                    d_jac: np.ndarray | None = None) -> np.ndarray:
    """d(column j) / d(input k) for rows of ``inputs``: an array (n, N, len(terms)).

    ``d_jac`` (n, 3, N) is the gradient of each displacement estimate by the inputs, for the
    d-terms (the device computes d from the same noisy readings); None treats d as exact.
    """
    n, n_in = inputs.shape
    out = np.zeros((n, n_in, len(terms)))
    for j, t in enumerate(terms):
        base = None
        if t.element:
            if t.element > n_in:
                raise InputError(f"term {t.text} needs input v{t.element}; the data has {n_in} inputs")
            slope = element_power_slopes(inputs[:, t.element - 1], t.exponent)
            base = element_powers(inputs[:, t.element - 1], t.exponent)
        if not t.mult:
            out[:, t.element - 1, j] = slope
            continue
        if d is None:
            raise InputError(f"term {t.text} needs the displacement estimates")
        i = DISPLACEMENTS.index(t.mult)
        if d_jac is not None:
            out[:, :, j] = d_jac[:, i, :] if base is None else base[:, None] * d_jac[:, i, :]
        if base is not None:
            out[:, t.element - 1, j] += slope * d[:, i]
    return out
