"""A ``capture`` run at one temperature: the options checked, the bus (or simulated bus) and the stage opened,
every pose of the schedule set at Enter, by a trigger command, by a G-code stage or by the simulation and
captured (host.capture), then the bus and the stage closed; a fault or Ctrl-C keeps the rows written."""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path

from fitgen.base.errors import InputError
from fitgen.base.fileio import write_target
from fitgen.base.parse import LONGEST_WAIT, MAX_NOISE, MAX_ROW_SAMPLES, MAX_TRIES, parse_positive
from fitgen.base.progress import Progress
from fitgen.physics.dataset import thermistor_degc
from fitgen.physics.pose import check_above_board
from fitgen.physics.sensor import load_sensor
from fitgen.physics.simulate import recorded_spec

from host.adc import AdcArray, DeviceSilent, RetryPolicy
from host.capture import SAMPLES, SpreadTooLarge, capture, designed_samples, load_schedule, simulated_sensor
from host.capturefile import check_resume, output_lock, prepare_output, prior_meta
from host.posewait import TRIGGER_TIMEOUT, TriggerFailed, enter_waiter, trigger_waiter
from host.motion import parse_drift
from host.session import adc_defaults, channel_map_from_args, open_bus_from_args, refuse_alone
from host.stage import StageError, StageState
from host.stagezero import run_zeros
from host.stagecapture import open_stage, same_stage, stage_settings
from host.stagesim import pose_file_motion
from host.temperature import CAPTURE_DEGC_TOL, Thermometer, temperature_input


class CaptureFailed(RuntimeError):
    """A capture stopped by a fault; the message says which, and what is kept."""


class CaptureInterrupted(RuntimeError):
    """A capture stopped by Ctrl-C (or SIGTERM, SIGHUP: ``stop``, the KeyboardInterrupt raised); the message says
    what is kept."""

    def __init__(self, message: str, stop: BaseException | None = None):
        super().__init__(message)
        self.stop = stop


def capture_samples(args) -> int:
    """--samples, checked; without it the samples per row the schedule --poses was designed for (`fitgen
    schedule --samples`), else SAMPLES."""
    if args.samples is not None:
        return parse_positive(args.samples, "--samples", integer=True, most=MAX_ROW_SAMPLES)
    designed = designed_samples(args.poses)
    return SAMPLES if designed is None else designed


def capture_numbers(args) -> tuple:
    """--samples (capture_samples), --max-spread, --tries, --settle and --retries, checked."""
    return (capture_samples(args), parse_positive(args.max_spread, "--max-spread", most=MAX_NOISE),
            parse_positive(args.tries, "--tries", integer=True, most=MAX_TRIES),
            parse_positive(args.settle, "--settle", zero=True, most=LONGEST_WAIT),
            parse_positive(args.retries, "--retries", integer=True, most=MAX_TRIES))


def trigger_timeout(args) -> float:
    """--trigger-timeout, checked (> 0, at most an hour; only with --trigger), or its default."""
    refuse_alone([(args.trigger_timeout is not None, "--trigger-timeout", "--trigger", bool(args.trigger))])
    if args.trigger_timeout is None:
        return TRIGGER_TIMEOUT
    return parse_positive(args.trigger_timeout, "--trigger-timeout", most=LONGEST_WAIT)


def kept(outputs, what: str) -> str:
    """What a run stopped early leaves in its capture files ``outputs``, for its last line; ``what``: the
    message when they hold rows."""
    outputs = [Path(p) for p in outputs]
    if any(written_rows(p) for p in outputs):
        return what
    made = [str(p) for p in outputs if p.exists()]
    # stopped before the first row: at the stage's zero, or at pose 1 once the header was written
    return f"no row was captured ({', '.join(made)}: the header only)" if made else "nothing was written"


def written_rows(path: Path) -> int:
    """Rows below the header of capture file ``path``; 0 when it does not exist."""
    try:
        with open(path) as fh:
            return max(sum(1 for line in fh if line.strip()) - 1, 0)
    except OSError:
        return 0


def _kept(output, resume: str = "") -> str:
    return kept([output], f"the rows written so far are kept in {output}: "
                + (resume or "run the same command again to resume"))


