"""capture --stage: the G-code driver against simulated Marlin and GRBL controllers that move a simulated sensor."""

import contextlib
import io
import json
import os
import re
import signal
import subprocess
import sys
import threading

import numpy as np
import pytest
import serial

from fitgen.c.codegen import render_header
from fitgen.physics.dataset import load_dataset
from fitgen.base.errors import InputError
from fitgen.fitting.fit import fit_model
from fitgen.fitting.capturezero import stage_zero
from fitgen.physics.transfer import readings
from host.adc import AdcArray
from host.capture import capture, load_schedule
from host.channelmap import parse_spec
from host.clock import VirtualClock
from host.simbus import SimBus
from host.gcode import GcodeController, StageError
from host.stage import PoseStage, jog_to_zero
from host.stageserver import PoseFile, PtyServer, SocketServer
from host.stagesettings import AxisMap, StageSettings, parse_approach, parse_ranges
from host.stagesim import GRBL_Z_SWITCH, MARLIN_VERSION, SimController, SimRig
from host.stagezero import StageState, choose_zero, parse_zero, run_zeros, zero_still_valid

from conftest import assert_one_line_error

TWO_1115 = "ads1115@0x48:0-3,ads1115@0x49:0-3"
# the rig's stage-to-magnet map: 3 degrees of yaw between stage and sensor, the skin passes 92..95 % of the
# indenter's motion to the magnet, and a press drags it sideways a little
M_RIG = np.array([[0.95, 0.05, 0.02], [-0.05, 0.95, 0.0], [0.0, 0.0, 0.92]])
BACKLASH = 0.04
CONTACT, START = (12.0, 8.0, 4.0), (10.0, 10.0, 10.0)  # home frame; machine coordinates start at 0 at START
FEED = 6000.0
LIMITS = "dx=-2:2,dy=-2:2,dz=-2:1"


def grid():
    return [(dx, dy, dz) for dz in (0, -0.5, -1) for dy in (-1, 0, 1) for dx in (-1.5, 0, 1.5)]  # 27 poses


def write_schedule(path, rows):
    path.write_text("dx,dy,dz\n" + "".join(",".join(map(str, r)) + "\n" for r in rows))
    return path


def settings(axes="X=dx,Y=dy,Z=dz", limits=LIMITS, approach="dx=-0.3,dy=-0.3,dz=0.3"):
    return StageSettings(AxisMap.parse(axes), parse_ranges(limits, "--stage-limits"), feed=FEED,
                         approach=parse_approach(approach)).check()


class Sink:
    def __init__(self):
        self.pose = np.zeros(5)

    def set_pose(self, pose):
        self.pose = np.array(pose)


def server(flavor, target=None, *, M=None, transport=None, backlash=BACKLASH, repeatability=0.0, **kw):
    rig = SimRig(target if target is not None else Sink(), M, contact=CONTACT, start=START, backlash=backlash,
                 repeatability=repeatability, seed=1)
    ctrl = SimController(flavor, rig, **kw)
    transport = transport or (SocketServer if flavor == "grbl" else PtyServer)
    return transport(ctrl)


def connect(srv, timeout=2.0):
    c = GcodeController.open(srv.url, timeout=timeout)
    c.connect(boot_wait=0.1)
    return c


def connect_after_reset(srv, timeout=2.0):
    """Open the port, then reset the controller, as DTR resets a board when its port opens: pyserial's open
    flushes the terminal's input, so a banner written before it would be lost."""
    c = GcodeController.open(srv.url, timeout=timeout)
    srv.ctrl.reset()
    c.connect(boot_wait=1.0)  # the banner's first line may take a moment; quiet after it ends the wait
    return c


def contact_zero(srv):
    """First contact in the controller's present machine coordinates (what a careful user jogs to)."""
    c = np.array(CONTACT) - srv.ctrl.offset
    return dict(zip("XYZ", map(float, c)))


def truth_poses(schedule_poses, M=M_RIG, approach=(-0.3, -0.3, 0.3)):
    """Where the magnet is at each scheduled pose: backlash taken up on the approach's side, then M."""
    lag = BACKLASH / 2 * np.sign(approach)
    d = schedule_poses[:, :3] + lag
    out = np.zeros_like(schedule_poses)
    out[:, :3] = d @ M.T
    return out


# --- settings, checked before anything moves ----------------------------------------------------------------


def test_axis_map_limits_and_approach_parse_or_refuse_in_one_line():
    m = AxisMap.parse("Z=dz, X=-dy ,Y=dx")
    assert str(m) == "X=-dy,Y=dx,Z=dz"
    assert m.to_machine({"X": 1.0, "Y": 2.0, "Z": 3.0}, np.array([0.5, 0.25, -1])) == {"X": 0.75, "Y": 2.5, "Z": 2.0}
    np.testing.assert_allclose(m.to_pose({"X": 1.0, "Y": 2.0, "Z": 3.0}, np.array([0.75, 2.5, 2.0])), [0.5, 0.25, -1])
    for bad, msg in [("X=dx,X=dy", "X appears twice"), ("X=dx,Y=dx", "dx appears twice"), ("A=dx", "is not MACHINE="),
                     ("X=thx", "is not MACHINE="), ("", "no axis")]:
        with pytest.raises(InputError, match=msg):
            AxisMap.parse(bad)
    assert parse_ranges("dx=-1:2", "--stage-limits") == {"dx": (-1.0, 2.0)}
    # the separators of fitgen schedule --limits (spaces) work too: the two options of one workflow
    assert parse_ranges("dx=-1:2 dz=-2:0.5", "l") == parse_ranges("dx=-1:2, dz=-2:0.5", "l") == \
        {"dx": (-1.0, 2.0), "dz": (-2.0, 0.5)}
    for bad in ("dx=2:1", "dq=0:1", "dx=0", "dx=a:1", "dz=-inf:inf"):
        with pytest.raises(InputError, match="AXIS=LO:HI"):
            parse_ranges(bad, "--stage-limits")
    with pytest.raises(InputError, match="dz is given twice"):
        parse_ranges("dx=-1:1,dz=-2.5:1,dz=-1:1", "--stage-limits")
    # soft limits of +-1e308 mm had been taken, and the capture ran: a safety box that keeps nothing out
    for bad in ("dx=-1e308:1e308", "dz=-3:41"):
        with pytest.raises(InputError, match=r"must lie within \+-40 mm of the zero"):
            parse_ranges(bad, "--stage-limits")
    assert parse_ranges("dx=-40:40", "l") == {"dx": (-40.0, 40.0)}
    with pytest.raises(InputError, match="X is given twice"):
        parse_zero("X=1,X=2,Y=0,Z=0")
    np.testing.assert_array_equal(parse_approach("dz=0.5,dx=0,dy=-0.2"), [0, -0.2, 0.5])
    # an axis left out had been set to 0: its backlash compensation off, unsaid
    with pytest.raises(InputError, match="--stage-approach 'dz=0.5' leaves out dx, dy: give every axis"):
        parse_approach("dz=0.5")
    with pytest.raises(InputError):
        parse_approach("dz=20")
    with pytest.raises(InputError, match="dz=-0.3 starts each pose's last move 0.3 mm deeper than the pose"):
        parse_approach("dx=-0.3,dy=0,dz=-0.3")  # was taken: every row pressed past its pose first
    assert parse_zero("ask") == "ask" and parse_zero("1,2,3") == {"X": 1.0, "Y": 2.0, "Z": 3.0}
    assert parse_zero("z=-4.5,x=1,y=2") == {"X": 1.0, "Y": 2.0, "Z": -4.5}
    # G-code words, as M114 and stage-sim print a position, pasted as they are
    for words in ("X1 Y2 Z-4.5", "X1,Y2,Z-4.5", "x1 y2 z-4.5", "Z-4.5 X1 Y2", "X 1 Y 2 Z -4.5", "X1. Y2. Z-4.5",
                  "X1Y2Z-4.5"):
        assert parse_zero(words) == {"X": 1.0, "Y": 2.0, "Z": -4.5}, words
    # Marlin's M114 answer as printed, which docs/calibration.md says works: its step counts and extruder are not
    # the position (the colons had been refused)
    for m114 in ("X:1.00 Y:2.00 Z:-4.50 E:0.00 Count X:80 Y:160 Z:-1800", "X:1.00 Y:2.00 Z:-4.50", "X: 1 Y: 2 Z: -4.5"):
        assert parse_zero(m114) == {"X": 1.0, "Y": 2.0, "Z": -4.5}, m114
    for bad in ("X1 Y2 Q3", "X1 Y-- Z3", "X1 X2 Z3", "X:1 Y:2 Z:3 Q:4"):
        with pytest.raises(InputError, match=re.escape(f"--zero {bad!r}: ")):
            parse_zero(bad)
    with pytest.raises(InputError, match="ask, here, or the machine coordinates"):
        parse_zero("1,2")
    # metres from the origin: the capture drove for it, its move's time limit years away
    with pytest.raises(InputError, match=re.escape("--zero '1e9,0,0': X1e+09 lies over 2000 mm from the machine's "
                                                   "origin")):
        parse_zero("1e9,0,0")
    assert parse_zero("-1999,0,250") == {"X": -1999.0, "Y": 0.0, "Z": 250.0}
    with pytest.raises(InputError, match="give a range for dz"):
        StageSettings(AxisMap.parse("X=dx,Z=dz"), parse_ranges("dx=-1:1", "l")).check()


def test_the_schedule_is_checked_against_limits_approach_and_axes(tmp_path):
    s = settings(limits="dx=-2:2,dy=-2:2,dz=-1:0.2")
    poses = np.zeros((3, 5))
    poses[1, :3] = [1, 0, -1]
    with pytest.raises(InputError, match=r"pose 1/3 \(#0\) \(with its approach\) reaches dz=0.3, outside"):
        s.check_schedule(poses, lambda i: f"#{i}")  # rest + the approach from above is over dz's 0.2
    ok = settings()
    poses[2, 2] = -2.5
    with pytest.raises(InputError, match=r"pose 3/3 \(#2\) reaches dz=-2.5, outside --stage-limits dz=-2:1"):
        ok.check_schedule(poses, lambda i: f"#{i}")
    # and says, all at once, the limits that hold the whole schedule and its approach points (a walkthrough took
    # three tries, one limit each)
    said = pytest.raises(InputError, ok.check_schedule, poses, lambda i: f"#{i}").value.args[0]
    assert said.endswith("; the schedule with its approach points spans dx=-0.3:1,dy=-0.3:0,dz=-2.5:0.3: give "
                         "limits at least that wide where the machine allows"), said
    settings(limits="dx=-0.3:1,dy=-0.3:0,dz=-2.5:0.3").check_schedule(poses, lambda i: f"#{i}")  # and they do
    poses[2] = [0, 0, -1, 3, 0]
    with pytest.raises(InputError, match="has thx != 0: the stage moves dx,dy,dz only"):
        ok.check_schedule(poses, lambda i: f"#{i}")
    poses[2] = [0, 1, -1, 0, 0]
    with pytest.raises(InputError, match="has dy != 0: --stage-axes X=dx,Z=dz moves no machine axis along it"):
        settings(axes="X=dx,Z=dz").check_schedule(poses, lambda i: f"#{i}")


