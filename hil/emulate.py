"""Run the reference firmware where the HIL suite can reach it: QEMU's mps2-an386 or microbit, simavr's
ATmega328P (the Arduino Uno), or the host build on a pty."""

from __future__ import annotations

import os
import select
import shutil
import signal
import socket
import subprocess
import time
from pathlib import Path

from fitgen.base.children import tied
from fitgen.base.errors import InputError
from fitgen.base.fileio import foreign_files, hold_folder, write_atomic

QEMU = "qemu-system-arm"
# the emulated boards: QEMU machine per target (mps2: Cortex-M4F; microbit: nRF51822, Cortex-M0)
MACHINES = {"mps2": "mps2-an386", "microbit": "microbit"}
TARGETS = tuple(MACHINES) + ("uno", "host")
INSTALL_HINT = "install them with: sudo apt-get install qemu-system-arm gcc-arm-none-eabi"
AVR_TOOLS = ("avr-gcc", "avr-size", "avr-nm", "gcc", "pkg-config")
AVR_HINT = "install the Uno's tools with: sudo apt-get install gcc-avr binutils-avr avr-libc simavr libsimavr-dev libelf-dev pkg-config"
# -icount shift=0: the emulated core retires one instruction per ns of virtual time, so the
# 25 MHz SysTick counts one tick per 40 instructions (docs/hil.md)
ICOUNT_SHIFT = 0
# QEMU's CMSDK UART (mps2) holds one received byte and has no FIFO: fed straight from the socket, QEMU
# reads one byte per turn of its main loop, and only after the core has taken the one before (a wake of
# the emulated core, thread switches and a lock hand-over per byte: 45-75 us on a 2-core VM, 150 s for
# the suite's 2.2 MB of fuzz frames; docs/hil.md). A mux chardev in front holds 32 bytes and hands the
# next one to the UART as soon as the firmware reads DATA (qemu_chr_fe_accept_input), so the socket is
# read while the core works. The mux's escape character (C-a by default; C-a x would stop QEMU) is set
# outside the byte range, so every byte passes. The microbit's nRF51 UART has a 6-byte FIFO and is left
# as it was (the mux measured within 10 % there).
MUX_ESCAPE_OFF = "256"
BUFFERED_MACHINES = ("mps2-an386",)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def listens(pid: int, port: int) -> bool | None:
    """Whether process ``pid`` holds the socket listening on 127.0.0.1:``port`` (None where /proc cannot say):
    a probe must not take another program's listener for the emulator's."""
    try:
        owned = set()
        for fd in os.scandir(f"/proc/{pid}/fd"):
            try:
                target = os.readlink(fd.path)
            except OSError:
                continue
            if target.startswith("socket:["):
                owned.add(target[8:-1])
        with open("/proc/net/tcp") as table:
            rows = table.read().splitlines()[1:]
    except OSError:
        return None
    for row in rows:
        f = row.split()
        if len(f) > 9 and f[3] == "0A" and int(f[1].rpartition(":")[2], 16) == port and f[9] in owned:
            return True
    return False


def stop_process(proc: subprocess.Popen | None, sig: int = signal.SIGTERM, timeout: float = 5.0) -> None:
    """Send ``sig`` to a running ``proc`` and wait for it; killed when it has not ended after ``timeout`` s."""
    if proc is None or proc.poll() is not None:
        return
    proc.send_signal(sig)
    try:
        proc.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


class _Running:
    """A started firmware process: stopped (and its build folder removed) on exit."""

    proc: subprocess.Popen | None = None
    _tmp = _lock = None

    def start(self):
        raise NotImplementedError

    def stop(self) -> None:
        stop_process(self.proc)
        if self.proc is not None and self.proc.stderr is not None:
            self.proc.stderr.close()
        self.proc = None
        if self._tmp is not None:
            self._tmp.cleanup()
            self._tmp = None
        if self._lock is not None:
            self._lock.close()
            self._lock = None

    def __enter__(self):
        try:
            return self.start()
        except BaseException:  # a start that failed: its process, folder and lock go too (no __exit__ follows)
            self.stop()
            raise

    def __exit__(self, *exc) -> None:
        self.stop()


