"""The reference firmware reading its ADCs (issue 12, part 2): the C drivers in the firmware, through the
channel map, over the emulated board's I2C bridge to the bus model (host/simbus.py); STREAM carries
estimates from those readings, and a failed read is flagged instead of fed to the model."""

import os
import re
import shlex
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

import fitgen.physics
from hil.emulate import start_target
from hil.suite import READ_FAILED
from host import protocol as P
from host.adc import AdcArray, DeviceSilent, RetryPolicy
from host.device import Device
from host.engine import make_engine
from host.pi import StandIn

from conftest import TWO_CHIPS, assert_one_line_error, drifting_bus, require_tool, run_cli, sim_bus

MAP = TWO_CHIPS


@pytest.fixture(scope="module")
def model(device_model):
    return device_model


def _bus(faults=()):
    return sim_bus(MAP, faults)


def _stream(model, target, n, faults=()):
    cmap, bus, clock = _bus(faults)
    with start_target(model, target, precision="float", style="unrolled", cmap=cmap,
                      bridge=StandIn(bus, clock)) as emu:
        with Device.open(emu.url, timeout=5) as dev:
            samples = dev.stream(10, n, timeout=60)
            info = dev.info(refresh=True)
    return samples, info


def _python(model, n, faults=()):
    """The Python drivers on the same bus, through the float C engine (tactile-host read --engine c --precision
    float): inputs as the float firmware holds them, outputs, and the counts; None for a failed read."""
    cmap, bus, clock = _bus(faults)
    arr = AdcArray(bus, cmap, clock=clock, policy=RetryPolicy())
    arr.probe()
    arr.setup()
    rows = []
    engine = make_engine("c", model, precision="float", style="unrolled")  # tactile-host read's C engine
    try:
        for _ in range(n):
            try:
                v = arr.read_volts()
            except DeviceSilent:
                rows.append(None)
                continue
            out, status = engine.estimate(v)
            rows.append((v.astype(np.float32).astype(float), out, status))
    finally:
        engine.close()
    return rows, arr.counts


@pytest.mark.parametrize("target", ["host", "mps2"])
def test_stream_from_the_c_drivers_equals_the_python_readout(model, target):
    """On the emulated Cortex-M4 (and the host build) the firmware's STREAM, fed by the C ADS1115 driver and
    the bus model at a set pose, gives tactile-host read --engine c's estimates on the Python driver."""
    require_tool("gcc")
    if target == "mps2":
        require_tool("qemu-system-arm")
        require_tool("arm-none-eabi-gcc")
    n = 3 if target == "mps2" else 8
    faults = [dict(kind="nack", rate=0.1)]
    samples, info = _stream(model, target, n, faults)
    rows, counts = _python(model, n, faults)
    for s, (v, out, status) in zip(samples, rows):
        assert s.status == status
        np.testing.assert_array_equal(np.asarray(s.inputs), v)
        np.testing.assert_array_equal(np.asarray(s.outputs), out)
    assert info.adc_chips == (("ads1115", 0x48, 4, 1, 7, 0), ("ads1115", 0x49, 4, 1, 7, 0))
    assert info.adc_counts == counts.as_dict() and counts.nack > 0


@pytest.mark.parametrize("target", ["host", "mps2"])
def test_the_suites_stream_is_the_first_after_boot_and_reports_its_latency(model, target):
    """emulate --adc ... --suite: the suite's stream check is the firmware's first STREAM after boot (the ADCs
    are probed and set up on that read): 5 samples from the ADCs, none failed, each what EVAL gives for its
    inputs. When the first and the last arrived is reported (a figure for docs/hil.md, not a limit), and so
    is the suite's own duration, in its table and its JUnit XML."""
    import xml.etree.ElementTree as ET

    from hil.suite import run_suite

    require_tool("gcc")
    if target == "mps2":
        require_tool("qemu-system-arm")
        require_tool("arm-none-eabi-gcc")
    cmap, bus, clock = _bus()
    with start_target(model, target, precision="float", style="table", cmap=cmap,
                      bridge=StandIn(bus, clock)) as emu:
        with Device.open(emu.url, timeout=5) as dev:
            res = run_suite(dev, model, url=emu.url, n_vectors=50, n_fuzz=100, flash=False, verbose=False)
    assert res.ok, res.table()
    stream = {c.name: c for c in res.checks}["stream"]
    assert stream.figures["samples"] == 5 and "2 ADC chips" in stream.detail
    assert 0 < stream.figures["first_sample_s"] <= stream.figures["last_sample_s"]
    assert f"the first {stream.figures['first_sample_s']:.3f} s" in stream.detail
    assert res.seconds >= sum(c.seconds for c in res.checks) > 0
    assert f"checks in {res.seconds:.1f} s" in res.table().splitlines()[0]
    assert float(ET.fromstring(res.junit()).get("time")) == pytest.approx(res.seconds, abs=1e-3)


