"""The C ADC drivers (firmware_templates/firmware/adc.c) against the Python drivers (host/adc.py), both
answering to the same register-level bus model (host/simbus.py) with the same faults."""

import ctypes
import shutil
import subprocess
from importlib import resources

import numpy as np
import pytest

from fitgen.base.errors import InputError
from fitgen.physics.sensor import load_sensor
from host.adc import ADS1115, ADS7828, AdcArray, BusIO, DeviceSilent, RetryPolicy
from host.cdrivers import ERR_CONFIG, AdcI2c, AdcPolicy, CAdcArray, chip_table, library
from host.channelmap import Settings, parse_spec
from host.clock import VirtualClock
from fitgen.c.compiled import WARNING_FLAGS
from host.simbus import SimBus

from conftest import require_tool

SENSOR = load_sensor("paper")
POSE = [0.5, 0.2, -1.0, 1.0, 0.0]
TWO = "ads1115@0x48:0-3,ads1115@0x49:0-3"


def _run(cls, spec, settings=Settings(), faults=(), reads=5, seed=3):
    """Probe, set up and read a few times; returns (codes or the error, counts, transfers, clock, injected)."""
    cmap = parse_spec(spec, settings)
    clock = VirtualClock()
    bus = SimBus.for_channel_map(cmap, SENSOR, POSE, clock=clock, noise=0.0005, seed=seed)
    for f in faults:
        bus.inject(**f)
    arr = cls(bus, cmap, clock=clock, policy=RetryPolicy())
    out = []
    try:
        arr.probe()
        arr.setup()
        for _ in range(reads):
            out.append(arr.read_codes())
    except DeviceSilent as exc:
        out.append(("silent", str(exc).split(":")[0].split(" ")[0]))
    return out, arr.counts.as_dict(), bus.transfers, clock.t, dict(bus.injected)


CASES = [
    (TWO, Settings(), ()),
    (TWO, Settings(mode="continuous"), ()),
    ("ads1115@0x48:d0-1,d2-3,ads1115@0x49:0-3,ads1115@0x4a:0,ads1115@0x4b:1", Settings(mode="continuous"), ()),
    ("ads1115@0x48:0-3,ads1115@0x49:0-3", Settings(pga=2.048, data_rate=128), ()),
    ("ads7828@0x4a", Settings(), ()),
    ("ads7828@0x4a:0-3,ads1115@0x48:0-3", Settings(vref="internal"), ()),
    # every fault the Python bus model injects
    (TWO, Settings(), [dict(kind="nack", rate=0.3)]),
    (TWO, Settings(), [dict(kind="timeout", address=0x49, rate=0.2)]),
    (TWO, Settings(), [dict(kind="stuck", address=0x49, count=2)]),
    ("ads7828@0x4a:0-3,ads1115@0x48:0-3", Settings(vref="internal"), [dict(kind="stuck", address=0x4A, count=3)]),
    (TWO, Settings(), [dict(kind="nack", address=0x49, after=30)]),  # a chip that falls silent
    (TWO, Settings(), [dict(kind="stuck", address=0x48)]),  # a conversion that never completes
]


@pytest.mark.parametrize("spec, settings, faults", CASES)
def test_c_drivers_give_the_python_drivers_codes_and_counts(spec, settings, faults):
    require_tool("gcc")
    py = _run(AdcArray, spec, settings, faults)
    c = _run(CAdcArray, spec, settings, faults)
    assert len(py[0]) == len(c[0])
    for a, b in zip(py[0], c[0]):
        if isinstance(a, tuple):
            assert a == b  # the same error, on the same chip
        else:
            np.testing.assert_array_equal(a, b)
    assert py[1] == c[1]  # NACKs, timeouts, stuck conversions, retries and resets, counted alike
    assert py[2] == c[2]  # the same number of bus transfers
    assert py[4] == c[4]  # and the same faults fired
    assert c[3] == pytest.approx(py[3], abs=1e-7)  # the same bus time, to the C clock's nanosecond
    if faults:
        assert sum(py[1].values()) > 0  # the fault did something


