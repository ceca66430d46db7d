"""ADC drivers against the register-level simulated bus: registers, timing, channel maps, faults, pose recovery."""

import errno
import inspect
import json
import re

import numpy as np
import pytest
import smbus2

from fitgen.base.errors import InputError
from fitgen.fitting.fit import fit_model
from fitgen.physics.sensor import load_sensor
from fitgen.physics.simulate import grid_poses, simulate
from fitgen.physics.transfer import readings
from host.adc import ADS1115, ADS7828, AdcArray, BusIO, DeviceSilent, ads7828_channel_code
from host.channelmap import Settings, channel_map, parse_spec
from host.clock import VirtualClock
from host.motion import parse_pose
from host.simbus import SimBus, parse_fault

from conftest import assert_one_line_error, run_cli

TWO_1115 = "ads1115@0x48:0-3,ads1115@0x49:0-3"
POSE = np.array([1.2, -0.7, -1.4, 2.0, -3.0])  # no symmetry: eight distinct readings


def rig(spec, sensor, pose=POSE, settings=Settings(), **kw):
    cmap = parse_spec(spec, settings)
    clock = VirtualClock()
    bus = SimBus.for_channel_map(cmap, sensor, pose, clock=clock, **kw)
    return bus, AdcArray(bus, cmap, clock=clock), clock


def ads1115_bus(*volts):
    """(VirtualClock, SimBus) with one ADS1115 at 0x48, its AIN0, AIN1, ... at ``volts``."""
    clock = VirtualClock()
    bus = SimBus(clock)
    bus.add_ads1115(0x48)
    for pin, v in enumerate(volts):
        bus.set_pin(0x48, pin, v)
    return clock, bus


# --- register maps -----------------------------------------------------------------


def test_ads7828_command_bytes_follow_the_datasheet_table():
    # SBAS181 table 1, single-ended: SD=1, C2 C1 C0 interleaved; PD1 PD0 = 01 (reference off, converter on)
    expected = {0: 0x84, 1: 0xC4, 2: 0x94, 3: 0xD4, 4: 0xA4, 5: 0xE4, 6: 0xB4, 7: 0xF4}
    io = BusIO(SimBus())
    assert {ch: ADS7828(io, 0x48).command(ch) for ch in range(8)} == expected
    assert [ADS7828(io, 0x48, vref="internal").command(ch) for ch in range(8)] == [b | 0x08 for b in expected.values()]
    assert [ads7828_channel_code(ch) for ch in range(8)] == [0b000, 0b100, 0b001, 0b101, 0b010, 0b110, 0b011, 0b111]


def test_ads1115_config_words():
    io = BusIO(SimBus())
    # OS=1, AIN0-GND (100), +-4.096 V (001), single-shot, 860 SPS (111), comparator off (00011)
    assert ADS1115(io, 0x48).config_word(0) == 0b1_100_001_1_111_00011 == 0xC3E3
    # AIN0-AIN1 (000), +-2.048 V (010), continuous, 128 SPS (100), no start
    drv = ADS1115(io, 0x48, pga=2.048, data_rate=128)
    assert drv.config_word((0, 1), single=False, start=False) == 0x0483
    assert drv.config_word((2, 3), single=False, start=False) >> 12 == 0b011


def test_simbus_has_the_smbus2_calls_with_the_same_arguments():
    for name in ("read_byte", "write_byte", "read_byte_data", "write_byte_data", "read_word_data",
                 "write_word_data", "read_i2c_block_data", "write_i2c_block_data", "i2c_rdwr", "close", "open"):
        real = list(inspect.signature(getattr(smbus2.SMBus, name)).parameters)
        sim = list(inspect.signature(getattr(SimBus, name)).parameters)
        assert sim == real, name


