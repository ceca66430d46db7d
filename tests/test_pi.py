"""The Raspberry Pi build (firmware_templates/pi/): the C drivers over i2c-dev, built for ARM Linux and run
under qemu-arm against a stand-in for the kernel device answered by the bus model (host/simbus.py)."""

import os
import re
import select
import signal
from dataclasses import replace
from functools import partial
import subprocess
import time

import numpy as np
import pytest

from fitgen.app.cliutil import EXIT_PIPE
from host.adc import AdcArray, DeviceSilent, RetryPolicy
from host.channelmap import Settings, load_map_file, parse_spec
from host.pi import StandIn, build_pi, render_adc_map, render_pi
from host.readout import LineFormat
from host.temperature import TempComp

from conftest import (TWO_CHIPS, assert_one_line_error, drifting_bus, interrupt_after_rename, require_tool, run_cli,
                      sim_bus, twin_and_another_unit)

MAP = TWO_CHIPS


@pytest.fixture(scope="module")
def model(device_model):
    return device_model


@pytest.fixture(scope="module")
def standin_build(model, tmp_path_factory):
    require_tool("arm-linux-gnueabihf-gcc")
    folder = render_pi(model, parse_spec(MAP), tmp_path_factory.mktemp("pi"), precision="float")
    return build_pi(folder, standin=True)


def _bus(faults=()):
    return sim_bus(MAP, faults)


def _python_lines(model, n, faults=(), spec=MAP, settings=None):
    """What the Python drivers and the float model give for the same bus, as tactile-host read's lines."""
    cmap, bus, clock = sim_bus(spec, faults, settings)
    arr = AdcArray(bus, cmap, clock=clock, policy=RetryPolicy())
    arr.probe()
    arr.setup()
    fmt = LineFormat("csv", model.n_inputs, model.output_names)
    lines = []
    try:
        for _ in range(n):
            t = clock.time()
            v = arr.read_volts()
            out, status = model.predict(v, with_status=True, precision="float")
            lines.append(fmt.line(t, v, out[0], int(status[0])))
    except DeviceSilent:
        pass
    return lines, arr.counts


def _float_engine(model):
    """The engine of read that computes as tm_pi's float build: Python's emulation of the float header."""
    from host.engine import PythonEngine

    class FloatEngine(PythonEngine):
        def estimate(self, inputs):
            out, status = self.model.predict(np.asarray(inputs).reshape(1, -1), with_status=True, precision="float")
            return out[0], int(status[0])

    return FloatEngine(model)


def _python_readout(model, bus, clock, count, *, tempcomp=None, tin=None, rest=None, autozero=None, tare_n=50,
                    stats=None, cmap=None):
    """tactile-host read's CSV lines (header first) for ``bus``, and its tare (None without ``rest``): the Python
    drivers, a tare onto ``rest`` and ``tempcomp`` (with the thermistor at ``tin``), then Python's emulation of
    the float header, as tm_pi's float build computes them; ``autozero(tare, lsb)``: an AutoZero that follows
    the tare; ``stats``: a list the run's ReadoutStats is appended to; ``cmap``: the map read (default MAP's)."""
    import io

    from host.readout import Corrections, Readout
    from host.rest import tare
    from host.temperature import Thermometer

    arr = AdcArray(bus, cmap or parse_spec(MAP), clock=clock, policy=RetryPolicy())
    arr.probe()
    arr.setup()
    thermometer = Thermometer(arr, tin) if tin else None
    compensate = None
    if rest is not None and tempcomp is not None:  # as read: the tare's rows compensated at the temperature first
        compensate = partial(tempcomp.apply, temp=thermometer.read(fresh=True))
    t = None if rest is None else tare(arr, rest, tare_n, compensate=compensate)
    sink, fmt = io.StringIO(), LineFormat("csv", model.n_inputs, model.output_names)
    sink.write(fmt.header)
    run = Readout(arr, _float_engine(model), sink, fmt, clock=clock,
                  corrections=Corrections(None if t is None else t.offsets, tempcomp,
                                          None if autozero is None else autozero(t, arr.lsb)),
                  thermometer=thermometer).run(count=count)
    if stats is not None:
        stats.append(run)
    return sink.getvalue().splitlines(), t


def test_pi_build_under_qemu_gives_the_python_readout(model, standin_build):
    require_tool("qemu-arm")
    cmap, bus, clock = _bus()
    res = StandIn(bus, clock).run(["qemu-arm", str(standin_build), "--count", "6", "--format", "csv"])
    assert res.returncode == 0, res.stderr
    lines = res.stdout.splitlines(keepends=True)
    assert lines[0] == LineFormat("csv", model.n_inputs, model.output_names).header
    expected, _ = _python_lines(model, 6)
    # the same readings from the same conversions, the same float estimates, to every printed digit
    assert [ln.split(",", 1)[1] for ln in lines[1:]] == [ln.split(",", 1)[1] for ln in expected]
    assert re.search(r"tm_pi: 6 samples in \d+\.\d\d s \(\d+\.\d Hz\); I2C errors 0", res.stderr), res.stderr
    assert "estimated outside" not in res.stderr


def test_pi_build_reads_an_ads7828_to_the_digit_of_the_python_readout(model, tmp_path):
    """The ADS7828's external reference went into C as a float (3.3 became 3.2999999523), so tm_pi's volts and
    estimates left read's in the last digits on 7 of 20 lines; the ADS1115's power-of-two LSBs hid it."""
    require_tool("arm-linux-gnueabihf-gcc")
    require_tool("qemu-arm")
    from host.channelmap import Settings

    spec, settings = "ads7828@0x48:7,6,5,4,3,2,1,0", Settings(vref=3.3)
    exe = build_pi(render_pi(model, parse_spec(spec, settings), tmp_path, precision="float"), standin=True)
    _, bus, clock = sim_bus(spec, (), settings)
    res = StandIn(bus, clock).run(["qemu-arm", str(exe), "--count", "20", "--format", "csv"])
    assert res.returncode == 0, res.stderr
    expected, _ = _python_lines(model, 20, spec=spec, settings=settings)
    assert [ln.split(",", 1)[1] for ln in res.stdout.splitlines(keepends=True)[1:]] == \
        [ln.split(",", 1)[1] for ln in expected]


def _boxed_build(model, folder):
    """``model`` held out on a box dx -0.1..0.1 that GMR_POSE's dx 0.5 lies 0.4 past, and its float tm_pi built in
    ``folder`` against the stand-in."""
    import dataclasses

    boxed = dataclasses.replace(model, fit_info={**model.fit_info, "held_out": {"box": {"dx": [-0.1, 0.1],
                                                                                      "dz": [-2, 0]}}})
    return boxed, build_pi(render_pi(boxed, parse_spec(MAP), folder, precision="float"), standin=True)


