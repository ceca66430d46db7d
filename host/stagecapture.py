"""The stage side of a capture: ``--stage`` and its options checked against the schedule, the controller
connected, homed or unlocked, and the zero found (host.stage has the driver, the settings and the zero's rules)."""

from __future__ import annotations

import sys
from pathlib import Path

from fitgen.base.errors import InputError
from fitgen.base.parse import LONGEST_WAIT, parse_positive

from host.stage import (AxisMap, GcodeController, PoseStage, StageError, StageSettings, StageState, choose_zero,
                        jog_to_zero, parse_approach, parse_ranges, parse_zero, stage_url)
from host.capturefile import prior_meta
from host.gcode import QUEUED_WAIT
from host.gcodereplies import LEAVE_ALARM
from host.prompt import ask_line
from host.stagezero import KEPT
from host.stagesettings import APPROACH

STAGE_OPTIONS = ("stage_flavor", "stage_baud", "stage_axes", "stage_limits", "stage_feed", "stage_approach",
                 "stage_timeout", "stage_boot_wait", "home", "unlock", "zero")


def stage_settings(args, schedule):
    """--stage and its options, checked against the schedule before anything moves (None without --stage)."""
    given = [o for o in STAGE_OPTIONS if getattr(args, o) not in (None, False)]
    if args.stage is None:
        if given:
            raise InputError(f"--{given[0].replace('_', '-')} needs --stage gcode:URL")
        if args.sim_pose_file:
            raise InputError("--sim-pose-file needs --stage (the simulated sensor follows a simulated stage)")
        return None
    if args.trigger:
        raise InputError("--stage and --trigger both set the poses: give one")
    if args.home and args.unlock:
        raise InputError("--home and --unlock both leave GRBL's ALARM: give one (--home homes; --unlock trusts the "
                         "position GRBL believes)")
    if args.temperature is not None:
        raise InputError("--stage with --temperature is not supported: capture each temperature on its own "
                         "(--stage, a thermistor in --adc, an -o each), then fit the compensation from them with "
                         "tactile-host tempcomp-fit CAP1.csv CAP2.csv ... -o cap.tempcomp.json")
    if args.simulate and not args.sim_pose_file:
        raise InputError("--simulate with --stage needs --sim-pose-file FILE (the pose file tactile-host stage-sim "
                         "--pose-file FILE writes), or the simulated sensor would never move")
    if args.sim_pose_file and not args.simulate:
        raise InputError("--sim-pose-file needs --simulate")
    if args.sim_pose_file and not Path(args.sim_pose_file).is_file():  # stage-sim writes it from its start
        raise InputError(f"--sim-pose-file {args.sim_pose_file}: no such file; give the one `tactile-host stage-sim "
                         "--pose-file FILE` writes (it is there while the simulated stage runs), or the simulated "
                         "sensor would rest whatever the stage does")
    if args.stage_limits is None:
        raise InputError("--stage needs --stage-limits, e.g. dx=-3.5:3.5,dy=-3.5:3.5,dz=-3.5:0.5 (mm from the zero): "
                         "a move outside them is never sent")
    settings = StageSettings(AxisMap.parse(args.stage_axes or "X=dx,Y=dy,Z=dz"),
                             parse_ranges(args.stage_limits, "--stage-limits"),
                             feed=parse_feed(args.stage_feed or "600"),
                             approach=parse_approach(args.stage_approach or APPROACH)).check()
    settings.check_schedule(schedule.poses, schedule.describe)
    return {"url": stage_url(args.stage), "settings": settings, "zero": parse_zero(args.zero or "ask"),
            "baud": parse_baud(args.stage_baud or "115200"),
            "timeout": parse_positive(args.stage_timeout or "5", "--stage-timeout", most=LONGEST_WAIT),
            "boot_wait": parse_positive(args.stage_boot_wait or "2", "--stage-boot-wait", zero=True, most=LONGEST_WAIT)}


def same_stage(output, rows: int, opts: dict | None, settle: float) -> None:
    """Refuse to add rows to ``output``'s ``rows`` taken otherwise than they were: through a stage or not, or through
    one with another axis map, approach or settle time (where a row's pose lies, from which side it was reached, how
    long the skin crept before it was read), which the meta's one stage record speaks for. ``opts``:
    :func:`stage_settings`'s (None without --stage). The limits, the feed and the port may change: they guard and
    pace the moves, not where they end."""
    prior = prior_meta(output, rows)
    if not prior:
        return
    was = prior.get("stage") if isinstance(prior.get("stage"), dict) else None
    these = "its row was" if rows == 1 else f"its {rows} rows were"
    if was is not None and opts is None:
        raise InputError(f"output {output}: {these} captured through a stage (--stage), this run's is not: resume "
                         "with --stage and the same settings, or choose another -o")
    if was is None and opts is not None:
        raise InputError(f"output {output}: {these} captured without a stage, this run moves one (--stage): its zero "
                         "is not theirs; resume as they were taken, or choose another -o")
    if opts is None:
        return
    now = {**opts["settings"].describe(), "settle_s": settle}
    for key, option in (("axes", "--stage-axes"), ("approach_mm", "--stage-approach"), ("settle_s", "--settle")):
        if key in was and was[key] != now[key]:
            raise InputError(f"output {output}: {these} captured with {option} {_words(was[key])}, this run's is "
                             f"{_words(now[key])}: resume with the same, or choose another -o")


def _words(value) -> str:
    """A stage setting as its option is typed: 'dx=-0.3,dy=-0.3,dz=0.3', '0.5' (s)."""
    if isinstance(value, dict):
        return ",".join(f"{k}={v:g}" if isinstance(v, (int, float)) else f"{k}={v!r}" for k, v in value.items())
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return f"{value:g}"
    return value if isinstance(value, str) else repr(value)


