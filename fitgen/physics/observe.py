"""Observability: the Jacobian of readings by pose, its singular values, and Cramer-Rao bounds."""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from fitgen.base.errors import InputError, is_finite_number, shown
from fitgen.physics.pose import (POSE_NAMES, POSE_UNITS, as_poses, board_clearance, check_above_board, check_box,
                                 check_pose_range, field_readings, pose_label)
from fitgen.physics.sensor import Sensor
from fitgen.physics.transfer import apply_transfer, missing_noise, past_linear, step_rms

# central-difference steps (mm, deg): small against the field's length scale (mm),
# large against rounding (readings ~1 mT, eps ~1e-16)
_STEP = np.array([1e-4, 1e-4, 1e-4, 1e-3, 1e-3])


def jacobian(sensor: Sensor, poses) -> np.ndarray:
    """d reading / d pose, shape (P, N, 5); pose in mm and deg, readings in the transfer's units.

    The transfer is taken without noise or quantisation (the ideal response).
    """
    poses = as_poses(poses)
    check_above_board(sensor, poses)  # here, so that a refusal names the pose, not one of its probes
    P = len(poses)
    shifts = np.concatenate([np.diag(_STEP), -np.diag(_STEP)])  # (10, 5)
    probe = (poses[:, None, :] + shifts[None]).reshape(-1, 5)
    into = np.flatnonzero(board_clearance(sensor, probe) <= 0)
    if into.size:  # a pose a hair above the board: its differences would reach into it
        p = int(into[0]) // len(shifts)
        pose = pose_label(poses[p])
        raise InputError(f"pose {p + 1} ({pose}) puts the magnet within {_STEP[2]:g} mm (or {_STEP[3]:g} deg) of "
                         "the board's top face: the Jacobian's differences there would reach into the board; keep "
                         "the box further above it")
    vals = apply_transfer(sensor, field_readings(sensor, probe), adc_bits=0).reshape(P, 10, -1)
    # adc_bits=0: no quantisation steps, but the gmr output is still clipped to the ADC range
    return ((vals[:, :5] - vals[:, 5:]) / (2 * _STEP[None, :, None])).transpose(0, 2, 1)


@dataclass
class PoseObservability:
    pose: np.ndarray  # (5,)
    singular_values: np.ndarray  # (5,) descending
    directions: np.ndarray  # (5, 5) rows: right singular vectors (pose directions)
    bounds: np.ndarray  # (5,) Cramer-Rao standard deviation per component
    past_linear: int = 0  # elements whose reading no longer follows the field here (saturated, on a rail)


NULL_SHARE = 1e-6  # a component whose unit vector has more than this in the readings' null space is not seen
# A singular value below this share of the largest is zero: the central differences' rounding leaves the directions
# a symmetric layout cannot see at 1e-12..1e-11 of it (the paper's ring at rest: 2.2e-11), which read as seen at
# 1e-12 and gave bounds of 1e5 mm or inf by the luck of the rounding; a direction seen at 1e-9 bounds 1e6 noise/s.
ZERO_SHARE = 1e-9


def _svd_bounds(J: np.ndarray, noise: float):
    """Batched SVD of J (P, N, C) and the Cramer-Rao standard deviations (P, C): inf for a component with a share
    in the null space of J (where J^T J is singular); the others by the pseudo-inverse, which a component clear of
    that space is bounded by (a symmetric ring at rest cannot tell a slide from a tilt, yet sees a press)."""
    # full V: with fewer readings than components its last rows are the directions the readings cannot see
    _, s, vt = np.linalg.svd(J, full_matrices=True)
    k = s.shape[1]
    seen = s > s[:, :1] * ZERO_SHARE  # (P, k): the singular values that are not zero in floating point
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # a bound past float's range is inf
        # (J^T J)^+ = V diag(1/s^2) V^T over the seen directions, without forming J^T J
        terms = np.where(seen[:, None, :], (vt[:, :k].transpose(0, 2, 1) / s[:, None, :]) ** 2, 0.0)
        bounds = noise * np.sqrt(np.sum(terms, axis=2))
    # the unseen rows of V: those of zero singular values, and with fewer readings than components the rest
    unseen = np.concatenate([~seen, np.ones((len(J), J.shape[2] - k), dtype=bool)], axis=1)
    share = np.sqrt(np.sum(np.where(unseen[:, :, None], vt, 0.0) ** 2, axis=1))  # (P, C)
    bounds[share > NULL_SHARE] = np.inf
    full_s = np.zeros((len(J), J.shape[2]))
    full_s[:, : s.shape[1]] = s
    return full_s, vt, bounds


