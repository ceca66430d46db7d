"""A simulated G-code stage: a Marlin or GRBL controller moving a simulated sensor (host.stageserver serves it)
through host.simrig.SimRig, the mechanics.

``SimController`` is the firmware as a host sees it: lines in, lines out, at the
times a real one answers. Both flavors queue ``G1`` moves in a planner (``ok`` at
once while it has room) and move at the feed; Marlin answers ``M400`` when the
planner is empty (``echo:busy: processing`` every ``busy_interval`` meanwhile),
``M114`` with ``X:.. Y:.. Z:.. E:.. Count ..``, ``M115`` with its firmware name,
unknown commands with ``echo:Unknown command``, and clamps moves to its software
endstops once homed, silently, as Marlin does; GRBL answers ``G4 P0`` when the
planner is empty, the real-time ``?`` at once with ``<State|MPos:..|FS:..>``,
``$I``, ``$#``, ``$X``, ``$H``, errors as ``error:N``, a target beyond its travel
when homed as ``ALARM:2``; after a limit's alarm (1 or 2) it answers nothing, ``?`` included, until it is reset
(``reset()`` or Ctrl-X), then starts in Alarm, as it does after a reset with
``homing_lock``, with ``[MSG:'$H'|'$X' to unlock]``. ``reset()``
is the reset button: the carriage stays where it is and its coordinates restart at 0.
``inject(kind, at_move)`` makes the controller fail at its ``at_move``-th G1:
``error`` (GRBL error:33 / Marlin Error: and a halt), ``alarm`` (GRBL ALARM:1, a hard limit),
``silent`` (no answer ever again), ``reset`` (a brown-out).

``simulated_stage_capture`` is a whole ``capture --stage`` run against them.
"""

from __future__ import annotations

import re
import threading
import time
from collections import deque

import numpy as np

from fitgen.base.errors import InputError
from fitgen.base.parse import parse_numbers
from fitgen.physics.sensor import MAX_STAGE_MAP

from host.gcode import MACHINE_AXES
from host.simrig import SimRig
from host.stageserver import PoseFile, PtyServer, SocketServer, pose_file_motion
from host.stagesettings import APPROACH, AxisMap, parse_approach
from host.stagezero import MAX_COORD

# fitgen/app/host_cli.py imports the rig's and the serving side's names from here too
__all__ = ["PoseFile", "PtyServer", "SimController", "SimRig", "SocketServer", "parse_matrix", "parse_xyz",
           "pose_file_motion", "simulated_stage_capture"]

GRBL_VERSION = "1.1h"
GRBL_Z_SWITCH = 20.0  # mm above first contact: where a simulated GRBL's Z homes to (a CNC's Z homes up)
GRBL_WELCOME = f"Grbl {GRBL_VERSION} ['$' for help]"  # grblHAL says "GrblHAL 1.1f ['$' or '$HELP' for help]"
MARLIN_VERSION = "2.1.2.1"


class _Move:
    __slots__ = ("start", "end", "t0", "t1")

    def __init__(self, start, end, t0, t1):
        self.start, self.end, self.t0, self.t1 = start, end, t0, t1


