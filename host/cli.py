"""The ``tactile-host`` command: tools that run beside hardware."""

from __future__ import annotations

import sys

from fitgen.cliutil import EXIT_CHECK_FAILED, Parser, run
from fitgen.errors import InputError

from .channelmap import ADS1115_PGA, ADS1115_RATES, MODES


def cmd_verify(args) -> int:
    from fitgen.codegen import STYLES
    from fitgen.dataset import load_dataset
    from fitgen.model import load_model

    from .verify import held_out_from_args, verify

    model = load_model(args.model)
    precisions = ("double", "float") if args.precision == "both" else (args.precision,)
    styles = STYLES if args.style == "both" else (args.style,)
    if (args.input_lsb is not None or args.input_offset is not None) and args.precision != "fixed":
        raise InputError("--input-lsb and --input-offset apply to --precision fixed only")
    if args.fma and args.precision == "fixed":
        raise InputError("--fma does not apply to --precision fixed")
    extra = None
    if args.data:
        ds = load_dataset(args.data, min_rows=1)
        if ds.n_inputs != model.n_inputs:
            raise InputError(f"dataset {args.data} has {ds.n_inputs} inputs; the model takes {model.n_inputs}")
        extra = ds.inputs
    if args.vectors < 0:
        raise InputError("--vectors must be >= 0")
    held_out = held_out_from_args(model, args)
    ok = True
    for precision in precisions:
        # the fixed-point header has one form (straight-line code): checked once
        for style in (("unrolled",) if precision == "fixed" else styles):
            res = verify(model, precision, style, cc=args.cc, runner=args.runner or "", prefix=args.prefix,
                         n_random=args.vectors, extra_inputs=extra, fma=args.fma, input_lsb=args.input_lsb,
                         input_offset=args.input_offset, held_out=held_out, max_share=args.max_share)
            print(res.table())
            print("PASS" if res.ok else "FAIL: " + "; ".join(res.failures))
            print()
            ok &= res.ok
    return 0 if ok else EXIT_CHECK_FAILED


def cmd_flash(args) -> int:
    from fitgen.calblob import to_blob
    from fitgen.model import load_model

    from .device import Device, DeviceError
    from .protocol import ProtocolError

    timeout = _positive(args.timeout, "--timeout")
    model = load_model(args.model)
    with Device.open(args.port, timeout=timeout) as dev:
        try:
            info = dev.info()
        except (DeviceError, ProtocolError) as exc:
            raise InputError(f"{args.port}: INFO failed: {exc}") from None
        if info.precision == "fixed":
            raise InputError("the device is a fixed-point build; calibration blobs need a float or double build")
        if (info.n_inputs, info.n_outputs) != (model.n_inputs, len(model.equations)):
            raise InputError(f"model {args.model} has {model.n_inputs} inputs and {len(model.equations)} outputs; "
                             f"the device's build has {info.n_inputs} and {info.n_outputs}")
        blob = to_blob(model, info.precision, sensor_id=args.sensor_id, fma=args.fma)
        try:
            answer = dev.load_calibration(blob)
            back = dev.read_calibration()
        except (DeviceError, ProtocolError) as exc:
            print(f"tactile-host flash: error: calibration not loaded: {exc}", file=sys.stderr)
            return EXIT_CHECK_FAILED
    if back != blob:
        first = next((i for i, (a, b) in enumerate(zip(back, blob)) if a != b), min(len(back), len(blob)))
        print(f"tactile-host flash: error: read-back differs from the {len(blob)}-byte blob sent "
              f"({len(back)} bytes read, first difference at byte {first})", file=sys.stderr)
        return EXIT_CHECK_FAILED
    if answer != model.sha256:
        print(f"tactile-host flash: error: the device reports active model {answer}, expected {model.sha256}",
              file=sys.stderr)
        return EXIT_CHECK_FAILED
    print(f"flashed model {model.sha256} ({len(blob)}-byte {info.precision} blob{', fma' if args.fma else ''}, "
          f"sensor id {args.sensor_id!r}) to {args.port}: the device reports active model {answer}, "
          "read-back identical")
    return 0


def _vref(text: str):
    if text.lower() == "internal":
        return "internal"
    try:
        return float(text)
    except ValueError:
        raise InputError(f"--vref {text!r}: give 'internal' or the external reference in volts") from None


