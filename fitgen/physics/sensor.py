"""Sensor description files (TOML): magnet, board, elements and transfer model, validated."""

from __future__ import annotations

import difflib
import math
from dataclasses import dataclass, field, replace
from importlib import resources
from pathlib import Path

import numpy as np

from fitgen.base.errors import InputError, is_finite_number, shown
from fitgen.base.fileio import read_text
from fitgen.base.texts import canonical_json, load_toml, sha256_hex
from fitgen.base.parse import DEGC, MAX_NOISE
from fitgen.physics.tolerances import STIFFENING_MAX, TOLERANCE_MAX, Tolerances

AXIS_WORDS = ("radial", "tangential", "z", "-z")
TRANSFERS = ("raw", "gmr")  # a sensor file's [transfer] kinds: field in mT, or a GMR bridge's volts
# V: the most an amplifier's output or an ADC's range may reach from 0 (a GMR bridge's amplifier runs on a few
# volts; past this a file's volts are in other units, and an ADC's span past it overflows its step)
MAX_VOLTS = 100.0
# a unit file's [unit] table as fitgen simulate --unit and fitgen identify write it: each key's reader
UNIT_KEYS = {**dict.fromkeys(("drawing", "source", "posterior", "capture", "capture_sha256", "drawing_spec"), "string"),
             "seed": "integer", "reduced_chi2": "number", "capture_degc": "number", "compensated_from_degc": "number"}


@dataclass(frozen=True)
class Magnet:
    diameter: float  # mm
    height: float  # mm
    polarization: float  # T, along the magnet's own +z
    rest_center: tuple[float, float, float]  # mm (the drawing's centre plus a unit's offset)
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)  # mm, a unit's rest centre from the drawing's
    tilt: tuple[float, float] = (0.0, 0.0)  # deg, a unit's rest tilt (thx, thy), applied before a pose's


@dataclass(frozen=True)
class RawTransfer:
    noise: float = 0.0  # mT rms
    full_scale: float = 2.0  # mT
    adc_bits: int = 0


@dataclass(frozen=True)
class GmrTransfer:
    supply: float = 5.0  # V
    sensitivity: float = 2.6  # mV/V/Oe
    gain: float = 12.0
    offset: float = 0.0  # V
    saturation: float = 2.0  # mT
    adc_min: float = 0.0  # V
    adc_max: float = 3.3  # V
    adc_bits: int = 16
    noise: float = 0.0  # V rms