def test_every_pose_is_approached_from_the_same_side():
    class Recorder:
        flavor = "grbl"

        def __init__(self):
            self.sent = []

        def move(self, target, feed, start=None):
            self.sent.append(dict(target))
            return np.array([target["X"], target["Y"], target["Z"]])

    rec = Recorder()
    st = PoseStage(rec, settings(), {"X": 10.0, "Y": 20.0, "Z": 30.0})
    st.move_to([0, 0, 0, 0, 0])  # backlash state unknown: through the approach point
    assert rec.sent == [{"X": 9.7, "Y": 19.7, "Z": 30.3}, {"X": 10.0, "Y": 20.0, "Z": 30.0}]
    rec.sent.clear()
    st.move_to([1, 0.5, -1, 0, 0])  # +dx, +dy, -dz: all the approach's way: one move
    assert rec.sent == [{"X": 11.0, "Y": 20.5, "Z": 29.0}]
    rec.sent.clear()
    st.move_to([0.5, 0.5, -1.5, 0, 0])  # dx goes back: only dx goes round by its approach point
    assert rec.sent == [{"X": 10.2, "Y": 20.5, "Z": 28.5}, {"X": 10.5, "Y": 20.5, "Z": 28.5}]
    rec.sent.clear()
    st.move_to([0.5, 0.5, -1.0, 0, 0])  # dz lifts: from above again
    assert rec.sent == [{"X": 10.5, "Y": 20.5, "Z": 29.3}, {"X": 10.5, "Y": 20.5, "Z": 29.0}]
    rec.sent.clear()
    st.move_to([0.5, 0.5, -1.0, 0, 0])  # the same pose again: out to the approach point and back (a fresh landing)
    assert rec.sent == [{"X": 10.2, "Y": 20.2, "Z": 29.3}, {"X": 10.5, "Y": 20.5, "Z": 29.0}]
    st.settings.approach = np.zeros(3)  # approach off: straight there
    rec.sent.clear()
    st.move_to([0, 0, 0, 0, 0])
    assert rec.sent == [{"X": 10.0, "Y": 20.0, "Z": 30.0}]


@pytest.mark.parametrize("flavor", ["marlin", "grbl"])
def test_a_repeat_lands_anew_on_every_axis_and_small_jogs_add_up(flavor):
    """Marlin reports its position to 0.01 mm: the stage counts from where it sent each move (0.001 mm)."""
    with server(flavor) as srv:
        c = connect(srv)
        c.setup()
        st = PoseStage(c, settings(), {"X": 2.015, "Y": -1.985, "Z": -6.015})
        st.move_to([0, 0, 0, 0, 0])
        n = len(srv.ctrl.lines)
        st.move_to([0, 0, 0, 0, 0])
        sent = [ln.rsplit(" F", 1)[0] for ln in srv.ctrl.lines[n:] if ln.startswith("G1")]
        assert sent == ["G1 X1.715 Y-2.285 Z-5.715", "G1 X2.015 Y-1.985 Z-6.015"]
        jogger = PoseStage(c, settings(), {})
        jogger.position = c.position()  # as jog_to_zero starts: the first step counts from the report
        jogger.jog("dz", -0.004)
        before = srv.ctrl.machine().copy()
        for _ in range(4):
            jogger.jog("dz", -0.004)
        srv.ctrl.wait_idle()
        assert srv.ctrl.machine()[2] - before[2] == pytest.approx(-0.016, abs=1e-9)
        c.close()


def test_the_simulated_rig_has_backlash_and_repeatability():
    sink = Sink()
    rig = SimRig(sink, M_RIG, contact=CONTACT, start=(12, 8, 6), backlash=0.1, repeatability=0.0)
    rig.move([12, 8, 3])  # down, 1 mm into the skin: the tool lags 0.05 above the carriage
    np.testing.assert_allclose(rig.displacement(), [0, 0, -0.95])
    np.testing.assert_allclose(sink.pose, [0.02 * -0.95, 0, 0.92 * -0.95, 0, 0])  # M applied
    rig.move([12, 8, 3.08])  # reversal inside the dead band: nothing moves
    np.testing.assert_allclose(rig.displacement(), [0, 0, -0.95])
    rig.move([12, 8, 3.2])  # out of it: the tool follows 0.05 below the carriage
    np.testing.assert_allclose(rig.displacement(), [0, 0, -0.85])
    rig.move([12, 8, 6])  # lifted off: the magnet rests
    np.testing.assert_array_equal(sink.pose, np.zeros(5))
    rep = SimRig(None, contact=CONTACT, start=(0, 0, 0), backlash=0.0, repeatability=0.003, seed=2)
    ends = []
    for _ in range(400):
        rep.move([0, 0, 0])
        ends.append(rep.tool.copy())
    assert 0.0025 < np.std(ends) < 0.0035


@pytest.mark.parametrize("axes", ["X=dx,Y=dy,Z=dz", "X=-dx,Y=-dy,Z=dz", "X=dy,Y=-dx,Z=-dz"])
def test_the_simulated_rigs_printed_contact_is_the_zero_the_documented_jog_finds(axes):
    rig = SimRig(None, contact=CONTACT, start=(5, 5, 5), axes=axes, backlash=0.1, repeatability=0.0)
    at = rig.carriage_at_contact()
    approach = np.array([-0.3, -0.3, 0.3])
    delta = np.zeros(3)
    for m, spec in zip("XYZ", [a.split("=")[1] for a in axes.split(",")]):
        s, p = (-1.0, spec[1:]) if spec.startswith("-") else (1.0, spec)
        delta["XYZ".index(m)] = s * approach[["dx", "dy", "dz"].index(p)]
    rig.move(at + delta)  # the approach point, then the zero: each axis's last move from its approach side
    rig.move(at)
    np.testing.assert_allclose(rig.displacement(), 0.0, atol=1e-12)
    rig.move(at - delta)  # from the other side: the zero would be off by the whole backlash on every axis
    rig.move(at)
    np.testing.assert_allclose(np.abs(rig.displacement()), 0.1, atol=1e-12)


def test_a_zero_set_above_first_contact_lifts_the_rows_at_first_contact_off_the_skin(tmp_path):
    """simulated_stage_capture's zero_off: the zero a hand sets, off the one the documented jog finds. Set 0.1 mm
    high, the rows labelled at first contact stand past the skin's adhesion and read the magnet at rest
    (fitgen.fitting.capturecheck.reads_at_rest); pressed 0.2 mm they still press; set where the jog finds it, none
    reads at rest."""
    from fitgen.fitting.capturecheck import reads_at_rest
    from fitgen.fitting.schedule import write_schedule
    from fitgen.physics.sensor import load_sensor
    from host.stagesim import simulated_stage_capture

    poses = np.array([[0, 0, 0.2, 0, 0]] * 2 + [[1, 0, 0, 0, 0], [0, 1, 0, 0, 0], [1, 1, -0.2, 0, 0],
                                                 [-1, 0, -0.2, 0, 0]], dtype=float)
    plan = tmp_path / "s.csv"
    write_schedule(plan, poses, ("dx", "dy", "dz"), {"samples_per_row": 4})
    unit = load_sensor("paper").with_transfer("gmr")
    for off, at_rest in ((0.0, [False] * 4), (0.1, [True, True, False, False])):
        cap = tmp_path / f"c{off:g}.csv"
        simulated_stage_capture(unit, load_schedule(plan), cap, samples=4, repeatability=0.0, zero_off=(0, 0, off))
        ds = load_dataset(cap)
        noise = np.full(8, 0.0005 / 2)
        assert reads_at_rest(ds.inputs, ds.poses(), noise)[2:].tolist() == at_rest, off


# --- the protocol ----------------------------------------------------------------------------------------


@pytest.mark.parametrize("flavor", ["grbl", "marlin"])
def test_driver_detects_the_flavor_moves_and_reports_position(flavor):
    with server(flavor) as srv:
        c = connect(srv)
        try:
            assert c.flavor == flavor and not c.banner_seen  # no banner on this connection: detected by its answers
            assert ("Grbl 1.1h" if flavor == "grbl" else "Marlin 2.1.2.1") in c.firmware
            c.setup()
            pos = c.move({"X": 1.25, "Y": -0.5, "Z": -2.0}, FEED, start=np.zeros(3))
            np.testing.assert_allclose(pos, [1.25, -0.5, -2.0], atol=0.003)
            np.testing.assert_allclose(srv.ctrl.rig.carriage, np.array(START) + [1.25, -0.5, -2.0])
            lines = srv.ctrl.lines
            assert "G90" in lines and "G21" in lines and "G1 X1.250 Y-0.500 Z-2.000 F6000" in lines
            assert ("M400" in lines) == (flavor == "marlin") and ("G4 P0" in lines) == (flavor == "grbl")
        finally:
            c.close()


@pytest.mark.parametrize("flavor,named", [("marlin", "auto"), ("marlin", "marlin"), ("grbl", "auto"),
                                          ("grbl", "grbl")])
def test_connecting_while_a_stopped_runs_long_move_ends(flavor, named):
    """A run stopped (Ctrl-C) after sending a slow move and its wait: the next run's connect waits for the end
    (Marlin's keepalive extends the wait; a GRBL answers its real-time status, named or detected), longer than
    --stage-timeout."""
    with server(flavor, busy_interval=0.3) as srv:
        c = connect(srv)
        c.setup()
        c.command("G1 X0.05 F1")  # 3 s
        c.send("M400" if flavor == "marlin" else "G4 P0")
        c.close()
        c = GcodeController.open(srv.url, timeout=1.0)
        c.connect(named, boot_wait=0.1)
        assert c.flavor == flavor and c.firmware
        c.close()


def test_a_banner_on_connect_means_a_reset_and_names_the_flavor():
    with server("marlin") as srv:
        c = connect_after_reset(srv)
        assert c.flavor == "marlin" and c.banner_seen and c.firmware.startswith("Marlin")
        c.close()
        with pytest.raises(InputError, match="--stage-flavor grbl, but the controller is marlin"):
            GcodeController.open(srv.url, timeout=1).connect("grbl", boot_wait=0.1)


GRBLHAL_WELCOME = "GrblHAL 1.1f ['$' or '$HELP' for help]"  # grblHAL's start-up line (grblHAL/core, grbl.h)


