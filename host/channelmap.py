"""Which ADC input reads which sensor element: a ``--adc`` spec string or a TOML file, validated.

Spec string (elements numbered in the order listed, chips separated by commas)::

    ads1115@0x48:0-3,ads1115@0x49:0-3     two ADS1115, AIN0..AIN3 single-ended each
    ads1115@0x48:d0-1,d2-3                one ADS1115, differential pairs AIN0-AIN1, AIN2-AIN3
    ads1115@0x48:0,2,ads1115@0x49:1       single inputs may be listed one by one
    ads7828@0x4a                          one ADS7828, CH0..CH7 (same as ads7828@0x4a:0-7)

TOML file (per-chip settings; anything left out takes the command-line value)::

    bus = 1
    [[chip]]
    type = "ads1115"
    address = 0x48
    inputs = [0, 1, 2, 3]          # as in a spec: ["0-3"] is the same, ["d0-1", "d2-3"] two pairs
    pga = 4.096                    # full scale, V
    data_rate = 860                # samples per second
    mode = "single"                # or "continuous"
    [[chip]]
    type = "ads7828"
    address = 0x4b
    inputs = [0, 1, 2, 3]
    vref = 3.3                     # external reference in V, or "internal" (2.5 V)
    [temperature]                  # optional: a thermistor on a spare input (host/temperature.py)
    input = "ads1115@0x4a:0"
    beta = 3950                    # and r25, series (ohms), vref (V): the NTC divider
"""

from __future__ import annotations

import re
from dataclasses import dataclass, replace
from pathlib import Path

from fitgen.base.errors import InputError, is_finite_number, is_whole_number, shown
from fitgen.base.fileio import read_text
from fitgen.base.texts import load_toml

CHIPS = ("ads1115", "ads7828")
ADDRESSES = (0x48, 0x49, 0x4A, 0x4B)  # both chips: 1001 0xx, set by the ADDR / A1 A0 pins
MAX_BUS = (1 << 20) - 1  # the greatest N of /dev/i2c-N: the kernel's i2c-dev has 2^20 minors (tm_pi reads an int)
ADS1115_PGA = (6.144, 4.096, 2.048, 1.024, 0.512, 0.256)  # full-scale range, +-V
ADS1115_RATES = (8, 16, 32, 64, 128, 250, 475, 860)  # samples per second
ADS1115_PAIRS = ((0, 1), (0, 3), (1, 3), (2, 3))  # the differential pairs the MUX offers
MODES = ("single", "continuous")
INTERNAL_VREF = 2.5  # V, the ADS7828's internal reference
N_INPUTS = {"ads1115": 4, "ads7828": 8}
CHIP_SETTINGS = {"ads1115": ("pga", "data_rate", "mode"), "ads7828": ("vref",)}  # what each kind's conversions take


@dataclass(frozen=True)
class Settings:
    """Chip settings from the command line; a TOML file may override them per chip."""

    pga: float = 4.096
    data_rate: int = 860
    mode: str = "single"
    vref: float | str = 3.3  # ADS7828: external reference in V, or "internal"

    def checked(self, origin: str = "option") -> "Settings":
        if self.pga not in ADS1115_PGA:
            raise InputError(f"{origin}: pga {self.pga:g} is not one of {', '.join(f'{p:g}' for p in ADS1115_PGA)} (V)")
        if self.data_rate not in ADS1115_RATES:
            raise InputError(f"{origin}: data rate {self.data_rate} is not one of "
                             f"{', '.join(map(str, ADS1115_RATES))} (samples/s)")
        if self.mode not in MODES:
            raise InputError(f"{origin}: mode {self.mode!r} is not one of {', '.join(MODES)}")
        if self.vref != "internal":
            if isinstance(self.vref, bool) or not isinstance(self.vref, (int, float)) or not 0.05 <= self.vref <= 5.5:
                raise InputError(f"{'--vref' if origin == 'option' else origin + ': vref'} must be 'internal' or an "
                                 f"external reference in 0.05..5.5 V, got {shown(self.vref)}")
        return self


@dataclass(frozen=True)
class Chip:
    kind: str  # ads1115 | ads7828
    address: int
    inputs: tuple  # per element: an input number, or a (positive, negative) pair
    settings: Settings

    @property
    def label(self) -> str:
        return f"{self.kind}@0x{self.address:02x}"

    @property
    def vref_volts(self) -> float:
        v = self.settings.vref
        return INTERNAL_VREF if v == "internal" else float(v)