@dataclass(frozen=True)
class Sensor:
    """A validated sensor: geometry in mm, polarisation in T, element axes as unit vectors."""

    name: str
    description: str
    magnet: Magnet
    board_thickness: float
    board_gap: float
    positions: np.ndarray = field(repr=False)  # (N, 3) mm
    axes: np.ndarray = field(repr=False)  # (N, 3) unit
    transfer: str = "raw"
    raw: RawTransfer = RawTransfer()
    gmr: GmrTransfer = GmrTransfer()
    source: dict = field(default_factory=dict, repr=False, compare=False)
    # a built unit's own: per element gain (x the transfer's) and offset (mT, after |B . axis|), a static
    # ambient field (mT), and the map from the labels' (the stage's) displacement to the magnet's
    gains: np.ndarray | None = field(default=None, repr=False)
    offsets: np.ndarray | None = field(default=None, repr=False)
    ambient: np.ndarray | None = field(default=None, repr=False)
    stage_map: np.ndarray | None = field(default=None, repr=False)
    stiffening: float = 0.0  # 1/mm: a press dz reaches the magnet as dz (1 - stiffening |dz|), before the map
    tolerances: Tolerances = field(default=Tolerances(), compare=False)
    # how far a calibration capture may move the skin from first contact, per stage axis (dx, dy, dz: (lo, hi) mm);
    # empty: the working pose box (fitgen.physics.simulate.DEFAULT_RANGES). Not physics: not in the hash
    travel: dict = field(default_factory=dict, compare=False)

    def __post_init__(self):
        n = self.positions.shape[0]
        for name, default in (("gains", np.ones(n)), ("offsets", np.zeros(n)), ("ambient", np.zeros(3)),
                              ("stage_map", np.eye(3))):
            val = getattr(self, name)
            object.__setattr__(self, name, default if val is None else np.asarray(val, dtype=float))

    @property
    def n_elements(self) -> int:
        return int(self.positions.shape[0])

    @property
    def is_drawing(self) -> bool:
        """True when nothing of a built unit differs from the drawing's defaults."""
        return next(self._traits(), None) is None  # the first difference settles it (readings ask on every call)

    def unit_traits(self) -> list[str]:
        """What makes this a built unit rather than a drawing, as the sensor file names it (empty on a drawing):
        the magnet's offset or tilt, an element's gain other than 1 or offset other than 0, an ambient field, a
        stage map other than the identity, a stiffening."""
        return list(self._traits())

    def _traits(self):
        m = self.magnet
        for key, val in (("magnet.offset", m.offset), ("magnet.tilt", m.tilt)):
            if any(val):
                yield f"{key} {[float(v) for v in val]}"
        for key, vals, plain in (("gain", self.gains, 1.0), ("offset", self.offsets, 0.0)):
            odd = np.flatnonzero(vals != plain)
            if odd.size:
                more = f" (and {odd.size - 1} more)" if odd.size > 1 else ""
                yield f"element {odd[0] + 1}'s {key} {float(vals[odd[0]]):g}{more}"
        if np.any(self.ambient):
            yield "ambient.field"
        if not np.array_equal(self.stage_map, np.eye(3)):
            yield "stage.map"
        if self.stiffening:
            yield "stage.stiffening"

    @property
    def noise(self) -> float:
        """Element noise (rms) in the output units of the active transfer."""
        return self.raw.noise if self.transfer == "raw" else self.gmr.noise

    @property
    def units(self) -> str:
        return "mT" if self.transfer == "raw" else "V"

    def with_noise(self, noise: float) -> "Sensor":
        """The sensor with ``noise`` (rms, in its units) as its active transfer's reading noise."""
        return replace(self, **{self.transfer: replace(getattr(self, self.transfer), noise=float(noise))})

    def with_transfer(self, kind: str) -> "Sensor":
        if kind not in TRANSFERS:
            raise InputError(f"transfer must be 'raw' or 'gmr', got {kind!r}")
        return replace(self, transfer=kind)

    def to_dict(self) -> dict:
        """The normalised description: what the hash covers."""
        return {
            "name": self.name,
            "magnet": {
                "shape": "cylinder",
                "diameter": self.magnet.diameter,
                "height": self.magnet.height,
                "polarization": self.magnet.polarization,
                "rest_center": list(self.magnet.rest_center),
            },
            "board": {"thickness": self.board_thickness, "gap": self.board_gap},
            "elements": {"positions": self.positions.tolist(), "axes": self.axes.tolist()},
            "transfer": {"kind": self.transfer, "raw": vars(self.raw), "gmr": vars(self.gmr)},
        } | ({} if self.is_drawing else {"unit": {
            "magnet_tilt": list(self.magnet.tilt),
            "gains": self.gains.tolist(),
            "offsets": self.offsets.tolist(),
            "ambient": self.ambient.tolist(),
            "stage_map": self.stage_map.tolist(),
        } | ({"stiffening": self.stiffening} if self.stiffening else {})})

    @property
    def sha256(self) -> str:
        return sha256_hex(canonical_json(self.to_dict()))


# --- parsing -----------------------------------------------------------------


def _unit_vector(vec: np.ndarray) -> np.ndarray:
    """``vec`` over its length, the same bits on every machine: the sensor's hash is of them (a dataset's meta and a
    unit's posterior record it). One of length 1 within rounding (as a unit file writes it) is taken as given, its
    hash the file's; np.linalg.norm's dot product rounds by the BLAS kernel, and a unit file's axes had read as other
    bits, and another sensor, on another machine. Lengths near float's limits (1e308, 1e-320) are scaled first."""
    if abs(math.fsum(float(x) * float(x) for x in vec) - 1.0) <= 16 * np.finfo(float).eps:
        return vec
    norm = math.hypot(*vec)  # Python's own C, no BLAS
    if not np.finfo(float).tiny <= norm < np.inf:
        vec = vec / np.abs(vec).max()
        norm = math.hypot(*vec)
    return vec / norm


