"""The ``tactile-host`` command: tools that run beside hardware."""

from __future__ import annotations

import sys

from fitgen.app.options import check_host, map_options, refuse_readout_options
from fitgen.app.arduino_cli import add_arduino_build
from fitgen.app.noise_cli import add_noise, cmd_noise
from fitgen.app.tempcomp_cli import add_tempcomp, cmd_tempcomp_fit
from fitgen.app.verify_cmd import cmd_verify
from fitgen.app.cliutil import (EXIT_CHECK_FAILED, Parser, StopFlag, check_not_empty, check_written, command_main,
                                count, ended_by, noise_volts)
from fitgen.app.outputkind import check_output_kind
from fitgen.base.errors import InputError
from fitgen.base.fileio import OutputText
from fitgen.base.parse import LONGEST_WAIT, parse_positive
from fitgen.base.signals import signals_held

from host.stagesettings import APPROACH


def cmd_flash(args) -> int:
    from fitgen.c.calblob import blob_refusal, check_sensor_id, model_sensor_id
    from fitgen.equations.model import load_model

    from host.device import BOOT_WAIT, Device, FlashFailed, flash_model

    timeout = parse_positive(args.timeout, "--timeout", most=LONGEST_WAIT)
    model = load_model(args.model)
    if refused := blob_refusal(model):  # said before the port is opened, not after the device answered
        raise InputError(refused)
    sensor_id = model_sensor_id(model) if args.sensor_id is None else check_sensor_id(args.sensor_id)
    try:
        with Device.open(args.port, timeout=timeout, ready=max(BOOT_WAIT, timeout)) as dev:
            blob, info, answer = flash_model(dev, model, args.model, sensor_id=sensor_id, fma=args.fma)
    except FlashFailed as exc:
        print(f"tactile-host flash: error: {exc}", file=sys.stderr)
        return EXIT_CHECK_FAILED
    print(f"flashed model {model.sha256} ({len(blob)}-byte {info.precision} blob{', fma' if args.fma else ''}, "
          f"sensor id {sensor_id!r}) to {args.port}: the device reports active model {answer}, "
          "read-back identical")
    if info.sensor_id and info.sensor_id != sensor_id:  # the drawing's model on a calibrated unit errs by millimetres
        print(f"tactile-host flash: note: the device held a model for sensor {info.sensor_id!r} and now holds one for "
              f"{sensor_id!r}; a model fitted for another sensor errs on this unit (if it is the same unit, give "
              "--sensor-id)", file=sys.stderr)
    return 0


def _where(server) -> str:
    """The page's address, and when it listens on every interface, that other machines reach it too."""
    return server.url if not server.every_interface else (
        f"{server.url} and on every interface (from another machine: this one's address, the same port; anyone on "
        "the network can see it)")


def _warn(prog: str):
    """A readout's warning as one line on stderr, at once."""
    return lambda text: print(f"{prog}: warning: {text}", file=sys.stderr, flush=True)


def cmd_read(args) -> int:
    from host.adc import DeviceSilent
    from host.readout import LineFormat, Readout
    from host.session import ReadoutSession

    s = sink = None
    try:
        s = ReadoutSession(args, "tactile-host read")  # a chip silent during its tare: one line, as later
        fmt = LineFormat(args.format, s.model.n_inputs, s.model.output_names)
        with signals_held():  # both started or neither: a Ctrl-C between them emptied the record, kept the old -o
            record = s.record(args.record)  # before -o is opened: a record that cannot be made leaves -o as it was
            if args.output:
                sink = OutputText(args.output)  # a device, FIFO or descriptor's link refused
        out = sink or sys.stdout
        out.write(fmt.header)
        reader = Readout(s.array, s.engine, out, fmt, clock=s.clock, corrections=s.corrections,
                         thermometer=s.thermometer, record=record, warn=_warn("tactile-host read"))
        with StopFlag() as stop:
            stats = reader.run(rate=s.rate, count=s.count, duration=s.duration, stop=stop)
        for done in [f for f in (sink, s) if f is not None]:  # a last block the disk refuses is said here
            done.close()
        s = sink = None
        how = "stopped" if stop.stopped else "done"
        print(f"tactile-host read: {how}: {stats.summary()}", file=sys.stderr)
        return 0
    except DeviceSilent as exc:
        return _silent("tactile-host read", exc)
    finally:  # ending on an error or a signal, which is the one to say
        for f in [f for f in (s, sink) if f is not None]:
            f.close(quiet=True)


