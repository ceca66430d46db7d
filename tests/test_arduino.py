"""The Arduino library (host/arduino.py): its manifests against the specifications' required fields, its
headers as C++, and its ReadPose example built for the Uno with Debian's arduino-builder, offline."""

import json
import re
import subprocess

import pytest

from host.arduino import BOARDS, build_example, library_properties, render_arduino
from host.channelmap import parse_spec

from conftest import TWO_CHIPS, assert_one_line_error, require_tool, run_cli

UNO = BOARDS["uno"]
SIZE = re.compile(r"flash (\d+) of 32256 B .*, RAM (\d+) of 2048 B")


@pytest.fixture(scope="module")
def model_path(device_model, tmp_path_factory):
    return str(device_model.save(tmp_path_factory.mktemp("model") / "model.json"))


def _build_cli(model_path, out, *extra):
    return run_cli("tactile-host", "arduino-build", "--model", model_path, "--adc", TWO_CHIPS, "-o", str(out), *extra)


def test_manifests_carry_the_specifications_required_fields(device_model, tmp_path):
    lib = render_arduino(device_model, parse_spec(TWO_CHIPS), tmp_path / "TactilePose")
    props = dict(ln.split("=", 1) for ln in (lib / "library.properties").read_text().splitlines())
    # arduino-lint's strict schema (arduino-library-properties-definitions-schema.json, requiredObjects)
    for key in ("name", "version", "author", "maintainer", "sentence", "paragraph", "url", "category", "architectures"):
        assert props.get(key, "").strip(), key
    name = props["name"]
    assert re.fullmatch(r"[A-Za-z][A-Za-z0-9_.\-]*", name) and len(name) <= 16
    assert "arduino" not in name.lower() and "library" not in name.lower()
    assert re.fullmatch(r"\d+\.\d+\.\d+", props["version"])
    assert props["category"] in ("Display", "Communication", "Signal Input/Output", "Sensors", "Device Control",
                                 "Timing", "Data Storage", "Data Processing", "Other")
    assert re.fullmatch(r"https?://\S+", props["url"])
    assert (lib / "src" / props["includes"]).is_file()
    # PlatformIO's library.json: name (slug, <= 50), version (semver, <= 20), description (<= 255)
    pio = json.loads((lib / "library.json").read_text())
    assert re.fullmatch(r"[A-Za-z0-9]([A-Za-z0-9\-]*[A-Za-z0-9])?", pio["name"]) and len(pio["name"]) <= 50
    assert pio["version"] == props["version"] and len(pio["version"]) <= 20
    assert 0 < len(pio["description"]) <= 255
    assert (lib / "examples" / "ReadPose" / "ReadPose.ino").is_file()
    assert library_properties() == (lib / "library.properties").read_text()


