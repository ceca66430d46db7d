"""The ``tactile-host`` command: tools that run beside hardware."""

from __future__ import annotations

import sys

from fitgen.app.cliutil import EXIT_CHECK_FAILED, Parser, run
from fitgen.base.errors import InputError

from host.channelmap import ADS1115_PGA, ADS1115_RATES, MODES


def cmd_verify(args) -> int:
    from fitgen.c.codegen import STYLES
    from fitgen.physics.dataset import load_dataset
    from fitgen.equations.model import load_model

    from fitgen.c.verify import held_out_from_args, verify

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
    from fitgen.c.calblob import to_blob
    from fitgen.equations.model import load_model

    from host.device import Device, DeviceError
    from host.protocol import ProtocolError

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
    from host.channelmap import Settings, channel_map
    from host.temperature import split_channel_map

    settings = Settings(pga=args.pga, data_rate=args.data_rate, mode=args.mode, vref=_vref(args.vref)).checked("option")
    return channel_map(split_channel_map(args.adc)[0], settings)


def _open_bus(args, cmap, simulate_pose, *, motion=None, drift=None, thermistor=None):
    """Bus and clock from the options; with a simulated pose, the simulated bus instead of /dev/i2c-N."""
    from fitgen.physics.sensor import load_sensor

    from host.adc import open_bus
    from host.clock import REAL_CLOCK
    from host.simbus import simulated_bus

    sim_opts = [o for o, v in (("--sim-noise", args.sim_noise), ("--sim-fault", args.sim_fault),
                               ("--sim-offsets", args.sim_offsets)) if v is not None]
    if simulate_pose is None:
        if sim_opts:
            raise InputError(f"{sim_opts[0]} needs --simulate")
        number = args.bus if args.bus is not None else (cmap.bus if cmap.bus is not None else 1)
        return open_bus(number), REAL_CLOCK
    bus = simulated_bus(cmap, load_sensor(args.sensor), simulate_pose, clock=REAL_CLOCK, noise=args.sim_noise,
                        offsets=args.sim_offsets, faults=args.sim_fault or (), seed=args.seed, motion=motion,
                        drift=drift, thermistor=thermistor)
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


def _motion(spec: str):
    """``--simulate``: a pose, or ``motion`` (a slow circular slide with a press every few seconds)."""
    import numpy as np

    from host.motion import parse_pose

    if spec.strip().lower() != "motion":
        return parse_pose(spec), None

    def motion(t: float):
        # 8 s circle of 1 mm radius; every 6 s a 1.5 s press to dz = -1 mm with a little tilt
        phase = (t % 6.0) / 1.5
        press = np.sin(np.pi * phase) if phase < 1.0 else 0.0
        return np.array([np.cos(2 * np.pi * t / 8), np.sin(2 * np.pi * t / 8), -press, 2.0 * press, -1.0 * press])

    return np.zeros(5), motion


def _sim_drift(spec: str | None, n: int):
    """``--sim-drift ramp=5,over=300,tau=100,creep=0.002,start=25,seed=0``: host.simsensor.Drift."""
    from fitgen.base.parse import parse_assignments

    from host.simsensor import Drift

    if spec is None:
        return None
    keys = ("ramp", "over", "tau", "creep", "start", "seed")
    vals = parse_assignments(spec, keys, "--sim-drift")
    over, tau = vals.get("over", 600.0), vals.get("tau", 600.0)
    if not (over > 0 and tau > 0):
        raise InputError(f"--sim-drift {spec!r}: over and tau must be > 0 s")
    d = Drift.typical(n, seed=int(vals.get("seed", 0)), ramp_degc=vals.get("ramp", 5.0), ramp_s=over,
                      creep_tau=tau, start_degc=vals.get("start", 25.0))
    if "creep" in vals:
        d.creep = d.creep / 2e-3 * vals["creep"]
    return d


