"""Capture schedules: the stage poses that pin a unit's parameters best (D-optimal).

Candidates are a grid over the axes the stage moves (the others stay 0) within the capture box and, when the
stage moves dz, the rest row: the indenter lifted REST_LIFT_MM above first contact, off the skin, where
the magnet rests whatever the rig's error (fitgen.physics.pose.contact_poses), so the row carries the
reading noise alone. The capture box is the sensor's travel (its file's ``[travel]``: how far a capture may
move the skin; the working pose box where it gives none) within the stage's limits: wider than the box the
estimator works in, since the field's shape over a longer lever pins the unit's geometry (the magnet's
height against the stage's gain) where the working box alone leaves it to the prior (bench/identify_bound.py).
Rows in contact stand no higher than fitgen.physics.pose.contact_top of the rig's and the zero's error: pressed
0.039 mm at the defaults (a 0.01 mm rig, a zero set by hand to 0.02 mm), where one capture in 17 lost a row at first
contact off the skin, its magnet read at rest; 0.094 mm on a printer's 0.03 mm.
A candidate that drives an element of the drawing past LINEAR_SHARE of its linear range (saturation, or the
ADC's rail) is left out: a unit within its tolerances reads up to about a fifth more there, and rows at the
kink leave the fit without a slope to follow (20 units' captures failed at 0.9 where none did at 0.8). Each
candidate's information about the unit's parameters (fitgen.fitting.identify.Problem, at the drawing, with
the rig's error) is a rank-N update of the prior's; poses are chosen greedily for the largest
log det of prior + information (by the matrix determinant lemma, an N x N determinant per
candidate), then improved by exchange passes (Fedorov): each chosen pose is swapped for the
candidate that raises the log det most, until no swap does. A pose may be chosen twice. The zero's error,
which identify allows for (one error shared by the rows in contact), couples the rows, so the design leaves
it out: rows add up, as the greedy step and the exchange need (bench/identify_bound.py gives the bound with
it).
"""

from __future__ import annotations

import json

import numpy as np

from fitgen.base.errors import InputError, check_seed, is_finite_number, is_whole_number, shown
from fitgen.base.fileio import write_all
from fitgen.fitting.capturecheck import MIN_DISTINCT, MIN_ROWS, check_error
from fitgen.fitting.identify import RIG_ERROR, ZERO_ERROR, Problem, unit_space
from fitgen.physics.dataset import meta_path
from fitgen.physics.pose import (POSE_NAMES, REST_LIFT_MM, contact_top, edge_margin, field_readings, inner_box,
                                 off_skin)
from fitgen.physics.sensor import TRAVEL_AXES, Sensor
from fitgen.physics.simulate import DEFAULT_RANGES
from fitgen.physics.transfer import LINEAR_SHARE, linear_top, missing_noise, within_linear_range

LEVELS = 9  # grid levels per moving axis
MAX_CANDIDATES = 20_000  # fewer levels where LEVELS ** axes would pass it (five axes: 7 levels, not 59,049 poses)
MAX_PASSES = 4
CHUNK = 2048  # candidates whose criterion is computed at once (bounds the memory: CHUNK x N x P numbers)


def levels_for(n_axes: int) -> int:
    """Grid levels per axis for ``n_axes`` moving axes: LEVELS, or the most (odd: the centre is a level) that
    keep the grid within MAX_CANDIDATES."""
    k = LEVELS
    while k > 3 and k ** n_axes > MAX_CANDIDATES:
        k -= 2
    return k


def candidates(axes: tuple[str, ...], ranges: dict) -> np.ndarray:
    """The grid of candidate poses over ``axes`` (others 0), :func:`levels_for` levels per axis; then the rest
    row (the stage lifted REST_LIFT_MM off the skin) when ``axes`` has dz."""
    k = levels_for(len(axes))
    levels = [np.linspace(*ranges[a], k) if a in axes else np.zeros(1) for a in POSE_NAMES]
    mesh = np.meshgrid(*levels, indexing="ij")
    grid = np.column_stack([m.ravel() for m in mesh])
    if "dz" not in axes:
        return grid
    return np.vstack([grid, [[0.0, 0.0, REST_LIFT_MM, 0.0, 0.0]]])


