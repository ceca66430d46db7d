"""An Arduino sketch run on the emulated Uno (hil/emulate.py's libsimavr board), its I2C chips answered by the
bus model: the lines it prints over Serial and the stack's peak, from stack painting. ``build_readpose``
builds the library's ReadPose example (host/arduino.py) and runs it so; ``readpose_table`` reads its lines."""

from __future__ import annotations

import select
import socket
import tempfile
import threading
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from fitgen.base.errors import InputError

from host.boards import BOARDS
from host.arduino import Size, arduino_build, example_elf
from host.sketchbuild import find_builder, require_builder
from host.channelmap import ChannelMap

from hil.emulate import UnoEmulator, bss_end, build_uno_board, require_avr_tools, uno_emulator_available

# the cores the simavr board runs: each one's last RAM address (RAMEND; 0x8FF on the ATmega328P)
RAM_END = {b.mcu: (b.ram_start & 0xFFFF) + b.ram - 1 for b in BOARDS.values() if b.emulated}
REST = "0,0,0,0,0"  # the pose the stack is measured at when none is asked for
LINE_MAX = 1024  # longer than any line ReadPose prints: a line past it is not a sketch's line


@dataclass(frozen=True)
class SketchRun:
    lines: tuple[str, ...]  # the complete lines printed, in order, from the program's start
    stack_peak: int  # the deepest the stack reached, bytes below RAMEND (RAM above .bss no longer painted)
    cycles: int  # the core's cycles over the run (16 MHz)


class StackOverflow(InputError):
    """The stack grew down into static RAM (every painted byte above .bss was overwritten)."""

    def __init__(self, message: str, stack_peak: int):
        super().__init__(message)
        self.stack_peak = stack_peak


def sim_pose(pose) -> np.ndarray:
    """The simulated magnet's pose from ``dx=1,dz=-1`` (parts left out are 0), five numbers, or an array."""
    from host.motion import parse_pose

    if not isinstance(pose, str):
        return np.asarray(pose, dtype=float)
    return parse_pose(pose, "the simulated pose")


def run_sketch(elf: str | Path, cmap: ChannelMap, pose="0,0,0,0,0", *, n_lines: int = 6, sensor: str = "paper",
               noise: float | None = None, seed: int = 0, timeout: float = 60.0,
               board: str | Path | None = None, rest_first: bool = False, offsets: str | None = None,
               send: dict | None = None, mcu: str = "atmega328p") -> SketchRun:
    """Run an ATmega328P ELF (``mcu``: another core of RAM_END's) on the emulated Uno with ``cmap``'s chips on its
    TWI bus, ``sensor`` at ``pose`` (``dx=1,dz=-1`` or five numbers) with ``noise`` V rms (None: the sensor's),
    until it has printed ``n_lines`` lines or a line starting ``error:``. InputError when that takes over
    ``timeout`` s of wall time or the program crashes; :class:`StackOverflow` when its stack ran into static RAM.
    ``board``: a built hil.emulate board (default: built here). ``rest_first``: the sensor rests until the sketch prints its header
    (ReadPose's tare comes before it), then moves to ``pose`` at the start of a sample, as a real one is pressed
    after power-up.
    ``offsets``: each element's offset in volts (host.simbus.simulated_bus's), a drift the tare takes out.
    ``send``: {k: bytes} sent to its Serial once it has printed k lines."""
    from fitgen.physics.sensor import load_sensor
    from host.clock import VirtualClock
    from host.pi import StandIn
    from host.simbus import simulated_bus

    if n_lines < 1:
        raise InputError(f"n_lines must be >= 1, got {n_lines}")
    require_avr_tools()
    clock, target, pressed = VirtualClock(), sim_pose(pose), threading.Event()
    # the feed asks the motion for its pose at each conversion, in the bridge's thread: an event set here is the
    # one thing the two threads share; the press lands on a sample's first conversion, so that no row straddles it
    # (a row read half at rest and half pressed is no pose at all, yet its status is 0)
    gate = {"first": None, "on": False}
    motion = (lambda t: target if gate["on"] else 0 * target) if rest_first else None
    bus = simulated_bus(cmap, load_sensor(sensor), target, clock=clock, noise=noise, seed=seed, motion=motion,
                        offsets=offsets)
    if rest_first:
        feed, element = bus.feed, bus.feed.element
        feed.motion_step = 0.0  # the pose asked at every conversion: it changes only where the gate opens

        def gated(k: int, t: float | None = None) -> float:
            gate["first"] = k if gate["first"] is None else gate["first"]  # the tare's first: a sample's first
            gate["on"] = gate["on"] or (k == gate["first"] and pressed.is_set())
            return element(k, t)

        feed.element = gated
    paint = bss_end(elf)
    with tempfile.TemporaryDirectory(prefix="tactile-sketch-") as tmp:
        board = build_uno_board(tmp) if board is None else board
        # held until the client is there, so that the lines start with the program's first
        emu = UnoEmulator(board, elf, bridge=StandIn(bus, clock), paint=paint, hold=True, mcu=mcu)
        failed = None
        try:
            with emu:
                lines = _read_lines(emu.port, n_lines, timeout, on_header=pressed.set, send=send)
        except InputError as exc:
            failed = exc
    said = "; ".join(emu.messages[-2:])  # the board's own word, e.g. that the program crashed
    if emu.stack_peak is not None and emu.stack_peak >= RAM_END[mcu] + 1 - paint:
        raise StackOverflow(f"the stack ran into static RAM: all {emu.stack_peak} B above .bss were used"
                            + (f" ({said})" if said else ""), emu.stack_peak)
    if failed is not None:
        raise InputError(f"{failed} ({said})" if said else str(failed))
    if emu.stack_peak is None or emu.cycles is None:
        raise InputError(f"the simavr board running {elf} did not report its stack and cycles")
    return SketchRun(tuple(lines), emu.stack_peak, emu.cycles)