class _Session:
    """What ``read`` and ``view`` share: model, channel map, bus (or simulated bus), ADC array, engine and
    the corrections (tare, auto-zero, temperature), built from the options and closed in one place."""

    def __init__(self, args, prog: str):
        from fitgen.equations.model import load_model

        from host.adc import AdcArray, RetryPolicy
        from host.autozero import AutoZero, AutoZeroSettings
        from host.engine import make_engine
        from host.readout import Corrections, rest_reference, tare
        from host.temperature import Thermometer, load_tempcomp, temperature_input

        self.prog = prog
        self.rate = _positive(args.rate, "--rate") if args.rate is not None else None
        self.count = _positive(args.count, "--count", integer=True) if args.count is not None else None
        self.duration = _positive(args.duration, "--duration") if args.duration is not None else None
        tare_n = _positive(args.tare_samples, "--tare-samples", integer=True)
        retries = _positive(args.retries, "--retries", integer=True)
        pose, motion = _motion(args.simulate) if args.simulate is not None else (None, None)
        cmap0 = _channel_map(args)
        tin = temperature_input(args.adc, cmap0, args.thermistor)
        if args.temp_comp and tin is None:
            raise InputError("--temp-comp needs the temperature: add the thermistor's input to --adc as "
                             "temp=CHIP@ADDRESS:INPUT (e.g. temp=ads1115@0x4a:0)")
        tempcomp = load_tempcomp(args.temp_comp) if args.temp_comp else None
        band = _rest_band(args.rest_band)
        az_settings = AutoZeroSettings(band_mm=band[0], band_deg=band[1],
                                       hold=_positive(args.rest_hold, "--rest-hold")).checked()
        self.model = model = load_model(args.model)
        if model.input_units != "V":
            raise InputError(f"model {args.model} takes inputs in {model.input_units}; the ADCs give volts: fit it on "
                             "a dataset in V (fitgen simulate --transfer gmr, or tactile-host capture)")
        if tempcomp is not None and tempcomp.n != model.n_inputs:
            raise InputError(f"--temp-comp {args.temp_comp} has {tempcomp.n} elements; the model takes {model.n_inputs}")
        self.cmap = cmap = cmap0
        if cmap.n_elements != model.n_inputs:
            raise InputError(f"--adc reads {cmap.n_elements} elements; the model takes {model.n_inputs}")
        need_ref = args.tare or args.auto_zero
        reference = rest_reference(args.rest or args.sensor, model.n_inputs) if need_ref else None
        self.engine = make_engine(args.engine, model, **({"precision": args.precision, "cc": args.cc}
                                                         if args.engine == "c" else {}))
        self.bus = None
        try:
            drift = _sim_drift(args.sim_drift, cmap.n_elements) if args.simulate is not None else None
            if args.sim_drift and args.simulate is None:
                raise InputError("--sim-drift needs --simulate")
            rest_first = pose is not None and need_ref
            # a simulated sensor rests during the tare, then moves to its pose, as a real one is pressed after it
            self.bus, self.clock = _open_bus(args, cmap, None if pose is None else (0 * pose if rest_first else pose),
                                             motion=None if rest_first else motion, drift=drift, thermistor=tin)
            self.array = array = AdcArray(self.bus, cmap, clock=self.clock, policy=RetryPolicy(attempts=retries))
            array.probe()
            array.setup()
            self.thermometer = Thermometer(array, tin, cmap.chips[0].settings) if tin is not None else None
            offsets, noise = None, None
            if need_ref:
                t = tare(array, reference, tare_n)
                print(f"{prog}: {t.describe()}", file=sys.stderr)
                offsets = t.offsets
                noise = t.noise_floor(array.lsb)
                if pose is not None:
                    self.bus.set_pose(pose)
                    self.bus.feed.motion = motion
            autozero = None
            if args.auto_zero:
                autozero = AutoZero(reference, noise, model.output_names, zero=offsets, settings=az_settings)
                autozero.log = lambda text: print(f"{prog}: {text}", file=sys.stderr)
            self.corrections = Corrections(offsets, tempcomp, autozero)
            self.reference, self.noise = reference, noise
        except BaseException:
            self.close()
            raise
        self.source = (f"simulated {args.sensor}: " + ("motion" if motion is not None else
                                                       ",".join(f"{x:g}" for x in pose))
                       if pose is not None else f"I2C bus: {cmap.describe()}")

    def record(self, path):
        from host.readout import RunRecord

        if path is None:
            return None
        try:
            self._record_file = open(path, "w")
        except OSError as exc:
            raise InputError(f"cannot write {path}: {exc.strerror}") from None
        ref = None if self.reference is None else [float(x) for x in self.reference]
        return RunRecord(self._record_file, {"model": self.model.sha256, "outputs": list(self.model.output_names),
                                             "n_inputs": self.model.n_inputs, "source": self.source,
                                             "reference": ref, "noise": self.noise,
                                             **self.corrections.describe(), "model_file": self.model.to_dict()})

    def close(self):
        self.engine.close()
        f = getattr(self, "_record_file", None)
        if f is not None:
            f.close()
        if self.bus is not None:
            self.bus.close()


def _rest_band(text: str) -> tuple[float, float]:
    parts = text.replace(",", " ").split()
    try:
        mm, deg = (float(p) for p in parts)
    except ValueError:
        raise InputError(f"--rest-band {text!r}: give MM,DEG, e.g. 0.08,1.5") from None
    return mm, deg


