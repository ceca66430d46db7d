"""Tests of fitgen.physics.pose: the pose convention and the element readings.

Pose = (dx, dy, dz, thx, thy), R = Ry(thy) Rx(thx) about the magnet's own centre,
rotation first, then translation; reading k = B . axis_k in mT
(docs/conventions.md). The whole chain is checked against magpylib with scipy's
rotation, which implements the same convention independently.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fitgen.base.errors import InputError
from fitgen.physics.pose import as_poses, field_readings, magnet_frame, rotation_matrices
from fitgen.physics.sensor import load_sensor, parse_sensor

import magpylib as magpy  # noqa: E402  (the test extra; a missing oracle must fail, not skip)

SEED = 5


@pytest.fixture(scope="module")
def paper():
    return load_sensor("paper")


def random_poses(rng, n, tilt=10.0):
    return np.column_stack([
        rng.uniform(-2, 2, n), rng.uniform(-2, 2, n), rng.uniform(-3, 0, n),
        rng.uniform(-tilt, tilt, n), rng.uniform(-tilt, tilt, n),
    ])


def magpylib_readings(sensor, poses):
    """Readings from magpylib: one cylinder with a path of positions and scipy orientations."""
    mag = sensor.magnet
    rot = Rotation.from_euler("xy", poses[:, 3:5], degrees=True)  # extrinsic x, then y
    cyl = magpy.magnet.Cylinder(
        dimension=(mag.diameter, mag.height),
        polarization=(0, 0, mag.polarization),  # T
        position=np.asarray(mag.rest_center) + poses[:, :3],
        orientation=rot,
    )
    B = cyl.getB(sensor.positions) * 1e3  # (P, N, 3), T -> mT
    return np.einsum("pnj,nj->pn", B, sensor.axes)


def mirror_index(sensor, flip):
    """For each element, the element at its mirror image (positions and axes); flip is a diagonal."""
    pos, ax = sensor.positions * flip, sensor.axes * flip
    idx = []
    for p, a in zip(pos, ax):
        d = np.linalg.norm(sensor.positions - p, axis=1)
        k = int(np.argmin(d))
        assert d[k] < 1e-9 and np.allclose(sensor.axes[k], a, atol=1e-12)
        idx.append(k)
    return np.array(idx)


# --- rotation -----------------------------------------------------------------------


def test_rotation_matrices_match_scipy():
    rng = np.random.default_rng(SEED)
    thx = np.concatenate([rng.uniform(-10, 10, 500), rng.uniform(-180, 180, 500), [0, 90, -90, 180]])
    thy = np.concatenate([rng.uniform(-10, 10, 500), rng.uniform(-180, 180, 500), [90, 0, 45, -180]])
    R = rotation_matrices(thx, thy)
    ref = Rotation.from_euler("xy", np.column_stack([thx, thy]), degrees=True).as_matrix()
    assert R.shape == (len(thx), 3, 3)
    np.testing.assert_allclose(R, ref, rtol=0, atol=1e-15)
    # and the convention in words: R = Ry(thy) @ Rx(thx)
    rx = Rotation.from_euler("x", thx[:, None], degrees=True).as_matrix()
    ry = Rotation.from_euler("y", thy[:, None], degrees=True).as_matrix()
    np.testing.assert_allclose(R, ry @ rx, rtol=0, atol=1e-15)


def test_rotation_matrices_scalar_and_orthonormal():
    R = rotation_matrices(3.0, -4.0)
    assert R.shape == (3, 3)
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-15)
    assert np.isclose(np.linalg.det(R), 1.0)
    # a positive thx tips the magnet's +z axis toward -y (right-hand rule about +x)
    z_axis = rotation_matrices(10.0, 0.0) @ [0, 0, 1]
    assert z_axis[1] < 0 and z_axis[0] == 0
    # a positive thy tips it toward +x
    z_axis = rotation_matrices(0.0, 10.0) @ [0, 0, 1]
    assert z_axis[0] > 0 and z_axis[1] == 0


# --- the whole convention against magpylib ---------------------------------------------


def test_readings_match_magpylib(paper):
    rng = np.random.default_rng(SEED)
    poses = random_poses(rng, 200)
    poses[0] = 0.0  # rest
    poses[1] = [0, 0, 0, 10, 0]
    poses[2] = [0, 0, 0, 0, -10]
    poses[3] = [2, -2, -3, 10, -10]
    ours = field_readings(paper, poses)
    ref = magpylib_readings(paper, poses)
    assert ours.shape == (200, paper.n_elements) == ref.shape
    scale = np.abs(ref).max()
    assert scale > 0.1  # mT: the comparison is not vacuous
    assert np.abs(ours - ref).max() <= 1e-9 * scale, np.abs(ours - ref).max() / scale


def test_readings_match_magpylib_other_axes():
    """Tangential, z and tilted element axes, elements above and below the magnet, a shifted magnet."""
    sensor = parse_sensor({
        "name": "probe",
        "magnet": {"diameter": 4.0, "height": 2.5, "polarization": -1.1},
        "board": {"thickness": 1.0, "gap": 6.0},
        "transfer": {"kind": "raw"},
        "elements": {
            "ring": [{"count": 5, "radius": 7.0, "z": 0.5, "start": 10.0, "axis": "tangential"},
                     {"count": 3, "radius": 4.0, "z": -1.0, "axis": "z"}],
            "list": [{"position": [1.0, -2.0, 14.0], "axis": [1.0, 2.0, -3.0]},
                     {"position": [0.0, 0.0, 3.0], "axis": [0.0, 0.0, -1.0]}],
        },
    }, "test")
    rng = np.random.default_rng(SEED + 1)
    poses = random_poses(rng, 100, tilt=30.0)
    ours = field_readings(sensor, poses)
    ref = magpylib_readings(sensor, poses)
    assert np.abs(ours - ref).max() <= 1e-9 * np.abs(ref).max()


def test_magnet_frame_roundtrip(paper):
    """Element positions in the magnet's frame, mapped back with R and the centre, give the positions."""
    rng = np.random.default_rng(SEED + 2)
    poses = random_poses(rng, 50, tilt=40.0)
    local, axes = magnet_frame(paper, poses)
    R = rotation_matrices(poses[:, 3], poses[:, 4])
    centre = np.asarray(paper.magnet.rest_center) + poses[:, :3]
    back = np.einsum("pij,pnj->pni", R, local) + centre[:, None, :]
    np.testing.assert_allclose(back, np.broadcast_to(paper.positions, back.shape), atol=1e-12)
    np.testing.assert_allclose(np.einsum("pij,pnj->pni", R, axes),
                               np.broadcast_to(paper.axes, axes.shape), atol=1e-15)


