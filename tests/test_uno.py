"""The reference firmware on the Arduino Uno's ATmega328P in simavr (tactile-hil emulate --target uno): two
ADS1115s on its TWI bus answered by the Python bus model, the HIL suite, EEPROM calibration, RAM and stack."""

import numpy as np
import pytest

from fitgen.equations.model import load_model
from fitgen.fitting.fit import fit_model
from fitgen.fitting.holdout import box_of, clean_readings, evaluate
from fitgen.physics.sensor import load_sensor
from fitgen.physics.simulate import PAPER_GRIDS, grid_poses, simulate
from hil.bridge import adc_bridge
from hil.emulate import start_target
from hil.suite import run_suite
from host.device import Device

from conftest import assert_one_line_error, require_tool, run_cli

ADC = "ads1115@0x48:0-3,ads1115@0x49:0-3"
UNO_FLASH = 32 * 1024 - 512  # less the bootloader
UNO_RAM = 2048


def _require_avr():
    for tool in ("avr-gcc", "avr-size", "avr-nm", "pkg-config", "gcc"):
        require_tool(tool)


@pytest.fixture(scope="module")
def gmr_model():
    """The library's default fit (FitSettings(): the paper's power kinds, as `fitgen fit --family all`) of the paper
    sensor in volts, with its held-out record."""
    sensor = load_sensor("paper").with_transfer("gmr")
    ds = simulate(sensor, grid_poses(PAPER_GRIDS["paper-sim"]))
    model = fit_model(ds)
    model.fit_info["held_out"] = evaluate(model, sensor, box_of(ds.poses()), n=300, draws=1)
    return model


def test_hil_suite_on_the_emulated_uno(gmr_model):
    """The whole suite through the firmware on the ATmega328P: EVAL, held-out accuracy, a stream of real
    conversions from two ADS1115s on the TWI bus, flashing into the EEPROM (the model's own blob refused
    for its size, a smaller one taken), 2,000 fuzz frames; EVAL equal to Python's float bit for bit; the
    streamed estimate of the simulated pose within 0.15 mm of it; flash, RAM and the stack's peak within
    the Uno's."""
    _require_avr()
    cmap, bridge, _, _ = adc_bridge(ADC, "dx=1,dz=-1")
    emu = start_target(gmr_model, "uno", precision="float", style="table", cmap=cmap, bridge=bridge)
    with emu:
        with Device.open(emu.url, timeout=10) as dev:
            res = run_suite(dev, gmr_model, url=emu.url, n_vectors=500, n_fuzz=2000, verbose=False,
                            held_out=clean_readings(gmr_model))
            rng = np.random.default_rng(3)
            x = gmr_model.input_min + (gmr_model.input_max - gmr_model.input_min) * rng.uniform(-0.1, 1.1, (300, 8))
            x = x.astype(np.float32).astype(float)
            status, out = dev.eval(x)
            samples = dev.stream(10, 5, timeout=30)
    assert res.ok, res.table()
    by_name = {c.name: c for c in res.checks}
    assert {"held-out accuracy", "stream", "flash too big", "flash", "corrupt flash", "fuzz"} <= set(by_name)
    assert by_name["fuzz"].figures["frames"] == 2000
    assert by_name["flash too big"].figures["store_bytes"] == 508 < by_name["flash too big"].figures["blob_bytes"]
    assert by_name["flash"].figures["blob_bytes"] <= 508
    want, want_status = gmr_model.predict(x, with_status=True, precision="float")
    np.testing.assert_array_equal(np.asarray(out), want)
    np.testing.assert_array_equal(np.asarray(status), want_status)
    assert np.any(want_status != 0)  # clamped inputs among them
    est = np.array([s.outputs for s in samples])
    assert all(s.status == 0 for s in samples)
    assert np.all(np.abs(est[:, :3] - [1.0, 0.0, -1.0]) <= 0.15), est
    assert emu.size["flash"] <= UNO_FLASH
    assert emu.stack_peak is not None and 100 < emu.stack_peak
    assert emu.size["ram"] + emu.stack_peak <= UNO_RAM


def test_simulated_inputs_on_the_uno_sweep_the_models_domain(gmr_model):
    """Without ADCs the firmware streams inputs swept across the model's domain, and BENCH times vectors inside it:
    on the Uno both read the domain's bounds from RAM at the flash tables' addresses, so every streamed input was
    the stack paint's 0xA5A5A5A5 (status 254) and BENCH's cycles were those of clamped inputs."""
    from hil.suite import check_stream

    _require_avr()
    with start_target(gmr_model, "uno", precision="float", style="table") as emu:
        with Device.open(emu.url, timeout=10) as dev:
            samples = dev.stream(10, 5, timeout=30)
            check = check_stream(dev)
    inputs = np.array([s.inputs for s in samples])
    assert all(s.status == 0 for s in samples), [hex(s.status) for s in samples]
    assert np.all((inputs >= gmr_model.input_min.astype(np.float32) - 1e-6)
                  & (inputs <= gmr_model.input_max.astype(np.float32) + 1e-6)), inputs
    assert check.ok, check.detail


