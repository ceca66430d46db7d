"""The readout session ``read`` and ``view`` share, and the channel map and bus every command opens from its options.

A session checks the options, loads the model, opens the I2C bus (or, with ``--simulate``, a
simulated bus), sets up the ADC array, takes the tare, builds the corrections (tare,
auto-zero, temperature) and the engine, and closes them all in one place.
"""

from __future__ import annotations

import sys
from functools import partial

from fitgen.base.errors import InputError
from fitgen.base.fileio import OutputText
from fitgen.base.parse import LONGEST_RUN, LONGEST_WAIT, MAX_TRIES, parse_numbers, parse_positive
from fitgen.base.progress import Progress
from fitgen.c.codegen import check_magnitudes
from fitgen.equations.model import check_input_units, load_model
from fitgen.fitting.holdout import fitted_sensor_spec, simulated_sensor_spec
from fitgen.physics.pose import POSE_LIMITS, check_above_board
from fitgen.physics.sensor import load_sensor

from host.adc import AdcArray, RetryPolicy, open_bus
from host.autozero import AutoZero, AutoZeroSettings
from host.channelmap import CHIP_SETTINGS, CHIPS, Settings, channel_map, check_bus, check_full_scale
from host.clock import REAL_CLOCK
from host.engine import make_engine
from host.motion import parse_drift, pose_or_motion
from host.readout import Corrections, RunRecord
from host.rest import TARE_SAMPLES, another_unit_note, check_rest_reference, rest_degc, rest_reference, tare
from host.simbus import simulated_bus
from host import tempunit
from host.temperature import (Thermometer, capture_temperature_note, channel_map_note, load_tempcomp,
                              split_channel_map, temperature_input)


def parse_vref(text: str):
    """``--vref``: ``internal`` or the external reference in volts."""
    if text.lower() == "internal":
        return "internal"
    try:
        return float(text)
    except ValueError:
        raise InputError(f"--vref {text!r}: give 'internal' or the external reference in volts") from None


def channel_map_from_args(args):
    """The channel map of ``--adc`` (without its thermistor) and the ADS options; InputError for ``--vref`` when
    no chip it reads (the thermistor's included) is an ADS7828, the only one it sets, and for ``--pga``,
    ``--data-rate`` or ``--mode`` when none is an ADS1115, the only one they set."""
    chosen = {k: getattr(args, k) for k in CHIP_SETTINGS["ads1115"] if getattr(args, k) is not None}
    settings = Settings(**chosen, vref=parse_vref(args.vref or "3.3")).checked("option")  # Settings' defaults
    spec, temp = split_channel_map(args.adc)
    cmap = channel_map(spec, settings)
    if getattr(args, "bus", None) is not None:
        check_bus(args.bus, "--bus")
    temp = temp or (cmap.temperature[0] if cmap.temperature is not None else "")
    kinds = {c.kind for c in cmap.chips} | {k for k in CHIPS if temp.strip().lower().startswith(k)}
    if args.vref is not None and "ads7828" not in kinds:
        raise InputError("--vref sets the ADS7828's reference; no chip in --adc is an ADS7828 (the ADS1115's "
                         "full scale is --pga): drop --vref")
    if chosen and "ads1115" not in kinds:  # the ADS7828 has one range (--vref), one rate and no continuous mode
        flag = "--" + next(iter(chosen)).replace("_", "-")
        raise InputError(f"{flag} sets the ADS1115's conversions; no chip in --adc is an ADS1115 (the ADS7828's full "
                         f"scale is --vref): drop {flag}")
    return cmap


# the bus options read, view and capture take with no argparse default (view --replay refuses one typed)
ADC_DEFAULTS = {"retries": "5", "sensor": "paper", "seed": 0}


def adc_defaults(args) -> None:
    """The options of ADC_DEFAULTS that were left out take their defaults (``args.adc_given``: those typed)."""
    args.adc_given = {name for name in ADC_DEFAULTS if getattr(args, name) is not None}
    for name, value in ADC_DEFAULTS.items():
        if getattr(args, name) is None:
            setattr(args, name, value)