def cramer_rao(sensor: Sensor, poses, noise: float, components: tuple[str, ...] = POSE_NAMES) -> np.ndarray:
    """Cramer-Rao standard deviation per pose and component, shape (P, C), for Gaussian noise of rms ``noise``."""
    cols = [POSE_NAMES.index(c) for c in components]
    return _svd_bounds(jacobian(sensor, poses)[:, :, cols], noise)[2]


def analyse(sensor: Sensor, poses, noise: float, components: tuple[str, ...] = POSE_NAMES) -> list[PoseObservability]:
    """SVD and Cramer-Rao bound per pose for Gaussian element noise of rms ``noise``.

    Only ``components`` are estimated; the others are taken as known (held fixed).
    The bound is sqrt(diag((J^T J)^-1)) * noise; infinite where J^T J is singular.
    """
    poses = as_poses(poses)
    cols = [POSE_NAMES.index(c) for c in components]
    s, vt, bounds = _svd_bounds(jacobian(sensor, poses)[:, :, cols], noise)
    clipped = past_linear(sensor, field_readings(sensor, poses)).sum(axis=1)
    return [PoseObservability(p, s[i], vt[i], bounds[i], int(clipped[i])) for i, p in enumerate(poses)]


def corner_poses(ranges: dict) -> np.ndarray:
    """Rest (all zero, clipped into the box) followed by every corner of the pose box (unique)."""
    rest = np.array([min(max(0.0, ranges[n][0]), ranges[n][1]) for n in POSE_NAMES])
    corners = {tuple(c) for c in itertools.product(*[sorted(set(ranges[n])) for n in POSE_NAMES])}
    corners.discard(tuple(rest))
    return np.vstack([rest] + [np.array(c) for c in sorted(corners)])


def describe_direction(vec: np.ndarray, components: tuple[str, ...]) -> str:
    """A pose direction in words: its largest parts, e.g. '0.71 dy - 0.70 thx'."""
    order = np.argsort(-np.abs(vec))
    sign = 1.0 if vec[order[0]] >= 0 else -1.0
    parts = []
    for j in order[:3]:
        if abs(vec[j]) < 1e-4:
            continue
        val = sign * vec[j]
        parts.append(f"{'-' if val < 0 else '+'} {abs(val):.2g} {components[j]}")
    text = " ".join(parts)
    return text[2:] if text.startswith("+ ") else text


def units_of(components) -> list[str]:
    return [POSE_UNITS[POSE_NAMES.index(c)] for c in components]


DEFAULT_ACCURACY = {"dx": 0.1, "dy": 0.1, "dz": 0.1, "thx": 1.0, "thy": 1.0}