def test_grblhals_start_up_line_is_a_reset_too():
    """grblHAL (Teensy, STM32 and ESP32 boards) names itself GrblHAL: its start-up line on connect, or in the
    middle of a capture, is a reset as GRBL's is; taken for a harmless line, a reset between moves would let the
    capture go on in coordinates that restarted at 0."""
    with server("grbl", transport=PtyServer) as srv:  # a pty keeps what is said before the host listens
        srv.ctrl.welcome = GRBLHAL_WELCOME
        c = connect_after_reset(srv)
        try:
            assert c.flavor == "grbl" and c.banner_seen
            c.setup()
            c.move({"X": 1.0}, FEED, start=np.zeros(3))
            srv.ctrl.inject("reset", 1)
            with pytest.raises(StageError, match="reset itself") as err:
                c.move({"X": 2.0}, FEED)
            assert err.value.lost
        finally:
            c.close()


def test_grbl_0_9_reports_and_settings_are_read():
    """GRBL 0.9 (older CNC 3018 and laser boards) reports <Idle,MPos:x,y,z,WPos:x,y,z> and comments its
    settings ($110=500.000 (x max rate, mm/min)): the position and the top rates are read as 1.1's."""
    class Grbl09(SimController):
        def _status(self, now):
            state = "Run" if self.queue else "Idle"
            m = np.round((self._where(now) - self.offset) * self.steps_per_mm) / self.steps_per_mm
            self._say(f"<{state},MPos:{m[0]:.3f},{m[1]:.3f},{m[2]:.3f},WPos:{m[0]:.3f},{m[1]:.3f},{m[2]:.3f},"
                      f"Buf:{len(self.queue)},RX:0,Lim:000>")  # $10=31: every field 0.9 has

        def _grbl_system(self, text, now):
            if text == "$$":
                self._say("$100=400.000 (x, step/mm)", "$110=500.000 (x max rate, mm/min)",
                          "$111=600.000 (y max rate, mm/min)", "$112=300.000 (z max rate, mm/min)", "ok")
            elif text == "$I":
                self._say("[0.9j.20160726:]", "ok")
            else:
                super()._grbl_system(text, now)

    with _controller(Grbl09, "grbl") as srv:
        c = connect(srv)
        try:
            assert c.flavor == "grbl"
            c.setup()
            np.testing.assert_allclose(c.max_rates, [500.0, 600.0, 300.0])
            np.testing.assert_allclose(c.position(), [0.0, 0.0, 0.0])
            np.testing.assert_allclose(c.move({"X": 0.5, "Z": -1.0}, FEED), [0.5, 0.0, -1.0])
            np.testing.assert_allclose(c.position(), [0.5, 0.0, -1.0])
            np.testing.assert_allclose(srv.ctrl.machine(), [0.5, 0.0, -1.0])
        finally:
            c.close()


def test_a_grbl_reporting_inches_or_left_in_g55_is_moved_in_mm_in_g54():
    """$13=1 makes GRBL report positions and offsets in inches whatever G21 says, and a G55 left selected (a $N
    start-up line, or a port that does not reset the board) puts every target off by its offset: a 'dz -0.1' jog
    had moved the machine tens of mm (grbl/print.c printFloat_CoordValue; report.c's WCO, every 10th report)."""
    class Inches(SimController):
        def _status(self, now):
            m = (self._where(now) - self.offset) / 25.4
            self._say(f"<{'Run' if self.queue else 'Idle'}|MPos:{m[0]:.4f},{m[1]:.4f},{m[2]:.4f}|FS:0,0>")

        def _grbl_system(self, text, now):
            if text == "$$":
                self._say("$13=1", "$110=12000.000", "$111=12000.000", "$112=12000.000", "ok")
            elif text == "$#":
                self._say("[G54:0.0000,0.0000,0.0000]", "[G92:0.0000,0.0000,0.0000]", "[TLO:0.0000]", "ok")
            else:
                super()._grbl_system(text, now)

    class G55(SimController):
        def _power_on(self):
            super()._power_on()
            self.system, self.reports = np.array([-30.0, -20.0, -25.0]), 0

        def _execute(self, line, now):
            if line.strip() != "G54":
                return super()._execute(line, now)
            self.system = np.zeros(3)
            self._say("ok")
            return True

        def _g1(self, args, now):  # a target in the selected system: the machine's, less its offset
            super()._g1({k: v + self.system["XYZ".index(k)] if k in "XYZ" else v for k, v in args.items()}, now)

        def _status(self, now):
            m, w = self._where(now) - self.offset, self.system
            wco = f"|WCO:{w[0]:.3f},{w[1]:.3f},{w[2]:.3f}" if self.reports % 10 == 0 else ""
            self.reports += 1
            self._say(f"<{'Run' if self.queue else 'Idle'}|MPos:{m[0]:.3f},{m[1]:.3f},{m[2]:.3f}|FS:0,0{wco}>")

    for cls in (Inches, G55):
        with _controller(cls, "grbl") as srv:
            c = connect(srv)
            try:
                c.setup()
                np.testing.assert_allclose(c.position(), [0.0, 0.0, 0.0], atol=0.003)
                np.testing.assert_allclose(c.move({"X": 0.5, "Z": -1.0}, FEED), [0.5, 0.0, -1.0])
                np.testing.assert_allclose(srv.ctrl.machine(), [0.5, 0.0, -1.0], atol=1e-9)
                np.testing.assert_allclose(c.position(), [0.5, 0.0, -1.0], atol=0.003)
            finally:
                c.close()


def test_marlins_boot_screen_and_a_banner_after_the_boot_wait_are_said_as_such():
    """Marlin prints 'start', then stays silent through its boot screens (4 s and more) before it serves lines: G21
    had timed out at the answer's limit, which --stage-boot-wait could not change. A banner that comes after the
    boot wait had been called a reset during a status query. Marlin 2 names itself without echo:."""
    class SlowBoot(SimController):
        def reset(self):
            super().reset()
            self._out = bytearray(self._out.replace(b"echo:Marlin", b"Marlin"))
            self.booting = self.clock() + 3.0

        def step(self, now=None):
            if self.clock() < getattr(self, "booting", 0.0):
                return
            super().step(now)

    with _controller(SlowBoot, "marlin") as srv:
        c = connect_after_reset(srv)
        try:
            assert c.flavor == "marlin" and c.firmware == f"Marlin {MARLIN_VERSION}"
            c.setup()  # answered after the boot screen, past the 2 s the answers have
            assert c.position().tolist() == [0.0, 0.0, 0.0]
        finally:
            c.close()
    with _controller(SimController, "marlin") as srv:
        c = GcodeController.open(srv.url, timeout=2.0)
        try:
            threading.Timer(0.4, srv.ctrl.reset).start()
            with pytest.raises(StageError) as err:
                c.connect(boot_wait=0.1)
            assert str(err.value).endswith("the controller printed its start-up banner only after --stage-boot-wait "
                                           "0.1 s had passed (a board that resets when its port opens, booting "
                                           "slowly): give --stage-boot-wait 2.2"), str(err.value)
        finally:
            c.close()


@pytest.mark.parametrize("state, said", [("Hold:0", "holds its moves (Hold:0: a feed hold) during G1 X0.500 F6000; "
                                          "resume it with cycle start (its button, or '~')"),
                                         ("Door:1", "holds its moves (Door:1: its safety door is open) during G1 "
                                          "X0.500 F6000; close the door, then resume it with cycle start")])
def test_a_grbl_held_says_so_not_that_it_is_off(state, said):
    """A feed hold or an open safety door keeps G4 P0 waiting for ever: the line had asked whether the controller
    was on and its baud rate right."""
    class Held(SimController):
        held = False  # from the first move: the hold (or the door) stops it

        def _execute(self, line, now):
            if not (line.startswith("G1") or self.held and line.startswith("G4")):
                return super()._execute(line, now)
            self.held = True
            self.blocked_until = (lambda t: False, lambda: None)
            self._say("ok")
            return True

        def _status(self, now):
            if not self.held:
                return super()._status(now)
            m = self._where(now) - self.offset
            self._say(f"<{state}|MPos:{m[0]:.3f},{m[1]:.3f},{m[2]:.3f}|FS:0,0>")

    with _controller(Held, "grbl") as srv:
        c = connect(srv, timeout=0.5)
        try:
            c.setup()
            with pytest.raises(StageError) as err:
                c.move({"X": 0.5}, FEED, start=np.zeros(3))
            assert said in str(err.value), str(err.value)
        finally:
            c.close()


def test_grbl_after_reset_with_homing_is_in_alarm_until_homed():
    with server("grbl", homing_lock=True) as srv:
        c = connect(srv)
        try:
            assert c.alarm == "Alarm"
            with pytest.raises(StageError, match=r"error:9 \(G-code locked out during alarm or jog\)"):
                c.command("G90")
            c.home(timeout=5)
            assert not c.alarm and c.homed
            c.setup()
            np.testing.assert_allclose(c.position(), [0, 0, 0])
            # a CNC homes Z up, away from the sensor: the tool stands 20 mm above first contact, the magnet at rest
            assert srv.ctrl.rig.displacement()[2] == pytest.approx(GRBL_Z_SWITCH, abs=0.1)
            assert not srv.ctrl.rig.pose.any()
            # homed, GRBL's own soft limits hold: a target beyond its travel is ALARM:2
            with pytest.raises(StageError, match=r"ALARM:2 \(soft limit"):
                c.move({"X": -5.0}, FEED)
        finally:
            c.close()


def test_marlin_clamping_at_its_endstops_is_caught_by_the_position_check():
    with server("marlin") as srv:
        c = connect(srv)
        try:
            c.home(timeout=5)
            c.setup()
            with pytest.raises(StageError, match="reports X0: a move clamped by its own software endstops"):
                c.move({"X": -3.0}, FEED)  # Marlin says ok and goes to 0
        finally:
            c.close()


def test_every_wait_has_a_time_limit_and_marlin_busy_extends_it():
    with server("marlin", busy_interval=0.1) as srv:
        c = connect(srv)
        try:
            c.setup()
            c.timeout = 1.0  # tightened for the waits under test, after a set-up with room
            c.command("G1 X15 F300")  # 3 s of travel
            c.command("M400", timeout=1.0)  # answered late, but busy: processing every 0.1 s keeps it alive
            np.testing.assert_allclose(c.position(), [15, 0, 0])
            srv.ctrl.inject("silent", 1)
            with pytest.raises(StageError, match=r"no answer to 'G1 X0.000 F6000' within 1 s"):
                c.move({"X": 0.0}, FEED)
        finally:
            c.close()
    with server("grbl") as srv:
        c = connect(srv)
        try:
            c.setup()
            c.timeout = 1.0
            c.command("G1 X15 F300")
            with pytest.raises(StageError, match=r"no answer to 'G4 P0' within 1 s"):
                c.command("G4 P0")  # GRBL says nothing until the move ends
        finally:
            c.close()


