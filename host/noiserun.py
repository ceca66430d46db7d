"""``tactile-host noise``: the resting sensor read for a while, the Allan deviation of its readings, and the
samples per row a capture can average before its rows read better than they are (host.allan)."""

from __future__ import annotations

import json
import math

import numpy as np

from fitgen.base.errors import InputError
from fitgen.base.fileio import read_text
from fitgen.base.parse import LONGEST_WAIT, MAX_TRIES, parse_positive
from fitgen.base.progress import Progress

from host.adc import AdcArray, RetryPolicy
from host.temperature import thermistor_given
from host.allan import CANDIDATES, CAPTURE_S, EXCESS, SURE, WHITE_RATIO, Averaging, averaging, needed_samples
from host.session import adc_defaults, channel_map_from_args, open_bus_from_args, refuse_alone

# at two ADS1115s' 140 samples per second white noise's flicker floor is read to about 6e-6 mV^2, so that 128 and
# 256 samples per row can be told safe (host.allan.EXCESS); at 300 s 1 in 3 white recordings is told 64
SECONDS = 600.0
# V rms a sample can read: below 1 nV no ADC resolves (an ADS1115's least step is 7.8 uV), above 10 V none reads
SINGLE_V = (1e-9, 10.0)


def _seconds(samples: int, rate: float) -> int:
    """Whole seconds a recording at ``rate`` takes to hold ``samples``: rounded up, so that the time said is
    enough (8.4 s said as 8 was too short)."""
    return math.ceil(samples / rate)


def record(array: AdcArray, seconds: float, clock, stop=lambda: False, progress=None) -> tuple[np.ndarray, float]:
    """Samples of every element for ``seconds`` on ``clock`` (or until ``stop()``), back to back, so nearly evenly
    spaced: (samples, rate in samples per second). InputError when an input sat at its converter's full scale."""
    rows = []
    clipped = np.zeros(array.n, dtype=int)
    t0 = clock.monotonic()
    while (now := clock.monotonic()) - t0 < seconds and not stop():
        rows.append(array.read_volts())
        clipped += array.clipped
        if progress is not None:  # the bar counts tenths of a second
            progress.update(min(int(10 * (now - t0)), progress.total) - progress.done,
                            f"{(now - t0):.0f} of {seconds:g} s read, {len(rows)} samples")
    elapsed = clock.monotonic() - t0
    if progress is not None and not stop():
        progress.update(progress.total - progress.done, f"{seconds:g} of {seconds:g} s read, {len(rows)} samples")
    if clipped.any():
        k = int(np.argmax(clipped))
        raise InputError(f"element {k + 1} read at its converter's full scale in {clipped[k]} of {len(rows)} samples: "
                         "a clipped input's noise is not the sensor's (a wider --pga, or the magnet too close)")
    if len(rows) < 3 or elapsed <= 0:
        raise InputError(f"recorded {len(rows)} samples in {elapsed:.2f} s: too few to measure the noise")
    return np.vstack(rows), len(rows) / elapsed


def run_noise(args, stop=lambda: False) -> Averaging:
    """The rest recording of the options' bus (or of a simulated sensor at rest) and its Averaging."""
    adc_defaults(args)
    refuse_alone([("sensor" in args.adc_given, "--sensor", "--simulate", args.simulate)])  # what it simulates
    seconds = parse_positive(args.seconds, "--seconds", most=LONGEST_WAIT)
    retries = parse_positive(args.retries, "--retries", integer=True, most=MAX_TRIES)
    cmap = channel_map_from_args(args)
    if thermistor_given(args, cmap):  # it records the elements' noise only
        raise InputError("noise reads the elements only, no thermistor: drop temp= from --adc and --thermistor")
    bus, clock = open_bus_from_args(args, cmap, np.zeros(5) if args.simulate else None)
    try:
        array = AdcArray(bus, cmap, clock=clock, policy=RetryPolicy(attempts=retries))
        array.probe()
        array.setup()
        with Progress("noise", int(10 * seconds)) as progress:
            x, rate = record(array, seconds, clock, stop, progress)
    finally:
        bus.close()
    return averaging(x, rate)


def table(av: Averaging) -> str:
    """The recording's verdict per candidate, as Markdown."""
    lines = ["| samples per row | reading time | Allan deviation, worst element [mV] | white noise's [mV] | "
             "real / recorded noise of a row, worst element | flicker / a row's white noise (variance, upper) |",
             "| --- | --- | --- | --- | --- | --- |"]
    for i, s in enumerate(av.candidates):
        k = int(np.argmax(av.ratio[i]))
        white = av.single[k] / np.sqrt(s)
        lines.append(f"| {s} | {s / av.rate:.2f} s | {1e3 * av.adev[i].max():.4g} | {1e3 * white:.4g} | "
                     f"{av.ratio[i, k]:.2f} (e{k + 1}) | {av.flicker_share(s):.3f} |")
    for s in av.too_short:
        lines.append(f"| {s} | {s / av.rate:.2f} s | record {_seconds(needed_samples(s), av.rate)} s to read it | | | |")
    return "\n".join(lines)