def _read_lines(port: int, n_lines: int, timeout: float, on_header=None, send=None) -> list[str]:
    """Up to ``n_lines`` lines from the board's UART (fewer when one starts ``error:``); ``on_header()`` once a
    line starts ``t,``; ``send``: {k: bytes} written to the UART once k lines are in."""
    deadline = time.monotonic() + timeout
    lines, buf, send = [], b"", dict(send or {})
    with socket.create_connection(("127.0.0.1", port), timeout=5) as sock:
        while len(lines) < n_lines and not (lines and lines[-1].startswith("error:")):
            left = deadline - time.monotonic()
            if left <= 0 or not select.select([sock], [], [], left)[0]:
                raise InputError(f"the sketch printed {len(lines)} of {n_lines} lines within {timeout:g} s"
                                 + (f" (the last: {lines[-1]!r})" if lines else ""))
            data = sock.recv(4096)
            if not data:
                raise InputError("the simavr board closed its UART")
            buf += data
            *done, buf = buf.split(b"\n")
            lines += [ln.rstrip(b"\r").decode(errors="replace") for ln in done]
            if on_header is not None and any(ln.startswith("t,") for ln in lines):
                on_header()
            for k in [k for k in send if len(lines) >= k]:
                sock.sendall(send.pop(k))
            if len(buf) > LINE_MAX:
                raise InputError(f"the sketch printed {len(buf)} bytes without a line end")
    return lines[:n_lines]


def readpose_table(lines) -> tuple[tuple[str, ...], np.ndarray]:
    """ReadPose's lines (a header, then t,v1..vN,outputs,status; its tare's line, ``# tare: ...``, before them)
    as (column names, rows); InputError naming the sketch's own ``error:`` line, or a line that is not one of its
    rows."""
    lines = [ln for ln in lines if not ln.startswith("#")]
    err = next((ln for ln in lines if ln.startswith("error:")), None)
    if err is not None:
        raise InputError(f"ReadPose stopped: {err}")
    if not lines or not lines[0].startswith("t,"):
        raise InputError(f"ReadPose's first line is not its header: {lines[0] if lines else 'no lines'!r}")
    names = tuple(lines[0].split(","))
    rows = []
    for ln in lines[1:]:
        try:
            row = [float(x) for x in ln.split(",")]
        except ValueError:
            row = []
        if len(row) != len(names):
            raise InputError(f"ReadPose printed {ln!r}, not a row of {lines[0]!r}")
        rows.append(row)
    return names, np.array(rows, dtype=float).reshape(len(rows), len(names))


def build_readpose(model, cmap: ChannelMap, folder: str | Path, pose=None, *, precision: str = "float",
                   style: str = "unrolled", build: bool | None = None, n_lines: int = 6, sensor: str = "paper",
                   noise: float | None = None, seed: int = 0, build_path: str | Path | None = None,
                   rest=None, offsets: str | None = None, board: str = "uno") -> tuple[Size | None, SketchRun | None]:
    """``arduino_build`` for ``board`` (host.arduino.BOARDS): (its size, None). With a ``pose``, ReadPose is also
    run on the emulated Uno (on a Mega's core for the Mega; a board whose core is not emulated is refused) as
    :func:`run_sketch` runs it, and so is each setting tried when it does not fit: (the size with the stack's
    measured peak, the run). InputError when ReadPose prints an error line, and when it does not fit (flash,
    or static RAM and the stack's peak) naming a setting that does. Without a pose, the stack is still
    measured (ReadPose run at rest) whenever the example is built and the emulated Uno can be: a setting
    whose stack overflows is then refused, not suggested. ``rest``: the tare's rest readings (render_arduino's);
    with them the simulated sensor rests through the tare, then moves to ``pose``; ``offsets``: run_sketch's."""
    asked = pose is not None  # a run asked for needs the builder and the emulator: said before the work
    spec = BOARDS[board]
    if asked and not spec.emulated:
        emulated = ", ".join(k for k, b in BOARDS.items() if b.emulated)
        raise InputError(f"the {spec.label}'s {spec.mcu} is not emulated here: --emulate runs ReadPose with --board "
                         f"{emulated}; without --emulate the {spec.label}'s build is checked for flash and static RAM")
    if pose is None and build is not False and spec.emulated and find_builder() is not None \
            and uno_emulator_available():
        pose = REST
    if pose is None:
        return arduino_build(model, cmap, folder, precision=precision, style=style, build=build,
                             build_path=build_path, rest=rest, board=board), None
    pose, runs = sim_pose(pose), {}  # a bad pose refused before the build
    if asked:
        require_builder()
        require_avr_tools()

    def measure(path, size):
        try:
            run = run_sketch(example_elf(path), cmap, pose, n_lines=n_lines, sensor=sensor, noise=noise, seed=seed,
                             rest_first=rest is not None, offsets=offsets, mcu=spec.mcu)
        except StackOverflow as exc:
            return replace(size, stack=exc.stack_peak)
        readpose_table(run.lines)  # its own error line, or lines that are not its rows, refused
        runs[Path(path)] = run
        return replace(size, stack=run.stack_peak)

    with tempfile.TemporaryDirectory(prefix="tactile-readpose-") as tmp:
        path = Path(tmp) / "build" if build_path is None else Path(build_path)
        size = arduino_build(model, cmap, folder, precision=precision, style=style, build=True, build_path=path,
                             measure=measure, rest=rest, board=board)
    return size, runs[path]
