"""Tests of fitgen.physics.field: the closed-form field of an axially magnetised cylinder.

The reference is magpylib's ``Cylinder`` (an independent implementation of the
same Derby & Olbert solution), the textbook on-axis formula, the point-dipole
limit, and, where mpmath is installed, the same solution evaluated at 40 digits
with Carlson's integrals instead of Bulirsch's ``cel``.
"""

from __future__ import annotations

import functools
import json
import subprocess
import sys
import textwrap
import zlib

import numpy as np
import pytest

from fitgen.physics.field import cylinder_axial_rz, cylinder_field, cylinder_projection, dipole_field

import magpylib as magpy  # noqa: E402  (the test extra; a missing oracle must fail, not skip)

# (diameter, height): the paper's 6 x 1 mm disc, a tall rod and a flat disc
SHAPES = {"paper-6x1": (6.0, 1.0), "tall-2x10": (2.0, 10.0), "flat-10x0.2": (10.0, 0.2)}
# observer families outside the magnet and how many points each shape gets
FAMILIES = {
    "near": 1000,  # anywhere within 2 radii of the surface
    "hull-skin": 500,  # r in (1, 1.01) radii, |z| <= h: just outside the side wall
    "base-skin": 500,  # r <= R, |z| - h in (0, 0.01] radii: just above / below a base
    "far": 800,  # 3 .. 1000 radii from the centre, random direction
    "axis": 300,  # x = y = 0 exactly, h < |z| < h + 100 radii
    "hull-plane": 300,  # r == R exactly, |z| > h
    "base-plane": 300,  # |z| == h exactly, r > R
}
SEED = 20100229  # Derby & Olbert, Am. J. Phys. 78 (2010) 229


def _rng(*key) -> np.random.Generator:
    """A generator seeded from SEED and a name, so each case is reproducible on its own."""
    return np.random.default_rng([SEED, zlib.crc32(repr(key).encode())])


def _directions(rng, n):
    u = rng.normal(size=(n, 3))
    return u / np.linalg.norm(u, axis=1, keepdims=True)


def _outside(pts, R, h):
    return (np.hypot(pts[:, 0], pts[:, 1]) > R) | (np.abs(pts[:, 2]) > h)


@functools.lru_cache(maxsize=None)
def observer_points(shape: str, family: str) -> np.ndarray:
    """Seeded random observer points (n, 3) in mm, all strictly outside the magnet."""
    D, H = SHAPES[shape]
    R, h = D / 2, H / 2
    n = FAMILIES[family]
    rng = _rng(shape, family)
    sign = lambda: rng.choice([-1.0, 1.0], n)  # noqa: E731
    phi = rng.uniform(0, 2 * np.pi, n)
    if family == "near":
        chunks = []
        while sum(len(c) for c in chunks) < n:
            # cylindrical box reaching 2 radii beyond the side wall and the bases
            m = 4 * n
            r = 3 * R * np.sqrt(rng.uniform(0, 1, m))
            a = rng.uniform(0, 2 * np.pi, m)
            z = rng.uniform(-h - 2 * R, h + 2 * R, m)
            p = np.column_stack([r * np.cos(a), r * np.sin(a), z])
            chunks.append(p[_outside(p, R, h)])
        pts = np.vstack(chunks)[:n]
    elif family == "hull-skin":
        r = R * rng.uniform(1.0, 1.01, n)
        r = np.where(r > R, r, np.nextafter(R, np.inf))
        z = rng.uniform(-h, h, n)
        pts = np.column_stack([r * np.cos(phi), r * np.sin(phi), z])
    elif family == "base-skin":
        r = R * np.sqrt(rng.uniform(0, 1, n))
        dz = R * rng.uniform(0, 0.01, n)
        z = sign() * (h + np.where(dz > 0, dz, 1e-9 * R))
        pts = np.column_stack([r * np.cos(phi), r * np.sin(phi), z])
    elif family == "far":
        d = R * 10 ** rng.uniform(np.log10(3), 3, n)
        pts = _directions(rng, n) * d[:, None]
    elif family == "axis":
        # up to 100 radii: farther out the closed form loses digits near the axis
        # (see test_on_axis_far_flat_disc_precision)
        z = sign() * (h + R * 10 ** rng.uniform(-3, 2, n))
        pts = np.column_stack([np.zeros(n), np.zeros(n), z])
    elif family == "hull-plane":
        # keep only azimuths where the rounded point still has hypot(x, y) == R exactly
        cand = rng.uniform(0, 2 * np.pi, 20 * n)
        xy = np.column_stack([R * np.cos(cand), R * np.sin(cand)])
        xy = xy[np.hypot(xy[:, 0], xy[:, 1]) == R][: n - 4]
        xy = np.vstack([[[R, 0.0], [-R, 0.0], [0.0, R], [0.0, -R]], xy])
        z = sign()[: len(xy)] * (h + R * 10 ** rng.uniform(-3, 2, len(xy)))
        pts = np.column_stack([xy, z])
    elif family == "base-plane":
        r = R * (1 + 10 ** rng.uniform(-3, 2, n))
        pts = np.column_stack([r * np.cos(phi), r * np.sin(phi), sign() * h])
    else:  # pragma: no cover
        raise KeyError(family)
    assert np.all(_outside(pts, R, h))
    return pts