def test_a_failed_read_is_flagged_not_estimated(model):
    require_tool("gcc")
    faults = [dict(kind="nack", address=0x49, after=60)]  # the second chip falls silent after a few samples
    samples, info = _stream(model, "host", 6, faults)
    rows, counts = _python(model, 6, faults)
    good = [r for r in rows if r is not None]
    assert 0 < len(good) < 6
    for s, row in zip(samples, rows):
        if row is None:
            # READ_FAILED, chip 2 (0x49), ADC_ERR_SILENT; nothing made up
            assert s.status == READ_FAILED | (2 << 8) | 2
            assert not np.any(np.asarray(s.outputs)) and not np.any(np.asarray(s.inputs))
        else:
            np.testing.assert_array_equal(np.asarray(s.outputs), row[1])
    assert info.adc_counts["nack"] >= 5 and info.adc_counts["retries"] >= 4


def test_info_adc_block_round_trip():
    info = P.DeviceInfo(1, "float", 8, 5, 0, 1, 256, "ab" * 32, "paper", "0.1.0",
                        (("ads1115", 0x48, 4, 1, 7, 0), ("ads7828", 0x4B, 8, 0, 0, 0)),
                        {"nack": 3, "timeout": 1, "stuck": 0, "other": 0, "retries": 4, "resets": 0})
    raw = P.pack_info(info)
    assert len(raw) == P.INFO_SIZE + 1 + 12 + 24
    assert P.unpack_info(raw) == info
    with pytest.raises(P.ProtocolError):
        P.unpack_info(raw[:-1])
    old = P.pack_info(P.DeviceInfo(1, "float", 8, 5, 0, 1, 256, "ab" * 32, "paper", "0.1.0"))
    assert len(old) == P.INFO_SIZE and P.unpack_info(old).adc_counts is None


def test_emulate_refuses_a_bad_channel_map(tmp_path, model):
    path = str(model.save(tmp_path / "m.json"))
    assert_one_line_error(run_cli("tactile-hil", "emulate", "--model", path, "--target", "host", "--adc",
                                  "ads1116@0x48:0-3"), 2, "unknown chip")
    assert_one_line_error(run_cli("tactile-hil", "emulate", "--model", path, "--target", "host", "--adc",
                                  "ads1115@0x48:0-3"), 2, "the channel map reads 4 elements; the model takes 8")
    # with a simulated sensor of as few elements, the model's count is still the one named (it named the sensor)
    four = tmp_path / "four.toml"
    paper = (Path(fitgen.physics.__file__).parent / "presets" / "paper.toml").read_text()
    four.write_text(paper.replace('name = "paper"', 'name = "four"').replace("count = 8", "count = 4"))
    assert_one_line_error(run_cli("tactile-hil", "emulate", "--model", path, "--target", "host", "--adc",
                                  "ads1115@0x48:0-3", "--sim-sensor", str(four)), 2,
                          "the channel map reads 4 elements; the model takes 8")
    # ADCs whose full scale the model's readings pass: read and pi-build refused them, emulate built the firmware,
    # whose readings clipped at 2.048 V (estimates off by a millimetre and tens of degrees, status 0)
    assert model.input_units == "V" and model.input_max.max() > 2.048
    chips = "".join(f'[[chip]]\ntype = "ads1115"\naddress = {a}\ninputs = [0, 1, 2, 3]\npga = 2.048\n' for a in (72, 73))
    (tmp_path / "small.toml").write_text(chips)
    for tool, cmd in (("tactile-hil", "emulate"), ("tactile-host", "read")):
        proc = run_cli(tool, cmd, "--model", path, *(("--target", "host") if cmd == "emulate" else ("--count", "1")),
                       "--adc", str(tmp_path / "small.toml"), "--simulate", "0,0,-1,0,0")
        assert_one_line_error(proc, 2, "beyond its ADC's full scale 2.048 V (ads1115@0x48, PGA 2.048 V): its "
                                       "readings would clip")