@dataclass
class ObserveReport:
    components: tuple[str, ...]
    noise: float
    units: str
    accuracy: dict
    results: list[PoseObservability]
    inside: int = 0  # the last results: random poses inside the box (judged, not tabled)
    n_elements: int = 0
    lsb: float = 0.0  # the ADC's step; its rounding, lsb / sqrt(12), is part of ``noise``
    element_noise: float = 0.0
    scenes: tuple = ()  # (name, outputs) of the scenes to point a sensor of too few elements at

    @property
    def worst(self) -> np.ndarray:
        return np.max([r.bounds for r in self.results], axis=0)

    def unresolved(self) -> list[str]:
        return [c for c, w in zip(self.components, self.worst) if not w <= self.accuracy[c]]

    def table(self) -> str:
        comps = self.components
        single = len(comps) == 1  # one singular value: no second smallest to table
        head = (["pose (dx dy dz thx thy)", "s_min"] + ([] if single else ["s_2nd"])
                + [f"{c} [{u}]" for c, u in zip(comps, units_of(comps))])
        rows = []
        for r in self.results[:len(self.results) - self.inside]:
            pose = " ".join(f"{v:g}" for v in r.pose)
            s = sorted(r.singular_values)
            rows.append([pose] + [f"{v:.3g}" for v in s[:1 if single else 2]] + [_fmt_bound(b) for b in r.bounds])
        widths = [max(len(h), *(len(row[i]) for row in rows)) for i, h in enumerate(head)]
        lines = ["  ".join(h.ljust(w) for h, w in zip(head, widths))]
        lines.append("  ".join("-" * w for w in widths))
        lines += ["  ".join(c.ljust(w) for c, w in zip(row, widths)) for row in rows]
        return "\n".join(lines)

    def examined(self) -> str:
        """The tabled poses in words: 'at rest and every corner', or for a box that leaves rest out 'at the
        box's pose nearest rest (dx=1 ...) and every corner' (the first result: corner_poses moves rest in)."""
        first = self.results[0].pose
        corners = len(self.results) - self.inside > 1
        if not np.any(first):
            return "at rest and every corner" if corners else "at rest"
        nearest = pose_label(first)
        return f"at the box's pose nearest rest ({nearest})" + (" and every corner" if corners else "")

    def verdicts(self) -> list[str]:
        """One sentence per component: resolvable or not, and where it fails."""
        out = []
        for j, c in enumerate(self.components):
            unit = units_of([c])[0]
            need = self.accuracy[c]
            bad = [r for r in self.results if not r.bounds[j] <= need]
            worst = self.worst[j]
            if not bad:
                out.append(f"{c}: resolvable: Cramer-Rao bound at most {worst:.3g} {unit} "
                           f"(required {need:g} {unit}) {self.examined()}"
                           + (f", and at {self.inside} random poses inside the box." if self.inside else "."))
                continue
            r = max(bad, key=lambda b: b.bounds[j])  # the worst pose, as the table's worst column
            where = "at rest" if np.all(r.pose == 0) else f"at {' '.join(f'{v:g}' for v in r.pose)}"
            # the pose direction that contributes most to this component's bound
            weight = np.abs(r.directions[:, j]) / np.maximum(r.singular_values, 1e-300)
            blind = describe_direction(_blind_direction(r, j, int(np.argmax(weight))), self.components)
            # a reading that stopped following the field is why, more often than the layout's geometry
            why = (f"; {r.past_linear} of {self.n_elements} elements there are past their linear range, saturated "
                   "or on the ADC's rails" if r.past_linear else "")
            if 0 < self.n_elements < len(self.components):
                fits = [f"--scene {n}" for n, k in self.scenes if k <= self.n_elements]
                why += (f"; {self.n_elements} readings cannot pin {len(self.components)} pose components at once: "
                        f"a scene of at most {self.n_elements} outputs ({', '.join(fits + ['a scene file'])})")
            msg = (f"{c}: NOT resolvable to {need:g} {unit} at {len(bad)} of {len(self.results)} poses "
                   f"(bound {_fmt_bound(r.bounds[j])} {unit} {where}; the readings barely change along {blind}"
                   f"{why}).")
            out.append(msg)
        return out

    def text(self) -> str:
        noise = f"element noise {self.noise:g} {self.units} rms" if not self.lsb else (
            f"reading noise {self.noise:.3g} {self.units} rms (element noise {self.element_noise:g} and the ADC's "
            f"{self.lsb:.3g} {self.units} steps, {self.lsb / np.sqrt(12):.3g} rms)")
        head = (f"Observability: {noise}; bounds are 1-sigma "
                f"Cramer-Rao limits with {', '.join(self.components)} estimated "
                f"{'jointly' if len(self.components) > 1 else 'alone'}.\n"
                f"Singular values of d(readings)/d(pose) in {self.units} per mm or per deg.\n")
        return head + "\n" + self.table() + "\n\n" + "\n".join(self.verdicts()) + "\n"


def _fmt_bound(b: float) -> str:
    return "inf" if not np.isfinite(b) or b > 1e6 else f"{b:.3g}"


