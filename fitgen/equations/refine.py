"""The refinement: a few Gauss-Newton steps on a fitted forward model, started from the equations.

The equations give a first pose p0. The forward model predicts each reading from a pose: element
k's reading is ``f(t_k)``, t_k a polynomial in the scaled pose u = (p - centre) * scale, and f the
identity or t^-3 (``cbrt``: t_k then fits v_k^(-1/3), which varies slowly with distance, as the
field's 1/r^3 does). Each step solves the maximum a posteriori update

    (J^T W J + P) delta = J^T W (v - f(p)) + P (p0 - p)

where W holds each element's weight (1 / its noise and fit variance) and P the prior's precision
matrix about p0 (the inverse of the equations' expected error covariance, which couples slide and
tilt: their errors are correlated), by a 5x5 Cholesky factorisation. The prior is
what keeps the step from amplifying noise where the readings hardly change with the pose. The new
pose is clamped into the fitted pose box. A step whose forward value or factorisation is not
usable (t <= 0 for cbrt, a non-positive pivot, a non-finite number) ends the refinement, and the
last pose stands.

The evaluation here is the C's (firmware_templates/model.h.j2), operation for operation, so that
float32 numpy gives the float header's results bit for bit.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from fitgen.base.errors import InputError, finite_number, shown
from fitgen.physics.pose import POSE_NAMES, check_pose_range

TRANSFORMS = ("identity", "cbrt")
MAX_STEPS = 8
MAX_DEGREE = 8  # per pose component in one monomial


@dataclass(frozen=True)
class ForwardEquation:
    """One element's forward polynomial: ``intercept + sum(coefficients[j] * u^exponents[j])``."""

    intercept: float
    exponents: tuple[tuple[int, ...], ...]  # per term, the power of each of dx, dy, dz, thx, thy
    coefficients: tuple[float, ...]