def cmd_read(args) -> int:
    from host.adc import DeviceSilent
    from host.readout import LineFormat, Readout

    s = _Session(args, "tactile-host read")
    sink = None
    try:
        fmt = LineFormat(args.format, s.model.n_inputs, s.model.output_names)
        if args.output:
            try:
                sink = open(args.output, "w")
            except OSError as exc:
                raise InputError(f"cannot write {args.output}: {exc.strerror}") from None
        out = sink or sys.stdout
        out.write(fmt.header)
        reader = Readout(s.array, s.engine, out, fmt, clock=s.clock, corrections=s.corrections,
                         thermometer=s.thermometer, record=s.record(args.record))
        with _StopFlag() as stop:
            stats = reader.run(rate=s.rate, count=s.count, duration=s.duration, stop=stop)
        how = "stopped" if stop.stopped else "done"
        print(f"tactile-host read: {how}: {stats.summary()}", file=sys.stderr)
        return 0
    except DeviceSilent as exc:
        done = getattr(exc, "stats", None)
        where = f"stopped after {done.summary()}" if done is not None else "stopped before the first sample"
        print(f"tactile-host read: error: {exc}; {where}", file=sys.stderr)
        return EXIT_CHECK_FAILED
    finally:
        s.close()
        if sink is not None:
            sink.close()


def cmd_view(args) -> int:
    from host.adc import DeviceSilent
    from host.live import LiveHub, LiveServer, view_meta
    from host.readout import LineFormat, Readout

    if args.replay:
        return _view_replay(args)
    if args.model is None or args.adc is None:
        raise InputError("view needs --model and --adc (or --replay RUN.jsonl)")
    s = _Session(args, "tactile-host view")
    server = None
    try:
        hub = LiveHub(view_meta(s.model.n_inputs, s.model.output_names, s.model.sha256, s.source, s.rate))
        server = LiveServer(hub, args.host, args.port)
        server.start()
        print(f"tactile-host view: serving {server.url} ({s.source}); Ctrl-C stops", file=sys.stderr, flush=True)
        fmt = LineFormat("csv", s.model.n_inputs, s.model.output_names)
        reader = Readout(s.array, s.engine, None, fmt, clock=s.clock, corrections=s.corrections,
                         thermometer=s.thermometer, observer=hub.publish, record=s.record(args.record))
        with _StopFlag() as stop:
            stats = reader.run(rate=s.rate, count=s.count, duration=s.duration, stop=stop)
        print(f"tactile-host view: {'stopped' if stop.stopped else 'done'}: {stats.summary()}", file=sys.stderr)
        return 0
    except DeviceSilent as exc:
        print(f"tactile-host view: error: {exc}", file=sys.stderr)
        return EXIT_CHECK_FAILED
    finally:
        if server is not None:
            server.stop()
        s.close()


def _view_replay(args) -> int:
    import time

    from host.live import LiveHub, LiveServer, view_meta
    from host.replay import load_run, replay

    run = load_run(args.replay)
    res = replay(run, model=args.model, auto_zero=_flag(args), temp_comp=args.temp_comp)
    hub = LiveHub(view_meta(run.n_inputs, res.outputs, res.model_hash, f"replay of {args.replay}", None))
    server = LiveServer(hub, args.host, args.port)
    server.start()
    print(f"tactile-host view: serving {server.url} (replay of {args.replay}, {len(res.t)} samples); Ctrl-C stops",
          file=sys.stderr, flush=True)
    try:
        with _StopFlag() as stop:
            t0, w0 = res.t[0], time.monotonic()
            for i in range(len(res.t)):
                if stop():
                    break
                wait = (res.t[i] - t0) - (time.monotonic() - w0)
                if wait > 0:
                    time.sleep(wait)
                hub.publish(res.sample(i))
            while args.hold and not stop():
                time.sleep(0.2)
    finally:
        server.stop()
    return 0


def _flag(args):
    """--auto-zero / --no-auto-zero for replay: True, False, or None (as recorded)."""
    return True if args.auto_zero else (False if getattr(args, "no_auto_zero", False) else None)


def cmd_tempcomp_c(args) -> int:
    from fitgen.base.fileio import write_in_folder

    from host.temperature import load_tempcomp, render_c

    tc = load_tempcomp(args.tempcomp)
    path = write_in_folder(args.output, f"{args.prefix}_tempcomp.h", render_c(tc, args.prefix, args.precision))
    print(f"wrote {path} ({tc.n} elements about {tc.t0:g} degC, {args.precision}); call "
          f"{args.prefix}_tempcomp(v, degc) on the readings before {args.prefix}_estimate", file=sys.stderr)
    return 0


def cmd_replay(args) -> int:
    from host.replay import load_run, replay

    run = load_run(args.run)
    res = replay(run, model=args.model, auto_zero=_flag(args), temp_comp=args.temp_comp,
                 no_temp_comp=args.no_temp_comp)
    if args.output:
        res.save(args.output)
    print(res.report(), end="")
    return 0


def _temperatures(text: str) -> list[float]:
    import math

    try:
        vals = [float(x) for x in text.replace(",", " ").split()]
    except ValueError:
        raise InputError(f"--temperature {text!r}: give temperatures in degC, e.g. 15,25,35") from None
    if len(vals) < 2 or len(set(vals)) != len(vals) or not all(math.isfinite(v) and -40 <= v <= 125 for v in vals):
        raise InputError(f"--temperature {text!r}: give two or more different temperatures in -40..125 degC")
    return vals