@pytest.mark.parametrize("cxx", ["avr-g++ -mmcu=atmega328p", "g++"])
def test_headers_compile_as_cxx_warning_free(device_model, tmp_path, cxx):
    tool = cxx.split()[0]
    require_tool(tool)
    lib = render_arduino(device_model, parse_spec(TWO_CHIPS), tmp_path / "TactilePose")
    main = tmp_path / "main.cpp"
    main.write_text('#include "TactilePose.h"\nint main(void)\n{\n    tm_real in[TM_N_INPUTS] = { 0 }, '
                    'out[TM_N_OUTPUTS];\n    return tm_estimate(in, out) + ADC_MAP[0].address + (int)TACTILE_LSB[0];\n}\n')
    proc = subprocess.run(cxx.split() + ["-std=gnu++11", "-Wall", "-Wextra", "-Werror", "-pedantic",
                                         "-Wdouble-promotion", "-Wfloat-conversion", "-I", str(lib / "src"), "-c",
                                         str(main), "-o", str(tmp_path / "main.o")], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr


def test_read_pose_builds_for_the_uno_and_fits(model_path, tmp_path):
    require_tool("arduino-builder")
    require_tool("avr-size")
    proc = _build_cli(model_path, tmp_path / "TactilePose")
    assert proc.returncode == 0, proc.stderr
    flash, ram = map(int, SIZE.search(proc.stderr).groups())
    assert 4000 < flash <= UNO.flash and 400 < ram <= UNO.ram
    # the figures are avr-size's of the ELF the example builds to
    size = build_example(tmp_path / "TactilePose", tmp_path / "again")
    assert (size.flash, size.ram) == (flash, ram)
    assert (tmp_path / "again" / "ReadPose.ino.hex").is_file()


def test_fixed_point_builds_for_the_uno(model_path, tmp_path):
    require_tool("arduino-builder")
    proc = _build_cli(model_path, tmp_path / "TactilePose", "--precision", "fixed")
    assert proc.returncode == 0, proc.stderr
    flash, ram = map(int, SIZE.search(proc.stderr).groups())
    assert flash <= UNO.flash and ram <= UNO.ram
    assert "#define TM_FIXED_POINT 1" in (tmp_path / "TactilePose" / "src" / "tm_model.h").read_text()


def test_a_model_that_does_not_fit_is_refused_naming_a_setting_that_does(tmp_path):
    require_tool("arduino-builder")
    # the paper grid fitted with a small penalty (about 290 terms): unrolled code overflows the Uno's flash,
    # the table style (its tables in PROGMEM) does not
    data, model = tmp_path / "g.csv", tmp_path / "big.json"
    for args in (("simulate", "--grid", "paper-sim", "--transfer", "gmr", "-o", str(data)),
                 ("fit", str(data), "-o", str(model), "--k", "0.05", "--held-out", "0")):
        proc = run_cli("fitgen", *args)
        assert proc.returncode == 0, proc.stderr
    model_path = str(model)
    proc = _build_cli(model_path, tmp_path / "big", "--style", "unrolled")
    assert_one_line_error(proc, 2, "does not fit the uno: flash over")
    named = re.search(r"; (--style \w+|--precision \w+) fits", proc.stderr)
    assert named, proc.stderr
    ok = _build_cli(model_path, tmp_path / "TactilePose", *named[1].split())
    assert ok.returncode == 0, ok.stderr
    flash, ram = map(int, SIZE.search(ok.stderr).groups())
    assert flash <= UNO.flash and ram <= UNO.ram


def test_fixed_point_of_the_no_roots_model_fits_the_uno(sensor, tmp_path):
    """The paper grid fitted without roots (138 terms) in fixed point fits the Uno (the issue's acceptance): its
    header is the plan for the Uno's 16-bit multiply, its 32x32->64 products in AVR assembly (fitgen/c/avrasm.py;
    with avr-gcc's 64-bit library calls it took 35,384 B and was refused)."""
    require_tool("arduino-builder")
    from fitgen.fitting.fit import FitSettings, fit_model
    from fitgen.physics.simulate import PAPER_GRIDS, grid_poses, simulate

    model = fit_model(simulate(sensor, grid_poses(PAPER_GRIDS["paper-sim"])), settings=FitSettings.family("no-roots"))
    path = str(model.save(tmp_path / "noroots.json"))
    proc = _build_cli(path, tmp_path / "TactilePose", "--precision", "fixed")
    assert proc.returncode == 0, proc.stderr
    flash, ram = map(int, SIZE.search(proc.stderr).groups())
    assert flash <= UNO.flash and ram <= UNO.ram
    header = (tmp_path / "TactilePose" / "src" / "tm_model.h").read_text()
    assert " * Plan: for a 16-bit multiply (--target uno)" in header and "tm_avr_dot" in header


def test_double_and_bad_maps_are_refused_in_one_line(model_path, tmp_path):
    assert_one_line_error(_build_cli(model_path, tmp_path / "d", "--precision", "double"), 2, "32 bits")
    proc = run_cli("tactile-host", "arduino-build", "--model", model_path, "--adc", "ads1115@0x48:0-3",
                   "-o", str(tmp_path / "m"), "--no-build")
    assert_one_line_error(proc, 2, "the channel map reads 4 elements; the model takes 8")
