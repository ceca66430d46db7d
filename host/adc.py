"""I2C ADC drivers (TI ADS1115, TI ADS7828) over smbus2 calls, and the array that reads every element.

Register maps (TI datasheets SBAS444 and SBAS181):

ADS1115 -- a pointer byte selects the register: 0 conversion, 1 config (2 and 3:
comparator thresholds, unused here). Registers are 16-bit words sent MSB first.
Config bits: 15 OS (write 1: start a single conversion; read 0: converting),
14:12 MUX (000 AIN0-AIN1, 001 AIN0-AIN3, 010 AIN1-AIN3, 011 AIN2-AIN3, 100..111
AINx-GND), 11:9 PGA (+-6.144, 4.096, 2.048, 1.024, 0.512, 0.256 V), 8 MODE
(1 single-shot, 0 continuous), 7:5 DR (8, 16, 32, 64, 128, 250, 475, 860 SPS),
4:0 comparator (00011: disabled). Result: two's complement, 0x7FFF = +full scale.
A conversion takes 1/DR (internal oscillator, +-10 %).

ADS7828 -- no registers: a command byte SD C2 C1 C0 PD1 PD0 x x selects the input
and power mode, and the next two bytes read are the 12-bit result (0000 D11..D8,
D7..D0), converted inside the transfer. Single-ended (SD = 1) channel codes are
interleaved: CH0 000, CH1 100, CH2 001, CH3 101, CH4 010, CH5 110, CH6 011,
CH7 111 (code = (ch & 1) << 2 | ch >> 1). PD1 = 1 keeps the internal 2.5 V
reference on; PD0 = 1 keeps the converter on between conversions.

Which smbus2 calls: ``write_i2c_block_data(addr, reg, [msb, lsb])`` and
``read_i2c_block_data(addr, reg, 2)`` for both chips. They put the bytes on the
wire in the order given (write: pointer then MSB, LSB; read: pointer, repeated
start, MSB, LSB), which is the chips' order; ``read_word_data`` would hand back
an SMBus word, low byte first, and need a byte swap that is easy to get wrong.
For the ADS7828 the "register" byte of the block read is its command byte, so one
combined transfer sends the command and reads the result.
"""

from __future__ import annotations

import errno
from dataclasses import dataclass, field

import numpy as np

from fitgen.base.errors import InputError

from host.channelmap import ADS1115_PAIRS, ADS1115_PGA, ADS1115_RATES, ChannelMap, Chip, check_bus
from host.clock import REAL_CLOCK

# --- ADS1115 -----------------------------------------------------------------------
REG_CONVERSION, REG_CONFIG = 0x00, 0x01
OS_BIT = 0x8000
MODE_SINGLE = 0x0100
COMP_DISABLE = 0x0003
CONFIG_DEFAULT = 0x8583  # the power-on value of the config register
MUX_SINGLE = {0: 0b100, 1: 0b101, 2: 0b110, 3: 0b111}
MUX_PAIR = dict(zip(ADS1115_PAIRS, range(4)))  # (0,1) 000, (0,3) 001, (1,3) 010, (2,3) 011
PGA_CODE = {p: n for n, p in enumerate(ADS1115_PGA)}
DR_CODE = {r: n for n, r in enumerate(ADS1115_RATES)}
WAKE_S = 25e-6  # power-up from power-down before a single-shot conversion
RATE_TOLERANCE = 1.1  # the oscillator may run 10 % slow
GENERAL_CALL, RESET_COMMAND = 0x00, 0x06  # I2C general-call reset: every ADS1115 on the bus resets

# --- ADS7828 -----------------------------------------------------------------------
SD_SINGLE = 0x80
PD_REF_ON = 0x08  # PD1: internal reference on
PD_ADC_ON = 0x04  # PD0: converter on between conversions

NACK_ERRNOS = (errno.EREMOTEIO, errno.ENXIO)
TIMEOUT_ERRNOS = (errno.ETIMEDOUT,)


