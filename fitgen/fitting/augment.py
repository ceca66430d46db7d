"""What the device adds to the readings and to the arithmetic, as extra rows of the least-squares problem.

Fitted on noise-free readings, the stepwise search exploits exact relations among the
redundant readings with large, cancelling coefficients; the device's noise and its rounding
then break them (docs/deployed-accuracy.md). Both are noise of a known size, and the
expected effect of each on a least-squares fit is a set of extra rows with target 0:

- Input noise, independent, sigma per reading: for data row i and input k the row
  sigma * d(x_i)/d(v_k). To first order in sigma,
  E ||y - X(v + e) b||^2 = ||y - X(v) b||^2 + sum_ik sigma^2 (d(x_i)/d(v_k) . b)^2, so these rows
  make every RSS the search compares, and the refit, the expected RSS on noisy readings.
  A d-term's derivative goes through the displacement equation that computes d on the device.
- Rounding: each term c_j x_j is computed with a relative error of a few unit roundoffs u
  (the coefficient's own rounding, the power's, the product's, the partial sums'). Modelled as
  independent relative noise of size ROUNDING_FACTOR * u on each term and on the intercept:
  one row with ROUNDING_FACTOR * u * ||column j|| in column j. This penalises exactly the
  magnitude sum |c_j x_j| that the float error bound (fitgen.equations.rounding) grows with.

No random replicas: the rows are formed in blocks and folded into the compressed triangle
(fitgen.fitting.stepwise.compress), so the search's cost stays independent of the number of rows. The
noise rows, N per data row, are most of the rows: with the rounding rows (precision float or
fixed) they enter as their Gram matrix, one matrix product per block, ~5x cheaper than folding
them by QR (:func:`gram_fold` says when, and why the conditioning holds). The terms without d
(powers, harmonic monomials) have the same noise rows for every output and family:
:class:`NoiseGrams` forms their Gram once for a whole fit.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from fitgen.fitting.stepwise import one_blas_thread
from fitgen.equations.terms import DISPLACEMENTS, Term, design_jacobian

# unit roundoff of the device's arithmetic, by generated precision. Fixed point is planned
# with wider accumulators (fitgen.equations.fixedpoint) but its coefficients and products keep about
# 24 bits at their scale, so it is treated as float.
UNIT_ROUNDOFF = {"float": 2.0**-24, "fixed": 2.0**-24, "double": 2.0**-53}
# Rounding noise is taken ROUNDING_FACTOR times the unit roundoff. A term costs up to 3 + 3
# roundings (coefficient, product, sum; up to 3 for 1/v^4) and the error that matters is the
# largest over the held-out poses, not the RMS the fit weighs: 8 keeps the float C's deviation
# under 5 % of the model's held-out error on every layout of docs/deployed-accuracy.md. A built unit's
# equations, with three times the terms, can need more: fitgen.fitting.family.rounding_checked doubles it there.
ROUNDING_FACTOR = 8.0
_ROWS = 2048  # data rows per block of noise rows (each gives n_inputs rows)
GRAM_FLOOR = 1e-7  # the least rounding noise (ROUNDING_FACTOR * u) under which the noise rows fold as a Gram
# data rows per block of the noise Gram: 1,024 x 8 inputs x 279 terms is an 18 MB block of rows;
# larger blocks gain < 10 % in time and cost their size in peak memory
_GRAM_ROWS = 1024


def noise_blocks(terms: list[Term], inputs: np.ndarray, sigma: float, d: np.ndarray | None = None,
                 d_jac=None, rows: int = _ROWS, harmonics=None) -> Iterator[np.ndarray]:
    """Blocks of rows [0, sigma * d(x)/d(v_k), 0] (m + 2 columns) for the terms' columns x, to fold by QR
    (where :func:`gram_fold` is False; elsewhere :func:`noise_gram` sums them).

    ``d_jac``: a function (lo, hi) -> the (hi - lo, 3, N) gradient of the displacement estimates ``d``
    by the inputs on those rows (None: d is exact), formed block by block like everything here."""
    n, n_in = inputs.shape
    m = len(terms)
    for lo in range(0, n, rows):
        hi = min(n, lo + rows)
        jac = design_jacobian(terms, inputs[lo:hi], None if d is None else d[lo:hi],
                              None if d_jac is None else d_jac(lo, hi), harmonics)
        blk = np.zeros((jac.shape[0] * n_in, m + 2))
        blk[:, 1:-1] = sigma * jac.reshape(-1, m)
        yield blk


def gram_fold(precision: str | None) -> bool:
    """Whether the noise rows may enter as their Gram matrix (:func:`noise_gram`) for this precision.

    A Gram squares the condition number of the rows it sums. The rounding rows put a floor,
    ROUNDING_FACTOR * u (4.8e-7 for float), under every column-scaled singular value of the
    triangle, so its condition number stays below ~10 / floor and the Gram's rounding,
    eps x cond^2, below ~1e-2 of |A x|^2 in every direction x (measured on the paper ring's
    harmonics candidates: 3e-8; docs/fit-benchmark.md). Without that floor (no precision, or
    double) candidates reach singular values of 1e-16: those rows are folded by QR, as before.
    """
    return precision is not None and ROUNDING_FACTOR * UNIT_ROUNDOFF[precision] >= GRAM_FLOOR


def rounding_rows(compressed: np.ndarray, u: float) -> np.ndarray:
    """Rows u * ||column|| on the diagonal, for the intercept and each column (m + 2 columns).

    The norms come from the compressed data (R^T R = A^T A, so ||A_j|| = ||R_j||): no pass over the rows."""
    norms = np.linalg.norm(compressed[:, :-1], axis=0)
    m1 = norms.size
    out = np.zeros((m1, m1 + 1))
    out[np.arange(m1), np.arange(m1)] = u * norms
    return out


@one_blas_thread
def noise_gram(terms: list[Term], inputs: np.ndarray, sigma: float, d: np.ndarray | None = None, d_jac=None,
               rows: int = _GRAM_ROWS, harmonics=None, cross: list[int] | None = None) -> np.ndarray:
    """sigma^2 J^T J (m, m), J the stacked noise rows of :func:`noise_blocks` without their 0 intercept
    and y columns, formed block by block. With ``cross`` (indices into ``terms``): only the columns
    J^T J[:, cross], (m, len(cross))."""
    n = inputs.shape[0]
    m = len(terms)
    out = np.zeros((m, m if cross is None else len(cross)))
    for lo in range(0, n, rows):
        J = _noise_rows(terms, inputs, d, d_jac, lo, min(n, lo + rows), harmonics)
        out += J @ (J if cross is None else J[cross]).T  # J @ J.T: numpy's symmetric product (syrk)
    return sigma**2 * out


def _noise_rows(terms, inputs, d, d_jac, lo, hi, harmonics) -> np.ndarray:
    """d(column j) / d(input k) on rows lo..hi, one row per term: (m, (hi - lo) * N).

    When ``d_jac`` names its equations (fitgen.fitting.fit's) and their terms are among ``terms``, the
    gradient of d is formed from those terms' rows here instead of evaluating them again."""
    m = len(terms)
    eqs = getattr(d_jac, "equations", None)
    dpos = [j for j, t in enumerate(terms) if t.mult]
    base = [j for j, t in enumerate(terms) if not t.mult]
    where = {terms[j]: i for i, j in enumerate(base)}
    if not dpos or eqs is None or not all(t in where for eq in eqs for t in eq.terms):
        # (m, rows x inputs): a view of design_jacobian's term-by-term array, no copy
        return design_jacobian(terms, inputs[lo:hi], None if d is None else d[lo:hi],
                               None if d_jac is None else d_jac(lo, hi), harmonics).transpose(2, 0, 1).reshape(m, -1)
    jb = design_jacobian([terms[j] for j in base], inputs[lo:hi], harmonics=harmonics)
    grad = np.zeros((hi - lo, 3, inputs.shape[1]))
    for eq in eqs:
        grad[:, DISPLACEMENTS.index(eq.name), :] = jb[:, :, [where[t] for t in eq.terms]] @ np.asarray(eq.coefficients)
    jd = design_jacobian([terms[j] for j in dpos], inputs[lo:hi], d[lo:hi], grad, harmonics)
    out = np.empty((m, jb.shape[0] * jb.shape[1]))
    out[base] = jb.transpose(2, 0, 1).reshape(len(base), -1)
    out[dpos] = jd.transpose(2, 0, 1).reshape(len(dpos), -1)
    return out


class NoiseGrams:
    """The noise Gram matrices (:func:`noise_gram`) of fits to one dataset's ``inputs`` at noise ``sigma``,
    the shared parts formed once.

    Terms without d (powers, harmonic monomials) have the same noise rows for every output and
    family: their Gram is formed once, over ``scope`` (their union, if known) and any such term
    asked for later. The rows of d-terms follow the stage-1 equations: the Gram's columns of an
    output's d-terms are kept for the next output with the same terms, d and d_jac (thx, thy).
    """

    def __init__(self, inputs: np.ndarray, sigma: float, harmonics=None, scope=()):
        self.inputs, self.sigma, self.harmonics = inputs, sigma, harmonics
        self.scope = [t for t in dict.fromkeys(scope) if not t.mult]
        self._base = None  # ({term: index}, Gram)
        self._with_d = None  # (d, d_jac, terms, the Gram's columns of the d-terms)

    def gram(self, terms: list[Term], d: np.ndarray | None = None, d_jac=None) -> np.ndarray:
        """:func:`noise_gram` of ``terms`` (the same to rounding), from what is kept where it applies."""
        base = [i for i, t in enumerate(terms) if not t.mult]
        if self._base is None or not {terms[i] for i in base} <= self._base[0].keys():
            scope = list(dict.fromkeys(self.scope + list(self._base[0] if self._base else ()) +
                                       [terms[i] for i in base]))
            self._base = ({t: i for i, t in enumerate(scope)},
                          noise_gram(scope, self.inputs, self.sigma, harmonics=self.harmonics))
        index, base_gram = self._base
        G = np.empty((len(terms), len(terms)))
        ix = [index[terms[i]] for i in base]
        G[np.ix_(base, base)] = base_gram[np.ix_(ix, ix)]
        dpos = [i for i, t in enumerate(terms) if t.mult]
        if dpos:
            w = self._with_d
            if w is None or not (w[0] is d and w[1] is d_jac and w[2] == list(terms)):
                w = self._with_d = (d, d_jac, list(terms), noise_gram(terms, self.inputs, self.sigma, d, d_jac,
                                                                      harmonics=self.harmonics, cross=dpos))
            G[:, dpos] = w[3]
            G[dpos, :] = w[3].T
            G[np.ix_(dpos, dpos)] = (w[3][dpos] + w[3][dpos].T) / 2  # symmetric to the last bit
        return G
