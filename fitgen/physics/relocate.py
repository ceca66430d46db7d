"""Files a record names by absolute path (a unit's sensor file, a drawing's, a scene's), found after the folder that
holds them was moved, copied to another machine or archived: where the recorded path no longer holds the file
recorded (a sensor by its hash, a scene by its name), the file of that name beside the record is taken if it does.
Where neither does, the record is left as it is, to the checks that say the file is missing or changed."""

from __future__ import annotations

import os
import re
from pathlib import Path

from fitgen.base.errors import InputError


def _is(test, path: str) -> bool:
    """``test(path)``, False where the path does not read as such a file (or not at all)."""
    try:
        return os.path.isfile(path) and bool(test(path))
    except (InputError, OSError, ValueError):
        return False


def _beside(recorded, folder, same) -> str | None:
    """The file named as ``recorded`` in ``folder`` (absolute), where ``recorded`` is a path that does not hold the
    file recorded (``same`` false or no file there) and that one does; else None. The name is the path's last part
    whichever separator it was written with (a record written on Windows)."""
    if not isinstance(recorded, str) or not recorded or _is(same, recorded):
        return None
    candidate = os.path.join(folder, re.split(r"[\\/]", recorded)[-1])
    return str(Path(candidate).resolve()) if _is(same, candidate) else None


def _sensor_hashed(sha):
    """Whether the sensor file at a path has hash ``sha`` in either transfer (records hash the sensor in theirs)."""
    def same(path: str) -> bool:
        from fitgen.physics.sensor import load_sensor
        from fitgen.physics.transfer import sensor_hashes

        return isinstance(sha, str) and sha in sensor_hashes(load_sensor(path))
    return same


def holds_sensor(path, sha) -> bool:
    """Whether the file at ``path`` is a sensor file whose hash in either transfer is ``sha``; False where it reads
    as none."""
    return _is(_sensor_hashed(sha), str(path))


def relocated(rec, folder, file_key: str = "sensor_file", sha_key: str = "sensor_sha256") -> dict:
    """``rec`` (a record naming a sensor file by ``file_key`` and its hash by ``sha_key``: a dataset's meta, a
    model's held-out record, a posterior) with that file found beside it in ``folder`` where the recorded path no
    longer holds it; ``rec`` itself where there is nothing to find."""
    from fitgen.physics.sensor import preset_names

    if not isinstance(rec, dict) or rec.get(file_key) in preset_names():
        return rec
    found = _beside(rec.get(file_key), folder, _sensor_hashed(rec.get(sha_key)))
    return rec if found is None else {**rec, file_key: found}


def relocated_meta(meta: dict, folder) -> dict:
    """A dataset's or a capture's ``meta`` with its unit's sensor file, its schedule's drawing and its scene file
    found beside it in ``folder`` where the recorded paths no longer hold them (a scene file is taken where its name
    is the scene the meta names)."""
    meta = relocated(meta, folder)
    made = meta.get("schedule_drawing")  # what identify takes as the drawing, as tactile-host capture passed it on
    if isinstance(made, dict) and (moved := relocated(made, folder)) is not made:
        meta = {**meta, "schedule_drawing": moved}
    scene = _beside(meta.get("scene_spec"), folder, lambda path: _scene_name(path) == meta.get("scene"))
    return meta if scene is None else {**meta, "scene_spec": scene}


def _scene_name(path: str):
    """A scene file's name as fitgen.physics.scenes.load_scene reads it (its ``name``, else the file's stem), read
    here without it: scenes import the datasets whose meta this reads."""
    from fitgen.base.fileio import read_text
    from fitgen.base.texts import tomllib

    try:
        return tomllib.loads(read_text(path, "scene file")).get("name", Path(path).stem)
    except ValueError:  # TOMLDecodeError, or an integer past the digits Python converts
        return None
