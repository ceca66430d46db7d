"""``capture --temperature``: the schedule captured at each of several temperatures (the sensor brought there,
or the simulated one set there), then the per-element compensation fitted from the captures (host.temperature)."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

from fitgen.base.errors import InputError
from fitgen.base.parse import parse_numbers
from fitgen.physics.dataset import load_dataset, row_degc
from fitgen.physics.sensor import load_sensor

from host.adc import AdcArray, DeviceSilent, RetryPolicy
from host.capture import SpreadTooLarge, capture, load_schedule, simulated_sensor
from host.capturefile import check_resume, output_lock, prepare_output
from host.posewait import TriggerFailed, enter_waiter, trigger_waiter
from host.prompt import ask_line
from host.capturerun import (CaptureFailed, CaptureInterrupted, capture_numbers, kept, same_temperature,
                             same_thermistor, start_degc, trigger_timeout)
from host.motion import parse_drift
from host.session import adc_defaults, channel_map_from_args, open_bus_from_args, refuse_alone
from host.simsensor import Drift
from host.temperature import T_RANGE, Thermometer, fit_tempcomp_at, load_tempcomp, spread_note, temperature_input


def parse_temperatures(text: str) -> list[float]:
    """``--temperature T1,T2,..``: two or more different temperatures in -40..125 degC."""
    vals = parse_numbers(text)
    if vals is None:
        raise InputError(f"--temperature {text!r}: give temperatures in degC, one between each two commas, e.g. "
                         "15,25,35")
    lo, hi = T_RANGE
    bad = next((v for v in vals if not (math.isfinite(v) and lo <= v <= hi)), None)
    if bad is not None:
        raise InputError(f"--temperature {text!r}: {bad:g} degC is outside {lo:g}..{hi:g} degC, the thermistor's "
                         "range")
    if len(vals) < 2:
        raise InputError(f"--temperature {text!r}: give two or more different temperatures in {lo:g}..{hi:g} degC")
    if len({round(v, 1) for v in vals}) != len(vals):  # the compensation tells levels apart to 0.1 degC
        raise InputError(f"--temperature {text!r}: give temperatures at least 0.1 degC apart")
    return vals


def check_temperature_options(args) -> None:
    """InputError for --t0 or --temp-comp-output without --temperature (they would be ignored)."""
    refuse_alone([(value is not None, option, "--temperature", args.temperature is not None)
                  for option, value in (("--t0", args.t0), ("--temp-comp-output", args.temp_comp_output))])


def parse_t0(text: str | None, temps: list[float]) -> float | None:
    """``--t0``: one of the temperatures captured (the readings there are the compensation's base), or None."""
    if text is None:
        return None
    try:
        t0 = float(text)
    except ValueError:
        t0 = math.nan
    if not any(math.isfinite(t0) and round(t0, 1) == round(T, 1) for T in temps):
        raise InputError(f"--t0 {text}: give one of the temperatures captured ({', '.join(f'{T:g}' for T in temps)}):"
                         " the readings taken there are what the others are compensated to")
    return t0


def capture_temperatures(args, prog: str):
    """``capture --temperature T1,T2,..``: the schedule at each temperature (one file each), then the compensation
    fitted and saved; progress goes to stderr after ``prog``. The TempComp, or None when the user stops it at a
    prompt (q or the input's end); CaptureFailed when a fault stops it (the temperatures done are kept); InputError
    when another run holds the output."""
    with output_lock(args.output):  # for every temperature's file, named after it: two runs would interleave
        return _capture_temperatures(args, prog)


def _temperature_file(out: Path, T: float) -> Path:
    """The capture at temperature ``T`` of a run whose -o is ``out``."""
    return out.with_name(f"{out.stem}.T{T:g}{out.suffix or '.csv'}")


def _kept(out: Path, temps) -> str:
    """What a multi-temperature run stopped early leaves, for its last line."""
    return kept([_temperature_file(out, T) for T in temps],
                "the temperatures and rows done so far are kept: run the same command again to resume")


def _stopped(prog: str, out: Path, temps, T: float) -> None:
    """Say where the user stopped a run at a prompt, and what it kept; None, as capture_temperatures returns then."""
    what = kept([_temperature_file(out, t) for t in temps], "the temperatures and rows done so far are kept")
    print(f"{prog}: stopped at {T:g} degC; {what}; run the same command again to resume", file=sys.stderr)


def _replaced(dest, tc) -> str:
    """What the compensation file ``dest`` held where writing ``tc`` changes it (its t0 and levels), else ''."""
    try:
        old = load_tempcomp(dest)
    except InputError:  # none there, or no compensation (the output checks said what it is)
        return ""
    # the same coefficients from the same rows, whatever order the levels were given in or path they were named by
    if (old.t0 == tc.t0 and old.info.get("temperatures") == tc.info.get("temperatures")
            and np.allclose(old.offset, tc.offset, rtol=1e-9, atol=0)
            and np.allclose(old.gain, tc.gain, rtol=1e-9, atol=0)):
        return ""
    levels = old.info.get("temperatures")
    at = f", levels {', '.join(f'{t:g}' for t in levels)}" if isinstance(levels, list) and levels else ""
    return f"a compensation about {old.t0:g} degC{at}"


def _capture_temperatures(args, prog: str):
    schedule = load_schedule(args.poses)
    simulated_sensor(args, schedule)
    if note := schedule.capture_note():
        print(f"{prog}: {note}", file=sys.stderr)
    adc_defaults(args)
    temps = parse_temperatures(args.temperature)
    t0 = parse_t0(args.t0, temps)
    samples, spread, tries, settle, retries = capture_numbers(args)
    timeout = trigger_timeout(args)
    # a pose visited twice is one pose to the compensation: its gain needs two different ones
    if len(np.unique(schedule.poses, axis=0)) < 2:
        print(f"{prog}: note: one pose per temperature gives offsets only (gain needs two poses)", file=sys.stderr)
    cmap = channel_map_from_args(args)
    tin = temperature_input(args.adc, cmap, args.thermistor)
    out = Path(args.output)
    source = {"source": f"simulated {args.sensor}" if args.simulate else "hardware"}
    if args.simulate:  # the sensor itself tells a resume whether it is the same one
        source["sensor_sha256"] = load_sensor(args.sensor).sha256
    had = {}  # per level, the rows an earlier run took
    for T in temps:  # every level's rows checked as a plain capture's are, before any is taken
        path = _temperature_file(out, T)
        if path.is_file() and path.samefile(args.poses):  # its header had been read as another run's
            raise InputError(f"-o {out} writes {T:g} degC's rows to {path}, which is the --poses schedule: writing "
                             "it would destroy it; give -o another name")
        state = prepare_output(path, cmap.n_elements, schedule, write=False)
        check_resume(path, state.rows, {"adc": cmap.describe(), **source, "samples_per_row": samples})
        same_thermistor(path, state.rows, tin is not None)
        had[T] = (state.rows, bool(state.done.all()))
    drift = None
    if args.simulate:
        drift = (parse_drift(args.sim_drift, cmap.n_elements) or Drift.typical(cmap.n_elements, seed=args.seed)
                 ).steady(temps[0])
    bus, clock = open_bus_from_args(args, cmap, schedule.poses[0] if args.simulate else None, drift=drift,
                                    thermistor=tin)
    rows, level_poses, row_temps, files = [], [], [], []
    try:
        array = AdcArray(bus, cmap, clock=clock, policy=RetryPolicy(attempts=retries))
        array.probe()
        array.setup()
        thermo = Thermometer(array, tin) if tin is not None else None
        for T in temps:
            path = _temperature_file(out, T)
            now = float("nan")
            if not had[T][1]:  # a level an earlier run finished needs neither the sensor brought there nor a row
                if args.simulate:
                    drift.start_degc = T
                elif not args.trigger and ask_line(sys.stdin, sys.stderr, f"{prog}: bring the sensor to {T:g} degC "
                                                   "and let it settle, then press Enter (q to stop) ") is None:
                    return _stopped(prog, out, temps, T)
                wait = trigger_waiter(args.trigger, schedule, timeout) if args.trigger else None
                if wait is None and not args.simulate:
                    wait = enter_waiter(schedule)
                # read now, at this level (not a value kept from the last one); a level captured by an earlier run
                # keeps the reading its meta recorded then
                # (a resume's rows taken more than CAPTURE_DEGC_TOL away refused, as a plain capture's)
                now = same_temperature(path, had[T][0], start_degc(thermo, tin)) if thermo is not None \
                    else float("nan")
                with output_lock(path):  # a plain capture into this temperature's file is another run too
                    res = capture(array, schedule, path, samples=samples, max_spread=spread, tries=tries,
                                  wait=wait, set_pose=bus.set_pose if args.simulate else None, settle=settle,
                                  clock=clock, meta={"adc": cmap.describe(), "temperature_set": T, **source,
                                                     **({"thermistor_degc": now} if np.isfinite(now) else {})},
                                  temperature=None if thermo is None else lambda: thermo.read(fresh=True))
                if not res.complete:  # 'q' at a pose stops the run, not only this level
                    return _stopped(prog, out, temps, T)
            ds = load_dataset(path, min_rows=1)
            recorded = ds.meta.get("thermistor_degc")
            measured = float(recorded) if isinstance(recorded, (int, float)) and thermo is not None else now
            rows.append(ds.inputs)
            level_poses.append(ds.poses())  # by value: a row deleted and taken again sits at the file's end
            each = row_degc(ds.meta, ds.n_rows) if thermo is not None else None  # as the thermistor read each row
            row_temps.append(each if each is not None else np.full(ds.n_rows, measured if np.isfinite(measured) else T))
            files.append(str(path))
            before = had[T][0]  # as the plain capture counts them: a resume says what it took, a rerun nothing
            print(f"{prog}: {ds.n_rows} poses at {T:g} degC"
                  f"{f' (thermistor {measured:.2f} degC)' if np.isfinite(measured) else ''} in {path}"
                  f"{f' ({ds.n_rows - before} captured now, {before} already there)' if before else ''}",
                  file=sys.stderr)
    except KeyboardInterrupt as exc:
        raise CaptureInterrupted(_kept(out, temps), exc) from None
    except (DeviceSilent, SpreadTooLarge, TriggerFailed) as exc:
        raise CaptureFailed(f"{exc}; {_kept(out, temps)}") from exc
    finally:
        bus.close()
    # the rest readings at t0 tell whose sensor the file is for (the readouts compare a twin's unit with them)
    tc = fit_tempcomp_at(np.vstack(rows), np.vstack(level_poses), np.concatenate(row_temps), t0=t0)
    tc.info["captures"] = files
    tc.info["adc"] = cmap.describe()  # the elements each coefficient is for: read and pi-build compare their map
    dest = args.temp_comp_output or str(out.with_name(out.stem + ".tempcomp.json"))
    was = _replaced(dest, tc)
    tc.save(dest)
    worst = max(tc.info["residual_rms_v"]) * 1e3
    print(f"{prog}: temperature compensation about {tc.t0:g} degC -> {dest} (offsets up to "
          f"{np.abs(tc.offset).max() * 1e3:.3g} mV/degC, gains up to {np.abs(tc.gain).max() * 100:.3g} %/degC; "
          f"residual up to {worst:.3g} mV rms)", file=sys.stderr)
    if spread := spread_note(tc):
        print(f"{prog}: {spread}", file=sys.stderr)
    if was:
        print(f"{prog}: note: {dest} held {was}, now replaced: a twin identified through that one, or a build "
              "that compiled it in, no longer matches it (--temp-comp-output keeps both)", file=sys.stderr)
    print(f"{prog}: next: --temp-comp {dest} with read, view, pi-build or emulate --adc, and with fitgen identify "
          "and check for captures read away from its t0", file=sys.stderr)
    if tin is None:  # the levels as set, not as the sensor reached them: a chamber off by a degree is fitted so
        print(f"{prog}: note: no thermistor (temp=CHIP@ADDRESS:INPUT in --adc): each level was taken at the "
              "temperature given, not one measured, and read cannot compensate without one", file=sys.stderr)
    if args.simulate and args.sim_drift and parse_drift(args.sim_drift, cmap.n_elements).ramp_degc:  # held steady
        print(f"{prog}: note: --sim-drift's ramp was not simulated: each level held its temperature", file=sys.stderr)
    return tc
