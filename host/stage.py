"""A G-code stage (Marlin or GRBL over pyserial) that sets each pose of a capture by itself.

Three layers. ``GcodeController`` speaks the line protocol: one command at a
time, each answered by ``ok`` (or ``error:N`` / ``Error:`` / ``ALARM:N`` / ``!!``,
all faults) within a time limit that a Marlin ``busy:`` keepalive extends; every
line it reads is length-checked; a move is ``G1`` (absolute, ``G90``, with a feed)
then a wait for its end (Marlin ``M400``, GRBL ``G4 P0`` then ``?`` until Idle)
and a position check (``M114`` / the status report) against the target.
``PoseStage`` moves in pose axes: the signed axis map, the user's zero, soft
limits checked before anything is sent, and every pose approached from the same
side so that backlash lags every pose alike. ``StageState`` keeps the zero and
the last position beside the dataset (``<output>.stage.json``) so that a resumed
capture knows whether the controller was reset meanwhile, and asks for the zero again if so.

Faults of the controller raise ``StageError`` (the CLI: one line, exit status 1,
rows kept); bad settings raise ``InputError`` before any motion.
"""

from __future__ import annotations

import json
import math
import re
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fitgen.base.errors import InputError
from fitgen.base.fileio import write_atomic
from fitgen.physics.pose import POSE_NAMES

from host.device import no_nagle

MACHINE_AXES = ("X", "Y", "Z")
STAGE_AXES = ("dx", "dy", "dz")  # what a 3-axis stage can set; thx, thy need a tilt stage
FLAVORS = ("marlin", "grbl")
MAX_LINE = 256  # longest line accepted from a controller (GRBL's longest report is about 100)
MAX_COMMAND = 70  # GRBL's line buffer holds 80 characters with the newline; Marlin's 96
POLL = 0.02  # seconds one read of the port blocks at most
POSITION_TOL = 0.02  # mm: reported against commanded position (Marlin prints 2 decimals, GRBL steps)

GRBL_BANNER = re.compile(r"^Grbl (\S+)")
GRBL_ERRORS = {1: "expected command letter", 2: "bad number format", 3: "invalid $ statement",
               5: "homing is not enabled in the settings", 8: "$ command needs Idle", 9: "G-code locked out "
               "during alarm or jog", 11: "line too long", 15: "jog target exceeds machine travel",
               20: "unsupported or invalid G-code command", 22: "feed rate not set", 33: "invalid motion target"}
GRBL_ALARMS = {1: "hard limit triggered", 2: "soft limit: the target exceeds the machine's travel",
               3: "reset while in motion, position lost", 4: "probe fail", 5: "probe fail",
               6: "homing fail: reset during homing", 8: "homing fail: pull-off did not clear the switch",
               9: "homing fail: no limit switch found"}
_NUM = r"(-?\d+(?:\.\d*)?)"
_MARLIN_POS = re.compile(rf"X:{_NUM}\s*Y:{_NUM}\s*Z:{_NUM}")


class StageError(RuntimeError):
    """The controller failed: an error or alarm, a halt, silence, a reset, or a position not the commanded one."""


def _describe_port_error(exc: BaseException) -> str:
    for e in (exc.__cause__, exc.__context__, exc):
        if isinstance(e, OSError) and e.strerror:
            return e.strerror[:1].lower() + e.strerror[1:]
    return (str(exc).strip() or type(exc).__name__).splitlines()[0]


def stage_url(spec: str) -> str:
    """``gcode:URL`` -> URL (a device path or a pyserial URL such as socket://127.0.0.1:PORT)."""
    kind, sep, url = spec.partition(":")
    if not sep or kind != "gcode" or not url.strip():
        raise InputError(f"--stage {spec!r}: expected gcode:URL, e.g. gcode:/dev/ttyUSB0 or "
                         "gcode:socket://127.0.0.1:PORT")
    return url.strip()


# --- the line protocol ------------------------------------------------------------------


