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

A harmonic monomial's own error replaces a_t |b_t|: with S = sum v_k (N - 1 additions),
hr = 1/S is off by at most u N |hr|, a harmonic h = (sum w_k v_k) hr by
u ((2 n_w - 1) sum |w_k v_k| |hr| + (N + 1) |h|), and a product of factors by the sum over
factors of (the others' product) times that factor's error, plus u per multiplication.
"""

from __future__ import annotations

import numpy as np

from .model import Model
from .terms import DISPLACEMENTS, design_matrix, element_powers, monomial_factors

U_FLOAT = 2.0**-24
U_DOUBLE = 2.0**-53
POWER_ROUNDINGS = {"1": 0, "2": 1, "3": 2, "4": 2, "-1": 1, "-2": 2, "-3": 3, "-4": 3,
                   "1/2": 1, "1/3": 2, "1/4": 2}


def harmonic_errors(model: Model, v: np.ndarray) -> dict[str, np.ndarray]:
    """Per harmonic monomial a term uses: its rounding error bound in units of u, per row of clamped v."""
    texts = {t.harm for eq in model.equations for t in eq.terms if t.harm}
    if not texts:
        return {}
    h = model.harmonics
    vals = h.values(v)
    n_in = v.shape[1]
    hr = np.abs(vals["hr"])
    err = {"hr": n_in * hr}
    for sym, w in h.weights:
        w = np.asarray(w)
        n_w = int(np.count_nonzero(w))
        err[sym] = (2 * n_w - 1) * (np.abs(v) @ np.abs(w)) * hr + (n_in + 1) * np.abs(vals[sym])
    out = {}
    for text in texts:
        fs = monomial_factors(text)
        total = np.zeros(v.shape[0])
        for i in range(len(fs)):
            others = np.ones(v.shape[0])
            for o, f in enumerate(fs):
                if o != i:
                    others = others * np.abs(vals[f])
            total += others * err[fs[i]]
        prod = np.ones(v.shape[0])
        for f in fs:
            prod = prod * np.abs(vals[f])
        out[text] = total + (len(fs) - 1) * prod
    return out


def error_bound(model: Model, inputs: np.ndarray, u: float) -> np.ndarray:
    """Bound (n, n_outputs) on |C result - exact result| for each row of (clamped, finite) inputs."""
    v, _ = model.clamp(inputs)
    n = v.shape[0]
    harm_err = harmonic_errors(model, v)
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
        for k, t in enumerate(eq.terms):
            acc = acc + coefs[k] * cols[:, k]
            partial += np.abs(acc)
            if t.harm:
                weighted += terms[:, k] * 3 + abs(coefs[k]) * harm_err[t.harm]
            else:
                weighted += terms[:, k] * (3 + (POWER_ROUNDINGS[t.exponent] if t.element else 0))
            if t.mult:
                i = DISPLACEMENTS.index(t.mult)
                base = element_powers(v[:, t.element - 1], t.exponent) if t.element else 1.0
                slope[:, i] += coefs[k] * base
        prop = np.sum(np.abs(slope) * e_d, axis=1)
        out[:, j] = u * (weighted + partial) + prop
        if eq.name in DISPLACEMENTS:
            i = DISPLACEMENTS.index(eq.name)
            d[:, i] = acc
            e_d[:, i] = out[:, j]
    return out
