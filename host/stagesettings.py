"""What a stage run is set to: which machine axis moves which pose axis, the soft limits, the approach, the feed.

``AxisMap`` is the signed axis map (``--stage-axes``); ``StageSettings`` holds it
with the soft limits in mm from the zero (``--stage-limits``), the point every pose
is approached from (``--stage-approach``) and the feed, and checks a whole schedule
against them before anything is sent.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

import numpy as np

from fitgen.base.errors import InputError
from fitgen.physics.pose import POSE_NAMES
from fitgen.physics.sensor import TRAVEL_MAX

from host.gcode import MACHINE_AXES

STAGE_AXES = ("dx", "dy", "dz")  # what a 3-axis stage can set; thx, thy need a tilt stage
MAX_LIMIT_MM = 2 * TRAVEL_MAX  # soft limits past this, from the zero, guard nothing a capture moves to


@dataclass(frozen=True)
class AxisMap:
    """Machine axis -> (pose axis, sign): pose component = sign * machine displacement."""

    pairs: tuple  # ((machine axis, pose axis, sign), ...)

    @classmethod
    def parse(cls, spec: str, flag: str = "--stage-axes") -> "AxisMap":
        what = f"{flag} {spec!r}"
        pairs, seen_m, seen_p = [], set(), set()
        for part in spec.replace(";", ",").split(","):
            part = part.strip()
            if not part:
                continue
            m = re.fullmatch(r"([XYZxyz])\s*=\s*([+-]?)\s*(dx|dy|dz)", part)
            if not m:
                raise InputError(f"{what}: {part!r} is not MACHINE=[-]POSE with MACHINE in X,Y,Z and POSE in "
                                 "dx,dy,dz (e.g. X=dx,Y=-dy,Z=dz)")
            ma, pa = m.group(1).upper(), m.group(3)
            if ma in seen_m or pa in seen_p:
                raise InputError(f"{what}: {ma if ma in seen_m else pa} appears twice")
            seen_m.add(ma)
            seen_p.add(pa)
            pairs.append((ma, pa, -1 if m.group(2) == "-" else 1))
        if not pairs:
            raise InputError(f"{what}: no axis")
        return cls(tuple(sorted(pairs)))

    def __str__(self) -> str:
        return ",".join(f"{m}={'-' if s < 0 else ''}{p}" for m, p, s in self.pairs)

    @property
    def pose_axes(self) -> tuple[str, ...]:
        return tuple(p for _, p, _ in self.pairs)

    def to_machine(self, zero: dict[str, float], d: np.ndarray) -> dict[str, float]:
        """Machine targets for the pose displacement ``d`` (dx, dy, dz) from ``zero``."""
        return {m: zero[m] + s * float(d[STAGE_AXES.index(p)]) for m, p, s in self.pairs}

    def to_pose(self, zero: dict[str, float], machine: np.ndarray) -> np.ndarray:
        d = np.zeros(3)
        for m, p, s in self.pairs:
            d[STAGE_AXES.index(p)] = s * (machine[MACHINE_AXES.index(m)] - zero[m])
        return d


def parse_ranges(spec: str, what: str) -> dict[str, tuple[float, float]]:
    """``dx=-3:3,dz=-2:0.5`` (or separated by spaces, as ``fitgen schedule --limits``) -> {axis: (lo, hi)} over
    dx, dy, dz."""
    out = {}
    for part in re.split(r"[,;]|\s+(?=[A-Za-z]\w*\s*=)", spec):
        part = part.strip()
        if not part:
            continue
        name, sep, rng = part.partition("=")
        lo, sep2, hi = rng.partition(":")
        try:
            lo_v, hi_v = float(lo), float(hi)
        except ValueError:
            lo_v = hi_v = math.nan
        if (not sep or not sep2 or name.strip() not in STAGE_AXES or not (lo_v < hi_v)
                or not (math.isfinite(lo_v) and math.isfinite(hi_v))):
            raise InputError(f"{what} {spec!r}: expected AXIS=LO:HI (mm, finite, LO < HI) for AXIS in dx,dy,dz, "
                             "e.g. dx=-3.5:3.5,dy=-3.5:3.5,dz=-3.5:0.5")
        if name.strip() in out:
            raise InputError(f"{what} {spec!r}: {name.strip()} is given twice")
        if max(-lo_v, hi_v) > MAX_LIMIT_MM:  # a safety box a metre wide keeps no indenter off anything
            raise InputError(f"{what} {spec!r}: {name.strip()} must lie within +-{MAX_LIMIT_MM:g} mm of the zero "
                             f"(no sensor's travel reaches past {TRAVEL_MAX:g} mm from first contact)")
        out[name.strip()] = (lo_v, hi_v)
    return out


APPROACH = "dx=-0.3,dy=-0.3,dz=0.3"  # every pose from -dx, -dy and above: the last move presses into the skin


def parse_approach(spec: str) -> np.ndarray:
    """``dx=-0.3,dy=-0.3,dz=0.3`` -> where the last move to a pose starts from, relative to it (mm); every axis
    named (``dz=0.4`` once set the others to 0, turning their backlash compensation off unsaid)."""
    from fitgen.base.parse import parse_assignments

    vals = parse_assignments(spec, STAGE_AXES, "--stage-approach")
    if missing := [a for a in STAGE_AXES if a not in vals]:
        raise InputError(f"--stage-approach {spec!r} leaves out {', '.join(missing)}: give every axis (0 turns one's "
                         f"backlash compensation off; default {APPROACH})")
    d = np.array([vals[a] for a in STAGE_AXES])
    if not np.all(np.isfinite(d)) or np.any(np.abs(d) > 10):
        raise InputError(f"--stage-approach {spec!r}: each distance within -10..10 mm")
    dz = d[STAGE_AXES.index("dz")] if "dz" in STAGE_AXES else 0.0
    if dz < 0:  # from below, every row would first press deeper than its pose and read the skin as it relaxes
        raise InputError(f"--stage-approach {spec!r}: dz={dz:g} starts each pose's last move {-dz:g} mm deeper than "
                         "the pose, pressing into the skin past it; approach dz from above (dz > 0), or give dz=0")
    return d


@dataclass
class StageSettings:
    axes: AxisMap
    limits: dict  # pose axis -> (lo, hi) mm, from the zero
    feed: float = 600.0  # mm/min
    approach: np.ndarray = field(default_factory=lambda: parse_approach(APPROACH))
    jog_max: float = 5.0  # mm per jog step while the zero is set

    def check(self) -> "StageSettings":
        if not (math.isfinite(self.feed) and self.feed > 0):
            raise InputError(f"--stage-feed must be > 0 mm/min, got {self.feed}")
        missing = [a for a in self.axes.pose_axes if a not in self.limits]
        if missing:
            raise InputError(f"--stage-limits: give a range for {missing[0]} (it is in --stage-axes {self.axes})")
        return self

    def check_schedule(self, poses: np.ndarray, describe) -> None:
        """Every pose, and the point its approach starts from, inside the limits; nothing a 3-axis stage
        without an axis for it cannot set."""
        for name in POSE_NAMES:
            k = POSE_NAMES.index(name)
            if name in self.axes.pose_axes:
                continue
            bad = np.flatnonzero(poses[:, k] != 0)
            if bad.size:
                i = int(bad[0])
                how = "the stage moves dx,dy,dz only" if name not in STAGE_AXES else \
                    f"--stage-axes {self.axes} moves no machine axis along it"
                raise InputError(f"pose {i + 1}/{len(poses)} ({describe(i)}) has {name} != 0: {how}")
        for name in self.axes.pose_axes:
            k = STAGE_AXES.index(name)
            lo, hi = self.limits[name]
            for label, vals in (("", poses[:, k]), (" (with its approach)", poses[:, k] + self.approach[k])):
                bad = np.flatnonzero((vals < lo - 1e-9) | (vals > hi + 1e-9))
                if bad.size:
                    i = int(bad[0])
                    raise InputError(f"pose {i + 1}/{len(poses)} ({describe(i)}){label} reaches {name}={vals[i]:g}, "
                                     f"outside --stage-limits {name}={lo:g}:{hi:g}; the schedule with its approach "
                                     f"points spans {self.span(poses)}: give limits at least that wide where the "
                                     "machine allows")

    def span(self, poses: np.ndarray) -> str:
        """The --stage-limits that hold ``poses`` and the points their approaches start from, to the micrometre
        outward: 'dx=-3.3:3.3,dy=-3.3:3.3,dz=-3:0.5'."""
        parts = []
        for name in self.axes.pose_axes:
            k = STAGE_AXES.index(name)
            vals = np.concatenate([poses[:, k], poses[:, k] + self.approach[k]])
            lo, hi = np.floor(vals.min() * 1000 + 1e-6) / 1000, np.ceil(vals.max() * 1000 - 1e-6) / 1000
            parts.append(f"{name}={lo + 0.0:g}:{hi + 0.0:g}")  # + 0.0: no -0
        return ",".join(parts)

    def describe(self) -> dict:
        return {"axes": str(self.axes), "feed_mm_min": self.feed,
                "limits_mm": {k: list(v) for k, v in sorted(self.limits.items())},
                "approach_mm": {a: float(v) for a, v in zip(STAGE_AXES, self.approach)}}