class GcodeController:
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
        self.log = log  # optional callable(str) for each line in and out
        self._buf = bytearray()

    @classmethod
    def open(cls, url: str, *, baud: int = 115200, timeout: float = 5.0, log=None) -> "GcodeController":
        import serial

        try:
            port = serial.serial_for_url(url, baudrate=baud, timeout=POLL, write_timeout=timeout)
        except (serial.SerialException, ValueError, OSError) as exc:
            raise InputError(f"cannot open stage {url}: {_describe_port_error(exc)}") from None
        no_nagle(port)  # one short line each way
        return cls(port, url, timeout=timeout, log=log)

    def close(self) -> None:
        if self.port is not None:
            try:
                self.port.close()
            finally:
                self.port = None

    # -- bytes and lines

    def _write(self, data: bytes) -> None:
        import serial

        if self.log:
            self.log(f"> {data.decode('ascii', 'replace').rstrip()}")
        try:
            self.port.write(data)
            self.port.flush()
        except (serial.SerialException, OSError) as exc:
            raise StageError(f"{self.name}: cannot write to the controller: {_describe_port_error(exc)}") from None

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
                                 f"{_describe_port_error(exc)}") from None
            self._buf += chunk

    def _fault(self, text: str, what: str) -> StageError | None:
        """The StageError an unsolicited or answer line means, or None if it is harmless."""
        low = text.lower()
        if low.startswith("error:"):
            code = text[6:].strip()
            if self.flavor == "marlin" or not code.isdigit():
                return StageError(f"{self.name}: the controller answered {what} with {text!r}")
            meaning = GRBL_ERRORS.get(int(code))
            return StageError(f"{self.name}: the controller answered {what} with error:{code}"
                              f"{f' ({meaning})' if meaning else ''}")
        if text.startswith("ALARM:"):
            code = text[6:].strip()
            meaning = GRBL_ALARMS.get(int(code)) if code.isdigit() else None
            return StageError(f"{self.name}: the controller raised ALARM:{code}{f' ({meaning})' if meaning else ''} "
                              f"during {what}; home it (--home) or unlock it (--unlock), then set the zero again")
        if text == "!!" or "halted" in low or "kill() called" in low:
            return StageError(f"{self.name}: the controller halted ({text}) during {what}; reset it, home it and "
                              "set the zero again")
        if low.startswith("echo:unknown command"):
            return StageError(f"{self.name}: the controller does not know {what} ({text})")
        if GRBL_BANNER.match(text) or text == "start":
            self.banner_seen = True
            return StageError(f"{self.name}: the controller reset itself during {what} (it printed {text!r}); "
                              "its position is lost: set the zero again")
        return None

    def command(self, line: str, *, timeout: float | None = None, what: str | None = None) -> list[str]:
        """Send one line and wait for its ``ok``; the lines before it are returned."""
        what = what or repr(line)
        limit = self.timeout if timeout is None else timeout
        self.send(line)
        deadline = time.monotonic() + limit
        got = []
        while True:
            text = self.read_line(deadline)
            if text is None:
                raise StageError(f"{self.name}: no answer to {what} within {limit:g} s; is the controller on, "
                                 "and is the baud rate right?")
            if text == "ok" or text.startswith("ok "):
                return got
            if "busy:" in text:  # Marlin's host keepalive: still working on a long command
                deadline = max(deadline, time.monotonic() + self.timeout)
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
            elif text == "start" or text.startswith("echo:Marlin"):
                seen = "marlin"
                if text.startswith("echo:Marlin"):
                    self.firmware = text[5:].strip()
        self.banner_seen = seen is not None
        if seen is None:
            seen = self._probe()
        if flavor != "auto" and seen != flavor:
            raise InputError(f"{self.name}: --stage-flavor {flavor}, but the controller is {seen} "
                             f"({self.firmware or 'by its answers'})")
        self.flavor = seen
        if seen == "grbl":
            self.alarm = "Alarm" if self.status()[0].startswith("Alarm") else ""
            if not self.alarm:
                self._work_offset()

    def _probe(self) -> str:
        """No banner: ask. Marlin answers M115 with its firmware name; GRBL answers it with error:N."""
        self.send("M115")
        deadline = time.monotonic() + self.timeout
        name = ""
        while True:
            text = self.read_line(deadline)
            if text is None:
                raise StageError(f"{self.name}: no answer to M115 within {self.timeout:g} s; is the controller on, "
                                 "and is the baud rate right?")
            if text.startswith("FIRMWARE_NAME:"):
                name = text[len("FIRMWARE_NAME:"):].split(" SOURCE_CODE_URL")[0].strip()
            elif text.lower().startswith("error:") and text[6:].strip().isdigit():
                self.send("$I")  # GRBL: build info, then ok
                info = self._until_ok("$I")
                ver = next((t for t in info if t.startswith("[VER:")), "")
                self.firmware = f"Grbl {ver[5:].split(':')[0]}" if ver else "Grbl"
                return "grbl"
            elif text == "ok" or text.startswith("ok "):
                if "marlin" not in name.lower():
                    raise InputError(f"{self.name}: the controller answered M115 with firmware {name or 'unnamed'}; "
                                     "give --stage-flavor marlin or grbl if it speaks one of them")
                self.firmware = name
                return "marlin"

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

    def _work_offset(self) -> None:
        """GRBL reports MPos (or WPos); G1 targets are in work coordinates: WCO = G54 + G92 (+ G43.1 on Z)."""
        wco = np.zeros(3)
        for text in self.command("$#"):
            m = re.match(r"\[(G54|G92|TLO):([^\]]*)\]", text)
            if m:
                vals = [float(v) for v in m.group(2).split(",")]
                if m.group(1) == "TLO":
                    wco[2] += vals[0]
                else:
                    wco += np.array(vals[:3])
        self.wco = wco

    # -- state and motion

    def status(self) -> tuple[str, np.ndarray]:
        """GRBL: the real-time ``?`` report: (state, work position)."""
        self._write(b"?")  # real-time: no line end, answered at once, no ok
        deadline = time.monotonic() + self.timeout
        while True:
            text = self.read_line(deadline)
            if text is None:
                raise StageError(f"{self.name}: no status report within {self.timeout:g} s after '?'")
            if text.startswith("<") and text.endswith(">"):
                return self._parse_status(text)
            fault = self._fault(text, "a status query")
            if fault is not None:
                raise fault

    def _parse_status(self, text: str) -> tuple[str, np.ndarray]:
        fields = text[1:-1].split("|")
        state = fields[0]
        pos, kind = None, None
        for f in fields[1:]:
            name, _, val = f.partition(":")
            if name in ("MPos", "WPos"):
                pos, kind = np.array([float(v) for v in val.split(",")[:3]]), name
            elif name == "WCO":
                self.wco = np.array([float(v) for v in val.split(",")[:3]])
        if pos is None:
            raise StageError(f"{self.name}: a status report without a position: {text!r}")
        return state, (pos - self.wco if kind == "MPos" else pos)

    def position(self) -> np.ndarray:
        """X, Y, Z in the coordinates G1 uses, as the controller reports them."""
        if self.flavor == "grbl":
            return self.status()[1]
        for text in self.command("M114"):
            m = _MARLIN_POS.search(text)
            if m:
                return np.array([float(v) for v in m.groups()])
        raise StageError(f"{self.name}: M114 gave no position")

    def wait_idle(self, timeout: float, what: str) -> None:
        """Until every queued move has ended (Marlin M400; GRBL G4 P0, then Idle in the status report)."""
        if self.flavor == "marlin":
            self.command("M400", timeout=timeout, what=f"M400 after {what}")
            return
        self.command("G4 P0", timeout=timeout, what=f"G4 P0 after {what}")
        deadline = time.monotonic() + self.timeout
        while True:
            state, _ = self.status()
            if state.startswith("Idle"):
                return
            if state.startswith("Alarm"):
                raise StageError(f"{self.name}: the controller went into ALARM during {what}; home it (--home) or "
                                 "unlock it (--unlock), then set the zero again")
            if time.monotonic() > deadline:
                raise StageError(f"{self.name}: still {state} {self.timeout:g} s after {what} ended")
            time.sleep(POLL)

    def setup(self) -> None:
        """Millimetres, absolute coordinates, feed per minute; Marlin's steppers on."""
        self.command("G21")
        self.command("G90")
        self.command("M17" if self.flavor == "marlin" else "G94")

    def move(self, target: dict[str, float], feed: float, *, start: np.ndarray | None = None) -> np.ndarray:
        """G1 to ``target`` (machine axis -> mm) at ``feed`` mm/min, wait for its end, check the position."""
        words = " ".join(f"{a}{target[a]:.3f}" for a in MACHINE_AXES if a in target)
        line = f"G1 {words} F{feed:g}"
        if start is None:
            start = self.position()  # the move's length sets its time limit
        travel = math.sqrt(sum((target[a] - start[i]) ** 2 for i, a in enumerate(MACHINE_AXES) if a in target))
        self.command(line)
        # the move's own time, twice over (acceleration), plus the answer's time limit
        self.wait_idle(2.0 * travel / feed * 60.0 + self.timeout, line)
        pos = self.position()
        for i, a in enumerate(MACHINE_AXES):
            if a in target and abs(pos[i] - round(target[a], 3)) > POSITION_TOL:
                raise StageError(f"{self.name}: after {line!r} the controller reports {a}{pos[i]:g}: a move clamped "
                                 "by its own software endstops, or lost steps")
        return pos

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


