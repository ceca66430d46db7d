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
  magnitude sum |c_j x_j| that the float error bound (fitgen.precision) grows with.

No random replicas: the rows are formed in blocks and folded into the compressed triangle
(fitgen.stepwise.compress), so the search's cost stays independent of the number of rows.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from .terms import Term, design_jacobian

# unit roundoff of the device's arithmetic, by generated precision. Fixed point is planned
# with wider accumulators (fitgen.fixedpoint) but its coefficients and products keep about
# 24 bits at their scale, so it is treated as float.
UNIT_ROUNDOFF = {"float": 2.0**-24, "fixed": 2.0**-24, "double": 2.0**-53}
# Rounding noise is taken ROUNDING_FACTOR times the unit roundoff. A term costs up to 3 + 3
# roundings (coefficient, product, sum; up to 3 for 1/v^4) and the error that matters is the
# largest over the held-out poses, not the RMS the fit weighs: 8 keeps the float C's deviation
# under 5 % of the model's held-out error on every layout of docs/deployed-accuracy.md.
ROUNDING_FACTOR = 8.0
_ROWS = 2048  # data rows per block of noise rows (each gives n_inputs rows)


def noise_blocks(terms: list[Term], inputs: np.ndarray, sigma: float, d: np.ndarray | None = None,
                 d_jac=None, rows: int = _ROWS, harmonics=None) -> Iterator[np.ndarray]:
    """Blocks of rows [0, sigma * d(x)/d(v_k), 0] (m + 2 columns) for the terms' columns x.

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


def rounding_rows(compressed: np.ndarray, u: float) -> np.ndarray:
    """Rows u * ||column|| on the diagonal, for the intercept and each column (m + 2 columns).

    The norms come from the compressed data (R^T R = A^T A, so ||A_j|| = ||R_j||): no pass over the rows."""
    norms = np.linalg.norm(compressed[:, :-1], axis=0)
    m1 = norms.size
    out = np.zeros((m1, m1 + 1))
    out[np.arange(m1), np.arange(m1)] = u * norms
    return out
