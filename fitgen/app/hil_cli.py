"""tactile-hil: hardware-in-the-loop checks of the reference firmware, on a board or an emulated Cortex-M4.

  run       send vectors, calibrations and fuzz frames to a device and compare with Python
  emulate   build the firmware with a model and boot it (QEMU's mps2-an386 or micro:bit, simavr's Uno, or the host
            build on a pty)
"""

from __future__ import annotations

import argparse
import sys
import time

from fitgen.app.cliutil import (EXIT_CHECK_FAILED, STYLE_WITH_FIXED, Parser, StopFlag, check_written,
                               check_not_empty, command_main, count, degc, noise_volts, seconds, tcp_port)
from fitgen.app.outputkind import check_output_kind
from fitgen.base.errors import InputError


def _load(args, needs_id: bool = True):
    """The model and the --data inputs; ``needs_id``: the sensor id is compiled in or flashed (run --no-flash
    does neither, and a unit's name no blob carries is then no matter)."""
    from fitgen.c.calblob import model_sensor_id
    from fitgen.c.verify import data_inputs
    from fitgen.equations.model import load_model
    from hil.firmware import check_sensor_id as check_compiled_id

    model = load_model(args.model)
    if args.sensor_id is None and needs_id:  # the model's sensor, where the firmware compiles it in, a blob carries
        args.sensor_id = model_sensor_id(model, also=check_compiled_id)
    return model, (data_inputs(model, args.data) if getattr(args, "data", None) else None)


def _check_counts(args) -> None:
    from fitgen.c.verify import check_vectors

    check_vectors(args.vectors)
    if not 0 <= args.fuzz <= MAX_FUZZ:
        raise InputError(f"--fuzz must be a whole number from 0 to {MAX_FUZZ:,}, got {args.fuzz}")


def _suite(url: str, model, data, args, input_lsb: float | None = None) -> int:
    """The suite against ``url``; ``input_lsb``: a fixed-point firmware's ADC code scale (its channel map's)."""
    from fitgen.c.targets import TARGETS
    from host.device import BOOT_WAIT, Device
    from fitgen.c.verify import held_out_from_args, no_held_out_note

    from hil.suite import run_suite

    held_out = held_out_from_args(model, args)
    with Device.open(url, timeout=args.timeout, ready=BOOT_WAIT) as dev:
        res = run_suite(dev, model, url=url, n_vectors=args.vectors, data=data, n_fuzz=args.fuzz,
                        flash=not args.no_flash, sensor_id=args.sensor_id, fma=args.fma, held_out=held_out,
                        max_share=args.max_share, input_lsb=input_lsb,
                        input_offset=0.0 if input_lsb is not None else None,
                        mul_bits=TARGETS[args.target].mul_bits if args.target in TARGETS else None)
    print(res.table())
    if held_out is None and not args.no_held_out:
        print(no_held_out_note(model))
    if args.junit:
        res.write_junit(args.junit)
    print("PASS" if res.ok else "FAIL")
    return 0 if res.ok else EXIT_CHECK_FAILED


def cmd_run(args) -> int:
    _check_counts(args)
    model, data = _load(args, needs_id=not args.no_flash)
    return _suite(args.port, model, data, args)


def _describe(runner, dev, target: str, compiled: str = "") -> None:
    from hil.emulate import bench_instructions

    info = dev.info()
    if target == "uno":
        # the Uno's ticks are its CPU cycles (simavr's count); 16 MHz makes thousands of estimates slow
        b = bench_instructions(dev, 10, 60)
        cost = f"{b['ticks_per_estimate']:.0f} cycles per estimate (simavr), {b['tick_hz'] / b['ticks_per_estimate']:.0f} " \
               f"estimates/s at 16 MHz"
    else:
        b = bench_instructions(dev)
        cost = (f"{b['instructions']:.0f} instructions per estimate (icount)" if b["instructions"] is not None
                else f"{b['ns']:.0f} ns per estimate")
    print(f"{target} firmware: {info.precision}, {info.style_name}, model {info.model_hash[:12]}; {cost}")
    if info.cal_source == 1:  # the Uno's EEPROM kept a calibration flashed in an earlier run of this build folder
        where = getattr(runner, "eeprom", None)
        print(f"  (model {info.model_hash[:12]} is a calibration flashed earlier, kept in {where or 'EEPROM'}: "
              f"remove it to run the compiled-in model {compiled[:12]})")
    if runner.size:
        print(f"flash {runner.size['flash']} bytes, RAM {runner.size['ram']} bytes")
    if info.adc_chips:
        print("inputs from " + ", ".join(f"{c[0]}@0x{c[1]:02x} ({c[2]} inputs)" for c in info.adc_chips)
              + (" on the TWI bus" if target == "uno" else " over the I2C bridge") + ", answered by the bus model")