def _channel_map(args):
    from .channelmap import Settings, channel_map

    settings = Settings(pga=args.pga, data_rate=args.data_rate, mode=args.mode, vref=_vref(args.vref)).checked("option")
    return channel_map(args.adc, settings)


def _open_bus(args, cmap, simulate_pose):
    """Bus and clock from the options; with a simulated pose, a SimBus instead of /dev/i2c-N."""
    from fitgen.sensor import load_sensor

    from .adc import open_bus
    from .clock import REAL_CLOCK
    from .simbus import SimBus, parse_fault

    sim_opts = [o for o, v in (("--sim-noise", args.sim_noise), ("--sim-fault", args.sim_fault),
                               ("--sim-offsets", args.sim_offsets)) if v is not None]
    if simulate_pose is None:
        if sim_opts:
            raise InputError(f"{sim_opts[0]} needs --simulate")
        number = args.bus if args.bus is not None else (cmap.bus if cmap.bus is not None else 1)
        return open_bus(number), REAL_CLOCK
    sensor = load_sensor(args.sensor)
    noise = sensor.gmr.noise if args.sim_noise is None else args.sim_noise
    offsets = None
    if args.sim_offsets:
        try:
            offsets = [float(x) for x in args.sim_offsets.replace(",", " ").split()]
        except ValueError:
            raise InputError(f"--sim-offsets {args.sim_offsets!r}: not numbers") from None
        if len(offsets) != sensor.n_elements:
            raise InputError(f"--sim-offsets: give {sensor.n_elements} numbers (V), got {len(offsets)}")
    faults = [parse_fault(f) for f in args.sim_fault or ()]
    if noise < 0:
        raise InputError(f"--sim-noise must be >= 0 V, got {noise}")
    bus = SimBus.for_channel_map(cmap, sensor, simulate_pose, clock=REAL_CLOCK, noise=noise, offsets=offsets,
                                 seed=args.seed)
    for f in faults:
        bus.inject(**f)
    return bus, REAL_CLOCK


def _positive(text: str, what: str, *, integer: bool = False, zero: bool = False):
    import math

    try:
        val = int(text) if integer else float(text)
    except ValueError:
        raise InputError(f"{what} {text!r} is not a{' whole' if integer else ''} number") from None
    if not math.isfinite(val) or val < 0 or (val == 0 and not zero):
        raise InputError(f"{what} must be {'>= 0' if zero else '> 0'}, got {text}")
    return val


class _StopFlag:
    """SIGINT and SIGTERM set a flag the loop checks between samples (restored on exit)."""

    def __init__(self):
        self.stopped = False

    def __call__(self) -> bool:
        return self.stopped

    def __enter__(self):
        import signal

        def handler(signum, frame):
            self.stopped = True

        self._old = {s: signal.signal(s, handler) for s in (signal.SIGINT, signal.SIGTERM)}
        return self

    def __exit__(self, *exc):
        import signal

        for s, h in self._old.items():
            signal.signal(s, h)


