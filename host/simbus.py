"""A simulated I2C bus with register-level ADS1115 and ADS7828 models, fed by the sensor's physics.

``SimBus`` has the method names and arguments of ``smbus2.SMBus`` (read_byte,
write_byte, read/write_byte_data, read/write_word_data, read/write_i2c_block_data,
i2c_rdwr, close), so the drivers cannot tell it from a real bus. Each call is one
I2C transfer: it takes the time its clock cycles take at ``bus_hz`` (start, address
and data bytes with their ACK bits, repeated start, stop) on the bus's clock, then
the addressed chip acts at the transfer's end.

The chips are ``host.simchips``'s register-level models; their pins are wired to the
elements of a ``host.simsensor.SensorFeed`` (the sensor's physics at a pose, with
offsets, noise, motion and drift). ``simulated_bus`` builds the bus of ``--simulate``.

Faults: ``inject("nack" | "timeout" | "stuck", address=None, rate=1.0, after=0,
count=None)``. A NACK raises OSError(EREMOTEIO, 121) as Linux does for a chip
that does not acknowledge; a timeout OSError(ETIMEDOUT, 110); a stuck conversion
never completes (ADS1115: OS stays 0 until a general-call reset; ADS7828: the
read times out). ``silent`` in a fault spec is a NACK on every transfer from then on.
"""

from __future__ import annotations

import ctypes
import errno
from dataclasses import dataclass

import numpy as np

from fitgen.base.errors import InputError
from fitgen.base.parse import parse_numbers
from fitgen.physics.sensor import MAX_VOLTS, Sensor

from host.channelmap import ADDRESSES, ChannelMap
from host.clock import VirtualClock
from host.simchips import ADS1115Model, ADS7828Model
from host.simsensor import Drift, Flicker, SensorFeed, ntc_volts

_BLOCK_MAX = 32
FAULT_KINDS = ("nack", "timeout", "stuck")


@dataclass
class Fault:
    kind: str
    address: int | None = None
    rate: float = 1.0
    after: int = 0  # occasions that pass before the fault may fire
    count: int | None = None  # how many times it fires (None: no limit)
    seen: int = 0
    fired: int = 0


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
                        thermistor=None, flicker: float = 0.0) -> "SimBus":
        """The chips of ``cmap``, wired as it says to ``sensor``'s elements, the magnet at ``pose``.

        A differential pair's negative input sits at ``common_mode`` volts and its
        positive input at the element's voltage above it. ``motion`` and ``drift``: see
        :class:`SensorFeed`. ``thermistor``: a :class:`host.temperature.TemperatureInput` whose
        pin reads the NTC divider at the drift's temperature (its chip is added if the map has none there).
        ``flicker``: V, the level of each element's 1/f noise (:class:`host.simsensor.Flicker`).
        """
        if cmap.n_elements != sensor.n_elements:
            raise InputError(f"the channel map reads {cmap.n_elements} elements; the simulated sensor "
                             f"{sensor.name!r} has {sensor.n_elements}: give the sensor file whose elements the map reads "
                             "(tactile-host's --sensor; --sim-sensor to tactile-hil emulate and tactile-host "
                             "arduino-build)")
        bus = cls(clock, bus_hz=bus_hz, seed=seed)
        # the flicker's own generator: the white noise draws what it draws without flicker
        fl = Flicker(float(flicker), sensor.n_elements, np.random.default_rng(seed + 2)) if flicker else None
        bus.feed = SensorFeed(sensor, pose, noise=noise, offsets=offsets, rng=np.random.default_rng(seed + 1),
                              motion=motion, drift=drift, flicker=fl)
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

    def present(self, address: int) -> bool:
        """Whether a chip acknowledges ``address`` (the general call: any chip), as an address phase alone."""
        return bool(self.devices) if address == 0x00 else address in self.devices

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


def simulated_bus(cmap: ChannelMap, sensor: Sensor, pose, *, clock, noise: float | None = None,
                  offsets: str | None = None, faults=(), seed: int = 0, motion=None, drift: Drift | None = None,
                  thermistor=None, flicker: float | None = None) -> SimBus:
    """The bus ``--simulate`` reads: ``cmap``'s chips wired to ``sensor`` at ``pose`` (:meth:`SimBus.for_channel_map`),
    element noise ``noise`` V rms (None: the sensor file's), ``offsets`` (``--sim-offsets``: one number per element,
    V), 1/f noise of Allan deviation ``flicker`` V (``--sim-flicker``) and the ``faults`` (``--sim-fault`` specs,
    :func:`parse_fault`) injected."""
    noise = sensor.gmr.noise if noise is None else noise
    values = None
    if offsets:
        values = parse_numbers(offsets)
        if values is None or not all(abs(v) <= MAX_VOLTS for v in values):  # as --sim-noise's bound: past any rail
            raise InputError(f"--sim-offsets {offsets!r}: give numbers within +-{MAX_VOLTS:g} V")
        if len(values) != sensor.n_elements:
            raise InputError(f"--sim-offsets: give {sensor.n_elements} numbers (V), got {len(values)}")
    specs = [parse_fault(f) for f in faults]
    if not (np.isfinite(noise) and noise >= 0):
        raise InputError(f"--sim-noise must be a finite number >= 0 V, got {noise}")
    if flicker is not None and not (np.isfinite(flicker) and flicker >= 0):
        raise InputError(f"--sim-flicker must be a finite number >= 0 V, got {flicker}")
    bus = SimBus.for_channel_map(cmap, sensor, pose, clock=clock, noise=noise, offsets=values, seed=seed,
                                 motion=motion, drift=drift, thermistor=thermistor, flicker=flicker or 0.0)
    for spec, f in zip(faults, specs):
        if f["address"] is not None and not bus.present(f["address"]):  # it would never fire
            held = ", ".join(f"0x{a:02x}" for a in ADDRESSES if bus.present(a))
            raise InputError(f"--sim-fault {spec!r}: no chip at 0x{f['address']:02x} on the simulated bus (it has "
                             f"{held})")
        bus.inject(**f)
    return bus