def cmd_view(args) -> int:
    from host.adc import DeviceSilent
    from host.live import DRAIN, LiveHub, LiveServer, view_meta
    from host.readout import LineFormat, Readout
    from host.session import ReadoutSession

    if args.replay:
        return _view_replay(args)
    missing = [option for option, value in (("--model", args.model), ("--adc", args.adc)) if value is None]
    if missing:
        raise InputError(f"view needs {' and '.join(missing)} (or --replay RUN.jsonl)")
    s = server = None
    ended = False
    try:
        server = LiveServer(None, args.host, args.port)  # bound first: a port in use is said before tare and build
        s = ReadoutSession(args, "tactile-host view")
        server.hub = hub = LiveHub(view_meta(s.model.n_inputs, s.model.output_names, s.model.sha256, s.source, s.rate))
        server.start()
        print(f"tactile-host view: serving {_where(server)} ({s.source}); Ctrl-C stops", file=sys.stderr, flush=True)
        fmt = LineFormat("csv", s.model.n_inputs, s.model.output_names)
        reader = Readout(s.array, s.engine, None, fmt, clock=s.clock, corrections=s.corrections,
                         thermometer=s.thermometer, observer=hub.publish, record=s.record(args.record),
                         warn=_warn("tactile-host view"))
        with StopFlag() as stop:
            stats = reader.run(rate=s.rate, count=s.count, duration=s.duration, stop=stop)
        ended = not stop.stopped
        s.close()  # a record's last block the disk refuses is said, before the summary
        s = None
        print(f"tactile-host view: {'stopped' if stop.stopped else 'done'}: {stats.summary()}", file=sys.stderr)
        return 0
    except DeviceSilent as exc:
        return _silent("tactile-host view", exc)
    finally:
        if server is not None:
            server.stop(drain=DRAIN if ended else 0.0)  # a run that ended reaches its viewers whole
        if s is not None:
            s.close(quiet=True)


def _silent(prog: str, exc) -> int:
    """A chip that stopped answering: one line with what was read before it, exit status 1."""
    done = getattr(exc, "stats", None)
    where = f"stopped after {done.summary()}" if done is not None else "stopped before the first sample"
    print(f"{prog}: error: {exc}; {where}", file=sys.stderr)
    return EXIT_CHECK_FAILED


def _view_replay(args) -> int:
    from host.live import DRAIN, LiveHub, LiveServer, view_meta
    from host.replay import load_run

    refuse_readout_options(args)
    run = load_run(args.replay)
    server, ended = LiveServer(None, args.host, args.port), False
    try:
        res = _replayed(run, args)
        server.hub = hub = LiveHub(view_meta(run.n_inputs, res.outputs, res.model_hash, f"replay of {args.replay}",
                                             None))
        server.start()
        print(f"tactile-host view: serving {_where(server)} (replay of {args.replay}, {len(res.t)} samples); Ctrl-C "
              "stops", file=sys.stderr, flush=True)
        for note in res.notes:  # what replay's report says of the run: another model, a last line cut short
            print(f"tactile-host view: note: {note}", file=sys.stderr, flush=True)
        with StopFlag() as stop:
            played = res.play(hub.publish, stop, hold=args.hold)
        ended = not stop.stopped
        print(f"tactile-host view: {'done' if ended else 'stopped'}: played {played} of {len(res.t)} samples",
              file=sys.stderr)
    finally:
        server.stop(drain=DRAIN if ended else 0.0)
    return 0


def _replayed(run, args):
    """``run`` re-estimated as the options say, with a progress bar over its samples."""
    from fitgen.base.progress import Progress
    from host.replay import replay

    with Progress("replay", len(run.t)) as bar:
        return replay(run, model=args.model, auto_zero=_flag(args), temp_comp=args.temp_comp,
                      no_temp_comp=getattr(args, "no_temp_comp", False), progress=bar)