def _capture_numbers(args) -> tuple:
    """--samples, --max-spread, --tries, --settle and --retries, checked."""
    return (_positive(args.samples, "--samples", integer=True), _positive(args.max_spread, "--max-spread"),
            _positive(args.tries, "--tries", integer=True), _positive(args.settle, "--settle", zero=True),
            _positive(args.retries, "--retries", integer=True))


def cmd_capture_temperatures(args) -> int:
    """``capture --temperature T1,T2,..``: the schedule at each temperature, then the compensation fitted."""
    from pathlib import Path

    import numpy as np

    from fitgen.physics.dataset import load_dataset

    from host.adc import AdcArray, DeviceSilent, RetryPolicy
    from host.capture import SpreadTooLarge, TriggerFailed, capture, enter_waiter, load_schedule, trigger_waiter
    from host.simsensor import Drift
    from host.temperature import Thermometer, fit_tempcomp, temperature_input

    temps = _temperatures(args.temperature)
    samples, spread, tries, settle, retries = _capture_numbers(args)
    schedule = load_schedule(args.poses)
    if len(schedule.poses) < 2:
        print("tactile-host capture: note: one pose per temperature gives offsets only (gain needs two poses)",
              file=sys.stderr)
    cmap = _channel_map(args)
    tin = temperature_input(args.adc, cmap, args.thermistor)
    out = Path(args.output)
    drift = None
    if args.simulate:
        drift = (_sim_drift(args.sim_drift, cmap.n_elements) or Drift.typical(cmap.n_elements, seed=args.seed)
                 ).steady(temps[0])
    bus, clock = _open_bus(args, cmap, schedule.poses[0] if args.simulate else None, drift=drift, thermistor=tin)
    rows, pose_ids, row_temps, files = [], [], [], []
    try:
        array = AdcArray(bus, cmap, clock=clock, policy=RetryPolicy(attempts=retries))
        array.probe()
        array.setup()
        thermo = Thermometer(array, tin, cmap.chips[0].settings) if tin is not None else None
        for T in temps:
            path = out.with_name(f"{out.stem}.T{T:g}{out.suffix or '.csv'}")
            if args.simulate:
                drift.start_degc = T
            elif args.trigger:
                pass
            else:
                print(f"tactile-host capture: bring the sensor to {T:g} degC and let it settle, then press Enter",
                      file=sys.stderr, flush=True)
                if not sys.stdin.readline():
                    return 130
            wait = trigger_waiter(args.trigger, schedule) if args.trigger else None
            if wait is None and not args.simulate:
                wait = enter_waiter(schedule)
            capture(array, schedule, path, samples=samples, max_spread=spread, tries=tries, wait=wait,
                    set_pose=bus.set_pose if args.simulate else None, settle=settle, clock=clock,
                    meta={"adc": cmap.describe(), "temperature_set": T,
                          "source": f"simulated {args.sensor}" if args.simulate else "hardware"})
            measured = thermo.read() if thermo is not None else float("nan")
            ds = load_dataset(path, min_rows=1)
            rows.append(ds.inputs)
            pose_ids.append(np.arange(ds.n_rows))
            row_temps.append(np.full(ds.n_rows, measured if np.isfinite(measured) else T))
            files.append(str(path))
            print(f"tactile-host capture: {ds.n_rows} poses at {T:g} degC"
                  f"{f' (thermistor {measured:.2f} degC)' if np.isfinite(measured) else ''} in {path}", file=sys.stderr)
    except (DeviceSilent, SpreadTooLarge, TriggerFailed) as exc:
        print(f"tactile-host capture: error: {exc}; the temperatures done so far are kept: run the same command "
              "again to resume", file=sys.stderr)
        return EXIT_CHECK_FAILED
    finally:
        bus.close()
    tc = fit_tempcomp(np.vstack(rows), np.concatenate(pose_ids), np.concatenate(row_temps),
                      t0=_positive(args.t0, "--t0", zero=True) if args.t0 is not None else None)
    tc.info["captures"] = files
    dest = args.temp_comp_output or str(out.with_name(out.stem + ".tempcomp.json"))
    tc.save(dest)
    worst = max(tc.info["residual_rms_v"]) * 1e3
    print(f"tactile-host capture: temperature compensation about {tc.t0:g} degC -> {dest} (offsets up to "
          f"{np.abs(tc.offset).max() * 1e3:.3g} mV/degC, gains up to {np.abs(tc.gain).max() * 100:.3g} %/degC; "
          f"residual up to {worst:.3g} mV rms)", file=sys.stderr)
    return 0


_STAGE_OPTIONS = ("stage_flavor", "stage_baud", "stage_axes", "stage_limits", "stage_feed", "stage_approach",
                  "stage_timeout", "stage_boot_wait", "home", "unlock", "zero")