def magpylib_B(points, D, H, J=1.0):
    return magpy.magnet.Cylinder(dimension=(D, H), polarization=(0, 0, J)).getB(points)


def rel_err(ours, ref):
    return np.linalg.norm(ours - ref, axis=-1) / np.linalg.norm(ref, axis=-1)


# --- agreement with magpylib -------------------------------------------------------


def test_enough_random_points():
    total = sum(len(observer_points(s, f)) for s in SHAPES for f in FAMILIES)
    assert total >= 10_000, total
    hp = [observer_points(s, "hull-plane") for s in SHAPES]
    assert all(len(p) >= 250 for p in hp)  # enough azimuths survive the exact-radius filter


@pytest.mark.parametrize("family", list(FAMILIES))
@pytest.mark.parametrize("shape", list(SHAPES))
def test_matches_magpylib_outside(shape, family):
    D, H = SHAPES[shape]
    pts = observer_points(shape, family)
    J = 1.32
    ours = cylinder_field(pts, D, H, J)
    ref = magpylib_B(pts, D, H, J)
    assert np.all(np.isfinite(ours))
    err = rel_err(ours, ref)
    worst = int(np.argmax(err))
    assert err[worst] <= 1e-6, (shape, family, pts[worst].tolist(), ours[worst], ref[worst])


def test_hull_plane_points_are_exactly_on_the_hull():
    for shape, (D, H) in SHAPES.items():
        p = observer_points(shape, "hull-plane")
        assert np.all(np.hypot(p[:, 0], p[:, 1]) == D / 2)
        assert np.all(np.abs(p[:, 2]) > H / 2)
        b = observer_points(shape, "base-plane")
        assert np.all(np.abs(b[:, 2]) == H / 2)


@pytest.mark.parametrize("shape", list(SHAPES))
def test_matches_magpylib_inside(shape):
    """Inside the magnet the kernel gives B (H + J), as magpylib does."""
    D, H = SHAPES[shape]
    R, h = D / 2, H / 2
    rng = _rng(shape, "inside")
    n = 300
    r = R * np.sqrt(rng.uniform(0, 0.999, n))
    phi = rng.uniform(0, 2 * np.pi, n)
    z = rng.uniform(-0.999 * h, 0.999 * h, n)
    pts = np.column_stack([r * np.cos(phi), r * np.sin(phi), z])
    pts[:10, :2] = 0.0  # a few on the axis, inside
    pts[10] = 0.0  # the centre
    ours = cylinder_field(pts, D, H, 1.0)
    ref = magpylib_B(pts, D, H, 1.0)
    err = rel_err(ours, ref)
    assert err.max() <= 1e-6, (shape, pts[np.argmax(err)].tolist())


# --- independent high-precision reference ---------------------------------------------