class SimController:
    """Marlin or GRBL, fed bytes by ``receive`` and stepped by ``step(now)``; ``take_output`` gives its bytes."""

    def __init__(self, flavor: str, rig: SimRig, *, planner: int = 16, steps_per_mm: float = 400.0,
                 busy_interval: float = 2.0, homing_lock: bool = False, homing_time: float = 0.2,
                 max_feed=12000.0, clock=time.monotonic):
        if flavor not in ("marlin", "grbl"):
            raise InputError(f"simulated stage flavor {flavor!r}: marlin or grbl")
        self.flavor, self.rig = flavor, rig
        self.planner_size, self.steps_per_mm = planner, steps_per_mm
        self.busy_interval, self.homing_lock, self.homing_time = busy_interval, homing_lock, homing_time
        self.max_feed = np.broadcast_to(np.asarray(max_feed, dtype=float), (3,)).copy()  # per axis, mm/min
        self.clock = clock
        self.lock = threading.RLock()
        self.faults: list[dict] = []
        self.g1_count = 0
        self.lines: list[str] = []  # every line received (tests read it)
        self.on_line = None  # optional callable(line) called before a line is executed
        self._inbuf = bytearray()
        self._out = bytearray()
        self.silent = False
        self.welcome = GRBL_WELCOME  # GRBL's start-up line (a test may give grblHAL's)
        if flavor == "grbl":  # a CNC homes Z up, away from the work: its switch tops Z's travel
            top = min(rig.travel[2, 1], rig.contact[2] + GRBL_Z_SWITCH)
            rig.switches = np.array([0.0, 0.0, top])
            rig.travel[2, 1] = top
        self._power_on()

    # -- state

    def _power_on(self) -> None:
        self.offset = self.rig.carriage.copy()  # home frame = machine + offset; a reset restarts at 0 here
        self.homed = False
        self.queue: deque[_Move] = deque()
        self.pending: deque[str] = deque()  # lines received and not yet executed
        self.blocked_until = None  # a command waiting (M400, G4, homing): (predicate, then)
        self.absolute = True
        self.feed = None if self.flavor == "grbl" else 1500.0
        self.halted = False
        self.critical = False  # GRBL after a limit's alarm: nothing answered until a reset
        self.homing = False
        self.alarm = self.flavor == "grbl" and self.homing_lock
        self._last_busy = 0.0
        self.planned = self.machine()  # where the last queued move ends (machine coordinates)

    def machine(self) -> np.ndarray:
        return self.rig.carriage - self.offset

    def reset(self) -> None:
        """The reset button (or a power cycle): motion stops, coordinates restart at 0, the banner comes."""
        with self.lock:
            now = self.clock()
            moving, halted = bool(self.queue), self.critical
            if moving:  # the carriage stops where it is
                self.rig.move(self._where(now))
            self._power_on()
            self.silent = False
            self._inbuf.clear()
            if self.flavor == "grbl":
                self._say("", self.welcome)
                if halted:
                    self.alarm = True
                if moving:
                    self.alarm = True
                    self._say("ALARM:3")
                if self.alarm:
                    self._say("[MSG:'$H'|'$X' to unlock]")
            else:
                self._say("start", f"echo:Marlin {MARLIN_VERSION}", "echo: Last Updated: 2023-06-22 | Author: sim",
                          "echo:Compiled: Jun 22 2023", "echo: Free Memory: 4096  PlannerBufferBytes: 1024")

    def wait_idle(self, timeout: float = 10.0) -> None:
        """Until every queued move has ended (real time)."""
        end = time.monotonic() + timeout
        while self.queue and time.monotonic() < end:
            time.sleep(0.005)

    def inject(self, kind: str, at_move: int) -> None:
        """Fail at the ``at_move``-th G1 from now (1: the next): error, alarm, silent or reset."""
        if kind not in ("error", "alarm", "silent", "reset"):
            raise InputError(f"simulated stage fault {kind!r}: error, alarm, silent or reset")
        self.faults.append({"kind": kind, "at": self.g1_count + int(at_move)})

    # -- bytes

    def _say(self, *lines: str) -> None:
        if not self.silent:
            for text in lines:
                self._out += text.encode() + b"\r\n"

    def take_output(self) -> bytes:
        with self.lock:
            out = bytes(self._out)
            self._out.clear()
            return out

    def receive(self, data: bytes) -> None:
        with self.lock:
            for b in data:
                if self.flavor == "grbl" and b in (0x3F, 0x18, 0x21, 0x7E):  # ? ctrl-x ! ~ : real-time, never queued
                    if b == 0x3F and not self.critical:
                        self._status(self.clock())
                    elif b == 0x18:
                        self.reset()
                    continue
                if b in (0x0A, 0x0D):
                    if self._inbuf:
                        self.pending.append(self._inbuf.decode("ascii", "replace"))
                        self._inbuf.clear()
                    continue
                self._inbuf.append(b)

    # -- time

    def _where(self, now: float) -> np.ndarray:
        """The carriage (home frame) at ``now``, inside the move under way."""
        if not self.queue or now <= self.queue[0].t0:
            return self.rig.carriage.copy()
        m = self.queue[0]
        f = min((now - m.t0) / (m.t1 - m.t0), 1.0) if m.t1 > m.t0 else 1.0
        return m.start + f * (m.end - m.start)

    def step(self, now: float | None = None) -> None:
        with self.lock:
            now = self.clock() if now is None else now
            while self.queue and self.queue[0].t1 <= now:
                self.rig.move(self.queue.popleft().end)
            if self.silent or self.halted or self.critical:
                self.pending.clear()
                return
            if self.blocked_until is not None:
                done, then = self.blocked_until
                if not done(now):
                    if self.flavor == "marlin" and now - self._last_busy >= self.busy_interval:
                        self._last_busy = now
                        self._say("echo:busy: processing")
                    return
                self.blocked_until = None
                then()
            while self.pending and self.blocked_until is None:
                line = self.pending.popleft()
                if not self._execute(line, now):
                    self.pending.appendleft(line)  # planner full: the line waits, and so does its ok
                    return

    # -- commands

    def _words(self, line: str) -> list[tuple[str, float]] | None:
        line = re.sub(r"\(.*?\)|;.*$", "", line).replace(" ", "").upper()
        words = re.findall(r"([A-Z])([-+]?\d*\.?\d+)", line)
        if "".join(a + b for a, b in words) != line:
            return None
        return [(a, float(b)) for a, b in words]

    def _execute(self, line: str, now: float) -> bool:
        """Run one line; False when it has to wait for room in the planner."""
        text = line.strip()
        words = None if text.startswith("$") else self._words(text)
        if words and words[0][0] == "G" and words[0][1] in (0, 1) and len(self.queue) >= self.planner_size:
            return False
        if self.on_line is not None:
            self.on_line(text)
        if self.flavor == "grbl" and text.startswith("$"):
            self.lines.append(text)
            self._grbl_system(text, now)
            return True
        if words is None or not words:
            self.lines.append(text)
            if self.flavor == "grbl":
                self._say("error:1" if words is None else "ok")
            else:
                self._say(f'echo:Unknown command: "{text}"', "ok")
            return True
        letter, number = words[0]
        code = f"{letter}{number:g}"
        self.lines.append(text)
        if self.flavor == "grbl" and self.alarm:
            self._say("error:9")
            return True
        args = dict(words[1:])
        if code in ("G0", "G1"):
            self._g1(args, now)
        elif code in ("G21", "G54", "G94", "M17", "M18", "M84", "M211"):
            self._say("ok")
        elif code == "G90":
            self.absolute = True
            self._say("ok")
        elif code == "G91":
            self.absolute = False
            self._say("ok")
        elif code == "G4" and self.flavor == "grbl":
            dwell = args.get("P", 0.0)
            self.blocked_until = (lambda t, d=dwell, s=now: not self.queue and t >= s + d, lambda: self._say("ok"))
        elif code == "M400" and self.flavor == "marlin":
            self._last_busy = now
            self.blocked_until = (lambda t: not self.queue, lambda: self._say("ok"))
        elif code == "M114" and self.flavor == "marlin":
            p = self.planned  # Marlin reports where the planner is headed, not the motors
            counts = " ".join(f"{a}:{round(v * self.steps_per_mm)}" for a, v in zip(MACHINE_AXES, self.machine()))
            self._say(f"X:{p[0]:.2f} Y:{p[1]:.2f} Z:{p[2]:.2f} E:0.00 Count {counts}", "ok")
        elif code == "M115" and self.flavor == "marlin":
            self._say(f"FIRMWARE_NAME:Marlin {MARLIN_VERSION} (sim) SOURCE_CODE_URL:local PROTOCOL_VERSION:1.0 "
                      "MACHINE_TYPE:sim stage EXTRUDER_COUNT:1", "Cap:AUTOREPORT_POS:0", "ok")
        elif code == "M503" and self.flavor == "marlin":
            rates = " ".join(f"{a}{v / 60.0:.2f}" for a, v in zip(MACHINE_AXES, self.max_feed))
            self._say("echo:; Maximum feedrates (units/s):", f"echo:  M203 {rates} E25.00", "ok")
        elif code == "G28" and self.flavor == "marlin":
            self._home(now)
        elif self.flavor == "grbl":
            self._say("error:20")
        else:
            self._say(f'echo:Unknown command: "{text}"', "ok")
        return True

    def _g1(self, args: dict, now: float) -> None:
        if "F" in args:
            if args["F"] <= 0:
                self._say("error:2" if self.flavor == "grbl" else "Error:feed rate must be positive", "ok")
                return
            self.feed = args["F"]
        if self.feed is None:  # GRBL: G1 needs a feed rate once
            self._say("error:22")
            return
        target = self.planned.copy()
        for k, a in enumerate(MACHINE_AXES):
            if a in args:
                target[k] = args[a] if self.absolute else target[k] + args[a]
        self.g1_count += 1
        for f in list(self.faults):
            if f["at"] == self.g1_count:
                self.faults.remove(f)
                return self._fail(f["kind"], now)
        home_frame = target + self.offset
        if self.homed:
            lo, hi = self.rig.travel[:, 0], self.rig.travel[:, 1]
            outside = np.any((home_frame < lo) | (home_frame > hi))
            if outside and self.flavor == "grbl":  # soft limits: alarm, and a halt until reset
                return self._limit_alarm(2)
            home_frame = np.clip(home_frame, lo, hi)  # Marlin's software endstops: clamped, silently
            target = home_frame - self.offset
        start = self.queue[-1].end if self.queue else self.rig.carriage.copy()
        t0 = max(now, self.queue[-1].t1 if self.queue else now)
        dist = float(np.linalg.norm(home_frame - start))
        share = np.abs(home_frame - start) / dist if dist > 0 else np.zeros(3)
        # the planner slows the whole move until no axis passes its top rate
        speed = min([self.feed] + [m / s for m, s in zip(self.max_feed, share) if s > 0])
        self.queue.append(_Move(start, home_frame, t0, t0 + dist / speed * 60.0))
        self.planned = target
        self._say("ok")

    def _fail(self, kind: str, now: float) -> None:
        if kind == "silent":
            self.silent = True
        elif kind == "reset":
            self.reset()
        elif kind == "error":
            if self.flavor == "grbl":
                self._say("error:33")
            else:
                self._say("Error:Printer halted. kill() called!", "!!")
                self.halted = True
        else:  # a hard limit switch hit
            if self.flavor == "grbl":
                self._limit_alarm(1)
            else:
                self._say("Error:Printer halted. kill() called!", "!!")
                self.halted = True

    def _limit_alarm(self, code: int) -> None:
        """GRBL's critical event (grbl/protocol.c): motion stops, and it waits for a reset."""
        self.queue.clear()
        self.pending.clear()
        self.alarm = self.critical = True
        self._say(f"ALARM:{code}", "[MSG:Reset to continue]")

    def _home(self, now: float) -> None:
        def done():
            self.rig.move(self.rig.switches.copy())
            self.offset = self.rig.switches.copy()  # machine 0 at the switches
            self.homed = True
            self.homing = False
            self.alarm = False
            self.planned = self.machine()
            if self.flavor == "marlin":
                self._say("X:0.00 Y:0.00 Z:0.00 E:0.00 Count X:0 Y:0 Z:0")
            self._say("ok")
        self.queue.clear()
        self.homing = True
        self._last_busy = now
        self.blocked_until = (lambda t, end=now + self.homing_time: t >= end, done)

    def _grbl_system(self, text: str, now: float) -> None:
        if text == "$I":
            self._say(f"[VER:{GRBL_VERSION}.20190825:]", "[OPT:V,15,128]", "ok")
        elif text == "$#":
            self._say("[G54:0.000,0.000,0.000]", "[G55:0.000,0.000,0.000]", "[G28:0.000,0.000,0.000]",
                      "[G30:0.000,0.000,0.000]", "[G92:0.000,0.000,0.000]", "[TLO:0.000]", "[PRB:0.000,0.000,0.000:0]",
                      "ok")
        elif text == "$X":
            if self.alarm:
                self._say("[MSG:Caution: Unlocked]")
            self.alarm = False
            self._say("ok")
        elif text == "$H":
            if not self.homing_lock:
                self._say("error:5")  # homing not enabled in the settings
            else:
                self._home(now)
        elif text == "$$":
            rates = (f"$11{i}={v:.3f}" for i, v in enumerate(self.max_feed))
            self._say(f"$100={self.steps_per_mm:.3f}", *rates, "ok")
        elif text in ("$", "$G", "$N"):
            self._say("ok")
        else:
            self._say("error:3")

    def _status(self, now: float) -> None:
        if self.silent:
            return
        state = "Alarm" if self.alarm else "Home" if self.homing else "Run" if self.queue else "Idle"
        pos = self._where(now) - self.offset
        # GRBL counts steps: the report is the nearest step
        pos = np.round(pos * self.steps_per_mm) / self.steps_per_mm
        feed = self.feed if self.queue else 0
        self._say(f"<{state}|MPos:{pos[0]:.3f},{pos[1]:.3f},{pos[2]:.3f}|FS:{feed or 0:g},0>")