def test_pi_build_counts_estimates_far_outside_the_fitted_box_as_read_does(model, tmp_path):
    """tm_pi's summary counts the samples estimated outside the model's fitted pose box by more than its width,
    by the bounds tactile-host read and fitgen predict use (Model.far_bounds): here a box dx -0.1..0.1 that
    GMR_POSE's dx 0.5 lies 0.4 past, on every sample."""
    require_tool("arm-linux-gnueabihf-gcc")
    require_tool("qemu-arm")
    boxed, build = _boxed_build(model, tmp_path)
    cmap, bus, clock = _bus()
    res = StandIn(bus, clock).run(["qemu-arm", str(build), "--count", "6"])
    assert res.returncode == 0, res.stderr
    est = np.array([[float(x) for x in ln.split(",")[1 + model.n_inputs:-1]] for ln in res.stdout.splitlines()[1:]])
    assert int(boxed.far_outside(est).sum()) == 6
    assert res.stderr.rstrip().endswith("; 6 estimated outside the pose box the model was fitted in by more than "
                                        "its width: another sensor than the model's?")


def _hold_up(bus, clock, reads, seconds=0.2):
    """``bus`` holds up the sample reads numbered in ``reads`` (from 1) for ``seconds`` on ``clock`` after their
    first conversion's result (8 elements a read): a loaded machine between the conversions, as tm_pi and read
    meet it alike, the same transfers at the same times."""
    transfer, results = bus._transfer, []

    def held(address, wr, rd):
        got = transfer(address, wr, rd)
        if list(wr or ()) == [0x00] and rd == 2:  # a conversion's result (ADS1115 REG_CONVERSION)
            results.append(1)
            if len(results) % MAP_ELEMENTS == 1 and len(results) // MAP_ELEMENTS + 1 in reads:
                clock.sleep(seconds)
        return got

    bus._transfer = held
    return bus


MAP_ELEMENTS = 8


def test_pi_build_counts_far_estimates_from_held_up_reads_apart_as_read_does(model, tmp_path, standin_build):
    """A read held up between its conversions (0.2 s, where a read takes some 10 ms) gives a moving sensor's
    channels at two poses: read counts a far estimate from it apart from the others ("another sensor than the
    model's?") and says it in its own words; tm_pi counted every one as another sensor's. It now times each read
    with its clock, and a read over 3 times the quickest and 20 ms more is held up: the same counts as read's for
    the same bus, the same holds (the 3rd and 7th of 10 reads) and the same box (every estimate far)."""
    from host.readout import FAR_HELD, FAR_OUTSIDE

    require_tool("arm-linux-gnueabihf-gcc")
    require_tool("qemu-arm")
    boxed, build = _boxed_build(model, tmp_path)
    cmap, bus, clock = _bus()
    res = StandIn(_hold_up(bus, clock, (3, 7)), clock).run(["qemu-arm", str(build), "--count", "10"])
    assert res.returncode == 0, res.stderr
    cmap, bus, clock = _bus()
    stats = []
    lines, _ = _python_readout(boxed, _hold_up(bus, clock, (3, 7)), clock, 10, stats=stats)
    far, far_held = stats[0].far, stats[0].far_held
    assert (far, far_held) == (8, 2)
    # each line's t is its sample's start: the 3rd and 7th samples' reads took 0.2 s more than the others
    t = [float(ln.split(",")[0]) for ln in res.stdout.splitlines()[1:]]
    assert [round(b - a, 1) for a, b in zip(t, t[1:])] == [0.0, 0.0, 0.2, 0.0, 0.0, 0.0, 0.2, 0.0, 0.0]
    assert [ln.split(",", 1)[1] for ln in res.stdout.splitlines()[1:]] == [ln.split(",", 1)[1] for ln in lines[1:]]
    # read's words for each count ("another sensor" as tm_pi has said it, without read's pointer to the docs)
    assert res.stderr.rstrip().endswith(f"; {far} {FAR_OUTSIDE.split(': ', 1)[0]}: another sensor than the model's?"
                                        f"; {far_held} {FAR_HELD}"), res.stderr
    assert stats[0].summary().endswith(f"; {far} {FAR_OUTSIDE}; {far_held} {FAR_HELD}")
    # held-up reads estimated inside the box: nothing to count, as read counts nothing
    cmap, bus, clock = _bus()
    res = StandIn(_hold_up(bus, clock, (3, 7)), clock).run(["qemu-arm", str(standin_build), "--count", "10"])
    assert res.returncode == 0 and "estimated outside" not in res.stderr, res.stderr


def test_pi_build_counts_faults_as_python_does_and_stops_on_a_silent_chip(model, standin_build):
    require_tool("qemu-arm")
    faults = [dict(kind="nack", rate=0.2), dict(kind="nack", address=0x49, after=120)]
    cmap, bus, clock = _bus(faults=faults)
    res = StandIn(bus, clock).run(["qemu-arm", str(standin_build), "--count", "50"])
    expected, counts = _python_lines(model, 50, faults)
    assert res.returncode == 1, res.stderr
    assert "ads1115@0x49 stays silent" in res.stderr
    got = res.stdout.splitlines(keepends=True)[1:]
    assert len(got) == len(expected) < 50
    assert [ln.split(",", 1)[1] for ln in got] == [ln.split(",", 1)[1] for ln in expected]
    c = counts
    assert (f"I2C errors {c.total} (nack {c.nack}, timeout {c.timeout}, stuck {c.stuck}, other {c.other}; "
            f"{c.retries} retries, {c.resets} resets)") in res.stderr


def test_pi_build_bad_options_and_missing_bus(standin_build):
    require_tool("qemu-arm")
    for args, contains in ((["--count", "-1"], "--count"), (["--count", "0"], "--count must be a whole number >= 1"),
                           (["--format", "xml"], "--format"),
                           (["--bogus"], "unknown"), (["--bus", "3"], "cannot open /dev/i2c-3"),
                           (["--tare-samples", "10"], "--tare-samples needs: --tare"),
                           (["--tare", "--tare-samples", "0"], "--tare-samples must be 1..100000"),
                           *((["--rate", r], "--rate") for r in ("0", "-2", "nan", "inf", "2.5Hz", "1e-9", "1e-4"))):
        cmap, bus, clock = _bus()
        res = StandIn(bus, clock).run(["qemu-arm", str(standin_build), *args])
        assert_one_line_error(res, 2, contains)


def test_pi_build_native_i2c_dev_port_compiles(model, tmp_path):
    """The real i2c-dev port (no stand-in) builds warning-free natively and for ARM Linux."""
    require_tool("gcc")
    folder = render_pi(model, parse_spec("ads7828@0x4a", Settings(vref=3.3)), tmp_path, precision="double")
    assert not list(folder.glob("standin.*"))  # the tests' stand-in for the kernel is not the user's to keep
    assert build_pi(folder, "gcc").is_file()
    require_tool("arm-linux-gnueabihf-gcc")
    assert build_pi(folder).is_file()


