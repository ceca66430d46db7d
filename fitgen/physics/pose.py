"""Rigid-body pose of the magnet and element readings for a batch of poses.

Pose = (dx, dy, dz, thx, thy): displacement from rest in mm, tilt in degrees,
R = Ry(thy) Rx(thx) about the magnet's own centre, rotation first, then translation.
"""

from __future__ import annotations

import itertools
import math

import numpy as np

from fitgen.base.errors import InputError, is_finite_number, shown
from fitgen.physics.field import cylinder_projection
from fitgen.physics.sensor import Sensor

POSE_NAMES = ("dx", "dy", "dz", "thx", "thy")
POSE_UNITS = ("mm", "mm", "mm", "deg", "deg")
# A stage's label with dz above this (mm above first contact) has lifted the indenter off the skin: the
# magnet rests whatever the rig's error. The margin is the skin's adhesion when the indenter just lifts.
OFF_SKIN_MM = 0.05
# A schedule's rows in contact stand this many stage errors (rms, mm: the rig's and the zero's together) below the
# adhesion's edge, so that the stage lifts about one row in 30,000 off the skin (at a printer's 0.03 mm and an exact
# zero: dz -0.07 instead of 0, where one in 20 lifted off and read the magnet at rest under a label that moves it; at
# 3, one in 700 did, and one of 20 100-pose captures in bench/units.py was refused for it; with a zero off by 0.02
# mm at a 0.01 mm rig, one capture in 17 lost a row at dz 0, one in 3,000 at -0.039).
HOLD_SIGMAS = 4.0
# Where a schedule's rest row lifts the stage (mm above first contact): clear of the adhesion with the rig's
# error, and with a capture's default approach (0.3 mm from above) within a stage limit of dz <= 0.5.
REST_LIFT_MM = 0.2
# How far a pose box may reach from rest (mm, deg). A metre away a magnet a few mm across gives the elements
# nothing to read (its field falls as 1/r^3), and a tilt past 180 deg repeats one within; beyond, the field's
# arithmetic overflows.
POSE_LIMITS = (1000.0, 1000.0, 1000.0, 180.0, 180.0)


def check_pose_range(name: str, lo: float, hi: float, origin: str) -> None:
    """InputError naming ``origin`` unless component ``name``'s range lo..hi is finite and within POSE_LIMITS."""
    limit = POSE_LIMITS[POSE_NAMES.index(name)]
    if not (math.isfinite(lo) and math.isfinite(hi) and -limit <= lo and hi <= limit):
        unit = POSE_UNITS[POSE_NAMES.index(name)]
        raise InputError(f"{origin}: {name} from {lo:g} to {hi:g} {unit}: a pose box's {name} must lie within "
                         f"-{limit:g}..{limit:g} {unit} (finite numbers)")


def check_pose_rows(poses: np.ndarray, origin: str) -> None:
    """:func:`check_pose_range` of each component over rows of ``poses`` (n, 5); none when there are no rows."""
    if len(poses):
        for name, lo, hi in zip(POSE_NAMES, np.min(poses, axis=0), np.max(poses, axis=0)):
            check_pose_range(name, float(lo), float(hi), origin)


