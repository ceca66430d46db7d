"""Temperature: a thermistor on a spare ADC input, and per-element offset and gain compensation.

A GMR bridge's offset and sensitivity move with temperature. With element k reading
r_k(T) = v_k (1 + g_k (T - t0)) + o_k (T - t0) for the reading v_k it gives at the
calibration temperature t0, the compensation is v_k = (r_k - o_k (T - t0)) / (1 + g_k (T - t0)),
applied before the model, on the host (:meth:`TempComp.apply`) and in the generated C
(:func:`render_c`, the same operations in the same order).

The coefficients are fitted per element by least squares from captures of the same poses at
several temperatures: r_k(T) - v_k = g_k v_k (T - t0) + o_k (T - t0), v_k being the mean reading
of that pose at the temperature closest to t0. Two poses or more are needed to tell gain from
offset; with one (rest only) the gain is taken as 0.

Thermistor: an NTC (beta model) to ground with a series resistor to the reference, read as a
voltage on a spare ADC input named in the channel map: ``--adc ads1115@0x48:0-3,ads1115@0x49:0-3,temp=ads1115@0x4a:0``,
its divider with ``--thermistor beta=3950,r25=10000,series=10000,vref=3.3``.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import ClassVar

import numpy as np

from fitgen.base.errors import InputError, finite_number, is_finite_number
from fitgen.base.fileio import read_text, write_atomic
from fitgen.base.parse import DEGC

DIVIDER_KEYS = ("beta", "r25", "series", "vref")
DIVIDER_DEFAULTS = {"beta": 3950.0, "r25": 10_000.0, "series": 10_000.0, "vref": 3.3}
# what an NTC divider's parts can be, widely: beta 2000-5000 K, 1 kohm-1 Mohm at 25 degC, a reference under 6 V
DIVIDER_RANGES = {"beta": (500.0, 20_000.0), "r25": (1.0, 1e9), "series": (1.0, 1e9), "vref": (0.1, 50.0)}
DIVIDER_UNITS = {"beta": "K", "r25": "ohm", "series": "ohm", "vref": "V"}
READ_EVERY = 0.25  # s between thermistor reads: temperature moves slowly, conversions cost bus time
T_RANGE = DEGC  # degC: an NTC thermistor's usual rated range; a compensation must stay meaningful wherever it reads
FLOAT_MAX = float(np.finfo(np.float32).max)  # tempcomp-c's default header holds every coefficient as a float


@dataclass(frozen=True)
class TemperatureInput:
    """Where the thermistor is (chip kind, address, single-ended input) and its divider."""

    kind: str
    address: int
    input: int
    divider: dict = field(default_factory=lambda: dict(DIVIDER_DEFAULTS))

    def degc(self, volts: float) -> float:
        """The temperature of a divider voltage (inverse of host.simsensor.ntc_volts)."""
        d = self.divider
        if not 0.0 < volts < d["vref"]:
            return math.nan  # open or shorted thermistor
        r = d["series"] * volts / (d["vref"] - volts)
        return 1.0 / (1.0 / 298.15 + math.log(r / d["r25"]) / d["beta"]) - 273.15


def split_channel_map(spec: str) -> tuple[str, str | None]:
    """``--adc`` without its ``temp=CHIP@ADDRESS:INPUT`` item, and that item's value (None without one)."""
    parts = [p.strip() for p in spec.split(",")]
    temps = [p for p in parts if p.lower().startswith("temp=")]
    if len(temps) > 1:
        raise InputError(f"--adc {spec!r}: one temp= input at most")
    if temps and len(temps) == len([p for p in parts if p]):
        raise InputError(f"--adc {spec!r}: no element inputs besides the thermistor (e.g. "
                         f"ads1115@0x48:0-3,ads1115@0x49:0-3,{temps[0]})")
    return ",".join(p for p in parts if not p.lower().startswith("temp=")), (temps[0][5:] if temps else None)


