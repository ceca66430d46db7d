"""The HIL suite against the real firmware: the emulated Cortex-M4 (QEMU mps2-an386) and the host build on a pty."""

import dataclasses
import json
import re
import socket
import threading
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from fitgen.fitting.fit import fit_model
from fitgen.physics.sensor import load_sensor
from fitgen.physics.simulate import PAPER_GRIDS, grid_poses, simulate
from hil.emulate import bench_instructions, start_target
from hil.suite import flash_variant, run_suite
from host.device import Device

from conftest import Terminal, assert_one_line_error, model_for_sensor, require_tool, run_cli


@pytest.fixture(scope="module")
def paper_model():
    return fit_model(simulate(load_sensor("paper"), grid_poses(PAPER_GRIDS["paper-sim"])))


@pytest.fixture(scope="module")
def model_file(paper_model, tmp_path_factory):
    return paper_model.save(tmp_path_factory.mktemp("hil") / "paper.json")


def _assert_suite(res, n_vectors, n_fuzz):
    assert res.ok, res.table()
    by_name = {c.name: c for c in res.checks}
    assert {"info", "eval", "timing", "flash", "corrupt flash", "fuzz", "eval after fuzz"} <= set(by_name)
    assert int(by_name["eval"].detail.split()[0]) >= n_vectors
    assert by_name["fuzz"].figures["frames"] == n_fuzz


def test_full_suite_on_emulated_cortex_m4(paper_model):
    require_tool("qemu-system-arm")
    require_tool("arm-none-eabi-gcc")
    with start_target(paper_model, "mps2", precision="float", style="table") as emu:
        with Device.open(emu.url, timeout=5) as dev:
            res = run_suite(dev, paper_model, url=emu.url, n_vectors=1000, n_fuzz=10_000, verbose=False)
    _assert_suite(res, 1000, 10_000)


def test_a_port_taken_before_qemu_binds_it_is_picked_again(paper_model, monkeypatch):
    """free_port() chooses a port and lets it go; another process may take it before QEMU binds it. QEMU then
    fails to bind, and the emulator picks another port instead of failing (a port the user named is not
    changed: that one fails in one line)."""
    require_tool("qemu-system-arm")
    require_tool("arm-none-eabi-gcc")
    import hil.emulate as E

    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen(1)
        busy = taken.getsockname()[1]
        picks = iter([busy])
        real = E.free_port
        monkeypatch.setattr(E, "free_port", lambda: next(picks, None) or real())
        with start_target(paper_model, "mps2") as emu:
            assert emu.port != busy
            with Device.open(emu.url, timeout=5) as dev:
                assert dev.ping(b"moved") == b"moved"
        from fitgen.base.errors import InputError
        with pytest.raises(InputError, match=f"could not listen on 127.0.0.1:{busy}: another program uses it"):
            with start_target(paper_model, "mps2", port=busy):
                pass


def test_emulated_uart_passes_every_byte_and_answers_at_once(paper_model):
    """The mps2 UARTs go through a QEMU mux (a 32-byte buffer, hil/emulate.py) whose escape character is
    put out of reach: every byte value, C-a x (which stops QEMU at the default escape) among them, reaches
    the firmware and comes back; and a request sent the moment start() returns is answered (bytes that
    reach the mux before the firmware enables its UART are pushed on by start()'s handshake)."""
    require_tool("qemu-system-arm")
    require_tool("arm-none-eabi-gcc")
    with start_target(paper_model, "mps2") as emu:
        assert emu.buffered and "mux=on" in " ".join(emu.command())
        with Device.open(emu.url, timeout=5) as dev:
            assert dev.ping(b"first") == b"first"
            every = b"\x01x\x01c\x01s\x01b\x01h\x01t\x01\x01" + bytes(range(1, 256))
            for i in range(0, len(every), 128):
                assert dev.ping(every[i:i + 128]) == every[i:i + 128]
        assert emu.proc.poll() is None


@pytest.mark.parametrize("precision, style", [("double", "unrolled"), ("float", "table")])
def test_full_suite_on_host_build_over_a_pty(paper_model, precision, style):
    require_tool("gcc")
    with start_target(paper_model, "host", precision=precision, style=style) as fw:
        assert fw.url.startswith("/dev/pts/")
        with Device.open(fw.url, timeout=5) as dev:
            res = run_suite(dev, paper_model, url=fw.url, n_vectors=1000, n_fuzz=10_000, verbose=False)
    _assert_suite(res, 1000, 10_000)
    if precision == "double":
        # same header, same compiler, same order of operations: the device's answers are Python's exactly
        assert max(res.checks[1].figures["max_error"]) == 0.0


