"""What an output would replace: identify's unit file a drawing (refused), another unit or this capture's unit as
identified before (said), its posterior another kind of file (refused); simulate's unit file a drawing, its input
or an identified unit (refused), another drawn unit (said); fit's model another sensor's (said)."""

from __future__ import annotations

from fitgen.base.errors import InputError
from fitgen.base.fileio import replaces_other
from fitgen.physics.relocate import holds_sensor


def _held(path, given: str | None, identified: bool) -> str:
    """What a unit written over ``path`` would destroy ('' when nothing a user can't make again): the input
    ``given``, a drawing, or (``identified``) a unit identified from a capture."""
    from pathlib import Path

    from fitgen.physics.sensor import load_sensor

    path = Path(path)
    if not path.is_file():
        return ""
    if given is not None and Path(given).is_file() and path.samefile(given):
        return "input"
    try:
        there = load_sensor(str(path))
    except (InputError, OSError, ValueError):  # no sensor file: the tools' other checks say what it is
        return ""
    if there.is_drawing:
        return f"a drawing (sensor {there.name}, no unit's traits)"
    sha, capture = _recorded_capture(path)
    if identified and (sha or capture):  # made from a capture, which a seed cannot draw again
        return f"unit {there.name}, identified from {capture if isinstance(capture, str) else 'a capture'}"
    return ""


def unit_output(output, drawing: str, meta: dict | None = None) -> None:
    """InputError when identify's ``output`` is a drawing's file: the unit written there would destroy it (the
    drawing taken from the capture's record is no input the options name, so the general guard misses it); when it
    is the unit a simulated capture with ``meta`` was read from (its truth, which the identified unit is judged
    against); or when the posterior beside it would write over another kind of file (:func:`posterior_over`)."""
    held = _held(output, drawing, identified=False)
    if held == "input":
        raise InputError(f"-o {output} is the drawing identify reads (the capture's schedule names it): writing the "
                         "unit there would destroy it; give another name (e.g. unit.toml)")
    if held:
        raise InputError(f"-o {output} is {held}: writing the unit there would destroy it; give another name "
                         "(e.g. unit.toml)")
    if holds_sensor(output, (meta or {}).get("sensor_sha256")):
        raise InputError(f"-o {output} is the unit the capture was simulated from (its meta records its hash): "
                         "writing the identified unit there would destroy the truth it is judged against, and leave "
                         "the capture naming another unit; give another name (e.g. unit.toml)")
    posterior_over(output)


def posterior_over(output) -> None:
    """InputError when the posterior identify writes beside its unit file ``output`` would write over a capture, a
    dataset or another kind of the tools' files (no option names it, so the outputs' general check misses it)."""
    from fitgen.app.outputkind import written_over
    from fitgen.fitting.unitrecord import posterior_beside

    post = posterior_beside(output)
    if what := written_over(str(post), "identify", "a unit's posterior"):
        raise InputError(f"-o {output} writes the unit's posterior beside it, to {post}, which {what}")


def drawn_unit_over(unit, text: str, output, sensor: str):
    """``unit`` when ``simulate --unit``'s unit file there (named for ``output``) holds another drawn unit, for the
    note; None when it holds nothing or ``text``. InputError when it holds what a seed cannot draw again: the
    ``--sensor`` input, a drawing, or a unit identified from a capture (its posterior beside it)."""
    held = _held(unit, sensor, identified=True)
    what = f"--unit writes the unit it draws beside -o {output}, to {unit}"
    if held == "input":
        raise InputError(f"{what}, which is the --sensor input: writing it would destroy it; give -o another name")
    if held:
        raise InputError(f"{what}, which holds {held}: writing it would destroy it; give -o another name")
    return unit if replaces_other(unit, text) else None


def _recorded_capture(unit_file) -> tuple[str | None, str | None]:
    """(sha256, path) of the capture the unit file there was identified from, as its [unit] table records them."""
    import tomllib

    try:
        with open(unit_file, "rb") as f:
            unit = tomllib.load(f).get("unit")
    except (OSError, ValueError):
        return None, None
    unit = unit if isinstance(unit, dict) else {}
    return unit.get("capture_sha256"), unit.get("capture")


def replaced_unit(path, text: str, capture_sha256: str, capture) -> str:
    """What writing the unit ``text`` to ``path`` replaces, for identify's note: "another unit", "this capture's
    unit as identified before" (other options, or the capture resumed since), or "" (nothing, or the same unit:
    only its record's text differs, which no twin reads)."""
    import os
    import tomllib

    from fitgen.physics.sensor import load_sensor, parse_sensor

    if not replaces_other(path, text):
        return ""
    try:
        if load_sensor(str(path)).sha256 == parse_sensor(tomllib.loads(text)).sha256:
            return ""
    except (InputError, OSError, ValueError):  # no sensor file there: the write says what it says
        pass
    sha, recorded = _recorded_capture(path)
    same = sha == capture_sha256 or (isinstance(recorded, str)
                                     and os.path.realpath(recorded) == os.path.realpath(capture))
    return "this capture's unit as identified before" if same else "another unit"


def replaced_model(path, model) -> str:
    """A note when fit's output ``path`` holds a model fitted for another sensor than ``model`` is ('' otherwise)."""
    import json
    from pathlib import Path

    try:
        doc = json.loads(Path(path).read_text())
    except (OSError, ValueError, RecursionError):  # UnicodeDecodeError is a ValueError
        return ""
    fit = doc.get("fit") if isinstance(doc, dict) else None
    old = fit.get("sensor_sha256") if isinstance(fit, dict) else None
    new = model.fit_info.get("sensor_sha256")
    if not isinstance(old, str) or not isinstance(new, str) or old == new:
        return ""
    held = fit.get("held_out")
    name = held.get("sensor") if isinstance(held, dict) and isinstance(held.get("sensor"), str) else None
    now = (model.fit_info.get("held_out") or {}).get("sensor")
    if name is not None and name == now:  # the same name, other physics: a unit identified again, as identify says
        return (f"{path} held the model of sensor {name} as its file was before (identified again since), now "
                "replaced: a device flashed with the old one runs the old unit's physics")
    return (f"{path} held the model of another sensor{f' ({name})' if name else ''}, now replaced: a device running "
            "that one, or a check of its unit, needs it fitted again")
