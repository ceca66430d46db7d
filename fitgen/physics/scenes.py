"""Scenes: which pose components a use needs, and the pose ranges it sees."""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from fitgen.base.errors import InputError, is_finite_number
from fitgen.base.fileio import read_text
from fitgen.base.texts import load_toml
from fitgen.physics.pose import POSE_NAMES, check_pose_range
from fitgen.physics.simulate import DEFAULT_RANGES, grid_poses


@dataclass(frozen=True)
class Scene:
    """Outputs to estimate, the box of poses the sensor will see, and grid levels per component."""

    name: str
    outputs: tuple[str, ...]
    ranges: dict
    levels: int = 5

    def fixed(self) -> tuple[str, ...]:
        """Components the scene holds at 0 (range of width 0)."""
        return tuple(n for n in POSE_NAMES if self.ranges[n][0] == self.ranges[n][1])

    def grid(self) -> dict[str, list[float]]:
        """Grid levels: ``levels`` evenly spaced values over each range; a held component at its value."""
        out = {}
        for n in POSE_NAMES:
            lo, hi = self.ranges[n]
            out[n] = [float(lo)] if lo == hi else np.linspace(lo, hi, self.levels).round(12).tolist()
        return out

    def poses(self) -> np.ndarray:
        """The scene's full factorial grid of poses (n, 5)."""
        return grid_poses(self.grid())

    def with_rows(self, rows: int) -> "Scene":
        """This scene with its levels raised until its grid holds at least ``rows`` poses; itself where it holds
        them (a one-axis grid of 21 rows cannot carry the first equation of a ring of ten elements)."""
        free, levels = len(POSE_NAMES) - len(self.fixed()), self.levels
        while free and levels ** free < rows:
            levels += 1
        return self if levels == self.levels else replace(self, levels=levels)


_ZERO_TILT = {**DEFAULT_RANGES, "thx": (0.0, 0.0), "thy": (0.0, 0.0)}
PRESETS = {
    "full": Scene("full", POSE_NAMES, dict(DEFAULT_RANGES)),
    "slide": Scene("slide", ("dx", "dy", "dz"), dict(_ZERO_TILT)),
    "press": Scene("press", ("dz",), {**_ZERO_TILT, "dx": (0.0, 0.0), "dy": (0.0, 0.0)}, levels=21),
}


MAX_POSES = 1_000_000  # a scene's grid: 40 MB of poses, about a minute to simulate


def preset_sizes() -> tuple[tuple[str, int], ...]:
    """(name, number of outputs) of each preset scene: where observe points a sensor of too few elements."""
    return tuple((name, len(sc.outputs)) for name, sc in PRESETS.items())


