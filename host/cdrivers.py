"""The C ADC drivers (firmware_templates/firmware/adc.c) run from Python: a bus answers their I2C calls.

``CAdcArray`` has ``AdcArray``'s interface (probe, setup, read_codes, read_volts, counts,
clipped) but every transfer, wait and retry is decided by the C code, built by gcc into a
shared library and called through ctypes. Its three I2C calls go to the same smbus2 calls the
Python drivers make (a write of [register, data...] to ``write_i2c_block_data`` or ``write_byte``,
a register read to ``read_i2c_block_data``), so a ``host.simbus.SimBus`` with its fault
injection, or a real ``smbus2.SMBus``, answers both languages alike: for the same pose, noise
seed and faults they give the same codes and the same error counts (tests/test_cdrivers.py).
"""

from __future__ import annotations

import ctypes
import tempfile
from importlib import resources
from pathlib import Path

import numpy as np

from fitgen.base.errors import InputError

from host.adc import NACK_ERRNOS, TIMEOUT_ERRNOS, DeviceSilent, ErrorCounts, RetryPolicy
from host.channelmap import ADS1115_PGA, ADS1115_RATES, ChannelMap
from host.clock import REAL_CLOCK
from host.protocol import ADC_KINDS
from fitgen.c.compiled import compile_checked

I2C_OK, I2C_NACK, I2C_TIMEOUT, I2C_OTHER = 0, 1, 2, 3
ADC_OK, ERR_CONFIG, ERR_SILENT, ERR_STUCK, ERR_NOT_CHIP = 0, -1, -2, -3, -4
SINGLE_ENDED = 0xFF

# the shim reads what ctypes need not mirror: the array's size, counts and failed chip
_SHIM = r"""
#include <stddef.h>
#include "adc.h"
size_t adc_shim_sizeof(void) { return sizeof(adc_array); }
void adc_shim_counts(const adc_array *a, uint32_t out[6])
{
    out[0] = a->counts.nack; out[1] = a->counts.timeout; out[2] = a->counts.stuck;
    out[3] = a->counts.other; out[4] = a->counts.retries; out[5] = a->counts.resets;
}
int adc_shim_failed_chip(const adc_array *a) { return a->failed_chip; }
int adc_shim_n_elements(const adc_array *a) { return a->n_elements; }
"""


class AdcChip(ctypes.Structure):
    _fields_ = [("kind", ctypes.c_uint8), ("address", ctypes.c_uint8), ("n_inputs", ctypes.c_uint8),
                ("pos", ctypes.c_uint8 * 8), ("neg", ctypes.c_uint8 * 8), ("pga", ctypes.c_uint8),
                ("rate", ctypes.c_uint8), ("continuous", ctypes.c_uint8), ("vref_internal", ctypes.c_uint8),
                ("vref", ctypes.c_double)]


class AdcPolicy(ctypes.Structure):
    _fields_ = [("attempts", ctypes.c_uint8), ("first_delay_ns", ctypes.c_uint64), ("factor", ctypes.c_uint32),
                ("max_delay_ns", ctypes.c_uint64)]


WRITE = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_uint8, ctypes.POINTER(ctypes.c_uint8),
                         ctypes.c_uint16)
READ = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_uint8, ctypes.POINTER(ctypes.c_uint8),
                        ctypes.c_uint16)
WRITE_READ = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_uint8, ctypes.POINTER(ctypes.c_uint8),
                              ctypes.c_uint16, ctypes.POINTER(ctypes.c_uint8), ctypes.c_uint16)
NOW = ctypes.CFUNCTYPE(ctypes.c_uint64, ctypes.c_void_p)
SLEEP = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.c_uint64)


class AdcI2c(ctypes.Structure):
    _fields_ = [("ctx", ctypes.c_void_p), ("write", WRITE), ("read", READ), ("write_read", WRITE_READ),
                ("now_ns", NOW), ("sleep_ns", SLEEP)]


_LIB = None