def test_a_build_folder_in_use_is_refused_not_shared(paper_model, model_file, tmp_path):
    """Two emulators given one --build-dir interleaved their sources: one answered INFO with its model's hash and
    EVAL with the other's. A folder another build or firmware holds is refused in one line, before any file of it
    is written; once that firmware stops the folder serves again."""
    from fitgen.base.errors import InputError

    require_tool("gcc")
    folder = tmp_path / "fw"
    other = dataclasses.replace(paper_model, fit_info={**paper_model.fit_info, "note": "another"})
    with start_target(paper_model, "host", workdir=folder) as fw:
        main_c = (folder / "main.c").read_text()
        with pytest.raises(InputError, match=f"--build-dir {folder} is in use by another tactile-hil"):
            start_target(other, "host", workdir=folder)
        proc = run_cli("tactile-hil", "emulate", "--target", "host", "--model", str(model_file), "--build-dir",
                       str(folder))
        assert_one_line_error(proc, 2, f"--build-dir {folder} is in use by another tactile-hil")
        assert (folder / "main.c").read_text() == main_c
        assert not list(folder.glob("*lock*"))  # the folder itself is locked: no lock file is left in it
        with Device.open(fw.url, timeout=5) as dev:
            assert dev.info(refresh=True).model_hash == paper_model.sha256
    with start_target(other, "host", workdir=folder) as fw:
        with Device.open(fw.url, timeout=5) as dev:
            assert dev.info(refresh=True).model_hash == other.sha256


def test_a_build_folder_holding_files_no_build_wrote_is_refused_before_any_is_written(model_file, tmp_path):
    """--build-dir took any folder and wrote main.c, device.c and a dozen more over the user's files of those
    names. A folder an earlier build wrote serves again."""
    require_tool("gcc")
    folder = tmp_path / "project"
    folder.mkdir()
    (folder / "main.c").write_text("int main(void) { return 42; } /* my own work */\n")
    argv = ("tactile-hil", "emulate", "--target", "host", "--model", str(model_file), "--suite", "--vectors", "20",
            "--fuzz", "10", "--no-flash", "--build-dir")
    assert_one_line_error(run_cli(*argv, str(folder)), 2,
                          f"--build-dir {folder} holds files no firmware build wrote (main.c)")
    assert [p.name for p in folder.iterdir()] == ["main.c"] and "my own work" in (folder / "main.c").read_text()
    (folder / "main.c").unlink()
    (folder / "notes.txt").write_text("mine\n")
    assert_one_line_error(run_cli(*argv, str(folder)), 2, "holds files no firmware build wrote (notes.txt)")
    # a file given as the folder, or on the way to it: what is in the way, where it said the errno's words alone
    for given, said in ((folder / "notes.txt", "it is a file"), (folder / "notes.txt" / "fw", f"{folder / 'notes.txt'} "
                                                                  "is a file")):
        assert_one_line_error(run_cli(*argv, str(given)), 2, f"--build-dir {given}: {said}; give a folder")
    assert (folder / "notes.txt").read_text() == "mine\n"
    build = tmp_path / "fw"
    for _ in range(2):  # new, then an earlier build's
        proc = run_cli(*argv, str(build))
        assert proc.returncode == 0 and proc.stdout.rstrip().endswith("PASS"), proc.stdout + proc.stderr


def test_a_build_folder_named_relative_to_where_it_runs_serves_and_an_empty_one_is_refused(model_file, tmp_path):
    """--build-dir . ran its image as 'firmware', which the system looked up on PATH (a traceback); --build-dir ''
    did the same after writing the sources into the current folder."""
    require_tool("gcc")
    proc = run_cli("tactile-hil", "emulate", "--target", "host", "--model", str(model_file), "--suite", "--vectors",
                   "20", "--fuzz", "10", "--no-flash", "--build-dir", ".", cwd=tmp_path)
    assert proc.returncode == 0 and proc.stdout.rstrip().endswith("PASS"), proc.stdout + proc.stderr
    assert (tmp_path / "firmware").is_file()
    (tmp_path / "empty").mkdir()
    proc = run_cli("tactile-hil", "emulate", "--target", "host", "--model", str(model_file), "--build-dir", "",
                   cwd=tmp_path / "empty")
    assert_one_line_error(proc, 2, "--build-dir is empty")
    assert not list((tmp_path / "empty").iterdir())
    assert_one_line_error(run_cli("tactile-hil", "run", "--port", "socket://127.0.0.1:1", "--model", ""), 2,
                          "--model is empty")