def checked_axes(axes, ranges: dict | None) -> tuple[str, ...]:
    """``axes`` as a tuple; InputError unless they are distinct pose names and ``ranges`` (the stage's limits) limit
    none of the others."""
    axes = tuple(axes)
    if not axes or any(a not in POSE_NAMES for a in axes) or len(set(axes)) != len(axes):
        raise InputError(f"--axes takes distinct names of {','.join(POSE_NAMES)}, got {','.join(axes) or 'none'}")
    unmoved = [a for a in (ranges or {}) if a not in axes]
    if unmoved:
        raise InputError(f"--limits gives {unmoved[0]}, which --axes ({','.join(axes)}) does not move")
    return axes


def capture_box(drawing: Sensor, axes, limits: dict | None = None, working: bool = False,
                rig_error: float = RIG_ERROR, zero_error: float = ZERO_ERROR) -> dict:
    """Per pose component, the range a capture's candidates span: for each of ``axes`` the sensor's travel (dx, dy,
    dz; the working box DEFAULT_RANGES where its file gives none, and for the tilts), or with ``working`` the
    working box alone, within the stage's ``limits``, dz in contact no higher than a stage of ``rig_error`` zeroed
    within ``zero_error`` keeps on the skin (fitgen.physics.pose.contact_top); the others 0. InputError for an axis
    the limits leave no room."""
    travel = DEFAULT_RANGES if working else {**DEFAULT_RANGES, **drawing.travel}
    box = {a: (0.0, 0.0) for a in POSE_NAMES}
    for a in axes:
        lim = (limits or {}).get(a, travel[a])
        lo, hi = max(lim[0], travel[a][0]), min(lim[1], travel[a][1])
        top = contact_top(rig_error, zero_error) if a == "dz" else hi
        if not lo < hi:
            what = "working pose box" if working else "travel" if a in TRAVEL_AXES else "pose box"
            raise InputError(f"the limits of {a} ({lim[0]:g}..{lim[1]:g}) leave it no room to move within the "
                             f"sensor's {what} ({travel[a][0]:g}..{travel[a][1]:g})")
        if not lo < top:
            raise InputError(f"the limits of dz ({lim[0]:g}..{lim[1]:g}) leave no row below {top:g} mm, where a stage "
                             f"off by {rig_error:g} mm rms, zeroed within {zero_error:g} mm, keeps the indenter on the "
                             "skin: allow a deeper press")
        hi = min(hi, top)
        box[a] = (lo, hi)
    return box


def capture_candidates(drawing: Sensor, axes=("dx", "dy", "dz"), limits: dict | None = None,
                       rig_error: float = RIG_ERROR, zero_error: float = ZERO_ERROR) -> tuple[np.ndarray, dict, int]:
    """The candidate poses of a capture (:func:`candidates` over :func:`capture_box`, the rest row kept) less those
    beyond the linear range (:func:`within_linear_range`); the box; how many were left out."""
    box = capture_box(drawing, axes, limits, rig_error=rig_error, zero_error=zero_error)
    cand = candidates(tuple(axes), box)
    linear, lifted = within_linear_range(drawing, cand), off_skin(cand)
    keep = linear | lifted
    if not np.any(linear & ~lifted):  # the rest rows alone, whatever the limits: the drawing saturates at rest
        rest = float(np.abs(field_readings(drawing, np.zeros((1, 5)))).max())
        raise InputError(f"every candidate pose drives an element of {drawing.name} past {100 * LINEAR_SHARE:g} % "
                         f"of its linear range (saturation {linear_top(drawing):g} mT; at rest it reads {rest:.3g} "
                         "mT): move the elements out or the magnet up, or check the sensor file's transfer")
    return cand[keep], box, int(np.sum(~keep))


