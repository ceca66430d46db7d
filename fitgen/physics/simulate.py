"""Pose sets (the paper's grids, regular grids, random poses) and simulated datasets."""

from __future__ import annotations

import re
from dataclasses import replace

import numpy as np

from fitgen import __version__
from fitgen.physics.dataset import Dataset
from fitgen.base.errors import InputError, check_seed, is_finite_number, is_whole_number, shown
from fitgen.physics.pose import POSE_NAMES, as_poses, check_pose_range, field_readings, off_skin, pose_label
from fitgen.physics.sensor import TRANSFERS, Sensor
from fitgen.physics.transfer import past_linear, readings

PAPER_GRIDS = {
    # the seed's simulation grid (1,875 poses) and its experiment grid (450 poses)
    "paper-sim": {"dx": [-2, -1, 0, 1, 2], "dy": [-2, -1, 0, 1, 2], "dz": [0, -1, -2],
                  "thx": [-5, -2.5, 0, 2.5, 5], "thy": [-5, -2.5, 0, 2.5, 5]},
    "paper-exp": {"dx": [-2, -1, 0, 1, 2], "dy": [-2, -1, 0, 1, 2], "dz": [-2, -3],
                  "thx": [-5, 0, 5], "thy": [-5, 0, 5]},
}
DEFAULT_RANGES = {"dx": (-2.0, 2.0), "dy": (-2.0, 2.0), "dz": (-2.0, 0.0), "thx": (-5.0, 5.0), "thy": (-5.0, 5.0)}

_NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"


MAX_POSES = 5_000_000  # a grid's or a random draw's: beyond it the readings' arrays outgrow a machine's memory


def grid_poses(levels: dict[str, list[float]]) -> np.ndarray:
    """Full factorial grid; components not named stay 0. Row order: dx slowest, thy fastest."""
    axes = [np.asarray(levels.get(n, [0.0]), dtype=float) for n in POSE_NAMES]
    mesh = np.meshgrid(*axes, indexing="ij")
    return np.column_stack([m.ravel() for m in mesh])


def _components(spec: str, what: str) -> dict[str, str]:
    out = {}
    for part in re.split(r"[;\s]+", spec.strip()):
        if not part:
            continue
        name, sep, value = part.partition("=")
        if not sep or name not in POSE_NAMES:
            raise InputError(f"{what} {spec!r}: each part must be NAME=VALUES with NAME in {','.join(POSE_NAMES)}")
        if name in out:
            raise InputError(f"{what} {spec!r}: {name} given twice")
        out[name] = value
    if not out:
        raise InputError(f"{what} is empty")
    return out


def parse_grid(spec: str) -> dict[str, list[float]]:
    """A paper grid name, or ``dx=-2:2:5 dz=0,-1,-2 ...`` (start:stop:count or a list)."""
    if spec in PAPER_GRIDS:
        return PAPER_GRIDS[spec]
    if "=" not in spec:  # a name: the presets are the names there are
        raise InputError(f"grid {spec!r}: not a preset ({', '.join(PAPER_GRIDS)}) nor NAME=VALUES parts such as "
                         "'dx=-2:2:5 dz=0,-1,-2'")
    levels = {}
    for name, value in _components(spec, "grid").items():
        m = re.fullmatch(rf"({_NUM}):({_NUM}):(\d+)", value)
        if m:
            lo, hi, count = float(m.group(1)), float(m.group(2)), int(m.group(3))
            if count < 1 or count > 10000:
                raise InputError(f"grid {spec!r}: {name} count must be 1..10000, got {count}")
            levels[name] = list(np.linspace(lo, hi, count)) if count > 1 else [lo]
        elif re.fullmatch(rf"{_NUM}(?:,{_NUM})*", value):
            levels[name] = [float(v) for v in value.split(",")]
        else:
            raise InputError(f"grid {spec!r}: {name}={value!r} is neither START:STOP:COUNT nor a list of numbers")
        check_pose_range(name, min(levels[name]), max(levels[name]), f"grid {spec!r}")  # as --ranges is
    total = int(np.prod([len(v) for v in levels.values()]))
    if total > MAX_POSES:
        raise InputError(f"grid {spec!r} has {total} poses; at most {MAX_POSES:,}")
    return levels


