"""The reference firmware (``firmware_templates/firmware/``, protocol in docs/protocol.md) for a model:
rendered into a folder next to its ``tm_model.h`` and the protocol's ``proto_defs.h`` (host.protocol_c),
and built for a host process, QEMU's mps2-an386 or microbit, or the Arduino Uno (simavr's ATmega328P)."""

from __future__ import annotations

import re
import shlex
import shutil
import subprocess
from importlib import resources
from pathlib import Path

import jinja2
import numpy as np

from fitgen import __version__
from fitgen.c.cgen import c_real
from fitgen.c.codegen import PRECISIONS, STYLES, render_blob_interpreter, render_header
from fitgen.base.children import run_captured
from fitgen.base.errors import InputError
from fitgen.base.fileio import write_all
from fitgen.base.signals import signals_held
from fitgen.equations.model import Model, check_input_units
from fitgen.c.compiled import WARNING_FLAGS
from fitgen.c.targets import TARGETS, check_precision
from host.channelmap import check_full_scale
from host.protocol_c import render_proto_defs

PORTS = ("posix", "mps2", "microbit", "uno")
COMMON_FILES = ("model_api.h", "proto.h", "proto.c", "cal.h", "calstore.h", "device.h", "device.c", "hal.h", "adc.h",
                "inputs.h")
# written by render_firmware (besides tm_model.h): from the model, host/protocol.py, and cal.c.j2
RENDERED = ("main.c", "proto_defs.h", "cal.c")
# where the inputs come from: simulated triangle waves, or the ADC drivers through a channel map
SIM_FILES = ("inputs_sim.c",)
ADC_FILES = ("adc.c", "inputs_adc.c")
# the emulated ARM boards and the host build reach the bus model over a byte channel; the Uno has a real
# TWI driver (hal_uno.c), answered in simavr by the same bus model (firmware_templates/avr/uno_board.c)
BRIDGE_FILES = ("i2c_bridge.c",)
PORT_FILES = {"posix": ("hal_posix.c", "calstore_ram.c"),
              "mps2": ("hal_mps2.c", "calstore_ram.c", "startup.h", "startup_mps2.c", "mps2_an386.ld"),
              "microbit": ("hal_microbit.c", "calstore_ram.c", "startup.h", "startup_microbit.c", "microbit.ld"),
              "uno": ("hal_uno.c", "calstore_eeprom.c")}
BINARY = {"posix": "firmware", "mps2": "firmware.elf", "microbit": "firmware.elf", "uno": "firmware.elf"}
DEFAULT_CC = {"posix": "gcc", "mps2": "arm-none-eabi-gcc", "microbit": "arm-none-eabi-gcc", "uno": "avr-gcc"}
LINKER_SCRIPT = {"mps2": "mps2_an386.ld", "microbit": "microbit.ld"}
_BARE = ["-ffunction-sections", "-fdata-sections", "-nostartfiles", "-Wl,--gc-sections", "-Wl,--fatal-warnings",
         "--specs=nano.specs", "--specs=nosys.specs"]
MPS2_FLAGS = ["-mcpu=cortex-m4", "-mthumb", "-mfloat-abi=hard", "-mfpu=fpv4-sp-d16", "-fno-math-errno"] + _BARE
# the nRF51's Cortex-M0: ARMv6-M, no FPU, no 32x32->64 multiply (64-bit products are __aeabi_lmul calls)
MICROBIT_FLAGS = ["-mcpu=cortex-m0", "-mthumb", "-mfloat-abi=soft"] + _BARE
# the Uno: avr-libc's start-up and linker script; blobs in EEPROM (cal.h), 2 BENCH vectors (device.h), and
# the ADC array sized for the channel map it reads (adc.h, set in adc_map.h's limits below)
UNO_FLAGS = ["-mmcu=atmega328p", "-DF_CPU=16000000UL", "-DCAL_IN_EEPROM", "-DDEVICE_BENCH_VECTORS=2u",
             "-ffunction-sections", "-fdata-sections", "-Wl,--gc-sections"]
PORT_FLAGS = {"mps2": MPS2_FLAGS, "microbit": MICROBIT_FLAGS, "uno": UNO_FLAGS}
SENSOR_ID_MAX = 16
BUILD_FLAGS = "build_flags"  # defines a render adds to its build (one line, written by render_firmware)


