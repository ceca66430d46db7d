"""A Marlin or GRBL controller over pyserial: the G-code line protocol (what its lines mean: host.gcodereplies).

``GcodeController`` sends one command at a time, each answered by ``ok`` (or
``error:N`` / ``Error:`` / ``ALARM:N`` / ``!!`` / Klipper's ``!! why``, all faults) within a time limit
that a Marlin ``busy:`` keepalive extends; every line it reads is length-checked;
a move is ``G1`` (absolute, ``G90``, with a feed) then a wait for its end (Marlin
``M400``, GRBL ``G4 P0`` then ``?`` until Idle) and a position check (``M114`` /
the status report) against the target.

Faults of the controller raise ``StageError`` (the CLI: one line, exit status 1,
rows kept); bad settings raise ``InputError`` before any motion.
"""

from __future__ import annotations

import math
import re
import time

import numpy as np

from fitgen.base.errors import InputError

from host.device import PortOwner, no_nagle, port_error, url_hint
from host.gcodereplies import GRBL_BANNER, LEAVE_ALARM, NoAnswer, NoStatus, StageError, UnknownCommand, line_fault

__all__ = ["GcodeController", "MACHINE_AXES", "NoStatus", "POSITION_TOL", "QUEUED_WAIT", "StageError",
           "UnknownCommand", "stage_url"]

MACHINE_AXES = ("X", "Y", "Z")
FLAVORS = ("marlin", "grbl")
MAX_LINE = 256  # longest line accepted from a controller (GRBL's longest report is about 100)
MAX_COMMAND = 70  # GRBL's line buffer holds 80 characters with the newline; Marlin's 96
POLL = 0.02  # seconds one read of the port blocks at most
ASK_WAIT = 1.0  # s a GRBL takes at most to answer '?' (real-time, within milliseconds); a Marlin never does
QUEUED_WAIT = 60.0  # s a stopped run's queued moves (or homing) may take to end after a new run connects
POSITION_TOL = 0.02  # mm: reported against commanded position (Marlin prints 2 decimals, GRBL steps)
BOOT_SCREEN = 15.0  # s a Marlin may stay silent after its banner before it serves lines (its boot screens, settings)
INCH = 25.4  # mm: GRBL reports positions in inches when its $13 is 1, whatever G20/G21 says

_NUM = r"(-?\d+(?:\.\d*)?)"
_MARLIN_POS = re.compile(rf"X:{_NUM}\s*Y:{_NUM}\s*Z:{_NUM}")


def _busy_deadline(deadline: float, start: float, limit: float, timeout: float) -> float:
    """A Marlin ``busy:`` keepalive moves the answer's deadline to ``timeout`` s from now, but never past
    ``limit`` or QUEUED_WAIT s after ``start`` (whichever is later): a machine stuck or paused ends the wait."""
    return min(max(deadline, time.monotonic() + timeout), start + max(limit, QUEUED_WAIT))


def stage_url(spec: str) -> str:
    """``gcode:URL`` -> URL (a device path or a pyserial URL such as socket://127.0.0.1:PORT)."""
    kind, sep, url = spec.partition(":")
    if not sep or kind != "gcode" or not url.strip():
        raise InputError(f"--stage {spec!r}: expected gcode:URL, e.g. gcode:/dev/ttyUSB0 or "
                         "gcode:socket://127.0.0.1:PORT")
    return url.strip()