def thermistor_given(args, cmap) -> bool:
    """Whether the options name a thermistor (temp= in --adc, one in the map file, --thermistor): refused by a
    command that reads the elements only, rather than ignored."""
    return split_channel_map(args.adc)[1] is not None or cmap.temperature is not None or bool(args.thermistor)


def parse_temperature_input(spec: str, thermistor: str | None = None, divider: dict | None = None) -> TemperatureInput:
    """``ads1115@0x4a:0`` (or ``ads7828@0x48:7``) and ``beta=3950,r25=10000,series=10000,vref=3.3``."""
    from fitgen.base.parse import parse_assignments

    from host.channelmap import ADDRESSES, N_INPUTS

    head, _, inp = spec.strip().partition(":")
    kind, _, addr = head.partition("@")
    kind = kind.lower()
    if kind not in N_INPUTS or not addr or not inp:
        raise InputError(f"temp={spec!r} in --adc: expected CHIP@ADDRESS:INPUT, e.g. temp=ads1115@0x4a:0")
    try:
        address, pin = int(addr, 0), int(inp)
    except ValueError:
        raise InputError(f"temp={spec!r} in --adc: the address and input must be numbers") from None
    if address not in ADDRESSES:
        raise InputError(f"temp={spec!r} in --adc: address 0x{address:02x} is not one of "
                         f"{', '.join(f'0x{a:02x}' for a in ADDRESSES)}")
    if not 0 <= pin < N_INPUTS[kind]:
        raise InputError(f"temp={spec!r} in --adc: {kind} has inputs 0-{N_INPUTS[kind] - 1}")
    told = parse_assignments(thermistor, DIVIDER_KEYS, "--thermistor") if thermistor else {}
    divider = {**DIVIDER_DEFAULTS, **(divider or {}), **told}
    bad = next((k for k, v in divider.items() if not DIVIDER_RANGES[k][0] <= v <= DIVIDER_RANGES[k][1]), None)
    if bad:  # outside them a reading is nonsense, and the warning it raises blames the wiring; a map's too
        lo, hi = DIVIDER_RANGES[bad]
        where = f"--thermistor {thermistor!r}" if bad in told else "the channel map's [temperature]"
        raise InputError(f"{where}: {bad} must be {lo:g}..{hi:g} {DIVIDER_UNITS[bad]}, got {divider[bad]:g}")
    return TemperatureInput(kind, address, pin, divider)


def temperature_input(adc: str, cmap, thermistor: str | None = None) -> TemperatureInput | None:
    """The thermistor's input and divider: ``temp=`` in the ``--adc`` spec, else the TOML map's
    ``[temperature]`` (``cmap.temperature``); None without one (then ``thermistor`` is refused)."""
    spec = split_channel_map(adc)[1]
    if spec is not None:
        return check_beside(parse_temperature_input(spec, thermistor), cmap)
    if cmap.temperature is not None:
        return check_beside(parse_temperature_input(cmap.temperature[0], thermistor, cmap.temperature[1]), cmap,
                            "the channel map's [temperature]")
    if thermistor:
        raise InputError("--thermistor describes the temperature input: add temp=CHIP@ADDRESS:INPUT to --adc")
    return None


def check_beside(tin: TemperatureInput, cmap, where: str = "temp= in --adc") -> TemperatureInput:
    """``tin`` if it can be read beside the elements of ``cmap``: on an input of its own, a chip of one kind,
    in single-shot mode; InputError otherwise (naming ``where`` the input was given)."""
    for chip, inp in cmap.elements():
        if chip.address == tin.address and inp == tin.input:
            raise InputError(f"{where}: {tin.kind}@0x{tin.address:02x}:{tin.input} is also an element's input")
        if chip.address == tin.address and chip.kind != tin.kind:
            raise InputError(f"{where}: the chip at 0x{tin.address:02x} is a {chip.kind} among the elements")
        if chip.address == tin.address and chip.settings.mode == "continuous":
            raise InputError(f"{where}: a chip in continuous mode: use single-shot mode or another chip")
    return tin