def cmd_read(args) -> int:
    from fitgen.model import load_model

    from .adc import AdcArray, DeviceSilent, RetryPolicy
    from .engine import make_engine
    from .readout import LineFormat, Readout, rest_reference, tare
    from .simbus import parse_pose

    rate = _positive(args.rate, "--rate") if args.rate is not None else None
    count = _positive(args.count, "--count", integer=True) if args.count is not None else None
    duration = _positive(args.duration, "--duration") if args.duration is not None else None
    tare_n = _positive(args.tare_samples, "--tare-samples", integer=True)
    retries = _positive(args.retries, "--retries", integer=True)
    pose = parse_pose(args.simulate) if args.simulate is not None else None
    model = load_model(args.model)
    if model.input_units != "V":
        raise InputError(f"model {args.model} takes inputs in {model.input_units}; the ADCs give volts: fit it on "
                         "a dataset in V (fitgen simulate --transfer gmr, or tactile-host capture)")
    fmt = LineFormat(args.format, model.n_inputs, model.output_names)
    cmap = _channel_map(args)
    if cmap.n_elements != model.n_inputs:
        raise InputError(f"--adc reads {cmap.n_elements} elements; the model takes {model.n_inputs}")
    reference = rest_reference(args.rest or args.sensor, model.n_inputs) if args.tare else None
    engine = make_engine(args.engine, model, **({"precision": args.precision, "cc": args.cc}
                                                 if args.engine == "c" else {}))
    sink = bus = None
    try:
        # a simulated sensor rests during the tare, then moves to its pose, as a real one is pressed after it
        bus, clock = _open_bus(args, cmap, None if pose is None else (0 * pose if args.tare else pose))
        array = AdcArray(bus, cmap, clock=clock, policy=RetryPolicy(attempts=retries))
        array.probe()
        array.setup()
        offsets = None
        if args.tare:
            t = tare(array, reference, tare_n)
            print(f"tactile-host read: {t.describe()}", file=sys.stderr)
            offsets = t.offsets
            if pose is not None:
                bus.set_pose(pose)
        if args.output:
            try:
                sink = open(args.output, "w")
            except OSError as exc:
                raise InputError(f"cannot write {args.output}: {exc.strerror}") from None
        out = sink or sys.stdout
        out.write(fmt.header)
        reader = Readout(array, engine, out, fmt, clock=clock, offsets=offsets)
        with _StopFlag() as stop:
            stats = reader.run(rate=rate, count=count, duration=duration, stop=stop)
        how = "stopped" if stop.stopped else "done"
        print(f"tactile-host read: {how}: {stats.summary()}", file=sys.stderr)
        return 0
    except DeviceSilent as exc:
        done = getattr(exc, "stats", None)
        where = f"stopped after {done.summary()}" if done is not None else "stopped before the first sample"
        print(f"tactile-host read: error: {exc}; {where}", file=sys.stderr)
        return EXIT_CHECK_FAILED
    finally:
        engine.close()
        if sink is not None:
            sink.close()
        if bus is not None:
            bus.close()


def cmd_capture(args) -> int:
    from fitgen.progress import Progress

    from .adc import AdcArray, DeviceSilent, RetryPolicy
    from .capture import (SpreadTooLarge, TriggerFailed, capture, enter_waiter, load_schedule, prepare_output,
                          trigger_waiter)

    samples = _positive(args.samples, "--samples", integer=True)
    spread = _positive(args.max_spread, "--max-spread")
    tries = _positive(args.tries, "--tries", integer=True)
    settle = _positive(args.settle, "--settle", zero=True)
    retries = _positive(args.retries, "--retries", integer=True)
    schedule = load_schedule(args.poses)
    cmap = _channel_map(args)
    state = prepare_output(args.output, cmap.n_elements, schedule, write=False)  # checked before any waiting
    total, pending = len(schedule.poses), int((~state.done).sum())
    interactive = not args.trigger and not args.simulate
    if args.trigger:
        wait = trigger_waiter(args.trigger, schedule)
    elif args.simulate:
        wait = None  # the simulated stage sets each pose itself
    else:
        wait = enter_waiter(schedule)
    meta = {"adc": cmap.describe(), "source": f"simulated {args.sensor}" if args.simulate else "hardware"}
    bus, clock = _open_bus(args, cmap, schedule.poses[0] if args.simulate else None)
    keep = f"the rows written so far are kept in {args.output}: run the same command again to resume"
    try:
        array = AdcArray(bus, cmap, clock=clock, policy=RetryPolicy(attempts=retries))
        array.probe()
        array.setup()
        with Progress("capture", pending) as progress:
            res = capture(array, schedule, args.output, samples=samples, max_spread=spread, tries=tries,
                          wait=wait, set_pose=bus.set_pose if args.simulate else None, settle=settle,
                          clock=clock, progress=None if interactive else progress, meta=meta)
    except KeyboardInterrupt:
        print(f"tactile-host capture: interrupted; {keep}", file=sys.stderr)
        return 130
    except (DeviceSilent, SpreadTooLarge, TriggerFailed) as exc:
        print(f"tactile-host capture: error: {exc}; {keep}", file=sys.stderr)
        return EXIT_CHECK_FAILED
    finally:
        bus.close()
    done = res.before + res.captured
    note = "; dropped an unfinished last line" if res.dropped_partial else ""
    if res.complete:
        print(f"tactile-host capture: {done}/{total} poses in {args.output} ({res.captured} captured now, "
              f"{res.before} already there{note})", file=sys.stderr)
    else:
        print(f"tactile-host capture: stopped with {done}/{total} poses in {args.output}{note}; run the same "
              "command again to resume", file=sys.stderr)
    return 0