def same_thermistor(output, rows: int, reads: bool) -> None:
    """InputError when ``output``'s ``rows`` rows were captured with a thermistor and this run ``reads`` none, or the
    other way round: a resume dropped their temperatures from the meta, or gave rows read without one a
    temperature (``--adc`` names the elements' channels only, which the resume compares)."""
    had = rows > 0 and prior_meta(output, rows).get("thermistor_degc") is not None  # None: an older level's none
    if rows and had != reads:
        raise InputError(f"output {output}: its {rows} rows were captured {'with' if had else 'without'} a thermistor "
                         f"(temp= in --adc), this run's --adc {'has none' if had else 'reads one'}: resume with the "
                         "same, or choose another -o")


def start_degc(thermometer, tin) -> float:
    """The thermistor's reading as a run starts; InputError when it reads none, which every row would record."""
    degc = thermometer.read(fresh=True)
    if not math.isfinite(degc):
        raise InputError(f"the thermistor ({tin.kind}@0x{tin.address:02x}:{tin.input}) reads no temperature: "
                         f"{thermometer.fault()}: mend it, give that chip a --pga that reads the divider (one below "
                         "the divider's reference reads none), or leave temp= out of --adc")
    return degc


def same_temperature(output, rows: int, degc: float) -> float:
    """``degc``, the thermistor's reading as a run starts; InputError when ``output``'s ``rows`` rows were taken more
    than CAPTURE_DEGC_TOL away from it (the meta speaks for every row with one temperature)."""
    before = thermistor_degc(prior_meta(output, rows)) if rows else None
    if before is not None and math.isfinite(degc) and abs(degc - before) > CAPTURE_DEGC_TOL:
        raise InputError(f"the {rows} rows in {output} were captured at {before:.1f} degC and the thermistor reads "
                         f"{degc:.1f} degC now: let the sensor come back within {CAPTURE_DEGC_TOL:g} degC of it, or "
                         "choose another -o (identify takes one temperature for every row)")
    return degc


def run_capture(args, prog: str) -> None:
    """The schedule ``--poses`` into ``--output`` (resumed if it has rows); progress and the summary go to
    stderr after ``prog``. Raises CaptureFailed or CaptureInterrupted when it stops early, InputError when
    another run holds the output."""
    # held from before the output is read to after its last row: two runs would interleave their rows
    with output_lock(args.output):
        _run_capture(args, prog)


def next_step(schedule, output) -> str:
    """What a user runs on a finished capture (docs/calibration.md, "The workflow")."""
    from shlex import quote

    folder = Path(output).parent  # the unit's files beside its capture: two units' folders keep theirs apart
    if schedule.check:
        return (f"fitgen check {quote(str(folder / 'twin.json'))} {quote(str(output))} (the twin's model, named as "
                "identify's next step names it, on these poses against what identify predicts)")
    drawing = recorded_spec(schedule.drawing) if schedule.drawing else None
    # a unit.toml there is most likely another unit's: this capture's own name keeps it
    unit = folder / (f"{Path(output).stem}.unit.toml" if (folder / "unit.toml").exists() else "unit.toml")
    return (f"fitgen identify {quote(str(output))} --sensor {quote(drawing) if drawing else 'DRAWING'} -o "
            f"{quote(str(unit))} (the unit's physics from these rows)")


def check_simulation_options(args) -> None:
    """InputError for --sim-drift without --simulate (with or without --temperature: it would be ignored)."""
    refuse_alone([(args.sim_drift is not None, "--sim-drift", "--simulate", bool(args.simulate))])


