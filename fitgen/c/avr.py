"""The generated header on the ATmega328P (Arduino Uno) in simavr: outputs and cycles per estimate.

``run_on_avr`` builds the header into a small AVR program (firmware_templates/avr/bench_main.c.j2:
the inputs in flash, each estimate bracketed by GPIOR0 writes), runs it in libsimavr at 16 MHz
through a C runner (firmware_templates/avr/simavr_run.c) and reads back every output's bits and the
cycles simavr counted for each estimate.
"""

from __future__ import annotations

import re
import shutil
import subprocess
import tempfile
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np

from fitgen import __version__
from fitgen.base.children import run_captured
from fitgen.base.errors import InputError
from fitgen.c.codegen import _env, render_fixed_header, write_header
from fitgen.c.compiled import WARNING_FLAGS
from fitgen.c.targets import TARGETS, check_precision
from fitgen.equations.model import Model

MCU = "atmega328p"
F_CPU = 16_000_000
AVR_CC = "avr-gcc"
RUNNER_CC = "gcc"
MAX_VECTORS = 400  # the inputs sit in flash: 400 x 8 x 4 B = 12.8 KB of its 32 KB
# the runner's time limit, in emulated cycles: 2 M per vector is ~10x a float estimate's cost
CYCLES_PER_VECTOR_LIMIT = 2_000_000


@dataclass
class AvrRun:
    outputs: np.ndarray  # (n, K): float results as float64 (exact), fixed point as int64 codes
    status: np.ndarray  # (n,)
    cycles: np.ndarray  # (n,) cycles of each estimate (the bracket's own cost taken off)
    flash: int  # bytes of the whole program (text + data)
    ram: int  # static RAM of the whole program (data + bss), the stack not included

    def per_second(self) -> float:
        """Estimates per second at 16 MHz, from the mean cycles."""
        return F_CPU / float(np.mean(self.cycles))


def _tool(name: str) -> str:
    if shutil.which(name) is None:
        raise InputError(f"{name!r} not found (apt-get install gcc-avr avr-libc simavr libsimavr-dev libelf-dev)")
    return name


def _run(cmd: list[str], what: str, timeout: float = 600) -> subprocess.CompletedProcess:
    proc = run_captured(cmd, timeout=timeout)
    if proc.returncode != 0:
        lines = (proc.stderr.strip() or proc.stdout.strip() or "(no message)").splitlines()
        over = re.search(r"region `(text|data)' overflowed by (\d+) bytes", proc.stderr)
        if over:  # the linker's reason, not collect2's "ld returned 1 exit status" that follows it
            raise InputError(f"{what} failed: over the ATmega328P's {'flash' if over[1] == 'text' else 'RAM'} by "
                             f"{int(over[2]):,} B")
        first = next((ln for ln in lines if "error" in ln), lines[0])
        raise InputError(f"{what} failed: {first.strip()}")
    return proc


def build_simavr_program(folder: str | Path, source: str) -> Path:
    """A libsimavr program of firmware_templates/avr/ (``source``, with simavr_boot.h) compiled into ``folder``;
    the binary is named after the source."""
    folder = Path(folder)
    src, binary = folder / source, folder / Path(source).stem
    for name in (source, "simavr_boot.h"):
        (folder / name).write_bytes((resources.files("firmware_templates") / "avr" / name).read_bytes())
    flags = _run(["pkg-config", "--cflags", "--libs", "simavr"], "pkg-config simavr").stdout.split()
    _run([_tool(RUNNER_CC), "-O2", "-Wall", "-Wextra", "-Werror", str(src), "-o", str(binary)] + flags + ["-lelf"],
         f"building {source}")
    return binary


def build_runner(folder: Path) -> Path:
    """The libsimavr runner, compiled once into ``folder``."""
    binary = folder / "simavr_run"
    return binary if binary.is_file() else build_simavr_program(folder, "simavr_run.c")


def _literals(inputs: np.ndarray, precision: str) -> list[list[str]]:
    if precision == "fixed":
        return [[f"INT32_C({int(x)})" for x in row] for row in inputs]
    return [[float(x).hex() + "f" for x in row] for row in inputs]