def open_bus_from_args(args, cmap, simulate_pose, *, motion=None, drift=None, thermistor=None):
    """Bus and clock from the options; with a simulated pose, the simulated bus instead of /dev/i2c-N."""
    sim_opts = [o for o, v in (("--sim-noise", args.sim_noise), ("--sim-fault", args.sim_fault),
                               ("--sim-offsets", args.sim_offsets),
                               ("--sim-flicker", args.sim_flicker)) if v is not None]
    if "seed" in getattr(args, "adc_given", ()):
        sim_opts.append("--seed")
    if simulate_pose is None:
        if sim_opts:
            raise InputError(f"{sim_opts[0]} needs --simulate")
        number = args.bus if args.bus is not None else (cmap.bus if cmap.bus is not None else 1)
        return open_bus(number), REAL_CLOCK
    if getattr(args, "bus", None) is not None:
        raise InputError("--bus does not go with --simulate, which opens no bus (without it, it would be ignored)")
    bus = simulated_bus(cmap, load_sensor(args.sensor), simulate_pose, clock=REAL_CLOCK, noise=args.sim_noise,
                        offsets=args.sim_offsets, faults=args.sim_fault or (), seed=args.seed, motion=motion,
                        drift=drift, thermistor=thermistor, flicker=args.sim_flicker)
    return bus, REAL_CLOCK


def parse_rest_band(text: str) -> tuple[float, float]:
    """``--rest-band MM,DEG``."""
    vals = parse_numbers(text)
    if vals is None or len(vals) != 2:
        raise InputError(f"--rest-band {text!r}: give MM,DEG, e.g. 0.08,1.5")
    if not (0 < vals[0] <= POSE_LIMITS[0] and 0 < vals[1] <= POSE_LIMITS[3]):  # of the option, not of the settings
        raise InputError(f"--rest-band {text!r}: both must be numbers > 0, at most {POSE_LIMITS[0]:g} mm, then "
                         f"{POSE_LIMITS[3]:g} deg")
    return vals[0], vals[1]


MAX_TARE_SAMPLES = 100_000  # as tm_pi takes them
MIN_AUTOZERO_TARE = 5  # samples whose spread is the noise floor auto-zero tests rest against


# the readout's options that default to None, so that one typed (even as its default) is told from one left out
READOUT_DEFAULTS = {"engine": "python", "precision": "double", "cc": "gcc",
                    "tare_samples": str(TARE_SAMPLES),
                    "rest_band": "0.08,1.5", "rest_hold": "1"}


def check_depends(args) -> None:
    """InputError for an option given without the one it depends on (it would be ignored without a word); then
    those left out take their READOUT_DEFAULTS."""
    engine_c, ref = args.engine == "c", args.tare or args.auto_zero
    needs = ((args.precision is not None, "--precision", "--engine c", engine_c),
             (args.cc is not None, "--cc", "--engine c", engine_c),
             (args.rest is not None, "--rest", "--tare or --auto-zero", ref),
             (args.tare_samples is not None, "--tare-samples", "--tare or --auto-zero", ref),
             (args.rest_band is not None, "--rest-band", "--auto-zero", args.auto_zero),
             (args.rest_hold is not None, "--rest-hold", "--auto-zero", args.auto_zero),
             (getattr(args, "hold", False), "--hold", "--replay", False))  # view --replay never comes here
    refuse_alone(needs)
    for name, value in READOUT_DEFAULTS.items():
        if getattr(args, name) is None:
            setattr(args, name, value)


def refuse_alone(needs) -> None:
    """InputError for the first (given, option, needed, present) whose option is given without what it needs."""
    for given, option, needed, present in needs:
        if given and not present:
            raise InputError(f"{option} goes with {needed} (without it, it would be ignored)")


MAX_RATE = 100_000.0  # Hz: a hundred times the fastest converter's 860 SPS; past it every sample is late


def parse_rate(text: str) -> float:
    """--rate in Hz: > 0, and a sample at least every LONGEST_WAIT seconds (a slower pace is a slip, and
    would wait between samples for years)."""
    rate = parse_positive(text, "--rate", most=MAX_RATE)
    if rate < 1.0 / LONGEST_WAIT:
        raise InputError(f"--rate must be at least 1/{LONGEST_WAIT:g} (a sample an hour), got {text}")
    return rate


