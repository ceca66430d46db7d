"""Files a record names by absolute path (a unit's sensor file, a drawing's, a scene's), found after the folder that
holds them was moved or copied to another machine: the file of that name beside the record, taken only where it is
still the file recorded (a sensor by its hash, a scene by its name). A recorded file that is there is left to the
checks that say whether it changed."""

from __future__ import annotations

from pathlib import Path

from fitgen.base.errors import InputError


def _beside(recorded, folder, same) -> str | None:
    """The file named as ``recorded`` in ``folder`` (absolute), where ``recorded`` is a path that is missing and
    ``same(candidate)`` holds; else None."""
    if not isinstance(recorded, str) or not recorded or Path(recorded).exists():
        return None
    candidate = Path(folder) / Path(recorded).name
    try:
        found = candidate.is_file() and same(str(candidate))
    except (InputError, OSError):  # it no longer reads as such a file
        found = False
    return str(candidate.resolve()) if found else None


def _sensor_hashed(sha):
    """Whether the sensor file at a path has hash ``sha`` in either transfer (records hash the sensor in theirs)."""
    def same(path: str) -> bool:
        from fitgen.physics.sensor import TRANSFERS, load_sensor

        sensor = load_sensor(path)
        return isinstance(sha, str) and sha in {sensor.with_transfer(t).sha256 for t in TRANSFERS}
    return same


def relocated(rec, folder, file_key: str = "sensor_file", sha_key: str = "sensor_sha256") -> dict:
    """``rec`` (a record naming a sensor file by ``file_key`` and its hash by ``sha_key``: a dataset's meta, a
    model's held-out record, a posterior) with that file found beside it in ``folder`` where the recorded one is
    missing; ``rec`` itself where there is nothing to find."""
    from fitgen.physics.sensor import preset_names

    if not isinstance(rec, dict) or rec.get(file_key) in preset_names():
        return rec
    found = _beside(rec.get(file_key), folder, _sensor_hashed(rec.get(sha_key)))
    return rec if found is None else {**rec, file_key: found}


def relocated_meta(meta: dict, folder) -> dict:
    """A dataset's ``meta`` with its unit's sensor file and its scene file found beside it in ``folder`` where the
    recorded ones are missing (a scene file is taken where its name is the scene the meta names)."""
    from fitgen.physics.scenes import PRESETS, load_scene

    meta = relocated(meta, folder)
    spec = meta.get("scene_spec")
    scene = None if spec in PRESETS else _beside(spec, folder, lambda path: load_scene(path).name == meta.get("scene"))
    return meta if scene is None else {**meta, "scene_spec": scene}