def test_ads1115_model_registers_byte_order_and_conversion_time():
    clock, bus = ads1115_bus()
    assert bus.read_i2c_block_data(0x48, 1, 2) == [0x85, 0x83]  # power-on config, MSB first
    assert bus.read_word_data(0x48, 1) == 0x8385  # an SMBus word comes low byte first: swapped
    bus.set_pin(0x48, 0, 1.0)
    for rate, code in ((8, 0b000), (860, 0b111)):
        bus.write_i2c_block_data(0x48, 1, [0xC3, 0x03 | code << 5])  # OS, AIN0, 4.096 V, single-shot
        t0 = clock.monotonic()
        assert not bus.read_i2c_block_data(0x48, 1, 2)[0] & 0x80  # converting
        while not bus.read_i2c_block_data(0x48, 1, 2)[0] & 0x80:
            clock.sleep(1e-5)
        assert 1 / rate < clock.monotonic() - t0 < 1 / rate + 0.5e-3
        assert bus.read_i2c_block_data(0x48, 0, 2) == [0x1F, 0x40]  # 1.0 V / 4.096 V * 32768 = 8000


def test_single_conversions_through_the_drivers():
    clock = VirtualClock()
    bus = SimBus(clock)
    bus.add_ads1115(0x49)
    bus.add_ads7828(0x4B)
    for pin, v in enumerate((0.25, 1.5, 2.75, 0.5)):
        bus.set_pin(0x49, pin, v)
        bus.set_pin(0x4B, pin, v)
    io = BusIO(bus, clock)
    ads = ADS1115(io, 0x49, data_rate=8)
    assert [ads.read(p) for p in range(4)] == [0.25, 1.5, 2.75, 0.5]  # multiples of the 125 uV LSB
    assert clock.monotonic() == pytest.approx(4 / 8, rel=0.01)
    assert ads.read((1, 3)) == 1.0
    adc = ADS7828(io, 0x4B)
    assert [round(adc.read(p) / adc.lsb) for p in range(4)] == [round(v / 3.3 * 4096) for v in (0.25, 1.5, 2.75, 0.5)]


def test_ads1115_model_pga_clipping_and_negative_differential():
    clock, bus = ads1115_bus(2.5, 3.0)

    def convert(msb, lsb):
        bus.write_i2c_block_data(0x48, 1, [msb, lsb])
        clock.sleep(0.01)
        b = bus.read_i2c_block_data(0x48, 0, 2)
        code = b[0] << 8 | b[1]
        return code - 0x10000 if code & 0x8000 else code

    assert convert(0xC5, 0xE3) == 0x7FFF  # 2.5 V on +-2.048 V: clipped
    assert convert(0xC3, 0xE3) == round(2.5 / 4.096 * 32768)
    assert convert(0x83, 0xE3) == round(-0.5 / 4.096 * 32768)  # AIN0-AIN1 = -0.5 V
    bus.set_pin(0x48, 1, 0.0)
    assert convert(0x8B, 0xE3) == 0x7FFF  # +2.5 V differential on +-0.256 V (PGA 101)


def test_ads1115_model_continuous_mode_applies_a_new_input_after_the_conversion_under_way():
    clock, bus = ads1115_bus(1.0, 2.0)
    period = 1 / 860
    bus.write_i2c_block_data(0x48, 1, [0x42, 0xE3])  # continuous, AIN0
    clock.sleep(1.5 * period)
    assert bus.read_i2c_block_data(0x48, 1, 2)[0] & 0x80 == 0  # always converting
    bus.write_i2c_block_data(0x48, 1, [0x52, 0xE3])  # AIN1
    clock.sleep(0.8 * period)  # the conversion under way ends: still AIN0
    assert bus.read_i2c_block_data(0x48, 0, 2) == [0x1F, 0x40]
    clock.sleep(1.0 * period)  # the next one uses AIN1
    assert bus.read_i2c_block_data(0x48, 0, 2) == [0x3E, 0x80]
    bus.write_byte(0x00, 0x06)  # general-call reset: power-on state
    assert bus.read_i2c_block_data(0x48, 1, 2) == [0x85, 0x83]