@dataclass(frozen=True)
class ChannelMap:
    chips: tuple[Chip, ...]
    bus: int | None = None  # from a TOML file; the command line's --bus wins when given
    temperature: tuple | None = None  # from a TOML file: (input spec, {divider key: value})

    @property
    def n_elements(self) -> int:
        return sum(len(c.inputs) for c in self.chips)

    def elements(self) -> list[tuple[Chip, object]]:
        """(chip, input) for element 1..N, in order."""
        return [(c, i) for c in self.chips for i in c.inputs]

    def describe(self) -> str:
        parts = []
        for c in self.chips:
            ins = ",".join(f"d{i[0]}-{i[1]}" if isinstance(i, tuple) else str(i) for i in c.inputs)
            parts.append(f"{c.label}:{ins}")
        return ",".join(parts)


def check_bus(bus, where: str) -> None:
    """InputError naming ``where`` unless ``bus`` is the N of an I2C bus /dev/i2c-N (a whole number 0..MAX_BUS)."""
    if not (is_whole_number(bus) and 0 <= bus <= MAX_BUS):
        raise InputError(f"{where} must be a whole number 0..{MAX_BUS} (/dev/i2c-N), got {shown(bus)}")


def reordered_spec(spec, order) -> str | None:
    """The ``--adc`` spec that reads as element j+1 what ``spec`` reads as element ``order[j]`` + 1 (0-based), where
    a spec can say so: None where a chip's inputs would not stay together (a spec lists each chip once), and for
    a map file or a spec that does not parse."""
    if not isinstance(spec, str) or spec.endswith(".toml"):
        return None
    try:
        elements = parse_spec(spec).elements()
    except InputError:
        return None
    if sorted(order) != list(range(len(elements))):
        return None
    chips, inputs = [], []
    for chip, inp in (elements[k] for k in order):
        if not chips or chips[-1] is not chip:
            if any(c is chip for c in chips):
                return None
            chips.append(chip)
            inputs.append([])
        inputs[-1].append(inp)
    return ChannelMap(tuple(replace(c, inputs=tuple(i)) for c, i in zip(chips, inputs))).describe()


def check_full_scale(cmap: ChannelMap, low, high) -> None:
    """InputError when an element's ADC cannot reach readings from ``low`` to ``high`` (volts, per element: a
    model's fitted domain): each would clip at the full scale, and every estimate with it."""
    scales = []
    for chip, _ in cmap.elements():
        if chip.kind == "ads1115":
            # the map's setting, typed as --pga or written in a TOML map: named as neither
            scales.append((chip.settings.pga * 32767 / 32768, f"{chip.label}, PGA {chip.settings.pga:g} V"))
        else:
            scales.append((chip.vref_volts * 4095 / 4096, f"{chip.label}, reference {chip.settings.vref}"))
    _check_scales(scales, low, high, "choose a larger full scale (--pga or --vref, or the map file's pga or vref)")


def check_reported_full_scale(adc_chips, low, high) -> None:
    """:func:`check_full_scale` for the chips a device's INFO reports (kind, address, inputs, PGA code, ...): its
    ADS1115s' PGAs; an ADS7828's reference is not in INFO, so its elements go unchecked."""
    scales = []
    for kind, address, n, code, *_ in adc_chips:
        known = kind == "ads1115" and code < len(ADS1115_PGA)
        scales += [(ADS1115_PGA[code] * 32767 / 32768 if known else None,
                    f"{kind}@0x{address:02x}, the build's PGA" + (f" {ADS1115_PGA[code]:g} V" if known else ""))] * n
    _check_scales(scales, low, high, "rebuild the firmware with a larger --pga, or flash a model fitted within it")


def _check_scales(scales, low, high, fix: str) -> None:
    for k, (top, where) in enumerate(scales):
        reach = max(abs(float(low[k])), abs(float(high[k])))
        if top is not None and reach > top:
            raise InputError(f"element v{k + 1} was fitted on readings up to {reach:.4g} V, beyond its ADC's full "
                             f"scale {top:.4g} V ({where}): its readings would clip; {fix}")


# --- parsing -----------------------------------------------------------------------


