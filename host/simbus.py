"""A simulated I2C bus with register-level ADS1115 and ADS7828 models, fed by the sensor's physics.

``SimBus`` has the method names and arguments of ``smbus2.SMBus`` (read_byte,
write_byte, read/write_byte_data, read/write_word_data, read/write_i2c_block_data,
i2c_rdwr, close), so the drivers cannot tell it from a real bus. Each call is one
I2C transfer: it takes the time its clock cycles take at ``bus_hz`` (start, address
and data bytes with their ACK bits, repeated start, stop) on the bus's clock, then
the addressed chip acts at the transfer's end.

The chips are modelled as the datasheets describe them: the ADS1115's pointer,
config (power-on 0x8583) and conversion registers, MSB first; single-shot
conversions that take 25 us to wake plus 1/DR (times 1 + ``rate_error``) with
the OS bit reading 0 meanwhile; continuous mode, where a new config applies from
the conversion after the one under way; PGA full scale and 16-bit clipping; input
pins clamped to -0.3..VDD+0.3 V; the general-call reset. The ADS7828's command
byte (its single-ended channel codes interleaved, PD1 switching the 2.5 V internal
reference), 12-bit results converted inside the read, several results in one read.

Pins are wired to the sensor's elements: ``fitgen.physics.transfer.readings`` for the
sensor in its ``gmr`` transfer (volts, before any ADC) at the pose set with
``set_pose``, plus per-element offsets and fresh Gaussian noise per conversion.

Faults: ``inject("nack" | "timeout" | "stuck", address=None, rate=1.0, after=0,
count=None)``. A NACK raises OSError(EREMOTEIO, 121) as Linux does for a chip
that does not acknowledge; a timeout OSError(ETIMEDOUT, 110); a stuck conversion
never completes (ADS1115: OS stays 0 until a general-call reset; ADS7828: the
read times out). ``silent`` in a fault spec is a NACK on every transfer from then on.
"""

from __future__ import annotations

import ctypes
import errno
import math
from dataclasses import dataclass, replace

import numpy as np

from fitgen.base.errors import InputError
from fitgen.physics.pose import POSE_NAMES, as_poses
from fitgen.physics.sensor import Sensor
from fitgen.physics.transfer import readings

from host.channelmap import ADDRESSES, ChannelMap
from host.clock import VirtualClock

# ADS1115 (independent of the driver's tables on purpose: a driver bug shows as a wrong answer)
_PGA_FS = (6.144, 4.096, 2.048, 1.024, 0.512, 0.256, 0.256, 0.256)
_RATES = (8, 16, 32, 64, 128, 250, 475, 860)
_DIFF_1115 = ((0, 1), (0, 3), (1, 3), (2, 3))
_CONFIG_RESET = 0x8583
_WAKE = 25e-6
# ADS7828, SBAS181 table 1: C2 C1 C0 -> input(s)
_SINGLE_7828 = {0b000: 0, 0b100: 1, 0b001: 2, 0b101: 3, 0b010: 4, 0b110: 5, 0b011: 6, 0b111: 7}
_DIFF_7828 = {0b000: (0, 1), 0b001: (2, 3), 0b010: (4, 5), 0b011: (6, 7),
              0b100: (1, 0), 0b101: (3, 2), 0b110: (5, 4), 0b111: (7, 6)}
_BLOCK_MAX = 32
FAULT_KINDS = ("nack", "timeout", "stuck")