def _adc_bridge(args, model):
    """(channel map, stand-in bus, thermistor input, compensation) for --adc, or Nones."""
    from hil.bridge import adc_bridge

    if args.adc is not None and not args.adc.strip():
        raise InputError("--adc is empty: give the channel map, e.g. ads1115@0x48:0-3,ads1115@0x49:0-3")
    if not args.adc:
        bus = ("simulate", "temp_comp", "thermistor", "sim_temperature", "sim_sensor", "sim_noise", "seed")
        given = [f"--{k.replace('_', '-')}" for k in bus if getattr(args, k) is not None]
        if given:  # none of them reaches a firmware that reads the serial protocol
            raise InputError(f"{', '.join(given)} {'goes' if len(given) == 1 else 'go'} with --adc (without it the "
                             "firmware's inputs come from the serial protocol)")
        return None, None, None, None
    out = adc_bridge(args.adc, args.simulate or "0,0,0,0,0", sensor=args.sim_sensor, noise=args.sim_noise,
                     seed=args.seed or 0, thermistor=args.thermistor, temp_comp=args.temp_comp,
                     temperature=args.sim_temperature, n_inputs=model.n_inputs)
    if (tempcomp := out[3]) is not None:  # as read and pi-build say of the compensation they compile in
        from host.temperature import channel_map_note
        from host.tempunit import model_note

        option = f"--temp-comp {args.temp_comp}"
        for note in (channel_map_note(tempcomp, out[0], option), model_note(model, tempcomp, option)):
            if note:
                print(f"emulate: {note}", file=sys.stderr)
    return out


def _stopped(runner, args, advice, before: bool = True) -> None:
    """InputError with the board's own last words when the firmware ended (``before`` it could be opened, or
    while it was being measured); on the Uno, ``advice()``: what to try (hil.emulate.uno_crash_advice)."""
    if runner.proc is None or runner.proc.poll() is None:
        return
    runner.stop()
    said = "; ".join(getattr(runner, "messages", [])[-2:]) or f"exit status {runner.proc.returncode}"
    hint = advice() if args.target == "uno" else ""
    raise InputError(f"the {args.target} firmware stopped{' before answering' if before else ''}: {said}{hint}")


def _ending(runner) -> str:
    """How a firmware that ended while emulate waited ended: a signal (QEMU says it was stopped by one, and exits
    0), else its exit status and its last word on stderr."""
    rc = runner.proc.returncode
    if rc < 0:
        return f"killed by signal {-rc} from outside"
    err = runner.proc.stderr.read() if runner.proc.stderr is not None and not runner.proc.stderr.closed else ""
    lines = (err.decode(errors="replace") if isinstance(err, bytes) else err or "").strip().splitlines()
    # simavr's board ends with its counts (STACK n, CYCLES n): the reason is the line before them
    last = [ln for ln in lines if ln.strip() and ln.split(" ")[0] not in ("STACK", "CYCLES")][-1:]
    if last and "terminating on signal" in last[0]:
        return f"stopped from outside ({last[0].strip()})"
    return f"exit status {rc}" + (f" ({last[0].strip()})" if last else "")