def _input_files(port: str, adc: bool) -> tuple[str, ...]:
    """The sources a sample's inputs come from: the ADC drivers (and, but on the Uno, the I2C bridge), or
    the simulated ones."""
    return ADC_FILES + (() if port == "uno" else BRIDGE_FILES) if adc else SIM_FILES


def _check_port(port: str) -> None:
    if port not in PORTS:
        raise InputError(f"port must be one of {', '.join(PORTS)}, got {port!r}")


def _source(name: str) -> bytes:
    return (resources.files("firmware_templates") / "firmware" / name).read_bytes()


NARROW_TAG = "+uno"  # in INFO's firmware version: the fixed-point plan for the AVR's 16-bit multiply


def firmware_version(port: str) -> str:
    """INFO's firmware version (at most 12 characters): fitgen's, tagged when the port plans fixed point for a
    16-bit multiply, so that a suite run against the device compares it with that plan."""
    return __version__ + (NARROW_TAG if port == "uno" else "")


def adc_input_lsb(cmap) -> float:
    """The one value of an ADC code every element of ``cmap`` shares (a fixed-point build needs one)."""
    from host.adc import BusIO, make_driver
    from host.simbus import SimBus

    # a driver binds its bus's calls when made: an idle simulated bus stands in (nothing is transferred)
    lsbs = {make_driver(BusIO(SimBus()), chip).lsb for chip in cmap.chips}
    if len(lsbs) != 1:
        raise InputError(f"a fixed-point firmware takes one ADC code scale; the channel map {cmap.describe()} mixes "
                         f"{len(lsbs)} (give every chip the same PGA, or the same reference)")
    return lsbs.pop()


def check_sensor_id(sensor_id: str) -> str:
    """``sensor_id`` as the firmware compiles it in (a C string); InputError otherwise."""
    if not (0 < len(sensor_id) <= SENSOR_ID_MAX and sensor_id.isascii() and sensor_id.isprintable()
            and '"' not in sensor_id and "\\" not in sensor_id):
        raise InputError(f"sensor id must be 1..{SENSOR_ID_MAX} printable ASCII characters without quotes "
                         f"or backslashes, got {sensor_id!r}")
    return sensor_id


