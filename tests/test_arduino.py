"""The Arduino library (host/arduino.py): its manifests against the specifications' required fields, its
headers as C++, and its ReadPose example built for the Uno with Debian's arduino-builder, offline, and run on
the emulated ATmega328P (hil/sketch.py) with two ADS1115s on its TWI bus: what it prints, and RAM with the
stack's measured peak."""

import json
import re
import subprocess
from pathlib import Path

import numpy as np
import pytest

from fitgen.base.errors import InputError
from host.arduino import build_example, example_elf, library_properties, render_arduino
from host.sketchbuild import HARDWARE, build_sketch, sketch_elf
from host.boards import BOARDS
from host.channelmap import parse_spec

from conftest import TWO_CHIPS, Terminal, assert_one_line_error, require_tool, run_cli, twin_and_another_unit

UNO = BOARDS["uno"]
# flash and static RAM (the stack's peak after them when it was measured, as it is wherever simavr is)
SIZE = re.compile(r"flash (\d+) of 32256 B .*, RAM (\d+) (?:of 2048 B|\+ stack peak \d+ = \d+ of 2048 B)")
# with --emulate: static RAM + the stack's peak measured in the emulator = their sum
RAM_STACK = re.compile(r"flash (\d+) of 32256 B .*, RAM (\d+) \+ stack peak (\d+) = (\d+) of 2048 B")
POSE = (1.0, 0.0, -1.0)  # the simulated magnet: dx=1, dz=-1


@pytest.fixture(scope="module")
def model_path(device_model, tmp_path_factory):
    return str(device_model.save(tmp_path_factory.mktemp("model") / "model.json"))


def _build_cli(model_path, out, *extra):
    return run_cli("tactile-host", "arduino-build", "--model", model_path, "--adc", TWO_CHIPS, "-o", str(out), *extra)


def _require_emulator():
    for tool in ("arduino-builder", "avr-size", "avr-nm", "gcc", "pkg-config"):
        require_tool(tool)


def _fit_cli(tmp_path, name, *options):
    """The paper sensor's grid in volts fitted as ``fitgen fit`` does by default (the family chosen by auto:
    the harmonics), or with ``options``."""
    data, model = tmp_path / "sim.csv", tmp_path / f"{name}.json"
    if not data.exists():
        proc = run_cli("fitgen", "simulate", "--sensor", "paper", "--transfer", "gmr", "--grid", "paper-sim",
                       "-o", str(data))
        assert proc.returncode == 0, proc.stderr
    proc = run_cli("fitgen", "fit", str(data), "-o", str(model), "--held-out", "0", *options)
    assert proc.returncode == 0, proc.stderr
    return str(model)


def _assert_rows_show_the_pose(names, rows):
    assert names == ("t",) + tuple(f"v{k}" for k in range(1, 9)) + ("dx", "dy", "dz", "thx", "thy", "status")
    assert len(rows) >= 5 and np.all(np.diff(rows[:, 0]) > 0)  # t: seconds since reset, rising
    assert np.all(rows[:, -1] == 0)
    assert np.all(np.abs(rows[:, 9:12] - POSE) <= 0.15), rows[:, 9:12]


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
    # the drivers in src/ are the project's, under its license, whose notice goes with every copy
    assert (lib / "LICENSE").read_text() == (Path(__file__).parents[1] / "LICENSE").read_text()
    # keywords.txt: comments, or a name, one tab and a kind the IDE knows
    for line in (lib / "keywords.txt").read_text().splitlines():
        assert line.startswith("#") or re.fullmatch(r"[A-Za-z_]\w*\t(KEYWORD1|KEYWORD2|KEYWORD3|LITERAL1)", line), line


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
    # every name keywords.txt colours is one the library declares
    source = " ".join(p.read_text() for p in (lib / "src").rglob("*") if p.is_file())
    for line in (lib / "keywords.txt").read_text().splitlines():
        assert line.startswith("#") or re.search(rf"\b{line.split(chr(9))[0]}\b", source), line
    # an adc_map.h of another build (another element count) stops the compile, before ReadPose's arrays overrun
    amap = lib / "src" / "tactile" / "adc_map.h"
    amap.write_text(re.sub(r"#define ADC_MAP_N_ELEMENTS \d+", "#define ADC_MAP_N_ELEMENTS 6", amap.read_text()))
    proc = subprocess.run(cxx.split() + ["-std=gnu++11", "-I", str(lib / "src"), "-c", str(main), "-o",
                                         str(tmp_path / "main.o")], capture_output=True, text=True)
    assert proc.returncode != 0 and "come from different builds" in proc.stderr, proc.stderr


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


def test_another_librarys_header_of_a_common_name_is_its_own_in_a_sketch_beside_ours(device_model, tmp_path):
    """arduino-builder puts each library's src/ on the include path once a sketch includes one of its headers: a
    driver there named adc.h answered another library's <adc.h> in the same sketch, which the other library's own
    code then did not compile against. The library's src/ holds its one include; its parts are under src/tactile/."""
    require_tool("arduino-builder")
    lib = render_arduino(device_model, parse_spec(TWO_CHIPS), tmp_path / "TactilePose")
    assert [p.name for p in (lib / "src").iterdir() if p.is_file()] == ["TactilePose.h"]
    other = tmp_path / "OtherAdc"
    (other / "src").mkdir(parents=True)
    (other / "library.properties").write_text("name=OtherAdc\nversion=1.0.0\nauthor=A\nmaintainer=A\nsentence=S\n"
                                              "paragraph=P\ncategory=Other\nurl=https://example.org\narchitectures=*\n")
    (other / "src" / "adc.h").write_text("#define OTHER_ADC_CHANNELS 4\n")
    sketch = tmp_path / "Both" / "Both.ino"
    sketch.parent.mkdir()
    sketch.write_text("#include <TactilePose.h>\n#include <adc.h>\nvoid setup() { Serial.begin(OTHER_ADC_CHANNELS); "
                      "}\nvoid loop() {}\n")
    size = build_sketch(sketch, {"TactilePose": lib, "OtherAdc": other}, tmp_path / "build")
    assert size.flash > 0 and sketch_elf(tmp_path / "build", "Both").is_file()


def test_fixed_point_builds_for_the_uno(model_path, tmp_path):
    require_tool("arduino-builder")
    proc = _build_cli(model_path, tmp_path / "TactilePose", "--precision", "fixed")
    assert proc.returncode == 0, proc.stderr
    flash, ram = map(int, SIZE.search(proc.stderr).groups())
    assert flash <= UNO.flash and ram <= UNO.ram
    assert "#define TM_FIXED_POINT 1" in (tmp_path / "TactilePose" / "src" / "tactile" / "tm_model.h").read_text()