# --- pose axes ------------------------------------------------------------------------------


@dataclass(frozen=True)
class AxisMap:
    """Machine axis -> (pose axis, sign): pose component = sign * machine displacement."""

    pairs: tuple  # ((machine axis, pose axis, sign), ...)

    @classmethod
    def parse(cls, spec: str) -> "AxisMap":
        what = f"--stage-axes {spec!r}"
        pairs, seen_m, seen_p = [], set(), set()
        for part in spec.replace(";", ",").split(","):
            part = part.strip()
            if not part:
                continue
            m = re.fullmatch(r"([XYZxyz])\s*=\s*([+-]?)\s*(dx|dy|dz)", part)
            if not m:
                raise InputError(f"{what}: {part!r} is not MACHINE=[-]POSE with MACHINE in X,Y,Z and POSE in "
                                 "dx,dy,dz (e.g. X=dx,Y=-dy,Z=dz)")
            ma, pa = m.group(1).upper(), m.group(3)
            if ma in seen_m or pa in seen_p:
                raise InputError(f"{what}: {ma if ma in seen_m else pa} appears twice")
            seen_m.add(ma)
            seen_p.add(pa)
            pairs.append((ma, pa, -1 if m.group(2) == "-" else 1))
        if not pairs:
            raise InputError(f"{what}: no axis")
        return cls(tuple(sorted(pairs)))

    def __str__(self) -> str:
        return ",".join(f"{m}={'-' if s < 0 else ''}{p}" for m, p, s in self.pairs)

    @property
    def pose_axes(self) -> tuple[str, ...]:
        return tuple(p for _, p, _ in self.pairs)

    def to_machine(self, zero: dict[str, float], d: np.ndarray) -> dict[str, float]:
        """Machine targets for the pose displacement ``d`` (dx, dy, dz) from ``zero``."""
        return {m: zero[m] + s * float(d[STAGE_AXES.index(p)]) for m, p, s in self.pairs}

    def to_pose(self, zero: dict[str, float], machine: np.ndarray) -> np.ndarray:
        d = np.zeros(3)
        for m, p, s in self.pairs:
            d[STAGE_AXES.index(p)] = s * (machine[MACHINE_AXES.index(m)] - zero[m])
        return d