def test_adc_map_header_carries_the_channel_map():
    text = render_adc_map(parse_spec("ads1115@0x48:d0-1,2,ads7828@0x4b:0-3", Settings(pga=2.048, data_rate=128,
                                                                                      vref="internal")))
    assert "#define ADC_MAP_N_CHIPS 2" in text and "#define ADC_MAP_N_ELEMENTS 6" in text
    assert "{ ADC_ADS1115, 0x48, 2, { 0, 2, 0, 0, 0, 0, 0, 0 }, { 1, 255," in text
    assert ", 2, 4, 0, 1, 0.0 }" in text  # PGA code 2 (2.048 V), rate 4 (128 SPS), single-shot, internal ref
    assert '"ads1115@0x48", "ads7828@0x4b"' in text


def test_pi_build_cli_errors(tmp_path, model):
    path = str(model.save(tmp_path / "m.json"))
    assert_one_line_error(run_cli("tactile-host", "pi-build", "--model", path, "--adc", "ads1116@0x48:0-3",
                                  "-o", str(tmp_path / "x")), 2, "unknown chip")
    assert_one_line_error(run_cli("tactile-host", "pi-build", "--model", path, "--adc", "ads1115@0x48:0-3",
                                  "-o", str(tmp_path / "x")), 2, "reads 4 elements")
    assert_one_line_error(run_cli("tactile-host", "pi-build", "--model", path, "--adc", MAP, "--cc", "no-such-cc",
                                  "-o", str(tmp_path / "y")), 2, "not found")
    # a "compiler" that exits 0 and writes nothing: FileNotFoundError's traceback on the program it did not write
    assert_one_line_error(run_cli("tactile-host", "pi-build", "--model", path, "--adc", MAP, "--cc", "true",
                                  "-o", str(tmp_path / "z")), 2, "the compiler 'true' exited with status 0 but wrote no")
    assert not (tmp_path / "z").exists() and not list(tmp_path.glob(".z*"))
    assert_one_line_error(run_cli("tactile-host", "verify", path, "--cc", "true"), 2, "wrote no tm_vectors")
    # a model in mT is refused for its units, as read refuses it, not for rest readings it reads far from rest
    from fitgen.physics.sensor import load_sensor
    from fitgen.physics.transfer import readings

    # the paper's rest in mT, as a model fitted in mT records it: far from rest for these equations in V
    held = {"held_out": {"rest": readings(load_sensor("paper").with_transfer("raw"), np.zeros((1, 5)))[0].tolist()}}
    mt = str(replace(model, input_units="mT", fit_info={**model.fit_info, **held}).save(tmp_path / "mt.json"))
    assert_one_line_error(run_cli("tactile-host", "pi-build", "--model", mt, "--adc", MAP, "-o", str(tmp_path / "z")),
                          2, "the model takes inputs in mT; the ADCs' readings are in V: fit it on a dataset in V "
                             "(fitgen simulate --transfer gmr, or tactile-host capture)")
    assert "give readings" not in run_cli("tactile-host", "pi-build", "--model", mt, "--adc", MAP, "-o",
                                          str(tmp_path / "z")).stderr  # the ADCs' are what they are
    # absurd coefficients are named as the codegen names them, not as rest readings the model reads far from rest
    eq = replace(model.equations[0], coefficients=(1e300,) + model.equations[0].coefficients[1:])
    rest = {"held_out": {"rest": readings(load_sensor("paper").with_transfer("gmr"), np.zeros((1, 5)))[0].tolist()}}
    big = str(replace(model, equations=(eq,) + model.equations[1:], fit_info={**model.fit_info, **rest})
              .save(tmp_path / "big.json"))
    assert_one_line_error(run_cli("tactile-host", "pi-build", "--model", big, "--adc", MAP, "-o", str(tmp_path / "z")),
                          2, f"output {eq.name}: its terms reach")
    assert not (tmp_path / "z").exists()


def test_tm_pi_opens_the_bus_the_map_file_names(model, tmp_path):
    """A TOML map's `bus = 3` is read's bus unless --bus; tm_pi opened /dev/i2c-1 whatever the map said, and pi-build
    told the user to run it with --bus 1."""
    require_tool("arm-linux-gnueabihf-gcc")
    require_tool("qemu-arm")
    toml = tmp_path / "map.toml"
    toml.write_text("bus = 3\n" + "".join(f'[[chip]]\ntype = "ads1115"\naddress = {a}\ninputs = [0, 1, 2, 3]\n'
                                          for a in ("0x48", "0x49")))
    path = str(model.save(tmp_path / "m.json"))
    proc = run_cli("tactile-host", "pi-build", "--model", path, "--adc", str(toml), "--cc", "gcc", "-o",
                   str(tmp_path / "pi"))
    assert proc.returncode == 0 and "on the Pi: tm_pi --format csv (I2C bus 3 unless --bus N)" in proc.stderr, \
        proc.stderr
    folder = render_pi(model, load_map_file(toml), tmp_path / "standin", precision="float")
    binary = build_pi(folder, standin=True)
    for args, device in (([], "/dev/i2c-3"), (["--bus", "4"], "/dev/i2c-4")):
        cmap, bus, clock = _bus()
        assert_one_line_error(StandIn(bus, clock).run(["qemu-arm", str(binary), "--count", "1", *args]), 2,
                              f"cannot open {device}")
    cmap, bus, clock = _bus()
    res = StandIn(bus, clock, device="/dev/i2c-3").run(["qemu-arm", str(binary), "--count", "2"])
    assert res.returncode == 0 and len(res.stdout.splitlines()) == 3, res.stderr


def test_pi_build_defaults_to_the_precision_codegen_writes_for_the_pi(model, tmp_path):
    """Without --precision pi-build writes the header `fitgen codegen --target pi` writes (double: the Pi computes
    it in hardware), even for a model fitted for float; its summary and --help say so."""
    from fitgen.fitting.holdout import device_precision

    require_tool("gcc")
    assert device_precision(model) == "float"  # where the two rules could part
    path = str(model.save(tmp_path / "m.json"))
    proc = run_cli("tactile-host", "pi-build", "--model", path, "--adc", MAP, "--cc", "gcc", "-o", str(tmp_path / "pi"))
    assert proc.returncode == 0, proc.stderr
    assert ", double); on the Pi: tm_pi --format csv (I2C bus 1 unless --bus N)" in proc.stderr
    proc = run_cli("fitgen", "codegen", path, "--target", "pi", "--style", "unrolled", "-o", str(tmp_path / "c"))
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "pi" / "tm_model.h").read_text() == (tmp_path / "c" / "tm_model.h").read_text()
    assert "default double" in " ".join(run_cli("tactile-host", "pi-build", "--help").stdout.split())