def test_a_marlin_busy_for_ever_ends_the_wait(monkeypatch):
    """Marlin's busy: keepalive extends an answer's time limit, but not past a minute (QUEUED_WAIT, shortened
    here) or the command's own limit: a machine stuck, or paused for the user, is one StageError."""
    import host.gcode as G

    monkeypatch.setattr(G, "QUEUED_WAIT", 3.0)
    with server("marlin", busy_interval=0.1) as srv:
        c = connect(srv)
        try:
            c.setup()
            c.command("G1 X15 F1")  # 15 minutes of travel
            with pytest.raises(StageError, match=r"'M400' still busy \d+ s after it was sent .*stuck, or paused"):
                c.command("M400", timeout=1.0)
        finally:
            c.close()


def test_a_move_slowed_by_an_axis_top_rate_is_waited_for():
    """A feed above an axis's top rate (GRBL's $112, Marlin's M203: a printer's Z is often 5 mm/s) makes the
    controller slow the whole move; the driver reads the rates and waits for the move it will make."""
    for flavor in ("grbl", "marlin"):
        with server(flavor, max_feed=(12000.0, 12000.0, 300.0)) as srv:
            c = connect(srv, timeout=0.5)
            try:
                c.setup()
                np.testing.assert_allclose(c.max_rates, [12000, 12000, 300])
                assert c.move_time(np.array([0.0, 0.0, 5.0]), FEED) == pytest.approx(1.0)  # not 0.05 s
                assert c.move_time(np.array([3.0, 0.0, 4.0]), FEED) == pytest.approx(5 / (300 / 0.8) * 60)
                assert c.move_time(np.array([5.0, 0.0, 0.0]), FEED) == pytest.approx(0.05)
                c.move({"Z": 5.0}, FEED)  # 1 s: past the 0.5 s + 2 x 0.05 s a 6000 mm/min move would get
                np.testing.assert_allclose(c.position(), [0, 0, 5], atol=0.01)
            finally:
                c.close()


def _controller(cls, flavor):
    rig = SimRig(Sink(), None, contact=CONTACT, start=START, backlash=BACKLASH, repeatability=0.0, seed=1)
    return (SocketServer if flavor == "grbl" else PtyServer)(cls(flavor, rig))


def test_a_status_report_or_offset_it_cannot_read_is_one_stage_error():
    """Line noise can garble a GRBL report: a position with a letter in it, or two axes, is a StageError
    naming the line, not a traceback."""
    for bad in ("<Idle|MPos:1.0,x,3|FS:0,0>", "<Idle|MPos:1.0,2.0|FS:0,0>", "<Idle|MPos:1,2,nan|FS:0,0>"):
        class Garbled(SimController):
            def _status(self, now):
                self._say(bad)

        with _controller(Garbled, "grbl") as srv:
            c = GcodeController.open(srv.url, timeout=2.0)
            try:
                with pytest.raises(StageError, match=re.escape(f"fewer than 3 readable numbers: {bad!r}")):
                    c.connect("grbl", boot_wait=0.1)
            finally:
                c.close()

    class TwoAxisOffsets(SimController):
        def _grbl_system(self, text, now):
            self._say("[G54:0.000,0.000]", "ok") if text == "$#" else super()._grbl_system(text, now)

    with _controller(TwoAxisOffsets, "grbl") as srv:
        c = GcodeController.open(srv.url, timeout=2.0)
        try:
            with pytest.raises(StageError, match=re.escape("fewer than 3 readable numbers: '[G54:0.000,0.000]'")):
                c.connect("grbl", boot_wait=0.1)
        finally:
            c.close()


def test_a_firmware_speaking_marlins_dialect_under_another_name_is_taken_when_named():
    """Prusa's firmware says 'based on Marlin' in its M115 and is detected; Klipper does not, and is taken with
    --stage-flavor marlin, while auto refuses it in one line that says to name it."""
    for name, detected in [("Prusa-Firmware 3.13.3 based on Marlin FIRMWARE_URL:x", True),
                           ("Klipper FIRMWARE_VERSION:v0.12.0", False)]:
        class Other(SimController):
            def _execute(self, line, now):
                if line.strip() == "M115":
                    self._say(f"FIRMWARE_NAME:{name}", "ok")
                    return True
                return super()._execute(line, now)

        with _controller(Other, "marlin") as srv:
            c = GcodeController.open(srv.url, timeout=2.0)
            try:
                c.connect("marlin", boot_wait=0.1)
                assert c.flavor == "marlin" and c.firmware == name
                if detected:
                    c.connect("auto", boot_wait=0.1)
                    assert c.flavor == "marlin"
                else:
                    with pytest.raises(InputError, match="answered M115 with firmware Klipper .*give --stage-flavor "
                                                         "marlin"):
                        c.connect("auto", boot_wait=0.1)
            finally:
                c.close()


def _answering(answers):
    """A simulated Marlin whose answer to a line is ``answers(controller, line)`` where that gives one (a list of
    lines to say), its own otherwise."""
    class Answering(SimController):
        def _execute(self, line, now):
            said = answers(self, line.strip())
            if said is None:
                return super()._execute(line, now)
            self._say(*said)
            return True

    return Answering


@contextlib.contextmanager
def _set_up_marlin(cls):
    """A controller of class ``cls`` on a pty, connected as a Marlin and set up (mm, absolute)."""
    with _controller(cls, "marlin") as srv:
        c = GcodeController.open(srv.url, timeout=2.0)
        try:
            c.connect("marlin", boot_wait=0.1)
            c.setup()
            yield c
        finally:
            c.close()


@pytest.mark.parametrize("answer, message, lost", [
    ("!! Move out of range: 9.000 0.000 0.000 [0.000]", "with '!! Move out of range: 9.000", False),  # Klipper
    ("echo:Home XYZ first", r"refused 'G1 X9.000 F6000' until it is homed .*home it \(--home\)", False),  # Marlin
])
def test_a_refused_move_stops_on_the_controllers_words_not_on_a_clamped_move(answer, message, lost):
    """Klipper answers a command it refuses with '!! why' then ok, and a Marlin built with NO_MOTION_BEFORE_HOMING
    says 'echo:Home XYZ first' then ok: the capture stops on those words, not on the position check's 'clamped
    ... or lost steps' after them."""
    refusing = _answering(lambda ctrl, line: [answer, "ok"] if line.startswith("G1 X9") else None)
    with _set_up_marlin(refusing) as c:
        c.move({"X": 1.0}, FEED, start=np.zeros(3))
        with pytest.raises(StageError, match=message) as err:
            c.move({"X": 9.0}, FEED)
        assert bool(err.value.lost) == lost  # a refused move: the position still holds


def test_a_position_on_the_ok_line_is_read():
    """Smoothieware and Teacup answer M114 on the ok line itself ('ok C: X:1.2500 Y:0.0000 Z:-2.0000'), with no
    line before it: the position is read there."""
    def m114(ctrl, line):
        m = ctrl.machine()
        return [f"ok C: X:{m[0]:.4f} Y:{m[1]:.4f} Z:{m[2]:.4f} E:0.0000"] if line == "M114" else None

    with _set_up_marlin(_answering(m114)) as c:
        np.testing.assert_allclose(c.move({"X": 1.25, "Z": -2.0}, FEED), [1.25, 0.0, -2.0])
        np.testing.assert_allclose(c.position(), [1.25, 0.0, -2.0])


def test_reprapfirmwares_top_rates_are_in_mm_per_minute():
    """RepRapFirmware (Duet boards) names itself in M115 and prints its config.g for M503, where M203 is in mm/min,
    not Marlin's mm/s: a Z at 180 mm/min is read as 180, not 10,800, so a long Z move is waited for."""
    name = "RepRapFirmware for Duet 3 MB6HC FIRMWARE_VERSION: 3.4.5"

    def rrf(ctrl, line):
        if line == "M115":
            return [f"FIRMWARE_NAME: {name}", "ok"]
        if line == "M503":
            return ["; config.g", "M203 X6000.00 Y6000.00 Z180.00 E1200.00 ; maximum speeds (mm/min)", "ok"]
        return None

    with _set_up_marlin(_answering(rrf)) as c:
        assert c.firmware == name
        np.testing.assert_allclose(c.max_rates, [6000.0, 6000.0, 180.0])
        assert c.move_time(np.array([0.0, 0.0, 3.0]), 600.0) == pytest.approx(1.0)  # 3 mm at Z's 180 mm/min


def test_lines_are_length_checked():
    port = serial.serial_for_url("loop://", timeout=0.02)
    c = GcodeController(port, "loop", timeout=0.5)
    port.write(b"x" * 300 + b"\n")
    with pytest.raises(StageError, match="a line of 300 bytes from the controller"):
        c.read_line(1e18)
    port.write(b"y" * 300)
    with pytest.raises(StageError, match="without a line end"):
        c.read_line(1e18)
    with pytest.raises(InputError, match="not one ASCII line"):
        c.send("G1 X" + "1" * 80)


# --- capture through the stage ------------------------------------------------------------------------


def sim_rig_and_bus(sensor, flavor, *, M=M_RIG, seed=0, **kw):
    cmap = parse_spec(TWO_1115)
    clock = VirtualClock()
    bus = SimBus.for_channel_map(cmap, sensor, None, clock=clock, noise=0.0005, seed=seed)
    srv = server(flavor, bus.feed, M=M, repeatability=0.001, **kw)
    return srv, bus, AdcArray(bus, cmap, clock=clock), clock


# a rig whose indenter lifts the magnet as it shears it: 1.6 mm of dx raises it 0.064 mm while the tool is in contact
M_LIFT = np.array([[0.95, 0.0, 0.0], [0.0, 0.95, 0.0], [0.04, 0.0, 0.92]])


def unit_file(path, seed=5):
    from fitgen.physics.sensor import load_sensor
    from fitgen.physics.units import draw_unit, write_unit

    drawing = load_sensor("paper").with_transfer("gmr")
    write_unit(path, draw_unit(drawing, seed)[0], "paper", {"seed": seed})
    return load_sensor(path).with_transfer("gmr")


def composed(unit, M):
    """The unit as it reads behind a rig of map M: its own map after the rig's."""
    from dataclasses import replace

    return replace(unit, stage_map=unit.stage_map @ M)