class _Section:
    """Reads keys from one TOML table, remembering which were used, naming keys in errors."""

    def __init__(self, data, where: str, origin: str):
        if not isinstance(data, dict):
            raise InputError(f"{origin}: '{where}' must be a table")
        self.data, self.where, self.origin, self.used = data, where, origin, set()

    def _key(self, key: str) -> str:
        return f"{self.where}.{key}" if self.where else key

    def has(self, key: str) -> bool:
        return key in self.data

    def raw(self, key: str, default=None, required=False):
        if key not in self.data:
            if required:
                near = difflib.get_close_matches(key, [k for k in self.data if isinstance(k, str)], n=1, cutoff=0.6)
                raise InputError(f"{self.origin}: missing key '{self._key(key)}'"
                                 + (f" (is '{self._key(near[0])}' a misspelling of it?)" if near else ""))
            return default
        self.used.add(key)
        return self.data[key]

    def number(self, key, default=None, *, required=False, positive=False, min_=None, max_=None) -> float:
        val = self.raw(key, default, required)
        if not is_finite_number(val):  # a TOML integer past float's range too (math.isfinite raised on it)
            raise InputError(f"{self.origin}: '{self._key(key)}' must be a finite number, got {shown(val)}")
        val = float(val)
        if positive and val <= 0:
            raise InputError(f"{self.origin}: '{self._key(key)}' must be > 0, got {val:g}")
        if min_ is not None and val < min_:
            raise InputError(f"{self.origin}: '{self._key(key)}' must be >= {min_:g}, got {val:g}")
        if max_ is not None and val > max_:
            raise InputError(f"{self.origin}: '{self._key(key)}' must be <= {max_:g}, got {val:g}")
        return val

    def integer(self, key, default=None, *, min_=None, max_=None) -> int:
        val = self.raw(key, default, required=default is None)
        if isinstance(val, bool) or not isinstance(val, int):
            raise InputError(f"{self.origin}: '{self._key(key)}' must be a whole number, got {shown(val)}")
        if (min_ is not None and val < min_) or (max_ is not None and val > max_):
            raise InputError(f"{self.origin}: '{self._key(key)}' must be in {min_}..{max_}, got {val}")
        return val

    def string(self, key, default=None, *, required=False, choices=None) -> str:
        val = self.raw(key, default, required)
        if not isinstance(val, str):
            raise InputError(f"{self.origin}: '{self._key(key)}' must be a string, got {shown(val)}")
        if choices and val not in choices:
            raise InputError(f"{self.origin}: '{self._key(key)}' must be one of {', '.join(choices)}, got {shown(val)}")
        return val

    def vector(self, key, *, required=True, unit=False) -> np.ndarray:
        val = self.raw(key, None, required)
        ok = isinstance(val, list) and len(val) == 3 and all(map(is_finite_number, val))
        if not ok:
            raise InputError(f"{self.origin}: '{self._key(key)}' must be a list of 3 finite numbers, got {shown(val)}")
        vec = np.asarray(val, dtype=float)
        if unit:
            if not vec.any():
                raise InputError(f"{self.origin}: '{self._key(key)}' must not be the zero vector")
            vec = _unit_vector(vec)
        return vec

    def sub(self, key, *, required=True) -> "_Section":
        val = self.raw(key, None, required)
        return _Section({} if val is None else val, self._key(key), self.origin)

    def finish(self):
        unknown = sorted(set(self.data) - self.used)
        if unknown:
            raise InputError(f"{self.origin}: unknown key '{self._key(unknown[0])}'")