def parse_ranges(spec: str, what: str) -> dict[str, tuple[float, float]]:
    """``dx=-3:3,dz=-2:0.5`` -> {axis: (lo, hi)} over dx, dy, dz."""
    out = {}
    for part in spec.replace(";", ",").split(","):
        part = part.strip()
        if not part:
            continue
        name, sep, rng = part.partition("=")
        lo, sep2, hi = rng.partition(":")
        try:
            lo_v, hi_v = float(lo), float(hi)
        except ValueError:
            lo_v = hi_v = math.nan
        if not sep or not sep2 or name.strip() not in STAGE_AXES or not (lo_v < hi_v):
            raise InputError(f"{what} {spec!r}: expected AXIS=LO:HI (mm, LO < HI) for AXIS in dx,dy,dz, "
                             "e.g. dx=-3:3,dy=-3:3,dz=-2.5:0.5")
        out[name.strip()] = (lo_v, hi_v)
    return out


def parse_approach(spec: str) -> np.ndarray:
    """``dx=-0.3,dy=-0.3,dz=0.3`` -> where the last move to a pose starts from, relative to it (mm)."""
    from fitgen.base.parse import parse_assignments

    vals = parse_assignments(spec, STAGE_AXES, "--stage-approach")
    d = np.array([vals.get(a, 0.0) for a in STAGE_AXES])
    if not np.all(np.isfinite(d)) or np.any(np.abs(d) > 10):
        raise InputError(f"--stage-approach {spec!r}: each distance within -10..10 mm")
    return d