def parse_ranges(spec: str | None, base: dict[str, tuple[float, float]] | None = None) -> dict[str, tuple[float, float]]:
    """``dx=-2:2 thx=-5:5 ...``, or separated by commas as ``--stage-limits`` takes them (components not named: as in
    ``base``, default the paper-sim box)."""
    ranges = dict(DEFAULT_RANGES if base is None else base)
    if not spec:
        return ranges
    for name, value in _components(re.sub(r",\s*(?=[A-Za-z]\w*\s*=)", " ", spec), "ranges").items():
        m = re.fullmatch(rf"({_NUM}):({_NUM})", value)
        if not m and re.fullmatch(r"[-+]?(inf|infinity|nan)\s*:.*|.*:\s*[-+]?(inf|infinity|nan)", value, re.I):
            raise InputError(f"ranges {spec!r}: {name}={value!r}: LOW and HIGH must be finite numbers")
        if not m or float(m.group(1)) > float(m.group(2)):
            raise InputError(f"ranges {spec!r}: {name}={value!r} must be LOW:HIGH with LOW <= HIGH")
        ranges[name] = (float(m.group(1)), float(m.group(2)))
        check_pose_range(name, *ranges[name], f"ranges {spec!r}")
    return ranges


def random_poses(n: int, ranges: dict[str, tuple[float, float]], rng: np.random.Generator) -> np.ndarray:
    """``n`` poses uniform in the box ``ranges`` ({pose name: (low, high)}; a component it leaves out stays 0)."""
    if not (is_whole_number(n) and 1 <= n <= MAX_POSES):
        raise InputError(f"number of random poses must be a whole number 1..{MAX_POSES:,}, got {shown(n)}")
    odd = [k for k in ranges if k not in POSE_NAMES]
    if odd:
        raise InputError(f"ranges name {', '.join(map(str, odd))}, no pose component ({', '.join(POSE_NAMES)})")
    lo = np.array([ranges.get(k, (0.0, 0.0))[0] for k in POSE_NAMES], dtype=float)
    hi = np.array([ranges.get(k, (0.0, 0.0))[1] for k in POSE_NAMES], dtype=float)
    return lo + (hi - lo) * rng.random((n, 5))


def simulate(
    sensor: Sensor,
    poses,
    *,
    noise: float = 0.0,
    adc_bits: int | None = None,
    seed: int = 0,
    targets: tuple[str, ...] = POSE_NAMES,
    provenance: dict | None = None,
    labels: str = "stage",
) -> Dataset:
    """Readings for ``poses`` through the sensor's transfer, as a :class:`Dataset`.

    Deterministic: the noise stream is drawn from ``seed``. ``labels``: for a built unit whose magnet
    does not follow the stage one to one (its stage map), whether the poses and the targets are the
    stage's displacements (what a capture's labels measure) or the magnet's.
    """
    poses = as_poses(poses)
    unknown = [t for t in targets if t not in POSE_NAMES]
    if unknown or len(set(targets)) != len(targets):
        raise InputError(f"targets must be distinct pose components ({', '.join(POSE_NAMES)}), got {tuple(targets)}")
    # a dataset's missing pose columns read as 0 (fit's held-out box, identify): one the poses move in would lie
    moved = [c for k, c in enumerate(POSE_NAMES) if c not in targets and np.any(poses[:, k] != 0)]
    if moved:
        raise InputError(f"targets leave out {', '.join(moved)}, which the poses move in: a dataset's missing pose "
                         "columns read as 0; keep them, and choose the outputs when fitting")
    if not is_finite_number(noise) or noise < 0:  # one figure for every element: the meta records one
        raise InputError(f"noise must be a number >= 0 (one sample's, in the sensor's units), got {noise!r:.40}")
    if labels not in ("stage", "magnet"):
        raise InputError(f"labels are the stage's or the magnet's, not {labels!r}")
    source = _labelled(sensor, labels)
    rng = np.random.default_rng(np.random.SeedSequence(seed).spawn(2)[1])
    with np.errstate(all="ignore"):  # a pose far outside the sensor overflows the field: said below, once
        values = readings(source, poses, noise=noise, adc_bits=adc_bits, rng=rng)
    bad = np.flatnonzero(~np.isfinite(values).all(axis=1))
    if bad.size:
        pose = pose_label(poses[bad[0]])
        raise InputError(f"pose {bad[0] + 1} ({pose}) gives readings that are not finite numbers ({bad.size} of "
                         f"{len(poses)} poses do): it lies far outside the sensor")
    cols = [POSE_NAMES.index(t) for t in targets]
    meta = {
        "generator": f"fitgen {__version__}",
        "sensor": sensor.name,
        "sensor_sha256": sensor.sha256,
        "transfer": sensor.transfer,
        "units": sensor.units,
        "noise": noise,
        "adc_bits": adc_bits,
        "seed": seed,
    }
    if not sensor.is_drawing:
        meta["labels"] = labels
    meta.update(provenance or {})
    return Dataset(values, poses[:, cols].copy(), tuple(targets), meta)


