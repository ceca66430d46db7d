"""What the fits to one dataset share: the rows, compressed once.

fitgen.fitting.family fits two candidate families to the same rows, and within a fit the outputs share
their candidates. Data: one blocked QR (fitgen.fitting.stepwise.compress) of [1, the terms without d,
every target] serves each output whose terms are among them: its triangle is the QR of that
triangle's columns [1, its terms, its target], with the same inner products to QR's rounding.
Terms with d follow the stage-1 equations: [1, the output's terms, every target] is compressed
once per (terms, d), which thx and thy share. Noise: fitgen.fitting.augment.NoiseGrams. A single fit
(fitgen.fitting.fit.fit_model alone) shares the noise Gram only: its data triangles, and so the exact
fit's bits (which decide R's ties the way R does), stay its own.
"""

from __future__ import annotations

import numpy as np

from fitgen.fitting.augment import NoiseGrams
from fitgen.fitting.stepwise import compress, triangle
from fitgen.equations.terms import Term, finite_design_matrix

ROWS = 1 << 14  # rows per block of the compressing QR, as fitgen.fitting.fit's


class SharedRows:
    """The compressed rows of fits to ``inputs`` at noise ``sigma`` with ``harmonics``.

    ``scope``: the terms without d the fits will ask for (their union; others are added when
    asked). ``targets`` (n, t): the targets the data triangles carry; None: no data triangles
    (each output compresses its own rows), only the noise Gram matrices are shared.
    """

    def __init__(self, inputs: np.ndarray, sigma: float = 0.0, harmonics=None, scope=(),
                 targets: np.ndarray | None = None):
        self.inputs, self.sigma, self.harmonics = inputs, sigma, harmonics
        self.noise = NoiseGrams(inputs, sigma, harmonics, scope)
        self.scope = [t for t in dict.fromkeys(scope) if not t.mult]
        self.targets = targets
        self._base = None  # (terms, {term: column}, triangle)
        self._with_d = None  # (d, terms, {term: column}, triangle)

    def serves(self, inputs: np.ndarray, sigma: float, harmonics=None) -> bool:
        """Whether these are the rows of fits to ``inputs`` at noise ``sigma`` with ``harmonics``."""
        return self.inputs is inputs and self.sigma == sigma and harmonics in (None, self.harmonics)

    def triangle(self, terms: list[Term], y: np.ndarray, d: np.ndarray | None = None) -> np.ndarray | None:
        """The compressed triangle of [1, the terms' columns, y] (stepwise.compress's, to rounding);
        None when ``y`` is not one of the targets."""
        if self.targets is None:
            return None
        j = next((j for j in range(self.targets.shape[1]) if np.array_equal(self.targets[:, j], y)), None)
        if j is None:
            return None
        if any(t.mult for t in terms):
            w = self._with_d
            if w is None or w[0] is not d or w[1] != list(terms):
                w = self._with_d = (d, list(terms), *self._compress(list(terms), d))
            index, R = w[2], w[3]
        else:
            b = self._base
            if b is None or not set(terms) <= b[1].keys():
                scope = list(dict.fromkeys(self.scope + (b[0] if b else []) + list(terms)))
                b = self._base = (scope, *self._compress(scope, None))
            index, R = b[1], b[2]
        cols = [0] + [index[t] for t in terms] + [len(index) + 1 + j]
        return triangle(R[:, cols])

    def _compress(self, terms: list[Term], d) -> tuple[dict, np.ndarray]:
        """The triangle of [1, the terms' columns, every target] over all rows, and each term's column."""
        t = self.targets

        def columns(lo, hi):
            X = finite_design_matrix(terms, self.inputs[lo:hi], None if d is None else d[lo:hi], self.harmonics, lo)
            return np.hstack([X, t[lo:hi, :-1]])

        return {term: i + 1 for i, term in enumerate(terms)}, compress(columns, t[:, -1], block=ROWS)

    def gram(self, terms: list[Term], d: np.ndarray | None = None, d_jac=None) -> np.ndarray:
        """The noise rows' Gram matrix of ``terms`` (fitgen.fitting.augment.NoiseGrams.gram)."""
        return self.noise.gram(terms, d, d_jac)