def _stage_settings(args, schedule):
    """--stage and its options, checked against the schedule before anything moves (None without --stage)."""
    from host.stage import AxisMap, StageSettings, parse_approach, parse_ranges, parse_zero, stage_url

    given = [o for o in _STAGE_OPTIONS if getattr(args, o) not in (None, False)]
    if args.stage is None:
        if given:
            raise InputError(f"--{given[0].replace('_', '-')} needs --stage gcode:URL")
        if args.sim_pose_file:
            raise InputError("--sim-pose-file needs --stage (the simulated sensor follows a simulated stage)")
        return None
    if args.trigger:
        raise InputError("--stage and --trigger both set the poses: give one")
    if args.temperature is not None:
        raise InputError("--stage with --temperature is not supported yet: capture each temperature on its own")
    if args.simulate and not args.sim_pose_file:
        raise InputError("--simulate with --stage needs --sim-pose-file FILE (the pose file tactile-host stage-sim "
                         "--pose-file FILE writes), or the simulated sensor would never move")
    if args.sim_pose_file and not args.simulate:
        raise InputError("--sim-pose-file needs --simulate")
    if args.stage_limits is None:
        raise InputError("--stage needs --stage-limits, e.g. dx=-3:3,dy=-3:3,dz=-2.5:0.5 (mm from the zero): "
                         "a move outside them is never sent")
    settings = StageSettings(AxisMap.parse(args.stage_axes or "X=dx,Y=dy,Z=dz"),
                             parse_ranges(args.stage_limits, "--stage-limits"),
                             feed=_positive(args.stage_feed or "600", "--stage-feed"),
                             approach=parse_approach(args.stage_approach or "dx=-0.3,dy=-0.3,dz=0.3")).check()
    settings.check_schedule(schedule.poses, schedule.describe)
    return {"url": stage_url(args.stage), "settings": settings, "zero": parse_zero(args.zero or "ask"),
            "baud": _positive(args.stage_baud or "115200", "--stage-baud", integer=True),
            "timeout": _positive(args.stage_timeout or "5", "--stage-timeout"),
            "boot_wait": _positive(args.stage_boot_wait or "2", "--stage-boot-wait", zero=True)}


def _open_stage(args, opts, output, rows):
    """Connect, home or unlock if asked, check the controller's state, and get the zero: (PoseStage, meta)."""
    from host.stage import GcodeController, PoseStage, StageError, StageState, choose_zero, jog_to_zero

    prog = "tactile-host capture"
    ctrl = GcodeController.open(opts["url"], baud=opts["baud"], timeout=opts["timeout"])
    try:
        ctrl.connect(args.stage_flavor or "auto", boot_wait=opts["boot_wait"])
        if args.home:
            print(f"{prog}: homing the stage", file=sys.stderr, flush=True)
            ctrl.home(timeout=max(120.0, opts["timeout"]))
        elif args.unlock:
            ctrl.unlock()
        if ctrl.alarm:
            raise StageError(f"{ctrl.name}: the GRBL controller is in ALARM (it starts so after a reset when homing "
                             "is on): home it (--home) or unlock it (--unlock), then set the zero again")
        ctrl.setup()
        # moves a killed run left queued end first: the position that tells a reset must be a standstill's
        ctrl.wait_idle(60.0 + opts["timeout"], "the moves already queued")
        settings = opts["settings"]
        state = StageState.load(output)
        jogger = PoseStage(ctrl, settings, {})

        def ask(reason):
            print(f"{prog}: {reason}", file=sys.stderr)
            return jog_to_zero(jogger, sys.stdin, sys.stderr, prog)

        zero, how = choose_zero(ctrl, state, settings.axes, opts["zero"], rows=rows, ask=ask)
        homed = ctrl.homed or (how == "kept from the last run" and state.homed)
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