def _labelled(sensor: Sensor, labels: str) -> Sensor:
    """The sensor whose poses are ``labels``: for the magnet's own displacement, a unit with the identity for its
    stage map and no stiffening (a magnet label above first contact still rests: no indenter lifts it)."""
    if labels == "magnet" and not sensor.is_drawing:
        return replace(sensor, stage_map=np.eye(3), stiffening=0.0)
    return sensor


def rows_past_linear(sensor: Sensor, poses, labels: str = "stage") -> np.ndarray:
    """Per pose (bool): some element's reading there no longer follows the field (fitgen.physics.transfer.
    past_linear), noise-free, as :func:`simulate` draws the pose."""
    with np.errstate(all="ignore"):
        return past_linear(sensor, field_readings(_labelled(sensor, labels), as_poses(poses))).any(axis=1)


def rig_poses(labels: np.ndarray, rig_error: float, rng: np.random.Generator, zero=None) -> np.ndarray:
    """Where a stage with ``rig_error`` mm rms per axis stands at stage ``labels`` (n, 5): each displacement off by
    a normal draw. A row labelled on the skin that the error lifts past the adhesion (dz above OFF_SKIN_MM) leaves
    it, and the magnet rests, as on host.simrig's stage (fitgen.physics.pose.contact_top: how far a schedule
    presses so that this stays rare); a row labelled off the skin is left as labelled (the magnet rests wherever
    the stage stands). ``zero`` (mm, dx, dy, dz): how far the capture's zero is from first contact, added to every
    row labelled on the skin (a zero above first contact lifts the rows at dz 0 off it)."""
    true = np.array(labels, dtype=float)
    true[:, :3] += rig_error * rng.standard_normal((len(true), 3))
    touching = ~off_skin(labels)
    true[~touching] = labels[~touching]
    if zero is not None:
        true[touching, :3] += np.asarray(zero, dtype=float)
    return true


def pose_rng(seed: int) -> np.random.Generator:
    """The random stream for pose sampling (independent of the noise stream)."""
    check_seed(seed)
    return np.random.default_rng(np.random.SeedSequence(seed).spawn(2)[0])


def dataset_sensor(meta: dict, spec: str | None = None, n_inputs: int | None = None) -> Sensor | None:
    """The sensor a dataset was simulated with: ``spec`` (a preset or file) if given, else the
    preset its meta names when the hash matches; None for measured data or an unknown sensor.
    InputError when it has other than the dataset's ``n_inputs`` elements."""
    from pathlib import Path

    from fitgen.physics.sensor import load_sensor, preset_names

    if spec is None:
        name = meta.get("sensor")
        unit_file = meta.get("sensor_file")
        if isinstance(unit_file, str) and Path(unit_file).is_file():
            spec = unit_file  # a unit's own sensor file (fitgen simulate --unit, fitgen identify)
        elif name not in preset_names():
            return None
        else:
            spec = name
    given = spec is not None and spec not in (meta.get("sensor"), meta.get("sensor_file"))
    sensor = load_sensor(spec)
    if meta.get("transfer") in TRANSFERS:
        sensor = sensor.with_transfer(meta["transfer"])
    elif meta.get("units") in ("mT", "V") and sensor.units != meta["units"]:  # measured rows: their units say which
        sensor = sensor.with_transfer("raw" if meta["units"] == "mT" else "gmr")
    if given and (problem := other_sensor_problem(meta, sensor, spec)):
        raise InputError(f"{problem} (leave --sensor out)")
    if spec in (meta.get("sensor"), meta.get("sensor_file")) and meta.get("sensor_sha256") not in (None, sensor.sha256):
        return None
    if n_inputs is not None and sensor.n_elements != n_inputs:
        raise InputError(f"the dataset has {n_inputs} input columns, its sensor {sensor.name} {sensor.n_elements} "
                         "elements")
    return sensor


def with_adc_bits(sensor: Sensor, bits) -> Sensor:
    """``sensor`` with its transfer's ADC of ``bits`` (0..32; 0: no quantisation), as simulate's adc_bits reads."""
    if isinstance(bits, bool) or not isinstance(bits, int) or not 0 <= bits <= 32:
        raise InputError(f"the meta's adc_bits must be a whole number 0..32 (simulate --adc-bits), got {shown(bits)}")
    kind = "raw" if sensor.transfer == "raw" else "gmr"
    return replace(sensor, **{kind: replace(getattr(sensor, kind), adc_bits=bits)})