def test_ads7828_model_channels_references_and_repeated_reads():
    bus = SimBus()
    bus.add_ads7828(0x4A, vref_external=3.3)
    for ch in range(8):
        bus.set_pin(0x4A, ch, 0.3 * (ch + 1))
    for ch, cmd in enumerate((0x84, 0xC4, 0x94, 0xD4, 0xA4, 0xE4, 0xB4, 0xF4)):
        b = bus.read_i2c_block_data(0x4A, cmd, 2)
        assert b[0] >> 4 == 0 and (b[0] << 8 | b[1]) == round(0.3 * (ch + 1) / 3.3 * 4096)
    b = bus.read_i2c_block_data(0x4A, 0xC4 | 0x08, 4)  # internal 2.5 V reference; two conversions in one read
    assert b[:2] == b[2:] and (b[0] << 8 | b[1]) == round(0.6 / 2.5 * 4096)
    bus.set_pin(0x4A, 7, 2.6)
    assert bus.read_i2c_block_data(0x4A, 0xF4 | 0x08, 2) == [0x0F, 0xFF]  # over the 2.5 V reference: full scale
    assert bus.read_i2c_block_data(0x4A, 0xF4, 2) == [0x0C, 0x9B]  # 2.6 / 3.3 * 4096 = 3227
    bus.add_ads7828(0x4B, vref_external=None)  # no external reference and the internal one off: no result
    bus.set_pin(0x4B, 0, 1.0)
    assert bus.read_i2c_block_data(0x4B, 0x84, 2) == [0, 0]


# --- drivers through the simulated bus -----------------------------------------------


@pytest.mark.parametrize("spec, settings, lsb", [
    (TWO_1115, Settings(), 4.096 / 32768),
    (TWO_1115, Settings(mode="continuous"), 4.096 / 32768),
    (TWO_1115, Settings(pga=6.144, data_rate=128), 6.144 / 32768),
    ("ads1115@0x48:d0-1,d2-3,ads1115@0x49:d0-1,d2-3,ads1115@0x4a:d0-1,d2-3,ads1115@0x4b:d0-1,d2-3",
     Settings(mode="continuous"), 4.096 / 32768),
    ("ads1115@0x48:d0-3,d1-3,2,ads1115@0x4b:0,1,2,3,ads1115@0x49:d0-1", Settings(), 4.096 / 32768),
    ("ads7828@0x48", Settings(), 3.3 / 4096),
    ("ads7828@0x4b:7,6,5,4,3,2,1,0", Settings(vref="internal"), 2.5 / 4096),
    ("ads7828@0x48:0-3,ads1115@0x49:0-3", Settings(), 3.3 / 4096),
])
def test_drivers_read_each_element_within_one_lsb(sensor, spec, settings, lsb):
    truth = readings(sensor, POSE, adc_bits=0)[0]
    assert np.min(np.diff(np.sort(truth))) > 10 * lsb  # distinct values: a mix-up of channels would show
    bus, arr, _ = rig(spec, sensor, settings=settings, common_mode=0.4)
    arr.probe()
    arr.setup()
    for _ in range(2):
        v = arr.read_volts()
        assert np.all(np.abs(v - truth) <= 0.5 * lsb + 1e-12), (v - truth) / lsb
    assert not arr.clipped.any()
    assert arr.counts.total == 0


def test_a_naive_ads7828_channel_code_reads_the_wrong_inputs(sensor, monkeypatch):
    # the simulated chip decodes the datasheet's table on its own: a driver using ch << 4 is caught
    truth = readings(sensor, POSE, adc_bits=0)[0]
    monkeypatch.setattr("host.adc.ads7828_channel_code", lambda ch: ch)
    _, arr, _ = rig("ads7828@0x48", sensor)
    v = arr.read_volts()
    assert np.max(np.abs(v - truth)) > 0.05
    assert np.allclose(v[[0, 4, 1, 5, 2, 6, 3, 7]], truth, atol=1e-3)


