"""Built units: how one differs from its drawing, as a parameter vector; units drawn within tolerances;
the readings of many units at once; unit files.

A unit's parameters, relative to its drawing (:class:`UnitSpace`, in this order):

- the magnet's rest offset x, y, z (mm), rest tilt thx, thy (deg), log of its polarisation over the
  drawing's;
- per element k: azimuth and radius about the board's centre (deg, mm; on the centre itself, shifts along
  y and x, mm, both with the radius's spread), height (mm), its sensitive
  axis turned about the board's normal and raised out of its plane (deg; for an axis along the
  normal, turned about x and y), log gain, offset (mT, after |B . axis|);
- a static ambient field x, y, z (mT);
- the stage-to-magnet map M - I (9, row by row): the magnet moves by M (dx, dy, dz) when the stage,
  whose displacement the labels record, moves by (dx, dy, dz); a label lifted off the skin
  (fitgen.physics.pose.contact_poses) leaves the magnet at rest;
- where the drawing's tolerances allow for it, the elastomer's stiffening c (1/mm): a press dz reaches the
  magnet as dz (1 - c |dz|) before M (fitgen.physics.pose.pressed).

Every parameter is 0 on the drawing. Its spread is the sensor file's ``[tolerances]``
(:class:`fitgen.physics.tolerances.Tolerances`); :func:`draw_unit` draws each normal, clipped at 3 sigma.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import NamedTuple

import numpy as np

from fitgen.base.errors import InputError, check_seed
from fitgen.physics.field import cylinder_projection
from fitgen.base.fileio import write_atomic
from fitgen.base.texts import tomllib
from fitgen.physics.pose import as_poses, contact_poses, pressed, rotation_matrices
from fitgen.physics.sensor import Magnet, Sensor, parse_sensor
from fitgen.physics.tolerances import Tolerances
from fitgen.physics.transfer import volts_per_mt

MAGNET = ("magnet.x", "magnet.y", "magnet.z", "magnet.thx", "magnet.thy", "magnet.log_polarization")
ELEMENT = ("azimuth", "radius", "height", "turn", "tilt", "log_gain", "offset")
AMBIENT = ("ambient.x", "ambient.y", "ambient.z")
STAGE = tuple(f"stage.m{i}{j}" for i in range(1, 4) for j in range(1, 4))
STIFFENING = "stage.stiffening"  # a parameter only where the drawing's tolerance allows for it (not 0)
# mT/mm: the field the stage carries, component c per mm of its move along a; the capture's, not the unit's (its
# sensor() leaves it out); parameters only where the drawing's tolerance allows for it
FIELD = tuple(f"stage_field.{c}_d{a}" for c in "xyz" for a in "xyz")
CLIP_SIGMA = 3.0
CENTRE_MM = 1e-6  # an element this near the board's centre has no azimuth (its places: x and y shifts)


def _on_centre(drawing: Sensor) -> np.ndarray:
    """Per element (bool): on the board's centre, where a place has no azimuth."""
    return np.hypot(drawing.positions[:, 0], drawing.positions[:, 1]) < CENTRE_MM