def cmd_pi_build(args) -> int:
    from fitgen.model import load_model

    from .pi import build_pi, render_pi

    model = load_model(args.model)
    cmap = _channel_map(args)
    folder = render_pi(model, cmap, args.output, precision=args.precision, style=args.style)
    binary = build_pi(folder, args.cc)
    print(f"wrote {binary} ({cmap.describe()}, model {model.sha256[:12]}, {args.precision}); on the Pi: "
          f"{binary.name} --bus 1 --format csv", file=sys.stderr)
    return 0


def _map_options(p) -> None:
    p.add_argument("--adc", required=True, metavar="SPEC|FILE.toml",
                   help="channel map: e.g. ads1115@0x48:0-3,ads1115@0x49:0-3 or ads7828@0x48, or a TOML file")
    p.add_argument("--pga", type=float, default=4.096, choices=ADS1115_PGA, metavar="V",
                   help="ADS1115 full scale +-V: 6.144, 4.096 (default), 2.048, 1.024, 0.512, 0.256")
    p.add_argument("--data-rate", type=int, default=860, choices=ADS1115_RATES, metavar="SPS",
                   help="ADS1115 samples per second: 8..860 (default 860)")
    p.add_argument("--mode", default="single", choices=MODES, help="ADS1115 conversion mode (default single)")
    p.add_argument("--vref", default="3.3", help="ADS7828 reference: external volts (default 3.3) or 'internal' (2.5 V)")


def _adc_options(p) -> None:
    _map_options(p)
    p.add_argument("--bus", type=int, help="I2C bus number: /dev/i2c-N (default 1, or the map file's bus)")
    p.add_argument("--retries", default="5", help="tries per I2C transfer before a chip counts as silent (default 5)")
    p.add_argument("--sensor", default="paper",
                   help="sensor preset or TOML file: what --simulate simulates, and the rest readings for --tare")
    p.add_argument("--sim-noise", type=float, help="simulated element noise, V rms (default: the sensor file's)")
    p.add_argument("--sim-offsets", metavar="V1,..,VN", help="simulated offset of each element, V")
    p.add_argument("--sim-fault", action="append", metavar="SPEC",
                   help="simulated fault: nack|timeout|stuck[:ADDR]:RATE or silent:ADDR[:AFTER] (repeatable)")
    p.add_argument("--seed", type=int, default=0, help="seed of the simulated noise and faults")