def test_pga_clipping_is_flagged(sensor):
    truth = readings(sensor, POSE, adc_bits=0)[0]
    _, arr, _ = rig(TWO_1115, sensor, settings=Settings(pga=2.048))
    v = arr.read_volts()
    assert np.array_equal(arr.clipped, truth > 2.048)
    assert arr.clipped.any() and np.allclose(v[arr.clipped], 2.048 * 32767 / 32768)


@pytest.mark.parametrize("spec, settings, expected", [
    # single-shot: 4 rounds of (25 us wake-up + 1/DR) and the transfers (2 chips x 3 transfers, ~0.1 ms each)
    (TWO_1115, Settings(), 4 * (25e-6 + 1 / 860) + 24 * 0.105e-3),
    (TWO_1115, Settings(data_rate=8), 4 * (25e-6 + 1 / 8)),
    # continuous with 4 inputs a chip: each switch waits two (10 % slow) periods
    (TWO_1115, Settings(mode="continuous"), 4 * (25e-6 + 2.2 / 860) + 16 * 0.105e-3),
    # ADS7828: 8 transfers of 48 clock cycles at 400 kHz
    ("ads7828@0x48", Settings(), 8 * 48 / 400e3),
])
def test_time_per_sample_follows_data_rate_and_bus_clock(sensor, spec, settings, expected):
    _, arr, clock = rig(spec, sensor, settings=settings)
    arr.setup()
    t0 = clock.monotonic()
    arr.read_volts()
    assert clock.monotonic() - t0 == pytest.approx(expected, rel=0.05)


def test_ads7828_time_scales_with_the_bus_clock(sensor):
    times = {}
    for hz in (100e3, 400e3):
        cmap = parse_spec("ads7828@0x48")
        clock = VirtualClock()
        arr = AdcArray(SimBus.for_channel_map(cmap, sensor, POSE, clock=clock, bus_hz=hz), cmap, clock=clock)
        arr.read_volts()
        times[hz] = clock.monotonic()
    assert times[100e3] == pytest.approx(4 * times[400e3])
    assert times[100e3] == pytest.approx(8 * 48 / 100e3)


def test_a_slow_oscillator_is_polled_out(sensor):
    truth = readings(sensor, POSE, adc_bits=0)[0]
    bus, arr, _ = rig(TWO_1115, sensor, rate_error=0.3)  # 30 % slow, beyond the datasheet's 10 %
    v = arr.read_volts()
    assert np.allclose(v, truth, atol=1e-4)
    assert bus.transfers > 24  # more than one OS poll per conversion


# --- faults ------------------------------------------------------------------------


def test_nacks_are_retried_with_back_off_and_counted(sensor):
    truth = readings(sensor, POSE, adc_bits=0)[0]
    bus, arr, clock = rig(TWO_1115, sensor)
    bus.inject("nack", address=0x48, count=3, after=5)
    v = arr.read_volts()
    assert np.allclose(v, truth, atol=1e-4)
    assert (arr.counts.nack, arr.counts.retries, arr.counts.timeout) == (3, 3, 0)
    assert clock.monotonic() > 4 * (1 / 860) + 0.001 + 0.002 + 0.004  # the back-off was waited


def test_bus_timeouts_are_counted_apart(sensor):
    bus, arr, _ = rig(TWO_1115, sensor)
    bus.inject("timeout", count=2)
    arr.read_volts()
    assert (arr.counts.timeout, arr.counts.nack, arr.counts.retries) == (2, 0, 2)


def test_a_stuck_conversion_is_reset_and_redone(sensor):
    truth = readings(sensor, POSE, adc_bits=0)[0]
    bus, arr, _ = rig(TWO_1115 + "", sensor)
    bus.inject("stuck", address=0x49, count=1, after=2)
    v = arr.read_volts()
    assert np.allclose(v, truth, atol=1e-4)
    assert (arr.counts.stuck, arr.counts.resets) == (1, 1)