@dataclass(frozen=True)
class Refinement:
    """Everything the refinement steps read; see the module's docstring."""

    steps: int
    transform: str
    pose_min: tuple[float, ...]  # the pose box (5 components), where the forward model was fitted
    pose_max: tuple[float, ...]
    weights: tuple[float, ...]  # per element
    prior: tuple[tuple[float, ...], ...]  # 5x5 prior precision matrix (symmetric), in 1 / (unit x unit)
    forward: tuple[ForwardEquation, ...]  # per element

    @property
    def centre(self) -> np.ndarray:
        return (np.asarray(self.pose_min) + np.asarray(self.pose_max)) / 2

    @property
    def scale(self) -> np.ndarray:
        return 2.0 / (np.asarray(self.pose_max) - np.asarray(self.pose_min))

    @property
    def monomials(self) -> tuple[tuple[int, ...], ...]:
        """The distinct monomials a step computes, in order of first use: each term's, then the
        monomials of its derivatives (its exponents with one power fewer in one component)."""
        return self._tables[0]

    def term_table(self) -> tuple[tuple[int, ...], ...]:
        """Per term, in element order: its monomial's index, then per component the index of its
        derivative's monomial, -1 where the term does not hold that component."""
        return self._tables[1]

    @cached_property
    def _tables(self):
        # computed once per object (a frozen dataclass: cached_property writes the instance's __dict__)
        index: dict[tuple[int, ...], int] = {}
        rows = []
        for eq in self.forward:
            for e in eq.exponents:
                row = [index.setdefault(e, len(index))]
                for j in range(5):
                    if e[j]:
                        lower = tuple(a - (q == j) for q, a in enumerate(e))
                        row.append(index.setdefault(lower, len(index)))
                    else:
                        row.append(-1)
                rows.append(tuple(row))
        return tuple(index), tuple(rows)

    @property
    def degree(self) -> int:
        """The highest power of one pose component in any monomial."""
        return max((max(e) for e in self.monomials), default=0)

    @property
    def n_terms(self) -> int:
        return sum(len(eq.exponents) for eq in self.forward)

    # --- evaluation ------------------------------------------------------------------

    def forward_values(self, poses: np.ndarray) -> np.ndarray:
        """The readings the forward model predicts at ``poses`` (n, 5), in double."""
        t, _ = self._forward(np.asarray(poses, dtype=float), np.float64)
        return t ** -3.0 if self.transform == "cbrt" else t

    def numbers(self) -> tuple[float, ...]:
        """Every real the generated C holds as a literal."""
        return (*self.pose_min, *self.pose_max, *self.weights, *(x for row in self.prior for x in row),
                *(x for eq in self.forward for x in (eq.intercept, *eq.coefficients)))

    def magnitude(self, x_bound: np.ndarray) -> float:
        """The largest number a step's normal equations reach over the pose box (inf when one overflows).

        Evaluated on the box's 3^5 grid (each component at its ends and centre), where the forward model
        is defined (t > 0 for cbrt; elsewhere a step stops anyway): the prior, the forward values t,
        ``sum w J^2`` and ``sum w |J| (|x| + |f|)`` per component, ``x_bound`` being each input's largest
        magnitude. Weights scale as 1 / input^2 and J as the input, so the figure is the same in any units.
        """
        levels = np.stack([self.pose_min, self.centre, self.pose_max], axis=1)  # (5, 3)
        grid = np.stack(np.meshgrid(*levels, indexing="ij"), axis=-1).reshape(-1, 5)
        w = np.asarray(self.weights, dtype=float)
        with np.errstate(all="ignore"):
            t, dtdu = self._forward(grid, np.float64)
            if self.transform == "cbrt":
                defined = np.all(t > 0, axis=1)
                t, dtdu = t[defined], dtdu[defined]
                f, fd = t ** -3.0, -3.0 * t ** -4.0
            else:
                f, fd = t, np.ones_like(t)
            J = np.abs(fd[:, :, None] * dtdu * self.scale)  # (n, N, 5)
            normal = np.einsum("k,nkj->nj", w, J * J)
            rhs = np.einsum("k,nkj,nk->nj", w, J, np.asarray(x_bound, dtype=float) + np.abs(f))
            parts = (np.abs(np.asarray(self.prior)), np.abs(t), normal, rhs)
            values = np.concatenate([np.ravel(a) for a in parts])
        return float(np.max(np.where(np.isnan(values), np.inf, values)))

    def _forward(self, p: np.ndarray, dt) -> tuple[np.ndarray, np.ndarray]:
        """t (n, N) and dt/du (n, N, 5), in the C's order of operations."""
        u = (p - self.centre.astype(dt)) * self.scale.astype(dt)
        deg = self.degree
        pw = [np.ones_like(u)]
        for _ in range(deg):
            pw.append(pw[-1] * u)
        pw = np.stack(pw, axis=-1)  # (n, 5, deg + 1)
        monos, table = self._tables
        m = np.empty((len(u), len(monos)), dtype=dt)
        for i, e in enumerate(monos):
            val = pw[:, 0, e[0]]
            for j in range(1, 5):
                val = val * pw[:, j, e[j]]
            m[:, i] = val
        t = np.empty((len(u), len(self.forward)), dtype=dt)
        dtdu = np.empty((len(u), len(self.forward), 5), dtype=dt)
        rows = iter(table)
        for k, eq in enumerate(self.forward):
            acc = np.full(len(u), eq.intercept, dtype=dt)
            dacc = np.zeros((len(u), 5), dtype=dt)
            for e, c in zip(eq.exponents, np.asarray(eq.coefficients, dtype=dt)):
                row = next(rows)
                acc = acc + c * m[:, row[0]]
                for j in range(5):
                    if row[1 + j] >= 0:
                        # d(u^e)/du_j = e_j u^(e - 1_j): the power times the derivative's monomial
                        dacc[:, j] = dacc[:, j] + c * (dt(e[j]) * m[:, row[1 + j]])
            t[:, k] = acc
            dtdu[:, k, :] = dacc
        return t, dtdu

    def apply(self, x: np.ndarray, p0: np.ndarray, dt=np.float64) -> np.ndarray:
        """Refined poses (n, 5) from clamped inputs ``x`` (n, N) and first estimates ``p0`` (n, 5), in ``dt``."""
        x = np.asarray(x, dtype=dt)
        p0 = np.asarray(p0, dtype=dt)
        p = p0.copy()
        lo, hi = np.asarray(self.pose_min, dtype=dt), np.asarray(self.pose_max, dtype=dt)
        w = np.asarray(self.weights, dtype=dt)
        prior = np.asarray(self.prior, dtype=dt)
        scale = self.scale.astype(dt)
        active = np.ones(len(p), dtype=bool)
        with np.errstate(all="ignore"):
            for _ in range(self.steps):
                t, dtdu = self._forward(p, dt)
                ok = active.copy()
                if self.transform == "cbrt":
                    ok &= np.all(t > 0, axis=1)
                    f = dt(1.0) / (t * t * t)
                    fd = (dt(-3.0) * f) / t
                else:
                    f = t
                    fd = np.ones_like(t)
                A = np.zeros((len(p), 5, 5), dtype=dt)
                g = np.zeros((len(p), 5), dtype=dt)
                dp = p0 - p
                for j in range(5):
                    for q in range(5):
                        g[:, j] = g[:, j] + prior[j, q] * dp[:, q]
                        if q <= j:
                            A[:, j, q] = prior[j, q]
                for k in range(x.shape[1]):
                    r = x[:, k] - f[:, k]
                    J = [(fd[:, k] * dtdu[:, k, j]) * scale[j] for j in range(5)]
                    wr = w[k] * r
                    for j in range(5):
                        g[:, j] = g[:, j] + J[j] * wr
                        wj = w[k] * J[j]
                        for q in range(j + 1):
                            A[:, j, q] = A[:, j, q] + wj * J[q]
                delta, solved = _cholesky_solve(A, g, dt)
                ok &= solved
                new = p + delta
                new = np.where(new < lo, lo, np.where(new > hi, hi, new))
                ok &= np.all(np.isfinite(new), axis=1)
                p = np.where(ok[:, None], new, p)
                active = ok
        return p

    # --- files -------------------------------------------------------------------------

    def to_dict(self) -> dict:
        return {
            "steps": self.steps,
            "transform": self.transform,
            "pose_names": list(POSE_NAMES),
            "pose_min": list(self.pose_min),
            "pose_max": list(self.pose_max),
            "weights": list(self.weights),
            "prior_precision": [list(row) for row in self.prior],
            "forward": [{"intercept": eq.intercept, "exponents": [list(e) for e in eq.exponents],
                         "coefficients": list(eq.coefficients)} for eq in self.forward],
        }

    @classmethod
    def from_dict(cls, data, n_inputs: int, origin: str) -> "Refinement":
        where = f"{origin}: refine"
        if not isinstance(data, dict):
            raise InputError(f"{where} must be an object")
        try:
            if data.get("pose_names", list(POSE_NAMES)) != list(POSE_NAMES):
                raise InputError(f"{where}.pose_names must be {','.join(POSE_NAMES)}")
            prior = data["prior_precision"]
            if not isinstance(prior, list) or len(prior) != 5:
                raise InputError(f"{where}.prior_precision must be a 5x5 matrix (5 lists of 5 numbers)")
            steps = data["steps"]
            forward = []
            for k, eq in enumerate(data["forward"]):
                exps = tuple(tuple(e) for e in eq["exponents"])
                forward.append(ForwardEquation(finite_number(eq["intercept"], f"{where}.forward[{k}].intercept"), exps,
                                               tuple(finite_number(c, f"{where}.forward[{k}].coefficients") for c in eq["coefficients"])))
            ref = cls(steps, data["transform"], _nums(data["pose_min"], f"{where}.pose_min"),
                      _nums(data["pose_max"], f"{where}.pose_max"), _nums(data["weights"], f"{where}.weights"),
                      tuple(_nums(row, f"{where}.prior_precision", "a matrix (a list of rows of numbers)")
                            for row in prior), tuple(forward))
        except (KeyError, TypeError) as exc:
            raise InputError(f"{where}: malformed ({type(exc).__name__}: {exc})") from None
        ref.validate(n_inputs, where)
        return ref

    def validate(self, n_inputs: int, where: str = "refine") -> None:
        if isinstance(self.steps, bool) or not isinstance(self.steps, int) or not 1 <= self.steps <= MAX_STEPS:
            raise InputError(f"{where}.steps must be an integer from 1 to {MAX_STEPS}, got {shown(self.steps)}")
        if self.transform not in TRANSFORMS:
            raise InputError(f"{where}.transform must be one of {', '.join(TRANSFORMS)}, got {shown(self.transform)}")
        for name, vals, n in (("pose_min", self.pose_min, 5), ("pose_max", self.pose_max, 5),
                              ("weights", self.weights, n_inputs)):
            if len(vals) != n:
                raise InputError(f"{where}.{name} needs {n} numbers, got {len(vals)}")
        try:
            P = np.asarray(self.prior, dtype=float)
        except (TypeError, ValueError):
            P = np.zeros(0)
        if P.shape != (5, 5) or not np.all(np.isfinite(P)) or not np.array_equal(P, P.T):
            raise InputError(f"{where}.prior_precision must be a symmetric 5x5 matrix of finite numbers")
        if not all(a < b for a, b in zip(self.pose_min, self.pose_max)):
            raise InputError(f"{where}: the pose box needs pose_min < pose_max in every component")
        for name, lo, hi in zip(POSE_NAMES, self.pose_min, self.pose_max):
            check_pose_range(name, lo, hi, where)
        if not all(x > 0 for x in self.weights) or not np.all(np.diag(P) >= 0):
            raise InputError(f"{where}: weights must be > 0, and the prior precision's diagonal >= 0")
        if len(self.forward) != n_inputs:
            raise InputError(f"{where}.forward needs one equation per input ({n_inputs}), got {len(self.forward)}")
        for k, eq in enumerate(self.forward):
            for e in eq.exponents:
                if (len(e) != 5 or not all(isinstance(a, int) and not isinstance(a, bool) and 0 <= a <= MAX_DEGREE
                                           for a in e) or sum(e) == 0):
                    raise InputError(f"{where}.forward[{k}]: {list(e)!r} is not 5 powers from 0 to {MAX_DEGREE} "
                                     "(not all 0)")
            if len(eq.exponents) != len(eq.coefficients):
                raise InputError(f"{where}.forward[{k}]: {len(eq.exponents)} exponents but "
                                 f"{len(eq.coefficients)} coefficients")
            if len(set(eq.exponents)) != len(eq.exponents):
                raise InputError(f"{where}.forward[{k}] lists a monomial twice")