def cmd_capture(args) -> int:
    import time

    from fitgen.base.progress import Progress

    if args.temperature is not None and args.stage is None:
        return cmd_capture_temperatures(args)

    from host.adc import AdcArray, DeviceSilent, RetryPolicy
    from host.capture import (SpreadTooLarge, TriggerFailed, capture, enter_waiter, load_schedule, prepare_output,
                          trigger_waiter)
    from host.stage import StageError

    samples, spread, tries, settle, retries = _capture_numbers(args)
    schedule = load_schedule(args.poses)
    cmap = _channel_map(args)
    state = prepare_output(args.output, cmap.n_elements, schedule, write=False)  # checked before any waiting
    stage_opts = _stage_settings(args, schedule)  # and the stage's settings before anything moves
    total, pending = len(schedule.poses), int((~state.done).sum())
    interactive = not args.trigger and not args.simulate and stage_opts is None
    if args.trigger:
        wait = trigger_waiter(args.trigger, schedule)
    elif args.simulate or stage_opts is not None:
        wait = None  # the stage (simulated or G-code) sets each pose itself
    else:
        wait = enter_waiter(schedule)
    meta = {"adc": cmap.describe(), "source": f"simulated {args.sensor}" if args.simulate else "hardware"}
    motion = None
    if args.sim_pose_file:
        from host.stagesim import pose_file_motion

        motion = pose_file_motion(args.sim_pose_file)
    bus, clock = _open_bus(args, cmap, schedule.poses[0] if args.simulate else None, motion=motion)
    if motion is not None:
        bus.feed.motion_step = 0.0  # follow the stage at every conversion: a move ends between two rows
    keep = f"the rows written so far are kept in {args.output}: run the same command again to resume"
    stage = None
    t0 = time.monotonic()
    try:
        array = AdcArray(bus, cmap, clock=clock, policy=RetryPolicy(attempts=retries))
        array.probe()
        array.setup()
        set_pose = bus.set_pose if args.simulate else None
        if stage_opts is not None:
            stage, meta["stage"] = _open_stage(args, stage_opts, args.output, state.rows)
            meta["stage"]["settle_s"] = settle
            set_pose = stage.move_to
        with Progress("capture", pending) as progress:
            res = capture(array, schedule, args.output, samples=samples, max_spread=spread, tries=tries,
                          wait=wait, set_pose=set_pose, settle=settle,
                          clock=clock, progress=None if interactive else progress, meta=meta)
    except KeyboardInterrupt:
        print(f"tactile-host capture: interrupted; {keep}", file=sys.stderr)
        return 130
    except (DeviceSilent, SpreadTooLarge, TriggerFailed, StageError) as exc:
        from pathlib import Path

        if not Path(args.output).exists():
            keep = "nothing was written"  # the fault came before the first row's file was made
        print(f"tactile-host capture: error: {exc}; {keep}", file=sys.stderr)
        return EXIT_CHECK_FAILED
    finally:
        if stage is not None:
            stage.ctrl.close()
        bus.close()
    done = res.before + res.captured
    note = "; dropped an unfinished last line" if res.dropped_partial else ""
    took = f" in {time.monotonic() - t0:.1f} s" if stage is not None else ""
    if res.complete:
        print(f"tactile-host capture: {done}/{total} poses in {args.output} ({res.captured} captured now{took}, "
              f"{res.before} already there{note})", file=sys.stderr)
    else:
        print(f"tactile-host capture: stopped with {done}/{total} poses in {args.output}{note}; run the same "
              "command again to resume", file=sys.stderr)
    return 0


def cmd_stage_sim(args) -> int:
    """``stage-sim``: a simulated Marlin or GRBL on a loopback port or a pty until Ctrl-C."""
    import time

    from host.stagesim import PoseFile, PtyServer, SimController, SimRig, SocketServer, parse_matrix

    def triple(text, what):
        try:
            vals = [float(x) for x in text.replace(",", " ").split()]
        except ValueError:
            vals = []
        if len(vals) != 3:
            raise InputError(f"{what} {text!r}: three numbers X,Y,Z (mm)")
        return vals

    M = parse_matrix(args.map) if args.map else None
    backlash = _positive(args.backlash, "--backlash", zero=True)
    rep = _positive(args.repeatability, "--repeatability", zero=True)
    contact, start = triple(args.contact, "--contact"), triple(args.start, "--start")
    target = PoseFile(args.pose_file) if args.pose_file else None
    rig = SimRig(target, M, axes=args.axes, contact=contact, start=start, backlash=backlash, repeatability=rep,
                 seed=args.seed)
    ctrl = SimController(args.flavor, rig, homing_lock=args.homing)
    server = PtyServer(ctrl) if args.pty else SocketServer(ctrl, port=args.port)
    with server, _StopFlag() as stop:
        print(server.url, flush=True)
        first = " ".join(f"{a}{c - s:g}" for a, c, s in zip("XYZ", contact, start))
        print(f"tactile-host stage-sim: {args.flavor} on {server.url}; first contact at machine {first} (until "
              f"homed); {'pose in ' + args.pose_file if args.pose_file else 'no pose file'}; Ctrl-C stops",
              file=sys.stderr, flush=True)
        while not stop():
            time.sleep(0.1)
    return 0


def cmd_pi_build(args) -> int:
    from fitgen.equations.model import load_model

    from host.pi import build_pi, render_pi
    from host.temperature import load_tempcomp, temperature_input

    model = load_model(args.model)
    cmap = _channel_map(args)
    tin = temperature_input(args.adc, cmap, args.thermistor)
    tempcomp = load_tempcomp(args.temp_comp) if args.temp_comp else None
    folder = render_pi(model, cmap, args.output, precision=args.precision, style=args.style, tin=tin,
                       tempcomp=tempcomp)
    binary = build_pi(folder, args.cc)
    print(f"wrote {binary} ({cmap.describe()}, model {model.sha256[:12]}, {args.precision}); on the Pi: "
          f"{binary.name} --bus 1 --format csv", file=sys.stderr)
    return 0


