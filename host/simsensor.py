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
from fitgen.physics.pose import as_poses
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


def ntc_volts(temp_degc: float, *, beta: float = 3950.0, r25: float = 10_000.0, series: float = 10_000.0,
              vref: float = 3.3) -> float:
    """The divider's output: an NTC (beta model, r25 at 25 degC) to ground, ``series`` ohms to ``vref``."""
    r = r25 * math.exp(beta * (1.0 / (temp_degc + 273.15) - 1.0 / 298.15))
    return vref * r / (r + series)


class SensorFeed:
    """Element voltages of a sensor (its ``gmr`` transfer, no ADC) at a pose, with offsets and noise.

    ``motion``: a function of the bus clock's time (s) giving the pose, evaluated at most every
    ``motion_step`` seconds; ``drift``: a :class:`Drift` applied to the volts at that time.
    """

    def __init__(self, sensor: Sensor, pose=None, *, noise: float = 0.0, offsets=None,
                 rng: np.random.Generator | None = None, motion=None, drift: Drift | None = None,
                 motion_step: float = 5e-3):
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
        self.set_pose(np.zeros(5) if pose is None else pose)

    def set_pose(self, pose) -> None:
        self.pose = as_poses(pose)[0].copy()
        self.volts = readings(self.sensor, self.pose, adc_bits=0)[0]
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
        return v + self.noise * self.rng.standard_normal() if self.noise else v