class Emulator(_Running):
    """A Cortex-M4 firmware ELF booted in qemu-system-arm, its UART on ``socket://127.0.0.1:port``."""

    def __init__(self, elf: str | Path, port: int | None = None, icount: bool = True, boot_timeout: float = 10.0,
                 bridge=None, machine: str = "mps2-an386", buffered: bool | None = None):
        if shutil.which(QEMU) is None:
            raise InputError(f"{QEMU} not found; {INSTALL_HINT}")
        if not Path(elf).is_file():
            raise InputError(f"firmware {elf} not found")
        self.elf, self.icount, self.boot_timeout, self.machine = Path(elf), icount, boot_timeout, machine
        # buffered: the UARTs through a mux chardev (default: the boards whose UART has no FIFO)
        self.buffered = machine in BUFFERED_MACHINES if buffered is None else bool(buffered)
        # bridge (host.pi.StandIn): answers the firmware's I2C bridge on the board's second UART
        self.bridge = bridge
        self.bridge_port = free_port() if bridge is not None else None
        self.port = port if port is not None else free_port()
        if not 0 < self.port < 65536:
            raise InputError(f"port {self.port} is not a TCP port number")
        self._chosen = port is None  # ports picked here may be taken before QEMU binds them: picked again
        self.proc: subprocess.Popen | None = None

    @property
    def url(self) -> str:
        return f"socket://127.0.0.1:{self.port}"

    def _serial(self, name: str, port: int) -> list[str]:
        """QEMU's options for one board UART served on 127.0.0.1:``port`` (through a mux when buffered)."""
        if not self.buffered:
            return ["-serial", f"tcp:127.0.0.1:{port},server=on,wait=off,nodelay=on"]
        return ["-chardev", f"socket,id={name},host=127.0.0.1,port={port},server=on,wait=off,nodelay=on,mux=on",
                "-serial", f"chardev:{name}"]

    def command(self) -> list[str]:
        cmd = [QEMU, "-M", self.machine, "-display", "none", "-monitor", "none", "-nodefaults",
               *self._serial("uart0", self.port), "-kernel", str(self.elf)]
        if self.bridge is not None:
            cmd += self._serial("bridge", self.bridge_port)
        if self.buffered:
            cmd += ["-echr", MUX_ESCAPE_OFF]
        if self.icount:
            cmd += ["-icount", f"shift={ICOUNT_SHIFT}"]
        return cmd

    def start(self, attempts: int = 3) -> "Emulator":
        self.proc = subprocess.Popen(self.command(), stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                     stderr=subprocess.PIPE, text=True, preexec_fn=tied())
        deadline = time.monotonic() + self.boot_timeout
        while True:
            if self.proc.poll() is not None:
                err = (self.proc.stderr.read() or "").strip().splitlines()
                if any("Address already in use" in ln for ln in err):
                    if attempts > 1 and (self._chosen or self.bridge is not None):
                        self.port = free_port() if self._chosen else self.port
                        self.bridge_port = free_port() if self.bridge is not None else None
                        return self.start(attempts - 1)
                    raise InputError(f"{QEMU} could not listen on 127.0.0.1:{self.port}: another program uses it")
                raise InputError(f"{QEMU} exited at start: {err[-1] if err else 'no message'}")
            try:
                if any(listens(self.proc.pid, p) is False for p in (self.port, self.bridge_port) if p is not None):
                    raise ConnectionRefusedError  # not QEMU's listener yet (or another program's)
                # QEMU listens once its chardev is up; the probe's connection is closed at once
                with socket.create_connection(("127.0.0.1", self.port), timeout=0.5) as probe:
                    if self.buffered:
                        self._await_firmware(probe, deadline)
                if self.bridge is not None:
                    sock = socket.create_connection(("127.0.0.1", self.bridge_port), timeout=5)
                    sock.settimeout(None)
                    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                    self.bridge.serve_socket(sock)
                return self
            except OSError:
                if time.monotonic() > deadline:
                    self.stop()
                    raise InputError(f"{QEMU} did not open port {self.port} within {self.boot_timeout:g} s") from None
                time.sleep(0.05)

    def _await_firmware(self, sock: socket.socket, deadline: float) -> None:
        """PING until the firmware answers. Bytes that reach the mux before the firmware has enabled its UART
        stay in the mux until the next byte arrives: an empty frame (a lone delimiter, which the firmware
        ignores) every 20 ms pushes them on."""
        from host import protocol as P

        token = b"boot" + os.urandom(8)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        sock.sendall(P.encode_frame(P.MsgType.PING, 1, token))
        reader = P.FrameReader()
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                self.stop()
                raise InputError(f"the firmware on {self.url} did not answer PING within {self.boot_timeout:g} s")
            if select.select([sock], [], [], min(left, 0.02))[0]:
                data = sock.recv(4096)
                if not data:
                    raise OSError("QEMU closed the connection")
                if any(f.type == P.MsgType.PING | P.REPLY and f.payload == token for f in reader.feed(data)):
                    return
            else:
                sock.sendall(b"\x00")