def test_a_stuck_ads7828_read_times_out_and_is_retried(sensor):
    bus, arr, _ = rig("ads7828@0x48", sensor)
    bus.inject("stuck", count=1)
    arr.read_volts()
    assert (arr.counts.timeout, arr.counts.retries) == (1, 1)


def test_a_silent_chip_ends_with_a_clear_error(sensor):
    bus, arr, _ = rig(TWO_1115, sensor)
    arr.read_volts()
    bus.inject("nack", address=0x49)  # gone for good
    with pytest.raises(DeviceSilent, match=r"ads1115@0x49 stays silent: Remote I/O error \(errno 121\) on all 5 tries"):
        arr.read_volts()
    assert arr.counts.nack == 5 and arr.counts.retries == 4
    assert errno.EREMOTEIO == 121


def test_a_conversion_that_never_completes_ends_with_a_clear_error(sensor):
    bus, arr, _ = rig(TWO_1115, sensor)
    bus.inject("stuck", address=0x48)
    with pytest.raises(DeviceSilent, match="ads1115@0x48: a conversion never completes"):
        arr.read_volts()
    assert arr.counts.stuck == 5 and arr.counts.resets == 4


def test_probe_names_an_absent_chip_and_a_wrong_chip_type(sensor):
    cmap = parse_spec(TWO_1115)
    bus = SimBus()
    bus.add_ads1115(0x48)  # 0x49 missing
    with pytest.raises(InputError, match="no answer from ads1115@0x49"):
        AdcArray(bus, cmap, clock=bus.clock).probe()
    bus = SimBus.for_channel_map(parse_spec("ads7828@0x48"), sensor, POSE)
    with pytest.raises(InputError, match="does not behave as an ADS1115"):
        AdcArray(bus, parse_spec("ads1115@0x48:0-3,ads1115@0x49:0-3"), clock=bus.clock).drivers[0].probe(0)


# --- the acceptance: the pose back through the converters --------------------------


def _training(model, name, stat):
    return model.fit_info["outputs"][name]["model_training_error"][stat]


@pytest.mark.parametrize("spec, settings, dz_slack", [
    (TWO_1115, Settings(), 1.0),
    ("ads1115@0x48:d0-1,d2-3,ads1115@0x49:d0-1,d2-3,ads1115@0x4a:d0-1,d2-3,ads1115@0x4b:d0-1,d2-3",
     Settings(mode="continuous"), 1.0),
    # 12 bits over 3.3 V (0.8 mV) is coarse for this model's dz: up to ~0.4 mm from quantisation alone
    ("ads7828@0x48", Settings(), 2.0),
])
def test_simulated_pose_is_recovered_within_the_models_accuracy(sensor, model, spec, settings, dz_slack):
    rng = np.random.default_rng(11)
    lo, hi = np.array([-1.8, -1.8, -1.8, -4.5, -4.5]), np.array([1.8, 1.8, -0.2, 4.5, 4.5])
    poses = lo + (hi - lo) * rng.random((30, 5))
    bus, arr, _ = rig(spec, sensor, pose=poses[0], settings=settings)
    arr.setup()
    est = []
    for p in poses:
        bus.set_pose(p)
        est.append(model.predict(arr.read_volts())[0])
    err = np.abs(np.array(est) - poses)
    for j, name in enumerate(("dx", "dy")):
        assert err[:, j].max() <= 1.2 * _training(model, name, "max"), name
        assert np.sqrt(np.mean(err[:, j] ** 2)) <= 1.5 * _training(model, name, "rms"), name
    assert err[:, 2].max() <= 1.2 * dz_slack * _training(model, "dz", "max")
    # the rotations are poorly observable with this layout (docs/observe.md): only bounded loosely
    assert err[:, 3:].max() <= 1.5 * max(_training(model, "thx", "max"), _training(model, "thy", "max"))