def test_a_model_that_does_not_fit_is_refused_naming_a_setting_that_does(tmp_path):
    require_tool("arduino-builder")
    # the paper grid fitted with a small penalty in the power family (about 360 terms): unrolled code
    # overflows the Uno's flash, the table style (its tables in PROGMEM) does not, and runs (with harmonic
    # terms the table's monomials and powers overflow the stack: see the test after the next)
    model_path = _fit_cli(tmp_path, "big", "--family", "all", "--k", "0.01")
    proc = _build_cli(model_path, tmp_path / "big", "--style", "unrolled")
    assert_one_line_error(proc, 2, "does not fit the Uno: flash over")
    named = re.search(r"; (--style \w+|--precision \w+) fits", proc.stderr)
    assert named, proc.stderr
    ok = _build_cli(model_path, tmp_path / "TactilePose", *named[1].split())
    assert ok.returncode == 0, ok.stderr
    flash, ram = map(int, SIZE.search(ok.stderr).groups())
    assert flash <= UNO.flash and ram <= UNO.ram
    # the setting named when the stack is measured too, and its lines
    proc = _build_cli(model_path, tmp_path / "big", "--style", "unrolled", "--emulate", "dx=1,dz=-1")
    assert_one_line_error(proc, 2, "does not fit the Uno: flash over")
    assert named[0] + " (" in proc.stderr and RAM_STACK.search(proc.stderr.split(named[0])[-1])


def test_a_units_twin_that_fits_no_setting_is_told_how_to_find_one_that_does(tmp_path):
    """A built unit's equations take about three times the drawing's terms: the default fit of a unit's dense
    simulation (harmonics, no fixed point) fits the Uno in no precision or style. The line says to fit fewer terms
    and names the sweep that ranks term caps; a twin capped as that sweep finds builds."""
    require_tool("arduino-builder")
    data = tmp_path / "twin.csv"
    proc = run_cli("fitgen", "simulate", "--sensor", "paper", "--transfer", "gmr", "--unit", "2", "--grid",
                   "paper-sim", "--random", "5000", "-o", str(data))
    assert proc.returncode == 0, proc.stderr
    for name, extra in (("twin", []), ("capped", ["--max-terms", "40"]), ("bic", ["--k", "bic"])):
        proc = run_cli("fitgen", "fit", str(data), "-o", str(tmp_path / f"{name}.json"), "--held-out", "0", *extra)
        assert proc.returncode == 0, proc.stderr
    proc = _build_cli(str(tmp_path / "twin.json"), tmp_path / "big")
    assert_one_line_error(proc, 2, "does not fit the Uno: flash over")
    assert "no other precision or style fits: fit fewer terms than its " in proc.stderr
    assert "(fitgen fit --k bic, or --max-terms N;" in proc.stderr
    assert ("`fitgen tradeoff SENSOR --transfer gmr --scene full --core uno` ranks term caps by the estimator's "
            "flash alone, about 13-14 kB short of ReadPose's") in proc.stderr
    # the whole twin fits a Mega: said (and so it does, docs/arduino.md section 7)
    assert proc.stderr.rstrip().endswith("; or build for a board with more room: --board mega (253,952 B of flash)")
    # fitted with BIC already, and still too big: BIC is not offered again
    proc = _build_cli(str(tmp_path / "bic.json"), tmp_path / "big")
    assert_one_line_error(proc, 2, "does not fit the Uno: flash over")
    assert "(fitgen fit --max-terms N, per output;" in proc.stderr and "--k bic" not in proc.stderr
    ok = _build_cli(str(tmp_path / "capped.json"), tmp_path / "TactilePose")
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
    header = (tmp_path / "TactilePose" / "src" / "tactile" / "tm_model.h").read_text()
    assert " * Plan: for a 16-bit multiply (--target uno)" in header and "tm_avr_dot" in header


def _tree(folder):
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_a_refused_build_leaves_the_library_as_it_was_and_a_new_one_replaces_src(model_path, tmp_path):
    lib = tmp_path / "TactilePose"
    assert _build_cli(model_path, lib, "--no-build").returncode == 0
    (lib / "src" / "extra.h").write_text("/* a file the last build did not write */\n")
    before = _tree(lib)
    for extra, said in ((["--pga", "1.024"], "beyond its ADC's full scale 1.024 V (ads1115@0x48, PGA 1.024 V)"),
                        (["--sim-sensor", "nosuch"], "and --no-build runs none"),
                        (["--thermistor", "beta=3950"], "no thermistor")):
        assert_one_line_error(_build_cli(model_path, lib, "--no-build", *extra), 2, said)
        assert _tree(lib) == before
    proc = run_cli("tactile-host", "arduino-build", "--model", model_path, "--adc", TWO_CHIPS + ",temp=ads1115@0x4a:0",
                   "-o", str(lib), "--no-build")
    assert_one_line_error(proc, 2, "no thermistor")
    assert_one_line_error(run_cli("tactile-host", "arduino-build", "--model", model_path, "--adc", TWO_CHIPS, "-o", "",
                                  "--no-build", cwd=tmp_path), 2, "-o is empty")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["TactilePose"]  # nothing else, no partial folder
    assert _build_cli(model_path, lib, "--no-build").returncode == 0
    assert not (lib / "src" / "extra.h").exists() and _tree(lib) == {k: v for k, v in before.items()
                                                                      if k != "src/extra.h"}
    assert "architectures=avr\n" in (lib / "library.properties").read_text()


def test_a_ctrl_c_while_a_build_replaces_the_last_one_leaves_a_whole_library(model_path, tmp_path, monkeypatch):
    """A signal landing between two of the library's parts left a folder without library.properties (after src/
    went, before the manifest came), which the next build refused as a library it did not write."""
    import shutil
    import signal

    from fitgen.app import host_cli

    lib = tmp_path / "TactilePose"
    assert _build_cli(model_path, lib, "--no-build").returncode == 0
    (lib / "src" / "extra.h").write_text("/* a file the last build did not write */\n")
    real, removed = shutil.rmtree, []

    def rmtree(path, *args, **kwargs):
        real(path, *args, **kwargs)
        if Path(path).parent == lib:  # the last build's src/, the first part replaced
            removed.append(path)
            signal.raise_signal(signal.SIGINT)

    monkeypatch.setattr(shutil, "rmtree", rmtree)
    with pytest.raises(SystemExit) as stop:
        host_cli.main(["arduino-build", "--model", model_path, "--adc", TWO_CHIPS, "-o", str(lib), "--no-build"])
    monkeypatch.setattr(shutil, "rmtree", real)
    assert stop.value.code == 130 and len(removed) == 1
    assert not (lib / "src" / "extra.h").exists() and (lib / "src" / "tactile" / "tm_model.h").is_file()
    assert "architectures=avr\n" in (lib / "library.properties").read_text()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["TactilePose"]  # no partial folder left
    assert _build_cli(model_path, lib, "--no-build").returncode == 0