def _blind_direction(r, j: int, k: int) -> np.ndarray:
    """The direction along which component ``j`` is blind at result ``r``: singular direction ``k``, or where other
    singular values lie within 10x of its own (at rest the paper ring has two, 1e-11 each, and any mix of them is a
    singular direction) the direction of their span that moves ``j`` most, so that it names what ``j`` is confused
    with rather than an arbitrary mix."""
    s = r.singular_values
    near = np.flatnonzero((s <= 10 * s[k]) & (s >= s[k] / 10))
    if len(near) < 2:
        return r.directions[k]
    span = r.directions[near]
    v = span.T @ span[:, j]
    return v / np.linalg.norm(v)


def observe(sensor: Sensor, ranges: dict, components=POSE_NAMES, noise: float | None = None,
            accuracy: dict | None = None, scenes: tuple = ()) -> ObserveReport:
    """Observability at rest, at the corners of the pose box ``ranges`` and at INSIDE random poses within it (a
    layout can be blind inside the box where it sees at every corner: a saturating element, say). ``scenes``:
    (name, number of outputs) of the scenes a verdict may point a sensor of too few elements at."""
    from fitgen.physics.simulate import pose_rng, random_poses

    # -0.01 had been taken as 0.01; 0 is fit --noise 0's (the paper's procedure), its scene checked without noise
    if noise is not None and not (is_finite_number(noise) and noise >= 0):
        raise InputError(f"noise must be a number >= 0 (one sample's, in the sensor's units), got {noise!r:.40}")
    if noise is None and not sensor.noise > 0:  # a file without one reads 0: every bound would be 0
        raise InputError(f"{missing_noise(sensor)}: add it to the file, or give --noise; without noise every pose "
                         "component is resolved to 0, resolvable or not")
    bad = [c for c in components if c not in POSE_NAMES]
    if not components or bad or len(set(components)) != len(components):
        raise InputError(f"observe takes the pose components to estimate, each once, from {', '.join(POSE_NAMES)}; "
                         f"got {', '.join(map(str, components)) or 'none'}")
    for name in POSE_NAMES:
        if name not in ranges:
            raise InputError(f"observe's pose box gives no range for {name}: give every one of {', '.join(POSE_NAMES)} "
                             "(fitgen.physics.simulate.DEFAULT_RANGES holds the default box)")
        lo, hi = ranges[name]
        if not lo <= hi:
            raise InputError(f"observe's pose box gives {name} from {lo:g} to {hi:g}: lo must not exceed hi")
        check_pose_range(name, lo, hi, "observe")
    check_box(sensor, ranges, "observe")
    if accuracy is not None and not isinstance(accuracy, dict):  # one figure for all: which unit, mm or deg?
        raise InputError(f"accuracy is a dict of pose components' figures, e.g. {{'dz': 0.05}}, got {shown(accuracy)}")
    bad = next((c for c, v in (accuracy or {}).items() if not (is_finite_number(v) and v > 0)), None)
    if bad is not None:  # the command's --accuracy says as much; a notebook's -1 had read as 'NOT resolvable to -1'
        raise InputError(f"accuracy {bad} must be a finite number > 0, got {shown(accuracy[bad])}")
    extra = [c for c in (accuracy or {}) if c not in components]
    if extra:  # it would be ignored: say so rather than judge without it
        raise InputError(f"an accuracy is asked for {extra[0]}, which is not among the outputs estimated "
                         f"({','.join(components)}): give the scene that estimates it, or leave it out")
    element = sensor.noise if noise is None else noise
    # the ADC's rounding is noise the readings carry too: a coarse converter (or volts typed as millivolts)
    # bounds what they resolve more than the elements do
    lsb, step = step_rms(sensor)
    noise = float(np.hypot(element, step))
    acc = dict(DEFAULT_ACCURACY)
    acc.update(accuracy or {})
    poses = np.vstack([corner_poses(ranges), random_poses(INSIDE, ranges, pose_rng(INSIDE_SEED))])
    results = analyse(sensor, poses, noise, tuple(components))
    return ObserveReport(tuple(components), noise, sensor.units, acc, results, INSIDE, sensor.n_elements, lsb,
                         element, tuple(scenes))


INSIDE, INSIDE_SEED = 200, 11