# --- symmetry -----------------------------------------------------------------------------


def test_rest_readings_are_equal_and_inward(paper):
    """At rest all eight radial readings are equal (rotational symmetry) and negative.

    Below a magnet polarised along +z the field's radial part points inward.
    """
    r = field_readings(paper, np.zeros(5))[0]
    assert np.all(r < 0)
    np.testing.assert_allclose(r, r[0], rtol=1e-13)


def test_dx_mirror(paper):
    """dx = +1 and dx = -1 mirror the readings: element at phi <-> element at pi - phi."""
    idx = mirror_index(paper, np.array([-1.0, 1.0, 1.0]))
    phi = np.degrees(np.arctan2(paper.positions[:, 1], paper.positions[:, 0])) % 360
    np.testing.assert_allclose((180 - phi[idx]) % 360, phi, atol=1e-9)
    assert idx.tolist() == [4, 3, 2, 1, 0, 7, 6, 5]  # 1<->5, 2<->4, 3, 6<->8, 7
    for dy, dz, thx in [(0, 0, 0), (0.5, -1, 0), (-1.5, -2.5, 3)]:
        plus = field_readings(paper, [1, dy, dz, thx, 0])[0]
        minus = field_readings(paper, [-1, dy, dz, thx, 0])[0]
        np.testing.assert_allclose(minus[idx], plus, rtol=0, atol=1e-12 * np.abs(plus).max())
        assert not np.allclose(minus, plus)  # the shift does change the readings
    # in general: (dx, dy, dz, thx, thy) -> (-dx, dy, dz, thx, -thy)
    rng = np.random.default_rng(SEED + 3)
    poses = random_poses(rng, 100)
    mirrored = poses * [-1, 1, 1, 1, -1]
    a, b = field_readings(paper, poses), field_readings(paper, mirrored)
    np.testing.assert_allclose(b[:, idx], a, rtol=0, atol=1e-12 * np.abs(a).max())