def _ring(sec: _Section) -> tuple[np.ndarray, np.ndarray]:
    count = sec.integer("count", min_=1, max_=64)
    radius = sec.number("radius", required=True, positive=True)
    z = sec.number("z", 0.0)
    # within a turn: 1e308 + 45 is 1e308, and every element had taken the first's place
    start = math.fmod(sec.number("start", 0.0), 360.0)
    axis = sec.string("axis", "radial", choices=AXIS_WORDS)
    # a part mounted on a wedge: its in-plane axis tilted toward the board's normal
    elevation = sec.number("elevation", 0.0, min_=-90.0, max_=90.0)
    if elevation != 0.0 and axis not in ("radial", "tangential"):
        raise InputError(f"{sec.origin}: '{sec._key('elevation')}' tilts a radial or tangential axis, not '{axis}'")
    sec.finish()
    phi = np.deg2rad(start + 360.0 / count * np.arange(count))
    c, s = np.cos(phi), np.sin(phi)
    pos = np.column_stack([radius * c, radius * s, np.full(count, z)])
    axes = {
        "radial": np.column_stack([c, s, np.zeros(count)]),
        "tangential": np.column_stack([-s, c, np.zeros(count)]),
        "z": np.tile([0.0, 0.0, 1.0], (count, 1)),
        "-z": np.tile([0.0, 0.0, -1.0], (count, 1)),
    }[axis]
    if elevation != 0.0:
        e = math.radians(elevation)
        axes = math.cos(e) * axes + math.sin(e) * np.array([0.0, 0.0, 1.0])
    return pos, axes


MAX_MM, MAX_POLARIZATION, MAX_GAIN, MAX_OFFSET_MT, MAX_STAGE_MAP = 1000.0, 10.0, 1000.0, 1000.0, 10.0
MIN_MM, MIN_GAIN, MIN_ADC_SPAN = 1e-3, 1.0 / MAX_GAIN, 1e-3  # nor below: a micrometre magnet, a millivolt ADC


def _table_list(sec: _Section, key: str) -> list:
    val = sec.raw(key, [])
    if not isinstance(val, list) or not all(isinstance(v, dict) for v in val):
        raise InputError(f"{sec.origin}: '{sec._key(key)}' must be an array of tables ([[{sec._key(key)}]])")
    return val