def test_a_device_that_stops_mid_suite_leaves_the_table_so_far(paper_model, monkeypatch):
    """A device that stopped answering mid-suite ended `tactile-hil run` with one line, and the checks already done
    were lost: now the check it stopped in fails, the table holds those before it, and the rest are said not run."""
    import os
    import signal

    import hil.suite

    require_tool("gcc")
    real = hil.suite.check_stream
    with start_target(paper_model, "host") as fw:

        def check_stream(dev, *a, **kw):
            os.kill(fw.proc.pid, signal.SIGSTOP)  # hung: the pty stays open, nothing answers
            dev.timeout = 1.0  # the checks before ran at the default, as a loaded machine needs
            return real(dev, *a, **kw)

        monkeypatch.setattr(hil.suite, "check_stream", check_stream)
        try:
            with Device.open(fw.url, timeout=5) as dev:
                res = run_suite(dev, paper_model, url=fw.url, n_vectors=50, n_fuzz=100, verbose=False)
        finally:
            os.kill(fw.proc.pid, signal.SIGCONT)
    assert not res.ok
    names = [c.name for c in res.checks]
    assert names[:3] == ["info", "eval", "stream"] and "timing" not in names and "fuzz" not in names, names
    assert res.checks[0].ok and res.checks[1].ok
    assert "no answer" in res.checks[2].detail and res.checks[2].detail.endswith("the checks after it were not run")


def test_fixed_point_suite_on_emulated_cortex_m4():
    """A fixed-point build (integer powers only, ADC codes in) through the same suite on the emulated core."""
    require_tool("qemu-system-arm")
    require_tool("arm-none-eabi-gcc")
    from fitgen.fitting.fit import FitSettings
    from fitgen.equations.terms import FAMILIES

    ds = simulate(load_sensor("paper").with_transfer("gmr"), grid_poses(PAPER_GRIDS["paper-sim"]))
    model = fit_model(ds, settings=FitSettings(exponents=FAMILIES["no-roots"]))
    with start_target(model, "mps2", precision="fixed") as emu:
        with Device.open(emu.url, timeout=5) as dev:
            assert dev.info().precision == "fixed"
            res = run_suite(dev, model, url=emu.url, n_vectors=1000, n_fuzz=2000, verbose=False)
    assert res.ok, res.table()
    by_name = {c.name: c for c in res.checks}
    assert by_name["eval"].figures["max_lsb_diff"] <= 1
    assert "flash (fixed point)" in by_name and int(by_name["eval"].detail.split()[0]) >= 1000


def test_full_suite_on_emulated_cortex_m0(tmp_path):
    """The fixed-point firmware on QEMU's microbit (nRF51822: Cortex-M0, ARMv6-M, no FPU), the whole suite:
    10,000 fuzz frames, the held-out check from the model file's record, and its instruction count."""
    require_tool("qemu-system-arm")
    require_tool("arm-none-eabi-gcc")
    from fitgen.fitting.fit import FitSettings
    from fitgen.fitting.holdout import box_of, clean_readings, evaluate
    from fitgen.equations.terms import FAMILIES

    sensor = load_sensor("paper").with_transfer("gmr")
    ds = simulate(sensor, grid_poses(PAPER_GRIDS["paper-sim"]))
    model = fit_model(ds, settings=FitSettings(precision="fixed", exponents=FAMILIES["no-roots"]))
    model.fit_info["held_out"] = evaluate(model, sensor, box_of(ds.poses()), n=500, draws=1)
    with start_target(model, "microbit", precision="fixed") as emu:
        assert emu.machine == "microbit" and emu.size["ram"] < 16 * 1024
        with Device.open(emu.url, timeout=5) as dev:
            assert dev.info().precision == "fixed"
            cost = bench_instructions(dev)
            res = run_suite(dev, model, url=emu.url, n_vectors=1000, n_fuzz=10_000, verbose=False,
                            held_out=clean_readings(model))
    assert res.ok, res.table()
    by_name = {c.name: c for c in res.checks}
    assert {"held-out accuracy", "stream", "flash (fixed point)", "fuzz"} <= set(by_name)
    assert by_name["eval"].figures["max_lsb_diff"] <= 1
    assert by_name["fuzz"].figures["frames"] == 10_000
    # no FPU, no 32x32->64 multiply: many more instructions than the M4F's few thousand, but bounded
    assert 5_000 < cost["instructions"] < 100_000


def test_fixed_only_on_the_m0_and_no_bridge(paper_model, tmp_path):
    from fitgen.base.errors import InputError
    from hil.firmware import render_firmware
    from host.channelmap import parse_spec

    with pytest.raises(InputError, match="takes --precision fixed"):
        render_firmware(paper_model, tmp_path / "a", precision="float", port="microbit")
    with pytest.raises(InputError, match="one UART"):
        render_firmware(paper_model, tmp_path / "b", precision="fixed", port="microbit",
                        cmap=parse_spec("ads1115@0x48:0-3,ads1115@0x49:0-3"))