@pytest.mark.parametrize("target", ["host", "mps2"])
def test_the_firmware_compensates_temperature_as_the_python_readout_does(model, target):
    """A thermistor in the map and a compensation: the firmware reads it after the elements every 0.25 s and
    compensates the volts (tm_tempcomp.h) before its model; STREAM equals tactile-host read --temp-comp's
    engine input and estimates on the Python driver."""
    from host.channelmap import parse_spec
    from host.readout import Corrections
    from host.simsensor import Drift
    from host.temperature import TempComp, Thermometer, parse_temperature_input

    require_tool("gcc")
    if target == "mps2":
        require_tool("qemu-system-arm")
        require_tool("arm-none-eabi-gcc")
    tin = parse_temperature_input("ads1115@0x4a:3")
    cmap = parse_spec(MAP)
    drift = Drift.typical(8, seed=6).steady(18.0)
    tc = TempComp(25.0, drift.offset_tc, drift.gain_tc)

    def bus():
        return drifting_bus(cmap, drift, tin)

    b, clock = bus()
    n = 3 if target == "mps2" else 6
    with start_target(model, target, precision="float", style="unrolled", cmap=cmap, bridge=StandIn(b, clock),
                      tin=tin, tempcomp=tc) as emu:
        with Device.open(emu.url, timeout=5) as dev:
            samples = dev.stream(10, n, timeout=60)
    b, clock = bus()
    arr = AdcArray(b, cmap, clock=clock, policy=RetryPolicy())
    arr.probe()
    arr.setup()
    thermo = Thermometer(arr, tin)
    corr = Corrections(None, tc)
    engine = make_engine("c", model, precision="float", style="unrolled")
    try:
        for s in samples:
            raw = arr.read_volts()
            _, v = corr(raw, thermo.read())
            out, status = engine.estimate(v)
            assert s.status == status
            np.testing.assert_array_equal(np.asarray(s.inputs), v.astype(np.float32).astype(float))
            np.testing.assert_array_equal(np.asarray(s.outputs), out)
            assert np.abs(v - raw).max() > 1e-3  # 7 degC from calibration: the compensation moved the readings
    finally:
        engine.close()


def test_emulate_temperature_options_need_the_thermistor(model, tmp_path):
    path = str(model.save(tmp_path / "m.json"))
    assert_one_line_error(run_cli("tactile-hil", "emulate", "--model", path, "--target", "host", "--temp-comp",
                                  "tc.json"), contains="--temp-comp goes with --adc")
    assert_one_line_error(run_cli("tactile-hil", "emulate", "--model", path, "--target", "host", "--adc", MAP,
                                  "--temp-comp", "tc.json"), contains="temp=CHIP@ADDRESS:INPUT")
    # taken as given: nan failed the stream's reads with no line saying why, -300 degC and 1e308 V ran
    for option, said in ((["--sim-temperature", "nan"], "--sim-temperature: 'nan' is not a finite number"),
                         (["--sim-temperature", "-300"], "--sim-temperature: must be -40..125 degC"),
                         (["--sim-noise", "1e308"], "--sim-noise: must be >= 0 and at most 1000 V")):
        assert_one_line_error(run_cli("tactile-hil", "emulate", "--model", path, "--target", "host", "--adc", MAP,
                                      *option), contains=said)


def test_the_drift_sections_emulate_command_runs_as_written(model, tmp_path):
    """docs/live.md's tactile-hil emulate with a compensation, typed as the doc has it: the firmware comes up."""
    from host.simsensor import Drift
    from host.temperature import TempComp

    require_tool("gcc")
    root = Path(__file__).resolve().parent.parent
    found = re.search(r"^ +(tactile-hil emulate [^\n]*\\\n[^\n]*)$", (root / "docs" / "live.md").read_text(), re.M)
    assert found, "no tactile-hil emulate command block in docs/live.md"
    argv = shlex.split(found.group(1).replace("\\\n", " "))
    model.save(tmp_path / "model.json")
    d = Drift.typical(8)
    TempComp(25.0, d.offset_tc, d.gain_tc).save(tmp_path / "cap.tempcomp.json")
    code = "import sys; from fitgen.app.hil_cli import main; sys.argv[0] = 'tactile-hil'; main()"
    # run in the doc's folder, the fitgen of this checkout (not an installed one)
    proc = subprocess.Popen([sys.executable, "-c", code, *argv[1:]], cwd=tmp_path, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env={**os.environ, "PYTHONPATH": str(root)})
    watchdog = threading.Timer(300, proc.kill)  # a firmware that never comes up fails the test, not hangs it
    watchdog.start()
    try:
        lines = [proc.stdout.readline() for _ in range(3)]
        assert lines[-1].startswith("ready: "), (lines, proc.poll() is not None and proc.stderr.read())
        assert "over the I2C bridge" in lines[1], lines
        proc.terminate()  # the moment it says ready, as a script that waits for the line would
        _, err = proc.communicate(timeout=60)  # a handler that deadlocked hung here (CI, stop 75)
        assert proc.returncode == 0 and err.rstrip().endswith("stopped"), (proc.returncode, err)
    finally:
        watchdog.cancel()
        proc.kill()
        proc.wait()