def thermistor_chip(tin: TemperatureInput, cmap):
    """The chip the thermistor is read through: with the settings of the map's chip at its address where it shares
    one with the elements (its reference, its gain: read with the first chip's, an ADS7828 told to use its internal
    reference read nothing), else the map's first chip's (the command line's)."""
    from host.channelmap import Chip

    own = next((c.settings for c in cmap.chips if (c.kind, c.address) == (tin.kind, tin.address)), None)
    return Chip(tin.kind, tin.address, (tin.input,), own or cmap.chips[0].settings)


class Thermometer:
    """Reads the thermistor through the ADC array's bus (same retries and counts), at most every READ_EVERY s."""

    def __init__(self, array, tin: TemperatureInput):
        from host.adc import make_driver

        check_beside(tin, array.cmap)
        self.tin, self.clock = tin, array.clock
        self.driver = make_driver(array.io, thermistor_chip(tin, array.cmap))
        self.last_t = -math.inf
        self.value = self.raw = math.nan  # raw: degC as the divider last read, in T_RANGE or not (NaN at a rail)

    def read(self, fresh: bool = False) -> float:
        """Degrees C within T_RANGE, else NaN; the last value when read less than READ_EVERY s ago, unless ``fresh``."""
        now = self.clock.monotonic()
        if fresh or now - self.last_t >= READ_EVERY:
            self.last_t = now
            volts = self.driver.read(self.tin.input)
            # a code at full scale is the divider past what the chip reads at its gain; outside the thermistor's rated
            # range a reading is a fault (an open NTC against an ADS1115's input, about 6 Mohm, reads -72 degC):
            # neither is a temperature to compensate at, nor one for a capture's meta (fitgen refuses it)
            self.raw = math.nan if volts >= self.driver.code_max * self.driver.lsb else self.tin.degc(volts)
            self.value = self.raw if T_RANGE[0] <= self.raw <= T_RANGE[1] else math.nan
        return self.value

    def fault(self) -> str:
        """Why the last read gave no temperature, in a few words: what the divider read, where it read one."""
        return (f"it reads {self.raw:.1f} degC, outside {T_RANGE[0]:g}..{T_RANGE[1]:g} (an open thermistor reads about "
                "-72 against an ADS1115's input, a shorted one far above)" if math.isfinite(self.raw) else
                "its divider reads 0 V or its reference (open, shorted), or more than its chip reads at its gain")


@dataclass
class TempComp:
    """Per-element offset (V/degC) and gain (1/degC) coefficients about ``t0`` (degC)."""

    KIND: ClassVar[str] = "tactile temperature compensation"
    t0: float
    offset: np.ndarray
    gain: np.ndarray
    info: dict = field(default_factory=dict)

    @property
    def n(self) -> int:
        return int(self.offset.size)

    @property
    def fitted_range(self) -> tuple[float, float] | None:
        """(lowest, highest) of the temperatures the compensation was fitted at (its ``fit.temperatures``), where
        it records two or more; else None."""
        temps = self.info.get("temperatures")
        if not isinstance(temps, list) or len(temps) < 2 or not all(is_finite_number(t) for t in temps):
            return None
        return float(min(temps)), float(max(temps))

    @property
    def rest_v(self) -> np.ndarray | None:
        """The rest readings (V) of the sensor it was fitted on, at t0 (its ``fit.rest_v``, recorded where the
        captures held a row at rest); None without the record."""
        rest = self.info.get("rest_v")
        return None if rest is None else np.asarray(rest, dtype=float)

    def reading_at(self, v: np.ndarray, temp: float) -> np.ndarray:
        """What the sensor reads at ``temp`` (degC) where it reads ``v`` at t0: the drift :meth:`apply` takes off."""
        dT = temp - self.t0
        return v * (1.0 + self.gain * dT) + self.offset * dT

    def apply(self, raw: np.ndarray, temp) -> np.ndarray:
        """Compensated readings (one row, or rows with a temperature each); a non-finite temperature leaves its
        row as it is."""
        if np.ndim(temp) == 0:  # the readout's one sample: no array work on its hot path
            return self._at(raw, temp - self.t0) if math.isfinite(temp) else raw
        temp = np.asarray(temp, dtype=float)
        with np.errstate(invalid="ignore"):  # rows without a temperature are taken as they are below
            out = self._at(raw, (temp - self.t0)[:, None])
        return np.where(np.isfinite(temp)[:, None], out, raw)

    def _at(self, raw: np.ndarray, dT) -> np.ndarray:
        return (raw - self.offset * dT) / (1.0 + self.gain * dT)

    def to_dict(self) -> dict:
        return {"kind": self.KIND, "version": 1, "t0": self.t0,
                "offset_v_per_degc": self.offset.tolist(), "gain_per_degc": self.gain.tolist(), "fit": self.info}

    def save(self, path) -> Path:
        return write_atomic(path, json.dumps(self.to_dict(), indent=1) + "\n")