def ads7828_channel_code(ch: int) -> int:
    """The C2 C1 C0 code of single-ended channel ``ch`` (interleaved, datasheet table 1)."""
    return ((ch & 1) << 2) | (ch >> 1)


class DeviceSilent(RuntimeError):
    """A chip that keeps failing after every retry: the run cannot go on."""


class ConversionStuck(RuntimeError):
    def __init__(self, label: str):
        super().__init__(f"{label}: conversion did not complete (OS bit stays 0)")
        self.label = label


@dataclass
class ErrorCounts:
    """I2C trouble seen so far: failed transfers by kind, retries made, resets sent."""

    nack: int = 0
    timeout: int = 0
    stuck: int = 0
    other: int = 0
    retries: int = 0
    resets: int = 0

    @property
    def total(self) -> int:
        return self.nack + self.timeout + self.stuck + self.other

    def as_dict(self) -> dict:
        return {"nack": self.nack, "timeout": self.timeout, "stuck": self.stuck, "other": self.other,
                "retries": self.retries, "resets": self.resets}


@dataclass(frozen=True)
class RetryPolicy:
    """Tries per transfer (or per conversion), and the back-off between them: first, first*factor, ..."""

    attempts: int = 5
    first_delay: float = 0.001
    factor: float = 2.0
    max_delay: float = 0.05

    def __post_init__(self):
        if self.attempts < 1:
            raise InputError(f"retries: at least 1 try is needed, got {self.attempts}")


def _count(counts: ErrorCounts, exc: OSError) -> None:
    if exc.errno in NACK_ERRNOS:
        counts.nack += 1
    elif exc.errno in TIMEOUT_ERRNOS:
        counts.timeout += 1
    else:
        counts.other += 1


@dataclass
class BusIO:
    """A bus with retries: an ``OSError`` from a transfer is counted, waited out with back-off and retried."""

    bus: object
    clock: object = REAL_CLOCK
    policy: RetryPolicy = RetryPolicy()
    counts: ErrorCounts = field(default_factory=ErrorCounts)

    def call(self, label: str, fn, *args):
        try:
            return fn(*args)
        except OSError as exc:
            return self._retry(label, fn, args, exc)

    def _retry(self, label, fn, args, exc):
        p = self.policy
        delay = p.first_delay
        for _ in range(p.attempts - 1):
            _count(self.counts, exc)
            self.counts.retries += 1
            self.clock.sleep(delay)
            delay = min(delay * p.factor, p.max_delay)
            try:
                return fn(*args)
            except OSError as again:
                exc = again
        _count(self.counts, exc)
        why = exc.strerror or str(exc)
        raise DeviceSilent(f"{label} stays silent: {why} (errno {exc.errno}) on all {p.attempts} tries") from None