def _map_options(p, required: bool = True) -> None:
    p.add_argument("--adc", required=required, metavar="SPEC|FILE.toml",
                   help="channel map: e.g. ads1115@0x48:0-3,ads1115@0x49:0-3 or ads7828@0x48, or a TOML file; "
                        "temp=CHIP@ADDRESS:INPUT adds a thermistor, e.g. ...,temp=ads1115@0x4a:0")
    p.add_argument("--thermistor", metavar="beta=..,r25=..,series=..,vref=..",
                   help="the thermistor's NTC divider (default beta=3950,r25=10000,series=10000,vref=3.3)")
    p.add_argument("--pga", type=float, default=4.096, choices=ADS1115_PGA, metavar="V",
                   help="ADS1115 full scale +-V: 6.144, 4.096 (default), 2.048, 1.024, 0.512, 0.256")
    p.add_argument("--data-rate", type=int, default=860, choices=ADS1115_RATES, metavar="SPS",
                   help="ADS1115 samples per second: 8..860 (default 860)")
    p.add_argument("--mode", default="single", choices=MODES, help="ADS1115 conversion mode (default single)")
    p.add_argument("--vref", default="3.3", help="ADS7828 reference: external volts (default 3.3) or 'internal' (2.5 V)")


def _readout_options(p) -> None:
    """Options read and view share (beside the ADC's)."""
    p.add_argument("--rate", help="samples per second (default: as fast as the converters allow)")
    p.add_argument("--count", help="stop after this many samples")
    p.add_argument("--duration", help="stop after this many seconds")
    p.add_argument("--tare", action="store_true", help="measure the rest readings first and correct the offsets")
    p.add_argument("--tare-samples", default="50", help="samples averaged for --tare (default 50)")
    p.add_argument("--rest", metavar="SENSOR|DATASET.csv",
                   help="the rest readings --tare maps onto: a dataset's rows at pose 0, or a sensor's physics "
                        "(default: --sensor)")
    p.add_argument("--auto-zero", action="store_true",
                   help="tare, then keep re-zeroing slowly while the sensor is at rest (never while touched); "
                        "each update is logged")
    p.add_argument("--rest-band", default="0.08,1.5", metavar="MM,DEG",
                   help="at rest: every displacement estimate within MM and tilt within DEG (default 0.08,1.5)")
    p.add_argument("--rest-hold", default="1", metavar="S", help="seconds at rest before an auto-zero update (default 1)")
    p.add_argument("--temp-comp", metavar="FILE.json",
                   help="per-element temperature compensation (tactile-host capture --temperature); needs the "
                        "thermistor's input in --adc (temp=CHIP@ADDRESS:INPUT)")
    p.add_argument("--record", metavar="RUN.jsonl", help="also record the run at full precision for tactile-host replay")
    p.add_argument("--engine", default="python", choices=("python", "c"),
                   help="python: Model.predict; c: the generated header as a shared library (default python)")
    p.add_argument("--precision", default="double", choices=("double", "float"), help="C engine precision")
    p.add_argument("--cc", default="gcc", help="C compiler for --engine c (default gcc)")
    p.add_argument("--simulate", metavar="POSE|motion",
                   help="no hardware: a simulated bus with the sensor at POSE (e.g. dx=1,dz=-1 or 0.5,0,-1,0,0), or "
                        "'motion': sliding in a circle and pressed every 6 s")
    p.add_argument("--sim-drift", metavar="ramp=5,over=300,tau=100,creep=0.002",
                   help="simulated drift: a temperature ramp (degC over s), creep (V, time constant s)")