def _run_capture(args, prog: str) -> None:
    schedule = load_schedule(args.poses)
    simulated_sensor(args, schedule)
    if note := schedule.capture_note():
        print(f"{prog}: {note}", file=sys.stderr)
    adc_defaults(args)
    samples, spread, tries, settle, retries = capture_numbers(args)
    timeout = trigger_timeout(args)
    cmap = channel_map_from_args(args)
    state = prepare_output(args.output, cmap.n_elements, schedule, write=False)  # checked before any waiting
    stage_opts = stage_settings(args, schedule)  # and the stage's settings before anything moves
    if stage_opts is not None:
        write_target(StageState.path_for(args.output))  # its record, written when the zero is taken
    total, pending = len(schedule.poses), int((~state.done).sum())
    source = {"source": f"simulated {args.sensor}" if args.simulate else "hardware"}
    if args.simulate:  # the sensor itself, not the path typed for it, tells a resume whether it is the same one
        simulated = load_sensor(args.sensor)
        source["sensor_sha256"] = simulated.sha256
        try:  # every pose before the first row, numbered as in the schedule (the bus checks one at a time)
            check_above_board(simulated, schedule.poses)
        except InputError as exc:
            raise InputError(f"{args.poses}: {exc}") from None
    check_resume(args.output, state.rows, {"adc": cmap.describe(), **source, "samples_per_row": samples})
    tin = temperature_input(args.adc, cmap, args.thermistor)
    same_thermistor(args.output, state.rows, tin is not None)
    if pending == 0:  # the stage and the bus stay shut, the meta as it is
        print(f"{prog}: {total}/{total} poses in {args.output} already: nothing to capture", file=sys.stderr)
        return
    same_stage(args.output, state.rows, stage_opts, settle)
    interactive = not args.trigger and not args.simulate and stage_opts is None
    if args.trigger:
        wait = trigger_waiter(args.trigger, schedule, timeout)
    elif args.simulate or stage_opts is not None:
        wait = None  # the stage (simulated or G-code) sets each pose itself
    else:
        wait = enter_waiter(schedule)
    meta = {"adc": cmap.describe(), **source}
    motion = pose_file_motion(args.sim_pose_file) if args.sim_pose_file else None
    drift = parse_drift(args.sim_drift, cmap.n_elements) if args.simulate else None
    bus, clock = open_bus_from_args(args, cmap, schedule.poses[0] if args.simulate else None, motion=motion,
                                    drift=drift, thermistor=tin)
    if motion is not None:
        bus.feed.motion_step = 0.0  # follow the stage at every conversion: a move ends between two rows
        bus.feed.touching = True  # the simulated rig decided contact on the tool (host.simrig.SimRig.publish)
    stage = None
    t0 = time.monotonic()
    try:
        array = AdcArray(bus, cmap, clock=clock, policy=RetryPolicy(attempts=retries))
        array.probe()
        array.setup()
        thermometer = Thermometer(array, tin) if tin is not None else None
        if thermometer is not None:  # the unit's readings are of this temperature: identify records it (--temp-comp's t0)
            meta["thermistor_degc"] = same_temperature(args.output, state.rows, start_degc(thermometer, tin))
        set_pose = bus.set_pose if args.simulate else None
        if stage_opts is not None:
            stage, meta["stage"] = open_stage(args, stage_opts, args.output, state.rows, prog, schedule.stage)
            meta["stage"]["settle_s"] = settle
            st = meta["stage"]
            st["zeros_machine_mm"] = run_zeros(prior_meta(args.output, state.rows), st["zero_machine_mm"],
                                               st["zero_source"])
            set_pose = stage.move_to
        with Progress("capture", pending) as progress:
            res = capture(array, schedule, args.output, samples=samples, max_spread=spread, tries=tries,
                          wait=wait, set_pose=set_pose, settle=settle,
                          clock=clock, progress=None if interactive else progress, meta=meta,
                          temperature=None if thermometer is None else lambda: thermometer.read(fresh=True))
        lifted = stage.lift() if stage is not None and res.complete else None  # not after Ctrl-C: it stops motion
    except KeyboardInterrupt as exc:
        raise CaptureInterrupted(_kept(args.output), exc) from None
    except (DeviceSilent, SpreadTooLarge, TriggerFailed, StageError) as exc:
        if getattr(exc, "lost", ""):
            StageState.mark_lost(args.output, exc.lost)
        raise CaptureFailed(f"{exc}; {_kept(args.output, getattr(exc, 'resume', ''))}") from exc
    finally:
        if stage is not None:
            stage.ctrl.close()
        bus.close()
    done = res.before + res.captured
    note = "; dropped an unfinished last line" if res.dropped_partial else ""
    took = f" in {time.monotonic() - t0:.1f} s" if stage is not None else ""
    if res.complete:
        print(f"{prog}: {done}/{total} poses in {args.output} ({res.captured} captured now{took}, "
              f"{res.before} already there{note})", file=sys.stderr)
        if lifted is not None:
            print(f"{prog}: the indenter lifted to dz {lifted:+g} mm, off the skin", file=sys.stderr)
        print(f"{prog}: next: {next_step(schedule, args.output)}", file=sys.stderr)
    else:
        print(f"{prog}: stopped with {done}/{total} poses in {args.output}{note}; run the same "
              "command again to resume", file=sys.stderr)