def test_a_silent_chip_is_an_error_not_a_hang():
    require_tool("gcc")
    cmap = parse_spec(TWO)
    clock = VirtualClock()
    bus = SimBus.for_channel_map(cmap, SENSOR, POSE, clock=clock, seed=1)
    bus.inject("nack", address=0x49)
    arr = CAdcArray(bus, cmap, clock=clock)
    with pytest.raises(InputError, match="no answer from ads1115@0x49"):
        arr.probe()
    with pytest.raises(DeviceSilent, match="ads1115@0x49"):
        arr.read_codes()
    assert clock.t < 1.0  # the back-off is bounded: 1 + 2 + 4 + 8 ms per transfer


def test_config_words_and_commands_match_the_python_drivers():
    require_tool("gcc")
    lib = library()
    lib.adc_ads1115_config.argtypes = [ctypes.c_void_p, ctypes.c_uint8, ctypes.c_uint8, ctypes.c_int, ctypes.c_int]
    lib.adc_ads1115_config.restype = ctypes.c_uint16
    lib.adc_ads7828_command.argtypes = [ctypes.c_void_p, ctypes.c_uint8]
    lib.adc_ads7828_command.restype = ctypes.c_uint8
    for pga in (6.144, 0.256):
        for rate in (8, 860):
            cmap = parse_spec("ads1115@0x48:0-3,ads1115@0x49:d0-1,d2-3,ads1115@0x4a:d0-3,ads1115@0x4b:d1-3",
                              Settings(pga=pga, data_rate=rate))
            arr = CAdcArray(SimBus(), cmap)
            for i, chip in enumerate(cmap.chips):
                drv = ADS1115(BusIO(SimBus()), chip.address, pga=pga, data_rate=rate)
                for j, inp in enumerate(chip.inputs):
                    for single, start in ((1, 1), (0, 0), (1, 0)):
                        assert lib.adc_ads1115_config(arr.array, i, j, single, start) == drv.config_word(
                            inp, single=bool(single), start=bool(start))
    for vref in ("internal", 3.3):
        cmap = parse_spec("ads7828@0x4b", Settings(vref=vref))
        table = chip_table(cmap)
        drv = ADS7828(BusIO(SimBus()), 0x4B, vref=vref)
        assert [lib.adc_ads7828_command(ctypes.byref(table[0]), ch) for ch in range(8)] == [drv.command(ch)
                                                                                          for ch in range(8)]


def test_bad_maps_are_refused_by_the_c_drivers():
    require_tool("gcc")
    lib = library()
    i2c = AdcI2c()
    buf = ctypes.create_string_buffer(lib.adc_shim_sizeof())
    pol = lib.adc_default_policy()
    assert isinstance(pol, AdcPolicy) and pol.attempts == RetryPolicy().attempts
    good = chip_table(parse_spec(TWO))
    assert lib.adc_init(buf, ctypes.byref(i2c), good, 2, pol) == 0
    for field, value in (("n_inputs", 5), ("address", 0x50), ("pga", 6), ("rate", 8), ("kind", 2)):
        table = chip_table(parse_spec(TWO))
        setattr(table[1], field, value)
        assert lib.adc_init(buf, ctypes.byref(i2c), table, 2, pol) == ERR_CONFIG, field
    table = chip_table(parse_spec(TWO))
    table[0].neg[0] = 2  # AIN0 - AIN2 is not a pair the ADS1115's MUX offers
    assert lib.adc_init(buf, ctypes.byref(i2c), table, 2, pol) == ERR_CONFIG
    assert lib.adc_init(buf, ctypes.byref(i2c), good, 0, pol) == ERR_CONFIG


@pytest.mark.parametrize("core", ["-mcpu=cortex-m0 -mthumb -mfloat-abi=soft",
                                  "-mcpu=cortex-m4 -mthumb -mfloat-abi=hard -mfpu=fpv4-sp-d16"])
def test_drivers_build_warning_free_for_cortex_m(core, tmp_path):
    gcc = require_tool("arm-none-eabi-gcc")
    src = resources.files("firmware_templates") / "firmware"
    for name in ("adc.h", "adc.c"):
        (tmp_path / name).write_bytes((src / name).read_bytes())
    proc = subprocess.run([gcc, *core.split(), *WARNING_FLAGS, "-Wconversion", "-O2", "-c", str(tmp_path / "adc.c"),
                           "-o", str(tmp_path / "adc.o")], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    nm = shutil.which("arm-none-eabi-nm")
    undefined = subprocess.run([nm, "-u", str(tmp_path / "adc.o")], capture_output=True, text=True).stdout
    assert "malloc" not in undefined and "free" not in undefined