def test_a_build_too_big_for_a_smaller_avr_board_says_so_and_options_that_would_be_ignored_are_refused(
        model_path, tmp_path):
    """The manifests say architectures=avr, and the fit is checked on one board: flash or RAM past another's room
    is noted, with the option that checks it there; --style with fixed point would be ignored."""
    from host.arduino import Size, smaller_boards_note

    assert smaller_boards_note(Size(26000, 1168)) == "" and smaller_boards_note(None) == ""
    # the Leonardo's USB core is about 2.2 kB more than the Uno's: 27,348 B on the Uno was 29,550 B there
    assert smaller_boards_note(Size(27348, 1168)) == (
        "note: the build (27,348 B of flash, 1,168 B of static RAM) does not fit the Leonardo or Micro (about 29,548 B "
        "of flash there, with its core, over 28,672 B): it was checked on the Uno; give --board leonardo (or the board "
        "you flash) to check it there (fewer terms: fitgen fit --max-terms)")
    assert smaller_boards_note(Size(29984, 1168), fixed_too=True).endswith(
        "(fewer terms: fitgen fit --max-terms; or --precision fixed)")
    assert "does not fit the Nano (over 30,720 B of flash) or the Leonardo or Micro (about 33,200 B of flash there" in \
        smaller_boards_note(Size(31000, 1168))
    # built for the Mega: its 8 kB of RAM is past the others'
    said = smaller_boards_note(Size(40000, 2100), "mega")
    assert "the Uno (about 39,600 B of flash there, with its core, over 32,256 B; over 2,048 B of RAM)" in said and \
        "checked on the Mega 2560; give --board uno" in said and "the Leonardo or Micro (about 41,800 B of flash " \
        "there" in said
    assert_one_line_error(_build_cli(model_path, tmp_path / "L", "--no-build", "--precision", "fixed", "--style",
                                     "table"), 2, "--style does not apply to --precision fixed")
    assert not (tmp_path / "L").exists()
    # a 12-bit ADS7828's codes round each reading by half the noise the model was fitted for: said, as codegen
    # --input-lsb says it; the ADS1115's 16 bits, not
    proc = run_cli("tactile-host", "arduino-build", "--model", model_path, "--adc", "ads7828@0x48", "-o",
                   str(tmp_path / "A7"), "--no-build")
    assert proc.returncode == 0, proc.stderr
    assert "note: codes of 0.000806 V round each reading by 0.000233 V rms" in proc.stderr
    assert "round each reading" not in _build_cli(model_path, tmp_path / "A5", "--no-build").stderr


def test_the_config_names_each_chips_settings_in_the_maps_order(tmp_path):
    """tactile_config.h's comment gives the ADS1115s' PGA and rate once when they agree, else per chip in the map's
    order (it gave the set of them sorted as text, whichever chip each was)."""
    from host.arduino import render_config
    from host.channelmap import Settings, channel_map

    f = tmp_path / "map.toml"
    f.write_text('[[chip]]\ntype = "ads1115"\naddress = 0x48\ninputs = ["0-3"]\npga = 6.144\n'
                 '[[chip]]\ntype = "ads1115"\naddress = 0x49\ninputs = ["0-3"]\n')
    mixed = render_config(channel_map(str(f), Settings()), "float")
    assert "; ADS1115 at 0x48: PGA +-6.144 V, 860 SPS; at 0x49: PGA +-4.096 V, 860 SPS */" in mixed
    same = render_config(parse_spec(TWO_CHIPS, Settings()), "float")
    assert "; ADS1115 PGA +-4.096 V, 860 SPS */" in same


def test_a_folder_that_holds_another_library_is_refused_untouched(model_path, tmp_path):
    """The build replaces src/ and the example whole: pointed at a library it did not write (another's
    library.properties, or sources without one), it would delete that library's sources; it refuses, in one line,
    and leaves the folder as it was. Its own library it replaces."""
    other = tmp_path / "OtherLib"
    (other / "src").mkdir(parents=True)
    (other / "src" / "helper.cpp").write_text("int helper;\n")
    pio = tmp_path / "PioLib"  # PlatformIO's manifest and old-layout sources at the root, no library.properties
    pio.mkdir()
    (pio / "library.json").write_text('{"name": "OtherPio", "version": "1.0.0"}\n')
    (pio / "other.cpp").write_text("int other;\n")
    old = tmp_path / "OldLib"  # sources at the root alone
    old.mkdir()
    (old / "old.h").write_text("#define OLD 1\n")
    for folder, props in ((other, "name=OtherLib\nparagraph=Someone else's.\n"), (other, None), (pio, None),
                          (old, None)):
        if folder is other and props is None:
            (other / "library.properties").unlink()
        elif props is not None:
            (folder / "library.properties").write_text(props)
        before = _tree(folder)
        assert_one_line_error(_build_cli(model_path, folder, "--no-build"), 2,
                              f"-o {folder} holds a library arduino-build did not write")
        assert _tree(folder) == before
    ours = tmp_path / "TactilePose"
    assert _build_cli(model_path, ours, "--no-build").returncode == 0
    assert _build_cli(model_path, ours, "--no-build").returncode == 0
    # the sketchbook's libraries folder (a natural -o: "copy it into libraries/"), the sketchbook, a sketch: the
    # library landed beside the others, its src/ and examples/ read by the IDE as libraries of those names
    book = tmp_path / "Arduino"
    (book / "Blink").mkdir(parents=True)
    (book / "Blink" / "Blink.ino").write_text("void setup() {}\nvoid loop() {}\n")
    (book / "libraries" / "Foo").mkdir(parents=True)
    (book / "libraries" / "Foo" / "library.properties").write_text("name=Foo\n")
    for folder, said in ((book / "libraries", "holds libraries of its own"),
                         (book, "holds sketches and a libraries folder of its own"),
                         (book / "Blink", "is a sketch (it holds Blink.ino)")):
        before = _tree(book)
        assert_one_line_error(_build_cli(model_path, folder, "--no-build"), 2, f"-o {folder} {said}")
        assert _tree(book) == before
    assert _build_cli(model_path, book / "libraries" / "TactilePose", "--no-build").returncode == 0