def library(workdir: str | Path | None = None) -> ctypes.CDLL:
    """adc.c and the shim built by gcc (the project's warning flags) into a shared library, once."""
    global _LIB
    if _LIB is None:
        folder = Path(workdir or tempfile.mkdtemp(prefix="fitgen-cdrivers-"))
        src = resources.files("firmware_templates") / "firmware"
        for name in ("adc.h", "adc.c"):
            (folder / name).write_bytes((src / name).read_bytes())
        (folder / "adc_shim.c").write_text(_SHIM)
        out = folder / "libadc.so"
        compile_checked("gcc", [folder / "adc.c", folder / "adc_shim.c"], out, folder, ["-shared", "-fPIC"])
        lib = ctypes.CDLL(str(out))
        lib.adc_shim_sizeof.restype = ctypes.c_size_t
        lib.adc_default_policy.restype = AdcPolicy
        lib.adc_init.argtypes = [ctypes.c_void_p, ctypes.POINTER(AdcI2c), ctypes.POINTER(AdcChip), ctypes.c_uint8,
                                 AdcPolicy]
        for fn in ("adc_probe", "adc_setup"):
            getattr(lib, fn).argtypes = [ctypes.c_void_p]
        lib.adc_read_codes.argtypes = [ctypes.c_void_p, ctypes.POINTER(ctypes.c_int32)]
        lib.adc_lsb_volts.argtypes = [ctypes.POINTER(AdcChip)]
        lib.adc_lsb_volts.restype = ctypes.c_double
        lib.adc_shim_counts.argtypes = [ctypes.c_void_p, ctypes.POINTER(ctypes.c_uint32)]
        lib.adc_shim_failed_chip.argtypes = [ctypes.c_void_p]
        lib.adc_shim_n_elements.argtypes = [ctypes.c_void_p]
        _LIB = lib
    return _LIB


def chip_table(cmap: ChannelMap):
    """The channel map as the C drivers' adc_chip array."""
    table = (AdcChip * len(cmap.chips))()
    for c, chip in zip(table, cmap.chips):
        c.kind = ADC_KINDS.index(chip.kind)  # adc.h's enum, which a test holds to the protocol's list
        c.address = chip.address
        c.n_inputs = len(chip.inputs)
        for j, inp in enumerate(chip.inputs):
            c.pos[j], c.neg[j] = (inp[0], inp[1]) if isinstance(inp, tuple) else (inp, SINGLE_ENDED)
        s = chip.settings
        c.pga = ADS1115_PGA.index(s.pga)
        c.rate = ADS1115_RATES.index(s.data_rate)
        c.continuous = int(s.mode == "continuous")
        c.vref_internal = int(s.vref == "internal")
        c.vref = 0.0 if s.vref == "internal" else float(s.vref)
    return table


def smbus_transfer(bus, addr: int, wr: list[int], nr: int) -> list[int]:
    """One transfer of the C drivers as the smbus2 call the Python drivers make for it: a register
    read (one pointer byte, then nr bytes) is ``read_i2c_block_data``, a one-byte write ``write_byte``,
    a longer write ``write_i2c_block_data``, a bare read an ``i2c_rdwr`` read message."""
    if wr and nr:
        if len(wr) != 1:
            raise InputError("the C drivers read registers with a one-byte pointer only")
        return list(bus.read_i2c_block_data(addr, wr[0], nr))
    if nr:
        from smbus2 import i2c_msg

        msg = i2c_msg.read(addr, nr)
        bus.i2c_rdwr(msg)
        return list(bytes(msg))
    if len(wr) == 1:
        bus.write_byte(addr, wr[0])
    else:
        bus.write_i2c_block_data(addr, wr[0], list(wr[1:]))
    return []


def _status_of(exc: OSError) -> int:
    if exc.errno in NACK_ERRNOS:
        return I2C_NACK
    if exc.errno in TIMEOUT_ERRNOS:
        return I2C_TIMEOUT
    return I2C_OTHER