def parse_sensor(data: dict, origin: str = "sensor") -> Sensor:
    """Validate a parsed TOML document and build a :class:`Sensor`."""
    top = _Section(data, "", origin)
    name = top.string("name", "unnamed")
    description = top.string("description", "")

    mag = top.sub("magnet")
    mag.string("shape", "cylinder", choices=("cylinder",))
    diameter = mag.number("diameter", required=True, min_=MIN_MM)
    height = mag.number("height", required=True, min_=MIN_MM)
    pol = mag.number("polarization", 1.32)
    if pol == 0:
        raise InputError(f"{origin}: 'magnet.polarization' must not be 0")
    offset = tuple(mag.vector("offset", required=False)) if mag.has("offset") else (0.0, 0.0, 0.0)
    tilt = tuple(_numbers(mag, "tilt", 2)) if mag.has("tilt") else (0.0, 0.0)
    if max(abs(t) for t in tilt) > 45:
        raise InputError(f"{origin}: 'magnet.tilt' must be within +-45 deg, got {list(tilt)}")
    mag.finish()

    board = top.sub("board")
    thickness = board.number("thickness", required=True, min_=0.0)
    gap = board.number("gap", required=True, positive=True)
    board.finish()
    rest_center = tuple(float(c) for c in np.add((0.0, 0.0, thickness + gap + height / 2), offset))

    el = top.sub("elements")
    positions, axes, gains, offsets = [], [], [], []
    for i, ring in enumerate(_table_list(el, "ring")):
        p, a = _ring(_Section(ring, f"elements.ring[{i}]", origin))
        positions.append(p)
        axes.append(a)
        gains += [1.0] * len(p)
        offsets += [0.0] * len(p)
    for i, item in enumerate(_table_list(el, "list")):
        sec = _Section(item, f"elements.list[{i}]", origin)
        positions.append(sec.vector("position")[None])
        axes.append(sec.vector("axis", unit=True)[None])
        gains.append(sec.number("gain", 1.0, min_=MIN_GAIN))
        offsets.append(sec.number("offset", 0.0))
        sec.finish()
    el.finish()
    if not positions:
        raise InputError(f"{origin}: 'elements' must have at least one [[elements.ring]] or [[elements.list]]")
    positions = np.vstack(positions)
    axes = np.vstack(axes)
    amb = top.sub("ambient", required=False)
    ambient = amb.vector("field", required=False) if amb.has("field") else np.zeros(3)
    amb.finish()
    st = top.sub("stage", required=False)
    stage_map = np.eye(3)
    if st.has("map"):
        rows = st.raw("map")
        if not isinstance(rows, list) or len(rows) != 3:
            raise InputError(f"{origin}: 'stage.map' must be 3 rows of 3 numbers (magnet displacement = map x "
                             "stage displacement)")
        stage_map = np.array([_numbers(_Section({"row": r}, "stage.map", origin), "row", 3) for r in rows])
    # past these no sensor is described, and the field's arithmetic overflows (a slip of the exponent)
    for what, values, limit, unit in (
            ("the magnet's size, the board's and the elements' places", [diameter, height, thickness, gap, *offset,
                                                                         *positions.ravel()], MAX_MM, " mm"),
            ("'magnet.polarization'", [pol], MAX_POLARIZATION, " T"), ("each element's gain", gains, MAX_GAIN, ""),
            ("each element's offset", offsets, MAX_OFFSET_MT, " mT"),
            ("'ambient.field'", ambient, MAX_OFFSET_MT, " mT"), ("'stage.map'", stage_map, MAX_STAGE_MAP, "")):
        if (worst := float(np.max(np.abs(values)))) > limit:
            raise InputError(f"{origin}: {what} must be within +-{limit:g}{unit}, got {worst:g}")
    if not abs(np.linalg.det(stage_map)) > 1e-6:
        raise InputError(f"{origin}: 'stage.map' is singular: the magnet would not follow the stage")
    stiffening = st.number("stiffening", 0.0, min_=-STIFFENING_MAX, max_=STIFFENING_MAX)
    st.finish()
    tol = top.sub("tolerances", required=False)
    tolerances = Tolerances(**{k: tol.number(k, v, min_=0.0, max_=TOLERANCE_MAX[k])
                               for k, v in vars(Tolerances()).items()})
    tol.finish()
    travel = _travel(top.sub("travel", required=False), gap)
    unit = top.sub("unit", required=False)  # provenance of a unit file (fitgen simulate --unit, fitgen identify)
    for key, kind in UNIT_KEYS.items():  # a key misspelt had been lost in silence: a posterior, a temperature
        if unit.has(key):
            getattr(unit, kind)(key, **({"min_": DEGC[0], "max_": DEGC[1]} if key.endswith("_degc") else {}))
    unit.finish()

    radius = diameter / 2
    for k, p in enumerate(positions, start=1):
        r = math.hypot(p[0] - rest_center[0], p[1] - rest_center[1])
        if r <= radius and abs(p[2] - rest_center[2]) <= height / 2:
            raise InputError(f"{origin}: element {k} at {p.tolist()} lies inside the magnet")
    dist = np.linalg.norm(positions[:, None] - positions[None], axis=-1) + np.eye(len(positions))
    if np.any(dist < 1e-9):
        k = int(np.argwhere(dist < 1e-9)[0][0]) + 1
        raise InputError(f"{origin}: element {k} shares its position with another element")

    tr = top.sub("transfer")
    kind = tr.string("kind", "raw", choices=TRANSFERS)
    rs = tr.sub("raw", required=False)
    raw = RawTransfer(
        noise=rs.number("noise", 0.0, min_=0.0, max_=MAX_NOISE),  # more overflows a fit's variance
        full_scale=rs.number("full_scale", 2.0, positive=True),
        adc_bits=rs.integer("adc_bits", 0, min_=0, max_=32),
    )
    rs.finish()
    gs = tr.sub("gmr", required=False)
    gmr = GmrTransfer(
        supply=gs.number("supply", 5.0, positive=True, max_=MAX_VOLTS),
        sensitivity=gs.number("sensitivity", 2.6, min_=1e-6, max_=1e6),  # mV/V/Oe: the AA003-02's is 2.0-3.2
        gain=gs.number("gain", 12.0, min_=1e-6, max_=1e6),
        offset=gs.number("offset", 0.0, min_=-MAX_VOLTS, max_=MAX_VOLTS),
        saturation=gs.number("saturation", 2.0, min_=1e-6, max_=MAX_OFFSET_MT),
        adc_min=gs.number("adc_min", 0.0, min_=-MAX_VOLTS, max_=MAX_VOLTS),
        adc_max=gs.number("adc_max", 3.3, min_=-MAX_VOLTS, max_=MAX_VOLTS),
        adc_bits=gs.integer("adc_bits", 16, min_=0, max_=32),
        noise=gs.number("noise", 0.0, min_=0.0, max_=MAX_NOISE),
    )
    gs.finish()
    if not gmr.adc_max - gmr.adc_min >= MIN_ADC_SPAN:
        raise InputError(f"{origin}: 'transfer.gmr.adc_max' must be at least {MIN_ADC_SPAN:g} V above "
                         f"'transfer.gmr.adc_min'")
    tr.finish()
    top.finish()

    return Sensor(
        name=name,
        description=description,
        magnet=Magnet(diameter, height, pol, rest_center, offset, tilt),
        board_thickness=thickness,
        board_gap=gap,
        positions=positions,
        axes=axes,
        transfer=kind,
        raw=raw,
        gmr=gmr,
        source=data,
        gains=np.array(gains),
        offsets=np.array(offsets),
        ambient=ambient,
        stage_map=stage_map,
        stiffening=stiffening,
        tolerances=tolerances,
        travel=travel,
    )