class ADS1115:
    kind = "ads1115"
    code_min, code_max = -0x8000, 0x7FFF

    def __init__(self, io: BusIO, address: int, *, pga: float = 4.096, data_rate: int = 860, mode: str = "single"):
        if pga not in PGA_CODE:
            raise InputError(f"ads1115: pga {pga!r} is not one of {', '.join(map(str, ADS1115_PGA))}")
        if data_rate not in DR_CODE:
            raise InputError(f"ads1115: data rate {data_rate!r} is not one of {', '.join(map(str, ADS1115_RATES))}")
        self.io, self.address, self.pga, self.data_rate, self.mode = io, address, pga, data_rate, mode
        self.label = f"ads1115@0x{address:02x}"
        self.lsb = pga / 32768.0
        self.period = 1.0 / data_rate
        self.timeout = 2.0 * self.period + 2e-3  # from the start of a conversion to giving up on it
        self.poll = max(50e-6, self.period / 50)
        self._base = (PGA_CODE[pga] << 9) | (DR_CODE[data_rate] << 5) | COMP_DISABLE
        self._cache: dict = {}
        self._write = io.bus.write_i2c_block_data
        self._read = io.bus.read_i2c_block_data

    def config_word(self, inp, *, single: bool = True, start: bool = True) -> int:
        mux = MUX_SINGLE[inp] if isinstance(inp, int) else MUX_PAIR[tuple(inp)]
        return (OS_BIT if start else 0) | (mux << 12) | self._base | (MODE_SINGLE if single else 0)

    def _config_bytes(self, inp, single: bool, start: bool) -> list[int]:
        key = (inp, single, start)
        b = self._cache.get(key)
        if b is None:
            w = self.config_word(inp, single=single, start=start)
            b = self._cache[key] = [w >> 8, w & 0xFF]
        return b

    def write_config(self, word: int) -> None:
        self.io.call(self.label, self._write, self.address, REG_CONFIG, [word >> 8, word & 0xFF])

    def read_config(self) -> int:
        b = self.io.call(self.label, self._read, self.address, REG_CONFIG, 2)
        return (b[0] << 8) | b[1]

    def start(self, inp) -> None:
        """Single-shot: write the config with OS = 1; the conversion takes 1/DR."""
        self.io.call(self.label, self._write, self.address, REG_CONFIG, self._config_bytes(inp, True, True))

    def select(self, inp) -> None:
        """Continuous mode on ``inp``: the conversion under way finishes with the old input, the next uses it."""
        self.io.call(self.label, self._write, self.address, REG_CONFIG, self._config_bytes(inp, False, False))

    def busy(self) -> bool:
        b = self.io.call(self.label, self._read, self.address, REG_CONFIG, 2)
        return not b[0] & 0x80

    def fetch_code(self) -> int:
        b = self.io.call(self.label, self._read, self.address, REG_CONVERSION, 2)
        code = (b[0] << 8) | b[1]
        return code - 0x10000 if code & 0x8000 else code

    def read(self, inp) -> float:
        """One single-shot conversion of ``inp`` in volts (start, wait 1/DR, poll OS, fetch)."""
        clock = self.io.clock
        t0 = clock.monotonic()
        self.start(inp)
        clock.sleep(self.period + WAKE_S)
        while self.busy():
            if clock.monotonic() - t0 > self.timeout:
                raise ConversionStuck(self.label)
            clock.sleep(self.poll)
        return self.fetch_code() * self.lsb

    def probe(self, inp) -> None:
        """Write a config and read it back: a chip that answers differently is not an ADS1115."""
        word = self.config_word(inp, single=True, start=False)
        self.write_config(word)
        back = self.read_config()
        if (back & 0x7FFF) != (word & 0x7FFF):
            raise InputError(f"the device at 0x{self.address:02x} does not behave as an ADS1115 (config 0x{word:04x} "
                             f"written, 0x{back:04x} read back); is the chip type in --adc right?")


class ADS7828:
    kind = "ads7828"
    code_min, code_max = 0, 0x0FFF

    def __init__(self, io: BusIO, address: int, *, vref: float | str = 3.3):
        self.io, self.address = io, address
        self.label = f"ads7828@0x{address:02x}"
        self.internal = vref == "internal"
        self.vref = 2.5 if self.internal else float(vref)
        self.lsb = self.vref / 4096.0
        # internal reference: keep it on (PD1) so it settles once; external: reference off, converter on
        self.power_bits = (PD_REF_ON | PD_ADC_ON) if self.internal else PD_ADC_ON
        self._read = io.bus.read_i2c_block_data
        self._commands = [self.command(ch) for ch in range(8)]

    def command(self, ch: int) -> int:
        if not 0 <= ch <= 7:
            raise InputError(f"ads7828: channel {ch} does not exist (0-7)")
        return SD_SINGLE | (ads7828_channel_code(ch) << 4) | self.power_bits

    def read_code(self, ch: int) -> int:
        b = self.io.call(self.label, self._read, self.address, self._commands[ch], 2)
        return ((b[0] & 0x0F) << 8) | b[1]

    def read(self, ch: int) -> float:
        return self.read_code(ch) * self.lsb

    def probe(self, ch: int) -> None:
        b = self.io.call(self.label, self._read, self.address, self._commands[ch], 2)
        if b[0] & 0xF0:
            raise InputError(f"the device at 0x{self.address:02x} does not behave as an ADS7828 (its result's top "
                             f"4 bits are not 0: 0x{b[0]:02x}{b[1]:02x}); is the chip type in --adc right?")