def _logdet_gain(Finv: np.ndarray, J: np.ndarray) -> np.ndarray:
    """log det(I + J_c F^-1 J_c^T) for each candidate's whitened rows J_c (C, N, P)."""
    M = (J @ Finv) @ np.swapaxes(J, 1, 2) + np.eye(J.shape[1])
    return np.linalg.slogdet(M)[1]


def _chunked(gain, Finv: np.ndarray, J: np.ndarray) -> np.ndarray:
    """``gain(Finv, J)`` over CHUNK candidates at a time: the same numbers, in bounded memory."""
    return np.concatenate([gain(Finv, J[i:i + CHUNK]) for i in range(0, len(J), CHUNK)])


def exchange_design(J: np.ndarray, n: int, gain, progress=None) -> np.ndarray:
    """Indices of ``n`` candidates (repeats allowed), chosen greedily then by exchange passes for the largest
    ``gain(F^-1, J)`` (per candidate, what its rows J_c add to the criterion at information F = I + sum).
    ``progress(done, total, note)`` after each greedy pick and each pass."""
    def info(c):  # one candidate's information on demand (all at once: C x P x P numbers, gigabytes at five axes)
        return np.einsum("np,nq->pq", J[c], J[c])  # einsum, as the whole stack's: the same bits, the same ties

    F = np.eye(J.shape[2])
    chosen = []
    for i in range(n):
        c = int(np.argmax(_chunked(gain, np.linalg.inv(F), J)))
        chosen.append(c)
        F = F + info(c)
        if progress is not None:
            progress(i + 1, n + MAX_PASSES, "greedy")
    for p in range(MAX_PASSES):
        improved = False
        for slot in range(n):
            rest = F - info(chosen[slot])
            gains = _chunked(gain, np.linalg.inv(rest), J)
            c = int(np.argmax(gains))
            if c != chosen[slot] and gains[c] > gains[chosen[slot]] + 1e-9:
                chosen[slot], F, improved = c, rest + info(c), True
        if progress is not None:
            progress(n + p + 1, n + MAX_PASSES, "exchange")
        if not improved:
            if progress is not None:
                progress(n + MAX_PASSES, n + MAX_PASSES, "no swap raises it")
            break
    return np.array(chosen)


def d_optimal(J: np.ndarray, n: int, progress=None) -> tuple[np.ndarray, float]:
    """Indices of ``n`` candidates (repeats allowed) maximising log det(I + sum J_c^T J_c), and that log det."""
    chosen = exchange_design(J, n, _logdet_gain, progress)
    F = np.eye(J.shape[2]) + np.einsum("cnp,cnq->pq", J[chosen], J[chosen])
    return chosen, float(np.linalg.slogdet(F)[1])


def stage_order(poses: np.ndarray) -> np.ndarray:
    """Poses in the order a stage visits them: from the top (dz high) down, rows in a serpentine."""
    keys = np.lexsort((poses[:, 0], poses[:, 1], -poses[:, 2]))
    out = poses[keys]
    # serpentine in dx within each (dz, dy) row: fewer long moves
    rows = {}
    for i, p in enumerate(out):
        rows.setdefault((round(p[2], 6), round(p[1], 6)), []).append(i)
    order = []
    for r, (_, idx) in enumerate(rows.items()):
        order += idx if r % 2 == 0 else idx[::-1]
    return out[order]