def test_calibration_survives_a_reset_in_eeprom(gmr_model, tmp_path, capsys):
    """A blob flashed into the EEPROM is the active calibration after the firmware starts again (the
    EEPROM image carried over by the board), and CAL_RESET makes the compiled-in model answer again."""
    _require_avr()
    from fitgen.app.hil_cli import _describe
    from hil.suite import fit_store, flash_variant
    from host.device import flash_model

    new = fit_store(flash_variant(gmr_model), 508, "float", "paper")
    with start_target(gmr_model, "uno", precision="float", workdir=tmp_path / "fw") as emu:
        with Device.open(emu.url, timeout=10) as dev:
            flash_model(dev, new, "variant")
            assert dev.info(refresh=True).model_hash == new.sha256
    # the same image again, in a board that keeps the EEPROM of the last run
    assert (tmp_path / "fw" / "eeprom.bin").is_file()
    with start_target(gmr_model, "uno", precision="float", workdir=tmp_path / "fw") as emu:
        with Device.open(emu.url, timeout=10) as dev:
            info = dev.info(refresh=True)
            assert info.model_hash == new.sha256 and info.cal_source == 1
            # what emulate prints: the flashed model is the one measured, and it is said to be a calibration
            _describe(emu, dev, "uno", gmr_model.sha256)
            said = capsys.readouterr().out
            assert f"model {new.sha256[:12]}; " in said and "cycles per estimate" in said
            assert f"(model {new.sha256[:12]} is a calibration flashed earlier, kept in {tmp_path / 'fw'}" in said
            assert f"remove it to run the compiled-in model {gmr_model.sha256[:12]})" in said
            dev.reset_calibration()
            assert dev.info(refresh=True).model_hash == gmr_model.sha256
            flash_model(dev, new, "variant")
    # a build of another model in the same folder runs that model, not the calibration the last build kept
    other = flash_variant(new)
    with start_target(other, "uno", precision="float", workdir=tmp_path / "fw") as emu:
        with Device.open(emu.url, timeout=10) as dev:
            info = dev.info(refresh=True)
            assert info.model_hash == other.sha256 and info.cal_source == 0
            assert info.firmware_version.endswith("+uno")


def test_uno_refuses_double_and_bad_options(gmr_model, tmp_path):
    model_file = gmr_model.save(tmp_path / "m.json")
    proc = run_cli("tactile-hil", "emulate", "--target", "uno", "--precision", "double", "--model", str(model_file))
    assert_one_line_error(proc, 2, "target uno")


def test_uno_refuses_a_thermistor_before_building(gmr_model, tmp_path):
    """A thermistor on the Uno took its reads' second ADC array into RAM, and a float build's stack then ran into
    it mid-suite ('connection closed by the device'); it is refused as arduino-build refuses it."""
    model_file = gmr_model.save(tmp_path / "m.json")
    proc = run_cli("tactile-hil", "emulate", "--target", "uno", "--style", "unrolled", "--model", str(model_file),
                   "--adc", ADC + ",temp=ads1115@0x4a:0", "--simulate", "dx=1", "--suite")
    assert_one_line_error(proc, 2, "--target uno reads no thermistor")
    assert "building" not in proc.stderr and "ready" not in proc.stdout


def test_a_board_that_ended_is_said_by_its_reason_not_its_counts():
    """simavr's board prints its STACK and CYCLES counts after the reason it stopped: the reason is said."""
    import io
    from types import SimpleNamespace

    from fitgen.app.hil_cli import _ending

    err = b"the stack ran into static RAM (SP 0x071b, .bss ends at 0x07aa) at cycle 183709630\nSTACK 484\nCYCLES 1\n"
    runner = SimpleNamespace(proc=SimpleNamespace(returncode=6, stderr=io.BytesIO(err)))
    assert _ending(runner) == ("exit status 6 (the stack ran into static RAM (SP 0x071b, .bss ends at 0x07aa) at "
                               "cycle 183709630)")
    runner = SimpleNamespace(proc=SimpleNamespace(returncode=-9, stderr=io.BytesIO(b"")))
    assert _ending(runner) == "killed by signal 9 from outside"