class ADS1115Model:
    kind = "ads1115"

    def __init__(self, bus: "SimBus", address: int, *, rate_error: float = 0.0, vdd: float = 3.3):
        self.bus, self.address, self.rate_error, self.vdd = bus, address, rate_error, vdd
        self.reset()

    def reset(self) -> None:
        self.config = _CONFIG_RESET & 0x7FFF  # OS is not stored: reading it reports the state
        self.pointer = 0
        self.conversion = 0
        self.lo_thresh, self.hi_thresh = 0x8000, 0x7FFF
        self.single_done = None  # completion time of a single-shot conversion under way (inf: stuck)
        self.single_cfg = 0
        self.cont_done = None  # continuous mode: completion time of the conversion under way
        self.cont_cfg = 0  # ... and the config it uses
        self.conversions = 0

    def period(self, cfg: int) -> float:
        return (1.0 + self.rate_error) / _RATES[(cfg >> 5) & 7]

    def convert(self, cfg: int) -> int:
        mux, fs = (cfg >> 12) & 7, _PGA_FS[(cfg >> 9) & 7]
        pin = self.bus.pin_volts
        lo, hi = -0.3, self.vdd + 0.3
        if mux < 4:
            p, n = _DIFF_1115[mux]
            v = min(max(pin(self.address, p), lo), hi) - min(max(pin(self.address, n), lo), hi)
        else:
            v = min(max(pin(self.address, mux - 4), lo), hi)
        self.conversions += 1
        return int(min(max(round(v / fs * 32768.0), -32768), 32767))

    def settle(self, t: float) -> None:
        """Complete the conversions that have finished by time ``t``."""
        if self.single_done is not None and t >= self.single_done:
            self.conversion = self.convert(self.single_cfg)
            self.single_done = None
        if self.cont_done is not None and t >= self.cont_done:
            done, cfg = self.cont_done, self.cont_cfg
            period = self.period(self.config)
            if t >= done + period:  # later conversions, all with the current config
                done += math.floor((t - done) / period) * period
                cfg = self.config
            self.conversion = self.convert(cfg)
            self.cont_cfg = self.config
            self.cont_done = done + period

    def write(self, data: list[int], t: float) -> None:
        self.settle(t)
        self.pointer = data[0] & 0x03
        if len(data) < 3:
            return  # a pointer write only (a register changes when both of its bytes arrive)
        word = (data[1] << 8) | data[2]
        if self.pointer == 1:
            self._write_config(word, t)
        elif self.pointer == 2:
            self.lo_thresh = word
        elif self.pointer == 3:
            self.hi_thresh = word

    def _write_config(self, word: int, t: float) -> None:
        self.config = word & 0x7FFF
        if word & 0x0100:  # single-shot mode: power-down, a conversion when OS = 1 and none is under way
            self.cont_done = None
            if word & 0x8000 and self.single_done is None:
                stuck = self.bus.fault_fires("stuck", self.address)
                self.single_done = math.inf if stuck else t + _WAKE + self.period(word)
                self.single_cfg = word
        elif self.cont_done is None:  # into continuous mode
            stuck = self.bus.fault_fires("stuck", self.address)
            self.single_done = None
            self.cont_done = math.inf if stuck else t + _WAKE + self.period(word)
            self.cont_cfg = word
        # already continuous: the conversion under way keeps its config; settle() applies the new one after it

    def read(self, n: int, t: float) -> list[int]:
        self.settle(t)
        if self.pointer == 0:
            word = self.conversion & 0xFFFF
        elif self.pointer == 1:
            idle = self.single_done is None and self.cont_done is None
            word = self.config | (0x8000 if idle else 0)
        else:
            word = self.lo_thresh if self.pointer == 2 else self.hi_thresh
        return ([word >> 8, word & 0xFF] * ((n + 1) // 2))[:n]

    def general_call(self, data: list[int], t: float) -> None:
        if data == [0x06]:
            self.reset()


class ADS7828Model:
    kind = "ads7828"

    def __init__(self, bus: "SimBus", address: int, *, vref_external: float | None = 3.3, vdd: float = 3.3):
        self.bus, self.address, self.vref_external, self.vdd = bus, address, vref_external, vdd
        self.command = None
        self.conversions = 0

    def settle(self, t: float) -> None:
        pass

    def write(self, data: list[int], t: float) -> None:
        self.command = data[0]  # further bytes are not part of the protocol; the chip ignores them

    def read(self, n: int, t: float) -> list[int]:
        if self.command is None:
            return [0] * n
        if self.bus.fault_fires("stuck", self.address):
            raise OSError(errno.ETIMEDOUT, "Connection timed out")
        cmd = self.command
        code_bits = (cmd >> 4) & 7
        pin = self.bus.pin_volts
        clamp = lambda v: min(max(v, -0.3), self.vdd + 0.3)  # noqa: E731
        vref = 2.5 if cmd & 0x08 else self.vref_external
        out = []
        for _ in range(max(1, n // 2)):  # each further pair of bytes is a new conversion of the same input
            if cmd & 0x80:
                v = clamp(pin(self.address, _SINGLE_7828[code_bits]))
            else:
                p, m = _DIFF_7828[code_bits]
                v = clamp(pin(self.address, p)) - clamp(pin(self.address, m))
            code = 0 if vref is None else int(min(max(round(v / vref * 4096.0), 0), 4095))
            self.conversions += 1
            out += [code >> 8, code & 0xFF]
        return out[:n]

    def general_call(self, data: list[int], t: float) -> None:
        pass


@dataclass
class Fault:
    kind: str
    address: int | None = None
    rate: float = 1.0
    after: int = 0  # occasions that pass before the fault may fire
    count: int | None = None  # how many times it fires (None: no limit)
    seen: int = 0
    fired: int = 0


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


class SimBus:
    """A simulated ``smbus2.SMBus`` (see the module's text)."""

    def __init__(self, clock=None, *, bus_hz: float = 400_000.0, seed: int = 0):
        self.clock = clock if clock is not None else VirtualClock()
        self.bus_hz = float(bus_hz)
        self.rng = np.random.default_rng(seed)
        self.devices: dict[int, object] = {}
        self.wiring: dict[tuple[int, int], tuple] = {}  # (address, pin) -> ("element", k, add) | ("volts", v)
        self.feed: SensorFeed | None = None
        self.faults: list[Fault] = []
        self.injected = {k: 0 for k in FAULT_KINDS}
        self.transfers = 0
        self.bus_time = 0.0
        self.closed = False
        self.t0 = self.clock.monotonic()

    # --- building ----------------------------------------------------------------------

    def add_ads1115(self, address: int, **kw) -> ADS1115Model:
        self.devices[address] = dev = ADS1115Model(self, address, **kw)
        return dev

    def add_ads7828(self, address: int, **kw) -> ADS7828Model:
        self.devices[address] = dev = ADS7828Model(self, address, **kw)
        return dev

    def set_pin(self, address: int, pin: int, volts: float) -> None:
        self.wiring[(address, pin)] = ("volts", float(volts))

    def wire(self, address: int, pin: int, element: int, add: float = 0.0) -> None:
        """Pin ``pin`` of the chip at ``address`` carries element ``element`` (0-based) plus ``add`` volts."""
        self.wiring[(address, pin)] = ("element", int(element), float(add))

    def pin_volts(self, address: int, pin: int) -> float:
        w = self.wiring.get((address, pin))
        if w is None:
            return 0.0
        if w[0] == "volts":
            return w[1]
        # the feed's time (motion, drift) starts when the bus is made
        if w[0] == "ntc":
            return ntc_volts(self.feed.temperature(self.clock.monotonic() - self.t0), **w[1])
        return self.feed.element(w[1], self.clock.monotonic() - self.t0) + w[2]

    def wire_thermistor(self, address: int, pin: int, **divider) -> None:
        """Pin ``pin`` of the chip at ``address`` reads an NTC divider (:func:`ntc_volts`) at the drift's temperature."""
        self.wiring[(address, pin)] = ("ntc", dict(divider))

    def set_pose(self, pose) -> None:
        """Move the magnet; conversions finished before now keep the old pose's values."""
        t = self.clock.monotonic()
        for dev in self.devices.values():
            dev.settle(t)
        self.feed.set_pose(pose)

    @classmethod
    def for_channel_map(cls, cmap: ChannelMap, sensor: Sensor, pose=None, *, clock=None, noise: float = 0.0,
                        offsets=None, seed: int = 0, common_mode: float = 0.0, rate_error: float = 0.0,
                        bus_hz: float = 400_000.0, motion=None, drift: Drift | None = None,
                        thermistor=None) -> "SimBus":
        """The chips of ``cmap``, wired as it says to ``sensor``'s elements, the magnet at ``pose``.

        A differential pair's negative input sits at ``common_mode`` volts and its
        positive input at the element's voltage above it. ``motion`` and ``drift``: see
        :class:`SensorFeed`. ``thermistor``: a :class:`host.temperature.TemperatureInput` whose
        pin reads the NTC divider at the drift's temperature (its chip is added if the map has none there).
        """
        if cmap.n_elements != sensor.n_elements:
            raise InputError(f"the channel map reads {cmap.n_elements} elements; the simulated sensor "
                             f"{sensor.name!r} has {sensor.n_elements}")
        bus = cls(clock, bus_hz=bus_hz, seed=seed)
        bus.feed = SensorFeed(sensor, pose, noise=noise, offsets=offsets, rng=np.random.default_rng(seed + 1),
                              motion=motion, drift=drift)
        for chip in cmap.chips:
            if chip.kind == "ads1115":
                bus.add_ads1115(chip.address, rate_error=rate_error)
            else:
                bus.add_ads7828(chip.address,
                                vref_external=None if chip.settings.vref == "internal" else chip.vref_volts)
        for k, (chip, inp) in enumerate(cmap.elements()):
            if isinstance(inp, tuple):
                bus.wire(chip.address, inp[0], k, add=common_mode)
                bus.set_pin(chip.address, inp[1], common_mode)
            else:
                bus.wire(chip.address, inp, k)
        if thermistor is not None:
            if thermistor.address not in bus.devices:
                if thermistor.kind == "ads1115":
                    bus.add_ads1115(thermistor.address, rate_error=rate_error)
                else:
                    bus.add_ads7828(thermistor.address)
            bus.wire_thermistor(thermistor.address, thermistor.input, **thermistor.divider)
        return bus

    # --- faults --------------------------------------------------------------------

    def inject(self, kind: str, address: int | None = None, *, rate: float = 1.0, after: int = 0,
               count: int | None = None) -> Fault:
        if kind not in FAULT_KINDS:
            raise InputError(f"fault kind {kind!r} is not one of {', '.join(FAULT_KINDS)}")
        if not 0 < rate <= 1:
            raise InputError(f"fault rate must be in (0, 1], got {rate}")
        f = Fault(kind, address, float(rate), int(after), count)
        self.faults.append(f)
        return f

    def fault_fires(self, kind: str, address: int) -> bool:
        for f in self.faults:
            if f.kind != kind or (f.address is not None and f.address != address):
                continue
            f.seen += 1
            if f.seen <= f.after or (f.count is not None and f.fired >= f.count):
                continue
            if f.rate < 1.0 and self.rng.random() >= f.rate:
                continue
            f.fired += 1
            self.injected[kind] += 1
            return True
        return False

    # --- transfers -------------------------------------------------------------------

    def _transfer(self, address: int, wr: list[int] | None, rd: int):
        if self.closed:
            raise OSError(errno.EBADF, "Bad file descriptor")
        for b in wr or ():
            if not (isinstance(b, int) and 0 <= b <= 255):
                raise ValueError(f"byte {b!r} out of range 0..255")
        bits = 2 + 9 + 9 * len(wr or ()) + ((1 + 9 if wr else 0) + 9 * rd if rd else 0)
        dt = bits / self.bus_hz
        self.clock.sleep(dt)
        self.bus_time += dt
        self.transfers += 1
        t = self.clock.monotonic()
        if self.faults:
            if self.fault_fires("nack", address):
                raise OSError(errno.EREMOTEIO, "Remote I/O error")
            if self.fault_fires("timeout", address):
                raise OSError(errno.ETIMEDOUT, "Connection timed out")
        if address == 0x00:  # general call: every chip listens
            if not self.devices:
                raise OSError(errno.EREMOTEIO, "Remote I/O error")
            for dev in self.devices.values():
                dev.general_call(list(wr or ()), t)
            return []
        dev = self.devices.get(address)
        if dev is None:
            raise OSError(errno.EREMOTEIO, "Remote I/O error")
        if wr:
            dev.write(list(wr), t)
        return dev.read(rd, t) if rd else []

    # smbus2.SMBus's calls, same names and arguments

    def read_byte(self, i2c_addr, force=None):
        return self._transfer(i2c_addr, None, 1)[0]

    def write_byte(self, i2c_addr, value, force=None):
        self._transfer(i2c_addr, [value], 0)

    def read_byte_data(self, i2c_addr, register, force=None):
        return self._transfer(i2c_addr, [register], 1)[0]

    def write_byte_data(self, i2c_addr, register, value, force=None):
        self._transfer(i2c_addr, [register, value], 0)

    def read_word_data(self, i2c_addr, register, force=None):
        b = self._transfer(i2c_addr, [register], 2)
        return b[0] | (b[1] << 8)  # SMBus words travel low byte first

    def write_word_data(self, i2c_addr, register, value, force=None):
        self._transfer(i2c_addr, [register, value & 0xFF, (value >> 8) & 0xFF], 0)

    def read_i2c_block_data(self, i2c_addr, register, length, force=None):
        if not 0 < length <= _BLOCK_MAX:
            raise ValueError(f"Desired block length over {_BLOCK_MAX} bytes")
        return self._transfer(i2c_addr, [register], length)

    def write_i2c_block_data(self, i2c_addr, register, data, force=None):
        if len(data) > _BLOCK_MAX:
            raise ValueError(f"Data length cannot exceed {_BLOCK_MAX} bytes")
        self._transfer(i2c_addr, [register] + list(data), 0)

    def i2c_rdwr(self, *i2c_msgs):
        for msg in i2c_msgs:
            if msg.flags & 0x0001:  # I2C_M_RD
                data = self._transfer(msg.addr, None, msg.len)
                ctypes.memmove(msg.buf, bytes(data), msg.len)
            else:
                self._transfer(msg.addr, list(bytes(msg)), 0)

    def open(self, bus):
        self.closed = False

    def close(self):
        self.closed = True

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def parse_fault(spec: str) -> dict:
    """``nack:0.02``, ``timeout:0x48:0.01``, ``stuck:0.005``, ``silent:0x49:200`` -> keyword arguments of inject."""
    parts = spec.strip().lower().split(":")
    kind = parts[0]
    what = f"--sim-fault {spec!r}"
    try:
        if kind == "silent":
            if len(parts) not in (2, 3):
                raise ValueError
            addr = int(parts[1], 0)
            after = int(parts[2]) if len(parts) == 3 else 0
            if addr not in ADDRESSES or after < 0:
                raise ValueError
            return {"kind": "nack", "address": addr, "after": after}
        if kind in FAULT_KINDS and len(parts) in (2, 3):
            addr = int(parts[1], 0) if len(parts) == 3 else None
            rate = float(parts[-1])
            if (addr is not None and addr not in ADDRESSES) or not 0 < rate <= 1:
                raise ValueError
            return {"kind": kind, "address": addr, "rate": rate}
    except ValueError:
        pass
    raise InputError(f"{what}: expected nack|timeout|stuck[:ADDRESS]:RATE (0 < RATE <= 1) "
                     "or silent:ADDRESS[:AFTER_TRANSFERS], ADDRESS in 0x48..0x4b")


def parse_pose(spec: str) -> np.ndarray:
    """``dx=1,dz=-1`` (components left out are 0) or five numbers ``0.5,0,-1,0,0``."""
    from fitgen.base.parse import parse_assignments

    if "=" in spec:
        vals = parse_assignments(spec, POSE_NAMES, "--simulate pose")
        pose = np.array([vals.get(n, 0.0) for n in POSE_NAMES])
    else:
        parts = spec.replace(",", " ").split()
        try:
            pose = np.array([float(p) for p in parts])
        except ValueError:
            raise InputError(f"--simulate pose {spec!r}: not numbers") from None
        if pose.size != 5:
            raise InputError(f"--simulate pose {spec!r}: give 5 numbers ({','.join(POSE_NAMES)}) "
                             "or NAME=VALUE parts such as dx=1,dz=-1")
    if not np.all(np.isfinite(pose)):
        raise InputError(f"--simulate pose {spec!r}: not finite")
    return pose