def cmd_emulate(args) -> int:
    from host.device import Device

    from contextlib import ExitStack

    from fitgen.base.progress import Progress
    from fitgen.fitting.holdout import device_precision, simulated_sensor_spec
    from hil.emulate import start_target, uno_crash_advice

    _check_counts(args)
    if args.precision == "fixed" and args.style is not None:  # as codegen refuses it: it would be ignored
        raise InputError(STYLE_WITH_FIXED)
    if args.target == "host" and args.port is not None:  # its UART is a pseudo-terminal, not a TCP port
        raise InputError("--port is the emulated UART's TCP port, and the host target has none (its UART is a "
                         "pseudo-terminal): drop --port")
    model, data = _load(args)
    # as codegen --target and arduino-build: a model fitted for fixed point runs in it (--style, --fma and
    # --temp-comp ask for float)
    fixed = args.target == "microbit" or (device_precision(model) == "fixed" and args.style is None
                                          and not args.fma and not args.temp_comp)  # each asks for float
    args.precision = args.precision or ("fixed" if fixed else "float")
    args.style = args.style or "table"
    if args.adc and not args.sim_sensor:  # the model's own, where found (without --adc, --sim-sensor is refused)
        args.sim_sensor, lost = simulated_sensor_spec(model, "--sim-sensor")
        if lost:
            print(f"tactile-hil emulate: {lost}", file=sys.stderr)
    cmap, bridge, tin, tempcomp = _adc_bridge(args, model)
    if tin is not None and args.target == "uno":  # its stack had run into static RAM mid-suite, the model's size aside
        raise InputError("--target uno reads no thermistor: its reads need an ADC array of their own, which the "
                         "Uno's 2 KB of RAM do not hold beside the elements' and a float model's stack (drop temp= "
                         "from --adc; --target mps2 emulates one, tactile-host read and pi-build read one)")
    with ExitStack() as stack:
        with Progress(f"{args.target} firmware", 2) as bar:  # building and booting take seconds
            bar.update(0, "building")
            target = start_target(model, args.target, precision=args.precision, style=args.style, fma=args.fma,
                                  port=args.port, workdir=args.build_dir, sensor_id=args.sensor_id, cmap=cmap,
                                  bridge=bridge, tin=tin, tempcomp=tempcomp)
            bar.update(1, "booting")
            runner = stack.enter_context(target)
        def advice():
            return uno_crash_advice(model, args.precision, args.style, fma=args.fma, sensor_id=args.sensor_id,
                                    cmap=cmap, tin=tin, tempcomp=tempcomp)

        try:
            dev = Device.open(runner.url, timeout=args.timeout)
        except InputError:
            _stopped(runner, args, advice)
            raise
        with dev:
            try:  # its first estimates: a stack that overruns the Uno's RAM ends the board here, not at boot
                _describe(runner, dev, args.target, model.sha256)
            except InputError:
                time.sleep(0.2)  # the board's exit and the host's time-out race: let the board's word come first
                _stopped(runner, args, advice, before=False)
                raise
        if args.suite:
            from hil.firmware import adc_input_lsb

            lsb = adc_input_lsb(cmap) if cmap is not None and args.precision == "fixed" else None
            try:
                return _suite(runner.url, model, data, args, lsb)
            except InputError:  # a board that ended mid-suite (the Uno's stack in a stream): its own last words
                time.sleep(0.2)
                _stopped(runner, args, advice, before=False)
                raise
        # a flag, not an Event: Event.set in a handler deadlocks when the signal lands while wait holds its lock
        with StopFlag() as stop:  # set before "ready": a caller may stop it the moment it reads that
            print(f"ready: {runner.url} (Ctrl-C stops)", flush=True)
            while not stop() and runner.proc is not None and runner.proc.poll() is None:
                time.sleep(0.2)
        if not stop():
            raise InputError(f"the {args.target} firmware ended: {_ending(runner)}")
    print("stopped", file=sys.stderr)
    return 0


VECTORS, FUZZ = 1000, 10_000  # the suite's defaults
MAX_FUZZ = 1_000_000  # frames: about an hour through an emulator


def _suite_options(p, suite=None) -> None:
    """The options ``run`` and ``emulate`` share; the suite's own go into ``suite`` when given (emulate's group of
    options that need --suite)."""
    from fitgen.c.verify import MAX_VECTORS, add_held_out_options

    s = suite or p
    p.add_argument("--model", required=True, metavar="MODEL", help="the model compiled into the firmware")
    s.add_argument("--vectors", type=int, default=VECTORS,
                   help=f"random vectors inside the domain (default {VECTORS}, at most {MAX_VECTORS:,})")
    s.add_argument("--data", metavar="CSV", help="also send the rows of this dataset")
    s.add_argument("--fuzz", type=int, default=FUZZ, help="random or mutated frames to send "
                   f"(default {FUZZ}, at most {MAX_FUZZ:,})")
    s.add_argument("--no-flash", action="store_true", help="skip the calibration flashing checks")
    s.add_argument("--junit", metavar="FILE", help="also write the results as JUnit XML")
    p.add_argument("--sensor-id", help="sensor id compiled in and written into flashed blobs (default: the name of "
                                       "the sensor the model's held-out figures are for, a unit file's, refused "
                                       "where it cannot be one; paper for a model that names none)")
    p.add_argument("--fma", action="store_true", help="the compiled-in model sums terms by fma")
    p.add_argument("--timeout", type=seconds, default=2.0, help="seconds to wait for each reply (default 2)")
    add_held_out_options(s)


# emulate's options that only the suite uses: refused without --suite (they would be ignored)
SUITE_ONLY = ("vectors", "data", "fuzz", "no_flash", "junit", "max_share", "sensor", "no_held_out")


def _suite_defaults() -> dict:
    """The defaults of SUITE_ONLY's options that have one: None in emulate's parser, so that one typed (even as its
    default) is told from one left out. --max-share's is filled by fitgen.c.verify.held_out_from_args, which
    refuses it with --no-held-out."""
    return {"vectors": VECTORS, "fuzz": FUZZ}