def check_rows(readings, poses, what: str) -> tuple[np.ndarray, np.ndarray]:
    """``readings`` (n, N) and ``poses`` (n, 5) of ``what`` as float arrays; InputError (one line) unless they have
    those shapes with one pose per row and every value finite."""
    try:
        readings, poses = np.asarray(readings, dtype=float), np.asarray(poses, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{what}: the readings and poses must be arrays of numbers") from None
    if readings.ndim != 2 or poses.ndim != 2 or poses.shape[1] != len(POSE_NAMES):
        raise InputError(f"{what}: readings of shape {readings.shape} and poses of shape {poses.shape}; they must be "
                         f"(rows, elements) and (rows, {len(POSE_NAMES)}: {', '.join(POSE_NAMES)})")
    if len(readings) != len(poses):
        raise InputError(f"{what}: {len(readings)} rows of readings and {len(poses)} poses; one pose per row")
    for values, kind in ((readings, "reading"), (poses, "pose")):
        if not np.all(np.isfinite(values)):
            r, c = np.argwhere(~np.isfinite(values))[0]
            name = f"v{c + 1}" if kind == "reading" else POSE_NAMES[c]
            raise InputError(f"{what}: row {r + 1}'s {kind} {name} is {values[r, c]}: every value must be finite")
    return readings, poses


def pose_label(pose) -> str:
    """``dx=.. dy=.. dz=.. thx=.. thy=..`` for messages, each value to 10 significant digits."""
    return " ".join(f"{n}={float(v):.10g}" for n, v in zip(POSE_NAMES, pose))


def as_poses(poses) -> np.ndarray:
    """Check and return an (P, 5) float array of poses."""
    arr = np.asarray(poses, dtype=float)
    if arr.ndim == 1:
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] != 5:
        raise InputError(f"poses must have 5 columns {POSE_NAMES}, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise InputError("poses must be finite numbers")
    return arr


def rotation_matrices(thx_deg: np.ndarray, thy_deg: np.ndarray) -> np.ndarray:
    """R = Ry(thy) Rx(thx), shape (P, 3, 3)."""
    a = np.deg2rad(np.asarray(thx_deg, dtype=float))
    b = np.deg2rad(np.asarray(thy_deg, dtype=float))
    ca, sa, cb, sb = np.cos(a), np.sin(a), np.cos(b), np.sin(b)
    R = np.empty(a.shape + (3, 3))
    R[..., 0, 0] = cb
    R[..., 0, 1] = sb * sa
    R[..., 0, 2] = sb * ca
    R[..., 1, 0] = 0.0
    R[..., 1, 1] = ca
    R[..., 1, 2] = -sa
    R[..., 2, 0] = -sb
    R[..., 2, 1] = cb * sa
    R[..., 2, 2] = cb * ca
    return R


def off_skin(poses: np.ndarray) -> np.ndarray:
    """Mask of the stage labels (P, 5) that lift the indenter off the skin (dz > OFF_SKIN_MM)."""
    return np.asarray(poses)[:, 2] > OFF_SKIN_MM


def taken_lifted(poses: np.ndarray, rows) -> np.ndarray:
    """``poses`` (n, 5) with ``rows`` lifted to REST_LIFT_MM, where a schedule's rest rows stand: rows that the stage
    lifted past the skin's adhesion whatever their labels say read the magnet at rest, as those do."""
    out = np.array(poses, dtype=float)
    out[list(rows), 2] = REST_LIFT_MM
    return out


def lifted_zero(poses: np.ndarray, rows) -> float:
    """How far above first contact (mm) a capture's zero sits for its stage to have lifted ``rows`` of ``poses`` (n,
    5), labelled in contact, past the skin's adhesion: OFF_SKIN_MM above the deepest of them, the rig's error aside."""
    return OFF_SKIN_MM - float(np.min(np.asarray(poses)[list(rows), 2]))


def contact_top(rig_error: float, zero_error: float = 0.0) -> float:
    """The highest dz (mm) a scheduled row in contact takes on a stage with ``rig_error`` mm rms per axis whose zero
    is off first contact by ``zero_error`` mm rms per axis: first contact (0), or lower where the two would lift it
    past the skin's adhesion (OFF_SKIN_MM) within HOLD_SIGMAS; to the micrometre, as a stage takes it."""
    return min(0.0, round(OFF_SKIN_MM - HOLD_SIGMAS * math.hypot(rig_error, zero_error), 3))


def inner_box(box: dict, rig_error: float, zero_error: float = 0.0) -> dict:
    """``box`` ({pose name: (low, high)}) less HOLD_SIGMAS stage errors (``rig_error`` and ``zero_error``, mm rms per
    axis, together) at each edge a stage's error can carry a row in contact past: dx's and dy's both, dz's floor,
    and dz's top by no more than it lies below first contact (above it the indenter lifts and the magnet rests, so a
    row carried up reaches first contact at most). A row labelled inside stays in ``box`` but for about one in 30,000
    per edge; a box the margins close is returned with low above high. The margin is :func:`edge_margin`'s."""
    margin = edge_margin(rig_error, zero_error)
    out = dict(box)
    for name in ("dx", "dy", "dz"):
        if name in box and box[name][0] != box[name][1]:  # a held component's rows lie at its value, not inside it
            lo, hi = box[name]
            top = min(margin, max(-hi, 0.0)) if name == "dz" else margin  # random poses' top: a hair below 0
            out[name] = (round(lo + margin, 6), hi if top == 0 else round(hi - top, 6))
    return out


def within_box(poses: np.ndarray, box: dict) -> np.ndarray:
    """Per row, whether its pose ``poses`` (n, 5) lie in ``box`` ({pose name: (low, high)}; a bound's last bits
    given)."""
    inside = np.ones(len(poses), bool)
    for name, (lo, hi) in box.items():
        if name in POSE_NAMES:
            v, slack = poses[:, POSE_NAMES.index(name)], 1e-9 * max(abs(lo), abs(hi), 1.0)
            inside &= (v >= lo - slack) & (v <= hi + slack)
    return inside


def box_problem(box) -> str:
    """What makes ``box`` no pose box ({pose name: [low, high]}, finite, low <= high), or '' when it is one."""
    if not isinstance(box, dict) or not box:
        return f"must be pose ranges {{name: [low, high]}}, got {shown(box)}"
    for name, pair in box.items():
        ok = (isinstance(pair, list) and len(pair) == 2
              and all(map(is_finite_number, pair)))  # an integer past float's range too (JSON holds any)
        if name not in POSE_NAMES or not ok or pair[0] > pair[1]:
            return (f"must be pose ranges {{name: [low, high]}} ({', '.join(POSE_NAMES)}), got {name!r:.20}: "
                    f"{shown(pair)}")
    return ""


def edge_margin(rig_error: float, zero_error: float = 0.0) -> float:
    """HOLD_SIGMAS stage errors (mm rms per axis, the rig's and the zero's together), up to the micrometre, as a
    stage takes it."""
    return math.ceil(round(1000 * HOLD_SIGMAS * math.hypot(rig_error, zero_error), 6)) / 1000


def lift_odds(dz: float, rig_error: float, zero_error: float = 0.0) -> float:
    """The chance that a stage off by ``rig_error`` mm rms, zeroed ``zero_error`` mm rms off first contact, lifts a
    row labelled at ``dz`` (mm, in contact) past the skin's adhesion (OFF_SKIN_MM)."""
    sd = math.hypot(rig_error, zero_error)
    if sd <= 0:
        return float(dz > OFF_SKIN_MM)
    return 0.5 * math.erfc((OFF_SKIN_MM - dz) / (sd * math.sqrt(2.0)))


def pressed(shift: np.ndarray, stiffening) -> np.ndarray:
    """Stage displacements (..., 3) as they reach the magnet of an elastomer that stiffens: a press (dz < 0)
    shortened by ``stiffening`` (1/mm, per unit: broadcast against shift[..., 0]) times its depth."""
    dz = shift[..., 2]
    out = np.array(shift, dtype=float)
    out[..., 2] = dz * (1.0 - np.asarray(stiffening) * np.abs(np.minimum(dz, 0.0)))
    return out


def contact_poses(poses: np.ndarray) -> np.ndarray:
    """Stage labels (P, 5) as the magnet feels them: a row off the skin is the rest pose."""
    return np.where(off_skin(poses)[:, None], 0.0, poses)


def magnet_frame(sensor: Sensor, poses: np.ndarray, touching: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Element positions and axes in the magnet's own frame, each (P, N, 3).

    For a built unit (fitgen.physics.units) the pose's displacement is the stage's: the magnet moves by
    ``stage_map @ (dx, dy, dz)``, a press shortened by the elastomer's stiffening (:func:`pressed`); its tilt is
    the pose's applied after the unit's rest tilt. On a drawing and a unit alike a label off the skin
    (:func:`contact_poses`) leaves it at rest, unless ``touching`` says every pose is in contact (a simulated rig
    that decided it on the tool's own height).
    """
    given = as_poses(poses)
    centre, R = _placed(sensor, given, touching)
    rel = sensor.positions[None, :, :] - centre[:, None, :]
    # R^T v for every pose and element: local = rel @ R
    local = np.einsum("pnj,pjk->pnk", rel, R)
    axes = np.einsum("nj,pjk->pnk", sensor.axes, R)
    return local, axes


def check_above_board(sensor: Sensor, poses, name: str | None = None) -> np.ndarray:
    """The magnet's centre (P, 3) at each pose; InputError for the first pose that puts any part of the magnet
    (its tilt included) on or below the board's top face (z = the board's thickness: the frame's origin is the
    centre of the board's bottom face): the magnet would be in or through the board. ``name`` calls the pose
    what the user gave (an option) where there is one pose, in place of "pose 1"."""
    return _placed(sensor, as_poses(poses), name=name)[0]


def lowest_point(sensor: Sensor, centre: np.ndarray, R: np.ndarray) -> np.ndarray:
    """z (P,) of the magnet's lowest point: its centre less the bottom rim's drop, R being its rotation."""
    m = sensor.magnet
    return centre[:, 2] - m.diameter / 2 * np.hypot(R[:, 2, 0], R[:, 2, 1]) - m.height / 2 * np.abs(R[:, 2, 2])


def board_clearance(sensor: Sensor, poses) -> np.ndarray:
    """How far (mm, P) the magnet's lowest point is above the board's top face at each pose; <= 0: into it."""
    centre, R = _unchecked(sensor, as_poses(poses))
    return lowest_point(sensor, centre, R) - sensor.board_thickness


def check_box(sensor: Sensor, ranges: dict, origin: str) -> None:
    """InputError when the pose box ``ranges`` takes the magnet into the board (at its lowest corner), said of the
    box the user gave rather than of a pose drawn in it."""
    corners = np.array(list(itertools.product(*[ranges[n] for n in POSE_NAMES])), dtype=float)
    clear = board_clearance(sensor, corners)
    if np.all(clear > 0):
        return
    worst = corners[int(np.argmin(clear))]
    room = float(board_clearance(sensor, np.zeros((1, 5)))[0])
    raise InputError(f"{origin}: the pose box reaches the board: at its corner {pose_label(worst)} the magnet's lowest "
                     f"point is {-clear.min():.3g} mm into it (at rest it is {room:.3g} mm above the board's top face): "
                     "narrow the box's dz (or tilt) range")


def _unchecked(sensor: Sensor, given: np.ndarray, touching: bool = False) -> tuple[np.ndarray, np.ndarray]:
    moved = given if touching else contact_poses(given)  # a drawing too: no indenter lifts the magnet
    shift = moved[:, :3] if sensor.is_drawing else pressed(moved[:, :3], sensor.stiffening) @ sensor.stage_map.T
    centre = np.asarray(sensor.magnet.rest_center) + shift
    R = rotation_matrices(moved[:, 3], moved[:, 4])
    if any(sensor.magnet.tilt):
        R = R @ rotation_matrices(*sensor.magnet.tilt)
    return centre, R


def _placed(sensor: Sensor, given: np.ndarray, touching: bool = False,
            name: str | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The magnet's centre (P, 3) and rotation (P, 3, 3) at the given poses, checked as
    :func:`check_above_board` says."""
    centre, R = _unchecked(sensor, given, touching)
    low = lowest_point(sensor, centre, R)
    bad = np.flatnonzero(low <= sensor.board_thickness)
    if bad.size:
        p = int(bad[0])
        pose = pose_label(given[p])
        rest = sensor.magnet.rest_center[2] - sensor.board_thickness
        raise InputError(f"{name or f'pose {p + 1}'} ({pose}) puts the magnet's lowest point at z = {low[p]:g} mm, "
                         f"on or below the board's top face (z = {sensor.board_thickness:g} mm; at rest the magnet's centre is "
                         f"{rest:g} mm above it): the magnet would be in or through the board")
    return centre, R


def inside_magnet(sensor: Sensor, local: np.ndarray) -> np.ndarray:
    """Mask (P, N) of element positions that lie inside or on the magnet."""
    r = np.hypot(local[..., 0], local[..., 1])
    return (r <= sensor.magnet.diameter / 2) & (np.abs(local[..., 2]) <= sensor.magnet.height / 2)


def field_readings(sensor: Sensor, poses, touching: bool = False) -> np.ndarray:
    """Signed B . axis_k in mT at every element for every pose, shape (P, N); ``touching``: see
    :func:`magnet_frame`."""
    poses = as_poses(poses)
    local, axes = magnet_frame(sensor, poses, touching)
    bad = inside_magnet(sensor, local)
    if np.any(bad):
        p, k = np.argwhere(bad)[0]
        raise InputError(f"pose {p + 1} {poses[p].tolist()} puts element {k + 1} inside the magnet")
    mag = sensor.magnet
    out = cylinder_projection(
        local.reshape(-1, 3), axes.reshape(-1, 3), mag.diameter, mag.height, mag.polarization * 1e3
    ).reshape(local.shape[:2])
    if np.any(sensor.ambient):
        out = out + sensor.axes @ sensor.ambient  # a uniform field, the same at every pose
    return out