def test_a_folder_name_the_ide_would_not_list_is_noted(model_path, tmp_path):
    """The library specification allows a root folder name of letters, digits, '_', '.' and '-' that starts with a
    letter or digit: another is written, and a note says the IDE will not list it and what to name it."""
    for name, noted in (("Tactile Pose", True), ("_hidden", True), ("unit-7_v1.2", False), ("TactilePose", False)):
        proc = _build_cli(model_path, tmp_path / name, "--no-build")
        assert proc.returncode == 0, proc.stderr
        assert (tmp_path / name / "src" / "TactilePose.h").is_file()
        note = [ln for ln in proc.stderr.splitlines() if ln.startswith("note:")]
        assert bool(note) == noted, (name, proc.stderr)
        if noted:
            assert note == [f"note: the folder name {name!r} is not one the Arduino library specification allows "
                            "(a letter or digit, then letters, digits, '_', '.' or '-', at most 63): the IDE will "
                            "not list it as a library; name the folder TactilePose"]


def test_double_and_bad_maps_are_refused_in_one_line(model_path, tmp_path):
    assert_one_line_error(_build_cli(model_path, tmp_path / "d", "--precision", "double"), 2, "32 bits")
    proc = run_cli("tactile-host", "arduino-build", "--model", model_path, "--adc", "ads1115@0x48:0-3",
                   "-o", str(tmp_path / "m"), "--no-build")
    assert_one_line_error(proc, 2, "the channel map reads 4 elements; the model takes 8")


def test_read_pose_notes_once_an_estimate_far_outside_the_fitted_box(tmp_path):
    """The drawing's model on a built unit: every reading inside its domain (status 0), the estimate millimetres
    off. ReadPose follows the first such row with one '# note:' line, by the header's tm_far_outside, as predict
    flags the same rows; on the drawing itself, none."""
    _require_emulator()
    import dataclasses

    from fitgen.equations.model import load_model

    fitted = load_model(_fit_cli(tmp_path, "h"))  # the default family, fitted without its held-out record
    box = {"dx": [-2, 2], "dy": [-2, 2], "dz": [-2, 0], "thx": [-5, 5], "thy": [-5, 5]}  # paper-sim's
    model = str(dataclasses.replace(fitted, fit_info={**fitted.fit_info, "held_out": {"box": box}}).save(
        tmp_path / "boxed.json"))
    proc = run_cli("fitgen", "simulate", "--sensor", "paper", "--transfer", "gmr", "--unit", "3", "--random", "1",
                   "-o", str(tmp_path / "u.csv"))
    assert proc.returncode == 0, proc.stderr
    note = ("# note: an estimate far outside the pose box the model was fitted in: another sensor than the model's? "
            "calibrate this unit (docs/calibration.md)")
    for sensor, far in ((str(tmp_path / "u.unit.toml"), True), ("paper", False)):
        proc = _build_cli(model, tmp_path / f"L{far}", "--emulate", "dx=1,dz=-1", "--sim-sensor", sensor)
        assert proc.returncode == 0, proc.stderr
        lines = proc.stdout.splitlines()
        assert lines.count(note) == int(far), proc.stdout
        rows = np.array([[float(x) for x in ln.split(",")] for ln in lines[1:] if not ln.startswith("#")])
        assert np.all(rows[:, -1] == 0)  # the domain's status sees nothing either way
        flagged = load_model(model).far_outside(rows[:, 9:14])
        assert flagged.all() if far else not flagged.any()
        if far:
            assert lines.index(note) == 2  # right after the first row, which is far already


def test_read_pose_runs_on_the_emulated_uno_and_prints_the_pose(sensor, tmp_path):
    """ReadPose, built by arduino-builder, on simavr's ATmega328P: the real Wire library talks to two ADS1115s
    of the bus model holding the paper sensor at dx=1, dz=-1. Its volts are ADS1115 codes near the sensor's
    readings there, its estimate is the Python float model's on those codes, within 0.15 mm of the pose."""
    _require_emulator()
    from fitgen.fitting.fit import fit_model
    from fitgen.physics.simulate import PAPER_GRIDS, grid_poses, simulate
    from hil.sketch import readpose_table, run_sketch

    model = fit_model(simulate(sensor, grid_poses(PAPER_GRIDS["paper-sim"])))
    cmap = parse_spec(TWO_CHIPS)
    lib = render_arduino(model, cmap, tmp_path / "TactilePose")
    size = build_example(lib, tmp_path / "build")
    run = run_sketch(example_elf(tmp_path / "build"), cmap, "dx=1,dz=-1", n_lines=6)
    names, rows = readpose_table(run.lines)
    _assert_rows_show_the_pose(names, rows)
    volts = rows[:, 1:9]
    lsb = 4.096 / 32768  # the default PGA's volts per code
    codes = np.round(volts / lsb)
    assert np.all(np.abs(codes * lsb - volts) <= 1e-6)  # whole codes, printed to the microvolt
    clean = simulate(sensor, [[*POSE, 0.0, 0.0]]).inputs[0]
    assert np.all(np.abs(volts - clean) <= 6 * sensor.noise + lsb)
    # the sketch's float inputs, code * LSB in float, through Python's emulation of the float header
    x = (codes.astype(np.float32) * np.float32(lsb)).astype(float)
    want, status = model.predict(x, with_status=True, precision="float")
    np.testing.assert_allclose(rows[:, 9:14], want, rtol=0, atol=6e-5)  # printed with 4 decimals
    assert np.all(status == 0)
    # the same from its printed lines through fitgen predict, as a user checks a device (docs/arduino.md)
    (tmp_path / "v.csv").write_text("\n".join([",".join(f"v{k}" for k in range(1, 9))]
                                              + [",".join(f"{v:.6f}" for v in row) for row in volts]) + "\n")
    proc = run_cli("fitgen", "predict", str(model.save(tmp_path / "m.json")), str(tmp_path / "v.csv"), "-o",
                   str(tmp_path / "p.csv"), "--precision", "float", "--input-lsb", repr(lsb))
    assert proc.returncode == 0, proc.stderr
    got = np.loadtxt(tmp_path / "p.csv", delimiter=",", skiprows=1)
    np.testing.assert_array_equal(got[:, :5], want)
    assert "not whole codes" not in proc.stderr
    # a tared board's volts carry the tare's offsets: rounding them to codes is not what it computed, and is said
    (tmp_path / "t.csv").write_text("\n".join([",".join(f"v{k}" for k in range(1, 9))]
                                              + [",".join(f"{v + 3.3e-5:.6f}" for v in row) for row in volts]) + "\n")
    proc = run_cli("fitgen", "predict", str(tmp_path / "m.json"), str(tmp_path / "t.csv"), "-o",
                   str(tmp_path / "p.csv"), "--precision", "float", "--input-lsb", repr(lsb))
    assert proc.returncode == 0 and "they are not whole codes (a tared ReadPose's lines" in proc.stderr, proc.stderr
    assert 100 < run.stack_peak and size.ram + run.stack_peak <= UNO.ram
    assert run.cycles > 16_000_000 * rows[-1, 0]  # the last line came after t seconds of 16 MHz cycles