def verdict(av: Averaging, record=None) -> str:
    """One line: the samples per row the recording supports, and what to give fitgen schedule (``record``, where
    the recording is written, or else the count); or that even rows of 16 do not average, or that the readings
    drift."""
    if not av.candidates:
        return (f"too short to read {CANDIDATES[0]} samples per row: record at least "
                f"{_seconds(needed_samples(CANDIDATES[0]), av.rate)} s (--seconds)")
    f2, se = av.flicker
    floor = (f"the flicker read at {av.longest / av.rate:.1f} s: {1e3 * np.sqrt(max(f2, 0.0)):.3g} mV, at most "
             f"{1e3 * np.sqrt(max(f2 + SURE * se, 0.0)):.3g} mV")
    if not av.averages_at_all:
        k = int(np.argmax(av.ratio[0]))
        return (f"the noise does not average down even over {av.candidates[0]} samples (e{k + 1}'s rows would carry "
                f"{av.ratio[0, k]:.2f}x the noise the capture records, more than {WHITE_RATIO}; {floor}): identify's "
                "reduced chi-square will read above 1; find what drifts (a longer --settle, the supply, the "
                "temperature)")
    if av.drifts():
        k = int(np.argmax(np.abs(av.drift)))
        return (f"the readings drift: e{k + 1} by {1e3 * av.drift[k] * 60:+.3g} mV per minute, "
                f"{1e3 * abs(av.drift[k]) * CAPTURE_S:.2g} mV over a {CAPTURE_S / 60:g}-minute capture, more than a "
                f"row's noise at {CANDIDATES[0]} samples ({1e3 * av.single[k] / np.sqrt(CANDIDATES[0]):.2g} mV): "
                "identify would read a moving offset as the unit's physics; let the sensor warm up (power on, the "
                "room's temperature) and run again")
    best = av.recommended()
    if best == CANDIDATES[0]:
        nxt = CANDIDATES[1]
        return (f"keep {best} samples per row ({floor}; at {nxt} samples its variance could reach "
                f"{av.flicker_share(nxt):.3f} of a row's white noise, more than {EXCESS}: it wanders over a capture "
                "and identify would read its posterior too narrow; a longer --seconds reads it closer)")
    return (f"the noise averages down up to {best} samples per row ({floor}: at most {av.flicker_share(best):.3f} of a "
            f"row's white noise there, within {EXCESS}): fitgen schedule ... --samples "
            + (f"{record} (which takes {best}, and the noise measured here)" if record else str(best)))


def record_text(av: Averaging, source: str) -> str:
    """The JSON record ``noise -o`` writes and :func:`told` reads; ``source``: what was read (hardware or a preset)."""
    return json.dumps({"source": source, **av.meta()}, indent=2, sort_keys=True) + "\n"


def told(path) -> tuple[int, np.ndarray]:
    """What a record of :func:`record_text` tells a capture: the samples per row it recommends and each element's
    single-sample noise, V. InputError when the file is no such record, or when its recording recommends
    no rows (too short to read one, readings that do not average down or that drift: verdict's order)."""
    text = read_text(path, "noise record")
    rec = None
    try:
        rec = json.loads(text)
        if not isinstance(rec, dict):
            raise TypeError
        samples, single = int(rec["recommended"]), np.asarray(rec["single_v"], dtype=float)
        candidates, ratio, drifts = list(rec["candidates"]), np.asarray(rec["ratio"], dtype=float), rec["drifts"]
    except (ValueError, TypeError, KeyError, OverflowError, RecursionError) as exc:
        why = ("not JSON" if isinstance(exc, json.JSONDecodeError) else "nested too deep"
               if isinstance(exc, RecursionError) else f"it has no {exc.args[0]!r}"
               if isinstance(exc, KeyError) else "not a JSON object" if not isinstance(rec, dict)
               else "a field that is not what such a record holds")
        raise InputError(f"{path} is not a record tactile-host noise -o wrote ({why})") from None
    sane = single.ndim == 1 and single.size and np.all((single >= SINGLE_V[0]) & (single <= SINGLE_V[1]))
    whole = type(rec["recommended"]) is int and all(type(c) is int and c in CANDIDATES for c in candidates)
    shaped = ratio.ndim == 2 and ratio.shape[0] == len(candidates) and ratio.size and np.all(np.isfinite(ratio))
    if samples not in CANDIDATES or not whole or not sane or not isinstance(drifts, bool) or \
            (candidates and not shaped):  # 16.7 read as 16, a NaN ratio as one that averages down
        raise InputError(f"{path} is not a record tactile-host noise -o wrote (its recommendation, candidates, "
                         "ratios, noise or drift are off)")
    if not candidates:
        raise InputError(f"{path}: its recording was too short to read {CANDIDATES[0]} samples per row: record "
                         "longer (tactile-host noise --seconds)")
    if ratio[0].max() > WHITE_RATIO:
        raise InputError(f"{path}: its noise does not average down even over {CANDIDATES[0]} samples per row: find "
                         "what drifts (a longer --settle, the supply, the temperature) and record again")
    if drifts:
        raise InputError(f"{path}: its readings drift, and a capture would read a moving offset as the unit's "
                         "physics: let the sensor warm up and record again")
    return samples, single
