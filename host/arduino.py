"""The Arduino library: the model, the ADC drivers over Wire and the channel map (firmware_templates/arduino/).

``render_arduino`` writes a library in the Arduino 1.5 format (library.properties, and library.json
for PlatformIO; ``src/``; ``examples/ReadPose``, which prints ``tactile-host read``'s CSV lines over
Serial). ``build_example`` compiles that example for a board with arduino-builder and reads its
flash and RAM from avr-size; ``arduino_build`` renders, builds when a builder is installed, and
refuses a model that does not fit the board in one line naming a setting that does (found by
building it). The stack's peak is measured by running the example on the emulated Uno
(hil/sketch.py), which a ``Size`` then carries.
"""

from __future__ import annotations

import json
import re
import shlex
import shutil
import subprocess
import tempfile
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

from fitgen import __version__
from fitgen.base.errors import InputError
from fitgen.base.fileio import check_folder, staged_beside, write_atomic
from fitgen.base.progress import Progress
from fitgen.c.cgen import c_real
from fitgen.c.codegen import write_header
from fitgen.equations.model import Model

from host.channelmap import ChannelMap
from host.pi import DRIVER_FILES, check_reads, render_adc_map
from host.readout import TARE_SAMPLES

LIBRARY_NAME = "TactilePose"  # arduino-lint's strict rule: <= 16 characters, no spaces, not "Arduino"/"library"
URL = "https://github.com/tactile-magnetics/fitgen"
SRC_FILES = ("TactilePose.h", "tactile_wire.h", "tactile_wire.cpp")
EXAMPLE = "ReadPose"
PRECISIONS = ("float", "fixed")
WIRE_CLOCK_HZ = 400000  # both ADCs take I2C fast mode
WIRE_TIMEOUT_US = 25000  # one transaction of a few bytes takes < 1 ms at 100 kHz


@dataclass(frozen=True)
class Board:
    fqbn: str
    flash: int  # bytes a sketch may take (the bootloader's excluded)
    ram: int


BOARDS = {"uno": Board("arduino:avr:uno", 32256, 2048)}
# Debian's arduino-builder and arduino-core-avr: the builder's own platform.txt adds the ctags recipe the
# packaged core lacks; the define stands in for a newer compiler's (the core's headers expect it)
HARDWARE = ("/usr/share/arduino-builder", "/usr/share/arduino/hardware")
BUILDER_PREFS = ("compiler.cpp.extra_flags=-DDECIMAL_DIG=9",)
CORE_API_VERSION = "10819"


@dataclass(frozen=True)
class Size:
    flash: int | None  # .text + .data (the data's initial values live in flash too); None: not known
    ram: int | None  # .data + .bss: static RAM, before the stack
    overflow: bool = False  # the linker refused it: a figure is where the section ran past its region
    # the stack's peak measured in an emulator by painting (bytes below RAMEND; None: not run). When it used
    # every painted byte above .bss it may have run past them into static RAM: that is not a fit.
    stack: int | None = None

    @property
    def ram_used(self) -> int | None:
        """Static RAM plus the stack's measured peak (static RAM alone when it was not measured)."""
        return None if self.ram is None else self.ram + (self.stack or 0)

    def fits(self, board: Board) -> bool:
        if self.overflow or self.flash > board.flash:
            return False
        return self.ram <= board.ram if self.stack is None else self.ram_used < board.ram

    def describe(self, board: Board) -> str:
        def part(what, used, limit):
            if used is None:  # the linker stopped at the other region: this one was never placed
                return f"{what} not known (the link failed first)"
            return f"{what} {'over ' if self.overflow and used > limit else ''}{used} of {limit} B ({100 * used / limit:.0f} %)"
        if self.ram is None:
            return f"{part('flash', self.flash, board.flash)}, {part('RAM', None, board.ram)}"
        if self.stack is None:
            return (f"{part('flash', self.flash, board.flash)}, {part('RAM', self.ram, board.ram)} before the stack "
                    "(not measured: simavr runs the sketch to measure it; a table build's may overrun the RAM)")
        if self.ram_used >= board.ram:
            return (f"{part('flash', self.flash, board.flash)}, RAM {self.ram} of {board.ram} B and the stack ran "
                    f"into it (all {self.stack} B above it used)")
        return (f"{part('flash', self.flash, board.flash)}, RAM {self.ram} + stack peak {self.stack} = "
                f"{part('', self.ram_used, board.ram).strip()}")