def test_cli_emulate_uno_suite(gmr_model, tmp_path):
    """`tactile-hil emulate --target uno --adc ... --suite`: the command a user runs, to its JUnit file."""
    _require_avr()
    import xml.etree.ElementTree as ET

    model_file = gmr_model.save(tmp_path / "m.json")
    junit = tmp_path / "hil.xml"
    proc = run_cli("tactile-hil", "emulate", "--target", "uno", "--model", str(model_file), "--adc", ADC,
                   "--simulate", "dx=1,dz=-1", "--suite", "--vectors", "200", "--fuzz", "2000", "--junit", str(junit),
                   "--timeout", "10")  # simavr on a loaded machine is slower than the board
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "cycles per estimate (simavr)" in proc.stdout and "on the TWI bus" in proc.stdout
    cases = {c.get("name"): c for c in ET.parse(junit).getroot()}
    assert {"eval", "held-out accuracy", "stream", "flash too big", "flash", "fuzz"} <= set(cases)
    assert all(c.find("failure") is None for c in cases.values())


def test_fixed_point_firmware_reads_the_ads1115s_on_the_uno(tmp_path):
    """A fixed-point build (ADC codes straight into integer arithmetic) with the ADS1115s on the TWI bus: the
    suite through the CLI, EVAL equal to the numpy integer model at the channel map's code scale."""
    _require_avr()
    from fitgen.fitting.fit import FitSettings
    from fitgen.equations.terms import FAMILIES

    ds = simulate(load_sensor("paper").with_transfer("gmr"), grid_poses(PAPER_GRIDS["paper-sim"]))
    model_file = fit_model(ds, settings=FitSettings.exact(exponents=FAMILIES["no-roots"])).save(tmp_path / "m.json")
    proc = run_cli("tactile-hil", "emulate", "--target", "uno", "--precision", "fixed", "--model", str(model_file),
                   "--adc", ADC, "--simulate", "dx=1,dz=-1", "--suite", "--vectors", "300", "--fuzz", "2000",
                   "--timeout", "10")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "largest difference from the numpy integer model 0 LSB" in proc.stdout
    assert "| stream | pass |" in proc.stdout and "| flash (fixed point) | pass |" in proc.stdout
    # the suite run against the board as `tactile-hil run` runs it, told neither the plan nor the code scale:
    # the firmware's version names the Uno's plan, its INFO the ADS1115s' PGA
    model = load_model(model_file)
    cmap, bridge, _, _ = adc_bridge(ADC, "dx=1,dz=-1")
    with start_target(model, "uno", precision="fixed", cmap=cmap, bridge=bridge) as emu:
        with Device.open(emu.url, timeout=10) as dev:
            res = run_suite(dev, model, url=emu.url, n_vectors=300, n_fuzz=0, flash=False, verbose=False)
    evals = [c for c in res.checks if c.name == "eval"]
    assert evals and evals[0].ok and evals[0].figures["max_lsb_diff"] == 0, res.table()


def test_a_board_that_stops_before_answering_is_said_in_its_own_words():
    """`tactile-hil emulate` on a firmware that crashes at boot (a table-style stack past the Uno's RAM) says the
    board's line and what to try, not that the port would not open."""
    from types import SimpleNamespace

    from fitgen.app.hil_cli import _stopped
    from fitgen.base.errors import InputError

    class Exited:
        returncode = 1

        def poll(self):
            return 1

    runner = SimpleNamespace(proc=Exited(), messages=["the AVR program crashed at cycle 12664"], stop=lambda: None)
    with pytest.raises(InputError, match="stopped before answering: the AVR program crashed at cycle 12664; a "
                                         "table-style build's stack can overrun"):
        _stopped(runner, SimpleNamespace(target="uno"), lambda: "; a table-style build's stack can overrun it")
    runner.proc = SimpleNamespace(poll=lambda: None)  # still running: the port's own error stands
    _stopped(runner, SimpleNamespace(target="uno"), lambda: "")


def test_the_advice_after_a_crash_is_checked_by_building_it(gmr_model, tmp_path):
    """A table build that crashed: --style unrolled is advised only when it builds; a 382-term model's unrolled
    code overflows the flash, and the line says so and advises fewer terms (it used to advise unrolled). (That
    model's table build crashed the Uno at boot while the firmware read its domain from RAM, a3d789f; it runs
    now, so the advice is asked of it directly.)"""
    _require_avr()
    from fitgen.fitting.fit import FitSettings
    from hil.emulate import uno_crash_advice

    assert "try --style unrolled (it builds: flash" in uno_crash_advice(gmr_model, "float", "table")
    assert uno_crash_advice(gmr_model, "float", "unrolled") == ""
    ds = simulate(load_sensor("paper").with_transfer("gmr"), grid_poses(PAPER_GRIDS["paper-sim"]))
    huge = fit_model(ds, settings=FitSettings.family("all", k=0.001))
    said = uno_crash_advice(huge, "float", "table")
    assert "--style unrolled does not build either (it does not fit, " in said and "fit fewer terms" in said, said