def _cholesky_solve(A: np.ndarray, g: np.ndarray, dt) -> tuple[np.ndarray, np.ndarray]:
    """delta with (L L^T) delta = g from the lower triangle of A, as the C does; and which rows factored."""
    n = A.shape[-1]
    L = np.zeros_like(A)
    ok = np.ones(len(A), dtype=bool)
    for j in range(n):
        s = A[:, j, j]
        for q in range(j):
            s = s - L[:, j, q] * L[:, j, q]
        ok &= s > 0
        L[:, j, j] = np.sqrt(np.where(s > 0, s, dt(1.0)))
        for i in range(j + 1, n):
            s = A[:, i, j]
            for q in range(j):
                s = s - L[:, i, q] * L[:, j, q]
            L[:, i, j] = s / L[:, j, j]
    y = np.empty_like(g)
    for j in range(n):
        s = g[:, j]
        for q in range(j):
            s = s - L[:, j, q] * y[:, q]
        y[:, j] = s / L[:, j, j]
    delta = np.empty_like(g)
    for j in reversed(range(n)):
        s = y[:, j]
        for q in range(j + 1, n):
            s = s - L[:, q, j] * delta[:, q]
        delta[:, j] = s / L[:, j, j]
    return delta, ok


def _nums(vals, where: str, what: str = "a list of numbers") -> tuple[float, ...]:
    if not isinstance(vals, list):
        raise InputError(f"{where} must be {what}")
    return tuple(finite_number(v, where) for v in vals)