def load_tempcomp(path) -> TempComp:
    """A compensation file (``capture --temperature``), checked by :func:`tempcomp_from_dict`."""
    origin = f"temperature compensation {path}"
    text = read_text(path, "temperature compensation file")  # its InputError is a ValueError: said as it is
    try:
        data = json.loads(text)
    except ValueError as exc:
        raise InputError(f"{origin}: not a compensation file (not JSON: {exc})") from None
    return tempcomp_from_dict(data, origin)


def tempcomp_from_dict(data, origin: str) -> TempComp:
    """A compensation from its :meth:`TempComp.to_dict` form; InputError naming the field unless it is version 1,
    every number finite and within a float (the C header's), t0 and the correction's factor 1 + g (T - t0) > 0
    at every temperature of T_RANGE."""
    if not isinstance(data, dict) or data.get("kind") != TempComp.KIND:
        kind = data.get("kind") if isinstance(data, dict) else None
        raise InputError(f"{origin}: not a compensation file (" + (f"its kind is {kind!r}, not {TempComp.KIND!r}"
                         if isinstance(kind, str) else f"it names no kind; a compensation file's is {TempComp.KIND!r}")
                         + ")")
    if data.get("version") != 1 or isinstance(data.get("version"), bool):
        raise InputError(f"{origin}: version {data.get('version')!r} is not one this tactile-host reads (1)")
    t0 = finite_number(data.get("t0"), f"{origin}: t0")
    if not T_RANGE[0] <= t0 <= T_RANGE[1]:
        raise InputError(f"{origin}: t0 {t0:g} degC is outside the thermistor's range ({T_RANGE[0]:g}..{T_RANGE[1]:g})")
    off, gain = (_coefficients(data.get(key), f"{origin}: {key}") for key in ("offset_v_per_degc", "gain_per_degc"))
    if off.size == 0:
        raise InputError(f"{origin}: it compensates no element")
    if off.shape != gain.shape:
        raise InputError(f"{origin}: {off.size} offsets but {gain.size} gains")
    for t in T_RANGE:  # the factor is linear in T: positive at both ends, positive between
        factor = 1.0 + gain * (t - t0)
        if not np.all(factor > 0):
            k = int(np.argmin(factor))
            raise InputError(f"{origin}: gain_per_degc[{k}] = {gain[k]:g} makes the correction's factor "
                             f"1 + g (T - t0) = {factor[k]:.3g} at {t:g} degC (it must stay > 0 over the thermistor's "
                             f"{T_RANGE[0]:g}..{T_RANGE[1]:g} degC)")
    fit = {} if data.get("fit") is None else data["fit"]
    if not isinstance(fit, dict):  # it holds the temperatures fitted at: a number there was taken as no record
        raise InputError(f"{origin}: fit must be an object (what the compensation was fitted on), got {fit!r:.40}")
    temps = fit.get("temperatures")
    if temps is not None and not (isinstance(temps, list) and all(is_finite_number(t) for t in temps)
                                  and len(set(temps)) >= 2 and min(temps) <= t0 <= max(temps)):
        # what the readouts flag extrapolation against: damaged, it would turn that check off in silence (a fit
        # chooses t0 among them, and two alike were no fit)
        raise InputError(f"{origin}: fit.temperatures must list the two or more different temperatures it was fitted "
                         f"at (degC), t0 ({t0:g}) within them, got {temps!r:.60}")
    adc = fit.get("adc")
    if adc is not None and not isinstance(adc, str):  # what read and pi-build compare their map with
        raise InputError(f"{origin}: fit.adc must be the channel map the captures were read through, got {adc!r:.40}")
    rest = fit.get("rest_v")
    if rest is not None:  # what read and identify tell another unit's compensation by: damaged, it would mislead
        rest = _coefficients(rest, f"{origin}: fit.rest_v")
        if rest.shape != off.shape:
            raise InputError(f"{origin}: fit.rest_v holds {rest.size} rest readings for {off.size} elements")
    return TempComp(t0, off, gain, fit)