def _address(text, origin: str) -> int:
    if isinstance(text, bool):
        raise InputError(f"{origin}: address must be one of 0x48..0x4b, got {shown(text)}")
    if isinstance(text, int):
        addr = text
    else:
        meant = int(str(text), 16) if re.fullmatch(r"[0-9a-fA-F]{2}", str(text)) else None
        try:
            addr = int(str(text), 0)
        except ValueError:
            hint = f"0x{meant:02x}?" if meant in ADDRESSES else "use 0x48..0x4b"
            raise InputError(f"{origin}: address {text!r} is not a number ({hint})") from None
        if meant in ADDRESSES and addr not in ADDRESSES:  # 48 typed for 0x48: read as decimal, it is 0x30
            raise InputError(f"{origin}: address {text} is decimal {addr} (0x{addr:02x}); I2C addresses are given in "
                             f"hex: 0x{meant:02x}")
    if addr not in ADDRESSES:
        said = f"0x{addr:02x}" if addr >= 0 else shown(text)  # not 0x-48
        raise InputError(f"{origin}: address {said} is not one an ADS1115 or ADS7828 can take "
                         "(0x48..0x4b, set by the ADDR or A1/A0 pins)")
    return addr


def _inputs(kind: str, items: list, origin: str) -> tuple:
    """Inputs from spec items: '2', '0-3' (a range of single inputs), 'd0-1' (a differential pair)."""
    out = []
    top = N_INPUTS[kind] - 1
    for item in items:
        text = str(item).strip().lower()
        m_pair = re.fullmatch(r"d(\d)-(\d)", text)
        m_range = re.fullmatch(r"(\d+)-(\d+)", text)
        if m_pair:
            pair = (int(m_pair.group(1)), int(m_pair.group(2)))
            if kind != "ads1115":
                raise InputError(f"{origin}: {kind} differential inputs are not supported; "
                                 f"list single-ended channels 0-{top}")
            if pair not in ADS1115_PAIRS:
                raise InputError(f"{origin}: d{pair[0]}-{pair[1]} is not a pair the ADS1115 offers "
                                 f"({', '.join(f'd{p}-{n}' for p, n in ADS1115_PAIRS)})")
            out.append(pair)
        elif m_range:
            lo, hi = int(m_range.group(1)), int(m_range.group(2))
            if lo > hi or hi > top:
                raise InputError(f"{origin}: input range {text!r} must lie in 0-{top} with start <= end")
            out.extend(range(lo, hi + 1))
        elif re.fullmatch(r"\d+", text):
            if int(text) > top:
                raise InputError(f"{origin}: input {text} does not exist on the {kind} (0-{top})")
            out.append(int(text))
        else:
            raise InputError(f"{origin}: input {item!r} is neither N, N-M (a range) nor dP-N (a differential pair)")
    if not out:
        raise InputError(f"{origin}: no inputs listed")
    positives = [i if isinstance(i, int) else i[0] for i in out]
    negatives = {i[1] for i in out if isinstance(i, tuple)}  # pairs may share a negative input (d0-3, d1-3)
    for n, p in enumerate(positives):
        if p in positives[:n]:
            raise InputError(f"{origin}: input {p} is listed twice")
        if p in negatives:
            raise InputError(f"{origin}: input {p} is both read and used as a pair's negative input")
    return tuple(out)


def _kind(text: str, origin: str) -> str:
    kind = str(text).strip().lower()
    if kind not in CHIPS:
        raise InputError(f"{origin}: unknown chip {text!r} (known: {', '.join(CHIPS)})")
    return kind


def _finish(chips: list[Chip], origin: str, bus: int | None = None) -> ChannelMap:
    if not chips:
        raise InputError(f"{origin}: no chips")
    seen = {}
    for c in chips:
        if c.address in seen:
            raise InputError(f"{origin}: address 0x{c.address:02x} is given twice ({seen[c.address]} and {c.label}); "
                             "chips on one bus need distinct addresses")
        seen[c.address] = c.label
    return ChannelMap(tuple(chips), bus)


def parse_spec(spec: str, settings: Settings = Settings()) -> ChannelMap:
    """A spec string such as ``ads1115@0x48:0-3,ads1115@0x49:0-3`` (see the module's text)."""
    origin = f"--adc {spec!r}"
    settings = settings.checked("--adc")
    chips: list[Chip] = []
    current = None  # [kind, address, items]
    groups = []
    for part in [p.strip() for p in spec.split(",")]:
        if not part:
            raise InputError(f"{origin}: empty item (two commas in a row?)")
        m = re.fullmatch(r"([A-Za-z0-9_]+)@([^:]+)(?::(.*))?", part)
        if m:
            current = [_kind(m.group(1), origin), _address(m.group(2), origin), []]
            groups.append(current)
            if m.group(3) is not None:
                current[2].append(m.group(3))
        elif current is None:
            raise InputError(f"{origin}: expected CHIP@ADDRESS[:INPUTS] first (e.g. ads1115@0x48:0-3 or ads7828@0x48)")
        else:
            current[2].append(part)
    for kind, addr, items in groups:
        items = items or [f"0-{N_INPUTS[kind] - 1}"]
        chips.append(Chip(kind, addr, _inputs(kind, items, f"{origin}, {kind}@0x{addr:02x}"), settings))
    return _finish(chips, origin)


