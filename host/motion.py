"""What ``--simulate`` describes: the simulated sensor's pose."""

from __future__ import annotations

import numpy as np

from fitgen.base.errors import InputError
from fitgen.base.parse import parse_assignments
from fitgen.physics.pose import POSE_NAMES


def parse_pose(spec: str) -> np.ndarray:
    """``dx=1,dz=-1`` (components left out are 0) or five numbers ``0.5,0,-1,0,0``."""
    if "=" in spec:
        vals = parse_assignments(spec, POSE_NAMES, "--simulate pose")
        pose = np.array([vals.get(n, 0.0) for n in POSE_NAMES])
    else:
        parts = spec.replace(",", " ").split()
        try:
            pose = np.array([float(p) for p in parts])
        except ValueError:
            raise InputError(f"--simulate pose {spec!r}: not numbers") from None
        if pose.size != 5:
            raise InputError(f"--simulate pose {spec!r}: give 5 numbers ({','.join(POSE_NAMES)}) "
                             "or NAME=VALUE parts such as dx=1,dz=-1")
    if not np.all(np.isfinite(pose)):
        raise InputError(f"--simulate pose {spec!r}: not finite")
    return pose