def test_read_pose_on_the_nano_and_the_mega_prints_what_it_prints_on_the_uno(model_path, tmp_path):
    """--board: the Nano's build (the Uno's core, less flash) and the Mega's (an ATmega2560, run on simavr's) read
    the same simulated sensor and print the same rows as the Uno's, each checked against its own board's room;
    the Leonardo's ATmega32U4 is built and checked, not emulated, and no table build (whose stack could not be
    measured there) is offered in its place."""
    _require_emulator()
    rows, limits = {}, {"uno": (32256, 2048), "nano": (30720, 2048), "mega": (253952, 8192)}
    for board, label in (("uno", "Uno"), ("nano", "Nano"), ("mega", "Mega 2560")):
        proc = _build_cli(model_path, tmp_path / board, "--board", board, "--emulate", "dx=1,dz=-1")
        assert proc.returncode == 0, proc.stderr
        flash, ram = limits[board]
        assert re.search(rf"ReadPose for the {label}: flash \d+ of {flash} B .*, RAM \d+ \+ stack peak \d+ = \d+ of "
                         rf"{ram} B", proc.stderr), proc.stderr
        rows[board] = [ln.split(",", 1)[1] for ln in proc.stdout.splitlines()[1:] if not ln.startswith("#")]
    assert len(rows["uno"]) >= 5 and rows["nano"] == rows["uno"] and rows["mega"] == rows["uno"]
    assert_one_line_error(_build_cli(model_path, tmp_path / "L", "--board", "leonardo", "--emulate", "dx=1"), 2,
                          "the Leonardo's atmega32u4 is not emulated here")
    # the Uno's build takes its flash to the Leonardo's USB core to note it: that estimate is what building for it
    # finds, within 100 B (the core's share measured 2,196-2,202 B); a setting suggested there says its stack is
    # not measured. Compared by size, not by the note alone, so that a model near the room's edge cannot flake.
    uno = _build_cli(model_path, tmp_path / "U").stderr
    uno_flash = int(re.search(r"ReadPose for the Uno: flash (\d+) of", uno)[1])
    assert ("the Leonardo or Micro's" in uno) == (uno_flash + BOARDS["leonardo"].core_flash > 28672), uno
    proc = _build_cli(model_path, tmp_path / "L", "--board", "leonardo")
    said = proc.stderr.strip().splitlines()[0]
    leonardo_flash = int(re.search(r"the Leonardo: flash (?:over )?(\d+) of 28672 B", said)[1])  # fits or not
    assert abs(leonardo_flash - (uno_flash + BOARDS["leonardo"].core_flash)) <= 100, (uno, said)
    assert "not measured: the emulated board runs no atmega32u4" in said, said


def test_read_pose_notes_a_tare_from_another_unit(tmp_path):
    """A twin's ReadPose tared with another unit resting: the tare's line is followed by a note, as read's tare is
    (host.rest.another_unit_note), the offsets' rms as read computes it; on the twin's own unit, no note."""
    _require_emulator()
    from hil.sketch import build_readpose, run_sketch
    from host.rest import another_unit_note, model_rest

    twin = twin_and_another_unit(tmp_path)
    rest, _ = model_rest(twin)
    cmap = parse_spec(TWO_CHIPS)
    lines = {"u8": build_readpose(twin, cmap, tmp_path / "lib", "0,0,0,0,0", n_lines=3, rest=rest,
                                  sensor=str(tmp_path / "u8.unit.toml"), build_path=tmp_path / "build")[1].lines}
    lines["u7"] = run_sketch(example_elf(tmp_path / "build"), cmap, "0,0,0,0,0", n_lines=3, rest_first=True,
                             sensor=str(tmp_path / "u7.unit.toml")).lines
    notes = {k: [ln for ln in v if ln.startswith("# note:")] for k, v in lines.items()}
    assert notes["u7"] == [], lines["u7"]
    assert len(notes["u8"]) == 1 and notes["u8"][0].endswith("is this the unit the model was fitted for?"), lines
    said = next(ln for ln in lines["u8"] if ln.startswith("# tare:"))
    offsets = np.array([float(x) for x in said.split()[4:]]) * 1e-3
    python = another_unit_note(twin, offsets)
    reach = [float(t.split("offsets reach ")[1].split(" mV rms")[0]) for t in (python, notes["u8"][0])]
    assert python and abs(reach[0] - reach[1]) <= 0.1, (python, notes)


