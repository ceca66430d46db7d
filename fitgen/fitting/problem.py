"""A capture's rows as identify's model reads them (fitgen.fitting.identify tells the model): the unit's
readings at the rows' poses, their slopes by the unit's parameters and by the stage's displacement, and each
row's whitening by the noise, the rig's error and the zero's."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fitgen.fitting.knees import KNEE_REACH, near_knees
from fitgen.physics.pose import off_skin
from fitgen.physics.units import UnitSpace

_H_THETA = 1e-3  # central-difference step, in prior spreads
_H_POSE = 1e-4  # mm


@dataclass
class Problem:
    """The unit space, the rows and their noise: residuals and Jacobians in prior spreads."""

    space: UnitSpace
    readings: np.ndarray  # (n, N)
    poses: np.ndarray  # (n, 5) labels
    noise: np.ndarray  # (N,) reading noise rms of a row
    rig_error: float
    valid: np.ndarray | None = None  # (n, N) False for a clipped reading, which says nothing of the field
    zero_error: float = 0.0  # mm rms per axis, common to the capture's rows in contact (not to other poses)
    # mm (3,): the zero's error about which the rows in contact are linearised (its posterior mean, from a sweep)
    shift: np.ndarray | None = None
    # rows labelled in contact that read at rest, taken as lifted off the skin (their dz in ``poses`` moved there)
    lifted: tuple = ()
    # mm: how far above first contact those rows put the zero, dz's prior spread where larger than zero_error (the
    # rows tell dz, not dx or dy, where a zero freed too takes up some of the magnet's offset)
    zero_lift: float = 0.0
    # (n, N) readings that weigh nothing at any z: those a looser stage's unit put by a knee (identify's last start)
    held: np.ndarray | None = None

    @property
    def zero_sd(self) -> np.ndarray:
        """The zero's error's prior spread per axis (mm, 3): ``zero_error``, dz's at least ``zero_lift``."""
        return np.array([self.zero_error, self.zero_error, max(self.zero_error, self.zero_lift)])

    @property
    def at(self) -> np.ndarray:
        """The rows' poses about which they are linearised: the labels, the rows in contact moved by ``shift``."""
        if self.shift is None:
            return self.poses
        at = self.poses.copy()
        at[~off_skin(at), :3] += self.shift
        return at

    def predict(self, z: np.ndarray, poses: np.ndarray | None = None, clipped: bool = True) -> np.ndarray:
        return self.space.readings(np.atleast_2d(z) * self.space.prior_sd, self.at if poses is None else poses,
                                   clipped)

    def residuals(self, z: np.ndarray, slopes: np.ndarray) -> np.ndarray:
        """The rows' readings less the unit's at the labels to first order in the zero's error (n, N): at ``at``,
        plus :meth:`shift_term` (the zero's share is in the rows' covariance)."""
        return self.readings - self.predict(z)[0] + self.shift_term(slopes)

    def shift_term(self, slopes: np.ndarray) -> np.ndarray | float:
        """``slopes`` (the rows', at ``at``) times ``shift`` on the rows in contact (n, N); 0 without a shift."""
        if self.shift is None:
            return 0.0
        return np.where(off_skin(self.poses)[:, None], 0.0, slopes @ self.shift)

    def zero_mean(self, wh: "Whitening", r: np.ndarray) -> np.ndarray:
        """The zero's error's posterior mean (mm, 3) given the rows' ``residuals`` ``r`` whitened by ``wh``."""
        if wh.U is None:
            return np.zeros(3)
        U = wh.U
        return self.zero_sd * np.linalg.solve(np.eye(3) + U.T @ U, U.T @ np.einsum("nij,nj->ni", wh.W, r).ravel())

    def jacobian(self, z: np.ndarray, poses: np.ndarray | None = None) -> np.ndarray:
        """d readings / d z: (n, N, P), by central differences (one batched evaluation)."""
        P = self.space.size
        steps = np.eye(P) * _H_THETA
        f = self.predict(np.vstack([z + steps, z - steps]), poses)
        return np.moveaxis((f[:P] - f[P:]) / (2 * _H_THETA), 0, -1)

    def pose_slopes(self, z: np.ndarray, poses: np.ndarray | None = None, clipped: bool = True) -> np.ndarray:
        """d readings / d stage displacement: (n, N, 3); ``clipped=False``: of the readings' lines (UnitSpace)."""
        poses = self.at if poses is None else poses
        shifted = [poses + sign * _H_POSE * np.eye(5)[a] for a in range(3) for sign in (1.0, -1.0)]
        f = self.predict(z, np.vstack(shifted), clipped)[0].reshape(6, len(poses), -1)
        return np.stack([(f[2 * a] - f[2 * a + 1]) / (2 * _H_POSE) for a in range(3)], axis=-1)

    def usable(self, z: np.ndarray) -> np.ndarray:
        """The readings (n, N) that weigh at z: not clipped, not ``held``, and not within KNEE_REACH stage errors of
        a knee (fitgen.fitting.knees: across one the rig's error moves a reading as no slope says); without a
        capture's mask (a design's rows, read nothing yet) every one."""
        if self.valid is None:
            return np.ones(self.readings.shape, dtype=bool)
        valid = self.valid if self.held is None else self.valid & ~self.held
        reach = KNEE_REACH * np.hypot(self.rig_error, self.zero_error)
        if reach <= 0:
            return valid
        line, slopes = self.predict(z, clipped=False)[0], self.pose_slopes(z, clipped=False)
        return valid & ~near_knees(self.space, z * self.space.prior_sd, self.readings, line, slopes, reach)

    def whiteners(self, z: np.ndarray, poses: np.ndarray | None = None, slopes: np.ndarray | None = None) -> np.ndarray:
        """Per row, L^-1 with L L^T = diag(noise^2) + rig_error^2 J_s J_s^T: (n, N, N)."""
        js = self.pose_slopes(z, poses) if slopes is None else slopes
        cov = np.einsum("nia,nja->nij", js, js) * self.rig_error**2 + np.diag(self.noise**2)[None]
        usable = self.usable(z) if poses is None else None
        if usable is not None and not usable.all():
            # a clipped reading, or one by a knee, weighs nothing: its variance made a million times the noise's square
            idx = np.nonzero(~usable)
            cov[idx[0], idx[1], idx[1]] += 1e12 * self.noise[idx[1]] ** 2
        L = np.linalg.cholesky(cov)
        eye = np.broadcast_to(np.eye(cov.shape[1]), cov.shape)
        return np.linalg.solve(L, eye)

    def whitening(self, z: np.ndarray, poses: np.ndarray | None = None, slopes=None) -> "Whitening":
        """The whitening of the rows (or of ``poses``, which share no zero) at z; ``slopes``: theirs, if at hand."""
        js = self.pose_slopes(z, poses) if slopes is None else slopes
        W = self.whiteners(z, poses, js)
        if poses is not None or self.zero_error <= 0:
            return Whitening(W)
        U = np.einsum("nij,nja->nia", W, js).reshape(-1, 3) * self.zero_sd
        phi, s, _ = np.linalg.svd(U, full_matrices=False)
        return Whitening(W, phi, 1.0 / np.sqrt(1.0 + s**2) - 1.0, U)

    def whitened_rows(self, z: np.ndarray, poses: np.ndarray | None = None) -> np.ndarray:
        """Each row's Jacobian whitened by its own covariance alone (n, N, P): rows whose information adds up,
        as a design needs (the zero's shared error left out)."""
        return np.einsum("nij,njp->nip", self.whiteners(z, poses), self.jacobian(z, poses))

    def information(self, z: np.ndarray, poses: np.ndarray | None = None,
                    whitening: "Whitening | None" = None) -> np.ndarray:
        """The Fisher information of the rows (or of ``poses``) about z: (P, P); ``whitening``: theirs at z, if
        already at hand."""
        J = (whitening or self.whitening(z, poses)).apply(self.jacobian(z, poses))
        return J.T @ J


@dataclass
class Whitening:
    """Each row's whitener W (n, N, N), then (I + U U^T)^(-1/2) = I + phi diag(c) phi^T for the zero's rank-3 term
    U (after W; U = phi s psi^T, c = 1/sqrt(1 + s^2) - 1)."""

    W: np.ndarray
    phi: np.ndarray | None = None
    c: np.ndarray | None = None
    U: np.ndarray | None = None  # the zero's whitened slopes (n N, 3), times its prior spread per axis

    def apply(self, a: np.ndarray) -> np.ndarray:
        """Whitened residuals (n, N) -> (n N,) or Jacobians (n, N, P) -> (n N, P)."""
        x = np.einsum("nij,nj...->ni...", self.W, a).reshape((-1,) + a.shape[2:])
        if self.phi is None:
            return x
        proj = self.phi.T @ x
        return x + self.phi @ (self.c.reshape((-1,) + (1,) * (x.ndim - 1)) * proj)