def run_on_avr(model: Model, inputs, precision: str = "float", style: str = "table",
               input_lsb: float | None = None, input_offset: float | None = None,
               workdir: str | Path | None = None, mul_bits: int | None = None, portable: bool = False,
               runner: Path | None = None, opt: tuple[str, ...] = ("-O2",)) -> AvrRun:
    """Estimates of ``inputs`` (float: values, rounded to float first; fixed: ADC codes) on the ATmega328P.

    Fixed point: the plan for ``mul_bits`` (default the Uno's, fitgen.c.targets); ``portable``: the
    header's portable C instead of its AVR assembly (TM_PORTABLE_C), for comparison. ``runner``: a
    simavr runner already built (:func:`build_runner`), else one is built in the work folder. ``opt``:
    avr-gcc's optimisation flags (the Arduino IDE's are -Os -flto)."""
    uno = check_precision("uno", precision)
    inputs = np.atleast_2d(np.asarray(inputs, dtype=float))
    if not 0 < len(inputs) <= MAX_VECTORS or inputs.shape[1] != model.n_inputs:
        raise InputError(f"give 1..{MAX_VECTORS} rows of {model.n_inputs} inputs, got {inputs.shape}")
    if precision == "fixed":
        from fitgen.equations.inputscale import plan_at

        fm = plan_at(model, input_lsb, input_offset, mul_bits or uno.mul_bits)[0]
        fm.clamp_codes(inputs)  # whole numbers within int32 (InputError otherwise)
    elif not np.all(np.isfinite(inputs)):
        raise InputError("the AVR bench takes finite inputs")
    else:
        inputs = inputs.astype(np.float32).astype(float)
    tmp = tempfile.TemporaryDirectory(prefix="fitgen-avr-") if workdir is None else None
    folder = Path(tmp.name if tmp else workdir)
    try:
        folder.mkdir(parents=True, exist_ok=True)
        if precision == "fixed":
            (folder / "tm_model.h").write_text(render_fixed_header(fm))
        else:
            write_header(model, folder, precision, style, target="uno")
        main = _env().get_template("avr/bench_main.c.j2").render(n=len(inputs), rows=_literals(inputs, precision),
                                                                 version=__version__)
        (folder / "bench_main.c").write_text(main)
        elf = folder / "bench.elf"
        _run([_tool(AVR_CC), f"-mmcu={MCU}", f"-DF_CPU={F_CPU}UL", *WARNING_FLAGS, *opt, "-I", str(folder),
              *(["-DTM_PORTABLE_C"] if portable else []),
              str(folder / "bench_main.c"), "-o", str(elf)], "building the AVR program")
        size = _run([_tool("avr-size"), str(elf)], "avr-size").stdout.splitlines()[1].split()
        text, data, bss = (int(x) for x in size[:3])
        limit = CYCLES_PER_VECTOR_LIMIT * (len(inputs) + 1)
        proc = _run([str(runner or build_runner(folder)), str(elf), str(limit)], "the AVR program in simavr")
    finally:
        if tmp is not None:
            tmp.cleanup()
    # simavr's ELF loader prints "Loaded N bytes" lines to stdout before the program runs
    lines = [ln for ln in proc.stdout.splitlines() if not ln.startswith("Loaded ")]
    if not lines or lines[-1] != "." or len(lines) != len(inputs) + 1:
        raise RuntimeError(f"the AVR program answered {len(lines)} lines for {len(inputs)} vectors")
    cycles = np.array([int(ln.split()[1]) for ln in proc.stderr.splitlines() if ln.startswith("CYCLES ")])
    if len(cycles) != len(inputs) + 1:
        raise RuntimeError(f"simavr counted {len(cycles)} brackets for {len(inputs)} vectors")
    rows = [ln.split() for ln in lines[:-1]]
    status = np.array([np.int16(np.uint16(int(r[0], 16))) for r in rows], dtype=np.int64)
    bits = np.array([[int(x, 16) for x in r[1:]] for r in rows], dtype=np.uint32)
    outputs = bits.view(np.int32).astype(np.int64) if precision == "fixed" \
        else bits.view(np.float32).astype(float)
    return AvrRun(outputs, status, cycles[1:] - cycles[0], text + data, data + bss)


def fits_uno(run: AvrRun) -> bool:
    """The program's flash and static RAM within the Uno's (flash less the 512 B bootloader)."""
    uno = TARGETS["uno"]
    return run.flash <= uno.flash - 512 and run.ram <= uno.ram