def _flag(args):
    """--auto-zero / --no-auto-zero for replay: True, False, or None (as recorded)."""
    if args.auto_zero and getattr(args, "no_auto_zero", False):
        raise InputError("give --auto-zero or --no-auto-zero, not both")
    return True if args.auto_zero else (False if getattr(args, "no_auto_zero", False) else None)


def cmd_replay(args) -> int:
    from host.replay import load_run

    run = load_run(args.run)
    res = _replayed(run, args)
    if args.output:
        res.save(args.output)
    print(res.report(), end="")
    return 0


def cmd_capture(args) -> int:
    from host.capturerun import CaptureFailed, CaptureInterrupted, check_simulation_options, run_capture
    from host.tempcapture import capture_temperatures, check_temperature_options

    prog = "tactile-host capture"
    check_temperature_options(args)
    check_simulation_options(args)
    try:
        if args.temperature is not None and args.stage is None:
            capture_temperatures(args, prog)  # stopped at a prompt, it said so: 0, as a plain capture stopped
            return 0
        run_capture(args, prog)
    except CaptureInterrupted as exc:  # SIGTERM and SIGHUP said and ended with their own status, as elsewhere
        said, status = ended_by(exc.stop)
        print(f"{prog}: {said}; {exc}", file=sys.stderr)
        return status
    except CaptureFailed as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return EXIT_CHECK_FAILED
    return 0


def cmd_stage_sim(args) -> int:
    """``stage-sim``: a simulated Marlin or GRBL on a loopback port or a pty until Ctrl-C."""
    import time

    from host.stagesim import PoseFile, PtyServer, SimController, SimRig, SocketServer, parse_matrix, parse_xyz

    if args.pty and args.port is not None:
        raise InputError("--port is the loopback socket's; with --pty there is none (without it, it would be ignored)")
    rig = SimRig(PoseFile(args.pose_file) if args.pose_file else None, parse_matrix(args.map) if args.map else None,
                 axes=args.axes, contact=parse_xyz(args.contact, "--contact"), start=parse_xyz(args.start, "--start"),
                 backlash=parse_positive(args.backlash, "--backlash", zero=True),
                 repeatability=parse_positive(args.repeatability, "--repeatability", zero=True), seed=args.seed)
    ctrl = SimController(args.flavor, rig, homing_lock=args.homing)
    server = PtyServer(ctrl) if args.pty else SocketServer(ctrl, port=args.port or 0)
    with server, StopFlag() as stop:
        print(server.url, flush=True)
        print(f"tactile-host stage-sim: {args.flavor} on {server.url}; {rig.contact_note()}; "
              f"{'pose in ' + args.pose_file if args.pose_file else 'no pose file'}; Ctrl-C stops",
              file=sys.stderr, flush=True)
        while not stop():
            time.sleep(0.1)
    print(f"tactile-host stage-sim: stopped after {len(ctrl.lines)} lines received, {ctrl.g1_count} moves",
          file=sys.stderr)
    return 0


def cmd_pi_build(args) -> int:
    from host.pi import pi_build

    print(pi_build(args), file=sys.stderr)
    return 0