def _mp_reference(point, R, h):
    """The Derby & Olbert field at 40 digits via Carlson's R_F, R_J (unit polarisation)."""
    import mpmath as mp
    with mp.workdps(40):
        x, y, z = (mp.mpf(float(v)) / mp.mpf(R) for v in point)
        hh = mp.mpf(h) / mp.mpf(R)
        r = mp.sqrt(x * x + y * y)
        g = (1 - r) / (1 + r)

        def cel(kc, p, a, b):  # Bulirsch's cel in terms of Carlson's integrals
            t = a * mp.elliprf(0, kc * kc, 1)
            if b - p * a != 0:
                t += (b - p * a) / 3 * mp.elliprj(0, kc * kc, 1, p)
            return t

        br = bz = mp.mpf(0)
        for sgn, xi in ((1, z + hh), (-1, z - hh)):
            a = 1 / mp.sqrt(xi**2 + (1 + r) ** 2)
            kc = mp.sqrt(xi**2 + (1 - r) ** 2) * a
            br += sgn * a * cel(kc, 1, 1, -1)
            bz += sgn * xi * a * cel(kc, g * g, 1, g)
        br, bz = br / mp.pi, bz / (mp.pi * (1 + r))
        return np.array([float(br * x / r), float(br * y / r), float(bz)])


@pytest.mark.parametrize("shape", list(SHAPES))
def test_matches_high_precision_reference(shape):
    """Near the magnet the double-precision kernel is good to ~1e-13 of |B|.

    Far away the closed form cancels (two base terms, and 1 - k^2 in the
    elliptic integrals), so the accuracy degrades to ~1e-9 at 1000 radii; magpylib,
    which evaluates the same form, shows the same error.
    """
    D, H = SHAPES[shape]
    R, h = D / 2, H / 2
    rng = _rng(shape, "mpmath")
    for dmax, tol in ((3, 1e-12), (10, 1e-12), (100, 1e-10), (1000, 1e-8)):
        d = R * rng.uniform(1.2, dmax, 12)
        pts = _directions(rng, 12) * d[:, None]
        pts = pts[_outside(pts, R, h) & (np.hypot(pts[:, 0], pts[:, 1]) > 0)]
        ref = np.array([_mp_reference(p, R, h) for p in pts])
        err = rel_err(cylinder_field(pts, D, H, 1.0), ref)
        assert err.max() <= tol, (shape, dmax, err.max())


# --- far field: the dipole limit -------------------------------------------------------


@pytest.mark.parametrize("shape", list(SHAPES))
def test_dipole_limit(shape):
    """At 200-2000 radii B -> dipole with mu0 m / 4pi = J V / 4pi; the error falls like 1/d^2.

    The first correction is the octupole term, of relative size ~ (L/d)^2 with L the
    magnet's larger half-dimension (the radius, or half the height of a tall rod).
    """
    D, H = SHAPES[shape]
    R, h = D / 2, H / 2
    L = max(R, h)
    J = 1.32
    moment = J * np.pi * R**2 * H / (4 * np.pi)
    rng = _rng(shape, "dipole")
    u = _directions(rng, 400)
    d = R * 10 ** rng.uniform(np.log10(200), np.log10(2000), len(u))
    pts = u * d[:, None]
    err = rel_err(cylinder_field(pts, D, H, J), dipole_field(pts, moment))
    assert np.all(err < 5 * (L / d) ** 2), (shape, np.max(err * (d / L) ** 2))
    # the error shrinks like (R/d)^2: ten times farther, a hundred times smaller. Measured
    # between 100 and 1000 radii: at 2000 radii the kernel's own rounding (up to ~1e-8 of
    # |B| for the flat disc) is no longer negligible against a correction of ~3e-7.
    e_near = rel_err(cylinder_field(u * 100 * R, D, H, J), dipole_field(u * 100 * R, moment))
    e_far = rel_err(cylinder_field(u * 1000 * R, D, H, J), dipole_field(u * 1000 * R, moment))
    ratio = e_near / e_far
    assert 97 < np.median(ratio) < 103, np.median(ratio)
    assert np.all((ratio > 85) & (ratio < 115)), (ratio.min(), ratio.max())