def build_parser() -> Parser:
    p = Parser(prog="tactile-hil", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="command", required=True, parser_class=Parser)
    r = sub.add_parser("run", help="run the HIL suite against a device")
    r.add_argument("--port", required=True, metavar="URL",
                   help="serial device, pty path, or socket://127.0.0.1:PORT (the emulator)")
    r.add_argument("--target", choices=("uno", "microbit", "mps2", "pi"),
                   help="the core the firmware was built for: a fixed-point build is compared with its plan "
                        "(uno: the plan for a 16-bit multiply; default: as the firmware's version in INFO says: +uno for the Uno)")
    _suite_options(r)
    r.set_defaults(func=cmd_run)

    from hil.emulate import TARGETS  # a board added there is a target here

    e = sub.add_parser("emulate", help="build the firmware with a model and boot it")
    e.add_argument("--target", default="mps2", choices=TARGETS,
                   help="mps2: Cortex-M4F in qemu-system-arm (default); microbit: Cortex-M0 (nRF51, fixed point "
                        "only); uno: the Arduino Uno's ATmega328P in simavr (float or fixed; --adc puts the chips "
                        "on its TWI bus); host: the POSIX build on a pty")
    e.add_argument("--port", type=tcp_port, help="TCP port of the emulated UART (default: a free one)")
    e.add_argument("--precision", choices=("float", "double", "fixed"),
                   help="the firmware's arithmetic (default float, or fixed for a model fitted for it; on the "
                        "microbit fixed, its only one)")
    e.add_argument("--style", choices=("table", "unrolled"),
                   help="the C's form: table (coefficient arrays and a loop; default) or unrolled (straight-line "
                        "code); not with --precision fixed, whose header is straight-line code")
    e.add_argument("--build-dir", metavar="DIR",
                   help="keep the firmware sources and image here: a new or empty folder, or an earlier build's")
    e.add_argument("--suite", action="store_true",
                   help="run the HIL suite against it (with its own options, below), then stop")
    e.add_argument("--adc", metavar="SPEC|FILE.toml",
                   help="the firmware reads its inputs from these ADCs (a channel map, as tactile-host read --adc) "
                        "over the emulated board's I2C (the Uno's TWI, the ARM boards' bridge), answered by the bus "
                        "model of --simulate")
    e.add_argument("--simulate", metavar="POSE",
                   help="with --adc: the bus model's magnet pose dx,dy,dz,thx,thy (default rest)")
    e.add_argument("--sim-sensor", help="with --adc: the simulated sensor, gmr (default: the sensor the model was "
                                        "fitted on where its file is found, else paper)")
    e.add_argument("--sim-noise", type=noise_volts,
                   help="with --adc: simulated element noise, V rms (default: the sensor's)")
    e.add_argument("--seed", type=count, help="with --adc: seed of the simulated noise (default 0)")
    e.add_argument("--thermistor", metavar="beta=..,r25=..,series=..,vref=..",
                   help="with temp= in --adc: the thermistor's NTC divider (default beta=3950,r25=10000,series=10000)")
    e.add_argument("--temp-comp", metavar="FILE.json",
                   help="with temp= in --adc: temperature compensation before the model (float and double builds)")
    e.add_argument("--sim-temperature", type=degc, metavar="DEGC",
                   help="with --adc: the simulated sensor at this temperature (typical coefficients, seed --seed)")
    _suite_options(e, e.add_argument_group("the HIL suite's options (only with --suite: refused without it)"))
    e.set_defaults(func=cmd_emulate, **dict.fromkeys(_suite_defaults()))
    return p


def _check(args) -> None:
    """Options checked before a model is loaded, firmware built or a device opened: under emulate, the suite's
    options without --suite; --junit's file, --sensor-id (as the firmware compiles it in under emulate; as a
    flashed blob carries it under run)."""
    from fitgen.c.calblob import check_sensor_id
    from hil.firmware import check_sensor_id as check_compiled_id

    check_not_empty(args)
    if args.command == "emulate":
        _suite_alone(args)
    check_written(args)
    check_output_kind(args)
    if args.sensor_id is not None:
        (check_compiled_id if args.command == "emulate" else check_sensor_id)(args.sensor_id)


def _suite_alone(args) -> None:
    """InputError for a suite option given to emulate without --suite; then those left out take their defaults."""
    from host.session import refuse_alone

    # a flag is given when True, any other option when not None: `--vectors 0` is given too (0 == False)
    values = [(name, getattr(args, name)) for name in SUITE_ONLY]
    refuse_alone([(v is not None and v is not False, "--" + name.replace("_", "-"), "--suite", args.suite)
                  for name, v in values])
    for name, value in _suite_defaults().items():
        if getattr(args, name) is None:
            setattr(args, name, value)


def main(argv=None) -> int:
    command_main(build_parser, argv, "tactile-hil", _check)