def schedule(drawing: Sensor, n: int, *, axes=("dx", "dy", "dz"), ranges: dict | None = None,
             noise: float | None = None, rig_error: float = RIG_ERROR, zero_error: float = ZERO_ERROR,
             progress=None) -> tuple[np.ndarray, dict]:
    """``n`` stage poses (n, 5) that pin ``drawing``'s units best, within ``ranges`` (the stage's limits), the
    sensor's travel and its elements' linear range, in contact as a stage of ``rig_error`` zeroed within
    ``zero_error`` keeps it (:func:`capture_candidates`), and a record of how they were chosen.
    ``progress(done, total, note)``."""
    axes = checked_axes(axes, ranges)
    if not is_whole_number(n) or n < MIN_ROWS or n > 10000:
        raise InputError(f"--n must be a whole number {MIN_ROWS}..10000 (identify needs at least {MIN_ROWS} rows), "
                         f"got {shown(n)}")
    check_error("rig error", rig_error)
    check_error("zero error", zero_error)
    if noise is not None and not (is_finite_number(noise) and noise > 0):  # given: not the sensor file's to blame
        raise InputError(f"noise, the rows' reading noise, must be a finite number > 0, got {shown(noise)}")
    noise = drawing.noise if noise is None else noise
    if not noise > 0:
        raise InputError(f"the schedule needs the reading noise > 0: {missing_noise(drawing)}: add it to the file, "
                         "or give --noise (or --transfer, for the transfer whose noise the file gives)")
    space = unit_space(drawing)
    cand, ranges, beyond = capture_candidates(drawing, axes, ranges, rig_error, zero_error)
    total = n + MAX_PASSES + 1
    prob = Problem(space, np.zeros((len(cand), drawing.n_elements)), cand, np.full(drawing.n_elements, noise),
                   float(rig_error))
    z = np.zeros(space.size)

    def chunk(i: int) -> np.ndarray:  # the note moves with each chunk: five axes' candidates take tens of seconds
        if progress is not None:
            progress(0, total, f"candidates {i:,}/{len(cand):,}")
        return prob.whitened_rows(z, cand[i:i + CHUNK])

    try:
        J = np.concatenate([chunk(i) for i in range(0, len(cand), CHUNK)])
    except (np.linalg.LinAlgError, OverflowError):  # a row's covariance no longer positive definite in float
        raise InputError(f"the rows' reading noise, {noise:g} {drawing.units}, is too small against the rig error "
                         f"({rig_error:g} mm) to weigh them in floating point (sensor {drawing.name}'s per sample is "
                         f"{drawing.noise:g}): give --noise as a single sample's") from None
    if progress is not None:
        progress(1, total, "information")
    idx, logdet = d_optimal(J, n, None if progress is None else lambda i, m, note: progress(i + 1, total, note))
    distinct = len(np.unique(idx))
    if distinct < MIN_DISTINCT:
        loud = noise > 10 * drawing.noise > 0  # past the readings' spread, every pose tells as little as another
        raise InputError(f"the best {n} poses over {','.join(axes)} are {distinct} distinct ones; identify needs at "
                         f"least {MIN_DISTINCT}: " + (f"the rows' reading noise, {noise:g} {drawing.units}, is "
                                                      f"{noise / drawing.noise:.3g}x sensor {drawing.name}'s per "
                                                      "sample (a figure in other units?)" if loud else
                                                      "move more axes (--axes dx,dy,dz) or widen the limits"))
    poses = stage_order(cand[idx])
    info = {"criterion": "D-optimal (log det of the prior plus the capture's information, in prior spreads)",
            "log_det": logdet, "candidates": len(cand), "levels_per_axis": levels_for(len(axes)), "axes": list(axes),
            "ranges": {a: list(ranges[a]) for a in axes}, "noise": noise, "rig_error": rig_error,
            "zero_error": zero_error, "beyond_linear_range": beyond, "linear_share": LINEAR_SHARE,
            "sensor": drawing.name, "distinct_poses": int(distinct),
            "rest_rows": int(np.sum(off_skin(cand[idx]))), "rest_lift_mm": REST_LIFT_MM}
    return poses, info


CHECK_TRIES = 8  # random poses drawn per pose wanted, before those past the linear range are left out