# --- channel maps ------------------------------------------------------------------


def test_channel_map_specs():
    m = parse_spec("ads1115@0x48:0-3,ads1115@0x49:d0-1,d2-3,ads7828@0x4a:5,0")
    assert m.n_elements == 8
    assert [(c.label, i) for c, i in m.elements()] == [
        ("ads1115@0x48", 0), ("ads1115@0x48", 1), ("ads1115@0x48", 2), ("ads1115@0x48", 3),
        ("ads1115@0x49", (0, 1)), ("ads1115@0x49", (2, 3)), ("ads7828@0x4a", 5), ("ads7828@0x4a", 0)]
    assert parse_spec("ads7828@0x48").chips[0].inputs == tuple(range(8))
    assert parse_spec("ADS1115@72:0").chips[0].address == 0x48
    assert m.describe() == "ads1115@0x48:0,1,2,3,ads1115@0x49:d0-1,d2-3,ads7828@0x4a:5,0"


def test_a_spec_rewritten_to_read_in_another_order():
    """What identify offers when the channels read the ring in another order: the spec whose element j+1 is the
    old spec's element order[j]+1; none where a chip's inputs would part (a spec lists each chip once)."""
    from host.channelmap import reordered_spec

    spec = "ads1115@0x48:0-3,ads1115@0x49:d0-1,d2-3,ads7828@0x4a:5,0"
    for order in ([4, 5, 0, 1, 2, 3, 6, 7], [7, 6, 5, 4, 0, 1, 2, 3], [0, 1, 2, 3, 4, 5, 6, 7]):
        fixed = reordered_spec(spec, order)
        old, new = parse_spec(spec).elements(), parse_spec(fixed).elements()
        assert [(c.label, i) for c, i in new] == [(old[k][0].label, old[k][1]) for k in order], fixed
    assert reordered_spec(spec, [0, 4, 1, 2, 3, 5, 6, 7]) is None  # 0x48's inputs parted by one of 0x49's
    assert reordered_spec(spec, [0, 1]) is None and reordered_spec("map.toml", [0]) is None
    assert reordered_spec("ads1115@0x99:0", [0]) is None  # no address a chip takes


def test_channel_map_toml(tmp_path):
    f = tmp_path / "map.toml"
    f.write_text('bus = 3\n[[chip]]\ntype = "ads1115"\naddress = 0x49\ninputs = ["d0-1", "d2-3"]\npga = 2.048\n'
                 'mode = "continuous"\n[[chip]]\ntype = "ads7828"\naddress = 0x4b\ninputs = ["0-3", 4, 5]\n'
                 'vref = "internal"\n[[chip]]\ntype = "ads7828"\naddress = 0x4a\n')
    m = channel_map(str(f), Settings(data_rate=475))
    assert m.bus == 3 and m.n_elements == 16
    a, b, c = m.chips
    assert a.inputs == ((0, 1), (2, 3)) and a.settings == Settings(pga=2.048, data_rate=475, mode="continuous")
    assert b.inputs == (0, 1, 2, 3, 4, 5) and b.vref_volts == 2.5
    assert c.inputs == tuple(range(8)) and c.vref_volts == 3.3


@pytest.mark.parametrize("spec, message", [
    ("ads1015@0x48:0-3", "unknown chip 'ads1015'"),
    ("ads1115@0x50:0-3", "address 0x50"),
    ("ads1115@48:0-3", "address 48 is decimal 48 (0x30); I2C addresses are given in hex: 0x48"),
    ("ads1115@4b:0-3", "address '4b' is not a number (0x4b?)"),
    ("ads1115@0x48:0-3,ads1115@0x48:0-3", "given twice"),
    ("ads1115@0x48:0-4", "must lie in 0-3"),
    ("ads1115@0x48:d0-2", "not a pair the ADS1115 offers"),
    ("ads1115@0x48:0,0", "listed twice"),
    ("ads1115@0x48:d0-3,3", "pair's negative input"),
    ("ads7828@0x48:d0-1", "differential inputs are not supported"),
    ("0-3", "expected CHIP@ADDRESS"),
    ("ads1115@0x48:x", "neither N"),
    ("ads1115@0x48:0-3,,ads1115@0x49", "empty item"),
    ("nothere.toml", "no such file"),
])
def test_channel_map_errors(spec, message):
    with pytest.raises(InputError, match=re.escape(message)):
        channel_map(spec)


