"""Re-zero that keeps working: the rest offsets follow slow drift while the sensor is at rest, never while touched.

The zero is the offset subtracted from each (temperature-compensated) reading so that the
sensor at rest reads as the model's rest readings (``reference``). ``--tare`` measures it once;
:class:`AutoZero` keeps measuring it. A sample counts as at rest when every estimate lies inside
the rest band (|dx|, |dy|, |dz| <= ``band_mm``, |thx|, |thy| <= ``band_deg``) and the readings
are quiet: over the last ``window`` samples each element's spread stays within ``spread_factor``
times the noise floor. After ``hold`` seconds of rest without a break, the zero moves a fraction
``rate`` of the way to the window's mean offset (an exponential follower, so one odd window moves it
little), the update is logged and the hold starts again. Any sample outside the band or with a loud
window restarts the hold: a press, even a light steady one, is never averaged into the zero unless
its estimate stays inside the rest band.

Deterministic: the state depends only on the samples' times, readings and estimates, so a
recorded run replays to the same zeros (``tactile-host replay``).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import numpy as np

from fitgen.base.errors import InputError


@dataclass(frozen=True)
class AutoZeroSettings:
    band_mm: float = 0.08
    band_deg: float = 1.5
    hold: float = 1.0  # s of continuous rest before an update
    window: int = 64  # samples whose spread must be at the noise floor
    spread_factor: float = 3.0
    rate: float = 0.5  # fraction of the way to the measured offset per update

    def checked(self) -> "AutoZeroSettings":
        for name in ("band_mm", "band_deg", "hold", "spread_factor"):
            v = getattr(self, name)
            if not v > 0 or v != v or v == float("inf"):
                raise InputError(f"auto-zero {name.replace('_', '-')} must be a finite number > 0, got {v}")
        if not 0 < self.rate <= 1:
            raise InputError(f"auto-zero rate must be in (0, 1], got {self.rate}")
        if self.window < 4:
            raise InputError(f"auto-zero window must be >= 4 samples, got {self.window}")
        return self


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
    updates: list[ZeroUpdate] = field(default_factory=list)
    log = None  # callable(str) for each update

    def __post_init__(self):
        self.reference = np.asarray(self.reference, dtype=float)
        self.zero = np.zeros_like(self.reference) if self.zero is None else np.asarray(self.zero, dtype=float).copy()
        self.settings = self.settings.checked()
        if not self.noise > 0:
            raise InputError(f"auto-zero needs the noise floor (V rms) > 0, got {self.noise}")
        lin = [o in ("dx", "dy", "dz") for o in self.outputs]
        self._band = np.array([self.settings.band_mm if m else self.settings.band_deg for m in lin])
        self._window: deque = deque(maxlen=self.settings.window)
        self._since: float | None = None
        self._first: float | None = None  # the first sample's t

    def correct(self, readings: np.ndarray) -> np.ndarray:
        """The readings with the current zero taken off."""
        return readings - self.zero

    def observe(self, t: float, readings: np.ndarray, estimate: np.ndarray, status: int) -> ZeroUpdate | None:
        """Feed one sample (readings before the zero is taken off, and the estimate made from it)."""
        s = self.settings
        self._first = t if self._first is None else self._first
        at_rest = status >= 0 and bool(np.all(np.abs(estimate) <= self._band))
        if not at_rest:
            self._window.clear()
            self._since = None
            return None
        self._window.append(np.array(readings, dtype=float))
        if len(self._window) < s.window:
            return None
        block = np.asarray(self._window)
        if np.any(block.std(axis=0) > s.spread_factor * self.noise):
            self._window.clear()
            self._since = None
            return None
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
        self._window.clear()
        self._since = None
        if self.log is not None:
            self.log(up.describe())
        return up