def _coefficients(values, where: str) -> np.ndarray:
    """A list of finite numbers, each within a float (the C header's precision); InputError naming ``where``."""
    if not isinstance(values, list):
        raise InputError(f"{where} must be a list of numbers")
    out = np.array([finite_number(x, f"{where}[{i}]") for i, x in enumerate(values)], dtype=float)
    big = np.flatnonzero(np.abs(out) > FLOAT_MAX)
    if big.size:
        raise InputError(f"{where}[{big[0]}] = {out[big[0]]:g} does not fit in a float")
    return out


def fit_tempcomp(readings: np.ndarray, pose_ids: np.ndarray, temps: np.ndarray, t0: float | None = None,
                 rest: int | None = None, source: str = "the capture") -> TempComp:
    """Coefficients from rows of readings (n, N), the pose each row was taken at, and its temperature.

    ``t0``: the calibration temperature (default: the temperature closest to the median, the lower of two);
    ``rest``: the pose id at rest, whose readings at t0 the file records (``fit.rest_v``: whose sensor it is);
    ``source``: what the rows are, as refusals name it.
    """
    readings, pose_ids, temps = np.asarray(readings, float), np.asarray(pose_ids), np.asarray(temps, float)
    if readings.ndim != 2 or pose_ids.shape != (len(readings),) or temps.shape != (len(readings),):
        raise InputError(f"a temperature capture is rows of readings (n, N) with a pose id and a temperature each; got "
                         f"shapes {readings.shape}, {pose_ids.shape} and {temps.shape}")
    if not np.all(np.isfinite(temps)):
        raise InputError("a capture row has no temperature (is the thermistor connected?)")
    levels = np.unique(np.round(temps, 1))
    if levels.size < 2:
        raise InputError("the capture holds one temperature: capture at two or more (--temperature T1,T2,...)")
    if t0 is not None:  # the level it names, as measured: the readings there are the compensation's base
        near = float(levels[np.argmin(np.abs(levels - float(t0)))])
        if not abs(near - float(t0)) <= 0.5:
            raise InputError(f"t0 {t0:g} degC is not a temperature of {source} "
                             f"({', '.join(f'{v:g}' for v in levels)}): the readings there are the compensation's base")
        t0 = near
    # two levels as near the median (15 and 35): the lower, not whichever the thermistor's rounding favours
    t0 = float(t0) if t0 is not None else float(levels[np.argmin(np.round(np.abs(levels - np.median(temps)), 1))])
    n = readings.shape[1]
    base = np.full(readings.shape, np.nan)
    for p in np.unique(pose_ids):
        rows = pose_ids == p
        near = rows & (np.abs(temps - t0) == np.abs(temps[rows] - t0).min())
        base[rows] = readings[near].mean(axis=0)
    dT = temps - t0
    multi = np.unique(pose_ids).size >= 2
    off, gain, resid, spread = np.zeros(n), np.zeros(n), np.zeros(n), np.full(n, np.nan)
    # the rows at t0 are the base, their y 0 by construction: they leave no degree of freedom to the residual
    dof = int(np.sum(dT != 0)) - (2 if multi else 1)
    for k in range(n):
        y = readings[:, k] - base[:, k]
        X = np.column_stack([dT, base[:, k] * dT]) if multi else dT[:, None]
        coef, *_ = np.linalg.lstsq(X, y, rcond=None)
        off[k] = coef[0]
        gain[k] = coef[1] if multi else 0.0
        r = y - X @ coef
        resid[k] = float(np.sqrt(np.mean(r ** 2)))
        if dof > 0:  # the drift per degC the coefficients' standard errors leave, rms over the rows' readings
            cov = np.linalg.pinv(X.T @ X) * float(r @ r) / dof
            per = X / np.where(dT == 0, np.inf, dT)[:, None]
            spread[k] = float(np.sqrt(np.mean(np.einsum("ri,ij,rj->r", per, cov, per)[dT != 0])))
    info = {"rows": int(readings.shape[0]), "temperatures": levels.tolist(), "poses": int(np.unique(pose_ids).size),
            "residual_rms_v": resid.tolist(), "gain_fitted": bool(multi)}
    if dof > 0:
        info["drift_se_v_per_degc"] = spread.tolist()
    if rest is not None and np.any(pose_ids == rest):
        info["rest_v"] = base[pose_ids == rest][0].tolist()
    tc = TempComp(t0, off, gain, info)
    tempcomp_from_dict(tc.to_dict(), "the compensation these captures give")  # nothing saved that read refuses
    return tc


