"""The field of an axially magnetised cylinder in closed form, vectorised.

Derby & Olbert, Am. J. Phys. 78 (2010) 229, with Bulirsch's complete elliptic
integral ``cel`` (Numer. Math. 7, 1965). The kernel works on dimensionless
coordinates (lengths over the cylinder radius), as magpylib does, so that
scaling the magnet and the observer together leaves the field unchanged.
"""

from __future__ import annotations

import numpy as np

_HALF_PI = np.pi / 2
# Bulirsch's AGM converges quadratically: once successive means agree to 1e-8
# the next step is exact to machine precision.
_CEL_TOL = 1e-8
_CHUNK = 1 << 15  # points per block: keeps the temporaries in cache


def _cel_pair(kc, p_a, c_a, s_a, p_b, c_b, s_b):
    """Two complete elliptic integrals cel(kc, p, c, s) sharing one modulus.

    The arithmetic-geometric mean of 1 and kc is the same for both, so it is run
    once. ``p`` must be > 0 for the first and >= 0 for the second integral.
    """
    # p > 0 branch of Bulirsch's preparation for a; the p <= 0 branch for b where p == 0.
    pa = np.sqrt(p_a)
    sa = s_a / pa
    ca = np.array(c_a, dtype=float, copy=True)
    zero = p_b <= 0
    pb = np.sqrt(p_b)
    with np.errstate(divide="ignore", invalid="ignore"):
        sb = np.where(zero, 0.0, s_b / pb)
    cb = np.array(c_b, dtype=float, copy=True)
    if np.any(zero):
        f = kc[zero] ** 2
        g = 1.0 - p_b[zero]
        q = (1.0 - f) * (s_b[zero] - c_b[zero] * p_b[zero])
        f = f - p_b[zero]
        pz = np.sqrt(f / g)
        cz = (c_b[zero] - s_b[zero]) / g
        pb[zero] = pz
        cb[zero] = cz
        sb[zero] = -q / (g * g * pz) + cz * pz
    mu = np.ones_like(kc)
    nu = np.abs(kc)
    munu = nu.copy()
    while True:
        g = munu / pa
        ca, sa = ca + sa / pa, 2.0 * (sa + ca * g)
        pa = pa + g
        g = munu / pb
        cb, sb = cb + sb / pb, 2.0 * (sb + cb * g)
        pb = pb + g
        prev = mu
        mu = mu + nu
        if np.all(np.abs(prev - nu) <= prev * _CEL_TOL):
            break
        nu = 2.0 * np.sqrt(munu)
        munu = mu * nu
    a = _HALF_PI * (sa + ca * mu) / (mu * (mu + pa))
    b = _HALF_PI * (sb + cb * mu) / (mu * (mu + pb))
    return a, b