@pytest.mark.parametrize("precision", ["float", "fixed"])
def test_read_pose_tares_at_start_onto_the_models_rest(device_model, sensor, tmp_path, precision):
    """--tare: ReadPose averages 50 readings of the untouched sensor and maps them onto the model's rest, as read
    --tare does. Elements up to 30 mV off (a drift since the fit) tilt the untared estimate of a press at dx=1,
    dz=-1 by degrees; tared, it reads what the model reads from the sensor without drift (within 0.1 mm and
    1 deg: the noise), and the tare's line gives the offsets."""
    _require_emulator()
    from fitgen.fitting.fit import FitSettings, fit_model
    from fitgen.physics.simulate import grid_poses, simulate
    from hil.sketch import build_readpose, readpose_table, run_sketch
    from host.rest import model_rest

    model = device_model
    if precision == "fixed":  # fixed point takes integer powers only
        grid = {"dx": [-2, -1, 0, 1, 2], "dy": [-2, -1, 0, 1, 2], "dz": [0, -1, -2], "thx": [-5, 0, 5],
                "thy": [-5, 0, 5]}
        model = fit_model(simulate(sensor, grid_poses(grid)), settings=FitSettings.family("no-roots"))
    cmap = parse_spec(TWO_CHIPS)
    rest, onto = model_rest(model, "paper")
    assert onto == "--rest paper"
    drift = np.linspace(-0.03, 0.03, 8)  # V
    runs = {}
    for tare in (False, True):
        runs[tare] = build_readpose(model, cmap, tmp_path / f"lib{int(tare)}", "dx=1,dz=-1", precision=precision,
                                    n_lines=9, rest=rest if tare else None, build_path=tmp_path / f"build{int(tare)}",
                                    offsets=",".join(repr(float(x)) for x in drift))[1].lines
    # a 't' over Serial tares again: here while pressed, so that the rows after it read the press as rest
    again = run_sketch(example_elf(tmp_path / "build1"), cmap, "dx=1,dz=-1", n_lines=12, rest_first=True,
                       send={6: b"t"}, offsets=",".join(repr(float(x)) for x in drift)).lines
    said = [k for k, ln in enumerate(again) if ln.startswith("# tare:")]
    assert len(said) == 2 and said[0] == 0 and 6 <= said[1] < 10, again
    _, after = readpose_table([again[1], *again[said[1] + 1:]])
    at_rest = model.predict(rest[None])[0]
    assert np.all(np.abs(after[:, 9:14] - at_rest) <= [0.1, 0.1, 0.1, 1.0, 1.0]), (after[:, 9:14], at_rest)
    _, untared = readpose_table(runs[False])
    clean = model.predict(simulate(sensor, [[*POSE, 0.0, 0.0]]).inputs)[0]  # the model's own, without drift
    assert np.min(np.abs(untared[1:, 12:14] - clean[3:]).max(axis=1)) > 3  # thx or thy, deg
    said = runs[True][0]
    assert said.startswith("# tare: offsets [mV] "), runs[True]
    np.testing.assert_allclose([float(x) for x in said.split()[4:]], drift * 1e3, atol=0.2)  # noise, LSB
    names, rows = readpose_table(runs[True])
    # the simulated sensor is pressed once the header is out, at a sample's start: the first row reads the sensor
    # at rest or pressed, never half of each (it read dz +4 mm, thx -57 deg, status 0 so)
    first = rows[0, 9:14]
    assert np.all(np.abs(first - at_rest) <= [0.1, 0.1, 0.1, 1.0, 1.0]) or \
        np.all(np.abs(first - clean) <= [0.1, 0.1, 0.1, 1.0, 1.0]), (first, at_rest, clean)
    _assert_rows_show_the_pose(names, rows[1:])
    assert np.all(np.abs(rows[1:, 9:14] - clean) <= [0.1, 0.1, 0.1, 1.0, 1.0]), (rows[1:, 9:14], clean)
    if precision == "float":  # the printed (tared) volts are what the model took (printed to the microvolt)
        want = model.predict(rows[1:, 1:9].astype(np.float32).astype(float), precision="float")
        np.testing.assert_allclose(rows[1:, 9:14], want, rtol=0, atol=1e-2)
    proc = _build_cli(str(model.save(tmp_path / "m.json")), tmp_path / "TP", "--rest", "paper", "--no-build")
    assert_one_line_error(proc, contains="--rest names what --tare maps the rest readings onto: give --tare too")
    assert_one_line_error(_build_cli(str(tmp_path / "m.json"), tmp_path / "TP", "--tare", "--no-build"),
                          contains="the model records no rest readings and names no sensor file found here")


def test_ram_with_the_stack_fits_in_float_with_harmonics_and_in_fixed_without_roots(tmp_path):
    """The acceptance figures, by arduino-build --emulate: flash <= 32,256 B and static RAM plus the stack's
    peak measured on the emulated Uno <= 2,048 B for the default paper model (harmonic terms) in float, and
    for the no-roots model (138 terms) in fixed point (the uno plan); each prints the simulated pose."""
    _require_emulator()
    for name, fit_options, build_options in (("default", (), ("--precision", "float")),
                                             ("noroots", ("--family", "no-roots"), ("--precision", "fixed"))):
        model_path = _fit_cli(tmp_path, name, *fit_options)
        terms = [t for o in json.loads(open(model_path).read())["outputs"] for t in o["terms"]]
        if name == "default":
            assert any(t.startswith("h") for t in terms)  # harmonic monomials: hc1*hr, ...
        else:
            assert not any("/" in t for t in terms)
        out = tmp_path / name / "TactilePose"
        proc = _build_cli(model_path, out, "--emulate", "dx=1,dz=-1", *build_options)
        assert proc.returncode == 0, proc.stderr
        flash, ram, stack, total = map(int, RAM_STACK.search(proc.stderr).groups())
        assert flash <= UNO.flash and total == ram + stack <= UNO.ram
        assert 100 < stack < UNO.ram - ram
        from hil.sketch import readpose_table

        _assert_rows_show_the_pose(*readpose_table(proc.stdout.splitlines()))
        fixed = "#define TM_FIXED_POINT 1" in (out / "src" / "tactile" / "tm_model.h").read_text()
        assert fixed == (name == "noroots")


def test_a_table_build_whose_stack_overflows_is_refused_naming_unrolled(tmp_path):
    """The harmonic model as a table keeps its powers and harmonic monomials on the stack (about 800 B): on
    the emulated Uno the stack runs into static RAM and the program crashes, though flash and static RAM fit.
    Refused in one line, which names --style unrolled, found to fit by running it; without --emulate too (the
    stack is then measured at rest), so a plain build never suggests the table style that would crash."""
    _require_emulator()
    model_path = _fit_cli(tmp_path, "default")
    plain = _build_cli(model_path, tmp_path / "TactilePose", "--style", "table")
    assert_one_line_error(plain, 2, "and the stack ran into it")
    assert "; --style unrolled fits (" in plain.stderr and plain.stdout == ""
    proc = _build_cli(model_path, tmp_path / "TactilePose", "--style", "table", "--emulate", "dx=1,dz=-1")
    assert_one_line_error(proc, 2, "does not fit the Uno: flash ")
    assert re.search(r"RAM (\d+) of 2048 B and the stack ran into it \(all (\d+) B above it used\)", proc.stderr)
    assert not (tmp_path / "TactilePose" / "src").exists()
    named = RAM_STACK.search(proc.stderr.split("; --style unrolled fits")[-1])
    assert "; --style unrolled fits (" in proc.stderr and named, proc.stderr
    ok = _build_cli(model_path, tmp_path / "TactilePose", "--style", "unrolled", "--emulate", "dx=1,dz=-1")
    assert ok.returncode == 0, ok.stderr
    flash, ram, stack, total = map(int, RAM_STACK.search(ok.stderr).groups())
    assert (flash, ram) == (int(named[1]), int(named[2])) and abs(stack - int(named[3])) <= 32
    assert total <= UNO.ram