def test_pi_build_compiles_warning_free_under_clang(model, tmp_path):
    """clang warns where gcc does not: glibc's NAN is a float, and returning it from a double function is a
    -Wdouble-promotion error under clang (pi-build --cc clang failed on its own adc.c)."""
    require_tool("clang")
    path = str(model.save(tmp_path / "m.json"))
    proc = run_cli("tactile-host", "pi-build", "--model", path, "--adc", MAP + ",temp=ads1115@0x4a:0", "--cc", "clang",
                   "-o", str(tmp_path / "pi"))
    assert proc.returncode == 0 and (tmp_path / "pi" / "tm_pi").is_file(), proc.stderr


def test_a_failed_pi_build_leaves_the_folder_as_it_was_and_refuses_before_it_writes(model, tmp_path):
    """A failed build changes nothing: the folder keeps the last build's sources and the program built from them
    (it was left with a new model's sources and no program), and no partial folder stays beside it."""
    require_tool("gcc")
    path = str(model.save(tmp_path / "m.json"))
    out = tmp_path / "pi"
    proc = run_cli("tactile-host", "pi-build", "--model", path, "--adc", MAP, "--cc", "gcc", "-o", str(out))
    assert proc.returncode == 0 and (out / "tm_pi").is_file(), proc.stderr
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    other = str(replace(model, input_min=model.input_min * 0.99).save(tmp_path / "other.json"))
    assert_one_line_error(run_cli("tactile-host", "pi-build", "--model", other, "--adc", MAP, "--cc", "gcc -Dfloat=",
                                  "-o", str(out)), contains="error")
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.json", "other.json", "pi"]
    # a failed first build makes no folder
    assert_one_line_error(run_cli("tactile-host", "pi-build", "--model", path, "--adc", MAP, "--cc", "gcc -Dfloat=",
                                  "-o", str(tmp_path / "new")), contains="error")
    assert not (tmp_path / "new").exists()
    # refusals come before anything is written: --temp-comp without the thermistor, the thermistor on an element
    tc = TempComp(25.0, np.zeros(8), np.zeros(8)).save(tmp_path / "tc.json")
    for adc, said in ((MAP, "--temp-comp needs the temperature"),
                      (MAP + ",temp=ads1115@0x49:3", "also an element's input")):
        assert_one_line_error(run_cli("tactile-host", "pi-build", "--model", path, "--adc", adc, "--temp-comp",
                                      str(tc), "--cc", "gcc", "-o", str(tmp_path / "none")), contains=said)
        assert not (tmp_path / "none").exists()
    # a folder of one's own whose adc.c the build would replace (it had been written over): refused, untouched;
    # the folder the build wrote is rebuilt into (above), and so is one that holds other files only
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "adc.c").write_text("/* my own driver */\n")
    assert_one_line_error(run_cli("tactile-host", "pi-build", "--model", path, "--adc", MAP, "--cc", "gcc", "-o",
                                  str(mine)), 2,
                          f"-o {mine} holds adc.c, which the build would replace, and no pi_options.h")
    assert [p.name for p in mine.iterdir()] == ["adc.c"] and (mine / "adc.c").read_text() == "/* my own driver */\n"
    (mine / "adc.c").rename(mine / "notes.txt")
    assert run_cli("tactile-host", "pi-build", "--model", path, "--adc", MAP, "--cc", "gcc", "-o",
                   str(mine)).returncode == 0 and (mine / "tm_pi").is_file()


def test_a_ctrl_c_while_a_pi_build_replaces_the_last_one_leaves_the_new_build_whole(model, tmp_path, monkeypatch):
    """A signal landing between two renames into the folder left the new sources beside the old ones and no
    program (the old one goes first, the new one comes last)."""
    from fitgen.app import host_cli

    require_tool("gcc")
    path = str(model.save(tmp_path / "m.json"))
    out = tmp_path / "pi"
    assert run_cli("tactile-host", "pi-build", "--model", path, "--adc", MAP, "--cc", "gcc", "-o",
                   str(out)).returncode == 0
    other = replace(model, input_min=model.input_min * 0.99)
    renamed = interrupt_after_rename(monkeypatch, out)
    with pytest.raises(SystemExit) as stop:
        host_cli.main(["pi-build", "--model", str(other.save(tmp_path / "other.json")), "--adc", MAP, "--cc", "gcc",
                       "-o", str(out)])
    monkeypatch.undo()
    assert stop.value.code == 130 and len(renamed) > 1 and (out / "tm_pi").is_file()
    assert other.sha256[:12] in (out / "tm_model.h").read_text()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.json", "other.json", "pi"]


def test_pi_build_compensates_temperature_as_the_python_readout_does(model, tmp_path):
    """A thermistor in the map and a compensation: tm_pi reads it after the elements every 0.25 s and applies
    tm_tempcomp.h before the model; the lines equal tactile-host read --temp-comp's to every printed digit."""
    from host.simsensor import Drift
    from host.rest import model_rest
    from host.temperature import TempComp, parse_temperature_input

    require_tool("arm-linux-gnueabihf-gcc")
    require_tool("qemu-arm")
    tin = parse_temperature_input("ads1115@0x4a:2")
    cmap = parse_spec(MAP)
    drift = Drift.typical(8, seed=4).steady(33.0)  # readings that do not depend on when they are taken
    tc = TempComp(25.0, drift.offset_tc * 0.9, drift.gain_tc * 1.1)

    def bus():
        return drifting_bus(cmap, drift, tin)

    folder = render_pi(model, cmap, tmp_path / "pi", precision="float", tin=tin, tempcomp=tc)
    binary = build_pi(folder, standin=True)
    b, clock = bus()
    res = StandIn(b, clock).run(["qemu-arm", str(binary), "--count", "8"])
    assert res.returncode == 0, res.stderr

    b, clock = bus()
    expected, _ = _python_readout(model, b, clock, 8, tempcomp=tc, tin=tin)
    got = res.stdout.splitlines()
    assert [ln.split(",", 1)[1] for ln in got[1:]] == [ln.split(",", 1)[1] for ln in expected[1:]]
    # and the compensation did something: without it the readings differ
    plain = render_pi(model, cmap, tmp_path / "plain", precision="float", tin=tin)
    b, clock = bus()
    res2 = StandIn(b, clock).run(["qemu-arm", str(build_pi(plain, standin=True)), "--count", "8"])
    assert [ln.split(",", 1)[1] for ln in res2.stdout.splitlines()[1:]] != [ln.split(",", 1)[1] for ln in got[1:]]
    # a tare at 33 degC, 8 from t0: its rows compensated as read compensates them (it averaged raw readings, so
    # every reading after it stayed off by the compensation's shift); the same lines to every printed digit
    rest = model_rest(model, "paper")
    tared = build_pi(render_pi(model, cmap, tmp_path / "tared", precision="float", tin=tin, tempcomp=tc, rest=rest),
                     standin=True)
    b, clock = bus()
    res3 = StandIn(b, clock).run(["qemu-arm", str(tared), "--tare", "--count", "8"])
    assert res3.returncode == 0, res3.stderr
    b, clock = bus()
    expected, t = _python_readout(model, b, clock, 8, tempcomp=tc, tin=tin, rest=rest[0])
    assert f"tm_pi: {t.describe()}" in res3.stderr, res3.stderr
    assert [ln.split(",", 1)[1] for ln in res3.stdout.splitlines()[1:]] == [ln.split(",", 1)[1] for ln in expected[1:]]
    assert_one_line_error(run_cli("tactile-host", "pi-build", "--model", str(tmp_path / "m.json"), "--adc", MAP,
                                  "--temp-comp", "x.json", "-o", str(tmp_path / "z")))