def test_a_rig_that_lifts_the_magnet_in_contact_leaves_a_unit_in_contact(tmp_path):
    """The rig decides contact on the tool's height; a built unit's own off-skin test, which reads a label's dz,
    must not judge the magnet's displacement again (it read the magnet 0.08 mm up as a lifted tool: the rest)."""
    from host.simsensor import SensorFeed

    unit = unit_file(tmp_path / "u.toml")
    feed = SensorFeed(unit)
    feed.touching = True
    rig = SimRig(feed, M_LIFT, contact=CONTACT, start=START, backlash=0.0, repeatability=0.0)
    rest = readings(unit, np.zeros((1, 5)), adc_bits=0)[0]
    rig.move(np.array(CONTACT) + [2.0, 0.0, 0.0])  # sheared 2 mm at first contact
    assert rig.pose[2] > 0.05  # the magnet lifted past the off-skin height, the tool in contact
    want = readings(composed(unit, M_LIFT), [[2.0, 0.0, 0.0, 0.0, 0.0]], adc_bits=0)[0]
    np.testing.assert_allclose(feed.volts, want, rtol=0, atol=1e-12)
    assert np.abs(want - rest).max() > 0.05  # far from the rest it was read as before
    rig.move(np.array(CONTACT) + [2.0, 0.0, 0.3])  # the tool lifted off the skin: the magnet rests
    np.testing.assert_allclose(feed.volts, rest, rtol=0, atol=1e-12)


def test_a_capture_command_of_a_unit_follows_a_rig_that_lifts_the_magnet(tmp_path):
    """The same through `capture --simulate --sensor unit.toml --sim-pose-file`, the rig in another process's
    place (stage-sim's): every row reads the unit behind the rig's map, those sheared far at dz 0 included."""
    unit = unit_file(tmp_path / "u.toml")
    rows = [(dx, 0.0, dz) for dz in (0.0, -1.0) for dx in (-1.6, 0.0, 1.6)]
    sched = write_schedule(tmp_path / "s.csv", rows)
    out, posefile = tmp_path / "d.csv", tmp_path / "pose.txt"
    with server("grbl", PoseFile(posefile), M=M_LIFT, backlash=0.0) as srv:
        proc = run_host(*capture_args(sched, out, srv.url, posefile, "--sensor", str(tmp_path / "u.toml"),
                                      "--sim-noise", "0"), input=jog_lines(srv))
    assert proc.returncode == 0, proc.stderr
    got = np.array(data_rows(out))
    poses = np.zeros((len(rows), 5))
    poses[:, :3] = rows
    want = readings(composed(unit, M_LIFT), poses, adc_bits=0)
    assert np.abs(got[:, :8] - want).max() < 2e-4  # the ADC's LSB (0.125 mV)
    rest = readings(unit, np.zeros((1, 5)), adc_bits=0)[0]
    assert np.abs(got[2, :8] - rest).max() > 0.05  # dx 1.6 at dz 0, which read the rest before


@pytest.mark.parametrize("flavor", ["grbl", "marlin"])
def test_capture_through_the_stage_gives_the_magnet_poses_of_the_rig(sensor, tmp_path, flavor):
    sched = load_schedule(write_schedule(tmp_path / "s.csv", grid()))
    srv, bus, arr, clock = sim_rig_and_bus(sensor, flavor)
    out = tmp_path / "d.csv"
    with srv:
        c = connect(srv)
        try:
            c.setup()
            st = PoseStage(c, settings(), contact_zero(srv))
            res = capture(arr, sched, out, samples=8, set_pose=st.move_to, clock=clock,
                          meta={"stage": {"flavor": c.flavor}})
        finally:
            c.close()
    assert res.complete and res.captured == 27
    ds = load_dataset(out)
    np.testing.assert_array_equal(ds.targets, sched.values)
    want = readings(sensor, truth_poses(sched.poses), adc_bits=0)
    naive = readings(sensor, sched.poses, adc_bits=0)
    err = np.abs(ds.inputs - want).max()
    assert err < 1.2e-3  # averaged noise (0.18 mV rms), 1 um repeatability and the ADC's LSB
    assert np.abs(ds.inputs - naive).max() > 5 * err  # the rig is not the identity, and the data show it
    # fewer moves than two per pose: only reversals go round by the approach point
    assert 27 < sum(1 for ln in srv.ctrl.lines if ln.startswith("G1")) < 54
    meta = json.loads((tmp_path / "d.csv.meta.json").read_text())
    assert meta["samples_per_row"] == 8 and meta["noise_rows"] == 27 and meta["runs"] == 1
    ns, nr = np.array(meta["sample_noise"]), np.array(meta["row_noise"])
    assert np.all((ns > 0.0004) & (ns < 0.0006))  # the simulated 0.5 mV rms per sample
    np.testing.assert_allclose(nr, ns / np.sqrt(8), rtol=1e-12)
    assert meta["stage"] == {"flavor": flavor} and meta["duration_s"] >= 0


def test_a_controller_fault_mid_capture_keeps_the_rows(sensor, tmp_path):
    sched = load_schedule(write_schedule(tmp_path / "s.csv", grid()[:9]))
    for flavor, kind, message in [("grbl", "alarm", r"ALARM:1 \(hard limit triggered\)"),
                                  ("marlin", "error", "halted"),
                                  ("grbl", "error", r"error:33 \(invalid motion target\)"),
                                  ("marlin", "reset", "reset itself")]:
        srv, bus, arr, clock = sim_rig_and_bus(sensor, flavor)
        out = tmp_path / f"{flavor}-{kind}.csv"
        with srv:
            c = connect(srv)
            try:
                c.setup()
                st = PoseStage(c, settings(), contact_zero(srv))
                srv.ctrl.inject(kind, 5)  # the 5th G1 from now
                with pytest.raises(StageError, match=message):
                    capture(arr, sched, out, samples=2, set_pose=st.move_to, clock=clock)
            finally:
                c.close()
        rows = data_rows(out)
        # G1 1-2 set pose 1 (through its approach point), 3 pose 2, 4 pose 3; the 5th, to pose 4's approach
        # point (dx goes back), fails: the rows of poses 1-3, whole
        assert [r[8:] for r in rows] == [(-1.5, -1.0, 0.0), (0.0, -1.0, 0.0), (1.5, -1.0, 0.0)], (flavor, kind)


def test_the_zero_holds_until_a_reset_and_a_homed_zero_holds_after_one(tmp_path):
    axes = AxisMap.parse("X=dx,Y=dy,Z=dz")
    with server("grbl", homing_lock=True) as srv:
        c = connect(srv)
        c.home(timeout=5)
        c.setup()
        z = contact_zero(srv)
        assert choose_zero(c, None, axes, "here", rows=0, ask=None)[1] == "here"
        with pytest.raises(InputError, match="--zero here takes the zero only for a dataset without rows"):
            choose_zero(c, None, axes, "here", rows=3, ask=None)
        c.move({"X": 1.0, "Y": 2.0, "Z": -3.0}, FEED)  # homed, GRBL's Z counts down from its switch at the top
        state = StageState("grbl", str(axes), z, True, [1.0, 2.0, -3.0], [])
        assert choose_zero(c, state, axes, "ask", rows=3, ask=None) == (z, "kept from the last run")
        # a dataset without rows (deleted, begun anew): the zero left beside its name is no longer taken
        here = choose_zero(c, state, axes, "here", rows=0, ask=None)
        assert here == ({"X": 1.0, "Y": 2.0, "Z": -3.0}, "here") and here[0] != z
        said = []
        assert choose_zero(c, state, axes, "ask", rows=0, ask=lambda why: said.append(why) or z) == (z, "set by "
                                                                                                      "jogging")
        assert said == ["the stage has no zero yet"]
        c.close()
        srv.ctrl.reset()  # between runs
        c = connect(srv)
        assert c.alarm
        c.home(timeout=5)
        assert choose_zero(c, state, axes, "ask", rows=3, ask=None) == (z, "kept from the last run")
        c.close()
    with server("marlin") as srv:
        c = connect(srv)
        c.setup()
        c.move({"X": 1.0, "Y": 2.0, "Z": 3.0}, FEED)
        state = StageState("marlin", str(axes), {"X": 2.0, "Y": -2.0, "Z": -6.0}, False, [1.0, 2.0, 3.0], [])
        assert choose_zero(c, state, axes, "ask", rows=3, ask=None)[1] == "kept from the last run"
        c.close()
        c = connect_after_reset(srv)
        asked = []
        zero, how = choose_zero(c, state, axes, "ask", rows=3, ask=lambda why: asked.append(why) or {"X": 0.0})
        assert how == "set by jogging" and asked == ["the controller was reset (it printed its start-up banner on "
                                                     "connect)"]
        # the same numbers given again after the reset: a machine not homed counts from where it woke, so they are
        # a zero set again, which the capture's record of its zeros keeps (a walkthrough found it folded into one)
        again = choose_zero(c, state, axes, dict(state.zero), rows=3, ask=None)
        assert again == (state.zero, "given again: the controller was reset (it printed its start-up banner on "
                                     "connect)")
        prior = {"stage": {"zeros_machine_mm": [dict(state.zero)]}}
        assert run_zeros(prior, state.zero, again[1]) == [state.zero, state.zero]
        assert run_zeros(prior, state.zero, "given") == [state.zero]  # given while it held: the same zero
        assert run_zeros(prior, state.zero) == [state.zero]
        c.close()
    with server("grbl") as srv:  # a reset nobody heard: the position tells
        c = connect(srv)
        c.setup()
        c.move({"X": 1.0, "Y": 2.0, "Z": 3.0}, FEED)
        c.close()
        srv.ctrl.reset()
        c = connect(srv)
        assert not c.banner_seen
        with pytest.raises(InputError, match="reports X0 Y0 Z0, not where the last run left it: it was reset"):
            choose_zero(c, StageState("grbl", str(axes), {"X": 2.0, "Y": -2.0, "Z": -6.0}, False, [1.0, 2.0, 3.0]),
                        axes, "ask", rows=3, ask=lambda why: None)
        c.close()


def test_jogging_to_the_zero(tmp_path):
    with server("grbl") as srv:
        c = connect(srv)
        c.setup()
        st = PoseStage(c, settings(), {})
        err = io.StringIO()
        zero = jog_to_zero(st, io.StringIO("dx 2\ndy -2\ndz -5\ndz 9\ndz nan\nwhat\ndz -1\n\n"), err, "cap")
        assert zero == pytest.approx({"X": 2.0, "Y": -2.0, "Z": -6.0})
        assert "a jog step is at most 5 mm" in err.getvalue() and "type AXIS STEP" in err.getvalue()
        assert "a jog step is a number of mm, got nan" in err.getvalue()
        assert jog_to_zero(st, io.StringIO("dz 1\nq\n"), io.StringIO(), "cap") is None
        # the prompt asks to end with a move down: a zero taken after one up is questioned once, then taken
        for typed, z in (("dz 0.5\n\ndz -0.25\n\n", -4.75), ("dz 0.5\n\n\n", -4.25)):  # from Z-5
            err = io.StringIO()
            zero = jog_to_zero(st, io.StringIO(typed), err, "cap")
            assert zero == pytest.approx({"X": 2.0, "Y": -2.0, "Z": z}), err.getvalue()
            assert err.getvalue().count("the last dz move was up") == 1, err.getvalue()
        c.close()


