"""Rounding-error bounds of the generated C, computed from the terms' magnitudes.

For IEEE arithmetic with unit roundoff u (2^-24 float, 2^-53 double), no fused
multiply-add, and inputs already representable, one output of the C evaluation
acc = c0; acc += c_t * (b_t * d_t) for each term t differs from the exact value of
the same equation by at most (first order in u)

    u * ( |c0| + sum_t |c_t b_t d_t| (3 + a_t) + sum_t |s_t| ) + sum_i |sum_{t: d_t = d_i} c_t b_t| E_d(i)

where b_t is the element power (a_t roundings to compute it: v^2 1, v^3 2, v^4 2,
1/v 1, 1/v^2 2, 1/v^3 3, 1/v^4 3, sqrt 1, cbrt 2, fourth root 2), the 3 counts the
coefficient's own rounding and the two products, s_t are the partial sums, and E_d
is the bound of the displacement estimate a d-term multiplies. The last sum is taken
per displacement before its absolute value (|sum_t c_t b_t| E_d): every term that
multiplies the same displacement sees the same error of it. Python evaluates the
same expression in double; its own error is the same formula with u = 2^-53.

A harmonic monomial counts its own multiplications (deg - 1) in place of a_t; the errors of the
harmonics it is made of enter like the displacements'. The sums are bounded by running error
analysis on the row's own partial sums: S = v_1 + ... + v_N is off by at most u sum_{i>=2} |S_i|,
so hr = 1/S by |hr| (that |hr| + u); a weighted sum H by u (sum of its partial sums' sizes and twice
its products by weights other than +-1: literal and product), so h = H hr by |hr| err(H) + |H| err(hr) + u |h| = E_h;
the output by sum_h |sum_t c_t d(monomial_t)/dh| E_h: every monomial holding h sees the same
error of it.
"""

from __future__ import annotations

import numpy as np

from fitgen.base.errors import InputError
from fitgen.equations.model import Model
from fitgen.equations.terms import DISPLACEMENTS, design_matrix, element_powers, monomial_factors

# the arithmetic the generated C can run in (fixed: integer codes in, int32 out: fitgen.equations.fixedpoint)
PRECISIONS = ("double", "float", "fixed")
U_FLOAT = 2.0**-24
U_DOUBLE = 2.0**-53
POWER_ROUNDINGS = {"1": 0, "2": 1, "3": 2, "4": 2, "-1": 1, "-2": 2, "-3": 3, "-4": 3,
                   "1/2": 1, "1/3": 2, "1/4": 2}


def harmonic_errors(model: Model, v: np.ndarray) -> tuple[dict, dict]:
    """The harmonics' values and each one's rounding error bound in units of u, per row of clamped v."""
    if not any(t.harm for eq in model.equations for t in eq.terms):
        return {}, {}
    h = model.harmonics
    vals = h.values(v)
    # running error bounds of the left-to-right sums the C computes: each addition rounds to its
    # partial sum; a product by a weight other than +-1 rounds twice (the weight's literal, the product)
    total = v[:, 0].copy()
    s_err = np.zeros(v.shape[0])
    for k in range(1, v.shape[1]):
        total = total + v[:, k]
        s_err += np.abs(total)
    hr = np.abs(vals["hr"])
    err = {"hr": hr * (s_err * hr + 1.0)}
    for sym, w in h.weights:
        acc, e = None, np.zeros(v.shape[0])
        for k, wk in enumerate(w):
            if wk == 0.0:
                continue
            p = wk * v[:, k]
            if abs(wk) != 1.0:
                e += 2.0 * np.abs(p)
            acc = p if acc is None else acc + p
            if acc is not p:
                e += np.abs(acc)
        err[sym] = e * hr + np.abs(acc) * err["hr"] + np.abs(vals[sym])
    return vals, err


def monomial_slopes(text: str, vals: dict) -> dict[str, np.ndarray]:
    """d(monomial) / d(symbol) for each symbol it holds: p f^(p-1) times the other factors."""
    fs = monomial_factors(text)
    out = {}
    for f in dict.fromkeys(fs):
        rest = list(fs)
        rest.remove(f)
        d = np.full(vals[f].shape, float(fs.count(f)))
        for g in rest:
            d = d * vals[g]
        out[f] = d
    return out


def error_bound(model: Model, inputs: np.ndarray, u: float) -> np.ndarray:
    """Bound (n, n_outputs) on |C result - exact result| for each row of (clamped, finite) inputs.

    Of the equations only: a refinement's iterations have none (InputError)."""
    if model.refine is not None:
        raise InputError("no a-priori rounding bound through a refinement's Gauss-Newton steps: compare the C with "
                         "Model.predict in its own precision (bit for bit) and measure the held-out deviation")
    v, _ = model.clamp(inputs)
    n = v.shape[0]
    harm_vals, harm_err = harmonic_errors(model, v)
    d = np.zeros((n, 3))
    e_d = np.zeros((n, 3))
    out = np.zeros((n, len(model.equations)))
    for j, eq in enumerate(model.equations):
        cols = design_matrix(list(eq.terms), v, d, model.harmonics)
        coefs = np.asarray(eq.coefficients)
        terms = np.abs(cols * coefs)
        acc = np.full(n, eq.intercept)
        partial = np.zeros(n)
        weighted = np.full(n, abs(eq.intercept))
        # per displacement, the sum of c_t * b_t over the terms that multiply it: every such term sees
        # the same error of that displacement, so its share is |sum c_t b_t| E_d, not sum |c_t b_t| E_d
        slope = np.zeros((n, 3))
        # likewise per harmonic: every monomial holding it sees the same error of it
        slope_h = {f: np.zeros(n) for f in harm_err}
        for k, t in enumerate(eq.terms):
            acc = acc + coefs[k] * cols[:, k]
            partial += np.abs(acc)
            if t.harm:
                # the coefficient's rounding, its product and sum, and the monomial's own multiplications
                weighted += terms[:, k] * (3 + len(monomial_factors(t.harm)) - 1)
                for f, dm in monomial_slopes(t.harm, harm_vals).items():
                    slope_h[f] += coefs[k] * dm
            else:
                weighted += terms[:, k] * (3 + (POWER_ROUNDINGS[t.exponent] if t.element else 0))
            if t.mult:
                i = DISPLACEMENTS.index(t.mult)
                base = element_powers(v[:, t.element - 1], t.exponent) if t.element else 1.0
                slope[:, i] += coefs[k] * base
        prop = np.sum(np.abs(slope) * e_d, axis=1)
        prop_h = sum((np.abs(slope_h[f]) * harm_err[f] for f in slope_h), np.zeros(n))
        out[:, j] = u * (weighted + partial + prop_h) + prop
        if eq.name in DISPLACEMENTS:
            i = DISPLACEMENTS.index(eq.name)
            d[:, i] = acc
            e_d[:, i] = out[:, j]
    return out
