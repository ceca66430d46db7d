"""What ``--simulate`` and ``--sim-drift`` describe: the simulated sensor's pose or motion, and its drift."""

from __future__ import annotations

import math

import numpy as np

from fitgen.base.errors import InputError
from fitgen.base.parse import parse_assignments, parse_numbers
from fitgen.physics.pose import POSE_NAMES, check_pose_rows

from host.simsensor import Drift


def parse_pose(spec: str, what: str = "--simulate pose") -> np.ndarray:
    """``dx=1,dz=-1`` (components left out are 0) or five numbers ``0.5,0,-1,0,0``; InputError naming ``what``."""
    if "=" in spec:
        vals = parse_assignments(spec, POSE_NAMES, what)
        pose = np.array([vals.get(n, 0.0) for n in POSE_NAMES])
    else:
        vals = parse_numbers(spec)
        if vals is None:
            raise InputError(f"{what} {spec!r}: not numbers")
        pose = np.array(vals, dtype=float)
        if pose.size != 5:
            raise InputError(f"{what} {spec!r}: give 5 numbers ({','.join(POSE_NAMES)}) "
                             "or NAME=VALUE parts such as dx=1,dz=-1")
    if not np.all(np.isfinite(pose)):
        raise InputError(f"{what} {spec!r}: not finite")
    check_pose_rows(pose[None], f"{what} {spec!r}")  # as --ranges and --grid: thx=1e6 had been simulated
    return pose


PRESS_EVERY = 20.0  # s between the starts of ``presses``' presses: rest between them, for auto-zero's hold


def pose_or_motion(spec: str):
    """``--simulate``: (pose, None) for a pose, or (rest pose, motion) for ``motion`` (a slow circular slide with a
    press every few seconds) or ``presses`` (at rest, pressed to dz -1 mm for 1.5 s every PRESS_EVERY s: drift and
    auto-zero's updates between), the pose as a function of the bus clock's seconds."""
    kind = spec.strip().lower()
    if kind not in ("motion", "presses"):
        return parse_pose(spec), None

    def motion(t: float):
        # 8 s circle of 1 mm radius; every 6 s a 1.5 s press to dz = -1 mm with a little tilt
        phase = (t % 6.0) / 1.5
        press = np.sin(np.pi * phase) if phase < 1.0 else 0.0
        return np.array([np.cos(2 * np.pi * t / 8), np.sin(2 * np.pi * t / 8), -press, 2.0 * press, -1.0 * press])

    def presses(t: float):
        phase = (t % PRESS_EVERY) / 1.5
        return np.array([0.0, 0.0, -np.sin(np.pi * phase) if phase < 1.0 else 0.0, 0.0, 0.0])

    return np.zeros(5), motion if kind == "motion" else presses


def parse_drift(spec: str | None, n: int) -> Drift | None:
    """``--sim-drift ramp=5,over=300,tau=120,creep=0.002,start=25,seed=0``: the drift of ``n`` elements
    (host.simsensor.Drift.typical, creep scaled to ``creep`` V); None without a spec."""
    if spec is None:
        return None
    keys = ("ramp", "over", "tau", "creep", "start", "seed")
    vals = parse_assignments(spec, keys, "--sim-drift")
    bad = next((k for k, v in vals.items() if not math.isfinite(v)), None)
    if bad is not None:
        raise InputError(f"--sim-drift {spec!r}: {bad} must be a finite number")
    if "seed" in vals and not (vals["seed"] >= 0 and vals["seed"] == int(vals["seed"])):
        raise InputError(f"--sim-drift {spec!r}: seed must be a whole number >= 0")
    over, tau = vals.get("over", 600.0), vals.get("tau", 600.0)
    if not (1.0 <= over <= 1e7 and 1.0 <= tau <= 1e7):  # a shorter ramp overflows its slope
        raise InputError(f"--sim-drift {spec!r}: over and tau must be 1..1e7 s")
    start, ramp = vals.get("start", 25.0), vals.get("ramp", 5.0)
    ends = (start, start + ramp)
    # past the thermistor's range is a case to simulate (a read warns of it, or reads none); past these, no sensor's
    if not all(-273.15 <= t <= 1000.0 for t in ends):
        raise InputError(f"--sim-drift {spec!r}: start and start + ramp must lie within -273.15..1000 degC")
    if not abs(vals.get("creep", 0.0)) <= 1.0:
        raise InputError(f"--sim-drift {spec!r}: creep must be within +-1 V")
    d = Drift.typical(n, seed=int(vals.get("seed", 0)), ramp_degc=ramp, ramp_s=over, creep_tau=tau,
                      start_degc=start)
    if "creep" in vals:
        d.creep = d.creep / 2e-3 * vals["creep"]
    return d