# --- the command line ------------------------------------------------------------------------------------


def host_cmd(*args):
    code = "import sys; from fitgen.app.host_cli import main; sys.argv[0] = 'tactile-host'; main()"
    return [sys.executable, "-c", code, *args]


def run_host(*args, input=""):
    return subprocess.run(host_cmd(*args), capture_output=True, text=True, input=input, timeout=300)


def capture_args(sched, out, url, posefile, *extra):
    return ["capture", "--poses", str(sched), "--adc", TWO_1115, "-o", str(out), "--simulate", "--samples", "8",
            "--sim-pose-file", str(posefile), "--stage", f"gcode:{url}", "--stage-limits", LIMITS,
            "--stage-feed", str(FEED), "--stage-boot-wait", "0.2", "--stage-timeout", "3", *extra]


def jog_lines(srv):
    """What a user types to reach first contact from where the stage stands, ending with a move down."""
    steps = np.array(CONTACT) - srv.ctrl.rig.carriage
    lines = [f"dx {steps[0]:.3f}", f"dy {steps[1]:.3f}"]
    z = steps[2] + 1.0
    while abs(z) > 4.9:
        lines.append(f"dz {np.sign(z) * 4.9:.3f}")
        z -= np.sign(z) * 4.9
    lines += [f"dz {z:.3f}", "dz -1", ""]
    return "\n".join(lines) + "\n"


def data_rows(path):
    return [tuple(float(x) for x in ln.split(",")) for ln in path.read_text().splitlines()[1:]]


@pytest.mark.parametrize("flavor, given, noted", [("marlin", False, True), ("marlin", True, False),
                                                 ("grbl", False, False)])
def test_a_printer_stage_on_a_schedule_for_a_cncs_rig_error_is_noted_before_the_zero(tmp_path, flavor, given, noted):
    """The docs' commands made a schedule for the default 0.01 mm rig error; on a printer (0.03 mm) identify then
    refused the capture as a stage looser than it allowed for, after every row was taken, with no word before."""
    sched = write_schedule(tmp_path / "s.csv", grid()[:2])
    (tmp_path / "s.csv.meta.json").write_text(json.dumps({"rig_error": 0.03 if given else 0.01,
                                                         "rig_error_given": given, "zero_error": 0.02}))
    out, posefile = tmp_path / "d.csv", tmp_path / "pose.txt"
    with server(flavor, PoseFile(posefile), M=M_RIG) as srv:
        zero = ",".join(f"{v:g}" for v in contact_zero(srv).values())
        proc = run_host(*capture_args(sched, out, srv.url, posefile, "--zero", zero))
    assert proc.returncode == 0, proc.stderr
    said = "note: the stage is a Marlin, a 3D printer's firmware, and the schedule was made for the default rig " \
           "error of 0.01 mm, a CNC's: a printer's is about 0.03 mm"
    assert (said in proc.stderr) == noted, proc.stderr
    if noted:
        assert "make the schedule with --rig-error 0.03 before capturing" in proc.stderr


def test_a_resume_through_another_stage_setting_or_none_is_refused_and_keeps_the_rows(tmp_path):
    """The meta's one stage record speaks for every row: a resume with no --stage dropped it (identify and check then
    lost the rows' zeros), and one with another axis map, approach or settle took rows in another frame, from
    another side or after another creep, then recorded its settings as every row's. Those are refused in one line;
    the limits, the feed and the port may change (they guard and pace the moves)."""
    sched = write_schedule(tmp_path / "s.csv", grid()[:6])
    out = tmp_path / "d.csv"
    (tmp_path / "pose.txt").write_text("")
    base = ["capture", "--poses", str(sched), "--adc", TWO_1115, "-o", str(out), "--simulate", "--samples", "2"]
    stop = run_host(*base, "--trigger", '[ "$TM_POSE_INDEX" -lt 3 ]')
    assert stop.returncode == 1 and len(data_rows(out)) == 2, stop.stderr
    rows = out.read_bytes()
    staged = ["--sim-pose-file", str(tmp_path / "pose.txt"), "--stage", "gcode:socket://127.0.0.1:9",
              "--stage-limits", LIMITS, "--stage-timeout", "1", "--stage-boot-wait", "0"]
    assert_one_line_error(run_host(*base, *staged), 2, "its 2 rows were captured without a stage, this run moves one "
                                                     "(--stage): its zero is not theirs")
    meta_file = tmp_path / "d.csv.meta.json"
    meta = json.loads(meta_file.read_text())
    meta["stage"] = {"kind": "gcode", **settings().describe(), "settle_s": 0.0}
    meta_file.write_text(json.dumps(meta))
    assert_one_line_error(run_host(*base), 2, "its 2 rows were captured through a stage (--stage), this run's is "
                                              "not: resume with --stage and the same settings")
    for extra, said in ((["--settle", "0.5"], "captured with --settle 0, this run's is 0.5"),
                        (["--stage-approach", "dx=0.3,dy=-0.3,dz=0.3"],
                         "captured with --stage-approach dx=-0.3,dy=-0.3,dz=0.3, this run's is dx=0.3,dy=-0.3,dz=0.3"),
                        (["--stage-axes", "X=dy,Y=dx,Z=dz"], "captured with --stage-axes X=dx,Y=dy,Z=dz, this run's")):
        assert_one_line_error(run_host(*base, *staged, *extra), 2, said)
    assert out.read_bytes() == rows
    # another feed and wider limits pass to the stage itself (none listens here)
    proc = run_host(*base, *staged[:5], "dx=-3:3,dy=-3:3,dz=-3:1", *staged[6:], "--stage-feed", "900")
    assert proc.returncode != 0 and "rows were captured" not in proc.stderr and "stage" in proc.stderr, proc.stderr
    assert out.read_bytes() == rows


@pytest.mark.parametrize("flavor", ["grbl", "marlin"])
def test_capture_command_killed_midway_and_reset_between_runs_keeps_every_row(sensor, tmp_path, flavor):
    rows = grid()
    sched = write_schedule(tmp_path / "s.csv", rows)
    out, posefile = tmp_path / "d.csv", tmp_path / "pose.txt"
    srv = server(flavor, PoseFile(posefile), M=M_RIG, repeatability=0.001)
    with srv:
        args = capture_args(sched, out, srv.url, posefile)

        def run_killed_at(k, stdin):
            """The controller kills the capture (SIGKILL, as a power cut would) when the k-th G1 from now arrives."""
            proc = subprocess.Popen(host_cmd(*args), stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                    stderr=subprocess.PIPE, text=True)
            seen = []

            def hook(line):
                if line.startswith("G1"):
                    seen.append(line)
                    if len(seen) == k:
                        os.kill(proc.pid, signal.SIGKILL)
            srv.ctrl.on_line = hook
            _, err = proc.communicate(stdin, timeout=300)
            srv.ctrl.on_line = None
            return proc.returncode, err

        rc, err = run_killed_at(20, jog_lines(srv))
        assert rc == -signal.SIGKILL, err
        first = data_rows(out)
        assert 2 <= len(first) < 27
        assert json.loads((tmp_path / "d.csv.stage.json").read_text())["pending"]  # killed mid-move
        # again, no reset: the zero holds (no prompt), and it goes on where it stopped
        rc, err = run_killed_at(12, "")
        assert rc == -signal.SIGKILL and "(kept from the last run)" in err, err
        second = data_rows(out)
        assert len(first) < len(second) < 27 and second[:len(first)] == first
        # the controller is reset between runs (standing still: GRBL reset in motion would be ALARM:3): the zero
        # must be set again, and without one nothing moves
        srv.ctrl.wait_idle()
        srv.ctrl.reset()
        moves = len(srv.ctrl.lines)
        proc = run_host(*args)
        assert proc.returncode == 2, proc.stderr
        assert "was reset" in proc.stderr and "set the zero:" in proc.stderr
        assert proc.stderr.strip().splitlines()[-1].startswith("tactile-host capture: error: ")
        assert "no zero was set" in proc.stderr.strip().splitlines()[-1]
        assert not any(ln.startswith("G1") for ln in srv.ctrl.lines[moves:])
        assert data_rows(out) == second
        proc = run_host(*args, input=jog_lines(srv))
        assert proc.returncode == 0, proc.stderr
        assert "(set by jogging)" in proc.stderr
        assert f"27/27 poses in {out} ({27 - len(second)} captured now" in proc.stderr
        # the last pose pressed 1 mm deep: a finished capture leaves the indenter above the skin (the limits' top,
        # dz 1), straight up from it, and the magnet at rest
        assert "the indenter lifted to dz +1 mm, off the skin" in proc.stderr
        srv.ctrl.wait_idle()
        lag = BACKLASH / 2  # dx and dy approached from below; dz just moved up, so it lags below too
        np.testing.assert_allclose(srv.ctrl.rig.displacement(), np.array([1.5, 1.0, 1.0]) - lag, atol=0.005)
        assert not srv.ctrl.rig.pose.any()
    got = data_rows(out)
    assert got[:len(second)] == second
    assert [r[8:] for r in got] == [tuple(map(float, r)) for r in rows]  # every pose once, in schedule order
    sched_poses = load_schedule(sched).poses
    want = readings(sensor, truth_poses(sched_poses), adc_bits=0)
    assert np.abs(np.array(got)[:, :8] - want).max() < 1.2e-3
    meta = json.loads((tmp_path / "d.csv.meta.json").read_text())
    assert meta["runs"] == 3 and meta["rows"] == 27  # the run without a zero captured nothing and 0 < meta["noise_rows"] <= 27
    assert meta["stage"]["flavor"] == flavor and meta["stage"]["axes"] == "X=dx,Y=dy,Z=dz"
    # the zero kept, then set again after the reset: two zeros, which identify and check say (tests/test_check.py)
    zeros = meta["stage"]["zeros_machine_mm"]
    assert len(zeros) == 2 and zeros[-1] == meta["stage"]["zero_machine_mm"] and zeros[0] != zeros[1]
    assert stage_zero(meta, "d.csv")["zeros"] == 2
    # the dataset fits, and the model becomes C: a model in volts
    model = fit_model(load_dataset(out))
    assert model.input_units == "V" and model.output_names == ("dx", "dy", "dz")
    assert "tm_estimate" in render_header(model)