def load_scene(spec) -> Scene:
    """A preset name (full, slide, press), a TOML file with ``outputs``, ``[ranges]``, ``levels``, or a Scene."""
    if spec is None:
        return PRESETS["full"]
    if isinstance(spec, Scene):  # a notebook's own, or a preset as docs/python.md hands it out
        return spec
    if spec in PRESETS:
        return PRESETS[spec]
    path = Path(spec)
    if not path.exists():  # anything else there (a folder) is said by read_text as what it is
        raise InputError(f"scene {spec!r}: no such file, and not a preset ({', '.join(PRESETS)})")
    origin = f"scene file {spec}"
    data = load_toml(read_text(path, "scene file"), origin, "scene file")
    unknown = set(data) - {"name", "outputs", "ranges", "levels"}
    if unknown:
        raise InputError(f"{origin}: unknown key {sorted(unknown)[0]!r}")
    outputs = data.get("outputs")
    if not isinstance(outputs, list) or not outputs or any(o not in POSE_NAMES for o in outputs):
        raise InputError(f"{origin}: 'outputs' must be a non-empty list drawn from {', '.join(POSE_NAMES)}")
    if len(set(outputs)) != len(outputs):
        raise InputError(f"{origin}: 'outputs' names a component twice")
    ranges = dict(DEFAULT_RANGES)
    raw = data.get("ranges", {})
    if not isinstance(raw, dict):
        raise InputError(f"{origin}: 'ranges' must be a table")
    for key, val in raw.items():
        if key not in POSE_NAMES:
            raise InputError(f"{origin}: unknown key 'ranges.{key}'")
        ok = (isinstance(val, list) and len(val) == 2
              and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in val) and val[0] <= val[1])
        # an integer past float's range (TOML holds any) is no pose, as inf is (check_pose_range says which)
        if not ok or not all(is_finite_number(v) or isinstance(v, float) for v in val):
            raise InputError(f"{origin}: 'ranges.{key}' must be [low, high], finite, with low <= high")
        ranges[key] = (float(val[0]), float(val[1]))
        check_pose_range(key, *ranges[key], origin)
    levels = data.get("levels", 5)
    if isinstance(levels, bool) or not isinstance(levels, int) or not 2 <= levels <= 101:
        raise InputError(f"{origin}: 'levels' must be a whole number 2..101")
    name = data.get("name", path.stem)
    if not isinstance(name, str) or not name.strip():  # every line names the scene: "scene :" says nothing
        raise InputError(f"{origin}: 'name' must be a string, not empty (or leave it out: the file's stem)")
    held = [o for o in outputs if ranges[o][0] == ranges[o][1]]
    if held:
        raise InputError(f"{origin}: output {held[0]} is held at {ranges[held[0]][0]:g}: there is nothing to "
                         "estimate (give it a range, or leave it out of 'outputs')")
    n_poses = levels ** sum(lo != hi for lo, hi in ranges.values())
    if n_poses > MAX_POSES:
        raise InputError(f"{origin}: {levels} levels over {sum(lo != hi for lo, hi in ranges.values())} varying "
                         f"components make {n_poses:,} poses (at most {MAX_POSES:,}): fewer levels, or hold "
                         "components the scene does not move")
    ordered = tuple(n for n in POSE_NAMES if n in outputs)
    return Scene(name, ordered, ranges, levels)


def scene_outputs(spec: str, ds, origin: str, sensor, force: bool = False, recorded=None,
                  noise: float | None = None) -> tuple[str, ...]:
    """The outputs scene ``spec`` asks for, after checking that the dataset ``ds`` (read from
    ``origin``) has them and, unless ``force``, that ``sensor`` (None: unknown) resolves them; ``recorded``:
    the outputs the scene named when ``ds`` was simulated for it (a scene file edited since is refused)."""
    scene = load_scene(spec)
    if recorded is not None and list(scene.outputs) != list(recorded):
        raise InputError(f"scene {spec} names {','.join(scene.outputs)} now, but {origin} was simulated when it "
                         f"named {','.join(map(str, recorded))}: simulate again, or give --outputs")
    missing = [o for o in scene.outputs if o not in ds.target_names]
    if missing:
        raise InputError(f"scene {scene.name} asks for {missing[0]}, which dataset {origin} does not have")
    if not force:
        if sensor is None:
            raise InputError("give --sensor (to check that it resolves the scene's outputs) or --force")
        bad = unresolved_warnings(sensor, scene, noise=noise)
        if bad:
            raise InputError(f"scene {scene.name}: sensor {sensor.name} cannot resolve {bad[0]} "
                             f"Fit anyway with --force, or use a scene without it.")
    return scene.outputs


def unresolved_warnings(sensor, scene: Scene, accuracy: dict | None = None, noise: float | None = None) -> list[str]:
    """One line per scene output the sensor cannot resolve to the required accuracy (fitgen.physics.observe) at the
    reading noise ``noise`` (default: the sensor's)."""
    from fitgen.physics.observe import observe

    report = observe(sensor, scene.ranges, scene.outputs, noise=noise, accuracy=accuracy, scenes=preset_sizes())
    bad = set(report.unresolved())
    return [v for c, v in zip(report.components, report.verdicts()) if c in bad]