def fit_tempcomp_at(readings: np.ndarray, poses: np.ndarray, temps: np.ndarray,
                    t0: float | None = None, source: str = "the capture") -> TempComp:
    """:func:`fit_tempcomp` from each row's pose (n, 5) rather than a pose id: rows of one pose matched by value
    (to 1e-6 mm or deg), wherever they sit, and the readings of the pose at rest recorded (whose sensor it is)."""
    from fitgen.physics.pose import contact_poses

    unique, ids = np.unique(np.round(poses, 6), axis=0, return_inverse=True)
    at_rest = np.flatnonzero(np.all(contact_poses(unique) == 0, axis=1))
    return fit_tempcomp(readings, ids.ravel(), temps, t0=t0, rest=int(at_rest[0]) if at_rest.size else None,
                        source=source)


def render_c(tc: TempComp, prefix: str = "tm", precision: str = "float") -> str:
    """``<prefix>_tempcomp.h``: the compensation in C99, the operations of :meth:`TempComp.apply`."""
    from fitgen.c.cgen import c_real, fp_guard, nonfinite_test, prefix_identifier

    prefix = prefix_identifier(prefix)
    P, U = prefix, prefix.upper()
    real = "float" if precision == "float" else "double"
    lit = lambda x: c_real(float(x), precision)  # noqa: E731
    fp_before, fp_after = fp_guard(f"{U}_TEMPCOMP_FP")
    lines = [f"/* {P}_tempcomp.h: per-element temperature compensation, generated by tactile-host. Do not edit. */",
             f"#ifndef {U}_TEMPCOMP_H", f"#define {U}_TEMPCOMP_H", "", "#include <math.h>", "#include <stdint.h>",
             "#include <string.h>", "",
             # the doubles of TempComp.apply under any flags: a NaN temperature must stay NaN to isfinite()
             fp_before,
             "",
             nonfinite_test(f"{P}_tc_nonfinite", f"{U}_TEMPCOMP_NONFINITE", real, "(!isfinite(v))"), "",
             f"#define {U}_TEMPCOMP_N {tc.n}",
             f"static const {real} {P}_tc_offset[{U}_TEMPCOMP_N] = {{ {', '.join(lit(x) for x in tc.offset)} }};",
             f"static const {real} {P}_tc_gain[{U}_TEMPCOMP_N] = {{ {', '.join(lit(x) for x in tc.gain)} }};",
             "",
             "/* v[k] = (v[k] - offset[k] (t - t0)) / (1 + gain[k] (t - t0)); a non-finite t leaves v as it is */",
             f"#ifndef {U}_TEMPCOMP_API", "#if defined(__GNUC__) || defined(__clang__)",
             f"#define {U}_TEMPCOMP_API static __attribute__((unused)) /* included, not called: no warning */",
             "#else", f"#define {U}_TEMPCOMP_API static", "#endif", "#endif",
             f"{U}_TEMPCOMP_API void {P}_tempcomp({real} v[{U}_TEMPCOMP_N], {real} temp)",
             "{", f"    {U}_TEMPCOMP_FP", "    int k;", f"    const {real} dt = temp - {lit(tc.t0)};",
             f"    if ({U}_TEMPCOMP_NONFINITE(temp)) {{",
             "        return;", "    }", f"    for (k = 0; k < {U}_TEMPCOMP_N; ++k) {{",
             f"        v[k] = (v[k] - {P}_tc_offset[k] * dt) / ({lit(1.0)} + {P}_tc_gain[k] * dt);", "    }", "}", "",
             fp_after, "", f"#endif /* {U}_TEMPCOMP_H */", ""]
    return "\n".join(lines)