def cylinder_axial_rz(r: np.ndarray, z: np.ndarray, z0: float) -> tuple[np.ndarray, np.ndarray]:
    """(B_r, B_z) of a cylinder of radius 1 and half-height ``z0``, unit polarisation.

    ``r`` >= 0 and ``z`` are observer coordinates over the radius, in the magnet's
    own frame (centre at the origin, polarisation along +z). Exact on the axis
    (B_r = 0 and the textbook on-axis B_z); NaN on the edge circles, where the
    field is singular. Valid inside the magnet too (B, not H).
    """
    r = np.asarray(r, dtype=float)
    z = np.asarray(z, dtype=float)
    zp, zm = z + z0, z - z0
    dpr, dmr = 1.0 + r, 1.0 - r
    zp2, zm2, dpr2, dmr2 = zp * zp, zm * zm, dpr * dpr, dmr * dmr
    sq1 = np.sqrt(zp2 + dpr2)
    sq0 = np.sqrt(zm2 + dpr2)
    # both moduli in one array so that the AGM runs once over both
    kc = np.sqrt(np.concatenate([(zp2 + dmr2), (zm2 + dmr2)])) / np.concatenate([sq1, sq0])
    gamma = dmr / dpr
    gamma2 = np.concatenate([gamma * gamma] * 2)
    one = np.ones_like(kc)
    # kc = 0 on the edge circles (and NaN for non-finite points): the AGM would never converge there
    stuck = ~(kc > 0) | ~np.isfinite(gamma2)
    if np.any(stuck):
        kc = np.where(stuck, 1.0, kc)
        gamma2 = np.where(stuck, 1.0, gamma2)
    with np.errstate(divide="ignore", invalid="ignore"):
        cel_r, cel_z = _cel_pair(kc, one, one, -one, gamma2, one, np.concatenate([np.where(np.isfinite(gamma), gamma, 1.0)] * 2))
    n = r.size
    br = (cel_r[:n] / sq1 - cel_r[n:] / sq0) / np.pi
    bz = (zp * cel_z[:n] / sq1 - zm * cel_z[n:] / sq0) / (np.pi * dpr)
    on_axis = r == 0
    if np.any(on_axis):
        # 1/2 (a/sa - b/sb) with a = |z| + z0, b = |z| - z0, rewritten without the cancellation far away
        with np.errstate(divide="ignore", invalid="ignore"):
            a, b = np.abs(z) + z0, np.abs(z) - z0
            sa, sb = np.sqrt(a * a + 1.0), np.sqrt(b * b + 1.0)
            far = 2.0 * z0 * np.abs(z) / (sa * sb * (a * sb + b * sa))
            near = 0.5 * (zp / np.sqrt(zp2 + 1.0) - zm / np.sqrt(zm2 + 1.0))
            axial = np.where(np.abs(z) > z0, far, near)
        br = np.where(on_axis, 0.0, br)
        bz = np.where(on_axis, axial, bz)
    bad = (r == 1.0) & (np.abs(z) == z0) | stuck[:n] | stuck[n:]
    if np.any(bad):
        br = np.where(bad, np.nan, br)
        bz = np.where(bad, np.nan, bz)
    return br, bz


def cylinder_field(points: np.ndarray, diameter: float, height: float, polarization: float) -> np.ndarray:
    """B (same unit as ``polarization``) at ``points`` (..., 3) in the magnet's own frame."""
    pts = np.asarray(points, dtype=float)
    flat = pts.reshape(-1, 3)
    out = np.empty_like(flat)
    radius = diameter / 2
    for lo in range(0, len(flat), _CHUNK):
        blk = flat[lo : lo + _CHUNK] / radius
        x, y, z = blk[:, 0], blk[:, 1], blk[:, 2]
        r = np.hypot(x, y)
        br, bz = cylinder_axial_rz(r, z, height / diameter)
        with np.errstate(divide="ignore", invalid="ignore"):
            scale = np.where(r > 0, br / r, 0.0)
        out[lo : lo + _CHUNK, 0] = scale * x
        out[lo : lo + _CHUNK, 1] = scale * y
        out[lo : lo + _CHUNK, 2] = bz
    return (out * polarization).reshape(pts.shape)


def cylinder_projection(
    points: np.ndarray, axes: np.ndarray, diameter: float, height: float, polarization: float
) -> np.ndarray:
    """B . axis at ``points`` (M, 3) for unit ``axes`` (M, 3), both in the magnet's frame."""
    out = np.empty(len(points))
    radius = diameter / 2
    for lo in range(0, len(points), _CHUNK):
        blk = points[lo : lo + _CHUNK] / radius
        ax = axes[lo : lo + _CHUNK]
        x, y, z = blk[:, 0], blk[:, 1], blk[:, 2]
        r = np.hypot(x, y)
        br, bz = cylinder_axial_rz(r, z, height / diameter)
        with np.errstate(divide="ignore", invalid="ignore"):
            scale = np.where(r > 0, br / r, 0.0)
        out[lo : lo + _CHUNK] = scale * (x * ax[:, 0] + y * ax[:, 1]) + bz * ax[:, 2]
    return out * polarization


def dipole_field(points: np.ndarray, moment_axis_z: float) -> np.ndarray:
    """Point-dipole B at ``points`` (..., 3) for a moment ``m`` along +z (B = mu0/4pi (3(m.r)r/r^5 - m/r^3)).

    ``moment_axis_z`` is mu0 m / (4 pi) in field-unit times length cubed.
    """
    p = np.asarray(points, dtype=float)
    r2 = np.sum(p * p, axis=-1, keepdims=True)
    r = np.sqrt(r2)
    m = np.zeros_like(p)
    m[..., 2] = moment_axis_z
    mdotr = p[..., 2:3] * moment_axis_z
    return 3 * mdotr * p / (r2 * r2 * r) - m / (r2 * r)
