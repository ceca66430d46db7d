"""Re-zero that keeps working: the rest offsets follow slow drift while the sensor is at rest, never while touched.

The zero is the offset subtracted from each (temperature-compensated) reading so that the
sensor at rest reads as the model's rest readings (``reference``). ``--tare`` measures it once;
:class:`AutoZero` keeps measuring it. The sensor counts as at rest over the last ``window``
samples when the readings are quiet (each element's spread within ``spread_factor`` times the
noise floor) and their mean estimate lies inside the rest band (``band_mm`` for dx, dy, dz;
``band_deg`` for thx, thy) about what the model estimates at rest. The mean, not each sample: a
built unit's twin barely sees tilt at rest and the paper's procedure amplifies noise, so their
single estimates at rest scatter past any useful band (:func:`rest_estimates`); where even the
mean scatters past the band, the band is ``SCATTER_SIGMAS`` times the mean's scatter.

After ``hold`` seconds of rest without a break, the zero moves a fraction ``rate`` of the way to
the window's mean offset (an exponential follower, so one odd window moves it little), the update
is logged and the hold starts again. A press moves the mean out of the band or makes the window
loud, and restarts the hold: a press, even a light steady one, is never averaged into the zero
unless its mean estimate stays inside the rest band.

Deterministic: the state depends only on the samples' times, readings and estimates, and the band
only on the model, the rest readings and the noise floor, so a recorded run replays to the same
zeros (``tactile-host replay``).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import numpy as np

from fitgen.base.errors import InputError
from fitgen.physics.pose import POSE_NAMES, POSE_UNITS

SCATTER_SIGMAS = 5.0  # band floor, in standard deviations of the window's mean estimate at rest
SCATTER_DRAWS = 2000  # noisy rest readings the scatter is measured on
SCATTER_NOISE = 0.0005  # V rms: the noise pi-build measures the scatter per volt at (a GMR element's, per sample)


@dataclass(frozen=True)
class AutoZeroSettings:
    band_mm: float = 0.08
    band_deg: float = 1.5
    hold: float = 1.0  # s of continuous rest before an update
    window: int = 64  # samples whose spread must be at the noise floor
    spread_factor: float = 3.0
    rate: float = 0.5  # fraction of the way to the measured offset per update
    # "mean": the window's mean estimate about the model's rest; "sample": every estimate about 0, as a run
    # recorded before the mean was tested (its header names no test) was zeroed, so that it replays exactly
    test: str = "mean"

    def checked(self) -> "AutoZeroSettings":
        for name in ("band_mm", "band_deg", "hold", "spread_factor"):
            v = getattr(self, name)
            if not v > 0 or v != v or v == float("inf"):
                raise InputError(f"auto-zero {name.replace('_', '-')} must be a finite number > 0, got {v}")
        if not 0 < self.rate <= 1:
            raise InputError(f"auto-zero rate must be in (0, 1], got {self.rate}")
        if self.window < 4:
            raise InputError(f"auto-zero window must be >= 4 samples, got {self.window}")
        if self.test not in ("mean", "sample"):
            raise InputError(f"auto-zero test must be 'mean' or 'sample', got {self.test!r}")
        return self


def rest_estimates(predict, reference: np.ndarray, noise: float,
                   draws: int = SCATTER_DRAWS) -> tuple[np.ndarray, np.ndarray]:
    """Each output's mean and standard deviation over single estimates at rest: ``predict`` (rows of readings in,
    rows of estimates out) on the rest readings with the noise floor's Gaussian noise added (a fixed seed: a run
    and its replay get the same band)."""
    ref = np.asarray(reference, dtype=float)
    rows = ref + np.random.default_rng(0).normal(0.0, noise, (draws, ref.size))
    est = np.asarray(predict(rows), dtype=float)
    est = est[np.all(np.isfinite(est), axis=1)]
    if not len(est):  # no noisy rest reading has a finite estimate: the band stays about 0, as given
        return np.zeros(est.shape[1]), np.zeros(est.shape[1])
    return est.mean(axis=0), est.std(axis=0)


def rest_response(predict, reference: np.ndarray, noise: float = SCATTER_NOISE) -> tuple[np.ndarray, np.ndarray]:
    """Each output's mean single estimate at rest and its scatter per volt of noise, both measured at ``noise``
    (:func:`rest_estimates`): what tactile-host pi-build compiles in for tm_pi --auto-zero, which scales the
    scatter by the tare's noise floor (small noise moves an estimate linearly) instead of estimating rest
    readings thousands of times on the Pi."""
    rest, scatter = rest_estimates(predict, reference, noise)
    return rest, scatter / noise


@dataclass
class ZeroUpdate:
    t: float
    number: int
    shift: np.ndarray  # V, per element
    since: float = 0.0  # s from the first sample auto-zero saw (t itself is a clock's: an epoch on a live run)

    def describe(self) -> str:
        return (f"auto-zero update {self.number} at {self.since:.3f} s: max shift "
                f"{np.abs(self.shift).max() * 1e3:.3f} mV "
                f"(element {int(np.argmax(np.abs(self.shift))) + 1})")


@dataclass
class AutoZero:
    """The zero offsets (V per element) and the rest detector that updates them."""

    reference: np.ndarray  # the model's rest readings
    noise: float  # noise floor, V rms per element
    outputs: tuple[str, ...]
    zero: np.ndarray = None  # current offsets (start: the tare's, or 0)
    settings: AutoZeroSettings = AutoZeroSettings()
    rest: np.ndarray = None  # each output's mean estimate at rest, the band's centre (rest_estimates; 0 without)
    scatter: np.ndarray = None  # each output's standard deviation over single estimates at rest (rest_estimates)
    updates: list[ZeroUpdate] = field(default_factory=list)
    log = None  # callable(str) for each update

    def __post_init__(self):
        self.reference = np.asarray(self.reference, dtype=float)
        self.zero = np.zeros_like(self.reference) if self.zero is None else np.asarray(self.zero, dtype=float).copy()
        self.settings = self.settings.checked()
        if not self.noise > 0:
            raise InputError(f"auto-zero needs the noise floor (V rms) > 0, got {self.noise}")
        self._units = [POSE_UNITS[POSE_NAMES.index(o)] for o in self.outputs]
        given = np.array([self.settings.band_mm if u == "mm" else self.settings.band_deg for u in self._units])
        sample = self.settings.test == "sample"
        mean_sd = (np.zeros(len(given)) if self.scatter is None or sample else np.asarray(self.scatter, dtype=float)) \
            / np.sqrt(self.settings.window)
        self.band = np.maximum(given, SCATTER_SIGMAS * mean_sd)
        self.rest = np.zeros(len(given)) if self.rest is None or sample else np.asarray(self.rest, dtype=float)
        self.widened = tuple(o for o, b, g in zip(self.outputs, self.band, given) if b > g)
        self._window: deque = deque(maxlen=self.settings.window)
        self._estimates: deque = deque(maxlen=self.settings.window)
        self._since: float | None = None
        self._first: float | None = None  # the first sample's t

    @classmethod
    def for_model(cls, model, reference: np.ndarray, noise: float, **kw) -> "AutoZero":
        """An AutoZero whose band is centred and widened for ``model`` (a :class:`fitgen.equations.model.Model`)
        at these rest readings and noise floor (the every-sample test of older runs takes neither)."""
        if kw.get("settings", AutoZeroSettings()).test == "sample":
            return cls(reference, noise, model.output_names, **kw)
        rest, scatter = rest_estimates(model.predict, reference, noise)
        return cls(reference, noise, model.output_names, rest=rest, scatter=scatter, **kw)

    def correct(self, readings: np.ndarray) -> np.ndarray:
        """The readings with the current zero taken off."""
        return readings - self.zero

    def observe(self, t: float, readings: np.ndarray, estimate: np.ndarray, status: int) -> ZeroUpdate | None:
        """Feed one sample (readings before the zero is taken off, and the estimate made from it)."""
        s = self.settings
        self._first = t if self._first is None else self._first
        if status < 0 or not np.all(np.isfinite(estimate)) or \
                (s.test == "sample" and np.any(np.abs(estimate) > self.band)):
            return self._restart()
        self._window.append(np.array(readings, dtype=float))
        self._estimates.append(np.array(estimate, dtype=float))
        if len(self._window) < s.window:
            return None
        block = np.asarray(self._window)
        if np.any(block.std(axis=0) > s.spread_factor * self.noise) or \
                np.any(np.abs(np.mean(self._estimates, axis=0) - self.rest) > self.band):
            return self._restart()
        if self._since is None:
            self._since = t
            return None
        if t - self._since < s.hold:
            return None
        target = block.mean(axis=0) - self.reference
        shift = s.rate * (target - self.zero)
        self.zero = self.zero + shift
        up = ZeroUpdate(t, len(self.updates) + 1, shift, t - self._first)
        self.updates.append(up)
        self._restart()
        if self.log is not None:
            self.log(up.describe())
        return up

    def _restart(self) -> None:
        self._window.clear()
        self._estimates.clear()
        self._since = None

    def describe_band(self) -> str:
        """The band's widened outputs and why, or '' when none is."""
        if not self.widened:
            return ""
        out = [(i, o, u) for i, (o, u) in enumerate(zip(self.outputs, self._units)) if o in self.widened]
        parts = [f"{o} {self.scatter[i]:.3g} {u}" for i, o, u in out]
        bands = [f"{o} +-{self.band[i]:.3g} {u}" for i, o, u in out]
        return (f"auto-zero: this model's single estimates at rest scatter by {', '.join(parts)} rms; the "
                f"{self.settings.window}-sample mean's rest band is {', '.join(bands)} "
                f"({SCATTER_SIGMAS:g} sigma of that mean, wider than --rest-band)")