def test_dipole_field_formula():
    m = 2.5
    # on the axis: B = 2 m / z^3 along z; in the equatorial plane: B = -m / r^3
    np.testing.assert_allclose(dipole_field(np.array([0.0, 0.0, 2.0]), m), [0, 0, 2 * m / 8], rtol=1e-15)
    np.testing.assert_allclose(dipole_field(np.array([[0.0, -2.0, 0.0]]), m), [[0, 0, -m / 8]], rtol=1e-15)


# --- scaling invariance -------------------------------------------------------------------


@pytest.mark.parametrize("shape", list(SHAPES))
def test_scaling_power_of_two_is_exact(shape):
    """Power-of-two factors leave x/R bit-identical, so B must be bit-identical too."""
    D, H = SHAPES[shape]
    pts = np.vstack([observer_points(shape, f) for f in FAMILIES])
    pts = np.vstack([pts, [[0, 0, 0]], [[0.3 * D, 0.1 * D, 0.2 * H]]])  # two inside
    B0 = cylinder_field(pts, D, H, 1.0)
    for s in (2.0**-7, 2.0**10, 2.0**30):
        np.testing.assert_array_equal(cylinder_field(pts * s, D * s, H * s, 1.0), B0)


@pytest.mark.parametrize("shape", list(SHAPES))
@pytest.mark.parametrize("factor", [0.01, 7.3, 1000.0])
def test_scaling_invariance(shape, factor):
    """Scaling magnet and observer together leaves B unchanged.

    To 1e-12 of |B| within 2 radii of the magnet (the near field, where the paper's
    elements live at rest). Farther out, rounding x/R in the last bit is amplified by
    the closed form's cancellation (see test_matches_high_precision_reference), so
    there the bound is the kernel's own accuracy.
    """
    D, H = SHAPES[shape]
    near = np.vstack([observer_points(shape, f) for f in ("near", "hull-skin", "base-skin")])
    b0 = cylinder_field(near, D, H, 1.0)
    b1 = cylinder_field(near * factor, D * factor, H * factor, 1.0)
    assert rel_err(b1, b0).max() <= 1e-12
    far = np.vstack([observer_points(shape, f) for f in ("far", "axis", "hull-plane", "base-plane")])
    b0 = cylinder_field(far, D, H, 1.0)
    b1 = cylinder_field(far * factor, D * factor, H * factor, 1.0)
    assert rel_err(b1, b0).max() <= 1e-7


def test_polarization_is_linear():
    pts = observer_points("paper-6x1", "near")
    np.testing.assert_allclose(cylinder_field(pts, 6, 1, -1320.0), -1000 * cylinder_field(pts, 6, 1, 1.32),
                               rtol=1e-14, atol=0)


# --- on the axis --------------------------------------------------------------------------


def _textbook_axial(z, R, h, J):
    return J / 2 * ((z + h) / np.sqrt((z + h) ** 2 + R**2) - (z - h) / np.sqrt((z - h) ** 2 + R**2))


@pytest.mark.parametrize("shape", list(SHAPES))
def test_on_axis_exact(shape):
    D, H = SHAPES[shape]
    R, h = D / 2, H / 2
    J = 1.32
    rng = _rng(shape, "axis-exact")
    z = np.concatenate([
        rng.uniform(-h - 5 * R, h + 5 * R, 2000),  # outside and inside
        rng.uniform(-h, h, 200),  # inside
        [0.0, h, -h, 2 * h, -3 * h],  # centre, base centres
    ])
    pts = np.column_stack([np.zeros_like(z), np.zeros_like(z), z])
    B = cylinder_field(pts, D, H, J)
    assert np.all(B[:, :2] == 0.0)  # exactly zero, not merely small
    # equal to 1e-12, or to the rounding of the formula's two terms (each <= J/2)
    np.testing.assert_allclose(B[:, 2], _textbook_axial(z, R, h, J), rtol=1e-12, atol=1e-15 * J)
    # a signed zero in x or y is still the axis
    Bm = cylinder_field(np.array([[-0.0, 0.0, h + R], [0.0, -0.0, -h - R]]), D, H, J)
    assert np.all(Bm[:, :2] == 0.0)
    np.testing.assert_allclose(Bm[:, 2], _textbook_axial(np.array([h + R, -h - R]), R, h, J), rtol=1e-13)