def other_sensor_problem(meta: dict, sensor: Sensor, named: str) -> str:
    """Why ``sensor`` (``named`` so in the words) is not the one a dataset's meta records by hash, in words ('' when
    it is, or the meta records none): figures held out on another sensor would not be the model's."""
    from fitgen.physics.transfer import sensor_hashes

    sha = meta.get("sensor_sha256")
    # either transfer's: a simulated capture records its sensor file's as read (raw), its rows are in volts
    if not isinstance(sha, str) or sha in sensor_hashes(sensor):
        return ""
    recorded = meta.get("sensor_file") or meta.get("sensor")
    return (f"the dataset was {f'simulated with sensor {recorded}' if recorded else 'read from another sensor'} "
            f"(sha256 {sha[:12]}), not {named} ({sensor.sha256[:12]}): figures held out on another sensor would not "
            "be this model's")


def sensor_record_problem(rec: dict) -> str:
    """What in a record naming a sensor (``sensor``, ``sensor_file``, ``sensor_sha256``, ``transfer``) is not what
    fitgen writes there, in words ('' when nothing): each is text, and the transfer raw or gmr."""
    for key in ("sensor", "sensor_file", "sensor_sha256"):
        if key in rec and not isinstance(rec[key], str):
            return f"{key} must be text, got {rec[key]!r}"
    if "transfer" in rec and rec["transfer"] not in TRANSFERS:
        return f"transfer must be raw or gmr, got {rec['transfer']!r}"
    return ""


def recorded_spec(rec) -> str | None:
    """The sensor file or preset name a record names (``sensor``, ``sensor_file``, ``sensor_sha256``, ``transfer``: a
    dataset's meta, a model's held-out record, a schedule's drawing), where it is found here and is still that
    sensor (by hash); else None."""
    from pathlib import Path

    if not isinstance(rec, dict) or not isinstance(rec.get("sensor"), str):
        return None
    try:
        if dataset_sensor(rec) is None:
            return None
    except InputError:  # a recorded file that no longer reads as a sensor
        return None
    path = rec.get("sensor_file")
    return path if isinstance(path, str) and Path(path).is_file() else rec["sensor"]


def check_sensor_file(meta: dict, spec: str | None = None, origin: str = "the dataset", folder=None) -> None:
    """InputError when the sensor file a simulated dataset's meta names (``sensor_file``: a unit's, say) is
    missing or has changed since the data were simulated, unless ``spec`` (a --sensor) names another: without
    it :func:`dataset_sensor` finds no sensor, and a fit would lose its noise and held-out figures unsaid.
    A meta naming no file (a preset's data, measured data) passes, and so does a missing file whose sensor is
    the preset the meta names. ``folder``: the dataset's, where a file of the recorded name that is not the one
    recorded (fitgen.physics.relocate left it) is said to be another."""
    from pathlib import Path

    from fitgen.physics.sensor import preset_names

    recorded = meta.get("sensor_file")
    if not isinstance(recorded, str) or (spec is not None and Path(spec).resolve() != Path(recorded).resolve()):
        return
    sha, name = meta.get("sensor_sha256"), meta.get("sensor")
    todo = "give the file it was simulated with as --sensor, or simulate the data again"
    if not Path(recorded).is_file():
        if name in preset_names() and sha in (None, _recorded_sensor(name, meta).sha256):
            return  # the preset it was: dataset_sensor takes that
        beside = None if folder is None else Path(folder, re.split(r"[\\/]", recorded)[-1])
        other = (f", and the {beside.name} beside it is another sensor (changed since, or another unit's)"
                 if beside is not None and beside.is_file() else "")
        raise InputError(f"{origin} was simulated with sensor file {recorded}, which is missing{other}: {todo}")
    try:
        changed = sha not in (None, _recorded_sensor(recorded, meta).sha256)
    except InputError:  # it no longer reads as a sensor file
        changed = True
    if changed:
        raise InputError(f"{origin} was simulated with sensor file {recorded}, which has changed since the data "
                         f"were simulated (edited, or identify wrote another unit into it): {todo}")


def _recorded_sensor(spec: str, meta: dict) -> Sensor:
    """Sensor ``spec`` in the transfer a dataset's meta records, as :func:`dataset_sensor` compares it."""
    from fitgen.physics.sensor import load_sensor

    sensor = load_sensor(spec)
    return sensor.with_transfer(meta["transfer"]) if meta.get("transfer") in TRANSFERS else sensor