class ReadoutSession:
    """What ``read`` and ``view`` share: model, channel map, bus (or simulated bus), ADC array, engine and
    the corrections (tare, auto-zero, temperature), built from the options and closed in one place."""

    def __init__(self, args, prog: str):
        self.prog = prog
        self.rate = parse_rate(args.rate) if args.rate is not None else None
        self.count = parse_positive(args.count, "--count", integer=True) if args.count is not None else None
        self.duration = (parse_positive(args.duration, "--duration", most=LONGEST_RUN) if args.duration is not None
                         else None)
        check_depends(args)
        sensor_given = args.sensor is not None
        # the sensor is what a simulation simulates, or what a tare rests on when --rest names nothing else
        refuse_alone([(sensor_given, "--sensor", "--simulate, or --tare or --auto-zero without --rest",
                       args.simulate is not None or ((args.tare or args.auto_zero) and not args.rest))])
        adc_defaults(args)
        tare_n = parse_positive(args.tare_samples, "--tare-samples", integer=True)
        if tare_n > MAX_TARE_SAMPLES:  # tm_pi's limit: at 860 SPS a tare of more would keep the sensor still for hours
            raise InputError(f"--tare-samples must be 1..{MAX_TARE_SAMPLES}, got {int(tare_n)}")
        if args.auto_zero and tare_n < MIN_AUTOZERO_TARE:
            raise InputError(f"--auto-zero takes its noise floor from the tare's spread: give --tare-samples "
                             f"{MIN_AUTOZERO_TARE} or more (got {tare_n:g})")
        retries = parse_positive(args.retries, "--retries", integer=True, most=MAX_TRIES)
        pose, motion = pose_or_motion(args.simulate) if args.simulate is not None else (None, None)
        cmap0 = channel_map_from_args(args)
        tin = temperature_input(args.adc, cmap0, args.thermistor)
        if args.temp_comp and tin is None:
            raise InputError("--temp-comp needs the temperature: add the thermistor's input to --adc as "
                             "temp=CHIP@ADDRESS:INPUT (e.g. temp=ads1115@0x4a:0)")
        tempcomp = load_tempcomp(args.temp_comp) if args.temp_comp else None
        band = parse_rest_band(args.rest_band)
        az_settings = AutoZeroSettings(band_mm=band[0], band_deg=band[1],
                                       hold=parse_positive(args.rest_hold, "--rest-hold", most=LONGEST_WAIT)).checked()
        self.model = model = load_model(args.model)
        notes = []  # said once every option has passed: a refusal is one line, not a note and then the refusal
        own = None if sensor_given else fitted_sensor_spec(model)
        if own:  # what --simulate simulates and --tare rests on: the model's own sensor, where found
            args.sensor = own
        elif not sensor_given and args.simulate is not None:
            lost = simulated_sensor_spec(model, "--sensor", args.sensor)[1]
            notes += [lost] if lost else []
        check_input_units(model, "V", "the ADCs' readings", f"model {args.model}")
        check_magnitudes(model, args.precision or "double")  # as predict and codegen: estimates always finite
        if motion is None and pose is not None:  # said of the option here; the simulated bus would say "pose 1"
            check_above_board(load_sensor(args.sensor), pose[None], name=f"--simulate {args.simulate}")
        if tempcomp is not None and tempcomp.n != model.n_inputs:
            raise InputError(f"--temp-comp {args.temp_comp} has {tempcomp.n} elements; the model takes {model.n_inputs}")
        if tempcomp is not None and (note := channel_map_note(tempcomp, cmap0, f"--temp-comp {args.temp_comp}")):
            notes.append(note)
        if tempcomp is not None and (note := tempunit.model_note(model, tempcomp, f"--temp-comp {args.temp_comp}")):
            notes.append(note)
        if tempcomp is not None and tempcomp.fitted_range is None:  # one made by hand, or from Python without it
            notes.append(f"note: --temp-comp {args.temp_comp} records no temperatures it was fitted at "
                         "(fit.temperatures), so samples read far from them are not flagged")
        self.cmap = cmap = cmap0
        if cmap.n_elements != model.n_inputs:
            raise InputError(f"--adc reads {cmap.n_elements} elements; the model takes {model.n_inputs}")
        check_full_scale(cmap, model.input_min, model.input_max)
        need_ref = args.tare or args.auto_zero
        if tempcomp is not None and not need_ref:
            note = capture_temperature_note(model, tempcomp)
            if note:
                notes.append(note)
        # without a file to rest on, the rest readings the model recorded from its own sensor
        recorded = None if args.rest or sensor_given or own or not need_ref else model.held_out_rest
        reference, target = None, (f"--rest {args.rest}" if args.rest else "the model's own record"
                                   if recorded is not None else f"{args.sensor} (the model's)" if own
                                   else f"--sensor {args.sensor}")  # own: no --sensor was typed
        if need_ref:
            reference = recorded if recorded is not None else rest_reference(args.rest or args.sensor, model.n_inputs)
            check_rest_reference(model, reference, target,
                                 degc=None if recorded is not None else rest_degc(args.rest or args.sensor))
        for note in notes:
            print(f"{prog}: {note}", file=sys.stderr)
        self.engine = make_engine(args.engine, model, **({"precision": args.precision, "cc": args.cc}
                                                         if args.engine == "c" else {}))
        self.bus = None
        try:
            drift = parse_drift(args.sim_drift, cmap.n_elements) if args.simulate is not None else None
            if args.sim_drift and args.simulate is None:
                raise InputError("--sim-drift needs --simulate")
            rest_first = pose is not None and need_ref
            # a simulated sensor rests during the tare, then moves to its pose, as a real one is pressed after it
            start = None if pose is None else (0 * pose if rest_first else pose)
            self.bus, self.clock = open_bus_from_args(args, cmap, start, motion=None if rest_first else motion,
                                                      drift=drift, thermistor=tin)
            self.array = array = AdcArray(self.bus, cmap, clock=self.clock, policy=RetryPolicy(attempts=retries))
            array.probe()
            array.setup()
            self.thermometer = Thermometer(array, tin) if tin is not None else None
            offsets, noise = None, None
            if need_ref:
                compensate = None
                if tempcomp is not None and self.thermometer is not None:  # the offsets are taken off compensated
                    compensate = partial(tempcomp.apply, temp=self.thermometer.read(fresh=True))  # readings too
                with Progress(f"{prog}: tare", tare_n) as bar:  # seconds at a low data rate: say so
                    t = tare(array, reference, tare_n, bar.update, compensate)
                print(f"{prog}: {t.describe()}, onto the rest readings of {target}", file=sys.stderr)
                if note := another_unit_note(model, t.offsets):
                    print(f"{prog}: {note}", file=sys.stderr)
                offsets = t.offsets
                noise = t.noise_floor(array.lsb)
                if pose is not None:
                    self.bus.set_pose(pose)
                    self.bus.feed.motion = motion
            autozero = None
            if args.auto_zero:
                autozero = AutoZero.for_model(model, reference, noise, zero=offsets, settings=az_settings)
                if autozero.widened:
                    print(f"{prog}: {autozero.describe_band()}", file=sys.stderr)
                autozero.log = lambda text: print(f"{prog}: {text}", file=sys.stderr)
            self.corrections = Corrections(offsets, tempcomp, autozero)
            self.reference, self.noise, self.rest_source = reference, noise, target if need_ref else None
        except BaseException:
            self.close()
            raise
        self.source = (f"simulated {args.sensor}: " + (args.simulate.strip().lower() if motion is not None else
                                                       ",".join(f"{x:g}" for x in pose))
                       if pose is not None else f"I2C bus: {cmap.describe()}")

    def record(self, path):
        """The run record ``--record`` asks for (None without it), closed with the session."""
        if path is None:
            return None
        self._record_file = OutputText(path)
        ref = None if self.reference is None else [float(x) for x in self.reference]
        return RunRecord(self._record_file, {"model": self.model.sha256, "outputs": list(self.model.output_names),
                                             "n_inputs": self.model.n_inputs, "source": self.source,
                                             "engine": self.engine.name,
                                             "precision": getattr(self.engine, "precision", "double"),
                                             "reference": ref, "rest_source": self.rest_source,
                                             "noise": self.noise,
                                             **self.corrections.describe(), "model_file": self.model.to_dict()})

    def close(self, quiet: bool = False):
        """The engine, the run record and the bus closed, each whatever the others do; a record that could not be
        flushed is said (InputError) unless ``quiet`` (the work ends on another error, the one to say)."""
        try:
            self.engine.close()
        finally:
            try:
                f = getattr(self, "_record_file", None)
                if f is not None:
                    f.close(quiet)
            finally:
                if self.bus is not None:
                    self.bus.close()