def parse_matrix(spec: str) -> np.ndarray:
    """``a,b,c;d,e,f;g,h,i`` (rows) -> 3x3."""
    try:
        rows = [[float(x) for x in r.replace(",", " ").split()] for r in spec.split(";")]
        M = np.array(rows, dtype=float)
    except ValueError:
        M = np.zeros(0)
    if M.shape != (3, 3) or not np.all(np.abs(M) <= MAX_STAGE_MAP):  # NaN and inf too
        raise InputError(f"--map {spec!r}: three rows of three numbers within +-{MAX_STAGE_MAP:g}, rows split by ';' "
                         "(e.g. 0.95,0.05,0;-0.05,0.95,0;0,0,0.9)")
    # the magnet follows the tool by a fraction: a map that leaves a direction unmoved is no elastomer's
    if np.linalg.svd(M, compute_uv=False)[-1] < 1e-3:
        raise InputError(f"--map {spec!r} leaves the magnet unmoved along some direction of the stage (singular); "
                         "an elastomer's map is near a scaled identity, e.g. 0.95,0.05,0;-0.05,0.95,0;0,0,0.9")
    return M


def parse_xyz(text: str, what: str) -> list[float]:
    """``X,Y,Z`` in mm (``what``: the option, for the error) -> three numbers, each within MAX_COORD."""
    vals = parse_numbers(text)
    if vals is None or len(vals) != 3:
        raise InputError(f"{what} {text!r}: three numbers X,Y,Z (mm)")
    if not all(abs(v) <= MAX_COORD for v in vals):  # NaN fails it too
        raise InputError(f"{what} {text!r}: each must lie within +-{MAX_COORD:g} mm (no machine travels further)")
    return vals


