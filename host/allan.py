"""Does a unit's reading noise average down? The overlapping Allan deviation of readings taken at rest, and the
samples per row it supports.

A capture averages S samples per row and records the row's noise as the samples' spread over sqrt(S)
(host.capture.NoiseStats): true only for noise that is white over the row. The overlapping Allan deviation at
S samples is the spread of adjacent S-sample means (over sqrt(2)): what a row's average really carries. For
white noise it is the one-sample deviation over sqrt(S); flicker (1/f) noise and drift make it larger. Flicker
matters long before it shows in one row: it wanders slowly, so it does not average over a capture's rows as
the white noise does, and identify, which takes the rows as independent, reads its posterior too narrow
(bench/noise_averaging.py). So the samples per row recommended rest on the flicker's floor, read where the
recording averages longest, with its uncertainty.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fitgen.base.errors import InputError

CANDIDATES = (16, 32, 64, 128, 256)  # samples per row a capture might average
# A row's real noise over what the capture records for it, beyond which even the default 16 samples read better
# than they are: identify's reduced chi-square grows by its square, and calibration.md reads above 1.5 as
# "something the model lacks".
WHITE_RATIO = 1.2
# The flicker's variance over a row's white variance (S F^2 / sigma^2) a capture stands before identify's
# posterior reads too narrow (bench/noise_averaging.py: 0.05 costs 128 samples all they gain).
EXCESS = 0.02
SURE = 2.0  # standard errors above the flicker floor's estimate it is taken to be, for a recommendation
# standard errors below its estimate a slope is taken to be: white noise alone then reads as drift in 1-2 of 100
# recordings of eight elements, however short (in 34 of 40 of 30 s when the slope was taken as read)
DRIFT_SURE = 3.0
FLOOR_AVERAGES = 20  # the flicker floor is read at averages of a twentieth of the recording: its error ~ 1 / samples
MIN_AVERAGES = 50  # independent S-sample means a candidate S needs before its ratio is read (about 8 % error)
CAPTURE_S = 120.0  # s: a 40-pose capture on a printer (calibration.md), over which a drift moves the offsets


def overlapping_adev(x: np.ndarray, ms) -> np.ndarray:
    """Overlapping Allan deviation of each column of ``x`` (N samples, k channels) at averaging factors ``ms``
    (samples): an array (len(ms), k). Each m needs N >= 2m + 1."""
    x = np.asarray(x, dtype=float)
    if x.ndim == 1:
        x = x[:, None]
    ms = np.asarray(ms, dtype=int).reshape(-1)
    n = x.shape[0]
    if ms.size == 0 or ms.min() < 1 or 2 * ms.max() + 1 > n:
        raise InputError(f"the Allan deviation at {ms.tolist()} samples needs at least {2 * max(ms.max(), 1) + 1} "
                         f"samples, got {n}")
    # subtracting the mean keeps the running sums small: long records lose no digits in the differences
    c = np.vstack([np.zeros((1, x.shape[1])), np.cumsum(x - x.mean(axis=0), axis=0)])
    out = np.empty((ms.size, x.shape[1]))
    for i, m in enumerate(ms):  # a handful of factors; each one vectorised over the record
        means = (c[m:] - c[:-m]) / m
        d = means[m:] - means[:-m]
        out[i] = np.sqrt(0.5 * np.mean(d * d, axis=0))
    return out


@dataclass
class Averaging:
    """What a rest recording says about averaging: per candidate S and element, the Allan deviation at S samples
    and its ratio to white noise's (the one-sample deviation over sqrt(S))."""

    rate: float  # samples per second
    samples: int  # in the recording
    candidates: tuple[int, ...]  # those the recording is long enough to read
    single: np.ndarray  # (k,) V: the Allan deviation at one sample (white noise's standard deviation)
    adev: np.ndarray  # (len(candidates), k) V
    too_short: tuple[int, ...]  # candidates the recording is too short for
    curve_m: np.ndarray  # averaging factors, log-spaced, for a plot
    curve: np.ndarray  # (len(curve_m), k) V
    longest: int  # the longest averaging the recording reads (samples): where the flicker is read
    excess: np.ndarray  # (k,) V^2: Allan variance there beyond white noise's, per element
    drift: np.ndarray  # (k,) V/s: each element's straight-line slope over the recording

    @property
    def drift_se(self) -> np.ndarray:
        """(k,) V/s: the standard error white noise alone gives each element's slope over the recording."""
        n = self.samples
        return self.single * self.rate * np.sqrt(12.0 / (n * max(n * n - 1.0, 1.0)))

    def drifts(self) -> bool:
        """True when some element drifts by more than a row of the smallest candidate's white noise over CAPTURE_S,
        its slope taken DRIFT_SURE standard errors low: a capture then reads an offset that moves under it (a sensor
        still warming up), and a short recording's white noise alone does not read as drift."""
        slope = np.abs(self.drift) - DRIFT_SURE * self.drift_se
        return bool(np.any(slope * CAPTURE_S > self.single / np.sqrt(CANDIDATES[0])))

    @property
    def flicker(self) -> tuple[float, float]:
        """The flicker floor's variance pooled over elements, V^2, and its standard error (their spread)."""
        e = self.excess
        return float(e.mean()), float(e.std(ddof=1) / np.sqrt(e.size)) if e.size > 1 else float(abs(e[0]))

    def flicker_share(self, s: int) -> float:
        """S F^2 / sigma^2 at ``s`` samples per row, F^2 taken SURE standard errors above its estimate."""
        f2, se = self.flicker
        return s * max(f2 + SURE * se, 0.0) / float(np.mean(self.single ** 2))

    @property
    def ratio(self) -> np.ndarray:
        """(len(candidates), k): a row's real noise over what the capture records for it."""
        return self.adev * np.sqrt(np.asarray(self.candidates, dtype=float))[:, None] / self.single

    @property
    def worst(self) -> np.ndarray:
        """Per candidate, the worst element's ratio."""
        return self.ratio.max(axis=1)

    def recommended(self) -> int:
        """The largest candidate S the recording reads whose flicker share is within EXCESS; the smallest candidate
        (the capture's default) when none is."""
        ok = [s for s in self.candidates if self.flicker_share(s) <= EXCESS]
        return max(ok) if ok else CANDIDATES[0]

    @property
    def averages_at_all(self) -> bool:
        """False when even the smallest candidate's rows carry more than WHITE_RATIO x the noise recorded."""
        return not self.candidates or bool(self.worst[0] <= WHITE_RATIO)

    def meta(self) -> dict:
        return {"rate_hz": self.rate, "samples": self.samples, "candidates": list(self.candidates),
                "too_short": list(self.too_short), "single_v": self.single.tolist(), "adev_v": self.adev.tolist(),
                "ratio": self.ratio.tolist(), "white_ratio_limit": WHITE_RATIO, "longest_samples": self.longest,
                "flicker_v2": list(self.flicker),
                "flicker_share": {str(s): self.flicker_share(s) for s in self.candidates},
                "excess_limit": EXCESS, "drift_v_per_s": self.drift.tolist(), "drifts": self.drifts(),
                "recommended": self.recommended()}