AVR_RAM_START = 0x800100  # the linker's address of the ATmega328P's first RAM byte
_OVERFLOW = re.compile(r"address 0x([0-9a-f]+) of .* section `[^']+' is not within region `(text|data)'")


_OVERFLOWED_BY = re.compile(r"region `(text|data)' overflowed by (\d+) bytes")
REGION = {"text": 32768, "data": 2048}  # the ATmega328P's regions in avr-gcc's device spec


def _overflow_size(text: str) -> Size | None:
    """The sizes a linker's region errors give ("not within region": the highest address past it;
    "overflowed by": the region's length and the excess)."""
    ends: dict[str, int] = {}
    for m in _OVERFLOW.finditer(text):
        ends[m[2]] = max(ends.get(m[2], 0), int(m[1], 16))
    for m in _OVERFLOWED_BY.finditer(text):
        end = REGION[m[1]] + int(m[2]) + (AVR_RAM_START if m[1] == "data" else 0)
        ends[m[1]] = max(ends.get(m[1], 0), end)
    if not ends:
        return None
    ram = ends["data"] - AVR_RAM_START if "data" in ends else None
    return Size(flash=ends.get("text"), ram=ram, overflow=True)


def library_properties(n_elements: int = 8) -> str:
    """library.properties: every field the Arduino library specification (rev. 2.2) and arduino-lint's
    strict schema require; ``n_elements``: the model's."""
    fields = {
        "name": LIBRARY_NAME,
        "version": __version__,
        "author": "fitgen contributors",
        "maintainer": "fitgen contributors",
        "sentence": f"Pose of a magnetic tactile sensor from {n_elements} GMR elements read by ADS1115 or ADS7828 "
                    "ADCs.",
        "paragraph": "Generated by tactile-host arduino-build: a fitted regression model (displacement and tilt "
                     "of the magnet), the ADC drivers over Wire with time limits on every wait, and the channel "
                     "map. The ReadPose example prints tactile-host read's CSV lines over Serial.",
        "category": "Sensors",
        "url": URL,
        # the Wire timeout calls (setWireTimeout and its flag) are the AVR core's; other cores lack some
        "architectures": "avr",
        "includes": "TactilePose.h",
    }
    return "".join(f"{k}={v}\n" for k, v in fields.items())


def library_json() -> str:
    """library.json for PlatformIO (its manifest's required fields: name, version, description)."""
    return json.dumps({
        "name": LIBRARY_NAME,
        "version": __version__,
        "description": "Pose of a magnetic tactile sensor from GMR elements read by ADS1115/ADS7828 ADCs over Wire "
                       "(generated by tactile-host arduino-build).",
        "keywords": "tactile, magnetic, sensor, ads1115, ads7828",
        "repository": {"type": "git", "url": URL + ".git"},
        "authors": [{"name": "fitgen contributors", "maintainer": True}],
        "license": "MIT",
        "frameworks": "arduino",
        "platforms": "atmelavr",
        "headers": "TactilePose.h",
    }, indent=2) + "\n"


def _lsb_volts(chip) -> float:
    """Volts per code, as adc.c's adc_lsb_volts computes it."""
    return chip.settings.pga / 32768.0 if chip.kind == "ads1115" else chip.vref_volts / 4096.0