class GcodeController(PortOwner):
    """One Marlin or GRBL controller over an open pyserial port: commands, moves, position, homing."""

    def __init__(self, port, name: str = "stage", *, timeout: float = 5.0, log=None):
        self.port, self.name = port, name
        self.timeout = float(timeout)
        self.flavor: str | None = None
        self.firmware = ""  # the banner or firmware name, as the controller gave it
        self.banner_seen = False  # a start-up banner since the port opened: the controller has just reset
        self.alarm = ""  # GRBL's alarm state at connect ("" if none)
        self.homed = False  # homed during this connection
        self.wco = np.zeros(3)  # GRBL: work coordinate offset (MPos - WPos)
        self.report_mm = 1.0  # GRBL: mm per unit of its reports (INCH with $13=1)
        self.settings: dict[int, float] = {}  # GRBL: its $$ settings, read at connect
        self.max_rates: np.ndarray | None = None  # each axis's top rate, mm/min (setup(); None: not said)
        self.log = log  # optional callable(str) for each line in and out
        self.last_ok = ""  # the last command's ok line, as the controller gave it
        self._buf = bytearray()

    @classmethod
    def open(cls, url: str, *, baud: int = 115200, timeout: float = 5.0, log=None) -> "GcodeController":
        import serial

        try:
            port = serial.serial_for_url(url, baudrate=baud, timeout=POLL, write_timeout=timeout)
        except (serial.SerialException, ValueError, OSError, OverflowError) as exc:  # a rate the driver cannot set
            raise InputError(f"cannot open stage {url}: {port_error(exc)}{url_hint(url)}") from None
        no_nagle(port)  # one short line each way
        return cls(port, url, timeout=timeout, log=log)

    # -- bytes and lines

    def _write(self, data: bytes) -> None:
        import serial

        if self.log:
            self.log(f"> {data.decode('ascii', 'replace').rstrip()}")
        try:
            self.port.write(data)
            self.port.flush()
        except (serial.SerialException, OSError) as exc:
            raise StageError(f"{self.name}: cannot write to the controller: {port_error(exc)}") from None

    def send(self, line: str) -> None:
        if len(line) > MAX_COMMAND or not line.isascii() or "\n" in line or "\r" in line:
            raise InputError(f"G-code line {line!r} is not one ASCII line of at most {MAX_COMMAND} characters")
        self._write(line.encode("ascii") + b"\n")

    def read_line(self, deadline: float) -> str | None:
        """The next line (without its end), or None when ``deadline`` (time.monotonic) passes first."""
        import serial

        while True:
            k = self._buf.find(b"\n")
            if k >= 0:
                raw = bytes(self._buf[:k])
                del self._buf[:k + 1]
                if len(raw) > MAX_LINE:
                    raise StageError(f"{self.name}: a line of {len(raw)} bytes from the controller (limit "
                                     f"{MAX_LINE}): is it a G-code controller, at the right baud rate?")
                text = raw.decode("ascii", "replace").strip("\r\x00 \t")
                if self.log and text:
                    self.log(f"< {text}")
                if text:
                    return text
                continue
            if len(self._buf) > MAX_LINE:
                raise StageError(f"{self.name}: more than {MAX_LINE} bytes from the controller without a line end: "
                                 "is it a G-code controller, at the right baud rate?")
            if time.monotonic() >= deadline:
                return None
            try:
                chunk = self.port.read(max(1, getattr(self.port, "in_waiting", 0) or 1))
            except (serial.SerialException, OSError) as exc:
                raise StageError(f"{self.name}: the connection to the controller broke: "
                                 f"{port_error(exc)}") from None
            self._buf += chunk

    def _fault(self, text: str, what: str) -> StageError | None:
        """The StageError an unsolicited or answer line means (host.gcodereplies.line_fault), or None; a start-up
        banner also marks the controller as just reset."""
        if GRBL_BANNER.match(text) or text == "start":
            self.banner_seen = True
        return line_fault(text, what, self.name, self.flavor)

    def command(self, line: str, *, timeout: float | None = None, what: str | None = None) -> list[str]:
        """Send one line and wait for its ``ok``; the lines before it are returned."""
        what = what or repr(line)
        limit = self.timeout if timeout is None else timeout
        self.send(line)
        start = time.monotonic()
        deadline, busy = start + limit, -math.inf
        got = []
        while True:
            text = self.read_line(deadline)
            if text is None and time.monotonic() - busy <= self.timeout + POLL:
                raise StageError(f"{self.name}: {what} still busy {time.monotonic() - start:.0f} s after it was "
                                 "sent (Marlin's busy: keepalive); is the machine stuck, or paused for the user?")
            if text is None:
                raise NoAnswer(f"{self.name}: no answer to {what} within {limit:g} s; is the controller on, "
                               "and is the baud rate right?")
            if text == "ok" or text.startswith("ok "):
                self.last_ok = text  # Smoothieware and Teacup answer M114 on it: "ok C: X:.. Y:.. Z:.."
                return got
            if "busy:" in text:  # Marlin's host keepalive: still working on a long command, but not for ever
                deadline, busy = _busy_deadline(deadline, start, limit, self.timeout), time.monotonic()
                continue
            fault = self._fault(text, what)
            if fault is not None:
                raise fault
            got.append(text)

    # -- start-up

    def connect(self, flavor: str = "auto", *, boot_wait: float = 2.0) -> None:
        """Read the start-up lines (a board that resets when its port opens prints a banner), then detect
        or check the flavor and, on GRBL, the state and the work offset."""
        if flavor not in ("auto",) + FLAVORS:
            raise InputError(f"--stage-flavor {flavor!r}: one of auto, marlin, grbl")
        lines = []
        deadline = time.monotonic() + boot_wait
        while True:
            text = self.read_line(deadline)
            if text is None:
                break
            lines.append(text)
            deadline = time.monotonic() + 0.3  # a banner comes in a burst: stop once it is quiet
        seen = None
        for text in lines:
            m = GRBL_BANNER.match(text)
            if m:
                seen, self.firmware = "grbl", text
            elif text == "start" or text.startswith(("echo:Marlin", "Marlin ")):  # Marlin 2 prints no echo:
                seen = "marlin"
                if "Marlin" in text:
                    self.firmware = text.removeprefix("echo:").strip()
        self.banner_seen = seen is not None
        if seen is None:
            try:
                # GRBL answers '?' at once, even behind a stopped run's queued move (M115 would wait behind it)
                seen = self._grbl_at_rest(self.timeout if flavor == "grbl" else min(self.timeout, ASK_WAIT)) \
                    if flavor != "marlin" else self._probe(named=True)
            except StageError:
                if self.banner_seen:  # a slow boot, not a reset: lines sent before it may be answered late
                    raise StageError(f"{self.name}: the controller printed its start-up banner only after "
                                     f"--stage-boot-wait {boot_wait:g} s had passed (a board that resets when its "
                                     f"port opens, booting slowly): give --stage-boot-wait {2 * boot_wait + 2:g}") \
                        from None
                raise
        if flavor != "auto" and seen != flavor:
            raise InputError(f"{self.name}: --stage-flavor {flavor}, but the controller is {seen} "
                             f"({self.firmware or 'by its answers'})")
        self.flavor = seen
        if seen == "grbl":
            self._grbl_settings()
            self.alarm = "Alarm" if self.status()[0].startswith("Alarm") else ""
            if not self.alarm:
                self._work_offset()

    def _grbl_at_rest(self, ask: float) -> str:
        """No banner: a GRBL's real-time status answers within ``ask`` s even while a stopped run's last move or
        homing ends (a line such as M115 waits behind them); wait for that, then ask its build."""
        try:
            self.status(ask)
        except NoStatus:  # not a GRBL: end the '?' as a line (a Marlin answers it ok), and ask who it is
            self._write(b"\n")
            return self._probe(spare_oks=2)
        deadline = time.monotonic() + QUEUED_WAIT + self.timeout
        while not (state := self.status()[0]).startswith(("Idle", "Alarm")):
            if time.monotonic() > deadline:
                raise StageError(f"{self.name}: the controller is still {state} {QUEUED_WAIT + self.timeout:g} s "
                                 "after connecting")
            time.sleep(POLL)
        return self._grbl_build()

    def _grbl_build(self) -> str:
        """Ask a GRBL its build ($I) for ``firmware``; 'grbl'."""
        self.send("$I")
        ver = next((t for t in self._until_ok("$I") if t.startswith("[VER:")), "")
        self.firmware = f"Grbl {ver[5:].split(':')[0]}" if ver else "Grbl"
        return "grbl"

    def _probe(self, spare_oks: int = 1, named: bool = False) -> str:
        """No banner: ask. Marlin answers M115 with its firmware name; GRBL answers it with error:N. Up to
        ``spare_oks`` answers to earlier lines (a stopped run's last, a '?' line) may come before M115's own.
        ``named`` (--stage-flavor marlin): any answer but GRBL's is taken as a Marlin (or a firmware derived
        from it, such as Prusa's or Klipper's, which name themselves otherwise)."""
        def unnamed(name):
            return InputError(f"{self.name}: the controller answered M115 with firmware {name or 'unnamed'}; "
                              "give --stage-flavor marlin or grbl if it speaks one of them")

        self.send("M115")
        start = time.monotonic()
        deadline = start + self.timeout
        name, nameless_oks = "", 0
        while True:
            text = self.read_line(deadline)
            if text is None and nameless_oks and named:
                self.firmware = "unnamed"
                return "marlin"
            if text is None and nameless_oks:
                raise unnamed(name)
            if text is None:
                raise StageError(f"{self.name}: no answer to M115 within {self.timeout:g} s; is the controller on, "
                                 "and is the baud rate right? (a GRBL halted by a limit alarm answers nothing "
                                 "until it is reset)")
            if "busy:" in text:  # Marlin's host keepalive: a stopped run's M400 or homing is still going on
                deadline = _busy_deadline(deadline, start, self.timeout, self.timeout)
                continue
            if text.startswith("FIRMWARE_NAME:"):
                name = text[len("FIRMWARE_NAME:"):].split(" SOURCE_CODE_URL")[0].strip()
            elif text.lower().startswith("error:") and text[6:].strip().isdigit():
                return self._grbl_build()
            elif text == "ok" or text.startswith("ok "):
                if "marlin" in name.lower() or (named and name):
                    self.firmware = name
                    return "marlin"
                if (name or nameless_oks >= spare_oks) and named:
                    self.firmware = name or "unnamed"
                    return "marlin"
                if name or nameless_oks >= spare_oks:
                    raise unnamed(name)
                nameless_oks += 1  # perhaps an earlier line's answer (a stopped run's M400): M115's own comes next
                deadline = time.monotonic() + self.timeout

    def _until_ok(self, what: str) -> list[str]:
        deadline = time.monotonic() + self.timeout
        got = []
        while True:
            text = self.read_line(deadline)
            if text is None:
                raise StageError(f"{self.name}: no answer to {what} within {self.timeout:g} s")
            if text == "ok" or text.startswith("ok "):
                return got
            if text.lower().startswith("error:"):
                raise self._fault(text, what)
            got.append(text)

    def _grbl_settings(self) -> None:
        """GRBL's $$ (answered in ALARM too): the unit of its reports ($13) and the axes' top rates ($110-$112)."""
        self.settings = {}
        for text in self.command("$$"):
            m = re.fullmatch(rf"\$(\d+)={_NUM}(?:\s*\(.*\))?", text)  # 0.9 adds (a comment)
            if m:
                self.settings[int(m.group(1))] = float(m.group(2))
        self.report_mm = INCH if self.settings.get(13) == 1 else 1.0

    def _work_offset(self) -> None:
        """GRBL reports MPos (or WPos); G1 targets are in work coordinates: WCO = G54 + G92 (+ G43.1 on Z), G54
        being the system setup() selects."""
        wco = np.zeros(3)
        for text in self.command("$#"):
            m = re.match(r"\[(G54|G92|TLO):([^\]]*)\]", text)
            if m and m.group(1) == "TLO":
                wco[2] += self._numbers(m.group(2), text, 1)[0]
            elif m:
                wco += self._numbers(m.group(2), text, 3)
        self.wco = wco

    def _numbers(self, field: str, text: str, n: int) -> np.ndarray:
        """The first ``n`` comma-separated coordinates of ``field`` (part of the controller's line ``text``), in
        mm."""
        try:
            vals = [float(v) for v in field.split(",")[:n]]
        except ValueError:
            vals = []
        if len(vals) < n or not all(math.isfinite(v) for v in vals):
            raise StageError(f"{self.name}: a report with fewer than {n} readable numbers: {text!r}")
        return np.array(vals) * self.report_mm

    # -- state and motion

    def status(self, timeout: float | None = None) -> tuple[str, np.ndarray]:
        """GRBL: the real-time ``?`` report: (state, work position), within ``timeout`` s (default the stage's)."""
        self._write(b"?")  # real-time: no line end, answered at once, no ok
        wait = self.timeout if timeout is None else timeout
        deadline = time.monotonic() + wait
        while True:
            text = self.read_line(deadline)
            if text is None:
                raise NoStatus(f"{self.name}: no status report within {wait:g} s after '?'")
            if text.startswith("<") and text.endswith(">"):
                return self._parse_status(text)
            fault = self._fault(text, "a status query")
            if fault is not None:
                raise fault

    def _parse_status(self, text: str) -> tuple[str, np.ndarray]:
        body = text[1:-1]
        if "|" in body:
            fields = body.split("|")
        else:  # GRBL 0.9: <Idle,MPos:x,y,z,WPos:x,y,z>: a field starts at each name
            fields = []
            for part in body.split(","):
                if fields and ":" not in part:
                    fields[-1] += "," + part
                else:
                    fields.append(part)
        state = fields[0]
        pos, kind = None, None
        for f in fields[1:]:
            name, _, val = f.partition(":")
            if name in ("MPos", "WPos"):
                pos, kind = self._numbers(val, text, 3), name
            elif name == "WCO":
                self.wco = self._numbers(val, text, 3)
        if pos is None:
            raise StageError(f"{self.name}: a status report without a position: {text!r}")
        return state, (pos - self.wco if kind == "MPos" else pos)

    def position(self) -> np.ndarray:
        """X, Y, Z in the coordinates G1 uses, as the controller reports them."""
        if self.flavor == "grbl":
            return self.status()[1]
        for text in self.command("M114") + [self.last_ok]:
            m = _MARLIN_POS.search(text)
            if m:
                return np.array([float(v) for v in m.groups()])
        raise StageError(f"{self.name}: M114 gave no position")

    def wait_idle(self, timeout: float, what: str) -> None:
        """Until every queued move has ended (Marlin M400; GRBL G4 P0, then Idle in the status report)."""
        if self.flavor == "marlin":
            self.command("M400", timeout=timeout, what=f"M400 after {what}")
            return
        try:
            self.command("G4 P0", timeout=timeout, what=f"G4 P0 after {what}")
        except NoAnswer as exc:  # a GRBL held waits with its moves: it still answers '?'
            try:
                state = self.status(ASK_WAIT)[0]
            except NoStatus:
                raise exc from None
            if state.startswith(("Hold", "Door")):
                door = state.startswith("Door")
                raise StageError(f"{self.name}: the controller holds its moves ({state}: "
                                 f"{'its safety door is open' if door else 'a feed hold'}) during {what}; "
                                 f"{'close the door, then ' if door else ''}resume it with cycle start (its button, "
                                 "or '~')") from None
            raise
        deadline = time.monotonic() + self.timeout
        while True:
            state, _ = self.status()
            if state.startswith("Idle"):
                return
            if state.startswith("Alarm"):
                raise StageError(f"{self.name}: the controller went into ALARM during {what}; home it (--home) or "
                                 "unlock it (--unlock), then set the zero again", lost="the controller went into ALARM",
                                 resume=LEAVE_ALARM)
            if time.monotonic() > deadline:
                raise StageError(f"{self.name}: still {state} {self.timeout:g} s after {what} ended")
            time.sleep(POLL)

    def setup(self) -> None:
        """Millimetres, absolute coordinates, feed per minute; Marlin's steppers on; GRBL's first work coordinate
        system (G54: a G55-G59 left selected would move every target by its offset); the axes' top rates."""
        boot = BOOT_SCREEN if self.banner_seen and self.flavor == "marlin" else 0.0  # 'start', then its boot screen
        self.command("G21", timeout=self.timeout + boot,
                     what="G21, the first line after its start-up banner," if boot else None)
        self.command("G90")
        self.command("M17" if self.flavor == "marlin" else "G94")
        if self.flavor == "grbl":
            self.command("G54")
        self.max_rates = self._max_rates()

    def _max_rates(self) -> np.ndarray | None:
        """Each machine axis's top rate (mm/min) as the controller reports it (GRBL's $110-$112; Marlin's
        M203, in mm/s, in M503's report; RepRapFirmware's, in mm/min), or None where it does not say: a move at a
        feed above it is slower."""
        rates = {}
        try:
            if self.flavor == "grbl":
                rates = {k - 110: v for k, v in self.settings.items() if k in (110, 111, 112)}
            else:
                # M203 is in mm/s on Marlin, in mm/min on RepRapFirmware (whose M503 prints its config.g)
                per_min = 1.0 if "reprapfirmware" in self.firmware.lower() else 60.0
                for text in self.command("M503"):
                    m = re.search(r"M203((?:\s+[A-Z]-?[\d.]+)+)", text)
                    for axis, value in re.findall(r"([XYZ])(-?[\d.]+)", m.group(1) if m else ""):
                        rates[MACHINE_AXES.index(axis)] = float(value) * per_min
        except UnknownCommand:  # a build without M503
            return None
        vals = [rates.get(i, math.nan) for i in range(3)]
        return np.array(vals) if all(math.isfinite(v) and v > 0 for v in vals) else None

    def move_time(self, delta: np.ndarray, feed: float) -> float:
        """Seconds a straight move by ``delta`` (mm, X Y Z) takes at ``feed`` mm/min, each axis held to its top
        rate (the controller slows the whole move so that no axis exceeds it)."""
        travel = float(np.linalg.norm(delta))
        if travel == 0.0:
            return 0.0
        speed = feed
        if self.max_rates is not None:
            share = np.abs(delta) / travel
            speed = min(speed, float(np.min(self.max_rates[share > 0] / share[share > 0])))
        return travel / speed * 60.0

    def move(self, target: dict[str, float], feed: float, *, start: np.ndarray | None = None) -> np.ndarray:
        """G1 to ``target`` (machine axis -> mm) at ``feed`` mm/min, wait for its end, check the position;
        the position sent (the report's within POSITION_TOL of it)."""
        words = " ".join(f"{a}{target[a]:.3f}" for a in MACHINE_AXES if a in target)
        line = f"G1 {words} F{feed:g}"
        if start is None:
            start = self.position()  # the move's length sets its time limit
        delta = np.array([target[a] - start[i] if a in target else 0.0 for i, a in enumerate(MACHINE_AXES)])
        self.command(line)
        # the move's own time, twice over (acceleration), plus the answer's time limit
        self.wait_idle(2.0 * self.move_time(delta, feed) + self.timeout, line)
        pos = self.position()
        for i, a in enumerate(MACHINE_AXES):
            if a in target and abs(pos[i] - round(target[a], 3)) > POSITION_TOL:
                raise StageError(f"{self.name}: after {line!r} the controller reports {a}{pos[i]:g}: a move clamped "
                                 "by its own software endstops, or lost steps")
        # where it was sent, not the report (Marlin's M114 has two decimals): the next move and a repeat's test
        # count from there, and jog steps below 0.01 mm are not lost to the report's rounding
        return np.array([round(target[a], 3) if a in target else pos[i] for i, a in enumerate(MACHINE_AXES)])

    def home(self, timeout: float) -> None:
        """G28 (Marlin) or $H (GRBL); the time limit is for the whole cycle."""
        self.command("G28" if self.flavor == "marlin" else "$H", timeout=timeout, what="homing")
        self.homed = True
        self.alarm = ""
        if self.flavor == "grbl":
            self._work_offset()

    def unlock(self) -> None:
        """GRBL's $X: out of ALARM without homing (the position is then whatever GRBL believes)."""
        if self.flavor != "grbl":
            raise InputError("--unlock is GRBL's $X; a Marlin controller has no alarm lock")
        self.command("$X", what="$X (unlock)")
        self.alarm = ""
        self._work_offset()