def test_suite_fails_when_the_device_runs_another_model(paper_model):
    require_tool("gcc")
    other = flash_variant(paper_model)
    with start_target(other, "host", precision="double", style="table") as fw:
        with Device.open(fw.url, timeout=5) as dev:
            res = run_suite(dev, paper_model, url=fw.url, n_vectors=100, n_fuzz=0, flash=False, verbose=False)
    assert not res.ok
    failed = {c.name for c in res.checks if not c.ok}
    assert failed == {"info", "eval"}


def test_suite_checks_the_compiled_in_model_when_a_calibration_was_flashed(paper_model):
    """A device left with a loaded calibration (tactile-host flash; the Uno keeps it in EEPROM) passes info: the
    suite resets it before it asks the model hash, and says so."""
    require_tool("gcc")
    from host.device import flash_model

    with start_target(paper_model, "host", precision="double", style="table") as fw:
        with Device.open(fw.url, timeout=5) as dev:
            flash_model(dev, flash_variant(paper_model), "the variant")
            assert dev.info(refresh=True).cal_source == 1
            res = run_suite(dev, paper_model, url=fw.url, n_vectors=50, n_fuzz=0, flash=False, verbose=False)
    assert res.ok, res.table()
    assert "was active: reset to the compiled-in model" in res.checks[0].detail


def test_a_suite_stopped_while_it_flashes_leaves_the_compiled_in_model(paper_model, monkeypatch):
    """Ctrl-C during the flash checks left the suite's variant loaded (on the Uno, in EEPROM: the next boot ran it)."""
    require_tool("gcc")
    import hil.suite as S

    def stopped(dev, *args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(S, "check_corrupt_flash", stopped)
    with start_target(paper_model, "host", precision="double", style="table") as fw:
        with Device.open(fw.url, timeout=5) as dev:
            with pytest.raises(KeyboardInterrupt):
                run_suite(dev, paper_model, url=fw.url, n_vectors=50, n_fuzz=0, verbose=False)
            info = dev.info(refresh=True)
    assert info.cal_source == 0 and info.model_hash == paper_model.sha256


def test_suite_fails_not_crashes_when_the_device_runs_fewer_outputs(paper_model):
    """The device refuses a calibration for five outputs: the flash checks fail, the suite finishes."""
    require_tool("gcc")
    dz_only = dataclasses.replace(paper_model, equations=(paper_model.equation("dz"),))
    with start_target(dz_only, "host", precision="float", style="table") as fw:
        with Device.open(fw.url, timeout=5) as dev:
            res = run_suite(dev, paper_model, url=fw.url, n_vectors=50, n_fuzz=0, verbose=False)
    by_name = {c.name: c for c in res.checks}
    assert not res.ok and not by_name["flash"].ok
    assert "ERROR" in by_name["flash"].detail and "corrupt flash" in by_name


def test_emulated_instruction_counts(paper_model):
    """icount makes the emulated core's counts repeatable; the unrolled style needs fewer instructions."""
    require_tool("qemu-system-arm")
    require_tool("arm-none-eabi-gcc")
    counts = {}
    for style in ("table", "unrolled"):
        with start_target(paper_model, "mps2", precision="float", style=style) as emu:
            with Device.open(emu.url, timeout=5) as dev:
                a, b = bench_instructions(dev), bench_instructions(dev)
                counts[style] = a["instructions"]
                assert abs(a["instructions"] - b["instructions"]) <= 0.01 * a["instructions"]
            assert 0 < emu.size["flash"] < 256 * 1024
    n_terms = sum(len(e.terms) for e in paper_model.equations)
    # at least a multiply-add's worth per term, and not absurdly more
    assert 2 * n_terms < counts["unrolled"] < counts["table"] < 40 * n_terms


def test_cli_emulate_suite_writes_junit(model_file, tmp_path):
    require_tool("gcc")
    junit = tmp_path / "hil.xml"
    proc = run_cli("tactile-hil", "emulate", "--target", "host", "--model", str(model_file), "--suite",
                   "--vectors", "100", "--fuzz", "200", "--junit", str(junit))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "PASS" in proc.stdout and "ns per estimate" in proc.stdout
    root = ET.parse(junit).getroot()
    assert root.get("failures") == "0" and int(root.get("tests")) >= 6


def test_emulate_compiles_in_the_name_of_the_unit_the_model_is_for(model, tmp_path):
    """Without --sensor-id the firmware says which sensor's calibration it holds: the name the model's held-out
    figures are for (a unit file's), as tactile-host flash writes it; before, every build said 'paper'."""
    require_tool("gcc")
    path = model_for_sensor(model, "unit-042", tmp_path / "u.json")
    proc = run_cli("tactile-hil", "emulate", "--target", "host", "--model", path, "--suite", "--vectors", "50",
                   "--fuzz", "0", "--no-held-out")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert re.search(r"\| info \| pass \|.*, sensor unit-042 \|", proc.stdout), proc.stdout


def _emulate_mps2(model_file, stderr):
    """`tactile-hil emulate --target mps2 --model MODEL_FILE` as a process of its own (a test signals it, or the
    QEMU it starts), its stdout a pipe."""
    import subprocess
    import sys

    require_tool("qemu-system-arm")
    require_tool("arm-none-eabi-gcc")
    code = "import sys; from fitgen.app.hil_cli import main; sys.argv[0] = 'tactile-hil'; main()"
    return subprocess.Popen([sys.executable, "-c", code, "emulate", "--target", "mps2", "--model", str(model_file)],
                            stdout=subprocess.PIPE, stderr=stderr, text=True)


def _ready_port(proc) -> int:
    """The TCP port an emulate process says it is ready on."""
    lines = []
    while not (lines and lines[-1].startswith("ready: ")):
        line = proc.stdout.readline()
        assert line, "".join(lines) + (proc.stderr.read() if proc.stderr else "")
        lines.append(line)
    return int(re.search(r"socket://127\.0\.0\.1:(\d+)", lines[-1]).group(1))


def test_the_emulator_ends_with_emulate_even_when_it_is_killed(model_file):
    """kill -9 leaves emulate no chance to stop QEMU: the kernel sends it SIGTERM (PR_SET_PDEATHSIG), so its port
    is free again and no QEMU is left running."""
    import signal
    import subprocess
    import time

    proc = _emulate_mps2(model_file, subprocess.DEVNULL)
    try:
        port = _ready_port(proc)
        socket.create_connection(("127.0.0.1", port), timeout=5).close()  # QEMU serves it
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait(10)
    deadline = time.monotonic() + 20
    while True:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=1).close()
        except OSError:
            break  # refused: QEMU is gone
        assert time.monotonic() < deadline, f"QEMU still serves port {port} after emulate was killed"
        time.sleep(0.1)