def averaging(x: np.ndarray, rate: float, candidates=CANDIDATES) -> Averaging:
    """The Allan deviation of rest readings ``x`` (N samples, k elements; ``rate`` samples per second) at one
    sample and at every candidate S the recording holds MIN_AVERAGES independent means of."""
    x = np.asarray(x, dtype=float)
    if x.ndim != 2 or x.shape[0] < 3:
        raise InputError(f"a rest recording needs at least 3 samples of every element, got shape {x.shape}")
    if not np.all(np.isfinite(x)):
        raise InputError("the rest recording holds readings that are not finite numbers")
    if not (np.isfinite(rate) and rate > 0):
        raise InputError(f"the sample rate must be > 0 samples/s, got {rate}")
    n = x.shape[0]
    ok = tuple(int(s) for s in candidates if n >= MIN_AVERAGES * s)
    short = tuple(int(s) for s in candidates if n < MIN_AVERAGES * s)
    longest = max(n // FLOOR_AVERAGES, 1)
    curve_m = np.unique(np.geomspace(1, max(n // MIN_AVERAGES, 1), 40).astype(int))
    dev = overlapping_adev(x, (1, *ok, longest))
    if np.any(dev[0] <= 0):
        dead = np.flatnonzero(dev[0] <= 0) + 1
        raise InputError(f"element {', '.join(map(str, dead))} reads the same value in every sample: no noise to "
                         "average (a dead channel, or an ADC too coarse for the noise)")
    excess = dev[-1] ** 2 - dev[0] ** 2 / longest
    t = (np.arange(n) - (n - 1) / 2.0) / rate  # centred: the slope is the least-squares one, vectorised over elements
    drift = t @ (x - x.mean(axis=0)) / (t @ t)
    return Averaging(float(rate), n, ok, dev[0], dev[1:-1], short, curve_m, overlapping_adev(x, curve_m), longest,
                     excess, drift)


def needed_samples(s: int) -> int:
    """Samples a rest recording needs to read candidate ``s``."""
    return MIN_AVERAGES * int(s)