def test_a_stack_that_overruns_ram_after_boot_is_caught_when_it_happens(tmp_path):
    """The harmonics model read from the ADCs boots and answers INFO, then its first estimate takes the stack
    into .bss: the board watches the stack pointer and stops there, and emulate says so with the advice (it
    printed a negative cycle count and 'ready', and the suite then blamed the port)."""
    _require_avr()
    from fitgen.fitting.fit import FitSettings

    ds = simulate(load_sensor("paper").with_transfer("gmr"), grid_poses(PAPER_GRIDS["paper-sim"]))
    model = fit_model(ds, settings=FitSettings.family("harmonics")).save(tmp_path / "harmonics.json")
    proc = run_cli("tactile-hil", "emulate", "--target", "uno", "--model", str(model), "--adc",
                   "ads1115@0x48:0-3,ads1115@0x49:0-3", "--simulate", "dx=1,dz=-1")
    assert_one_line_error(proc, 2, "the uno firmware stopped: the stack ran into static RAM (SP 0x")
    assert "cycles per estimate" not in proc.stdout and "ready" not in proc.stdout
    assert "--style unrolled does not build either (it does not fit, " in proc.stderr
    assert "bytes over the flash): fit fewer terms" in proc.stderr


def test_pkg_config_without_simavr_is_said_with_the_packages(gmr_model, tmp_path):
    """pkg-config not knowing simavr (libsimavr-dev or libelf-dev missing): one line naming the packages, before
    the firmware is built."""
    _require_avr()
    import os

    model_file = gmr_model.save(tmp_path / "m.json")
    env = dict(os.environ, PKG_CONFIG_LIBDIR=str(tmp_path / "none"), PKG_CONFIG_PATH="")
    import subprocess
    import sys

    proc = subprocess.run([sys.executable, "-c", "from fitgen.app.hil_cli import main; main()", "emulate", "--target",
                           "uno", "--model", str(model_file), "--build-dir", str(tmp_path / "fw")],
                          capture_output=True, text=True, env=env, timeout=120)
    assert_one_line_error(proc, 2, "pkg-config simavr failed")
    assert "apt-get install gcc-avr binutils-avr avr-libc simavr libsimavr-dev libelf-dev" in proc.stderr
    assert not (tmp_path / "fw").exists()  # refused before the firmware was rendered


LATE_ECHO = r"""
#include <avr/io.h>
int main(void)
{
    volatile unsigned long n;
    for (n = 0; n < 100000UL; ++n) {
    }
    UCSR0A = (unsigned char)_BV(U2X0);
    UBRR0L = 1u;
    UCSR0C = (unsigned char)(_BV(UCSZ01) | _BV(UCSZ00));
    UCSR0B = (unsigned char)(_BV(RXEN0) | _BV(TXEN0));
    for (;;) {
        unsigned char b;
        loop_until_bit_is_set(UCSR0A, RXC0);
        b = UDR0;
        loop_until_bit_is_set(UCSR0A, UDRE0);
        UDR0 = b;
    }
}
"""


def test_bytes_sent_before_the_program_turns_its_receiver_on_wait_for_it(tmp_path):
    """A client that writes the moment it connects, to a program that turns its UART's receiver on only after a
    start-up of a million cycles, gets every byte to the program (simavr drops a byte that arrives with the
    receiver off; the board holds the client's bytes until it is on): the echo comes back whole. The reference
    firmware's first request was lost that way when the client was quicker than its start-up."""
    _require_avr()
    import socket
    import subprocess

    from hil.emulate import UnoEmulator, build_uno_board

    src, elf = tmp_path / "late_echo.c", tmp_path / "late_echo.elf"
    src.write_text(LATE_ECHO)
    subprocess.run(["avr-gcc", "-mmcu=atmega328p", "-Os", "-Wall", "-Werror", str(src), "-o", str(elf)], check=True)
    # held: the core starts when the client connects, so the client's bytes surely precede the receiver
    with UnoEmulator(build_uno_board(tmp_path), elf, hold=True) as emu:
        with socket.create_connection(("127.0.0.1", emu.port), timeout=10) as sock:
            sock.sendall(b"ping!")
            got = b""
            while len(got) < 5:
                chunk = sock.recv(16)
                assert chunk, f"the board closed the connection after {got!r}"
                got += chunk
    assert got == b"ping!"