MAX_BAUD = 12_000_000  # a USB serial chip's fastest (FTDI's FT232H); pyserial overflowed past 2^31 in a traceback


def parse_baud(text: str) -> int:
    """``--stage-baud``: a whole number of bits per second, at most MAX_BAUD; InputError otherwise."""
    baud = parse_positive(text, "--stage-baud", integer=True)
    if baud > MAX_BAUD:
        raise InputError(f"--stage-baud must be at most {MAX_BAUD:,} (a USB serial chip's fastest; printers and CNCs "
                         f"run at 115,200 or 250,000), got {text}")
    return baud


def parse_feed(text: str) -> float:
    """--stage-feed in mm/min, 1 to 100,000 (G-code has no exponents: F1e-09 is F1 and a word E)."""
    feed = parse_positive(text, "--stage-feed", most=1e5)
    if feed < 1:
        raise InputError(f"--stage-feed is in mm/min, at least 1, got {text}")
    return feed


def open_stage(args, opts, output, rows, prog: str, planned: dict | None = None):
    """Connect, home or unlock if asked, check the controller's state, and get the zero: (PoseStage, meta).
    ``opts``: :func:`stage_settings`'s; ``planned``: the stage the schedule was made for (its record); messages go
    to stderr after ``prog``."""
    ctrl = GcodeController.open(opts["url"], baud=opts["baud"], timeout=opts["timeout"])
    if sys.stderr.isatty():  # seconds pass before the controller's first answer (its start-up lines): shown
        print(f"{prog}: connecting to the stage at {opts['url']}", file=sys.stderr, flush=True)
    try:
        ctrl.connect(args.stage_flavor or "auto", boot_wait=opts["boot_wait"])
        if ctrl.flavor == "marlin" and planned is not None and planned.get("rig_error_given") is False:
            print(f"{prog}: note: the stage is a Marlin, a 3D printer's firmware, and the schedule was made for the "
                  f"default rig error of {planned.get('rig_error', 0.01):g} mm, a CNC's: a printer's is about 0.03 mm, "
                  "which identify then refuses as a stage looser than the capture allowed for (and the rows in "
                  "contact may lift off the skin): make the schedule with --rig-error 0.03 before capturing",
                  file=sys.stderr, flush=True)
        if args.home:
            if ctrl.flavor == "marlin":  # most printers home Z down to the bed, where the sensor sits
                answer = ask_line(sys.stdin, sys.stderr, f"{prog}: this Marlin printer will home (G28), which on most "
                                  "printers drives Z down to the bed: is the indenter clear of the sensor? [y/N] ")
                if (answer or "").strip().lower() not in ("y", "yes"):
                    raise InputError("--home not confirmed: the stage was not moved; leave --home out on a printer "
                                     "that homes Z down with the sensor mounted (the zero is then asked for)")
            print(f"{prog}: homing the stage", file=sys.stderr, flush=True)
            ctrl.home(timeout=max(120.0, opts["timeout"]))
        elif args.unlock:
            locked = bool(ctrl.alarm)
            ctrl.unlock()
            print(f"{prog}: unlocked the stage ($X: out of ALARM without homing, its position taken as it stands)"
                  if locked else f"{prog}: the stage was not in ALARM: --unlock had nothing to unlock",
                  file=sys.stderr, flush=True)
        if ctrl.alarm:
            raise StageError(f"{ctrl.name}: the GRBL controller is in ALARM (it starts so after a reset when homing "
                             "is on): home it (--home; a zero taken on the homed machine holds) or unlock it "
                             "(--unlock; the zero is then set again)",
                             lost="the controller was in ALARM when the capture connected",
                             resume=LEAVE_ALARM)
        ctrl.setup()
        # moves a killed run left queued end first: the position that tells a reset must be a standstill's
        ctrl.wait_idle(QUEUED_WAIT + opts["timeout"], "the moves already queued")
        settings = opts["settings"]
        state = StageState.load(output)
        jogger = PoseStage(ctrl, settings, {})

        def ask(reason):
            print(f"{prog}: {reason}", file=sys.stderr)
            return jog_to_zero(jogger, sys.stdin, sys.stderr, prog)

        zero, how = choose_zero(ctrl, state, settings.axes, opts["zero"], rows=rows, ask=ask)
        if how == KEPT and opts["zero"] == "here":
            print(f"{prog}: note: --zero here not taken: the zero this dataset's rows were taken from still holds, "
                  "and is kept", file=sys.stderr)
        homed = ctrl.homed or (how == KEPT and state.homed)
        state = StageState(ctrl.flavor, str(settings.axes), zero, homed, None, [])
        state.save(output)
        stage = PoseStage(ctrl, settings, zero)

        def on_move(targets):
            if targets is None:
                state.position, state.pending = [float(x) for x in stage.position], []
            else:
                state.pending = [{k: float(v) for k, v in t.items()} for t in targets]
            state.save(output)

        stage.on_move = on_move
        z = " ".join(f"{m}{v:g}" for m, v in zero.items())
        print(f"{prog}: stage {ctrl.flavor} ({ctrl.firmware or 'firmware unnamed'}) at {opts['url']}, zero {z} "
              f"({how})", file=sys.stderr, flush=True)
        meta = {"kind": "gcode", "url": opts["url"], "flavor": ctrl.flavor, "firmware": ctrl.firmware,
                "zero_machine_mm": zero, "zero_homed": homed, "zero_source": how, **settings.describe()}
        return stage, meta
    except BaseException:
        ctrl.close()
        raise