def simulated_stage_capture(sensor, schedule, output, *, flavor: str = "grbl", samples: int = 16,
                            noise: float = 0.0005, backlash: float = 0.03, repeatability: float = 0.005,
                            limits: str = "dx=-3.5:3.5,dy=-3.5:3.5,dz=-3.5:1", approach: str = APPROACH,
                            seed: int = 0, zero_off=(0.0, 0.0, 0.0), progress=None):
    """A capture as `tactile-host capture --stage` makes it, all simulated: two ADS1115s on a simulated bus read
    ``sensor`` (a unit, say, whose file carries its stage map), a simulated ``flavor`` controller moves it through a
    rig with ``backlash`` and ``repeatability`` (mm), zeroed at first contact as the documented jog finds it (each
    axis from its approach side, so the backlash is taken up as at every pose), or ``zero_off`` (mm, dx, dy, dz)
    from it, as a zero set by hand is. Returns the capture's result."""
    from host.adc import AdcArray
    from host.capture import capture
    from host.channelmap import parse_spec
    from host.clock import VirtualClock
    from host.simbus import SimBus
    from host.gcode import GcodeController
    from host.stage import PoseStage
    from host.stagesettings import StageSettings, parse_ranges

    contact, start = (12.0, 8.0, 4.0), (10.0, 10.0, 10.0)
    cmap = parse_spec("ads1115@0x48:0-3,ads1115@0x49:0-3")
    clock = VirtualClock()
    bus = SimBus.for_channel_map(cmap, sensor.with_transfer("gmr"), None, clock=clock, noise=noise, seed=seed)
    bus.feed.touching = True  # the rig decides contact on the tool
    rig = SimRig(bus.feed, None, contact=contact, start=start, backlash=backlash, repeatability=repeatability,
                 seed=seed + 1)
    settings = StageSettings(AxisMap.parse("X=dx,Y=dy,Z=dz"), parse_ranges(limits, "--stage-limits"), feed=6000.0,
                             approach=parse_approach(approach)).check()
    settings.check_schedule(schedule.poses, schedule.describe)
    with SocketServer(SimController(flavor, rig)) as srv:
        ctrl = GcodeController.open(srv.url, timeout=2.0)
        try:
            ctrl.connect(boot_wait=0.1)
            ctrl.setup()
            found = rig.carriage_at_contact(settings.approach) - srv.ctrl.offset + np.asarray(zero_off, dtype=float)
            zero = dict(zip("XYZ", map(float, found)))
            arr = AdcArray(bus, cmap, clock=clock)
            arr.probe()
            arr.setup()
            return capture(arr, schedule, output, samples=samples, set_pose=PoseStage(ctrl, settings, zero).move_to,
                           clock=clock, progress=progress,
                           meta={"adc": cmap.describe(), "source": f"simulated {sensor.name} on a simulated "
                                 f"{flavor} stage", "stage": {"flavor": ctrl.flavor, "simulated": True,
                                                               # its coordinates never move, as a homed machine's
                                                               "zero_machine_mm": zero, "zero_homed": True,
                                                               "axes": str(settings.axes)}})
        finally:
            ctrl.close()