def test_fault_and_pose_specs():
    assert parse_fault("silent:0x49:200") == {"kind": "nack", "address": 0x49, "after": 200}
    assert parse_fault("nack:0.5") == {"kind": "nack", "address": None, "rate": 0.5}
    assert parse_fault("stuck:0x4a:1") == {"kind": "stuck", "address": 0x4A, "rate": 1.0}
    for bad in ("nack", "nack:2", "stuck:0x50:0.1", "silent", "melt:0.1"):
        with pytest.raises(InputError):
            parse_fault(bad)
    assert parse_pose("dx=1,dz=-1").tolist() == [1, 0, -1, 0, 0]
    assert parse_pose("0.5,0,-1,0,2").tolist() == [0.5, 0, -1, 0, 2]
    for bad in ("dq=1", "1,2,3", "a,b,c,d,e", "dx=nan"):
        with pytest.raises(InputError):
            parse_pose(bad)


# --- command line: bad input is one line and exit status 2 ------------------------------


@pytest.mark.parametrize("args, message", [
    (["--adc", "ads1015@0x48:0-3,ads1115@0x49:0-3", "--simulate", "dx=1"], "unknown chip 'ads1015'"),
    (["--adc", TWO_1115, "--bus", "99"], "/dev/i2c-99 does not exist"),
    (["--adc", TWO_1115, "--simulate", "dx=1,dq=2"], "--simulate pose"),
    (["--adc", "ads1115@0x48:0-3", "--simulate", "0,0,0,0,0"], "reads 4 elements; the model takes 8"),
    (["--adc", TWO_1115, "--pga", "5"], "invalid choice"),
    (["--adc", TWO_1115, "--simulate", "dx=0", "--rate", "-3"], "--rate must be a finite number > 0"),
    (["--adc", TWO_1115, "--sim-noise", "0.01"], "--sim-noise needs --simulate"),
    # each would be ignored: the seed without a simulation, a bus that a simulation opens no more than a sensor
    # file read neither for a simulation nor for a tare's rest
    (["--adc", TWO_1115, "--seed", "3"], "--seed needs --simulate"),
    (["--adc", TWO_1115, "--simulate", "dx=1", "--bus", "5"], "--bus does not go with --simulate"),
    (["--adc", TWO_1115, "--sensor", "paper"], "--sensor goes with --simulate, or --tare or --auto-zero without "
                                               "--rest"),
    (["--adc", TWO_1115, "--tare", "--rest", "paper", "--sensor", "paper"], "--sensor goes with --simulate, or"),
    (["--adc", TWO_1115, "--simulate", "dx=0", "--sim-fault", "melt:1"], "--sim-fault"),
    # a fault at a chip the map does not have would never fire
    (["--adc", TWO_1115, "--simulate", "dx=0", "--sim-fault", "nack:0x4b:0.9"], "--sim-fault 'nack:0x4b:0.9': no chip "
                                                                               "at 0x4b on the simulated bus (it has "
                                                                               "0x48, 0x49)"),
    (["--adc", TWO_1115, "--simulate", "dx=0", "--sim-fault", "silent:0x4a:20"], "no chip at 0x4a"),
    # absurd values had run: for ever, with every sample late, or with a chip retried for ever
    (["--adc", TWO_1115, "--simulate", "dx=0", "--duration", "1e308"], "--duration must be at most 2.592e+06"),
    (["--adc", TWO_1115, "--simulate", "dx=0", "--rate", "1e308"], "--rate must be at most 100000"),
    (["--adc", TWO_1115, "--simulate", "dx=0", "--retries", "99999999999"], "--retries must be at most 100"),
    (["--adc", TWO_1115, "--simulate", "dx=0", "--auto-zero", "--rest-hold", "1e308"], "--rest-hold must be at most"),
    (["--adc", TWO_1115, "--simulate", "dx=0", "--auto-zero", "--rest-band", "1e308,1e308"],
     "both must be numbers > 0, at most 1000 mm, then 180 deg"),
    (["--adc", TWO_1115, "--simulate", "dx=0", "--sim-offsets", "1e308,0,0,0,0,0,0,0"], "give numbers within +-100 V"),
    (["--adc", TWO_1115, "--simulate", "thx=1e6"], "thx must lie within -180..180 deg"),
])
def test_read_bad_input_is_one_line_exit_2(model_file, args, message):
    proc = run_cli("tactile-host", "read", "--model", model_file, *args)
    assert_one_line_error(proc, 2, message)