@pytest.mark.parametrize("pga, degc", [(2.048, 5.0), (4.096, -72.0), (4.096, 130.0)])
def test_a_thermistor_past_its_chips_full_scale_reads_none_in_tm_pi_and_read(model, tmp_path, pga, degc):
    """At 5 degC the divider gives 2.38 V, past the 2.048 V an ADS1115 reads at --pga 2.048: the clipped code had read
    as 14.3 degC, and tm_pi and read compensated every sample for it. Now both read no temperature and leave the
    samples uncompensated, as for an open thermistor (the model's domain cut to 2 V, which that gain reads). So for a
    reading outside the thermistor's rated range, -40..125 degC: an open NTC against an ADS1115's input (about 6 Mohm
    beside the 10 kohm series resistor) reads -72 degC, which both had compensated every sample for, extrapolated by
    97 degC, and a capture had recorded in a meta fitgen refuses."""
    from host.simsensor import Drift
    from host.temperature import Thermometer, parse_temperature_input

    require_tool("arm-linux-gnueabihf-gcc")
    require_tool("qemu-arm")
    tin = parse_temperature_input("ads1115@0x4a:2")
    cmap = parse_spec(MAP, Settings(pga=pga))
    model = replace(model, input_max=np.minimum(model.input_max, 2.0))
    drift = Drift.typical(8, seed=4).steady(degc)
    tc = TempComp(25.0, drift.offset_tc, drift.gain_tc)

    def bus():
        return drifting_bus(cmap, drift, tin)

    b, clock = bus()
    arr = AdcArray(b, cmap, clock=clock, policy=RetryPolicy())
    arr.probe()
    arr.setup()
    thermometer = Thermometer(arr, tin)
    assert np.isnan(thermometer.read())
    assert (thermometer.raw == pytest.approx(degc, abs=0.2)) if degc != 5.0 else np.isnan(thermometer.raw)
    runs = []
    for name, comp in (("comp", tc), ("plain", None)):
        b, clock = bus()
        binary = build_pi(render_pi(model, cmap, tmp_path / name, precision="float", tin=tin, tempcomp=comp),
                          standin=True)
        res = StandIn(b, clock).run(["qemu-arm", str(binary), "--count", "4"])
        assert res.returncode == 0, res.stderr
        runs.append([ln.split(",", 1)[1] for ln in res.stdout.splitlines()[1:]])
    assert runs[0] == runs[1]  # nothing compensated
    b, clock = bus()
    expected, _ = _python_readout(model, b, clock, 4, tempcomp=tc, tin=tin, cmap=cmap)
    assert runs[0] == [ln.split(",", 1)[1] for ln in expected[1:]]


def test_pi_build_notes_a_tare_from_another_unit_as_read_does(tmp_path):
    """tm_pi --tare on a twin's build with another unit resting: the note read gives, word for word, from the limit
    pi-build compiles in; on the twin's own unit, none. A drawing's build compiles in no limit."""
    from fitgen.equations.model import load_model
    from fitgen.physics.sensor import load_sensor
    from host.clock import VirtualClock
    from host.pi import _another_unit_block
    from host.rest import another_unit_note, model_rest
    from host.simbus import SimBus

    require_tool("arm-linux-gnueabihf-gcc")
    require_tool("qemu-arm")
    twin = twin_and_another_unit(tmp_path)
    rest = model_rest(twin)
    cmap = parse_spec(MAP)
    binary = build_pi(render_pi(twin, cmap, tmp_path / "pi", precision="float", rest=rest), standin=True)
    said = []
    for unit in ("u8", "u7"):
        def bus():
            clock = VirtualClock()
            return SimBus.for_channel_map(cmap, load_sensor(str(tmp_path / f"{unit}.unit.toml")).with_transfer("gmr"),
                                          [0.0] * 5, clock=clock, noise=0.0005, seed=3), clock

        b, clock = bus()
        res = StandIn(b, clock).run(["qemu-arm", str(binary), "--count", "1", "--tare"])
        assert res.returncode == 0, res.stderr
        b, clock = bus()
        note = another_unit_note(twin, _python_readout(twin, b, clock, 1, rest=rest[0])[1].offsets)
        said.append(note)
        assert [ln for ln in res.stderr.splitlines() if "note:" in ln] == ([f"tm_pi: {note}"] if note else [])
    assert said[0] and not said[1]
    assert _another_unit_block(load_model(tmp_path / "twin.json")) and not _another_unit_block(
        replace(twin, fit_info={k: v for k, v in twin.fit_info.items() if k != "held_out"}))