def test_an_alarm_mid_run_says_to_resume_with_unlock_and_that_resumes(tmp_path):
    """GRBL stays in ALARM after one mid-run: the line had said "run the same command again to resume", which then
    failed on the ALARM at connect. It says to reset the controller (a limit's alarm halts GRBL until then) and run
    it with --home or --unlock, and that resumes every row."""
    sched = write_schedule(tmp_path / "s.csv", grid()[:9])
    out, posefile = tmp_path / "d.csv", tmp_path / "pose.txt"
    with server("grbl", PoseFile(posefile), M=M_RIG) as srv:
        zero = ",".join(f"{v:g}" for v in contact_zero(srv).values())
        args = capture_args(sched, out, srv.url, posefile, "--zero", zero)
        srv.ctrl.inject("alarm", 5)
        proc = run_host(*args, "--unlock")  # not in ALARM yet: it had said "unlocked the stage"
        last = proc.stderr.strip().splitlines()[-1]
        assert proc.returncode == 1 and "ALARM:1" in last, proc.stderr
        assert "the stage was not in ALARM: --unlock had nothing to unlock" in proc.stderr, proc.stderr
        assert "unlocked the stage" not in proc.stderr
        # a limit's alarm halts GRBL until it is reset: --unlock alone had been told, which found no one answering
        assert "GRBL halts after a limit until it is reset: press its reset button" in last, last
        assert last.endswith(f"the rows written so far are kept in {out}: reset the controller, then run the command "
                             "again with --home or --unlock to resume"), last
        kept = data_rows(out)
        assert 1 <= len(kept) < 9
        assert_one_line_error(run_host(*args, "--unlock"), 1, "(a GRBL halted by a limit alarm answers nothing until "
                                                              "it is reset)")
        srv.ctrl.reset()  # the reset button
        assert_one_line_error(run_host(*args), 1, "is in ALARM")  # the same command, as the line no longer says
        proc = run_host(*args, "--unlock")
        assert proc.returncode == 0 and "unlocked the stage ($X: out of ALARM" in proc.stderr, proc.stderr
        assert f"9/9 poses in {out} ({9 - len(kept)} captured now" in proc.stderr
    assert data_rows(out)[:len(kept)] == kept


@pytest.mark.parametrize("flavor", ["marlin", "grbl"])
def test_a_reset_the_run_saw_makes_the_next_run_ask_for_the_zero(tmp_path, flavor):
    """The controller resets as a G1 arrives and then runs that G1 in its fresh coordinates, so it reports the
    very target the state file holds as pending: the zero must not be kept for that."""
    sched = write_schedule(tmp_path / "s.csv", grid()[:9])
    out, posefile = tmp_path / "d.csv", tmp_path / "pose.txt"
    with server(flavor, PoseFile(posefile), M=M_RIG) as srv:
        args = capture_args(sched, out, srv.url, posefile)
        g1 = []

        def reset_at_the_sixth(line):
            if line.startswith("G1"):
                g1.append(line)
                if len(g1) == 6:
                    srv.ctrl.reset()
        srv.ctrl.on_line = reset_at_the_sixth
        zero = ",".join(f"{v:g}" for v in contact_zero(srv).values())
        proc = run_host(*args, "--zero", zero)
        srv.ctrl.on_line = None
        assert proc.returncode == 1 and ("reset itself" in proc.stderr or "ALARM" in proc.stderr), proc.stderr
        state = json.loads((tmp_path / "d.csv.stage.json").read_text())
        assert state["lost"] and state["pending"]
        before = data_rows(out)
        assert 1 <= len(before) < 9
        srv.ctrl.wait_idle()
        proc = run_host(*args, *(["--unlock"] if flavor == "grbl" else []))
        assert proc.returncode == 2 and "the last run lost the stage's position" in proc.stderr, proc.stderr
        assert "kept from the last run" not in proc.stderr and data_rows(out) == before


def test_capture_command_alarm_at_start_is_one_line_exit_1_and_home_clears_it(tmp_path):
    sched = write_schedule(tmp_path / "s.csv", grid()[:3])
    out, posefile = tmp_path / "d.csv", tmp_path / "pose.txt"
    with server("grbl", PoseFile(posefile), homing_lock=True) as srv:
        args = capture_args(sched, out, srv.url, posefile)
        proc = run_host(*args)
        assert_one_line_error(proc, 1, "is in ALARM (it starts so after a reset when homing is on): home it (--home; "
                                       "a zero taken on the homed machine holds) or unlock it (--unlock; the zero is "
                                       "then set again)")
        assert proc.stderr.strip().endswith("; nothing was written") and not out.exists()
        # homed: machine 0 is at the switches, GRBL's Z at the top of its travel (a CNC homes Z up), so first
        # contact is below it
        homed = np.array(CONTACT) - srv.ctrl.rig.switches
        assert homed[2] < 0 and srv.ctrl.rig.switches[2] == CONTACT[2] + GRBL_Z_SWITCH
        proc = run_host(*args, "--home", "--zero", ",".join(f"{v:g}" for v in homed))
        assert proc.returncode == 0, proc.stderr
        assert f"zero X{homed[0]:g} Y{homed[1]:g} Z{homed[2]:g} (given)" in proc.stderr
        assert srv.ctrl.lines.count("$H") == 1


def test_home_on_marlin_asks_first_and_a_no_moves_nothing(tmp_path):
    """Most printers home Z down to the bed, where the sensor sits: G28 is sent only on a yes."""
    sched = write_schedule(tmp_path / "s.csv", grid()[:2])
    out, posefile = tmp_path / "d.csv", tmp_path / "pose.txt"
    with server("marlin", PoseFile(posefile)) as srv:
        zero = ",".join(f"{v:g}" for v in CONTACT)  # homed: machine coordinates are the home frame's
        args = capture_args(sched, out, srv.url, posefile, "--home", "--zero", zero)
        for answer in ("", "n\n", "no\n"):
            proc = run_host(*args, input=answer)
            assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
            assert "is the indenter clear of the sensor? [y/N]" in proc.stderr
            assert "error: --home not confirmed: the stage was not moved" in proc.stderr.splitlines()[-1]
            assert not out.exists() and not any(ln.startswith(("G28", "G1")) for ln in srv.ctrl.lines)
        proc = run_host(*args, input="y\n")
        assert proc.returncode == 0, proc.stderr
        assert srv.ctrl.lines.count("G28") == 1 and len(data_rows(out)) == 2


def blocked_reading(proc, timeout: float = 10.0) -> None:
    """Wait until ``proc`` sleeps in a pipe read (its stdin's). A signal that lands between the prompt's flush and
    the read sets CPython's flag, and the read then blocks without looking at it (signals are checked on EINTR,
    and none comes): a Ctrl-C sent the instant a prompt shows was lost about once in 40 runs. A user's comes
    while the read waits. Without /proc the signal is sent at once."""
    import time

    wchan = f"/proc/{proc.pid}/wchan"
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        try:
            with open(wchan) as f:
                if "pipe_read" in f.read():
                    return
        except OSError:
            return
        time.sleep(0.01)


def test_ctrl_c_says_what_is_kept_nothing_before_the_first_row(tmp_path):
    """Ctrl-C at a new capture's zero prompt: no file was made, and the line says so rather than pointing at rows
    kept in a file that does not exist."""
    sched = write_schedule(tmp_path / "s.csv", grid()[:3])
    out, posefile = tmp_path / "d.csv", tmp_path / "pose.txt"
    with server("grbl", PoseFile(posefile)) as srv:
        proc = subprocess.Popen(host_cmd(*capture_args(sched, out, srv.url, posefile)), stdin=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True)
        try:
            said = [proc.stderr.readline() for _ in range(3)]
            assert "set the zero: jog the indenter" in said[1], said
            assert said[2] == "tactile-host capture: the carriage stands at machine X0 Y0 Z0\n", said  # a fresh sim
            prompt = ""
            while not prompt.endswith("]> "):  # the jog prompt, its line open, waiting on stdin
                prompt += proc.stderr.read(1)
                assert "jog [".startswith(prompt[:5]), prompt
            blocked_reading(proc)
            proc.send_signal(signal.SIGINT)
            assert proc.wait(timeout=30) == 130
            err = proc.stderr.read()
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
            proc.stdin.close()
            proc.stderr.close()
    assert err == "\ntactile-host capture: interrupted; nothing was written\n"  # the prompt's line ended first
    assert sorted(f.name for f in tmp_path.iterdir()) == ["pose.txt", "s.csv"]


@pytest.mark.parametrize("extra, message", [
    (["--stage", "gcode:socket://127.0.0.1:1"], "cannot open stage socket://127.0.0.1:1"),
    (["--stage", "serial:/dev/ttyUSB0"], "expected gcode:URL"),
    (["--stage", "gcode:/dev/null"], "/dev/null: Could not configure port: (25, 'Inappropriate ioctl for device'); it is "
                                     "a device but no serial port"),  # was pyserial's words alone
    (["--stage-axes", "X=dx,Y=dx"], "--stage-axes 'X=dx,Y=dx': dx appears twice"),
    (["--stage-limits", "dx=-1:1,dy=-2:2,dz=-2:1"], "pose 1/27 (dx=-1.5 dy=-1 dz=0) reaches dx=-1.5, outside"),
    (["--stage-limits", "dx=-2:2,dy=-2:2"], "--stage-limits: give a range for dz"),
    (["--stage-feed", "0"], "--stage-feed must be a finite number > 0"),
    (["--settle", "1e308"], "--settle must be at most 3600"),
    (["--stage-feed", "1e-9"], "--stage-feed is in mm/min, at least 1"),
    (["--stage-timeout", "1e12"], "--stage-timeout must be at most 3600"),
    (["--stage-baud", "2147483648"], "--stage-baud must be at most 12,000,000"),  # pyserial's OverflowError
    (["--trigger", "true"], "--stage and --trigger both set the poses"),
    (["--zero", "1,2"], "--zero '1,2': ask, here, or the machine coordinates"),
    (["--home", "--unlock"], "--home and --unlock both leave GRBL's ALARM: give one"),
])
def test_capture_command_bad_stage_input_is_one_line_exit_2_before_anything(tmp_path, extra, message):
    sched = write_schedule(tmp_path / "s.csv", grid())
    out, posefile = tmp_path / "d.csv", tmp_path / "pose.txt"
    with server("grbl", PoseFile(posefile)) as srv:
        args = capture_args(sched, out, srv.url, posefile)
        for opt in ("--stage", "--stage-limits"):
            if opt in extra:
                k = args.index(opt)
                del args[k:k + 2]
        proc = run_host(*args, *extra)
        assert_one_line_error(proc, 2, message)
        assert not out.exists() and not (tmp_path / "d.csv.stage.json").exists()
        assert not any(ln.startswith("G1") for ln in srv.ctrl.lines)