def test_emulate_refuses_no_build_and_a_bad_pose_in_one_line(model_path, tmp_path):
    assert_one_line_error(_build_cli(model_path, tmp_path / "a", "--emulate", "dx=1", "--no-build"), 2,
                          "not allowed with argument --emulate")
    proc = _build_cli(model_path, tmp_path / "b", "--emulate", "dq=1")
    assert_one_line_error(proc, 2, "the simulated pose 'dq=1': expected NAME=NUMBER with NAME in dx, dy, dz, thx, thy")
    assert not (tmp_path / "b").exists()  # refused before anything was written
    # a pose past any pose box: its reason, where the syntax hint had read as a typo
    assert_one_line_error(_build_cli(model_path, tmp_path / "b", "--emulate", "dx=2000"), 2,
                          "the simulated pose 'dx=2000': dx from 2000 to 2000 mm: a pose box's dx must lie within "
                          "-1000..1000 mm")


def test_a_simulated_pose_is_refused_with_parse_poses_own_reason():
    """Each of the pose parser's reasons reaches --emulate under the name it is given there; sim_pose had matched one
    reason's words and put a syntax hint in place of every other (a component given twice, a word for a number)."""
    from hil.sketch import sim_pose

    assert sim_pose("dx=1,dz=-1").tolist() == [1, 0, -1, 0, 0] and sim_pose([0, 1, 0, 0, 0]).tolist()[1] == 1
    for bad, reason in (("dx=1,dx=2", "dx is given twice"), ("dx=one", "'one' is not a number"),
                        ("1,2,3", "give 5 numbers"), ("thx=400", "thx must lie within -180..180 deg")):
        with pytest.raises(InputError, match=re.escape(f"the simulated pose {bad!r}: ")) as err:
            sim_pose(bad)
        assert reason in str(err.value) and "--simulate" not in str(err.value)


def test_an_emulated_run_says_when_the_models_own_sensor_is_not_here(model_path, tmp_path):
    """A twin whose unit file was moved away: --emulate's ReadPose read the paper drawing in its place without a
    word (then, tared, blamed the user's unit in its other-unit note), where read says so; now it says so too.
    --sim-sensor with --no-build, which runs nothing to read it, is refused rather than ignored."""
    _require_emulator()
    data = json.loads(Path(model_path).read_text())
    gone = str(tmp_path / "gone" / "unit.toml")
    data.setdefault("fit", {}).setdefault("held_out", {}).update({"sensor": "unit", "sensor_file": gone})
    twin = tmp_path / "twin.json"
    twin.write_text(json.dumps(data))
    note = (f"tactile-host arduino-build: note: the model was fitted on {gone}, not found here as it was: simulating "
            "paper; give --sim-sensor")
    proc = _build_cli(str(twin), tmp_path / "lib", "--emulate", "dx=1,dz=-1")
    assert proc.returncode == 0 and note in proc.stderr, proc.stderr
    proc = _build_cli(str(twin), tmp_path / "lib", "--emulate", "dx=1,dz=-1", "--sim-sensor", "paper")
    assert proc.returncode == 0 and "not found here" not in proc.stderr, proc.stderr
    assert "not found here" not in _build_cli(model_path, tmp_path / "own", "--emulate", "dx=1,dz=-1").stderr
    assert_one_line_error(_build_cli(str(twin), tmp_path / "nb", "--no-build", "--sim-sensor", "paper"), 2,
                          "--sim-sensor is the sensor the emulated runs read, and --no-build runs none")
    assert not (tmp_path / "nb").exists()


def test_a_four_element_model_whose_sensor_file_is_gone_names_it_before_the_build(tmp_path):
    """Its build's run at rest simulated paper's 8 elements on a map of 4, and was refused in the map's words alone,
    naming no missing file; the library is written with --no-build, which runs nothing."""
    four = tmp_path / "four.toml"
    paper = Path(__file__).resolve().parents[1] / "fitgen" / "physics" / "presets" / "paper.toml"
    four.write_text(paper.read_text().replace("count = 8", "count = 4"))
    data, model = tmp_path / "four.csv", tmp_path / "four.json"
    for argv in (("simulate", "--sensor", str(four), "--transfer", "gmr", "--random", "300", "-o", str(data)),
                 ("fit", str(data), "-o", str(model), "--family", "no-roots")):  # its held-out record names four.toml
        assert run_cli("fitgen", *argv).returncode == 0
    four.unlink()
    argv = ("tactile-host", "arduino-build", "--model", str(model), "--adc", "ads1115@0x48:0-3", "-o")
    assert_one_line_error(run_cli(*argv, str(tmp_path / "lib")), 2,
                          f"the model was fitted on {four}, not found here as it was: simulating paper; give "
                          "--sim-sensor (the sensor the build's emulated runs read, the one at rest that measures the "
                          "stack too): paper has 8 elements where the channel map reads 4")
    assert not (tmp_path / "lib").exists()
    assert run_cli(*argv, str(tmp_path / "nb"), "--no-build").returncode == 0


def test_without_arduino_builder_the_library_is_written_and_said_not_built(model_path, tmp_path, monkeypatch):
    """The build is done when arduino-builder is installed: without it the library is written and the line says it
    was not built; --emulate, which asks for a build, is refused in one line before anything is written."""
    import os
    import sys

    bindir = tmp_path / "bin"  # a PATH with python but without arduino-builder
    bindir.mkdir()
    os.symlink(sys.executable, bindir / "python3")
    monkeypatch.setenv("PATH", str(bindir))
    proc = _build_cli(model_path, tmp_path / "TactilePose")
    assert proc.returncode == 0, proc.stderr
    assert "not built (no arduino-builder)" in proc.stderr
    assert (tmp_path / "TactilePose" / "src" / "tactile" / "tm_model.h").is_file()
    proc = _build_cli(model_path, tmp_path / "E", "--emulate", "dx=1")
    assert_one_line_error(proc, 2, "arduino-builder is not installed (apt-get install")
    assert not (tmp_path / "E").exists()