def _stable_axial(z, R, h, J):
    """The textbook on-axis B_z outside the magnet, rewritten without cancellation (|z| > h)."""
    a, b = np.abs(z) + h, np.abs(z) - h
    sa, sb = np.sqrt(a * a + R * R), np.sqrt(b * b + R * R)
    # a/sa - b/sb = R^2 (a^2 - b^2) / (sa sb (a sb + b sa)),  a^2 - b^2 = 4 h |z|
    return J / 2 * R * R * 4 * h * np.abs(z) / (sa * sb * (a * sb + b * sa))


@pytest.mark.parametrize("shape", list(SHAPES))
def test_on_axis_far_against_cancellation_free_form(shape):
    """Up to 100 radii along the axis B_z is right to 1e-8 of itself (all shapes)."""
    D, H = SHAPES[shape]
    R, h = D / 2, H / 2
    J = 1.32
    z = np.geomspace(h + 0.01 * R, h + 100 * R, 300)
    z = np.concatenate([z, -z])
    B = cylinder_field(np.column_stack([0 * z, 0 * z, z]), D, H, J)
    np.testing.assert_allclose(B[:, 2], _stable_axial(z, R, h, J), rtol=1e-8, atol=0)


def test_on_axis_far_flat_disc_precision():
    """Far along a flat disc's axis the textbook formula's two terms cancel; the kernel's form does not."""
    D, H, J = 10.0, 0.2, 1.32
    R, h = D / 2, H / 2
    z = np.geomspace(300 * R, 3000 * R, 200)
    B = cylinder_field(np.column_stack([0 * z, 0 * z, z]), D, H, J)
    np.testing.assert_allclose(B[:, 2], _stable_axial(z, R, h, J), rtol=1e-7, atol=0)


def test_axial_rz_on_axis():
    z = np.array([-3.0, -0.1, 0.0, 0.1, 3.0])
    br, bz = cylinder_axial_rz(np.zeros_like(z), z, 0.25)
    assert np.all(br == 0.0)
    np.testing.assert_allclose(bz, _textbook_axial(z, 1.0, 0.25, 1.0), rtol=1e-14)


# --- special points -----------------------------------------------------------------------


HANG_TIMEOUT = 60.0  # s: a hang, not a slow start (a fresh interpreter and numpy take seconds on a loaded machine)


def _run_isolated(code: str) -> dict:
    """Run ``code`` (which prints a JSON dict) in a fresh interpreter; fail if it does not finish.

    The kernel's AGM loop runs until every entry has converged; were a point that
    cannot converge (kc = 0 or NaN) to reach it, the process would hang. A subprocess
    turns such a regression into a failure instead of a stuck test run.
    """
    prelude = "import json, warnings, numpy as np\nwarnings.simplefilter('ignore')\n"
    try:
        proc = subprocess.run([sys.executable, "-c", prelude + textwrap.dedent(code)],
                              capture_output=True, text=True, timeout=HANG_TIMEOUT)
    except subprocess.TimeoutExpired:
        pytest.fail(f"the field kernel did not return within {HANG_TIMEOUT} s (endless AGM loop)")
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout)


def test_edge_circle_is_nan():
    """On the edge circles (r == R, |z| == H/2) the field is singular: the kernel returns NaN."""
    out = _run_isolated("""
        from fitgen.physics.field import cylinder_axial_rz, cylinder_field
        res = {}
        for name, (D, H) in %r.items():
            R, h = D / 2, H / 2
            edge = np.array([[R, 0, h], [-R, 0, h], [0, R, -h], [0, -R, -h], [R, 0, -h], [0, R, h]])
            mixed = np.vstack([edge, [[2 * R, 0.0, 3 * h], [0.0, 0.0, 2 * h]]])
            res[name] = np.isnan(cylinder_field(mixed, D, H, 1.0)).any(axis=1).tolist()
        br, bz = cylinder_axial_rz(np.array([1.0, 1.0, 1.0]), np.array([0.3, -0.3, 0.2]), 0.3)
        res["rz"] = (np.isnan(br) & np.isnan(bz)).tolist()
        print(json.dumps(res))
    """ % (SHAPES,))
    for name in SHAPES:
        assert out[name] == [True] * 6 + [False] * 2, (name, out[name])  # NaN on the edge only
    assert out["rz"] == [True, True, False]