def test_pi_build_tares_as_the_python_readout_does(model, tmp_path):
    """tm_pi --tare averages 50 samples and maps them onto the rest readings pi-build compiled in, as read --tare
    does: on a bus whose elements drift by up to 30 mV, the same offsets line and the same lines to every printed
    digit, and lines that differ from the untared ones. A build without rest readings refuses --tare in one line."""
    from fitgen.physics.sensor import load_sensor
    from host.clock import VirtualClock
    from host.rest import model_rest
    from host.simbus import SimBus

    require_tool("arm-linux-gnueabihf-gcc")
    require_tool("qemu-arm")
    cmap = parse_spec(MAP)
    drift = np.linspace(-0.03, 0.03, 8)

    def bus():
        clock = VirtualClock()
        return SimBus.for_channel_map(cmap, load_sensor("paper").with_transfer("gmr"), [0.5, 0.2, -1.0, 1.0, 0.0],
                                      clock=clock, noise=0.0005, seed=3, offsets=drift), clock

    rest = model_rest(model, "paper")
    binary = build_pi(render_pi(model, cmap, tmp_path / "pi", precision="float", rest=rest), standin=True)
    b, clock = bus()
    res = StandIn(b, clock).run(["qemu-arm", str(binary), "--count", "6", "--tare"])
    assert res.returncode == 0, res.stderr

    b, clock = bus()
    expected, tared = _python_readout(model, b, clock, 6, rest=rest[0])
    assert f"tm_pi: {tared.describe()}, onto the rest readings of --rest paper\n" in res.stderr, res.stderr
    got = res.stdout.splitlines()
    assert got == expected[:1] + got[1:] and len(got) == len(expected) == 7
    assert [ln.split(",", 1)[1] for ln in got[1:]] == [ln.split(",", 1)[1] for ln in expected[1:]]
    # a tare of one sample has no spread: both said so (each printed 0.00 mV rms, as of a sensor without noise)
    b, clock = bus()
    one = StandIn(b, clock).run(["qemu-arm", str(binary), "--count", "1", "--tare", "--tare-samples", "1"])
    b, clock = bus()
    _, tared_one = _python_readout(model, b, clock, 1, rest=rest[0], tare_n=1)
    assert f"tm_pi: {tared_one.describe()}, onto the rest readings of --rest paper\n" in one.stderr, one.stderr
    assert "(one sample: no spread)" in one.stderr
    b, clock = bus()
    plain = StandIn(b, clock).run(["qemu-arm", str(binary), "--count", "6"]).stdout.splitlines()
    assert [ln.split(",", 1)[1] for ln in plain[1:]] != [ln.split(",", 1)[1] for ln in got[1:]]
    bare = build_pi(render_pi(model, cmap, tmp_path / "bare", precision="float"), standin=True)
    b, clock = bus()
    assert_one_line_error(StandIn(b, clock).run(["qemu-arm", str(bare), "--tare"]), 2,
                          "--tare: this build has no rest readings to map onto")
    # --help is an answer, not an unknown option (it was one, with status 2)
    b, clock = bus()
    helped = StandIn(b, clock).run(["qemu-arm", str(bare), "--help"])
    assert helped.returncode == 0 and helped.stdout.startswith("usage: tm_pi [--bus N] [--count N]") and \
        "without --count, until Ctrl-C" in helped.stdout and not helped.stderr
    b, clock = bus()
    assert_one_line_error(StandIn(b, clock).run(["qemu-arm", str(bare), "--hlep"]), 2,
                          "tm_pi: error: unknown or incomplete option: --hlep (usage: tm_pi [--bus N]")


def test_pi_build_auto_zeroes_as_the_python_readout_does(model, tmp_path):
    """tm_pi --auto-zero follows a sensor whose elements creep by a few mV within seconds, at rest but for a
    0.6 s press: the same rest band, the same update lines (when, how far, which element; none from the press)
    and the same readings and estimates to every printed digit as tactile-host read's AutoZero, given the numbers
    pi-build compiled in (each output's estimate at rest and its scatter per volt, scaled by the tare's noise
    floor); a wall clock set back mid-run changes nothing (the hold runs on the monotonic clock); with --tare
    alone the drift stays in the estimates. Its options go together as read's do, in one line."""
    from fitgen.physics.sensor import load_sensor
    from host.autozero import AutoZero, AutoZeroSettings
    from host.clock import VirtualClock
    from host.pi import pi_autozero
    from host.rest import model_rest
    from host.simbus import SimBus
    from host.simsensor import Drift

    require_tool("arm-linux-gnueabihf-gcc")
    require_tool("qemu-arm")
    cmap = parse_spec(MAP)
    n, hold, press = 500, 0.3, (1.5, 2.1)  # s of the bus clock

    class Jumping(VirtualClock):  # the wall clock set back an hour at 1 s, as the network sets a Pi's after boot
        def time(self):
            return super().time() - 3600.0 * (self.t > 1.0)

    def bus(clock_type=VirtualClock):
        clock = clock_type()
        drift = Drift(offset_tc=np.zeros(8), gain_tc=np.zeros(8), creep=np.linspace(-0.004, 0.006, 8), creep_tau=1.5)
        return SimBus.for_channel_map(cmap, load_sensor("paper").with_transfer("gmr"), [0, 0, 0, 0, 0], clock=clock,
                                      noise=0.0005, seed=5, drift=drift,
                                      motion=lambda t: np.array([0, 0, -0.3 * (press[0] <= t < press[1]), 0, 0])), clock

    rest = model_rest(model, "paper")
    binary = build_pi(render_pi(model, cmap, tmp_path / "pi", precision="float", rest=rest), standin=True)
    b, clock = bus()
    res = StandIn(b, clock).run(["qemu-arm", str(binary), "--count", str(n), "--auto-zero", "--rest-hold", str(hold)])
    assert res.returncode == 0, res.stderr

    # read's AutoZero with the build's numbers, on the same bus from the same tare
    b, clock = bus()
    centre, per_volt = pi_autozero(model, rest, "float")
    updates, made = [], []

    class Built(AutoZero):  # the band from pi-build's scatter per volt, as tm_pi scales it
        settings_given = AutoZeroSettings(hold=hold)

        @classmethod
        def at(cls, tared, lsb):
            noise = tared.noise_floor(lsb)
            az = cls(rest[0], noise, model.output_names, zero=tared.offsets, rest=centre, scatter=per_volt * noise,
                     settings=cls.settings_given)
            az.log = updates.append
            made.append(az)
            return az

    expected, tared = _python_readout(model, b, clock, n, rest=rest[0], autozero=Built.at)
    want = [f"tm_pi: {u}" for u in updates]
    got = [ln for ln in res.stderr.splitlines() if "auto-zero update" in ln]
    assert len(want) >= 3 and got == want, (got, want)
    at = [u.t - clock.epoch for u in made[0].updates]  # bus seconds
    assert not any(press[0] <= t <= press[1] + hold for t in at) and any(t > press[1] for t in at), at
    # the hold runs on the monotonic clock: a wall clock set back mid-run changes no update
    b, clock = bus(Jumping)
    jumped = StandIn(b, clock).run(["qemu-arm", str(binary), "--count", str(n), "--auto-zero", "--rest-hold", str(hold)])
    assert [ln for ln in jumped.stderr.splitlines() if "auto-zero update" in ln] == got
    assert [ln.split(",", 1)[1] for ln in res.stdout.splitlines()[1:]] == [ln.split(",", 1)[1] for ln in expected[1:]]
    band = next(ln for ln in res.stderr.splitlines() if "rest band" in ln)
    assert band.startswith("tm_pi: auto-zero: noise floor 0.") and "dx +-0.08 mm, dy +-0.08 mm, dz +-0.08 mm" in band
    # a band given narrower than the window mean's scatter at rest widens to 5 of its standard deviations, as
    # read's does: the same band and the same updates
    b, clock = bus()
    narrow = StandIn(b, clock).run(["qemu-arm", str(binary), "--count", str(n), "--auto-zero", "--rest-hold", str(hold),
                                    "--rest-band", "0.001,0.01"])
    b, clock = bus()
    updates.clear()
    Built.settings_given = AutoZeroSettings(band_mm=0.001, band_deg=0.01, hold=hold)
    _python_readout(model, b, clock, n, rest=rest[0], autozero=Built.at)
    assert made[-1].widened == model.output_names
    units = ["deg" if o.startswith("th") else "mm" for o in model.output_names]
    assert (", ".join(f"{o} +-{w:.3g} {u}" for o, w, u in zip(model.output_names, made[-1].band, units))
            in narrow.stderr), narrow.stderr
    assert [ln for ln in narrow.stderr.splitlines() if "auto-zero update" in ln] == [f"tm_pi: {u}" for u in updates]
    # the zero followed the creep: the last estimates sit at the estimate at rest, as they do not without it
    last = np.array([[float(x) for x in ln.split(",")[9:12]] for ln in res.stdout.splitlines()[-50:]])
    b, clock = bus()
    tared_only = StandIn(b, clock).run(["qemu-arm", str(binary), "--count", str(n), "--tare"]).stdout.splitlines()
    drifted = np.array([[float(x) for x in ln.split(",")[9:12]] for ln in tared_only[-50:]])
    off, off_tared = np.abs(last.mean(axis=0) - centre[:3]), np.abs(drifted.mean(axis=0) - centre[:3])
    assert off.max() < off_tared.max() / 2, (off, off_tared)
    for args, said in ((["--rest-hold", "1"], "--rest-hold needs: --auto-zero"),
                       (["--auto-zero", "--rest-band", "0.08"], "--rest-band must be MM,DEG"),
                       (["--auto-zero", "--rest-band", "0.08,-1"], "--rest-band must be MM,DEG"),
                       (["--auto-zero", "--rest-hold", "nan"], "--rest-hold must be seconds"),
                       (["--auto-zero", "--tare-samples", "3"], "give --tare-samples 5 or more (got 3)")):
        b, clock = bus()
        assert_one_line_error(StandIn(b, clock).run(["qemu-arm", str(binary), *args]), 2, said)
    bare = build_pi(render_pi(model, cmap, tmp_path / "bare", precision="float"), standin=True)
    b, clock = bus()
    assert_one_line_error(StandIn(b, clock).run(["qemu-arm", str(bare), "--auto-zero"]), 2,
                          "--auto-zero: this build has no rest readings to map onto")