def _readout_options(p) -> None:
    """Options read and view share (beside the ADC's)."""
    p.add_argument("--rate", help="samples per second (default: as fast as the converters allow)")
    p.add_argument("--count", help="stop after this many samples")
    p.add_argument("--duration", help="stop after this many seconds")
    p.add_argument("--tare", action="store_true", help="measure the rest readings first and correct the offsets")
    p.add_argument("--tare-samples", help="samples averaged for --tare (default 50)")
    p.add_argument("--rest", metavar="SENSOR|DATASET.csv",
                   help="the rest readings --tare maps onto: a dataset's rows at pose 0, or a sensor's physics "
                        "(default: --sensor)")
    p.add_argument("--auto-zero", action="store_true",
                   help="tare, then keep re-zeroing slowly while the sensor is at rest (never while touched); "
                        "each update is logged")
    p.add_argument("--rest-band", metavar="MM,DEG",
                   help="at rest: the last 64 samples' mean displacement estimate within MM and tilt within DEG "
                        "of what the model reads at rest (default 0.08,1.5; wider where that mean scatters more)")
    p.add_argument("--rest-hold", metavar="S", help="seconds at rest before an auto-zero update (default 1)")
    p.add_argument("--temp-comp", metavar="FILE.json",
                   help="per-element temperature compensation (tactile-host capture --temperature); needs the "
                        "thermistor's input in --adc (temp=CHIP@ADDRESS:INPUT)")
    p.add_argument("--record", metavar="RUN.jsonl", help="also record the run at full precision for tactile-host replay")
    p.add_argument("--engine", choices=("python", "c"),
                   help="python: Model.predict; c: the generated header as a shared library (default python)")
    p.add_argument("--precision", choices=("double", "float"), help="C engine precision (default double)")
    p.add_argument("--cc", help="C compiler for --engine c (default gcc)")
    p.add_argument("--simulate", metavar="POSE|motion|presses",
                   help="no hardware: a simulated bus with the sensor at POSE (e.g. dx=1,dz=-1 or 0.5,0,-1,0,0), "
                        "'motion': sliding in a circle and pressed every 6 s, or 'presses': at rest, pressed for "
                        "1.5 s every 20 s (to watch drift and auto-zero)")
    p.add_argument("--sim-drift", metavar="ramp=..,over=..,tau=..,creep=..",
                   help="simulated drift: a temperature ramp (degC over s), creep (V, time constant s); also "
                        "start=DEGC, seed=N (default ramp=5,over=600,tau=600,creep=0.002,start=25,seed=0; a faster "
                        "one: ramp=5,over=300,tau=120,creep=0.002)")


def _adc_options(p, required: bool = True, sensor_help: str | None = None, thermistor: bool = True) -> None:
    map_options(p, required, thermistor)
    p.add_argument("--bus", type=int, help="I2C bus number: /dev/i2c-N (default 1, or the map file's bus)")
    # --retries, --sensor, --seed: no argparse defaults, so that view --replay tells one typed from one left out
    # (host.session.ADC_DEFAULTS fills them in)
    p.add_argument("--retries", help="tries per I2C transfer before a chip counts as silent (default 5)")
    p.add_argument("--sensor", help=sensor_help or (
        "sensor preset or TOML file: what --simulate simulates, and the rest readings for --tare (default paper; "
        "with --model, the sensor the model was fitted on, and for capture the drawing its schedule was made for, "
        "where the file is found)"))
    p.add_argument("--sim-noise", type=noise_volts, help="simulated element noise, V rms (default: the sensor file's)")
    p.add_argument("--sim-flicker", type=noise_volts, help="simulated 1/f noise per element: its Allan deviation, V")
    p.add_argument("--sim-offsets", metavar="V1,..,VN", help="simulated offset of each element, V")
    p.add_argument("--sim-fault", action="append", metavar="SPEC",
                   help="simulated fault: nack|timeout|stuck[:ADDR]:RATE or silent:ADDR[:AFTER] (repeatable)")
    p.add_argument("--seed", type=count, help="seed of the simulated noise and faults (default 0)")