BEYOND_DEGC = 5.0  # past the compensation's fitted temperatures by this much, its linear drift is a guess
CAPTURE_DEGC_TOL = 1.0  # degC between a unit's capture and a compensation's t0 that goes without a note


def unit_capture_degc(source) -> float | None:
    """The temperature a unit file's unit was identified at (its ``[unit] capture_degc``, from the capture's
    thermistor), given the file's parsed ``source``; None when it records none."""
    unit = source.get("unit") if isinstance(source, dict) else None
    return unit.get("capture_degc") if isinstance(unit, dict) else None  # a number of degC: the parser checked it


def channel_map_note(tempcomp: "TempComp", cmap, option: str) -> str:
    """A note when ``tempcomp`` was fitted on readings through another channel map than ``cmap`` (its
    ``fit.adc``, which tactile-host capture --temperature records; ``cmap`` a map, or the text of one as a
    capture's meta records it): each element then takes the coefficients fitted for the one in its place; ''
    otherwise, or when either records none."""
    theirs = tempcomp.info.get("adc")
    mine = cmap if isinstance(cmap, str) or cmap is None else cmap.describe()
    if not isinstance(theirs, str) or not isinstance(mine, str) or theirs == mine:
        return ""
    return (f"note: {option} was fitted on the elements read through {theirs}, and this reads {mine}: "
            "each element takes the coefficients fitted for the one in its place (a compensation of this map: "
            "tactile-host capture --temperature)")


def beyond_note(tempcomp: "TempComp", temps, option: str, what: str) -> str:
    """A note when any of ``temps`` (degC, NaN for none) lies more than BEYOND_DEGC past the temperatures
    ``tempcomp`` was fitted at, where it is extrapolated (as the readout counts such samples); ''
    otherwise, or when the file records no range."""
    fitted = tempcomp.fitted_range
    t = np.asarray(temps, dtype=float)
    t = t[np.isfinite(t)]
    if fitted is None or not t.size:
        return ""
    lo, hi = float(t.min()), float(t.max())
    if fitted[0] - BEYOND_DEGC <= lo and hi <= fitted[1] + BEYOND_DEGC:
        return ""
    at = f"{lo:.1f} degC" if lo == hi else f"{lo:.1f}..{hi:.1f} degC"
    return (f"note: {what} were read at {at}, and {option} was fitted at {fitted[0]:g}..{fitted[1]:g} degC: "
            f"beyond it by more than {BEYOND_DEGC:g} degC its linear drift is extrapolated (a compensation "
            "fitted across these temperatures: tactile-host capture --temperature)")