def make_driver(io: BusIO, chip: Chip):
    s = chip.settings
    if chip.kind == "ads1115":
        return ADS1115(io, chip.address, pga=s.pga, data_rate=s.data_rate, mode=s.mode)
    if chip.kind == "ads7828":
        return ADS7828(io, chip.address, vref=s.vref)
    raise InputError(f"unknown chip {chip.kind!r}")


@dataclass
class _Round:
    single: list = field(default_factory=list)  # (driver, input, element): single-shot conversions
    switch: list = field(default_factory=list)  # continuous mode, input changed each round
    fixed: list = field(default_factory=list)  # (driver, element): continuous mode on its only input
    direct: list = field(default_factory=list)  # (driver, channel, element): ADS7828, converted in the transfer
    wait: float = 0.0


class AdcArray:
    """Every element of a channel map read once per call, conversions on different chips overlapping.

    ADS1115 chips convert in parallel: round r starts the r-th input of every chip,
    waits 1/DR (polling the OS bit past it, under a timeout) and fetches the results;
    8 elements on two chips take 4 rounds. A chip in continuous mode with one input is
    configured once and only read; with several inputs each change of input waits two
    conversion periods (the one under way still uses the old input). ADS7828 channels
    are read during the first round's wait. A stuck conversion is answered with an
    I2C general-call reset (it resets every ADS1115 on the bus) and the round again.
    """

    def __init__(self, bus, cmap: ChannelMap, *, clock=REAL_CLOCK, policy: RetryPolicy = RetryPolicy(),
                 counts: ErrorCounts | None = None):
        self.cmap, self.clock, self.policy = cmap, clock, policy
        self.counts = counts if counts is not None else ErrorCounts()
        self.io = BusIO(bus, clock, policy, self.counts)
        self.drivers = [make_driver(self.io, c) for c in cmap.chips]
        self.n = cmap.n_elements
        self.lsb = np.empty(self.n)
        self.code_min = np.empty(self.n)
        self.code_max = np.empty(self.n)
        per_chip, el = [], 0
        for drv, chip in zip(self.drivers, cmap.chips):
            items = [(inp, el + j) for j, inp in enumerate(chip.inputs)]
            el += len(items)
            per_chip.append((drv, items))
            for _, i in items:
                self.lsb[i], self.code_min[i], self.code_max[i] = drv.lsb, drv.code_min, drv.code_max
        n_rounds = max([len(items) for drv, items in per_chip if drv.kind == "ads1115"] + [1])
        self.rounds = [_Round() for _ in range(n_rounds)]
        self._fixed = []
        for drv, items in per_chip:
            if drv.kind == "ads7828":
                self.rounds[0].direct.extend((drv, ch, i) for ch, i in items)
            elif drv.mode == "single":
                for r, (inp, i) in enumerate(items):
                    self.rounds[r].single.append((drv, inp, i))
                    self.rounds[r].wait = max(self.rounds[r].wait, drv.period + WAKE_S)
            elif len(items) == 1:
                self.rounds[0].fixed.append((drv, items[0][1]))
                self._fixed.append((drv, items[0][0]))
            else:
                for r, (inp, i) in enumerate(items):
                    self.rounds[r].switch.append((drv, inp, i))
                    self.rounds[r].wait = max(self.rounds[r].wait, 2 * RATE_TOLERANCE * drv.period + WAKE_S)
        self.rounds = [r for r in self.rounds if r.single or r.switch or r.fixed or r.direct]
        self._codes = [0] * self.n
        self.clipped = np.zeros(self.n, dtype=bool)

    # --- set-up ----------------------------------------------------------------------

    def probe(self) -> None:
        """Check that every chip answers as the chip it is said to be (InputError otherwise)."""
        for drv, chip in zip(self.drivers, self.cmap.chips):
            first = chip.inputs[0]
            try:
                drv.probe(first)
            except DeviceSilent as exc:
                raise InputError(f"no answer from {drv.label}: {exc}; check the wiring, its address pins "
                                 "and `i2cdetect -y BUS`") from None

    def setup(self) -> None:
        """Put continuous-mode chips with one input on it and wait for their first conversion."""
        wait = 0.0
        for drv, inp in self._fixed:
            drv.select(inp)
            wait = max(wait, RATE_TOLERANCE * drv.period + WAKE_S)
        self.clock.sleep(wait)

    def reset(self) -> None:
        """I2C general-call reset (every ADS1115 back to its power-on state), then set up again."""
        self.counts.resets += 1
        self.io.call("general-call reset", self.io.bus.write_byte, GENERAL_CALL, RESET_COMMAND)
        self.setup()

    # --- reading ---------------------------------------------------------------------

    def _round(self, rnd: _Round, codes: list) -> None:
        clock = self.clock
        for drv, inp, _ in rnd.single:
            drv.start(inp)
        for drv, inp, _ in rnd.switch:
            drv.select(inp)
        t0 = clock.monotonic()  # the last conversion started now
        for drv, ch, i in rnd.direct:
            codes[i] = drv.read_code(ch)
        for drv, i in rnd.fixed:
            codes[i] = drv.fetch_code()
        if rnd.wait:
            clock.sleep(t0 + rnd.wait - clock.monotonic())
        for drv, _, i in rnd.single:
            while drv.busy():
                if clock.monotonic() - t0 > drv.timeout:
                    raise ConversionStuck(drv.label)
                clock.sleep(drv.poll)
            codes[i] = drv.fetch_code()
        for drv, _, i in rnd.switch:
            codes[i] = drv.fetch_code()

    def read_codes(self) -> np.ndarray:
        """Raw codes of every element (n,), each round retried after a reset when a conversion sticks."""
        codes = self._codes
        for rnd in self.rounds:
            tries = 0
            while True:
                try:
                    self._round(rnd, codes)
                    break
                except ConversionStuck as exc:
                    tries += 1
                    self.counts.stuck += 1
                    if tries >= self.policy.attempts:
                        raise DeviceSilent(f"{exc.label}: a conversion never completes (OS bit stays 0), "
                                           f"{tries} tries with a general-call reset between them") from None
                    self.counts.retries += 1
                    self.reset()
        return np.array(codes, dtype=float)

    def read_volts(self) -> np.ndarray:
        """Volts at every element's input (n,); ``clipped`` marks inputs at the converter's full scale."""
        codes = self.read_codes()
        self.clipped = (codes >= self.code_max) | (codes <= self.code_min)
        return codes * self.lsb


def open_bus(number: int):
    """``smbus2.SMBus(number)``; a missing or forbidden /dev/i2c-N is bad input (one line, exit 2)."""
    check_bus(number, "the bus")
    try:
        import smbus2
    except ImportError:  # pragma: no cover - a dependency of the package
        raise InputError("the smbus2 package is not installed (pip install smbus2)") from None
    path = f"/dev/i2c-{number}"
    try:
        return smbus2.SMBus(number)
    except FileNotFoundError:
        raise InputError(f"I2C bus {number}: {path} does not exist (enable I2C: raspi-config, or dtparam=i2c_arm=on "
                         "in config.txt; see docs/readout.md), or simulate the sensor (--simulate)") from None
    except PermissionError:
        raise InputError(f"I2C bus {number}: permission denied on {path} (add the user to the i2c group: "
                         "sudo adduser $USER i2c, then log in again)") from None
    except OSError as exc:
        raise InputError(f"I2C bus {number}: cannot open {path}: {exc.strerror}") from None