def test_read_refuses_a_model_in_millitesla(tmp_path):
    raw = fit_model(simulate(load_sensor("paper"), grid_poses({"dx": [-1, 0, 1], "dy": [-1, 0, 1],
                                                                "dz": [0, -1, -2]})), outputs=("dx",))
    path = raw.save(tmp_path / "raw.json")
    proc = run_cli("tactile-host", "read", "--model", str(path), "--adc", TWO_1115, "--simulate", "dx=0")
    assert_one_line_error(proc, 2, "takes inputs in mT")


def test_the_c_enum_of_chip_kinds_is_the_protocols_list():
    """A chip's kind number stood in three places (the protocol's ADC_KINDS, adc.h's enum, a literal in the C
    drivers' table); the table takes the protocol's now, and adc.h's enum must agree with it."""
    from importlib import resources

    from host.protocol import ADC_KINDS

    text = (resources.files("firmware_templates") / "firmware" / "adc.h").read_text()
    body = re.search(r"enum \{([^}]*ADC_ADS1115[^}]*)\}", text)[1]  # the kinds' enum, every member of it
    enum = dict((m[1].lower(), int(m[2])) for m in re.finditer(r"ADC_(\w+) = (\d+)", body))
    assert len(enum) == body.count("=") and enum == {k: i for i, k in enumerate(ADC_KINDS)}


def test_the_c_drivers_thermistor_range_is_the_hosts():
    """adc_code_degc reads no temperature outside ADC_DEGC_MIN..ADC_DEGC_MAX, as the host's Thermometer reads none
    outside T_RANGE: the two must be one range."""
    from importlib import resources

    from host.temperature import T_RANGE

    text = (resources.files("firmware_templates") / "firmware" / "adc.h").read_text()
    got = [float(re.search(rf"#define ADC_DEGC_{end} \(?(-?[\d.]+)\)?", text)[1]) for end in ("MIN", "MAX")]
    assert tuple(got) == T_RANGE


@pytest.mark.parametrize("kind, key, value", [("ads7828", "pga", 2.048), ("ads7828", "mode", "continuous"),
                                              ("ads7828", "data_rate", 128), ("ads1115", "vref", 3.3)])
def test_a_map_file_refuses_a_setting_of_the_other_chip(tmp_path, kind, key, value):
    """--vref on an ADS1115 or --pga on an ADS7828 is refused on the command line; a TOML [[chip]] took them and
    ignored them."""
    from host.channelmap import load_map_file

    path = tmp_path / "map.toml"
    path.write_text(f'[[chip]]\ntype = "{kind}"\naddress = 0x48\n{key} = {json.dumps(value)}\n')
    with pytest.raises(InputError, match=f"chip\\[0\\]: {key} is not a setting of an {kind}"):
        load_map_file(path)