def _axis_bases(axes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per axis a, unit vectors u1 (turn: about the board's normal) and u2 (tilt: out of the plane)."""
    z = np.array([0.0, 0.0, 1.0])
    u1 = np.cross(z, axes)
    small = np.linalg.norm(u1, axis=1) < 1e-9
    u1[small] = [1.0, 0.0, 0.0]  # an axis along the normal: turn about x, tilt about y
    u1 /= np.linalg.norm(u1, axis=1, keepdims=True)
    u2 = np.cross(axes, u1)
    return u1, u2


def require_drawing(drawing: Sensor) -> None:
    """InputError unless ``drawing`` is a drawing, not a built unit (whose parameters a unit is drawn around)."""
    if drawing.is_drawing:
        return
    unit = drawing.source.get("unit") if isinstance(drawing.source, dict) else None
    named = (unit.get("drawing_spec") or unit.get("drawing")) if isinstance(unit, dict) else None
    if isinstance(named, str):
        raise InputError(f"sensor {drawing.name!r} is a built unit, not a drawing: give the drawing it was "
                         f"built to ({named}, as its [unit] table says)")
    # no [unit] table: most likely a drawing written with a unit's keys
    traits = "; ".join(drawing.unit_traits())
    raise InputError(f"sensor {drawing.name!r} is a built unit, not a drawing ({traits}; a drawing's elements "
                     "have gain 1 and offset 0, and it has no magnet offset or tilt, ambient field or stage "
                     "map): give the drawing it was built to, or leave those keys out, which a unit draws "
                     "within [tolerances]")


@dataclass(frozen=True)
class UnitSpace:
    """The units of one drawing: parameter names, their prior spreads, and the readings they give."""

    drawing: Sensor
    names: tuple[str, ...]
    prior_sd: np.ndarray

    @classmethod
    def of(cls, drawing: Sensor, tolerances: Tolerances | None = None) -> "UnitSpace":
        require_drawing(drawing)
        t = tolerances or drawing.tolerances
        n = drawing.n_elements
        stiff = (STIFFENING,) if t.stiffening > 0 else ()  # absent, the space (and its records) are as before
        moving = FIELD if t.stage_field > 0 else ()
        names = (MAGNET + tuple(f"e{k}.{p}" for k in range(1, n + 1) for p in ELEMENT) + AMBIENT + STAGE + stiff
                 + moving)
        per_el = [[t.element_radius if c else t.element_azimuth, t.element_radius, t.element_height, t.element_axis,
                   t.element_tilt, math.log1p(t.gain), t.offset] for c in _on_centre(drawing)]
        sd = ([t.magnet_offset_xy, t.magnet_offset_xy, t.magnet_offset_z, t.magnet_tilt, t.magnet_tilt,
               math.log1p(t.polarization)] + [x for el in per_el for x in el] + [t.ambient] * 3
              + [t.stage_gain if i == j else t.stage_cross for i in range(3) for j in range(3)]
              + [t.stiffening] * len(stiff) + [t.stage_field] * len(moving))
        return cls(drawing, names, np.array(sd, dtype=float))

    @property
    def size(self) -> int:
        return len(self.names)

    def index(self, name: str) -> int:
        return self.names.index(name)

    # --- the unit's geometry from parameters -------------------------------------------------

    def _parts(self, thetas: np.ndarray) -> dict:
        """Each unit's magnet, elements, ambient field and stage map, batched over rows of thetas (K, P)."""
        d = self.drawing
        th = np.atleast_2d(np.asarray(thetas, dtype=float))
        if th.shape[1] != self.size:
            raise InputError(f"a unit of {d.name!r} has {self.size} parameters, got {th.shape[1]}")
        n = d.n_elements
        el = th[:, 6:6 + 7 * n].reshape(-1, n, 7)
        r0 = np.hypot(d.positions[:, 0], d.positions[:, 1])
        phi = np.arctan2(d.positions[:, 1], d.positions[:, 0]) + np.deg2rad(el[..., 0])
        r = r0 + el[..., 1]
        # an element on the board's centre has no azimuth: its two places are shifts along x and y (mm)
        centre = _on_centre(d)
        x = np.where(centre, d.positions[:, 0] + el[..., 1], r * np.cos(phi))
        y = np.where(centre, d.positions[:, 1] + el[..., 0], r * np.sin(phi))
        pos = np.stack([x, y, d.positions[:, 2] + el[..., 2]], axis=-1)
        u1, u2 = _axis_bases(d.axes)
        ax = (d.axes + np.tan(np.deg2rad(el[..., 3]))[..., None] * u1
              + np.tan(np.deg2rad(el[..., 4]))[..., None] * u2)
        ax /= np.linalg.norm(ax, axis=-1, keepdims=True)
        rest = np.asarray(d.magnet.rest_center) + th[:, 0:3]
        tail = 6 + 7 * n
        stiff = STIFFENING in self.names
        k = tail + 12 + stiff
        return {"pos": pos, "axes": ax, "rest": rest, "offset": th[:, 0:3], "tilt": th[:, 3:5],
                "pol": d.magnet.polarization * np.exp(th[:, 5]), "gain": np.exp(el[..., 5]), "off": el[..., 6],
                "ambient": th[:, tail:tail + 3], "map": np.eye(3) + th[:, tail + 3:tail + 12].reshape(-1, 3, 3),
                "stiffening": th[:, tail + 12] if stiff else np.zeros(len(th)),
                "field": th[:, k:k + 9].reshape(-1, 3, 3) if self.moving_field else np.zeros((len(th), 3, 3))}

    @property
    def moving_field(self) -> bool:
        """Whether the space holds a field the stage carries (the drawing's tolerance allows for one)."""
        return FIELD[0] in self.names

    def sensor(self, theta, name: str | None = None, description: str = "") -> Sensor:
        """The unit with parameters ``theta`` as a :class:`Sensor`: its readings are :meth:`readings`' less the field
        the stage carries, which is the capture's, not the unit's."""
        p = {k: v[0] for k, v in self._parts(np.asarray(theta, dtype=float)[None]).items()}
        d = self.drawing
        mag = Magnet(d.magnet.diameter, d.magnet.height, float(p["pol"]), tuple(float(c) for c in p["rest"]),
                     tuple(float(c) for c in p["offset"]), tuple(float(c) for c in p["tilt"]))
        return replace(d, name=name or f"{d.name}-unit", description=description, magnet=mag, positions=p["pos"],
                       axes=p["axes"], gains=p["gain"], offsets=p["off"], ambient=p["ambient"],
                       stage_map=p["map"], stiffening=float(p["stiffening"]), source={})

    def readings(self, thetas: np.ndarray, poses, clipped: bool = True) -> np.ndarray:
        """Noise-free readings (K, n, N) of K units (rows of ``thetas``) at n poses, in the transfer's units,
        without the ADC's quantisation (a gmr reading, or a quantised raw one, is clipped to the ADC's range);
        ``clipped=False``: the reading as if neither the element saturated nor the ADC had rails (the line its
        slope follows)."""
        d = self.drawing
        stage = as_poses(poses)[:, :3]  # where the stage is, a lifted indenter's rows too: the field it carries
        poses = contact_poses(as_poses(poses))
        p = self._parts(thetas)
        R = rotation_matrices(poses[:, 3], poses[:, 4])[None] @ rotation_matrices(p["tilt"][:, 0], p["tilt"][:, 1])[:, None]
        if np.any(p["stiffening"]):
            shift = pressed(np.broadcast_to(poses[:, :3], (len(p["map"]), len(poses), 3)), p["stiffening"][:, None])
            centre = p["rest"][:, None, :] + np.einsum("knj,kij->kni", shift, p["map"])
        else:  # the sum as it always was: a unit space that does not stiffen reads as before to the last bit
            centre = p["rest"][:, None, :] + np.einsum("nj,kij->kni", poses[:, :3], p["map"])
        rel = p["pos"][:, None, :, :] - centre[:, :, None, :]
        local = np.einsum("knmj,knjl->knml", rel, R)
        axes = np.einsum("kmj,knjl->knml", p["axes"], R)
        b = cylinder_projection(local.reshape(-1, 3), axes.reshape(-1, 3), d.magnet.diameter, d.magnet.height,
                                1e3).reshape(local.shape[:3])
        b = b * p["pol"][:, None, None] + np.einsum("kmj,kj->km", p["axes"], p["ambient"])[:, None, :]
        if self.moving_field:
            b = b + np.einsum("kmi,kij,nj->knm", p["axes"], p["field"], stage)
        mag = np.abs(b)
        if d.transfer == "raw":  # quantised, its ADC clips at 0 and the full scale (fitgen.physics.transfer)
            out = p["gain"][:, None, :] * mag + p["off"][:, None, :]
            return np.clip(out, 0.0, d.raw.full_scale) if clipped and d.raw.adc_bits > 0 else out
        g = d.gmr
        field = p["gain"][:, None, :] * (np.minimum(mag, g.saturation) if clipped else mag) + p["off"][:, None, :]
        out = g.offset + volts_per_mt(g) * field
        return np.clip(out, g.adc_min, g.adc_max) if clipped else out

    @property
    def free(self) -> np.ndarray:
        """Which parameters vary between units (spread > 0); one with spread 0 is the drawing's."""
        return self.prior_sd > 0

    def in_spreads(self, theta: np.ndarray) -> np.ndarray:
        """``theta`` in units of the prior's spreads; 0 where a spread is 0."""
        theta = np.asarray(theta, dtype=float)
        return np.divide(theta, self.prior_sd, out=np.zeros(np.broadcast_shapes(theta.shape, self.prior_sd.shape)),
                         where=self.free)

    def draw(self, rng: np.random.Generator) -> np.ndarray:
        """One unit's parameters: each normal with its prior spread, clipped at 3 sigma."""
        return np.clip(rng.standard_normal(self.size), -CLIP_SIGMA, CLIP_SIGMA) * self.prior_sd


def draw_unit(drawing: Sensor, seed: int) -> tuple[Sensor, np.ndarray]:
    """A unit of ``drawing`` drawn within its tolerances (seed ``seed``), and its parameters."""
    check_seed(seed, "a unit's seed")
    space = UnitSpace.of(drawing)
    theta = space.draw(np.random.default_rng(np.random.SeedSequence([seed, 0x756E6974])))
    unit = space.sensor(theta, f"{drawing.name}-unit-{seed}",
                        f"a unit of {drawing.name} drawn within its tolerances (seed {seed})")
    return unit, theta


class Symmetry(NamedTuple):
    """A turn or mirror through the drawing's axis that carries every element onto another's place."""

    what: str  # e.g. "turned by 90 deg about z", "mirrored across the line at 45 deg from +x"
    order: np.ndarray  # (N,): element k goes onto the place of element order[k]
    matrix: np.ndarray  # (3, 3): the turn or mirror, acting on positions and on poses' displacements


def symmetries(drawing: Sensor) -> list[Symmetry]:
    """The drawing's symmetries about its axis, the identity left out: every turn about z and mirror through z
    that carries each element onto another's place, axis (either sign: the elements are omnipolar), gain and
    offset, to 1e-3 of the ring's size (a sensor file's places written to a few decimals). The drawing's readings
    at a pose whose displacement is turned by ``matrix``, taken as ``y[:, order]``, are its readings at the pose."""
    pos, n = drawing.positions, drawing.n_elements
    scale = max(float(np.abs(pos).max()), 1.0)
    out = []
    for mirror in (False, True):
        for k in range(int(not mirror), n):
            a = 2.0 * math.pi * k / n  # a mirror's line at a / 2 from +x
            c, s = math.cos(a), math.sin(a)
            m = np.array([[c, s, 0.0], [s, -c, 0.0], [0.0, 0.0, 1.0]] if mirror
                         else [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
            near = np.linalg.norm((pos @ m.T)[:, None] - pos[None], axis=2) < 1e-3 * scale
            order = np.argmax(near, axis=1)
            same = (np.allclose(np.abs(np.sum((drawing.axes @ m.T) * drawing.axes[order], axis=1)), 1.0, atol=1e-3)
                    and np.allclose(drawing.gains[order], drawing.gains, rtol=1e-6)
                    and np.allclose(drawing.offsets[order], drawing.offsets, rtol=1e-6, atol=1e-9))
            if (near.sum(axis=1) == 1).all() and len(set(order.tolist())) == n and same:
                deg = math.degrees(a)
                out.append(Symmetry(f"mirrored across the line at {deg / 2:g} deg from +x" if mirror
                                    else f"turned by {deg:g} deg about z", order, m))
    return out


# --- unit files ----------------------------------------------------------------------------------


def _num(x: float) -> str:
    return repr(float(x))


def _vec(v) -> str:
    return "[" + ", ".join(_num(x) for x in v) + "]"


def unit_toml(unit: Sensor, drawing: str, provenance: dict | None = None) -> str:
    """The sensor file of a built unit: every element as a list entry with its gain and offset, the magnet's
    offset and tilt, the ambient field, the stage map, the tolerances and the travel. Numbers round-trip."""
    m = unit.magnet
    lines = [f"# A built unit of the drawing {drawing!r}: fitgen reads it as any sensor file (--sensor).",
             f"name = {_quote(unit.name)}", f"description = {_quote(unit.description)}", "", "[unit]",
             f"drawing = {_quote(drawing)}"]
    for k, v in (provenance or {}).items():
        lines.append(f"{k} = {_quote(v) if isinstance(v, str) else v if isinstance(v, int) else _num(v)}")
    lines += ["", "[magnet]", 'shape = "cylinder"', f"diameter = {_num(m.diameter)}", f"height = {_num(m.height)}",
              f"polarization = {_num(m.polarization)}  # T", f"offset = {_vec(m.offset)}  # mm, rest centre from the drawing's",
              f"tilt = {_vec(m.tilt)}  # deg, rest thx, thy", "", "[board]", f"thickness = {_num(unit.board_thickness)}",
              f"gap = {_num(unit.board_gap)}"]
    for k in range(unit.n_elements):
        p, a = unit.positions[k], unit.axes[k]
        az, r = math.degrees(math.atan2(p[1], p[0])), math.hypot(p[0], p[1])
        lines += ["", f"[[elements.list]]  # element {k + 1}: azimuth {az:.4f} deg, radius {r:.4f} mm",
                  f"position = {_vec(p)}", f"axis = {_vec(a)}", f"gain = {_num(unit.gains[k])}",
                  f"offset = {_num(unit.offsets[k])}  # mT"]
    lines += ["", "[ambient]", f"field = {_vec(unit.ambient)}  # mT", "", "[stage]",
              "# magnet displacement = map x stage displacement (the labels are the stage's)",
              "map = [" + ", ".join(_vec(row) for row in unit.stage_map) + "]"]
    if unit.stiffening:
        lines.append(f"stiffening = {_num(unit.stiffening)}  # 1/mm: a press dz reaches the magnet as dz (1 - c |dz|)")
    lines += ["", "[transfer]",
              f"kind = {_quote(unit.transfer)}", "", "[transfer.raw]"]
    lines += [f"{k} = {_num(v) if isinstance(v, float) else v}" for k, v in vars(unit.raw).items()]
    lines += ["", "[transfer.gmr]"]
    lines += [f"{k} = {_num(v) if isinstance(v, float) else v}" for k, v in vars(unit.gmr).items()]
    lines += ["", "[tolerances]  # standard deviations (docs/calibration.md)"]
    lines += [f"{k} = {_num(v)}" for k, v in unit.tolerances.to_dict().items()]
    if unit.travel:
        lines += ["", "[travel]  # mm from first contact: how far a calibration capture may move the skin"]
        lines += [f"{k} = {_vec(v)}" for k, v in unit.travel.items()]
    return "\n".join(lines) + "\n"


def _quote(s: str) -> str:
    return '"' + str(s).replace("\\", "\\\\").replace('"', '\\"') + '"'


def unit_path(data_path: str | Path) -> Path:
    """Where a dataset's unit file goes: beside it, ``<stem>.unit.toml`` for a ``.csv``, else its whole name and
    ``.unit.toml`` (``run.1`` and ``run.2`` would share ``run.unit.toml``)."""
    return beside_as(data_path, ".csv", ".unit.toml")


def beside_as(path: str | Path, suffix: str, new: str) -> Path:
    """The file beside ``path`` with its ``suffix`` replaced by ``new``, or ``new`` added where it has another
    suffix: names that differ only past their last dot keep files of their own."""
    path = Path(path)
    return path.with_suffix(new) if path.suffix in ("", suffix) else path.with_name(path.name + new)


def write_unit(path: str | Path, unit: Sensor, drawing: str, provenance: dict | None = None) -> Path:
    return write_atomic(path, unit_toml(unit, drawing, provenance))


def unit_beside(drawing: Sensor, seed: int, data_path: str | Path) -> tuple[Sensor, Path, str, dict]:
    """A unit of ``drawing`` drawn with ``seed`` for the dataset ``data_path``: read back from its file's text,
    so that data simulated with it and the file agree to the last bit; the unit (in the drawing's transfer), the
    file's path beside the data (:func:`unit_path`), its text, and the dataset meta that names it. Nothing is
    written: the file goes with the data (``Dataset.save(..., beside=...)``), so that a refusal keeps the old."""
    unit, _ = draw_unit(drawing, seed)
    path = unit_path(data_path)
    text = unit_toml(unit, drawing.name,
                     {"seed": seed, "source": "drawn within the drawing's tolerances (fitgen simulate --unit)"})
    info = {"sensor_file": str(path.resolve()), "unit_seed": seed, "drawing": drawing.name}
    return parse_sensor(tomllib.loads(text), f"sensor file {path}").with_transfer(drawing.transfer), path, text, info