def _stop_with(stand, args, sig, ready):
    """tm_pi (``args``) under qemu-arm on ``stand`` until ``ready()``, then ``sig``: (exit status, stdout, stderr,
    seconds from the signal to the end)."""
    proc = stand.spawn(["qemu-arm", *args], stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 60
        while not ready() and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.01)
        assert ready() and proc.poll() is None, "tm_pi did not get going"
        sent = time.monotonic()
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=60)
        return proc.returncode, out.decode(), err.decode(), time.monotonic() - sent
    finally:
        proc.kill()
        stand.thread.join(timeout=10)


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_pi_build_stopped_by_a_signal_keeps_every_line_and_prints_its_summary(model, standin_build, sig):
    """Ctrl-C or SIGTERM ends tm_pi as it ends tactile-host read: after the sample under way, every line whole and
    none lost in stdout's buffer, the summary, exit status 0."""
    require_tool("qemu-arm")
    cmap, bus, clock = _bus()
    stand = StandIn(bus, clock)
    code, out, err, _ = _stop_with(stand, [str(standin_build)], sig, lambda: stand.requests > 600)
    assert code == 0, err
    summary = err.splitlines()
    assert len(summary) == 1 and summary[0].startswith("tm_pi: stopped: "), err
    n = int(summary[0].split("stopped: ")[1].split()[0])
    lines = out.splitlines(keepends=True)
    assert n >= 10 and len(lines) == n + 1 and lines[-1].endswith("\n")
    expected, _ = _python_lines(model, n)
    assert [ln.split(",", 1)[1] for ln in lines[1:]] == [ln.split(",", 1)[1] for ln in expected]


class _SlowSleeps(StandIn):
    """Sleeps take a tenth of their time for real, so that a wait deaf to signals shows as a late end."""

    waiting = False

    def answer(self, line):
        if line.startswith("S "):
            ns = int(line.split()[1])
            self.waiting |= ns >= 50_000_000  # the drivers' waits are a few ms: this is --rate's
            time.sleep(ns * 1e-10)
        return super().answer(line)


def test_pi_build_signal_ends_a_rate_wait_at_once(standin_build):
    """At 0.01 Hz the wait for the second sample is 100 s (10 s here): a SIGTERM in it ends the run within a
    fraction of a second, with no sample after it."""
    require_tool("qemu-arm")
    cmap, bus, clock = _bus()
    stand = _SlowSleeps(bus, clock)
    code, out, err, took = _stop_with(stand, [str(standin_build), "--rate", "0.01"], signal.SIGTERM,
                                      lambda: stand.waiting)
    assert code == 0 and "tm_pi: stopped: 1 samples" in err, err
    assert len(out.splitlines()) == 2
    assert took < 3.0