def render_config(cmap: ChannelMap, precision: str, rest=None) -> str:
    """``tactile_config.h``: the precision, the Wire settings, each element's volts per code, and with ``rest``
    (volts, the readings the model expects at rest) the tare ReadPose takes at start."""
    lsb = [_lsb_volts(chip) for chip, _ in cmap.elements()]
    tare = [] if rest is None else [
        f"#define TACTILE_TARE_SAMPLES {TARE_SAMPLES}",
        "/* V: the readings the model expects at rest, which the tare maps the untouched sensor's onto */",
        f"static const float TACTILE_REST[{len(lsb)}] = {{ {', '.join(c_real(float(x), 'float') for x in rest)} }};"]
    rates = sorted({f"{c.settings.pga:g} V, {c.settings.data_rate} SPS" for c in cmap.chips if c.kind == "ads1115"})
    return "\n".join([
        f"/* tactile_config.h: generated by tactile-host arduino-build (fitgen {__version__}). Do not edit. */",
        "#ifndef TACTILE_CONFIG_H", "#define TACTILE_CONFIG_H", "",
        f"/* the channel map {cmap.describe()}" + (f"; ADS1115 PGA +-{', '.join(rates)}" if rates else "") + " */",
        f"#define TACTILE_FIXED_POINT {int(precision == 'fixed')}",
        f"#define TACTILE_WIRE_CLOCK_HZ {WIRE_CLOCK_HZ}L",
        f"#define TACTILE_WIRE_TIMEOUT_US {WIRE_TIMEOUT_US}uL",
        f"static const float TACTILE_LSB[{len(lsb)}] = {{ {', '.join(c_real(x, 'float') for x in lsb)} }};",
        f"#define TACTILE_TARE {int(rest is not None)}", *tare,
        "", "#endif /* TACTILE_CONFIG_H */", ""])


def _write_model(model: Model, src: Path, precision: str, style: str, lsb: float | None) -> None:
    if precision == "fixed":  # the plan for the Uno's 16-bit multiply (fitgen.equations.fixednarrow)
        write_header(model, src, "fixed", input_lsb=lsb, input_offset=0.0, target="uno")
    else:  # a float header is the same for every core; the Uno's target refuses a refinement up front
        write_header(model, src, precision, style, target="uno")


def render_arduino(model: Model, cmap: ChannelMap, folder: str | Path, *, precision: str = "float",
                   style: str = "unrolled", rest=None) -> Path:
    """Write the library for ``model`` read through ``cmap`` into ``folder`` (created); with ``rest`` (volts, one
    per element: host.readout.model_rest) ReadPose tares at start onto them."""
    if precision == "double":
        raise InputError("an Arduino's double is 32 bits on AVR (avr-gcc): build the model in float or fixed")
    if precision not in PRECISIONS:
        raise InputError(f"the Arduino library computes in {' or '.join(PRECISIONS)}, not {precision!r}")
    check_reads(model, cmap)
    folder = Path(folder)
    src, tpl = folder / "src", resources.files("firmware_templates")
    if precision == "fixed":
        lsbs = {_lsb_volts(chip) for chip, _ in cmap.elements()}
        if len(lsbs) != 1:
            raise InputError("fixed point takes one volts-per-code for every element; the channel map mixes "
                             f"{len(lsbs)}: read every element with the same chip type and PGA, or use float")
        _write_model(model, src, precision, style, lsbs.pop())
    else:
        _write_model(model, src, precision, style, None)
    for name in DRIVER_FILES:
        write_atomic(src / name, (tpl / "firmware" / name).read_bytes())
    for name in SRC_FILES:
        write_atomic(src / name, (tpl / "arduino" / name).read_bytes())
    write_atomic(src / "adc_map.h", render_adc_map(cmap))
    if rest is not None and len(rest) != model.n_inputs:
        raise InputError(f"{len(rest)} rest readings for a model of {model.n_inputs} inputs")
    write_atomic(src / "tactile_config.h", render_config(cmap, precision, rest))
    ino = f"{EXAMPLE}/{EXAMPLE}.ino"
    (folder / "examples" / EXAMPLE).mkdir(parents=True, exist_ok=True)
    write_atomic(folder / "examples" / ino, (tpl / "arduino" / ino).read_bytes())
    write_atomic(folder / "library.properties", library_properties(model.n_inputs))
    write_atomic(folder / "library.json", library_json())
    return folder


