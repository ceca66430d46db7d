"""Element transfer models: signed field along the sensitive axis -> reading.

``raw``: |B . r_hat| in mT (the paper's simulation); a built unit's element gains and offsets
act on it (fitgen.physics.units). ``gmr``: the NVE AA003-02's
omnipolar response in volts, linear in |B . r_hat| up to saturation, amplified,
offset, and clipped and quantised by the ADC. Noise is added before the ADC.
"""

from __future__ import annotations

import numpy as np

from fitgen.physics.sensor import TRANSFERS, Sensor

OE_PER_MT = 10.0  # 1 Oe = 0.1 mT in air


def quantise(x: np.ndarray, lo: float, hi: float, bits: int) -> np.ndarray:
    """Clip to [lo, hi] and round to the nearest of 2**bits codes' centres (bits = 0: clip only)."""
    x = np.clip(x, lo, hi)
    if bits <= 0:
        return x
    lsb = (hi - lo) / (2**bits - 1)
    return lo + np.round((x - lo) / lsb) * lsb


def missing_noise(sensor: Sensor) -> str:
    """The words for a sensor whose active transfer gives no reading noise (a file that leaves it out reads 0)."""
    return (f"sensor {sensor.name} gives no noise figure for its {sensor.transfer} transfer (noise missing or 0 in "
            f"[transfer.{sensor.transfer}])")


def step_rms(sensor: Sensor) -> tuple[float, float]:
    """The active transfer's ADC step (LSB, in its units) and its rounding as noise, LSB / sqrt(12); (0, 0) where
    it does not quantise."""
    if sensor.transfer == "raw":
        bits, span = sensor.raw.adc_bits, sensor.raw.full_scale
    else:
        bits, span = sensor.gmr.adc_bits, sensor.gmr.adc_max - sensor.gmr.adc_min
    if bits <= 0:
        return 0.0, 0.0
    lsb = span / (2**bits - 1)
    return lsb, lsb / np.sqrt(12.0)


def volts_per_mt(g) -> float:
    """The gmr transfer's slope: volts out per mT of |B . axis| (supply x sensitivity x amplifier gain)."""
    return g.supply * g.sensitivity * 1e-3 * OE_PER_MT * g.gain


def linear_top(sensor: Sensor) -> float:
    """The least |B . axis| (mT) at which a drawing's reading stops following the field: the element's saturation
    or the ADC's top rail, whichever comes first (gmr); the raw transfer's full scale when it is quantised, else
    infinity."""
    if sensor.transfer == "raw":
        return sensor.raw.full_scale if sensor.raw.adc_bits > 0 else float("inf")
    g = sensor.gmr
    return min(g.saturation, (g.adc_max - g.offset) / volts_per_mt(g))


def past_linear(sensor: Sensor, b_axis: np.ndarray) -> np.ndarray:
    """Where a reading has stopped following its field (bool, the shape of ``b_axis``, signed fields in mT): the
    element saturated, or its output on the ADC's rails; a raw transfer only where it is quantised, past its
    full scale."""
    mag = np.abs(b_axis)
    if sensor.transfer == "raw":
        if sensor.raw.adc_bits <= 0:
            return np.zeros(mag.shape, dtype=bool)
        return element_response(sensor, mag) >= sensor.raw.full_scale
    g = sensor.gmr
    out = _gmr_volts(sensor, mag)
    return (mag >= g.saturation) | (out >= g.adc_max) | (out <= g.adc_min)


def _gmr_volts(sensor: Sensor, mag: np.ndarray) -> np.ndarray:
    """The gmr transfer's volts for |B . axis| ``mag`` (mT), saturated, before noise and the ADC."""
    g = sensor.gmr
    return g.offset + volts_per_mt(g) * element_response(sensor, np.minimum(mag, g.saturation))


def element_response(sensor: Sensor, mag: np.ndarray) -> np.ndarray:
    """Each element's field-equivalent output (mT) from |B . axis|: its gain and offset (a unit's; 1 and 0
    on a drawing)."""
    if sensor.is_drawing:
        return mag.copy()
    return sensor.gains * mag + sensor.offsets


def apply_transfer(
    sensor: Sensor,
    b_axis: np.ndarray,
    *,
    noise: float | np.ndarray = 0.0,
    adc_bits: int | None = None,
    rng: np.random.Generator | None = None,
) -> np.ndarray:
    """Readings from signed fields ``b_axis`` (mT), in the sensor's output units.

    ``noise`` is an rms in output units, one number or one per element, added before the ADC;
    ``adc_bits`` overrides the sensor file's (0 turns quantisation off, not the ADC's range).
    """
    mag = np.abs(b_axis)
    if sensor.transfer == "raw":
        out = element_response(sensor, mag)
        bits = sensor.raw.adc_bits if adc_bits is None else adc_bits
        lo, hi = 0.0, sensor.raw.full_scale
    else:
        g = sensor.gmr
        out = _gmr_volts(sensor, mag)
        bits = g.adc_bits if adc_bits is None else adc_bits
        lo, hi = g.adc_min, g.adc_max
    if np.any(np.asarray(noise) > 0):
        rng = rng or np.random.default_rng()
        out = out + rng.normal(0.0, noise, size=out.shape)
    # an ADC clips to its range whatever the rounding: the gmr transfer always has one, raw when its file gives bits
    if bits > 0 or sensor.transfer == "gmr" or sensor.raw.adc_bits > 0:
        out = quantise(out, lo, hi, bits)
    return out


def readings(sensor: Sensor, poses, touching: bool = False, **kw) -> np.ndarray:
    """Element readings (P, N) for a batch of poses, through the sensor's transfer; ``touching``: every pose in
    contact whatever its dz (fitgen.physics.pose.magnet_frame)."""
    from fitgen.physics.pose import field_readings

    return apply_transfer(sensor, field_readings(sensor, poses, touching), **kw)


def sensor_hashes(sensor: Sensor) -> set[str]:
    """The sensor's hash in either transfer: a record may hold either for the same sensor (a capture the file's as
    read, a simulation the one it read through)."""
    return {sensor.with_transfer(kind).sha256 for kind in TRANSFERS}


LINEAR_SHARE = 0.8  # of an element's linear range (linear_top) a scheduled or suggested pose may use


def within_linear_range(drawing: Sensor, poses: np.ndarray) -> np.ndarray:
    """Whether every element of ``drawing`` reads at most LINEAR_SHARE of its linear range at each pose (P,)."""
    from fitgen.physics.pose import field_readings

    top = linear_top(drawing)
    if not np.isfinite(top):
        return np.ones(len(poses), dtype=bool)
    return np.abs(field_readings(drawing, poses)).max(axis=1) <= LINEAR_SHARE * top
