"""The simulated sensor behind a simulated bus: its elements' volts at a pose, moving, drifting, and a thermistor.

``SensorFeed`` gives the volts of a sensor's elements in its ``gmr`` transfer
(``fitgen.physics.transfer.readings``, before any ADC) at the pose set with ``set_pose``
or given by a motion over time, plus per-element offsets and fresh Gaussian noise per
conversion; ``Drift`` moves them with temperature and creep; ``ntc_volts`` is a
thermistor divider's output at a temperature.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from fitgen.base.errors import InputError
from fitgen.physics.pose import as_poses, pose_label
from fitgen.physics.sensor import Sensor
from fitgen.physics.transfer import readings


@dataclass
class Drift:
    """What moves a real skin's readings while its pose does not: temperature and creep.

    Element k reads v_k (1 + gain_tc_k (T - t0)) + offset_tc_k (T - t0) + creep_k (1 - exp(-t / creep_tau)),
    with T = ``temperature(t)`` (degC; t the bus clock's seconds). Defaults are of the order of a GMR
    bridge's datasheet figures (offset drift about 1 mV/degC after the amplifier, gain -0.1 %/degC) and a
    silicone skin's creep; ``ramp`` makes T rise linearly by ``ramp_degc`` over ``ramp_s`` seconds.
    """

    offset_tc: np.ndarray  # V / degC, per element
    gain_tc: np.ndarray  # 1 / degC, per element
    creep: np.ndarray  # V, per element, reached after a few creep_tau
    creep_tau: float = 600.0  # s
    t0: float = 25.0  # degC at which the sensor reads as calibrated
    start_degc: float = 25.0
    ramp_degc: float = 0.0
    ramp_s: float = 1.0

    @classmethod
    def typical(cls, n: int, *, seed: int = 0, ramp_degc: float = 5.0, ramp_s: float = 600.0,
                creep_tau: float = 600.0, start_degc: float = 25.0) -> "Drift":
        rng = np.random.default_rng(seed)
        return cls(offset_tc=rng.normal(0.0, 1e-3, n), gain_tc=rng.normal(-1e-3, 3e-4, n),
                   creep=rng.normal(0.0, 2e-3, n), creep_tau=creep_tau, start_degc=start_degc,
                   ramp_degc=ramp_degc, ramp_s=ramp_s)

    def steady(self, degc: float) -> "Drift":
        """The same coefficients at a steady ``degc``: no ramp, no creep (readings that do not depend on time)."""
        return replace(self, start_degc=float(degc), ramp_degc=0.0, creep=np.zeros_like(self.creep))

    def temperature(self, t: float) -> float:
        return self.start_degc + self.ramp_degc * min(max(t / self.ramp_s, 0.0), 1.0)

    def apply(self, volts: np.ndarray, t: float) -> np.ndarray:
        dT = self.temperature(t) - self.t0
        return volts * (1.0 + self.gain_tc * dT) + self.offset_tc * dT + self.creep * (1.0 - math.exp(-t / self.creep_tau))


FLICKER_TAUS = (0.1, 1.0, 10.0, 100.0, 1000.0)  # s: one Gauss-Markov process a decade apart gives 1/f between


def _ou_allan_var(T: np.ndarray, tau: float) -> np.ndarray:
    """Allan variance at averaging time ``T`` of a unit-variance first-order Gauss-Markov process with time constant
    ``tau``: (4 V(T) - V(2T)) / (2 T^2), V(T) = 2 (tau T - tau^2 (1 - exp(-T / tau))) the variance of its integral."""
    def v(t):
        return 2.0 * (tau * t - tau * tau * -np.expm1(-t / tau))
    return (4.0 * v(T) - v(2.0 * T)) / (2.0 * T * T)


@dataclass
class Flicker:
    """Flicker (1/f) noise per element: a sum of first-order Gauss-Markov processes with FLICKER_TAUS, scaled so
    that its Allan deviation is about ``level`` volts from 0.3 s to 100 s (within 15 %). It does not average
    down: a row of S samples keeps about ``level`` whatever S."""

    level: float  # V
    n: int
    rng: np.random.Generator
    taus: tuple[float, ...] = FLICKER_TAUS

    def __post_init__(self):
        if not (np.isfinite(self.level) and self.level >= 0):
            raise InputError(f"simulated flicker must be a finite number >= 0 V, got {self.level}")
        t = np.geomspace(0.3, 100.0, 50)
        unit = np.mean(sum(_ou_allan_var(t, tau) for tau in self.taus))
        self.scale = self.level / math.sqrt(unit)  # each process's standard deviation
        self.state = self.scale * self.rng.standard_normal((len(self.taus), self.n))  # stationary from the start
        self.t = None
        self._tau = np.asarray(self.taus, dtype=float)[:, None]

    def at(self, t: float) -> np.ndarray:
        """The flicker of every element at time ``t`` (s; exact transitions over any step, forward in time)."""
        if self.t is not None and t > self.t:
            a = np.exp(-(t - self.t) / self._tau)
            self.state = a * self.state + self.scale * np.sqrt(1.0 - a * a) * self.rng.standard_normal(self.state.shape)
        if self.t is None or t > self.t:
            self.t = t
        return self.state.sum(axis=0)


def ntc_volts(temp_degc: float, *, beta: float = 3950.0, r25: float = 10_000.0, series: float = 10_000.0,
              vref: float = 3.3) -> float:
    """The divider's output: an NTC (beta model, r25 at 25 degC) to ground, ``series`` ohms to ``vref``; at
    absolute zero the NTC's resistance is infinite, the output ``vref``."""
    kelvin = temp_degc + 273.15
    exponent = beta * (1.0 / kelvin - 1.0 / 298.15) if kelvin > 0.0 else math.inf
    if exponent > 690.0:  # r / (r + series) is 1 to the last bit long before r overflows (near -215 degC)
        return vref
    r = r25 * math.exp(exponent)
    return vref * r / (r + series)


class SensorFeed:
    """Element voltages of a sensor (its ``gmr`` transfer, no ADC) at a pose, with offsets and noise.

    ``motion``: a function of the bus clock's time (s) giving the pose, evaluated at most every
    ``motion_step`` seconds; ``drift``: a :class:`Drift` applied to the volts at that time; ``flicker``: a
    :class:`Flicker` added at the time of each conversion.
    """

    def __init__(self, sensor: Sensor, pose=None, *, noise: float = 0.0, offsets=None,
                 rng: np.random.Generator | None = None, motion=None, drift: Drift | None = None,
                 motion_step: float = 5e-3, flicker: Flicker | None = None):
        self.sensor = sensor.with_transfer("gmr")
        self.noise = float(noise)
        if self.noise < 0:
            raise InputError(f"simulated noise must be >= 0 V, got {noise}")
        n = self.sensor.n_elements
        self.offsets = np.zeros(n) if offsets is None else np.asarray(offsets, dtype=float).reshape(n)
        self.rng = rng or np.random.default_rng(0)
        self.motion, self.drift, self.motion_step = motion, drift, motion_step
        self._t_motion = -math.inf
        self._t_drift = None
        self.flicker = flicker
        # True when a simulated rig sets the poses (host.simrig): it decided contact on the tool's height and hands
        # over the stage's displacement through its own map, so a unit's off-skin test must not judge it again
        self.touching = False
        self.set_pose(np.zeros(5) if pose is None else pose)

    def set_pose(self, pose) -> None:
        self.pose = as_poses(pose)[0].copy()
        with np.errstate(all="ignore"):  # a pose far outside the sensor overflows the field: said below
            self.volts = readings(self.sensor, self.pose, touching=self.touching, adc_bits=0)[0]
        if not np.all(np.isfinite(self.volts)):
            raise InputError(f"the simulated pose {pose_label(self.pose)} gives readings that are not finite numbers: "
                             "it lies far outside the sensor")
        self._t_drift = None

    def at(self, t: float) -> None:
        """Move to time ``t``: the motion's pose and the drift there."""
        if self.motion is not None and abs(t - self._t_motion) >= self.motion_step:
            self._t_motion = t
            pose = as_poses(self.motion(t))[0]
            if not np.array_equal(pose, self.pose):
                self.set_pose(pose)
        if self.drift is not None and self._t_drift != t:
            self._t_drift = t
            self.drifted = self.drift.apply(self.volts, t)

    def temperature(self, t: float) -> float:
        return self.drift.temperature(t) if self.drift is not None else 25.0

    def element(self, k: int, t: float | None = None) -> float:
        if t is not None and (self.motion is not None or self.drift is not None):
            self.at(t)
            v = (self.drifted[k] if self.drift is not None else self.volts[k]) + self.offsets[k]
        else:
            v = self.volts[k] + self.offsets[k]
        if self.flicker is not None and t is not None:
            v += self.flicker.at(t)[k]
        return v + self.noise * self.rng.standard_normal() if self.noise else v