@dataclass
class StageSettings:
    axes: AxisMap
    limits: dict  # pose axis -> (lo, hi) mm, from the zero
    feed: float = 600.0  # mm/min
    approach: np.ndarray = field(default_factory=lambda: np.array([-0.3, -0.3, 0.3]))
    jog_max: float = 5.0  # mm per jog step while the zero is set

    def check(self) -> "StageSettings":
        if not (math.isfinite(self.feed) and self.feed > 0):
            raise InputError(f"--stage-feed must be > 0 mm/min, got {self.feed}")
        missing = [a for a in self.axes.pose_axes if a not in self.limits]
        if missing:
            raise InputError(f"--stage-limits: give a range for {missing[0]} (it is in --stage-axes {self.axes})")
        return self

    def check_schedule(self, poses: np.ndarray, describe) -> None:
        """Every pose, and the point its approach starts from, inside the limits; nothing a 3-axis stage
        without an axis for it cannot set."""
        for name in POSE_NAMES:
            k = POSE_NAMES.index(name)
            if name in self.axes.pose_axes:
                continue
            bad = np.flatnonzero(poses[:, k] != 0)
            if bad.size:
                i = int(bad[0])
                how = "the stage moves dx,dy,dz only" if name not in STAGE_AXES else \
                    f"--stage-axes {self.axes} moves no machine axis along it"
                raise InputError(f"pose {i + 1}/{len(poses)} ({describe(i)}) has {name} != 0: {how}")
        for name in self.axes.pose_axes:
            k = STAGE_AXES.index(name)
            lo, hi = self.limits[name]
            for label, vals in (("", poses[:, k]), (" (with its approach)", poses[:, k] + self.approach[k])):
                bad = np.flatnonzero((vals < lo - 1e-9) | (vals > hi + 1e-9))
                if bad.size:
                    i = int(bad[0])
                    raise InputError(f"pose {i + 1}/{len(poses)} ({describe(i)}){label} reaches {name}={vals[i]:g}, "
                                     f"outside --stage-limits {name}={lo:g}:{hi:g}")

    def describe(self) -> dict:
        return {"axes": str(self.axes), "feed_mm_min": self.feed,
                "limits_mm": {k: list(v) for k, v in sorted(self.limits.items())},
                "approach_mm": {a: float(v) for a, v in zip(STAGE_AXES, self.approach)}}


class PoseStage:
    """Moves the controller to poses (dx, dy, dz from the zero), within the limits, each from the same side.

    An axis whose last move went the approach's way (towards the pose from the approach point) is
    "loaded": its backlash is taken up on that side. A pose is reached by one move when every axis
    moves that way or stays; otherwise by a move to the approach point first.
    """

    def __init__(self, ctrl: GcodeController, settings: StageSettings, zero: dict[str, float], *,
                 on_move=None):
        self.ctrl, self.settings, self.zero = ctrl, settings, dict(zero)
        self.on_move = on_move  # called with (list of machine targets about to be sent) and then (None)
        self.position: np.ndarray | None = None  # machine X, Y, Z last confirmed
        self.loaded = np.zeros(3, dtype=bool)
        self.moves = 0

    def _check(self, d: np.ndarray) -> None:
        for name in self.settings.axes.pose_axes:
            k = STAGE_AXES.index(name)
            lo, hi = self.settings.limits[name]
            if not lo - 1e-9 <= d[k] <= hi + 1e-9:
                # checked for the whole schedule before the first move: reaching this is a bug, never sent
                raise StageError(f"refused to move to {name}={d[k]:g}: outside the limits {lo:g}:{hi:g}")

    def plan(self, pose) -> list[np.ndarray]:
        """The pose displacements to send, the approach point first if one is needed."""
        target = np.asarray(pose, dtype=float)[:3].copy()
        a = self.settings.approach
        current = None if self.position is None else self.settings.axes.to_pose(self.zero, self.position)
        need = np.zeros(3, dtype=bool)
        for name in self.settings.axes.pose_axes:
            k = STAGE_AXES.index(name)
            if a[k] == 0:
                continue
            if current is None:
                need[k] = True  # where the backlash sits is unknown
                continue
            step = target[k] - current[k]
            towards = step * -np.sign(a[k]) > 1e-9  # moving the approach's way
            # loaded and staying or moving on the approach's way: still loaded; a move the approach's way
            # at least as long as the approach loads the axis too
            need[k] = not ((self.loaded[k] and (abs(step) <= 1e-9 or towards)) or
                           (towards and abs(step) >= abs(a[k]) - 1e-9))
        if not need.any():
            return [target]
        return [np.where(need, target + a, target), target]

    def move_to(self, pose) -> None:
        steps = self.plan(pose)
        for d in steps:
            self._check(d)
        targets = [self.settings.axes.to_machine(self.zero, d) for d in steps]
        if self.on_move is not None:
            self.on_move(targets)
        for d, t in zip(steps, targets):
            start = self.position
            self.position = self.ctrl.move(t, self.settings.feed, start=start)
            self.moves += 1
        for name in self.settings.axes.pose_axes:
            self.loaded[STAGE_AXES.index(name)] = True
        if self.on_move is not None:
            self.on_move(None)

    def jog(self, axis: str, step: float) -> np.ndarray:
        """A relative move along a pose axis while the zero is set (no limits: they count from the zero)."""
        if axis not in self.settings.axes.pose_axes:
            raise InputError(f"{axis} is not moved by --stage-axes {self.settings.axes}")
        if not (math.isfinite(step) and abs(step) <= self.settings.jog_max):
            raise InputError(f"a jog step is at most {self.settings.jog_max:g} mm")
        pos = self.position if self.position is not None else self.ctrl.position()
        here = {m: float(pos[MACHINE_AXES.index(m)]) for m, _, _ in self.settings.axes.pairs}
        d = np.zeros(3)
        d[STAGE_AXES.index(axis)] = step
        target = self.settings.axes.to_machine(here, d)
        self.position = self.ctrl.move(target, self.settings.feed, start=pos)
        self.loaded[:] = False
        return self.position