@pytest.mark.parametrize("sig, said", [("TERM", "stopped from outside (qemu-system-arm: terminating on signal 15"),
                                        ("KILL", "killed by signal 9 from outside")])
def test_an_emulator_stopped_from_outside_is_said_so(model_file, sig, said):
    """QEMU killed under emulate was reported as 'the mps2 firmware exited on its own (status 0)'."""
    import subprocess

    proc = _emulate_mps2(model_file, subprocess.PIPE)
    try:
        port = _ready_port(proc)
        subprocess.run(["pkill", f"-{sig}", "-f", f"qemu-system-arm.*port={port},"], check=True)
        _, err = proc.communicate(timeout=20)
    finally:
        proc.kill()
    assert proc.returncode == 2
    assert err.strip().splitlines()[-1].startswith(f"tactile-hil emulate: error: the mps2 firmware ended: {said}"), err


def test_cli_emulate_refuses_the_suites_options_without_suite(model_file, tmp_path):
    """Without --suite the suite never runs: each of its options, even typed as its default (--vectors 0 too), is
    one line before the model is read or the firmware built, and --help says they need --suite."""
    from fitgen.app.hil_cli import _check, build_parser
    from fitgen.base.errors import InputError

    for extra in (["--vectors", "0"], ["--vectors", "1000"], ["--data", "d.csv"], ["--fuzz", "5"], ["--no-flash"],
                  ["--junit", str(tmp_path / "j.xml")], ["--max-share", "0.05"], ["--sensor", "paper"],
                  ["--no-held-out"]):
        args = build_parser().parse_args(["emulate", "--model", "m.json", "--target", "host", *extra])
        with pytest.raises(InputError, match=f"^{extra[0]} goes with --suite "):
            _check(args)
    # with --suite, the ones left out take the defaults --help names
    args = build_parser().parse_args(["emulate", "--model", "m.json", "--suite", "--fuzz", "0"])
    _check(args)
    assert (args.vectors, args.fuzz, args.no_flash) == (1000, 0, False)
    from fitgen.c.verify import held_out_from_args
    from fitgen.equations.model import load_model

    held_out_from_args(load_model(model_file), args)  # --max-share's default is filled with the held-out check's
    assert args.max_share == 0.05
    proc = run_cli("tactile-hil", "emulate", "--target", "host", "--model", str(tmp_path / "none.json"),
                   "--junit", str(tmp_path / "j.xml"), "--fuzz", "5", "--no-flash", "--vectors", "0")
    assert_one_line_error(proc, 2, "--vectors goes with --suite (without it, it would be ignored)")
    assert not (tmp_path / "j.xml").exists()
    usage = run_cli("tactile-hil", "emulate", "--help").stdout
    group = usage[usage.index("only with --suite"):]
    assert all(f"--{o} " in group for o in ("vectors", "data", "fuzz", "no-flash", "junit", "max-share", "sensor",
                                             "no-held-out"))
    assert "--sensor-id" not in group and "--timeout" not in group