def render_firmware(model: Model, folder: str | Path, *, precision: str = "float", style: str = "table",
                    fma: bool = False, port: str = "mps2", sensor_id: str = "paper", cmap=None, tin=None,
                    tempcomp=None, bench_inputs=None) -> Path:
    """Write ``tm_model.h``, ``main.c`` and the port's sources into ``folder``; return ``folder``.

    ``cmap`` (a host.channelmap.ChannelMap): the inputs come from the ADC drivers through it (its
    ``adc_map.h``), over the port's I2C: the emulated ports reach the bus model through
    i2c_bridge.c. Without it, simulated triangle waves. ``tin``: a thermistor read as well (every
    0.25 s, as host/temperature.py does); ``tempcomp``: a host.temperature.TempComp applied to the
    volts before the model (float and double builds). ``bench_inputs``: rows of readings (at most 16, float and
    double builds, not the Uno) BENCH cycles through in place of its built-in vectors, which no pose gives (a
    refinement's step costs its whole on readings only). The files are written together, the last render's
    others and image removed with them; the same arguments give the same bytes.
    """
    _check_port(port)
    if precision not in PRECISIONS or style not in STYLES:
        raise InputError(f"precision must be one of {', '.join(PRECISIONS)} and style one of "
                         f"{', '.join(STYLES)}, got {precision!r}, {style!r}")
    check_sensor_id(sensor_id)
    folder = Path(folder)
    if port in TARGETS:
        check_precision(port, precision)  # what the board's core can run (fitgen/c/targets.py)
    if port == "microbit" and cmap is not None:
        raise InputError("the microbit has one UART: it has no I2C bridge to the bus model (use --target mps2 or "
                         "host for --adc)")
    if cmap is not None and cmap.n_elements != model.n_inputs:
        raise InputError(f"the channel map reads {cmap.n_elements} elements; the model takes {model.n_inputs}")
    if cmap is not None and precision != "fixed":  # fixed point takes the ADC's codes
        check_input_units(model, "V", "the ADCs' readings")
    if cmap is not None and model.input_units == "V":  # as read and pi-build: clipped, every estimate bent in silence
        check_full_scale(cmap, model.input_min, model.input_max)
    if (tin is not None or tempcomp is not None) and cmap is None:
        raise InputError("a thermistor and a temperature compensation need the ADC inputs (--adc)")
    if tempcomp is not None and tin is None:
        raise InputError("--temp-comp needs the temperature: add the thermistor's input to --adc as "
                         "temp=CHIP@ADDRESS:INPUT")
    if tempcomp is not None and precision == "fixed":
        raise InputError("a fixed-point firmware takes ADC codes: temperature compensation needs a float or "
                         "double build")
    header = {"input_lsb": adc_input_lsb(cmap), "input_offset": 0.0} if cmap is not None and precision == "fixed" \
        else {}
    files = {"tm_model.h": render_header(model, precision, style, "tm", fma, target=port if port in TARGETS else None,
                                         **header)}
    inputs = _input_files(port, cmap is not None)
    files.update({name: _source(name) for name in COMMON_FILES + inputs + PORT_FILES[port]})
    files.update({"proto_defs.h": render_proto_defs(), "cal.c": render_blob_interpreter()})
    # the other kind of build's, from an earlier render, and the last image, built from other sources
    stale = list(SIM_FILES if cmap is not None else ADC_FILES + BRIDGE_FILES + ("adc_map.h", "inputs_options.h"))
    stale += ["tm_tempcomp.h", BENCH_INPUTS, BUILD_FLAGS, *sorted(set(BINARY.values()))]
    if cmap is not None and port == "uno":
        # the ADC array sized for this map: 2 KB of RAM has no room for a 4-chip array's 540 bytes
        chips = max(len(cmap.chips), 1)
        files[BUILD_FLAGS] = f"-DADC_MAX_CHIPS={chips} -DADC_MAX_ELEMENTS={max(cmap.n_elements, 1)}\n"
    if bench_inputs is not None:
        files[BENCH_INPUTS], files[BUILD_FLAGS] = _bench_inputs(bench_inputs, model.n_inputs, precision, port)
    if cmap is not None:
        from host.pi import render_adc_map
        from host.temperature import render_c

        files["adc_map.h"] = render_adc_map(cmap, tin)
        files["inputs_options.h"] = (f"/* inputs_options.h: generated by tactile-hil. */\n"
                                     f"#define INPUTS_TEMPCOMP {int(tempcomp is not None)}\n")
        if tempcomp is not None:
            files["tm_tempcomp.h"] = render_c(tempcomp, "tm", "double")
    digest = bytes.fromhex(model.sha256)
    rows = [", ".join(f"0x{b:02x}" for b in digest[i:i + 8]) + ("," if i < 24 else "") for i in range(0, 32, 8)]
    env = jinja2.Environment(undefined=jinja2.StrictUndefined, autoescape=False, keep_trailing_newline=True,
                             trim_blocks=True, lstrip_blocks=True)
    files["main.c"] = env.from_string(_source("main.c.j2").decode()).render(
        port=port, version=firmware_version(port), model_hash=model.sha256, precision=precision, style=style, fma=fma,
        n_inputs=model.n_inputs, n_outputs=len(model.equations), hash_rows=rows, sensor_id=sensor_id)
    with signals_held():  # a Ctrl-C between two files left one model's header beside another's main.c and image
        write_all([(folder / name, data) for name, data in files.items()])
        for name in stale:
            if name not in files:
                (folder / name).unlink(missing_ok=True)
    return folder


BENCH_INPUTS = "bench_inputs.h"
MAX_BENCH_INPUTS = 16  # device.h's default count: the RAM the firmware is laid out for


def _bench_inputs(rows, n_inputs: int, precision: str, port: str) -> tuple[str, str]:
    """``bench_inputs.h`` for BENCH's vectors ``rows`` (k, n_inputs), and the build's flags that take it."""
    rows = np.asarray(rows, dtype=float)
    if precision == "fixed" or port == "uno":
        raise InputError("BENCH's own readings take a float or double build on a port other than the Uno")
    if rows.ndim != 2 or not 1 <= len(rows) <= MAX_BENCH_INPUTS or rows.shape[1] != n_inputs:
        raise InputError(f"BENCH's readings must be 1..{MAX_BENCH_INPUTS} rows of the model's {n_inputs} inputs, "
                         f"got an array of shape {rows.shape}")
    body = ",\n".join("    {" + ", ".join(c_real(x, precision) for x in row) + "}" for row in rows)
    header = ("/* bench_inputs.h: generated by tactile-hil: the readings BENCH cycles through. */\n"
              f"static const tm_input device_bench_inputs[DEVICE_BENCH_VECTORS][TM_N_INPUTS] = {{\n{body}\n}};\n")
    return header, f"-DDEVICE_BENCH_INPUTS -DDEVICE_BENCH_VECTORS={len(rows)}u\n"