def build_parser() -> Parser:
    from .verify import add_held_out_options

    p = Parser(prog="tactile-host", description=__doc__)
    sub = p.add_subparsers(dest="command", required=True, parser_class=Parser)
    v = sub.add_parser("verify", help="compile the generated C and compare it with the Python evaluation")
    v.add_argument("model", metavar="MODEL")
    v.add_argument("--precision", default="both", choices=("double", "float", "fixed", "both"),
                   help="both: double and float; fixed: the integer header against its numpy model and double")
    v.add_argument("--style", default="both", choices=("table", "unrolled", "both"))
    v.add_argument("--cc", default="gcc", help="C compiler command, with flags if needed (default gcc)")
    v.add_argument("--runner", help="prefix to run the binary with, e.g. qemu-arm")
    v.add_argument("--prefix", default="tm", help="C identifier prefix (default tm)")
    v.add_argument("--vectors", type=int, default=2000, help="random vectors inside the domain (default 2000)")
    v.add_argument("--data", help="also run the rows of this dataset")
    v.add_argument("--fma", action="store_true", help="generate with fused multiply-adds (fitgen codegen --fma)")
    v.add_argument("--input-lsb", type=float, metavar="X", help="fixed: the input value of one ADC code")
    v.add_argument("--input-offset", type=float, metavar="Y", help="fixed: the input value of code 0")
    add_held_out_options(v)
    v.set_defaults(func=cmd_verify)

    pb = sub.add_parser("pi-build", help="the readout in C for a Raspberry Pi: drivers, channel map and model "
                                         "over i2c-dev, built with arm-linux-gnueabihf-gcc")
    pb.add_argument("--model", required=True, metavar="MODEL", help="model file (inputs in V)")
    _map_options(pb)
    pb.add_argument("--precision", default="float", choices=("float", "double"))
    pb.add_argument("--style", default="unrolled", choices=("table", "unrolled"))
    pb.add_argument("--cc", default="arm-linux-gnueabihf-gcc -static",
                    help="compiler and flags (default: arm-linux-gnueabihf-gcc -static; gcc on the Pi itself)")
    pb.add_argument("-o", "--output", required=True, metavar="DIR", help="folder for the sources and tm_pi")
    pb.set_defaults(func=cmd_pi_build)

    f = sub.add_parser("flash", help="load a model into a device as a calibration blob and read it back")
    f.add_argument("model", metavar="MODEL")
    f.add_argument("--port", required=True, metavar="URL",
                   help="serial port: /dev/ttyACM0, /dev/pts/N or socket://HOST:PORT")
    f.add_argument("--sensor-id", default="paper", help="sensor id stored in the blob (ASCII, <= 16 bytes; "
                                                       "default paper)")
    f.add_argument("--fma", action="store_true", help="the device sums the terms by fused multiply-add")
    f.add_argument("--timeout", default="2", help="seconds to wait for each answer (default 2)")
    f.set_defaults(func=cmd_flash)

    r = sub.add_parser("read", help="stream readings and pose estimates from I2C ADCs")
    r.add_argument("--model", required=True, metavar="MODEL", help="model file (inputs in V)")
    _adc_options(r)
    r.add_argument("--rate", help="samples per second (default: as fast as the converters allow)")
    r.add_argument("--format", default="csv", choices=("csv", "jsonl"))
    r.add_argument("-o", "--output", metavar="FILE", help="write the stream here instead of stdout")
    r.add_argument("--count", help="stop after this many samples")
    r.add_argument("--duration", help="stop after this many seconds")
    r.add_argument("--tare", action="store_true", help="measure the rest readings first and correct the offsets")
    r.add_argument("--tare-samples", default="50", help="samples averaged for --tare (default 50)")
    r.add_argument("--rest", metavar="SENSOR|DATASET.csv",
                   help="the rest readings --tare maps onto: a dataset's rows at pose 0, or a sensor's physics "
                        "(default: --sensor)")
    r.add_argument("--engine", default="python", choices=("python", "c"),
                   help="python: Model.predict; c: the generated header as a shared library (default python)")
    r.add_argument("--precision", default="double", choices=("double", "float"), help="C engine precision")
    r.add_argument("--cc", default="gcc", help="C compiler for --engine c (default gcc)")
    r.add_argument("--simulate", metavar="POSE",
                   help="no hardware: a simulated bus with the sensor at POSE, e.g. dx=1,dz=-1 or 0.5,0,-1,0,0")
    r.set_defaults(func=cmd_read)

    c = sub.add_parser("capture", help="record a calibration dataset, one averaged row per scheduled pose")
    c.add_argument("--poses", required=True, metavar="SCHEDULE.csv", help="poses to visit: columns of dx,dy,dz,thx,thy")
    _adc_options(c)
    c.add_argument("-o", "--output", required=True, metavar="DATASET.csv",
                   help="dataset to write; an existing one is resumed")
    c.add_argument("--samples", default="16", help="samples averaged per pose (default 16)")
    c.add_argument("--max-spread", default="0.003", metavar="V",
                   help="largest standard deviation of an element over the samples, V (default 0.003)")
    c.add_argument("--tries", default="3", help="measurements of a pose before giving up on its spread (default 3)")
    c.add_argument("--trigger", metavar="CMD",
                   help="shell command run for each pose instead of waiting for Enter; it gets TM_POSE_INDEX, "
                        "TM_DX..TM_THY and must exit 0 once the pose is set")
    c.add_argument("--settle", default="0", help="seconds to wait after Enter or the trigger (default 0)")
    c.add_argument("--simulate", action="store_true",
                   help="no hardware: a simulated sensor that moves to each scheduled pose by itself")
    c.set_defaults(func=cmd_capture)
    return p


def _main(argv) -> int:
    args = build_parser().parse_args(argv)
    return args.func(args)


def main(argv=None) -> int:
    sys.exit(run(_main, argv, "tactile-host"))