def test_an_unwritable_folder_and_a_refinement_are_refused_in_one_line_up_front(sensor, tmp_path):
    from fitgen.fitting.fit import FitSettings, fit_model
    from fitgen.physics.simulate import PAPER_GRIDS, grid_poses, simulate

    refined = fit_model(simulate(sensor, grid_poses(PAPER_GRIDS["paper-sim"])),
                        settings=FitSettings.family("all", max_terms=12, refine=1, refine_terms=12), sensor=sensor)
    path = str(refined.save(tmp_path / "refined.json"))
    # /proc takes no folder (root's access() says it is writable): one line, not mkdtemp's traceback
    assert_one_line_error(_build_cli(path, "/proc/tactile-no-such", "--no-build"), 2, "/proc/tactile-no-such")
    # a refinement's solve does not fit the Uno: said before a build, as emulate --target uno says it
    proc = _build_cli(path, tmp_path / "R")
    assert_one_line_error(proc, 2, "fit without --refine")
    assert not (tmp_path / "R").exists()
    # the Mega's refusal named the Uno's target and core
    proc = _build_cli(path, tmp_path / "M", "--board", "mega")
    assert_one_line_error(proc, 2, "fit without --refine")
    assert "uno" not in proc.stderr.lower() and "ATmega328P" not in proc.stderr
    assert not (tmp_path / "M").exists()


def test_a_build_with_little_ram_above_its_stacks_peak_is_noted():
    """A fixed-point tared build on the Nano left 59 B above one run's stack peak, accepted without a word."""
    from host.arduino import Size, headroom_note

    assert headroom_note(Size(25000, 1242, stack=747), BOARDS["nano"]).startswith(
        "note: 59 B of RAM left above the stack's measured peak: it is one run's peak, not a bound")
    assert headroom_note(Size(25000, 1168, stack=463), BOARDS["uno"]) == ""
    assert headroom_note(Size(25000, 1168), BOARDS["leonardo"]) == "" and headroom_note(None, BOARDS["uno"]) == ""


def test_the_boards_are_the_installed_cores_boards_txt():
    """Each board's FQBN, flash and RAM for a sketch, and core, against Debian's arduino-core-avr (the IDE's own
    boards.txt), read here independently of host/boards.py."""
    text = (Path(HARDWARE[-1]) / "arduino" / "avr" / "boards.txt").read_text()
    props = dict(ln.split("=", 1) for ln in text.splitlines() if "=" in ln and not ln.startswith("#"))
    for key, board in BOARDS.items():
        _, _, board_id, *menu = board.fqbn.split(":")
        prefix = [board_id] + [f"menu.cpu.{m.split('=')[1]}" for m in menu]

        def get(name):  # a menu's value where it has one, else the board's
            return props.get(".".join(prefix + [name]), props.get(f"{board_id}.{name}"))

        assert (int(get("upload.maximum_size")), int(get("upload.maximum_data_size")), get("build.mcu")) == \
            (board.flash, board.ram, board.mcu), key


def test_a_size_the_link_did_not_give_is_said_plainly():
    from host.arduino import Size

    said = Size(flash=35118, ram=None, overflow=True).describe(UNO)
    assert "?" not in said and said == "flash over 35118 of 32256 B (109 %), RAM not known (the link failed first)"
    # without simavr the stack is not measured: the line says so and what it risks
    said = Size(flash=25186, ram=1167).describe(UNO)
    assert said == ("flash 25186 of 32256 B (78 %), RAM 1167 of 2048 B (57 %) before the stack (not measured: simavr "
                    "runs the sketch to measure it; a table build's may overrun the RAM)")
    # 40 B past the Nano's room read "flash 30760 of 30720 B (100 %)", its stack "not measured: simavr runs ..."
    said = Size(flash=30760, ram=1168).describe(BOARDS["nano"])
    assert said.startswith("flash over 30760 of 30720 B (100 %), RAM 1168 of 2048 B (57 %) before the stack (not "
                           "measured: it does not fit the flash, so it was not run;"), said


def test_the_build_shows_progress_on_a_terminal(device_model, tmp_path, monkeypatch):
    """A build takes 5-9 s: on a terminal a line says what is being done."""
    require_tool("arduino-builder")
    import sys

    from host.arduino import arduino_build

    term = Terminal()
    monkeypatch.setattr(sys, "stderr", term)
    monkeypatch.setenv("COLUMNS", "200")  # the whole note: on 80 columns the line is cut to the terminal's width
    size = arduino_build(device_model, parse_spec(TWO_CHIPS), tmp_path / "TactilePose", build=True)
    assert size.fits(UNO)
    assert "\rarduino-build [" in term.text and "building ReadPose (float, unrolled) with arduino-builder" in term.text


def test_help_says_the_library_reads_no_thermistor():
    """temp= and --thermistor are refused by arduino-build: its help does not offer them."""
    proc = run_cli("tactile-host", "arduino-build", "--help")
    assert proc.returncode == 0
    assert "adds a thermistor" not in proc.stdout and "--thermistor" not in proc.stdout
    assert "temp= (a thermistor) is refused" in " ".join(proc.stdout.split())


def test_the_precision_defaults_to_the_one_the_model_was_fitted_for(device_model, tmp_path):
    """A model fitted for fixed point was built in float without a word, while codegen --target uno wrote it in
    fixed point; --style, which fixed point does not take, is then refused saying how to build it in float."""
    model = json.loads(json.dumps(device_model.to_dict()))  # a copy: the fixture is the session's
    model["fit"]["precision"] = {"target": "fixed"}
    (tmp_path / "f.json").write_text(json.dumps(model))
    proc = _build_cli(str(tmp_path / "f.json"), tmp_path / "F", "--no-build")
    assert proc.returncode == 0, proc.stderr
    assert "#define TACTILE_FIXED_POINT 1" in (tmp_path / "F" / "src" / "tactile" / "tactile_config.h").read_text()
    assert_one_line_error(_build_cli(str(tmp_path / "f.json"), tmp_path / "G", "--no-build", "--style", "table"), 2,
                          "--style does not apply to --precision fixed (the model was fitted for it: give "
                          "--precision float to build it in float)")
    proc = _build_cli(str(tmp_path / "f.json"), tmp_path / "H", "--no-build", "--precision", "float")
    assert proc.returncode == 0 and "#define TACTILE_FIXED_POINT 0" in (tmp_path / "H" / "src" / "tactile" /
                                                                         "tactile_config.h").read_text()