def _run(cmd: list[str], what: str) -> subprocess.CompletedProcess:
    if shutil.which(cmd[0]) is None:
        raise InputError(f"{what}: {cmd[0]!r} not found")
    proc = run_captured(cmd)
    if proc.returncode != 0:
        lines = proc.stderr.strip().splitlines()
        # the linker's own words when the image does not fit (collect2's "error" line says only that ld failed)
        first = next((ln for ln in lines if "overflowed" in ln),
                     next((ln for ln in lines if "error" in ln), lines[0] if lines else "(no message)"))
        over = re.search(r"region `(\w+)' overflowed by (\d+) bytes?", first)
        if over:  # ld's region name (avr: text, data; the ARM scripts: FLASH, RAM) in a user's words
            memory = "RAM" if over.group(1).lower() in ("data", "ram") else "flash"
            raise InputError(f"{what} failed: it does not fit, {over.group(2)} bytes over the {memory}")
        raise InputError(f"{what} failed: {first.strip()}")
    return proc


def build_firmware(folder: str | Path, port: str, cc: str | None = None) -> Path:
    """Compile a rendered folder: ``port`` "posix" gives the host binary ``folder/firmware`` (gcc),
    "mps2" the ELF ``folder/firmware.elf`` (arm-none-eabi-gcc). Warnings are errors; a failure or a
    missing compiler is an InputError with the compiler's first error line."""
    _check_port(port)
    folder = Path(folder)
    names = RENDERED + COMMON_FILES \
        + _input_files(port, (folder / "inputs_adc.c").is_file()) \
        + PORT_FILES[port]
    missing = [n for n in names if not (folder / n).is_file()]
    if missing or not (folder / "tm_model.h").is_file():
        raise InputError(f"{folder} holds no rendered {port} firmware (missing {', '.join(missing) or 'tm_model.h'})")
    output = folder / BINARY[port]
    cmd = shlex.split(cc or DEFAULT_CC[port]) + WARNING_FLAGS + ["-O2", "-I", str(folder)]
    if port in PORT_FLAGS:
        cmd += PORT_FLAGS[port] + (["-T", str(folder / LINKER_SCRIPT[port])] if port in LINKER_SCRIPT else [])
    if (folder / BUILD_FLAGS).is_file():
        cmd += (folder / BUILD_FLAGS).read_text().split()
    cmd += [str(folder / n) for n in names if n.endswith(".c")] + ["-o", str(output), "-lm"]
    _run(cmd, f"building the {port} firmware")
    return output


def firmware_size(elf: str | Path, size_tool: str = "arm-none-eabi-size") -> dict[str, int]:
    """Bytes of an ELF: text, data, bss (``size`` in Berkeley format), flash = text + data, ram = data + bss."""
    proc = _run([size_tool, str(elf)], f"measuring {elf}")
    text, data, bss = (int(x) for x in proc.stdout.splitlines()[1].split()[:3])
    return {"text": text, "data": data, "bss": bss, "flash": text + data, "ram": data + bss}


def reported_lsb(info) -> float:
    """The volts of one ADC code of a fixed-point device reading ADS1115s at one PGA, from its INFO; InputError
    when INFO cannot say (an ADS7828's reference is not in it)."""
    from host.channelmap import ADS1115_PGA

    pgas = {c[3] for c in info.adc_chips if c[0] == "ads1115"}
    if len(pgas) != 1 or any(c[0] != "ads1115" for c in info.adc_chips) or min(pgas) >= len(ADS1115_PGA):
        raise InputError("the device reads ADCs whose code scale its INFO does not give (an ADS7828's reference, or "
                         "mixed PGAs): run the suite from tactile-hil emulate --suite, which knows the channel map")
    return ADS1115_PGA[pgas.pop()] / 32768.0