def find_builder() -> str | None:
    return shutil.which("arduino-builder")


def require_builder() -> str:
    """arduino-builder's path; InputError (how to install it) when it is not installed."""
    builder = find_builder()
    if builder is None:
        raise InputError("arduino-builder is not installed (apt-get install arduino-builder arduino-core-avr)")
    return builder


def build_example(library: str | Path, build_path: str | Path, board: Board = BOARDS["uno"]) -> Size:
    """Build examples/ReadPose against ``library`` with arduino-builder, offline; the ELF's sizes."""
    library, build_path = Path(library).resolve(), Path(build_path)
    builder = require_builder()
    build_path.mkdir(parents=True, exist_ok=True)
    # the builder takes a folder of libraries: a link named as the library, so that it is found by name
    with tempfile.TemporaryDirectory() as libs:
        (Path(libs) / LIBRARY_NAME).symlink_to(library, target_is_directory=True)
        cmd = [builder, "-compile"]
        for hw in HARDWARE:
            cmd += ["-hardware", hw]
        cmd += ["-tools", HARDWARE[-1], "-fqbn", board.fqbn, "-core-api-version", CORE_API_VERSION]
        cmd += [f"-prefs={p}" for p in BUILDER_PREFS]
        cmd += ["-libraries", libs, "-build-path", str(build_path.resolve()),
                str(library / "examples" / EXAMPLE / f"{EXAMPLE}.ino")]
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    if proc.returncode != 0:
        text = proc.stdout + proc.stderr
        over = _overflow_size(text)
        if over is not None:
            return over
        elf = example_elf(build_path)
        if elf.is_file() and ("too big" in text or "Not enough memory" in text):
            return elf_size(elf)  # linked, but past the board's limits (the bootloader's share)
        first = next((ln for ln in text.splitlines() if "error" in ln.lower()), text.strip()[-300:])
        raise InputError(f"building {EXAMPLE} for {board.fqbn} failed: {first.strip()} ({shlex.join(cmd)})")
    return elf_size(example_elf(build_path))


def elf_size(elf: str | Path) -> Size:
    """Flash and static RAM of an AVR ELF from ``avr-size -A``."""
    out = subprocess.run(["avr-size", "-A", str(elf)], capture_output=True, text=True, check=True).stdout
    sec = {m[1]: int(m[2]) for m in re.finditer(r"^(\.\w+)\s+(\d+)\s+\d+", out, re.M)}
    return Size(flash=sec.get(".text", 0) + sec.get(".data", 0), ram=sec.get(".data", 0) + sec.get(".bss", 0))


def _alternatives(precision: str, style: str):
    """Settings to try when a build does not fit, in the order a user would rather have them."""
    other = "table" if style == "unrolled" else "unrolled"
    if precision == "float":
        yield "float", other, f"--style {other}"
        yield "fixed", style, "--precision fixed"
    else:  # a fixed-point model too big for the flash: float's terms unrolled are its last resort
        yield "float", "unrolled", "--precision float"


def example_elf(build_path: str | Path) -> Path:
    """The ELF arduino-builder links the example into, in its build path."""
    return Path(build_path) / f"{EXAMPLE}.ino.elf"


def arduino_build(model: Model, cmap: ChannelMap, folder: str | Path, *, precision: str = "float",
                  style: str = "unrolled", board: str = "uno", build: bool | None = None,
                  build_path: str | Path | None = None, measure=None, rest=None) -> Size | None:
    """Render the library; when ``build`` (default: when arduino-builder is installed) build its example and
    refuse a model that does not fit ``board`` (InputError naming a setting that fits, or fewer terms).
    ``build_path``: where the example is built and kept (default: a folder removed afterwards). ``measure``:
    ``measure(build_path, size)`` -> the size with the stack's peak (hil/sketch.py runs the example), for the
    build and for each setting tried in its place. ``rest``: as for :func:`render_arduino`."""
    folder = _library_folder(folder)
    with staged_beside(folder) as partial:  # the library replaces the folder's only when it fits
        render_arduino(model, cmap, partial, precision=precision, style=style, rest=rest)
        size = _build_fitting(model, cmap, partial, precision, style, board, build, build_path, measure, rest)
        _install(partial, folder)
        return size


