"""Where ``fitgen simulate`` takes its poses from: a grid, random poses in a box (after a grid's when
both are given), a poses file, or a scene's grid or box; with the provenance its dataset records."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fitgen.base.errors import InputError
from fitgen.physics.dataset import load_poses
from fitgen.physics.pose import check_box
from fitgen.physics.scenes import PRESETS, Scene, load_scene
from fitgen.physics.simulate import grid_poses, parse_grid, parse_ranges, pose_rng, random_poses


def choose_poses(*, grid: str | None = None, random: int | None = None, poses: str | None = None,
                 ranges: str | None = None, scene: str | None = None, seed: int = 0,
                 sensor=None, min_rows: int = 0) -> tuple[np.ndarray, dict]:
    """(poses, provenance) from the options of ``fitgen simulate``; with ``sensor``, a box that reaches its board is
    refused as a box.

    ``scene``: its grid (its levels raised where it holds fewer than ``min_rows`` poses), or ``random`` poses in
    its box. Otherwise the ``poses`` file, ``random`` poses in ``ranges`` (seeded by ``seed``; after the ``grid``'s
    poses when it is given too), or the ``grid`` (default paper-sim). Any other combination is an InputError.
    """
    chosen = [x for x in (grid, random, poses) if x is not None]
    if len(chosen) > 1 and not (len(chosen) == 2 and poses is None and not scene):
        raise InputError("give one of --grid, --random, --poses (or --grid with --random: the grid, then random poses)")
    if scene and (grid or poses or ranges):
        raise InputError("--scene sets the poses: give it with --random N or alone, not with --grid, --poses, --ranges")
    if ranges is not None and random is None:
        raise InputError("--ranges is the box of --random poses: give --random N with it (without it, it would be "
                         "ignored)")
    if scene:
        sc = load_scene(scene)
        if isinstance(scene, Scene):  # made in Python: a preset by its name, else none that fit could find
            spec = sc.name if PRESETS.get(sc.name) == sc else None
        else:  # a scene file by its absolute path, so that fit finds it from any folder
            spec = scene if scene in PRESETS else str(Path(scene).resolve())
        scene_info = {"scene": sc.name, "scene_spec": spec, "scene_outputs": list(sc.outputs)}
        if random is None:
            sc = sc.with_rows(min_rows)
            return sc.poses(), {"scene_grid_levels": sc.levels, **scene_info}
        if sensor is not None:
            check_box(sensor, sc.ranges, f"scene {sc.name}")
        return random_poses(random, sc.ranges, pose_rng(seed)), {"random": random, **scene_info}
    if poses:
        return load_poses(poses), {"poses_file": str(poses)}
    if random is not None:
        box = parse_ranges(ranges)
        if sensor is not None:
            check_box(sensor, box, f"--ranges {ranges!r}" if ranges else "the default pose box")
        out = random_poses(random, box, pose_rng(seed))
        source = {"random": random, "ranges": ranges}
        if grid:
            # a rig's sweep and random presses between its levels: the grid's poses first
            return np.vstack([grid_poses(parse_grid(grid)), out]), {**source, "grid": grid}
        return out, source
    grid = grid or "paper-sim"
    return grid_poses(parse_grid(grid)), {"grid": grid}