def test_dy_mirror(paper):
    """(dx, dy, dz, thx, thy) -> (dx, -dy, dz, -thx, thy) maps element at phi to the one at -phi."""
    idx = mirror_index(paper, np.array([1.0, -1.0, 1.0]))
    assert idx.tolist() == [0, 7, 6, 5, 4, 3, 2, 1]
    rng = np.random.default_rng(SEED + 4)
    poses = random_poses(rng, 100)
    a = field_readings(paper, poses)
    b = field_readings(paper, poses * [1, -1, 1, -1, 1])
    np.testing.assert_allclose(b[:, idx], a, rtol=0, atol=1e-12 * np.abs(a).max())


def test_pressing_increases_every_reading(paper):
    """At zero tilt, dz more negative (magnet closer to the board) increases |reading| everywhere."""
    dz = np.linspace(0.0, -3.0, 31)
    for dx in np.linspace(-2, 2, 9):
        for dy in np.linspace(-2, 2, 9):
            poses = np.column_stack([np.full_like(dz, dx), np.full_like(dz, dy), dz,
                                     np.zeros_like(dz), np.zeros_like(dz)])
            mag = np.abs(field_readings(paper, poses))
            assert np.all(np.diff(mag, axis=0) > 0), (dx, dy)


# --- bad input -------------------------------------------------------------------------------


def _probe_sensor(position):
    return parse_sensor({
        "name": "probe",
        "magnet": {"diameter": 6.0, "height": 1.0},
        "board": {"thickness": 1.5, "gap": 11.0},  # magnet centre at rest: z = 13
        "transfer": {"kind": "raw"},
        "elements": {"list": [{"position": [8.0, 0.0, 0.0], "axis": [1.0, 0.0, 0.0]},
                              {"position": position, "axis": [0.0, 0.0, 1.0]}]},
    }, "test")


def test_element_inside_magnet_raises():
    sensor = _probe_sensor([0.0, 0.0, 11.0])
    field_readings(sensor, [0, 0, 0, 0, 0])  # fine at rest: 2 mm below the centre
    with pytest.raises(InputError, match=r"pose 1 .*element 2 inside the magnet"):
        field_readings(sensor, [0, 0, -2, 0, 0])  # the magnet's centre lands on the element
    poses = np.zeros((5, 5))
    poses[3, 2] = -2.0
    with pytest.raises(InputError, match=r"pose 4 "):
        field_readings(sensor, poses)  # one bad pose among good ones is named


def test_element_on_magnet_surface_raises():
    """On the surface, including the edge circle where the field is singular, counts as inside."""
    with pytest.raises(InputError):
        field_readings(_probe_sensor([0.0, 0.0, 11.0]), [0, 0, -1.5, 0, 0])  # bottom face centre
    with pytest.raises(InputError):
        field_readings(_probe_sensor([3.0, 0.0, 11.0]), [0, 0, -1.5, 0, 0])  # on the edge circle
    with pytest.raises(InputError):
        field_readings(_probe_sensor([3.0, 0.0, 11.0]), [0, 0, -2, 0, 0])  # on the side wall
    # just below the bottom face is outside and gives a finite reading
    r = field_readings(_probe_sensor([3.0, 0.0, 11.0]), [0, 0, -1.4999, 0, 0])
    assert np.all(np.isfinite(r))


@pytest.mark.parametrize("bad", [
    [0, 0, 0, 0],  # 4 columns
    [[0, 0, 0, 0, 0, 0]],  # 6 columns
    [0, 0, float("nan"), 0, 0],
    [0, float("inf"), 0, 0, 0],
    np.zeros((2, 2, 5)),
])
def test_bad_poses_raise(paper, bad):
    with pytest.raises(InputError):
        field_readings(paper, bad)


def test_as_poses_shapes():
    assert as_poses([1, 2, 3, 4, 5]).shape == (1, 5)
    assert as_poses(np.zeros((7, 5))).shape == (7, 5)
