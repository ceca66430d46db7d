"""Building a sketch for an AVR board with arduino-builder, offline, and reading its flash and RAM from avr-size;
the sizes a link that overflowed gives in its errors."""

from __future__ import annotations

import re
import shlex
import shutil
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path

from fitgen.base.children import run_captured
from fitgen.base.errors import InputError

from host.boards import BOARDS, Board

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
            return f"{what} {'over ' if used > limit else ''}{used} of {limit} B ({100 * used / limit:.0f} %)"
        if self.ram is None:
            return f"{part('flash', self.flash, board.flash)}, {part('RAM', None, board.ram)}"
        if self.stack is None:
            why = ("it does not fit the flash, so it was not run" if self.flash > board.flash
                   else "simavr runs the sketch to measure it" if board.emulated
                   else f"the emulated board runs no {board.mcu}, this board's core")
            return (f"{part('flash', self.flash, board.flash)}, {part('RAM', self.ram, board.ram)} before the stack "
                    f"(not measured: {why}; a table build's may overrun the RAM)")
        if self.ram_used >= board.ram:
            return (f"{part('flash', self.flash, board.flash)}, RAM {self.ram} of {board.ram} B and the stack ran "
                    f"into it (all {self.stack} B above it used)")
        return (f"{part('flash', self.flash, board.flash)}, RAM {self.ram} + stack peak {self.stack} = "
                f"{part('', self.ram_used, board.ram).strip()}")


_OVERFLOW = re.compile(r"address 0x([0-9a-f]+) of .* section `[^']+' is not within region `(text|data)'")


_OVERFLOWED_BY = re.compile(r"region `(text|data)' overflowed by (\d+) bytes")


def _overflow_size(text: str, board: Board = BOARDS["uno"]) -> Size | None:
    """The sizes a linker's region errors give ("not within region": the highest address past it;
    "overflowed by": the region's length and the excess), on ``board``'s core."""
    ends: dict[str, int] = {}
    for m in _OVERFLOW.finditer(text):
        ends[m[2]] = max(ends.get(m[2], 0), int(m[1], 16))
    region = dict(zip(("text", "data"), board.regions))
    for m in _OVERFLOWED_BY.finditer(text):
        end = region[m[1]] + int(m[2]) + (board.ram_start if m[1] == "data" else 0)
        ends[m[1]] = max(ends.get(m[1], 0), end)
    if not ends:
        return None
    ram = ends["data"] - board.ram_start if "data" in ends else None
    return Size(flash=ends.get("text"), ram=ram, overflow=True)


def find_builder() -> str | None:
    return shutil.which("arduino-builder")


def require_builder() -> str:
    """arduino-builder's path; InputError (how to install it) when it is not installed."""
    builder = find_builder()
    if builder is None:
        raise InputError("arduino-builder is not installed (apt-get install arduino-builder arduino-core-avr)")
    return builder


def build_sketch(sketch: str | Path, libraries: dict[str, Path], build_path: str | Path,
                 board: Board = BOARDS["uno"]) -> Size:
    """Build ``sketch`` (an .ino) with arduino-builder, offline, against ``libraries`` ({name: folder}) and the
    core's own; the ELF's sizes."""
    builder = require_builder()
    build_path = Path(build_path)
    build_path.mkdir(parents=True, exist_ok=True)
    # the builder takes a folder of libraries: a link named as each library, so that it is found by name
    with tempfile.TemporaryDirectory() as libs:
        for name, folder in libraries.items():
            (Path(libs) / name).symlink_to(Path(folder).resolve(), target_is_directory=True)
        cmd = [builder, "-compile"]
        for hw in HARDWARE:
            cmd += ["-hardware", hw]
        cmd += ["-tools", HARDWARE[-1], "-fqbn", board.fqbn, "-core-api-version", CORE_API_VERSION]
        cmd += [f"-prefs={p}" for p in BUILDER_PREFS]
        cmd += ["-libraries", libs, "-build-path", str(build_path.resolve()), str(Path(sketch).resolve())]
        proc = run_captured(cmd, timeout=600)
    name = Path(sketch).stem
    if proc.returncode != 0:
        text = proc.stdout + proc.stderr
        over = _overflow_size(text, board)
        if over is not None:
            return over
        elf = sketch_elf(build_path, name)
        if elf.is_file() and ("too big" in text or "Not enough memory" in text):
            return elf_size(elf)  # linked, but past the board's limits (the bootloader's share)
        first = next((ln for ln in text.splitlines() if "error" in ln.lower()), text.strip()[-300:])
        raise InputError(f"building {name} for {board.fqbn} failed: {first.strip()} ({shlex.join(cmd)})")
    return elf_size(sketch_elf(build_path, name))


def elf_size(elf: str | Path) -> Size:
    """Flash and static RAM of an AVR ELF from ``avr-size -A``."""
    out = subprocess.run(["avr-size", "-A", str(elf)], capture_output=True, text=True, check=True).stdout
    sec = {m[1]: int(m[2]) for m in re.finditer(r"^(\.\w+)\s+(\d+)\s+\d+", out, re.M)}
    return Size(flash=sec.get(".text", 0) + sec.get(".data", 0), ram=sec.get(".data", 0) + sec.get(".bss", 0))


def sketch_elf(build_path: str | Path, sketch: str) -> Path:
    """The ELF arduino-builder links ``sketch`` (its name, without .ino) into, in its build path."""
    return Path(build_path) / f"{sketch}.ino.elf"