def _adc_options(p, required: bool = True) -> None:
    _map_options(p, required)
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
    from fitgen.c.verify import add_held_out_options

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
    pb.add_argument("--temp-comp", metavar="FILE.json", help="temperature compensation before the model (needs "
                    "temp=CHIP@ADDRESS:INPUT in --adc)")
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
    _readout_options(r)
    r.add_argument("--format", default="csv", choices=("csv", "jsonl"))
    r.add_argument("-o", "--output", metavar="FILE", help="write the stream here instead of stdout")
    r.set_defaults(func=cmd_read)

    w = sub.add_parser("view", help="a live web page of the readings and estimates (same options as read)")
    w.add_argument("--model", metavar="MODEL", help="model file (inputs in V)")
    _adc_options(w, required=False)
    _readout_options(w)
    w.add_argument("--host", default="127.0.0.1",
                   help="address to serve on (default 127.0.0.1: this machine only; 0.0.0.0 serves the network)")
    w.add_argument("--port", type=int, default=8765, help="TCP port (default 8765)")
    w.add_argument("--replay", metavar="RUN.jsonl", help="play a recorded run (read/view --record) in the page")
    w.add_argument("--hold", action="store_true", help="with --replay: keep serving after the run's end")
    w.set_defaults(func=cmd_view)

    rp = sub.add_parser("replay", help="re-estimate a recorded run (--record) with another model or corrections")
    rp.add_argument("run", metavar="RUN.jsonl")
    rp.add_argument("--model", metavar="MODEL", help="model to re-estimate with (default: the run's own, if given "
                    "as the file whose hash the run names)")
    rp.add_argument("--auto-zero", action="store_true", help="re-zero at rest (default: as recorded)")
    rp.add_argument("--no-auto-zero", action="store_true", help="no auto-zero (default: as recorded)")
    rp.add_argument("--temp-comp", metavar="FILE.json", help="temperature compensation to apply (default: as recorded)")
    rp.add_argument("--no-temp-comp", action="store_true", help="no temperature compensation")
    rp.add_argument("-o", "--output", metavar="OUT.jsonl", help="write the re-estimated run here")
    rp.set_defaults(func=cmd_replay)

    tcc = sub.add_parser("tempcomp-c", help="the temperature compensation as a C99 header (<prefix>_tempcomp.h)")
    tcc.add_argument("tempcomp", metavar="FILE.json", help="from tactile-host capture --temperature")
    tcc.add_argument("-o", "--output", required=True, metavar="DIR")
    tcc.add_argument("--precision", default="float", choices=("float", "double"))
    tcc.add_argument("--prefix", default="tm", help="C identifier prefix (default tm)")
    tcc.set_defaults(func=cmd_tempcomp_c)

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
    c.add_argument("--temperature", metavar="T1,T2,..",
                   help="capture the schedule at each of these temperatures (degC; one file OUTPUT.T<t>.csv each) and "
                        "fit per-element offset and gain compensation from them (OUTPUT.tempcomp.json)")
    c.add_argument("--t0", metavar="DEGC", help="with --temperature: the calibration temperature (default: the one "
                   "nearest the median)")
    c.add_argument("--temp-comp-output", metavar="FILE.json", help="with --temperature: where the compensation goes")
    c.add_argument("--sim-drift", metavar="ramp=..,over=..,tau=..,creep=..,seed=..",
                   help="with --simulate --temperature: the simulated drift's coefficients (default: typical, seed --seed)")
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
    st.add_argument("--stage-approach", metavar="dx=-0.3,dy=-0.3,dz=0.3",
                    help="where the last move to each pose starts, relative to it (backlash: every pose approached "
                         "from the same side; 0 turns it off for an axis; default dx=-0.3,dy=-0.3,dz=0.3)")
    st.add_argument("--stage-timeout", metavar="S", help="time limit for each answer of the controller (default 5 s, "
                    "plus each move's own time)")
    st.add_argument("--stage-boot-wait", metavar="S", help="seconds to wait for a start-up banner after opening the "
                    "port (boards that reset on connect print one; default 2)")
    st.add_argument("--home", action="store_true", help="home the machine first (G28 / $H): a zero taken on a homed "
                    "machine holds across resets")
    st.add_argument("--unlock", action="store_true", help="GRBL: leave ALARM by $X without homing")
    st.add_argument("--zero", metavar="ask|here|X,Y,Z",
                    help="the stage's zero, first contact with the resting sensor, when the last one does not hold: "
                         "ask (default: jog to it at a prompt), here (new datasets only), or machine coordinates")
    st.add_argument("--sim-pose-file", metavar="FILE",
                    help="with --simulate --stage: the simulated sensor follows the pose tactile-host stage-sim "
                         "--pose-file FILE writes")
    c.set_defaults(func=cmd_capture)

    ss = sub.add_parser("stage-sim", help="a simulated Marlin or GRBL stage on a loopback port or a pty, moving a "
                                          "simulated sensor through a pose file")
    ss.add_argument("--flavor", default="grbl", choices=("grbl", "marlin"))
    ss.add_argument("--port", type=int, default=0, help="TCP port on 127.0.0.1 (default 0: any free one)")
    ss.add_argument("--pty", action="store_true", help="serve on a pseudo-terminal instead (prints its path)")
    ss.add_argument("--pose-file", metavar="FILE", help="write the magnet's pose here (capture --sim-pose-file FILE)")
    ss.add_argument("--map", metavar="a,b,c;d,e,f;g,h,i",
                    help="stage-to-magnet displacement map M, rows (default: identity)")
    ss.add_argument("--axes", default="X=dx,Y=dy,Z=dz", help="the rig's true machine -> sensor axes")
    ss.add_argument("--backlash", default="0.03", help="lost motion per axis on reversal, mm (default 0.03)")
    ss.add_argument("--repeatability", default="0.002", help="random error at the end of each move, mm rms "
                    "(default 0.002)")
    ss.add_argument("--contact", default="12,8,4", help="first contact, mm from the home switches (default 12,8,4)")
    ss.add_argument("--start", default="10,10,10", help="where the carriage stands at power-on, mm from the home "
                    "switches (default 10,10,10; machine coordinates start at 0 there)")
    ss.add_argument("--homing", action="store_true", help="homing on: GRBL starts in ALARM until $H or $X")
    ss.add_argument("--seed", type=int, default=0)
    ss.set_defaults(func=cmd_stage_sim)
    return p


def _main(argv) -> int:
    args = build_parser().parse_args(argv)
    return args.func(args)


def main(argv=None) -> int:
    sys.exit(run(_main, argv, "tactile-host"))