def test_cli_run_against_a_wrong_model_fails_with_status_1(paper_model, tmp_path):
    require_tool("gcc")
    from fitgen.fitting.holdout import evaluate
    from fitgen.physics.simulate import DEFAULT_RANGES

    other = flash_variant(paper_model)
    other.fit_info["held_out"] = evaluate(other, load_sensor("paper"), DEFAULT_RANGES, n=100, draws=1)
    other = other.save(tmp_path / "other.json")
    with start_target(paper_model, "host", precision="double", style="table") as fw:
        proc = run_cli("tactile-hil", "run", "--port", fw.url, "--model", str(other), "--vectors", "50",
                       "--fuzz", "0", "--no-flash")
    assert proc.returncode == 1, proc.stdout + proc.stderr
    assert "FAIL" in proc.stdout
    # the held-out check does not blame rounding for another model's differences
    assert "held-out accuracy: FAIL (not measured: another model)" in proc.stdout, proc.stdout
    assert "rounding adds" not in proc.stdout


def test_cli_emulate_refuses_bus_options_it_cannot_serve(model_file):
    for extra, said in ((["--simulate", "dx=1"], "--simulate goes with --adc"), (["--adc", " "], "--adc is empty"),
                        # ignored without a word: the emulated firmware read the serial protocol's inputs
                        (["--seed", "3", "--sim-sensor", "paper"], "--sim-sensor, --seed go with --adc"),
                        # a model in mT behind ADCs in volts: the check read, pi-build and replay share
                        (["--adc", "ads1115@0x48:0-3,ads1115@0x49:0-3"],
                         "the model takes inputs in mT; the ADCs' readings are in V")):
        assert_one_line_error(run_cli("tactile-hil", "emulate", "--model", str(model_file), "--target", "host",
                                      "--suite", *extra), contains=said)


def test_cli_emulate_takes_the_targets_precision_and_refuses_a_style_fixed_point_ignores(model_file):
    """The microbit runs fixed point alone: emulate asked for --precision fixed there, as codegen does not; and
    --style with fixed point was built unrolled without a word."""
    proc = run_cli("tactile-hil", "emulate", "--model", str(model_file), "--target", "microbit", "--suite",
                   "--vectors", "5", "--fuzz", "0")  # a suite ends, whether the model runs in fixed point or not
    assert "not float" not in proc.stderr, proc.stderr
    # planned for fixed point: refused for a term it has not (a root), or built and run so
    assert "fixed point" in proc.stderr or "microbit firmware: fixed" in proc.stdout, proc.stdout + proc.stderr
    assert_one_line_error(run_cli("tactile-hil", "emulate", "--model", str(model_file), "--precision", "fixed",
                                  "--style", "table"), 2, "--style does not apply to --precision fixed")


def test_cli_bad_ports_and_silent_devices(model_file, tmp_path):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        free = s.getsockname()[1]
    assert_one_line_error(run_cli("tactile-hil", "run", "--port", f"socket://127.0.0.1:{free}",
                                  "--model", str(model_file)), 2, "cannot open port")
    assert_one_line_error(run_cli("tactile-hil", "run", "--port", str(tmp_path / "no-tty"),
                                  "--model", str(model_file)), 2, "cannot open port")
    # a device that accepts the connection and never answers
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(1)
    held = []
    t = threading.Thread(target=lambda: held.append(server.accept()), daemon=True)
    t.start()
    try:
        proc = run_cli("tactile-hil", "run", "--port", f"socket://127.0.0.1:{server.getsockname()[1]}",
                       "--model", str(model_file), "--timeout", "0.5")
        assert_one_line_error(proc, 2, "answer")
    finally:
        for conn, _ in held:
            conn.close()
        server.close()
    assert_one_line_error(run_cli("tactile-hil", "run", "--port", "/dev/null", "--model", str(tmp_path / "none.json")),
                          2, "model file")
    assert_one_line_error(run_cli("tactile-hil", "run", "--port", "x", "--model", str(model_file), "--vectors", "-1"),
                          2, "--vectors")
    assert_one_line_error(run_cli("tactile-hil", "run", "--port", "x", "--model", str(model_file), "--vectors",
                                  "100000000000"), 2, "from 0 to 100,000")
    # frames without bound ran until killed
    assert_one_line_error(run_cli("tactile-hil", "run", "--port", "x", "--model", str(model_file), "--fuzz",
                                  "1000000000000"), 2, "--fuzz must be a whole number from 0 to 1,000,000")