SPREAD_NOTE = 2.0  # the compensation's own error over the rows' residual past which the fit says so


def spread_note(tempcomp: "TempComp") -> str:
    """A note when the coefficients' standard errors (``fit.drift_se_v_per_degc``), carried to the farthest
    temperature the readouts take without a note (BEYOND_DEGC past the fitted ones), exceed SPREAD_NOTE times
    the rows' residual on some element: levels too close for the rows' noise; '' otherwise."""
    se, resid, fitted = (tempcomp.info.get("drift_se_v_per_degc"), tempcomp.info.get("residual_rms_v"),
                         tempcomp.fitted_range)
    if fitted is None or not isinstance(se, list) or not isinstance(resid, list) or len(se) != len(resid):
        return ""
    reach = max(abs(fitted[0] - BEYOND_DEGC - tempcomp.t0), abs(fitted[1] + BEYOND_DEGC - tempcomp.t0))
    err = np.asarray(se, dtype=float) * reach
    ratio = err / np.maximum(np.asarray(resid, dtype=float), 1e-12)
    k = int(np.nanargmax(ratio)) if np.any(np.isfinite(ratio)) else -1
    if k < 0 or not ratio[k] > SPREAD_NOTE:
        return ""
    return (f"note: the compensation's temperatures span {fitted[1] - fitted[0]:.3g} degC, too little for the rows' "
            f"noise: {reach:.3g} degC from t0 (as far as the readouts take it without a note) its own error reaches "
            f"{err[k] * 1e3:.2g} mV on element {k + 1}, {ratio[k]:.2g}x the rows' residual; levels further apart "
            "pin the drift (that error falls as 1/span)")


def model_unit_degc(model) -> tuple[str | None, float | None]:
    """(``model``'s sensor file as found here, fitgen.fitting.holdout.fitted_sensor_spec; the temperature its unit
    was identified at, :func:`unit_capture_degc`), None for either it does not record or a file not read."""
    from fitgen.fitting.holdout import fitted_sensor_spec
    from fitgen.physics.sensor import load_sensor

    spec = fitted_sensor_spec(model)
    try:
        return spec, unit_capture_degc(load_sensor(spec).source) if spec else None
    except InputError:
        return spec, None


def capture_temperature_note(model, tempcomp: "TempComp", tare: str = "--tare") -> str:
    """A note when ``model``'s unit (its sensor file, fitgen.fitting.holdout.fitted_sensor_spec) was identified from a
    capture more than CAPTURE_DEGC_TOL from ``tempcomp``'s t0: the compensation maps readings to t0, the model was
    fitted for the capture's; '' otherwise, or when the file records no capture temperature. ``tare``: the option
    that takes the offsets off at start, which the note suggests."""
    spec, degc = model_unit_degc(model)
    if degc is None or abs(degc - tempcomp.t0) <= CAPTURE_DEGC_TOL:
        return ""
    # the offset's share and the gain's, over the readings the model takes (a tare takes off only the first)
    ends = np.vstack([model.input_min, model.input_max])
    shift = float(np.max(np.abs(tempcomp.apply(ends, np.full(2, degc)) - ends))) * 1e3
    return (f"note: the model's unit ({spec}) was identified from a capture at {degc:.1f} degC, and the compensation "
            f"maps readings to its t0, {tempcomp.t0:g} degC: they reach the model up to {shift:.2g} mV off what it "
            f"was fitted for; identify the unit with --temp-comp (its capture mapped to {tempcomp.t0:g} degC), or "
            f"tare at start ({tare}), which takes off the shift at rest, not the gains' share away from it")