def test_pi_build_ends_as_read_does_when_its_reader_goes_away_with_sigpipe_ignored(standin_build):
    """systemd (IgnoreSIGPIPE=yes) or `trap '' PIPE` ignores SIGPIPE: tm_pi's writes then failed with EPIPE and it
    polled the bus forever, to exit 0 when stopped. Now it stops at the first failed line, as read does: no more
    transfers, nothing on stderr, exit status 141; a full disk is one line and exit status 2; a closed one, nowhere."""
    require_tool("qemu-arm")
    cmap, bus, clock = _bus()
    stand = StandIn(bus, clock)
    proc = stand.spawn(["sh", "-c", "trap '' PIPE; exec \"$@\"", "sh", "qemu-arm", str(standin_build)],
                       stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        assert all(proc.stdout.readline().endswith(b"\n") for _ in range(4))
        proc.stdout.close()  # the reader goes away mid-run
        closed = stand.requests
        code = proc.wait(timeout=20)
        stand.thread.join(timeout=10)
        assert code == EXIT_PIPE == 141 and proc.stderr.read() == b""
        assert stand.requests - closed < 60  # the sample under way (24 transfers) at most: no more polling
    except subprocess.TimeoutExpired:
        pytest.fail(f"tm_pi still ran 20 s after its reader went away ({stand.requests - closed} more requests)")
    finally:
        proc.kill()
        proc.wait()
    cmap, bus, clock = _bus()
    with open("/dev/full", "w") as full:
        proc = StandIn(bus, clock).spawn(["qemu-arm", str(standin_build), "--count", "3"], stdin=subprocess.DEVNULL,
                                         stdout=full, stderr=subprocess.PIPE)
        _, err = proc.communicate(timeout=60)
    assert proc.returncode == 2 and err.decode() == (
        "tm_pi: error: cannot write standard output: No space left on device\n")
    # a stdout closed before the start (>&-) goes nowhere, as read's: no write error, the run as asked
    cmap, bus, clock = _bus()
    res = StandIn(bus, clock).run(["sh", "-c", 'exec "$@" >&-', "sh", "qemu-arm", str(standin_build), "--count", "3"])
    assert res.returncode == 0 and res.stderr.startswith("tm_pi: 3 samples in "), res.stderr


def test_pi_build_s_lines_reach_a_pipe_as_they_are_written(standin_build):
    """stdout to a pipe was fully buffered: at --rate 1 the first line reached its reader some 30 s late. Line
    buffered, as read flushes each line, the first sample's line is there while tm_pi waits for the second."""
    require_tool("qemu-arm")
    cmap, bus, clock = _bus()
    stand = _SlowSleeps(bus, clock)  # --rate 0.01's 100 s wait takes 10 s
    proc = stand.spawn(["qemu-arm", str(standin_build), "--rate", "0.01"], stdin=subprocess.DEVNULL,
                       stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    got, deadline = b"", time.monotonic() + 8
    try:
        while got.count(b"\n") < 2 and time.monotonic() < deadline:
            if select.select([proc.stdout], [], [], 0.1)[0]:
                got += os.read(proc.stdout.fileno(), 4096)
        at = clock.monotonic()
    finally:
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=60)
        stand.thread.join(timeout=10)
    assert got.count(b"\n") == 2 and at < 100.0, (got, at)  # the header and the first sample, before the second
    assert proc.returncode == 0 and "tm_pi: stopped: 1 samples" in err.decode(), err

class _Stall(StandIn):
    """The bus hangs for 1 s at its 300th transfer (in the 10th or so sample; 24 transfers a sample)."""

    transfers = 0

    def answer(self, line):
        if line.startswith("R "):
            self.transfers += 1
            if self.transfers == 300:
                self.clock.sleep(1.0)
        return super().answer(line)


def test_pi_build_rate_restarts_its_grid_after_a_stall_and_takes_fractions(standin_build):
    """As tactile-host read paces: a sample more than a period late is counted and the grid restarts from it, so
    a 1 s stall at 20 Hz is not followed by some 20 samples back to back; and --rate 2.5 is 2.5 Hz."""
    require_tool("qemu-arm")

    def gaps(res):
        assert res.returncode == 0, res.stderr
        return np.diff([float(ln.split(",")[0]) for ln in res.stdout.splitlines()[1:]])

    cmap, bus, clock = _bus()
    res = _Stall(bus, clock).run(["qemu-arm", str(standin_build), "--count", "40", "--rate", "20"])
    g = gaps(res)
    stalled = g > 0.5
    assert len(g) == 39 and stalled.sum() == 1
    assert np.allclose(g[~stalled], 0.05, atol=2e-6)  # every other sample on the grid: no burst
    assert "tm_pi: 40 samples in " in res.stderr and res.stderr.rstrip().endswith("; 1 late")
    cmap, bus, clock = _bus()
    res = StandIn(bus, clock).run(["qemu-arm", str(standin_build), "--count", "4", "--rate", "2.5"])
    assert np.allclose(gaps(res), 0.4, atol=2e-6) and "late" not in res.stderr
    # read's summary: the time from the start, and the pace from the first sample's start to the last's
    took, hz = re.search(r"tm_pi: 4 samples in (\d+\.\d\d) s \((\d+\.\d) Hz\); I2C errors 0", res.stderr).groups()
    assert hz == "2.5" and 1.2 <= float(took) < 1.3, res.stderr


def test_pi_build_checks_the_compiler_before_it_writes(model, tmp_path):
    """A compiler that is not there is said before anything is written: no folder made, an earlier build's kept."""
    require_tool("gcc")
    path = str(model.save(tmp_path / "m.json"))

    def pi_build(cc, out, *more):
        return run_cli("tactile-host", "pi-build", "--model", path, "--adc", MAP, "--cc", cc, "-o", str(out), *more)

    proc = pi_build("nosuchcc", tmp_path / "new")
    assert_one_line_error(proc, 2, "compiler 'nosuchcc' not found")
    assert "gcc-arm-linux-gnueabihf" not in proc.stderr  # the default compiler's package is no advice for another
    assert not (tmp_path / "new").exists()
    out = tmp_path / "pi"
    assert pi_build("gcc", out).returncode == 0
    before = {f.name: f.read_bytes() for f in out.iterdir()}
    assert_one_line_error(pi_build("nosuchcc", out, "--precision", "double"), 2, "not found")
    assert {f.name: f.read_bytes() for f in out.iterdir()} == before


def test_vref_is_refused_without_an_ads7828_and_the_thermistor_is_named(model, tmp_path):
    """--vref sets the ADS7828's reference only: with ADS1115s alone read and pi-build refuse it, even as the
    default 3.3 and before --adc; a thermistor on an ADS7828 takes it, and pi-build's summary names it."""
    path = str(model.save(tmp_path / "m.json"))
    read = ["read", "--model", path, "--simulate", "dx=0", "--count", "1"]
    for cmd in (read, ["pi-build", "--model", path, "--cc", "gcc", "-o", str(tmp_path / "x")]):
        for opts in (["--adc", MAP, "--vref", "3.3"], ["--vref", "internal", "--adc", MAP + ",temp=ads1115@0x4a:2"]):
            assert_one_line_error(run_cli("tactile-host", *cmd, *opts), 2, "--vref sets the ADS7828's reference")
    assert not (tmp_path / "x").exists()
    assert run_cli("tactile-host", *read, "--adc", "ads7828@0x4a", "--vref", "3.3").returncode == 0
    require_tool("gcc")
    proc = run_cli("tactile-host", "pi-build", "--model", path, "--adc", MAP + ",temp=ads7828@0x4a:0", "--vref",
                   "3.3", "--cc", "gcc", "-o", str(tmp_path / "t"))
    assert proc.returncode == 0, proc.stderr
    assert ", thermistor ads7828@0x4a:0, model" in proc.stderr


def test_the_ads1115_s_options_are_refused_without_an_ads1115(model, tmp_path):
    """--pga, --data-rate and --mode set the ADS1115's conversions only: with ADS7828s alone they did nothing and
    were taken without a word, as --vref is refused without an ADS7828; a thermistor on an ADS1115 takes them."""
    path = str(model.save(tmp_path / "m.json"))
    read = ["read", "--model", path, "--simulate", "dx=0", "--count", "1"]
    for cmd in (read, ["pi-build", "--model", path, "--cc", "gcc", "-o", str(tmp_path / "x")]):
        for flag, value in (("--pga", "2.048"), ("--data-rate", "128"), ("--mode", "continuous")):
            assert_one_line_error(run_cli("tactile-host", *cmd, "--adc", "ads7828@0x4a", flag, value), 2,
                                  f"{flag} sets the ADS1115's conversions; no chip in --adc is an ADS1115")
    assert not (tmp_path / "x").exists()
    assert run_cli("tactile-host", *read, "--adc", "ads7828@0x4a,temp=ads1115@0x48:0", "--pga", "4.096").returncode == 0