LIBRARY_FOLDER = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,62}")  # the library specification's root folder name


def folder_name_note(folder: str | Path) -> str:
    """'' when ``folder``'s name is one the Arduino library specification allows for a library's root folder, else
    a note that says why the IDE will not list it and what to name it."""
    name = Path(folder).name
    if LIBRARY_FOLDER.fullmatch(name):
        return ""
    return (f"note: the folder name {name!r} is not one the Arduino library specification allows (a letter or "
            "digit, then letters, digits, '_', '.' or '-', at most 63): the IDE will not list it as a library; "
            f"name the folder {LIBRARY_NAME}")


def _library_folder(folder: str | Path) -> Path:
    """``folder`` as the library's (its parents made); InputError when it cannot be one."""
    path = check_folder(folder)
    if path.name in ("", ".", ".."):
        raise InputError(f"-o {str(folder)!r}: name the library's folder (e.g. {LIBRARY_NAME})")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"cannot create {path.parent}: {exc.strerror}") from None
    return path


INSTALLED = ("src", f"examples/{EXAMPLE}", "library.properties", "library.json")


def _install(partial: Path, folder: Path) -> None:
    """Move the rendered library's parts into ``folder``, each replacing the last build's whole (``src/`` is
    generated: a file left there would be compiled with it); the folder's other files stay."""
    (folder / "examples").mkdir(parents=True, exist_ok=True)
    for part in INSTALLED:
        old = folder / part
        if old.is_dir() and not old.is_symlink():
            shutil.rmtree(old)
        elif old.exists() or old.is_symlink():
            old.unlink()
        (partial / part).replace(old)


def _build_fitting(model, cmap, library: Path, precision, style, board, build, build_path, measure,
                   rest=None) -> Size | None:
    """Build ``library``'s example when ``build`` (None: when a builder is installed); InputError naming a
    setting that fits when it does not."""
    spec = BOARDS[board]
    if build is None:
        build = find_builder() is not None
    if not build:
        return None

    def built(library, path, what):
        bar.update(0, f"building ReadPose ({what}) with arduino-builder")
        size = build_example(library, path, spec)
        if measure is None or not size.fits(spec):
            return size
        bar.update(0, f"running ReadPose ({what}) on the emulated Uno for its stack")
        return measure(path, size)

    # a bar on a terminal: a build takes 5-9 s, and one that does not fit is tried in other settings
    with tempfile.TemporaryDirectory() as tmp, Progress("arduino-build", 1) as bar:
        size = built(library, Path(tmp) / "build" if build_path is None else build_path, f"{precision}, {style}")
        if size.fits(spec):
            return size
        terms = sum(len(e.terms) for e in model.equations)
        penalty = (model.fit_info.get("settings") or {}).get("k") if isinstance(model.fit_info, dict) else None
        fewer = ("fitgen fit --max-terms N, per output" if isinstance(penalty, (int, float)) and penalty > 2.0
                 else "fitgen fit --k bic, or --max-terms N")  # a model fitted with BIC already: only the cap is left
        hint = (f"no other precision or style fits: fit fewer terms than its {terms} ({fewer}; `fitgen tradeoff "
                f"SENSOR --scene full --core {board}` measures which fit and what they cost in accuracy)")
        for k, (prec, sty, option) in enumerate(_alternatives(precision, style)):
            try:
                alt = render_arduino(model, cmap, Path(tmp) / f"alt{k}", precision=prec, style=sty, rest=rest)
                alt_size = built(alt, Path(tmp) / f"build{k}", f"does {option} fit?")
            except InputError:
                continue  # e.g. a model fixed point cannot plan
            if alt_size.fits(spec):
                hint = f"{option} fits ({alt_size.describe(spec)})"
                break
    raise InputError(f"the model does not fit the {board}: {size.describe(spec)}; {hint}")