class CAdcArray:
    """The C drivers reading every element of a channel map over ``bus`` (an smbus2.SMBus or a SimBus)."""

    def __init__(self, bus, cmap: ChannelMap, *, clock=REAL_CLOCK, policy: RetryPolicy = RetryPolicy()):
        self.lib, self.bus, self.cmap, self.clock = library(), bus, cmap, clock
        self.chips = chip_table(cmap)
        self.n = cmap.n_elements
        self._error: BaseException | None = None
        self.i2c = AdcI2c(None, WRITE(self._write), READ(self._read), WRITE_READ(self._write_read),
                          NOW(self._now), SLEEP(self._sleep))
        self.array = ctypes.create_string_buffer(self.lib.adc_shim_sizeof())
        pol = AdcPolicy(policy.attempts, round(policy.first_delay * 1e9), int(policy.factor),
                        round(policy.max_delay * 1e9))
        if policy.factor != int(policy.factor):
            raise InputError("the C drivers take a whole back-off factor")
        st = self.lib.adc_init(self.array, ctypes.byref(self.i2c), self.chips, len(self.chips), pol)
        if st != ADC_OK:
            raise InputError(f"the C drivers refuse the channel map {cmap.describe()} (status {st})")
        self.lsb = np.array([self.lib.adc_lsb_volts(ctypes.byref(self.chips[i]))
                             for i, chip in enumerate(cmap.chips) for _ in chip.inputs])
        self.code_min = np.array([-0x8000 if chip.kind == "ads1115" else 0 for chip in cmap.chips for _ in chip.inputs])
        self.code_max = np.array([0x7FFF if chip.kind == "ads1115" else 0x0FFF for chip in cmap.chips
                                  for _ in chip.inputs])
        self.clipped = np.zeros(self.n, dtype=bool)
        self._codes = (ctypes.c_int32 * self.n)()

    # --- the bus and the clock the C code calls -------------------------------------------

    def _guard(self, fn, *args) -> int:
        try:
            fn(*args)
            return I2C_OK
        except OSError as exc:
            return _status_of(exc)
        except BaseException as exc:  # noqa: BLE001 - never across the C frames: re-raised after the call
            self._error = exc
            return I2C_OTHER

    def _transfer(self, addr, wr, nr, rd=None):
        def run():
            for i, x in enumerate(smbus_transfer(self.bus, addr, wr, nr)):
                rd[i] = x
        return self._guard(run)

    def _write(self, ctx, addr, data, n):
        return self._transfer(addr, data[:n], 0)

    def _read(self, ctx, addr, data, n):
        return self._transfer(addr, [], n, data)

    def _write_read(self, ctx, addr, wr, nw, rd, nr):
        return self._transfer(addr, wr[:nw], nr, rd)

    def _now(self, ctx):
        return round(self.clock.monotonic() * 1e9)

    def _sleep(self, ctx, ns):
        self.clock.sleep(ns * 1e-9)

    # --- AdcArray's interface ----------------------------------------------------------------

    def _call(self, fn, *args) -> int:
        self._error = None
        st = fn(self.array, *args)
        if self._error is not None:
            raise self._error
        return st

    def _raise(self, st: int, what: str) -> None:
        if st == ADC_OK:
            return
        chip = self.lib.adc_shim_failed_chip(self.array)
        label = self.cmap.chips[chip].label if 0 <= chip < len(self.cmap.chips) else "general-call reset"
        if st == ERR_NOT_CHIP:
            raise InputError(f"the device at 0x{self.cmap.chips[chip].address:02x} does not behave as an "
                             f"{self.cmap.chips[chip].kind.upper()}; is the chip type in --adc right?")
        if st == ERR_STUCK:
            raise DeviceSilent(f"{label}: a conversion never completes (OS bit stays 0)")
        raise DeviceSilent(f"{label} stays silent during {what}")

    @property
    def counts(self) -> ErrorCounts:
        out = (ctypes.c_uint32 * 6)()
        self.lib.adc_shim_counts(self.array, out)
        return ErrorCounts(*out)

    def probe(self) -> None:
        st = self._call(self.lib.adc_probe)
        if st == ERR_SILENT:
            raise InputError(f"no answer from {self.cmap.chips[self.lib.adc_shim_failed_chip(self.array)].label}; "
                             "check the wiring, its address pins and `i2cdetect -y BUS`")
        self._raise(st, "the probe")

    def setup(self) -> None:
        self._raise(self._call(self.lib.adc_setup), "set-up")

    def read_codes(self) -> np.ndarray:
        self._raise(self._call(self.lib.adc_read_codes, self._codes), "a read")
        return np.array(self._codes[:], dtype=float)

    def read_volts(self) -> np.ndarray:
        codes = self.read_codes()
        self.clipped = (codes >= self.code_max) | (codes <= self.code_min)
        return codes * self.lsb