def test_cli_checks_junit_and_sensor_id_before_the_device(model_file, tmp_path):
    """--junit's file and --sensor-id are refused before a port is opened or firmware built, not after the suite."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        nobody = f"socket://127.0.0.1:{s.getsockname()[1]}"  # opening it would fail with "cannot open port"
    a_file = tmp_path / "g.csv"
    a_file.write_text("x\n")
    for extra, said in ((["--junit", str(tmp_path / "no" / "x.xml")], "does not exist"),
                        (["--junit", str(a_file / "x.xml")], f"{a_file} is a file, not a folder"),
                        (["--junit", str(tmp_path)], "it is a folder"),
                        (["--junit", str(model_file)], "is the input"),
                        (["--sensor-id", "toolongtoolongtoolong"], "longer than 16")):
        assert_one_line_error(run_cli("tactile-hil", "run", "--port", nobody, "--model", str(model_file), *extra),
                              2, said)
    # emulate: refused before the firmware is built
    proc = run_cli("tactile-hil", "emulate", "--target", "host", "--model", str(model_file), "--suite",
                   "--vectors", "10", "--fuzz", "0", "--junit", str(a_file / "x.xml"))
    assert_one_line_error(proc, 2, "is a file, not a folder")
    assert "firmware" not in proc.stdout


def test_cli_emulate_without_qemu_says_how_to_install(model_file, tmp_path, monkeypatch):
    import os
    import shutil

    # a PATH with python but without qemu-system-arm
    bindir = tmp_path / "bin"
    bindir.mkdir()
    import sys

    os.symlink(sys.executable, bindir / "python3")
    monkeypatch.setenv("PATH", str(bindir))
    assert shutil.which("qemu-system-arm") is None
    proc = run_cli("tactile-hil", "emulate", "--model", str(model_file))
    assert_one_line_error(proc, 2, "apt-get install")


def test_the_suite_shows_progress_through_eval_on_a_terminal(paper_model, monkeypatch):
    """eval and held-out accuracy take seconds on a slow board (10 s on the Uno): a bar moves through them."""
    require_tool("gcc")
    import sys

    term = Terminal()
    monkeypatch.setattr(sys, "stderr", term)
    rng = np.random.default_rng(0)
    readings = paper_model.input_min + (paper_model.input_max - paper_model.input_min) * rng.random((200, 8))
    truth = paper_model.predict(readings)
    with start_target(paper_model, "host", precision="double", style="table") as fw:
        with Device.open(fw.url, timeout=5) as dev:
            res = run_suite(dev, paper_model, url=fw.url, n_vectors=300, n_fuzz=0, flash=False, verbose=False,
                            held_out=(readings, truth))
    assert res.ok, res.table()
    assert "\reval [" in term.text and "] 64/" in term.text  # moved 64 vectors at a time
    assert "\rheld-out accuracy [" in term.text and "200/200" in term.text


def test_cli_emulate_port_numbers_are_refused_alike(model_file):
    """0 and -1 get the same line: 1..65535, and the option left out picks a free port."""
    for bad in ("0", "-1", "65536"):
        assert_one_line_error(run_cli("tactile-hil", "emulate", "--model", str(model_file), "--port", bad), 2,
                              f"{bad} is not a TCP port number (1..65535; leave --port out for a free one)")
    # the host target's UART is a pseudo-terminal: a port given was passed over without a word
    assert_one_line_error(run_cli("tactile-hil", "emulate", "--model", str(model_file), "--target", "host", "--port",
                                  "5555", "--suite"), 2, "the host target has none (its UART is a pseudo-terminal)")


def test_timing_reports_the_median_of_its_batched_evals(model, monkeypatch):
    """The batched throughput is the median over ``batches`` EVALs of n_batch vectors (bench/firmware_cost.py takes
    several: one timing moves with the machine's load), each a single EVAL of all the vectors."""
    import hil.suite

    clock = [0.0]
    monkeypatch.setattr(hil.suite.time, "perf_counter", lambda: clock[0])
    batch_seconds = iter([0.5, 0.1, 0.2])  # rates 40, 200, 100 per second: the median is 100
    sizes = []

    class Device:
        def eval(self, x):
            sizes.append(len(x))
            clock[0] += 0.001 if len(x) == 1 else next(batch_seconds)

    check = hil.suite.check_timing(Device(), model, n_single=5, n_batch=20, batches=3)
    assert sizes == [1] * 5 + [20] * 3
    assert check.figures["per_s"] == pytest.approx(100.0)
    assert check.figures["rtt_ms_median"] == pytest.approx(1.0)


def test_cli_emulate_with_adcs_says_when_the_models_own_sensor_is_not_here(device_model, tmp_path):
    """emulate --adc simulated paper in place of a twin's unit file moved away, without the note read makes."""
    require_tool("gcc")
    data = json.loads(Path(device_model.save(tmp_path / "m.json")).read_text())
    gone = str(tmp_path / "gone" / "unit.toml")
    data.setdefault("fit", {}).setdefault("held_out", {}).update({"sensor": "unit", "sensor_file": gone})
    (tmp_path / "twin.json").write_text(json.dumps(data))
    run = ["tactile-hil", "emulate", "--target", "host", "--adc", "ads1115@0x48:0-3,ads1115@0x49:0-3", "--simulate",
           "dx=1,dz=-1", "--suite", "--vectors", "5", "--fuzz", "0", "--no-flash", "--no-held-out", "--model"]
    proc = run_cli(*run, str(tmp_path / "twin.json"))
    assert (f"tactile-hil emulate: note: the model was fitted on {gone}, not found here as it was: simulating paper; "
            "give --sim-sensor") in proc.stderr, proc.stderr
    assert "not found here" not in run_cli(*run, str(tmp_path / "twin.json"), "--sim-sensor", "paper").stderr


def test_cli_emulate_runs_a_model_fitted_for_fixed_point_in_it_by_default(sensor, tmp_path):
    """codegen --target uno, predict --target uno and arduino-build run a model fitted for fixed point in it; emulate
    built float, so its suite checked another arithmetic than the library flashed. A style asks for float."""
    require_tool("gcc")
    from fitgen.fitting.fit import FitSettings
    from fitgen.physics.scenes import PRESETS

    slide = simulate(sensor, PRESETS["slide"].poses())
    fixed = fit_model(slide, PRESETS["slide"].outputs,
                      settings=FitSettings.family("no-roots", precision="fixed")).save(tmp_path / "fx.json")
    floated = fit_model(slide, PRESETS["slide"].outputs,
                        settings=FitSettings.family("no-roots")).save(tmp_path / "fl.json")
    run = ["tactile-hil", "emulate", "--target", "host", "--suite", "--vectors", "5", "--fuzz", "0", "--no-flash",
           "--no-held-out", "--model"]
    from host.temperature import TempComp

    tc = TempComp(25.0, np.zeros(8), np.zeros(8), {"temperatures": [15.0, 35.0]}).save(tmp_path / "tc.json")
    adc = ["--adc", "ads1115@0x48:0-3,ads1115@0x49:0-3,temp=ads1115@0x4a:0", "--simulate", "dx=1"]
    # --fma and --temp-comp have no fixed point: each asks for float, as --style does (they had been refused)
    for path, extra, built in ((fixed, [], "fixed, unrolled"), (fixed, ["--style", "table"], "float, table"),
                               (fixed, ["--precision", "float"], "float, table"), (floated, [], "float, table"),
                               (fixed, ["--fma"], "float, table"), (fixed, ["--temp-comp", str(tc), *adc],
                                                                   "float, table")):
        proc = run_cli(*run, str(path), *extra)
        assert proc.returncode == 0 and proc.stdout.startswith(f"host firmware: {built}"), proc.stdout + proc.stderr


def test_run_without_flashing_needs_no_sensor_id(paper_model, tmp_path):
    """run --no-flash writes no blob and compiles nothing, yet refused a unit's name longer than a blob's id."""
    from conftest import model_for_sensor

    long = model_for_sensor(paper_model, "unit-2026-12-04-lab-a", tmp_path / "long.json")
    proc = run_cli("tactile-hil", "run", "--port", "socket://127.0.0.1:1", "--model", long, "--no-flash")
    assert proc.returncode != 0 and "sensor id" not in proc.stderr and "127.0.0.1:1" in proc.stderr, proc.stderr
    assert "cannot be the calibration's sensor id" in run_cli("tactile-hil", "run", "--port", "socket://127.0.0.1:1",
                                                            "--model", long).stderr