class HostFirmware(_Running):
    """The host build of the firmware serving on a pseudo-terminal; ``url`` is the pty's path."""

    def __init__(self, binary: str | Path, boot_timeout: float = 5.0, bridge=None):
        if not Path(binary).is_file():
            raise InputError(f"firmware {binary} not found")
        self.binary, self.boot_timeout, self.bridge = Path(binary), boot_timeout, bridge
        self.proc: subprocess.Popen | None = None
        self.url = ""

    def start(self) -> "HostFirmware":
        popen = dict(stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        cmd = [str(self.binary), "--pty"]
        # with a bridge (host.pi.StandIn) the firmware's I2C requests go out on fd 3, answers come on fd 4
        self.proc = (self.bridge.spawn(cmd, **popen) if self.bridge is not None
                     else subprocess.Popen(cmd, preexec_fn=tied(), **popen))
        fd = self.proc.stderr.fileno()
        buf = b""
        deadline = time.monotonic() + self.boot_timeout
        while b"\n" not in buf:
            left = deadline - time.monotonic()
            ready = select.select([fd], [], [], max(left, 0))[0] if left > 0 else []
            chunk = os.read(fd, 256) if ready else b""
            if not chunk:
                self.stop()
                raise InputError(f"host firmware {self.binary} did not announce its pty")
            buf += chunk
        line = buf.split(b"\n", 1)[0].decode(errors="replace").strip()
        if not line.startswith("PTY "):
            self.stop()
            raise InputError(f"host firmware said {line!r} instead of 'PTY <path>'")
        self.url = line[4:]
        return self


class UnoEmulator(_Running):
    """An ATmega328P firmware ELF run by the libsimavr board (firmware_templates/avr/uno_board.c), its USART0
    on ``socket://127.0.0.1:port`` (without ``port``, one the board binds itself, known after start());
    with ``bridge`` (host.pi.StandIn) the TWI bus carries the bus model's
    chips. ``eeprom``: a file that keeps the EEPROM from one run to the next (what a board keeps over a
    reset). ``paint``: the address where RAM above .bss starts; after stop(), ``stack_peak`` holds the
    deepest the stack reached (bytes), and ``cycles`` the cycles the core ran. ``hold``: the core starts when
    the first client connects (as an Uno restarts when a serial monitor opens its port). ``mcu``: simavr's
    name of the core (another board's sketch: the Mega's atmega2560)."""

    def __init__(self, board: str | Path, elf: str | Path, port: int | None = None, *, bridge=None,
                 paint: int | None = None, eeprom: str | Path | None = None, boot_timeout: float = 10.0,
                 hold: bool = False, mcu: str = "atmega328p"):
        self.board, self.elf, self.bridge, self.paint, self.hold = Path(board), Path(elf), bridge, paint, hold
        self.mcu = mcu
        self.eeprom = eeprom
        self.port = port if port is not None else 0  # 0: the board binds a free port and says which
        self.boot_timeout = boot_timeout
        self.stack_peak: int | None = None
        self.cycles: int | None = None
        self.returncode: int | None = None  # the board's exit status, after stop()
        self.messages: list[str] = []  # what else it said on stderr, after stop()
        self.proc = None

    @property
    def url(self) -> str:
        return f"socket://127.0.0.1:{self.port}"

    def command(self) -> list[str]:
        return [str(self.board), str(self.elf), str(self.port)] + (["--bridge"] if self.bridge is not None else []) \
            + (["--eeprom", str(self.eeprom)] if self.eeprom else []) \
            + (["--paint", hex(self.paint)] if self.paint else []) + (["--hold"] if self.hold else []) \
            + (["--mcu", self.mcu] if self.mcu != "atmega328p" else [])

    def start(self) -> "UnoEmulator":
        popen = dict(stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        cmd = self.command()
        self.proc = (self.bridge.spawn(cmd, **popen) if self.bridge is not None
                     else subprocess.Popen(cmd, preexec_fn=tied(), **popen))
        fd = self.proc.stderr.fileno()
        deadline = time.monotonic() + self.boot_timeout
        line = b""
        while not line.endswith(b"\n"):
            left = deadline - time.monotonic()
            chunk = os.read(fd, 1) if left > 0 and select.select([fd], [], [], left)[0] else b""
            if not chunk:
                self.stop()
                raise InputError(f"the simavr board did not start: {line.decode(errors='replace').strip() or 'no message'}")
            line += chunk
        key, _, port = line.decode(errors="replace").strip().partition(" ")
        if key != "LISTENING" or not port.isdigit():
            self.stop()
            raise InputError(f"the simavr board said {line.decode(errors='replace').strip()!r}")
        self.port = int(port)
        return self

    def stop(self) -> None:
        if self.proc is not None:
            stop_process(self.proc)
            rest = self.proc.stderr.read().decode(errors="replace") if self.proc.stderr else ""
            self.returncode, self.messages = self.proc.returncode, []
            for ln in rest.splitlines():
                key, _, value = ln.partition(" ")
                if key == "STACK":
                    self.stack_peak = int(value)
                elif key == "CYCLES":
                    self.cycles = int(value)
                elif ln.strip():
                    self.messages.append(ln.strip())  # e.g. "the AVR program crashed at cycle N"
        super().stop()


def require_avr_tools() -> None:
    """InputError (one line, how to install them) unless the Uno's build and board tools are here, and libsimavr
    (with libelf, which its pkg-config file requires) is known to pkg-config."""
    missing = [t for t in AVR_TOOLS if shutil.which(t) is None]
    if missing:
        raise InputError(f"{' and '.join(missing)} not found; {AVR_HINT}")
    said = _pkg_config_simavr()
    if said is not None:
        raise InputError(f"pkg-config simavr failed ({said}); {AVR_HINT}")


def _pkg_config_simavr() -> str | None:
    """None when pkg-config knows libsimavr; else its first line."""
    try:
        proc = subprocess.run(["pkg-config", "--print-errors", "--exists", "simavr"], capture_output=True,
                              text=True, timeout=60)
    except subprocess.TimeoutExpired:
        return "no answer within 60 s"
    lines = [ln.strip() for ln in proc.stderr.splitlines() if ln.strip()]
    return None if proc.returncode == 0 else (lines[0].rstrip(".") if lines else f"exit status {proc.returncode}")


def uno_emulator_available() -> bool:
    """Whether the simavr board can be built here (its tools, and libsimavr known to pkg-config)."""
    return all(shutil.which(t) is not None for t in AVR_TOOLS) and _pkg_config_simavr() is None


def build_uno_board(folder: str | Path) -> Path:
    """The libsimavr board (firmware_templates/avr/uno_board.c) compiled into ``folder``."""
    from fitgen.c.avr import build_simavr_program

    return build_simavr_program(folder, "uno_board.c")


def bss_end(elf: str | Path) -> int:
    """The first RAM address above .data and .bss of an AVR ELF (where its stack may grow down to)."""
    from hil.firmware import _run

    for line in _run(["avr-nm", str(elf)], f"reading {elf}'s symbols").stdout.splitlines():
        parts = line.split()
        if len(parts) == 3 and parts[2] == "__bss_end":
            return int(parts[0], 16) & 0xFFFF
    raise InputError(f"{elf} has no __bss_end symbol")


def instructions_per_estimate(ticks_small: int, ticks_large: int, n_small: int, n_large: int, tick_hz: int,
                              shift: int = ICOUNT_SHIFT) -> float:
    """Instructions per estimate from two BENCH runs under ``-icount shift``: the difference cancels the
    fixed cost of the command; one instruction takes 2^shift ns of virtual time."""
    ns_per_tick = 1e9 / tick_hz
    return (ticks_large - ticks_small) * ns_per_tick / (2 ** shift) / (n_large - n_small)


def bench_instructions(dev, n_small: int = 200, n_large: int = 2200) -> dict:
    """Instructions (emulator, icount) or ns (host build) per estimate of the active calibration, from BENCH."""
    t1, hz, _ = dev.bench(n_small, timeout=dev.timeout + n_small * 1e-3)
    t2, hz2, _ = dev.bench(n_large, timeout=dev.timeout + n_large * 1e-3)
    per = (t2 - t1) / (n_large - n_small)
    return {"ticks_per_estimate": per, "tick_hz": hz,
            "instructions": instructions_per_estimate(t1, t2, n_small, n_large, hz) if hz != 1_000_000_000 else None,
            "ns": per * 1e9 / hz}


def fresh_eeprom(folder: Path, model_hash: str) -> None:
    """Erase the emulated Uno's EEPROM kept in ``folder`` when the build it was written under compiled in another
    model: a calibration flashed into the last build would otherwise run in place of the model just built (a real
    board keeps its EEPROM over a reflash; an emulator started for a model should run that model)."""
    stamp = folder / "eeprom.model"
    if not stamp.is_file() or stamp.read_text().strip() != model_hash:
        (folder / "eeprom.bin").unlink(missing_ok=True)
    write_atomic(stamp, model_hash + "\n")


FIRMWARE_MAIN = b"/* main.c: reference firmware of the tactile sensor"  # how a build's main.c starts


def _check_build_folder(folder: Path) -> None:
    """InputError where ``folder`` holds files and is no earlier build's (whose main.c is the generated one): a
    build writes main.c, device.c and a dozen more there, over files of those names."""
    held = sorted(p.name for p in folder.iterdir())
    try:
        with open(folder / "main.c", "rb") as f:
            ours = f.read(len(FIRMWARE_MAIN)) == FIRMWARE_MAIN
    except OSError:  # none there, or a folder of that name
        ours = False
    if held and not ours:
        raise foreign_files(f"--build-dir {folder}", held, "firmware build",
                            "a build writes main.c, device.c and more there")


def start_target(model, target: str = "mps2", *, precision: str = "float", style: str = "table", fma: bool = False,
                 port: int | None = None, workdir: str | Path | None = None, sensor_id: str = "paper",
                 cmap=None, bridge=None, tin=None, tempcomp=None, bench_inputs=None):
    """Render and build the firmware for ``target`` (mps2 or host) with ``model`` compiled in, and start it
    (``bench_inputs``: BENCH's readings, hil.firmware.render_firmware's).

    Returns the started :class:`Emulator` or :class:`HostFirmware`, with ``size`` (mps2: flash and RAM
    bytes) and ``workdir`` set; the caller stops it (it is a context manager).
    """
    import tempfile

    from hil.firmware import build_firmware, firmware_size, render_firmware

    if target not in TARGETS:
        raise InputError(f"target must be one of {', '.join(TARGETS)}, got {target!r}")
    if target in MACHINES:
        missing = [t for t in (QEMU, "arm-none-eabi-gcc") if shutil.which(t) is None]
        if missing:
            raise InputError(f"{' and '.join(missing)} not found; {INSTALL_HINT}")
    if target == "uno":
        require_avr_tools()
    tmp = lock = None
    if workdir is None:
        tmp = tempfile.TemporaryDirectory(prefix="tactile-fw-")
        workdir = tmp.name
    else:  # a folder the user named may be another emulator's: its sources and image are not to mix with these
        lock = hold_folder(Path(workdir), "tactile-hil", "--build-dir")
        try:
            _check_build_folder(Path(workdir))
        except InputError:
            lock.close()
            raise
    folder = Path(workdir).absolute()  # the image is run by its path: "firmware" alone would be looked up on PATH
    port_name = "posix" if target == "host" else target
    try:
        render_firmware(model, folder, precision=precision, style=style, fma=fma, port=port_name,
                        sensor_id=sensor_id, cmap=cmap, tin=tin, tempcomp=tempcomp, bench_inputs=bench_inputs)
        image = build_firmware(folder, port_name)
        if target in MACHINES:
            runner = Emulator(image, port, bridge=bridge, machine=MACHINES[target])
            runner.size = firmware_size(image)
        elif target == "uno":
            fresh_eeprom(folder, model.sha256)
            runner = UnoEmulator(build_uno_board(folder), image, port, bridge=bridge, paint=bss_end(image),
                                 eeprom=folder / "eeprom.bin")
            runner.size = firmware_size(image, "avr-size")
        else:
            runner = HostFirmware(image, bridge=bridge)
            runner.size = None
    except BaseException:  # no runner to release them with: the folder is free again, a temporary one gone
        for held in (lock, tmp):
            if held is not None:
                held.cleanup() if held is tmp else held.close()
        raise
    runner.workdir = folder
    runner._tmp, runner._lock = tmp, lock  # removed, and released, with the runner
    return runner


def uno_crash_advice(model, precision: str, style: str, **render) -> str:
    """What to try when a ``style`` build crashed on the Uno before answering (a table build's stack can overrun its
    2 KB of RAM): ``--style unrolled`` when that build links (checked by building it; ``render``: the rest of
    ``render_firmware``'s arguments), else fewer terms. Empty for builds the advice is not about."""
    import tempfile

    from hil.firmware import build_firmware, firmware_size, render_firmware

    if precision == "fixed" or style != "table":
        return ""
    why = "a table-style build's stack can overrun the Uno's 2 KB of RAM"
    try:
        with tempfile.TemporaryDirectory(prefix="tactile-fw-") as tmp:
            render_firmware(model, tmp, precision=precision, style="unrolled", port="uno", **render)
            size = firmware_size(build_firmware(tmp, "uno"), "avr-size")
    except InputError as exc:
        said = str(exc).split(" failed: ", 1)[-1]
        return f"; {why}, and --style unrolled does not build either ({said}): fit fewer terms " \
               "(fitgen fit --k bic, or --max-terms N)"
    return f"; {why}: try --style unrolled (it builds: flash {size['flash']} B, static RAM {size['ram']} B)"