def check_schedule(drawing: Sensor, n: int, *, axes=("dx", "dy", "dz"), ranges: dict | None = None,
                   seed: int = 0, rig_error: float = RIG_ERROR,
                   zero_error: float = ZERO_ERROR) -> tuple[np.ndarray, dict]:
    """``n`` random stage poses (n, 5) for a check capture (fitgen.fitting.check): uniform over the working pose
    box (DEFAULT_RANGES, where estimators are fitted and held out) within ``ranges`` (the stage's limits) in
    ``axes``, the others 0, in contact on a stage of ``rig_error`` zeroed within ``zero_error``
    (:func:`capture_box`), clear of the working box's edges by the margin fitgen check leaves there
    (fitgen.physics.pose.inner_box, for this zero and the calibration's, each set within ``zero_error``), and within
    the elements' linear range; and a record of how they were drawn.
    Random, not chosen: a check measures the estimator where it is used, not where it learns most."""
    axes = checked_axes(axes, ranges)
    if not (is_whole_number(n) and 1 <= n <= 10000):
        raise InputError(f"--check must be a whole number 1..10000 of poses, got {shown(n)}")
    check_seed(seed)
    check_error("rig error", rig_error)
    check_error("zero error", zero_error)
    box = capture_box(drawing, axes, ranges, working=True, rig_error=rig_error, zero_error=zero_error)
    zeros = float(np.hypot(zero_error, zero_error))  # this capture's zero and the calibration's, each set anew
    inner = inner_box(DEFAULT_RANGES, rig_error, zeros)
    for a in axes:
        lo, hi = max(box[a][0], inner[a][0]), min(box[a][1], inner[a][1])
        if not lo < hi:
            raise InputError(f"the limits of {a} leave no room in the working pose box ({DEFAULT_RANGES[a][0]:g}.."
                             f"{DEFAULT_RANGES[a][1]:g}) clear of its edges by the stage's error "
                             f"({edge_margin(rig_error, zeros):.2g} mm), where fitgen check reads no row")
        box[a] = (lo, hi)
    rng = np.random.default_rng(np.random.SeedSequence([seed, 0x636865636B]))
    cand = np.zeros((CHECK_TRIES * n, len(POSE_NAMES)))
    for a in axes:
        cand[:, POSE_NAMES.index(a)] = rng.uniform(*box[a], len(cand))
    cand = cand[within_linear_range(drawing, cand)][:n]
    if len(cand) < n:
        raise InputError(f"the working box drives {drawing.name}'s elements past {100 * LINEAR_SHARE:g} % of their "
                         "linear range almost everywhere: check the sensor file's transfer")
    return stage_order(cand), {"check": True, "seed": seed, "axes": list(axes), "sensor": drawing.name,
                               "ranges": {a: list(box[a]) for a in axes}, "linear_share": LINEAR_SHARE,
                               "rig_error": rig_error, "zero_error": zero_error,
                               "edge_margin": edge_margin(rig_error, zeros)}


def write_schedule(path, poses: np.ndarray, axes, info: dict) -> None:
    """The schedule (:func:`schedule_csv`) at ``path``, and ``info`` in its ``.meta.json`` beside it."""
    write_all([(path, schedule_csv(poses, axes)), (meta_path(path), json.dumps(info, indent=1) + "\n")])


def schedule_record(info: dict, drawing: Sensor, samples: int, **given) -> dict:
    """A schedule's meta as capture, identify and check read it back: how it was chosen (``info``), what the user
    gave (``given``), the samples per row it was made for, and the drawing's hash and transfer."""
    return {**info, **given, "samples_per_row": samples, "sensor_sha256": drawing.sha256,
            "transfer": drawing.transfer}


def schedule_csv(poses: np.ndarray, axes=("dx", "dy", "dz")) -> str:
    """The schedule as `tactile-host capture --poses` reads it: the moving axes' columns, numbers that round-trip."""
    names = [a for a in POSE_NAMES if a in axes]
    rows = [",".join(names)] + [",".join(repr(float(p[POSE_NAMES.index(a)]) + 0.0) for a in names) for p in poses]
    return "\n".join(rows) + "\n"