# --- the zero and what survives between runs -----------------------------------------------


@dataclass
class StageState:
    """What a resumed capture needs of the stage: the zero, and where the last moves left it."""

    flavor: str
    axes: str
    zero: dict  # machine axis -> mm: the pose origin (first contact with the resting sensor)
    homed: bool  # the zero was taken on a homed machine: it holds after a reset and homing
    position: list | None = None  # machine X, Y, Z after the last confirmed move
    pending: list = field(default_factory=list)  # targets sent but not confirmed (a run stopped mid-move)

    @staticmethod
    def path_for(output: str | Path) -> Path:
        return Path(str(output) + ".stage.json")

    def save(self, output: str | Path) -> None:
        write_atomic(self.path_for(output), json.dumps(self.__dict__, indent=2, sort_keys=True) + "\n")

    @classmethod
    def load(cls, output: str | Path) -> "StageState | None":
        path = cls.path_for(output)
        if not path.exists():
            return None
        try:
            d = json.loads(path.read_text())
            return cls(str(d["flavor"]), str(d["axes"]), {k: float(v) for k, v in d["zero"].items()},
                       bool(d["homed"]), d.get("position"), list(d.get("pending") or []))
        except (OSError, ValueError, KeyError, TypeError, AttributeError) as exc:
            raise InputError(f"{path}: not a stage state ({exc}); remove it to set the zero again") from None


def zero_still_valid(state: StageState | None, ctrl: GcodeController, axes: AxisMap, homed_now: bool) -> str:
    """'' if ``state``'s zero holds for this connection, else why not (one clause)."""
    if state is None:
        return "the stage has no zero yet"
    if state.axes != str(axes):
        return f"the zero was taken with --stage-axes {state.axes}"
    if state.flavor != ctrl.flavor:
        return f"the zero was taken on a {state.flavor} controller"
    if state.homed and homed_now:
        return ""  # homing gives the same machine coordinates after any reset
    if homed_now:
        return "homing moved the machine since the zero was taken (the zero was set before homing)"
    if ctrl.banner_seen:
        return "the controller was reset (it printed its start-up banner on connect)"
    pos = ctrl.position()
    known = ([state.position] if state.position is not None else []) + list(state.pending)
    for p in known:
        p = np.array([p[a] for a in MACHINE_AXES]) if isinstance(p, dict) else np.asarray(p, dtype=float)
        want = [MACHINE_AXES.index(m) for m, _, _ in axes.pairs]
        if np.all(np.abs(pos[want] - p[want]) <= POSITION_TOL):
            return ""
    where = " ".join(f"{a}{v:g}" for a, v in zip(MACHINE_AXES, pos))
    return (f"the controller reports {where}, not where the last run left it: it was reset or moved since the "
            "zero was taken")