TRAVEL_AXES = ("dx", "dy", "dz")
TRAVEL_MAX = 20.0  # mm: no press moves the skin further (identify refuses labels beyond it, capturecheck.FARTHEST)


def _travel(sec: _Section, gap: float) -> dict:
    """``[travel]``: per stage axis a ``[lo, hi]`` in mm from first contact that holds 0; dz at most 0 (above
    first contact the indenter leaves the skin: the schedule's rest row is its own) and above -gap (the magnet
    would reach the board)."""
    out = {}
    for a in TRAVEL_AXES:
        if not sec.has(a):
            continue
        lo, hi = _numbers(sec, a, 2)
        where = f"{sec.origin}: 'travel.{a}'"
        if not (lo < hi and lo <= 0.0 <= hi and max(-lo, hi) <= TRAVEL_MAX):
            raise InputError(f"{where} must be [lo, hi] in mm from first contact with lo < hi, 0 between them and "
                             f"both within {TRAVEL_MAX:g} mm, got {[lo, hi]}")
        if a == "dz" and (hi > 0.0 or lo <= -gap):
            raise InputError(f"{where} must lie within ({-gap:g}, 0] mm: above 0 the indenter is off the skin "
                             f"(the schedule lifts its rest row by itself), at -{gap:g} the magnet meets the board; "
                             f"got {[lo, hi]}")
        out[a] = (lo, hi)
    sec.finish()
    return out


def _numbers(sec: _Section, key: str, n: int) -> list[float]:
    val = sec.raw(key, None, True)
    if not (isinstance(val, list) and len(val) == n and all(map(is_finite_number, val))):
        raise InputError(f"{sec.origin}: '{sec._key(key)}' must be a list of {n} finite numbers, got {shown(val)}")
    return [float(v) for v in val]


def preset_names() -> list[str]:
    return sorted(p.name[:-5] for p in resources.files("fitgen.physics.presets").iterdir() if p.name.endswith(".toml"))


def load_sensor(spec: str | Path) -> Sensor:
    """Load a sensor from a preset name (``paper``) or a TOML file path."""
    spec = str(spec)
    if spec in preset_names():
        text = resources.files("fitgen.physics.presets").joinpath(f"{spec}.toml").read_text()
        origin = f"preset {spec}"
    else:
        path = Path(spec)
        if path.is_dir():
            raise InputError(f"sensor {spec!r}: a folder, not a sensor file (a TOML file, or a preset: "
                             f"{', '.join(preset_names())})")
        # a pipe (<(cat unit.toml)) reads once, and a dataset's meta names the file that fit reads again
        if path.exists() and not path.is_file():
            raise InputError(f"sensor {spec!r}: not a regular file (a pipe or a device): give the sensor file's path")
        if not path.is_file():
            raise InputError(f"sensor {spec!r}: no such file, and not a preset ({', '.join(preset_names())})")
        text = read_text(path, "sensor file")
        origin = f"sensor file {spec}"
    return parse_sensor(load_toml(text, origin, "sensor file"), origin)