def load_map_file(path: str | Path, settings: Settings = Settings()) -> ChannelMap:
    """A TOML channel map (see the module's text)."""
    origin = f"channel map {path}"
    data = load_toml(read_text(path, "channel map"), origin, "channel map")
    unknown = sorted(set(data) - {"bus", "chip", "temperature"})
    if unknown:
        raise InputError(f"{origin}: unknown key {unknown[0]!r} (known: bus, chip, temperature)")
    temperature = None
    if "temperature" in data:
        tt = data["temperature"]
        if not isinstance(tt, dict) or not isinstance(tt.get("input"), str):
            raise InputError(f"{origin}: [temperature] needs input = \"CHIP@ADDRESS:INPUT\"")
        extra = sorted(set(tt) - {"input", "beta", "r25", "series", "vref"})
        if extra:
            raise InputError(f"{origin}: [temperature]: unknown key {extra[0]!r}")
        divider = {k: tt[k] for k in ("beta", "r25", "series", "vref") if k in tt}
        # inf had passed (> 0), and an integer past float's range had raised OverflowError at float()
        if not all(is_finite_number(v) and v > 0 for v in divider.values()):
            raise InputError(f"{origin}: [temperature]: beta, r25, series and vref must be finite numbers > 0")
        temperature = (tt["input"], {k: float(v) for k, v in divider.items()})
    bus = data.get("bus")
    if bus is not None:
        check_bus(bus, f"{origin}: bus")
    tables = data.get("chip", [])
    if not isinstance(tables, list) or not all(isinstance(t, dict) for t in tables):
        raise InputError(f"{origin}: 'chip' must be an array of tables ([[chip]])")
    chips = []
    for n, t in enumerate(tables):
        where = f"{origin}, chip[{n}]"
        unknown = sorted(set(t) - {"type", "address", "inputs", "pga", "data_rate", "mode", "vref"})
        if unknown:
            raise InputError(f"{where}: unknown key {unknown[0]!r}")
        if "type" not in t or "address" not in t:
            raise InputError(f"{where}: 'type' and 'address' are required")
        kind = _kind(t["type"], where)
        addr = _address(t["address"], where)
        items = t.get("inputs", list(range(N_INPUTS[kind])))
        if not isinstance(items, list):
            raise InputError(f"{where}: 'inputs' must be a list such as [0, 1, 2, 3], [\"0-3\"] or [\"d0-1\", \"d2-3\"]")
        for x in items:
            if isinstance(x, bool) or not isinstance(x, (int, str)):
                raise InputError(f"{where}: input {x!r} must be a number or a string like \"0-3\" or \"d0-1\"")
        over = {k: t[k] for k in ("pga", "data_rate", "mode", "vref") if k in t}
        # as the command line refuses them: a setting of the other chip would be ignored
        foreign = [k for k in over if k not in CHIP_SETTINGS[kind]]
        if foreign:
            takes = "; ".join(f"an {c} takes {', '.join(v)}" for c, v in CHIP_SETTINGS.items())
            raise InputError(f"{where}: {foreign[0]} is not a setting of an {kind} ({takes})")
        if "pga" in over and (isinstance(over["pga"], bool) or not isinstance(over["pga"], (int, float))):
            raise InputError(f"{where}: pga must be a number")
        if "data_rate" in over and (isinstance(over["data_rate"], bool) or not isinstance(over["data_rate"], int)):
            raise InputError(f"{where}: data_rate must be a whole number")
        if "pga" in over:
            over["pga"] = float(over["pga"])
        chips.append(Chip(kind, addr, _inputs(kind, items, where), replace(settings, **over).checked(where)))
    return replace(_finish(chips, origin, bus), temperature=temperature)


def channel_map(arg: str, settings: Settings = Settings()) -> ChannelMap:
    """``--adc``: a TOML file when the argument names one (or ends in .toml), else a spec string."""
    if arg.endswith(".toml") or Path(arg).is_file():
        return load_map_file(arg, settings)
    return parse_spec(arg, settings)