def jog_to_zero(stage: PoseStage, stdin, stderr, prog: str) -> dict[str, float] | None:
    """Ask the user to jog to first contact with the resting sensor; the zero, or None if they stop."""
    axes = stage.settings.axes
    stderr.write(f"{prog}: set the zero: jog the indenter to first contact with the resting sensor, centred over "
                 f"the magnet. Type AXIS STEP (mm along the pose axes {','.join(axes.pose_axes)}, up to "
                 f"{stage.settings.jog_max:g}; e.g. 'dz -0.1'), end with a move down in dz; an empty line takes "
                 "the zero here; q stops.\n")
    origin = stage.ctrl.position()
    stage.position = origin
    moved = np.zeros(3)
    while True:
        stderr.write(f"jog [{' '.join(f'{a}{v:+.3f}' for a, v in zip(STAGE_AXES, moved))}]> ")
        stderr.flush()
        line = stdin.readline()
        if not line or line.strip().lower() in ("q", "quit"):
            stderr.write("\n")
            return None
        parts = line.replace("=", " ").split()
        if not parts:
            pos = stage.position
            return {m: float(pos[MACHINE_AXES.index(m)]) for m, _, _ in axes.pairs}
        try:
            if len(parts) != 2:
                raise InputError("type AXIS STEP, e.g. dz -0.1")
            try:
                step = float(parts[1])
            except ValueError:
                raise InputError(f"{parts[1]!r} is not a number") from None
            stage.jog(parts[0].lower(), step)
            moved[STAGE_AXES.index(parts[0].lower())] += step
        except InputError as exc:
            stderr.write(f"{prog}: {exc}\n")


def parse_zero(spec: str) -> str | dict[str, float]:
    """``ask``, ``here``, or machine coordinates ``X=..,Y=..,Z=..`` (or three numbers)."""
    s = spec.strip().lower()
    if s in ("ask", "here"):
        return s
    from fitgen.base.parse import parse_assignments

    if "=" in s:
        vals = parse_assignments(spec.upper(), MACHINE_AXES, "--zero")
    else:
        try:
            nums = [float(x) for x in s.replace(",", " ").split()]
        except ValueError:
            nums = []
        if len(nums) != 3:
            raise InputError(f"--zero {spec!r}: ask, here, or the machine coordinates X,Y,Z (e.g. 120.5,80,12.25)")
        vals = dict(zip(MACHINE_AXES, nums))
    if not all(math.isfinite(v) for v in vals.values()):
        raise InputError(f"--zero {spec!r}: not finite")
    return vals


def choose_zero(ctrl: GcodeController, state: StageState | None, axes: AxisMap, spec, *, rows: int,
                ask) -> tuple[dict[str, float], str]:
    """The zero for this run and how it was had: kept from ``state`` while it holds, else from ``spec``
    (``ask``: ``ask(reason)`` jogs with the user; ``here``: the current position, for a dataset without
    rows only; or machine coordinates). Raises InputError when none can be had."""
    reason = zero_still_valid(state, ctrl, axes, ctrl.homed)
    if isinstance(spec, dict):
        want = [m for m, _, _ in axes.pairs]
        missing = [m for m in want if m not in spec]
        if missing:
            raise InputError(f"--zero: give {missing[0]} too (it is in --stage-axes {axes})")
        zero = {m: float(spec[m]) for m in want}
        if not reason and rows and any(abs(zero[m] - state.zero[m]) > POSITION_TOL for m in want):
            raise InputError(f"--zero {' '.join(f'{m}{v:g}' for m, v in zero.items())} is not the zero the dataset's "
                             f"{rows} rows were taken from ({' '.join(f'{m}{v:g}' for m, v in state.zero.items())}); "
                             "choose another -o for another zero")
        return zero, "given"
    if not reason:
        return dict(state.zero), "kept from the last run"
    if spec == "here":
        if rows:
            raise InputError(f"{reason}; --zero here takes the zero only for a dataset without rows (the stage "
                             "may stand anywhere now): set it at the prompt (--zero ask) or give --zero X,Y,Z")
        pos = ctrl.position()
        return {m: float(pos[MACHINE_AXES.index(m)]) for m, _, _ in axes.pairs}, "here"
    zero = ask(reason)
    if zero is None:
        raise InputError(f"{reason}, and no zero was set: set it at the prompt, or give --zero X,Y,Z "
                         "(machine coordinates of first contact)")
    return zero, "set by jogging"