@pytest.mark.parametrize("beside", ["d.csv.meta.json", "d.csv.stage.json"])
def test_a_file_the_capture_writes_beside_its_output_is_checked_before_the_stage_moves(tmp_path, beside):
    """A folder where the capture's meta goes had failed the first row, after the stage was opened and its zero taken,
    leaving a header-only capture and a stage record."""
    sched = write_schedule(tmp_path / "s.csv", grid())
    out, posefile = tmp_path / "d.csv", tmp_path / "pose.txt"
    (tmp_path / beside).mkdir()
    with server("grbl", PoseFile(posefile)) as srv:
        proc = run_host(*capture_args(sched, out, srv.url, posefile))
    assert_one_line_error(proc, 2, f"cannot write {tmp_path / beside}: it is a folder")
    assert sorted(f.name for f in tmp_path.iterdir()) == sorted([beside, "pose.txt", "s.csv"])


def test_stage_options_need_stage(tmp_path):
    sched = write_schedule(tmp_path / "s.csv", grid()[:2])
    proc = run_host("capture", "--poses", str(sched), "--adc", TWO_1115, "-o", str(tmp_path / "d.csv"), "--simulate",
                    "--home")
    assert_one_line_error(proc, 2, "--home needs --stage gcode:URL")
    # a pose file no stage writes: every row read the sensor at rest under the stage's labels, exit 0
    proc = run_host(*capture_args(sched, tmp_path / "d.csv", "socket://127.0.0.1:9", tmp_path / "nope.txt",
                                  "--zero", "here"))
    assert_one_line_error(proc, 2, f"--sim-pose-file {tmp_path / 'nope.txt'}: no such file")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.csv"]


@pytest.mark.parametrize("args, message", [
    (["--port", "70000"], "cannot serve on 127.0.0.1:70000"),
    (["--port", "-5"], "cannot serve on 127.0.0.1:-5"),
    (["--pose-file", "{tmp}/missing/p.txt"], "missing"),
    (["--pose-file", "{tmp}"], "is a folder"),
    (["--axes", "foo"], "--axes 'foo': 'foo' is not MACHINE=[-]POSE"),
    # the port of a socket it does not open, and a map under which the magnet never moves: both were taken
    (["--pty", "--port", "5000"], "--port is the loopback socket's; with --pty there is none"),
    (["--map", "0,0,0;0,0,0;0,0,0"], "leaves the magnet unmoved along some direction of the stage (singular)"),
    (["--map", "1e308,0,0;0,1,0;0,0,1"], "three rows of three numbers within +-10"),  # had been served
    # served as they were: 'first contact at machine Xnan', numpy's warnings, a pose of 1e+308 in the pose file
    (["--start", "inf,0,0"], "--start 'inf,0,0': each must lie within +-2000 mm"),
    (["--contact", "nan,1,1"], "--contact 'nan,1,1': each must lie within +-2000 mm"),
    (["--start", "1e308,0,0"], "--start '1e308,0,0': each must lie within +-2000 mm"),
    (["--backlash", "1e308"], "--backlash must be 0..1 mm (a printer's is 0.01-0.1), got 1e+308"),
    (["--repeatability", "2"], "--repeatability must be 0..1 mm"),
    # a sensor past the travel no move reaches, a carriage past a stop: both had been served
    (["--contact", "250,8,4"], "--contact 250,8,4 lies outside the rig's travel (X 0..200, Y 0..200, Z 0..200 mm"),
    (["--start", "10,-5,10"], "--start 10,-5,10 lies outside the rig's travel"),
])
def test_stage_sim_bad_options_are_one_line(tmp_path, args, message):
    proc = subprocess.run(host_cmd("stage-sim", *[a.replace("{tmp}", str(tmp_path)) for a in args]),
                          capture_output=True, text=True, timeout=30)
    assert_one_line_error(proc, 2, message)
    assert list(tmp_path.iterdir()) == []


def test_stage_sim_command_prints_its_url_and_serves(tmp_path):
    proc = subprocess.Popen(host_cmd("stage-sim", "--flavor", "marlin", "--pose-file", str(tmp_path / "p.txt"),
                                     "--map", "1,0,0;0,1,0;0,0,0.9", "--repeatability", "0"),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        url = proc.stdout.readline().strip()
        assert url.startswith("socket://127.0.0.1:")
        c = GcodeController.open(url, timeout=3)
        c.connect(boot_wait=0.1)
        assert c.flavor == "marlin"
        c.setup()
        c.move({"X": 2.0, "Y": -2.0, "Z": -7.0}, FEED)  # 1 mm into the skin
        pose = [float(x) for x in (tmp_path / "p.txt").read_text().split(",")]
        assert pose[2] == pytest.approx(-0.9 * (1 - 0.015), abs=1e-9)  # the default 0.03 mm backlash, from above
        # the contact it prints, homed or not, is where the carriage stands when the indenter touches, each axis
        # come from the capture's approach side: a zero taken there is exact
        said = re.search(r"first contact at machine X(\S+) Y(\S+) Z(\S+) \(X(\S+) Y(\S+) Z(\S+) once homed;",
                         proc.stderr.readline())
        assert said, "stage-sim names the first contact before and after homing"
        unhomed, homed = np.array(said.groups()[:3], float), np.array(said.groups()[3:], float)
        assert unhomed == pytest.approx([2.015, -1.985, -6.015], abs=1e-9)  # the tool's 2,-2,-6 and half the backlash
        c.home(timeout=10)
        c.move({"X": homed[0], "Y": homed[1], "Z": homed[2] + 1.0}, FEED)  # from the switches: +X, +Y, then down
        c.move({"X": homed[0], "Y": homed[1], "Z": homed[2] - 1.0}, FEED)
        c.close()
        pose = [float(x) for x in (tmp_path / "p.txt").read_text().split(",")]
        assert pose[:3] == pytest.approx([0.0, 0.0, -0.9], abs=1e-9)
    finally:
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=10)
    assert proc.returncode == 0
    # stopped as it is meant to be, it says what it served (README: the commands that run until stopped)
    assert re.fullmatch(r"tactile-host stage-sim: stopped after \d+ lines received, 3 moves\n", proc.stderr.read())


def test_the_meta_pools_the_noise_over_the_runs_that_wrote_the_rows(sensor, tmp_path):
    sched = load_schedule(write_schedule(tmp_path / "s.csv", grid()[:10]))
    cmap = parse_spec(TWO_1115)
    clock = VirtualClock()
    bus = SimBus.for_channel_map(cmap, sensor, None, clock=clock, noise=0.001, seed=4)
    arr = AdcArray(bus, cmap, clock=clock)
    out = tmp_path / "d.csv"
    first = capture(arr, sched, out, samples=4, wait=lambda i, p: i < 6, set_pose=bus.set_pose, clock=clock)
    meta1 = json.loads((tmp_path / "d.csv.meta.json").read_text())
    assert first.captured == 6 and meta1["noise_rows"] == 6 and meta1["runs"] == 1
    bus.feed.noise = 0.002  # noisier in the second run: the pooled figure lies between
    second = capture(arr, sched, out, samples=16, set_pose=bus.set_pose, clock=clock)
    meta = json.loads((tmp_path / "d.csv.meta.json").read_text())
    assert second.captured == 4 and meta["noise_rows"] == 10 and meta["runs"] == 2
    ns1, ns = np.array(meta1["sample_noise"]), np.array(meta["sample_noise"])
    ns2 = np.sqrt((10 * ns ** 2 - 6 * ns1 ** 2) / 4)  # the second run's own rows, if pooled as said
    assert np.all((ns1 > 0.0007) & (ns1 < 0.0013)) and np.all((ns2 > 0.0014) & (ns2 < 0.0026))
    # rows of 4 and of 16 samples pooled: each row's noise is its own variance / its samples
    nr = np.array(meta["row_noise"])
    np.testing.assert_allclose(nr ** 2, (6 * ns1 ** 2 / 4 + 4 * ns2 ** 2 / 16) / 10)
    assert meta["duration_s"] > meta1["duration_s"] > 0  # the virtual clock's seconds: conversions take time


@pytest.mark.parametrize("edit, said", [
    (lambda d: d["zero"].pop("Z"), "its zero gives X,Y for the axes X,Y,Z"),
    (lambda d: d.__setitem__("zero", {}), "its zero gives no axis for the axes X,Y,Z"),
    (lambda d: d["zero"].__setitem__("X", float("nan")), "nan is no machine coordinate"),
    (lambda d: d["zero"].__setitem__("X", 1e6), "1000000.0 is no machine coordinate (a number within 2000 mm)"),
    (lambda d: d["zero"].__setitem__("X", 10 ** 400), "is no machine coordinate"),
    (lambda d: d.__setitem__("position", ["a", "b", "c"]), "'a' is no machine coordinate"),
    (lambda d: d.__setitem__("position", [1.0, 2.0]), "[1.0, 2.0] is no machine position"),
    (lambda d: d.__setitem__("pending", [[1.0]]), "[1.0] is no machine position"),
    (lambda d: d.__setitem__("pending", [{"Q": 1.0}]), "{'Q': 1.0} is no machine position")])
def test_a_damaged_stage_state_is_refused_in_one_line_before_anything_moves(tmp_path, edit, said):
    """The state file beside a capture gives the zero every move is sent from: a damaged one raised KeyError or
    IndexError (tracebacks), sent 'G1 Xnan', or drove the stage toward X 1,000,000 where --zero refuses past 2000
    mm. It is read whole, and refused naming the file."""
    out = tmp_path / "d.csv"
    StageState("grbl", "X=dx,Y=dy,Z=dz", {"X": 2.0, "Y": -2.0, "Z": -6.0}, False, [1.0, 2.0, 3.0],
               [{"X": 1.0, "Y": 2.0, "Z": 3.0}]).save(out)
    assert StageState.load(out).zero == {"X": 2.0, "Y": -2.0, "Z": -6.0}
    path = StageState.path_for(out)
    d = json.loads(path.read_text())
    edit(d)
    path.write_text(json.dumps(d))
    with pytest.raises(InputError) as err:
        StageState.load(out)
    assert str(err.value).startswith(f"{path}: not a stage state as tactile-host capture writes it (")
    assert said in str(err.value) and str(err.value).endswith("remove it to set the zero again")


def test_a_two_axis_stages_pending_target_tells_a_standstill_where_it_was_sent():
    """A stopped run's pending target names the mapped axes only (X and Z here): the check that the controller
    stands where the last run left it read all three and raised KeyError."""
    axes = AxisMap.parse("X=dx,Z=dz")
    with server("grbl") as srv:
        c = connect(srv)
        try:
            c.setup()
            c.move({"X": 1.0, "Z": -3.0}, FEED)
            state = StageState("grbl", str(axes), {"X": 2.0, "Z": -6.0}, False, None, [{"X": 1.0, "Z": -3.0}])
            assert zero_still_valid(state, c, axes, False) == ""
        finally:
            c.close()
