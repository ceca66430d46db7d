"""Register-level models of the ADS1115 and ADS7828 as a simulated bus (host.simbus.SimBus) addresses them.

The chips are modelled as the datasheets describe them: the ADS1115's pointer,
config (power-on 0x8583) and conversion registers, MSB first; single-shot
conversions that take 25 us to wake plus 1/DR (times 1 + ``rate_error``) with
the OS bit reading 0 meanwhile; continuous mode, where a new config applies from
the conversion after the one under way; PGA full scale and 16-bit clipping; input
pins clamped to -0.3..VDD+0.3 V; the general-call reset. The ADS7828's command
byte (its single-ended channel codes interleaved, PD1 switching the 2.5 V internal
reference), 12-bit results converted inside the read, several results in one read.

A chip reads its pins' volts from ``bus.pin_volts(address, pin)`` and asks
``bus.fault_fires("stuck", address)`` whether a conversion sticks.
"""

from __future__ import annotations

import errno
import math

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


class ADS1115Model:
    kind = "ads1115"

    def __init__(self, bus, address: int, *, rate_error: float = 0.0, vdd: float = 3.3):
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

    def __init__(self, bus, address: int, *, vref_external: float | None = 3.3, vdd: float = 3.3):
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