def build_parser() -> Parser:
    from fitgen.c.verify import MAX_VECTORS, add_held_out_options

    p = Parser(prog="tactile-host", description="Tools beside the sensor's hardware: read it live over I2C (or a "
               "simulated bus), capture calibration rows, build and flash firmware (docs/readout.md)")
    sub = p.add_subparsers(dest="command", required=True, parser_class=Parser)
    v = sub.add_parser("verify", help="compile the generated C and compare it with the Python evaluation")
    v.add_argument("model", metavar="MODEL", help="model file (fitgen fit)")
    v.add_argument("--precision", default="both", choices=("double", "float", "fixed", "both"),
                   help="both: double and float; fixed: the integer header against its numpy model and double")
    v.add_argument("--style", choices=("table", "unrolled", "both"),
                   help="the C's form: table (coefficient arrays and a loop), unrolled (straight-line code), "
                        "or both (default; not with --precision fixed, which has one form)")
    v.add_argument("--cc", default="gcc", help="C compiler command, with flags if needed (default gcc)")
    v.add_argument("--runner", help="prefix to run the binary with, e.g. qemu-arm")
    v.add_argument("--prefix", default="tm", help="C identifier prefix (default tm)")
    v.add_argument("--vectors", type=int, default=2000,
                   help=f"random vectors inside the domain (default 2000, at most {MAX_VECTORS:,})")
    v.add_argument("--data", help="also run the rows of this dataset")
    v.add_argument("--fma", action="store_true", help="generate with fused multiply-adds (fitgen codegen --fma)")
    v.add_argument("--input-lsb", type=float, metavar="X", help="fixed: the input value of one ADC code")
    v.add_argument("--input-offset", type=float, metavar="Y", help="fixed: the input value of code 0")
    add_held_out_options(v)
    v.set_defaults(func=cmd_verify)

    pb = sub.add_parser("pi-build", help="the readout in C for a Raspberry Pi: drivers, channel map and model "
                                         "over i2c-dev, built with arm-linux-gnueabihf-gcc")
    pb.add_argument("--model", required=True, metavar="MODEL", help="model file (inputs in V)")
    map_options(pb)
    pb.add_argument("--precision", choices=("float", "double"),
                    help="the model's precision (default double, as fitgen codegen --target pi writes it)")
    pb.add_argument("--style", default="unrolled", choices=("table", "unrolled"),
                    help="the C's form: table (coefficient arrays and a loop) or unrolled (straight-line code; "
                         "default)")
    pb.add_argument("--cc", default="arm-linux-gnueabihf-gcc -static",
                    help="compiler and flags (default: arm-linux-gnueabihf-gcc -static; gcc on the Pi itself)")
    pb.add_argument("-o", "--output", required=True, metavar="DIR", help="folder for the sources and tm_pi")
    pb.add_argument("--temp-comp", metavar="FILE.json", help="temperature compensation before the model (needs "
                    "temp=CHIP@ADDRESS:INPUT in --adc)")
    pb.add_argument("--rest", metavar="SENSOR|DATASET.csv", help="the rest readings tm_pi --tare maps onto (default: "
                    "the model's own sensor file where found, else the rest the model recorded)")
    pb.set_defaults(func=cmd_pi_build)

    add_arduino_build(sub)

    f = sub.add_parser("flash", help="load a model into a device as a calibration blob and read it back")
    f.add_argument("model", metavar="MODEL", help="model file (fitgen fit)")
    f.add_argument("--port", required=True, metavar="URL",
                   help="serial port: /dev/ttyACM0, /dev/pts/N or socket://HOST:PORT")
    f.add_argument("--sensor-id", help="sensor id stored in the blob (ASCII, <= 16 bytes; default: the name of "
                                       "the sensor the model's held-out figures are for, such as a unit file's, "
                                       "refused where it cannot be one; paper for a model that names none)")
    f.add_argument("--fma", action="store_true", help="the device sums the terms by fused multiply-add")
    f.add_argument("--timeout", default="2", help="seconds to wait for each answer (default 2); the first PING "
                   "waits at least 3 s, for a board that restarts when its port opens (an Uno's bootloader)")
    f.set_defaults(func=cmd_flash)

    r = sub.add_parser("read", help="stream readings and pose estimates from I2C ADCs")
    r.add_argument("--model", required=True, metavar="MODEL", help="model file (inputs in V)")
    _adc_options(r)
    _readout_options(r)
    r.add_argument("--format", default="csv", choices=("csv", "jsonl"), help="one line per reading (default csv)")
    r.add_argument("-o", "--output", metavar="FILE", help="write the stream here instead of stdout")
    r.set_defaults(func=cmd_read)

    w = sub.add_parser("view", help="a live web page of the readings and estimates (same options as read)")
    w.add_argument("--model", metavar="MODEL", help="model file (inputs in V)")
    _adc_options(w, required=False)
    _readout_options(w)
    w.add_argument("--host", default="127.0.0.1",
                   help="address to serve on (default 127.0.0.1: this machine only; 0.0.0.0 serves the network)")
    w.add_argument("--port", type=int, default=8765, help="TCP port (default 8765; 0 picks a free one)")
    w.add_argument("--replay", metavar="RUN.jsonl", help="play a recorded run (read/view --record) in the page")
    w.add_argument("--hold", action="store_true", help="with --replay: keep serving after the run's end")
    w.set_defaults(func=cmd_view)

    rp = sub.add_parser("replay", help="re-estimate a recorded run (--record) with another model or corrections")
    rp.add_argument("run", metavar="RUN.jsonl", help="a run recorded with --record (read, view)")
    rp.add_argument("--model", metavar="MODEL", help="model to re-estimate with (default: the run's own, if given "
                    "as the file whose hash the run names)")
    rp.add_argument("--auto-zero", action="store_true", help="re-zero at rest (default: as recorded)")
    rp.add_argument("--no-auto-zero", action="store_true", help="no auto-zero (default: as recorded)")
    rp.add_argument("--temp-comp", metavar="FILE.json", help="temperature compensation to apply (default: as recorded)")
    rp.add_argument("--no-temp-comp", action="store_true", help="no temperature compensation")
    rp.add_argument("-o", "--output", metavar="OUT.jsonl", help="write the re-estimated run here")
    rp.set_defaults(func=cmd_replay)

    add_tempcomp(sub)

    c = sub.add_parser("capture", help="record a calibration dataset, one averaged row per scheduled pose")
    c.add_argument("--poses", required=True, metavar="SCHEDULE.csv", help="poses to visit: columns of dx,dy,dz,thx,thy")
    _adc_options(c)
    c.add_argument("-o", "--output", required=True, metavar="DATASET.csv",
                   help="dataset to write; an existing one is resumed")
    c.add_argument("--samples", help="samples averaged per pose (default: as many as the schedule was made for, "
                   "fitgen schedule --samples; else 16)")
    c.add_argument("--max-spread", default="0.003", metavar="V",
                   help="largest standard deviation of an element over the samples, V (default 0.003)")
    c.add_argument("--tries", default="3", help="measurements of a pose before giving up on its spread (default 3)")
    c.add_argument("--trigger", metavar="CMD",
                   help="shell command run for each pose instead of waiting for Enter; it gets TM_POSE_INDEX, "
                        "TM_DX..TM_THY and must exit 0 once the pose is set")
    c.add_argument("--trigger-timeout", metavar="S", help="seconds --trigger may take per pose before it is killed and "
                   "the capture stops, the rows so far kept (default 60)")
    c.add_argument("--settle", default="0", help="seconds to wait after Enter or the trigger (default 0)")
    c.add_argument("--simulate", action="store_true",
                   help="no hardware: a simulated sensor that moves to each scheduled pose by itself")
    c.add_argument("--temperature", metavar="T1,T2,..",
                   help="capture the schedule at each of these temperatures (degC; one file OUTPUT.T<t>.csv each) and "
                        "fit per-element offset and gain compensation from them (OUTPUT.tempcomp.json)")
    c.add_argument("--t0", metavar="DEGC", help="with --temperature: the calibration temperature (default: the one "
                   "nearest the median, the lower of two as near)")
    c.add_argument("--temp-comp-output", metavar="FILE.json", help="with --temperature: where the compensation goes")
    c.add_argument("--sim-drift", metavar="ramp=..,over=..,tau=..,creep=..,seed=..",
                   help="with --simulate: the simulated sensor drifts so (ramp degC over `over` s, creep V with time "
                        "constant tau s); with --temperature too: the drift's coefficients (default: typical, seed "
                        "--seed)")
    st = c.add_argument_group("a stage that moves itself (docs/calibration.md)")
    st.add_argument("--stage", metavar="gcode:URL",
                    help="drive a Marlin or GRBL machine: gcode:/dev/ttyUSB0, gcode:socket://127.0.0.1:PORT "
                         "(tactile-host stage-sim), any pyserial URL")
    st.add_argument("--stage-flavor", choices=("auto", "marlin", "grbl"), help="default auto: from its banner or "
                    "its answer to M115")
    st.add_argument("--stage-baud", metavar="BAUD", help="serial baud rate (default 115200)")
    st.add_argument("--stage-axes", metavar="X=dx,Y=dy,Z=dz",
                    help="which machine axis moves along which pose axis, with its sign (default X=dx,Y=dy,Z=dz)")
    st.add_argument("--stage-limits", metavar="dx=LO:HI,..",
                    help="soft limits in mm from the zero for every mapped pose axis (required with --stage); "
                         "checked for every pose and its approach before anything moves")
    st.add_argument("--stage-feed", metavar="MM_MIN", help="feed rate of every move, mm/min (default 600)")
    st.add_argument("--stage-approach", metavar=APPROACH,
                    help="where the last move to each pose starts, relative to it (backlash: every pose approached "
                         f"from the same side; every axis named, 0 turns it off for one; default {APPROACH})")
    st.add_argument("--stage-timeout", metavar="S", help="time limit for each answer of the controller (default 5 s, "
                    "plus each move's own time)")
    st.add_argument("--stage-boot-wait", metavar="S", help="seconds to wait for a start-up banner after opening the "
                    "port (boards that reset on connect print one; default 2)")
    st.add_argument("--home", action="store_true", help="home the machine first (G28 / $H): a zero taken on a homed "
                    "machine holds across resets. Not on a printer that homes Z down to its bed with the sensor "
                    "mounted: the indenter would hit it; on Marlin it asks first (docs/calibration.md)")
    st.add_argument("--unlock", action="store_true", help="GRBL: leave ALARM by $X without homing")
    st.add_argument("--zero", metavar="ask|here|X,Y,Z",
                    help="the stage's zero, first contact with the resting sensor, when the last one does not hold: "
                         "ask (default: jog to it at a prompt), here (new datasets only), or machine coordinates "
                         "(120.5,80,12.25 or X120.5 Y80 Z12.25)")
    st.add_argument("--sim-pose-file", metavar="FILE",
                    help="with --simulate --stage: the simulated sensor follows the pose tactile-host stage-sim "
                         "--pose-file FILE writes")
    c.set_defaults(func=cmd_capture)
    add_noise(sub, _adc_options)

    ss = sub.add_parser("stage-sim", help="a simulated Marlin or GRBL stage on a loopback port or a pty, moving a "
                                          "simulated sensor through a pose file")
    ss.add_argument("--flavor", default="grbl", choices=("grbl", "marlin"), help="the controller (default grbl)")
    ss.add_argument("--port", type=int, help="TCP port on 127.0.0.1 (default 0: any free one)")
    ss.add_argument("--pty", action="store_true", help="serve on a pseudo-terminal instead (prints its path)")
    ss.add_argument("--pose-file", metavar="FILE", help="write the magnet's pose here (capture --sim-pose-file FILE)")
    ss.add_argument("--map", metavar="a,b,c;d,e,f;g,h,i",
                    help="stage-to-magnet displacement map M, rows (default: identity; a built unit's own map acts "
                         "after it); one that starts with a minus goes after an equals sign: --map=-1,0,0;0,1,0;0,0,1")
    ss.add_argument("--axes", default="X=dx,Y=dy,Z=dz", help="the rig's true machine -> sensor axes")
    ss.add_argument("--backlash", default="0.03", help="lost motion per axis on reversal, mm (default 0.03)")
    ss.add_argument("--repeatability", default="0.002", help="random error at the end of each move, mm rms "
                    "(default 0.002)")
    ss.add_argument("--contact", default="12,8,4", help="first contact, mm from the home switches (default 12,8,4)")
    ss.add_argument("--start", default="10,10,10", help="where the carriage stands at power-on, mm from the home "
                    "switches (default 10,10,10; machine coordinates start at 0 there)")
    ss.add_argument("--homing", action="store_true", help="homing on: GRBL starts in ALARM until $H or $X")
    ss.add_argument("--seed", type=count, default=0, help="seed of the rig's repeatability errors (default 0)")
    ss.set_defaults(func=cmd_stage_sim)
    return p


def _check(args) -> None:
    check_not_empty(args)
    if args.func is cmd_view:
        check_host(args.host)
    # -o is a file for these; a folder for pi-build, arduino-build and tempcomp-c
    check_written(args, files=(cmd_read, cmd_view, cmd_replay, cmd_capture, cmd_noise, cmd_tempcomp_fit))
    check_output_kind(args)


def main(argv=None) -> int:
    command_main(build_parser, argv, "tactile-host", _check)