def test_non_finite_points_give_nan():
    """A NaN or infinite coordinate gives NaN for that point (and does not stop the batch)."""
    out = _run_isolated("""
        from fitgen.physics.field import cylinder_field
        pts = np.array([[np.nan, 0, 5.0], [np.inf, 0, 5.0], [1.0, 2.0, 5.0]])
        print(json.dumps(np.isfinite(cylinder_field(pts, 6.0, 1.0, 1.0)).all(axis=1).tolist()))
    """)
    assert out == [False, False, True]


@pytest.mark.parametrize("shape", list(SHAPES))
def test_next_to_edge_circle_is_finite(shape):
    """Just off the edge circle (1e-12 .. 1e-6 of the radius) the kernel returns finite values."""
    D, H = SHAPES[shape]
    R, h = D / 2, H / 2
    offsets = np.array([1e-12, 1e-9, 1e-6])
    rr = np.concatenate([R * (1 + offsets), R * (1 - offsets)])
    zz = np.concatenate([h + R * offsets, h - R * offsets])
    pts = [[r, 0.0, s * z] for r in rr for z in zz for s in (1, -1)]
    pts += [[r, 0.0, s * h] for r in rr for s in (1, -1)]
    pts += [[0.0, R, s * z] for z in zz for s in (1, -1)]
    assert np.all(np.isfinite(cylinder_field(np.array(pts), D, H, 1.0)))


def test_field_keeps_shape_and_handles_many_points():
    """(..., 3) in, (..., 3) out; more points than one processing block (2**15)."""
    rng = _rng("blocks")
    pts = rng.uniform(-20, 20, (5, 9000, 3))
    pts[..., 2] += np.where(pts[..., 2] >= 0, 1.0, -1.0)  # keep clear of the magnet
    B = cylinder_field(pts, 6.0, 1.0, 1.0)
    assert B.shape == pts.shape
    flat = pts.reshape(-1, 3)
    idx = rng.choice(len(flat), 500, replace=False)
    assert rel_err(B.reshape(-1, 3)[idx], magpylib_B(flat[idx], 6.0, 1.0)).max() <= 1e-6
    single = cylinder_field(np.array([1.0, 2.0, 5.0]), 6.0, 1.0, 1.0)
    assert single.shape == (3,)


# --- projection -----------------------------------------------------------------------------


@pytest.mark.parametrize("shape", list(SHAPES))
def test_projection_equals_field_dot_axes(shape):
    D, H = SHAPES[shape]
    rng = _rng(shape, "projection")
    pts = np.vstack([observer_points(shape, f) for f in FAMILIES])
    pts = np.vstack([pts] * 10)  # > one block of 2**15 points
    axes = _directions(rng, len(pts))
    J = 1320.0
    proj = cylinder_projection(pts, axes, D, H, J)
    B = cylinder_field(pts, D, H, J)
    dot = np.einsum("ij,ij->i", B, axes)
    scale = np.linalg.norm(B, axis=1)
    assert proj.shape == (len(pts),)
    assert np.all(np.abs(proj - dot) <= 1e-13 * scale)
    # on the axis with a radial axis the projection is exactly 0
    on_axis = np.array([[0.0, 0.0, 5.0], [0.0, 0.0, -5.0]])
    radial = np.array([[1.0, 0.0, 0.0], [np.sqrt(0.5), np.sqrt(0.5), 0.0]])
    assert np.all(cylinder_projection(on_axis, radial, D, H, J) == 0.0)
