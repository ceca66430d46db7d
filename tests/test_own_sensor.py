"""A sensor of one's own (a file, not a preset, of other than eight elements) past the fit: the tools that simulate
its readings (read and view, arduino-build, emulate --adc) simulated the paper's eight elements unless told, so a
four-element model was refused ("the simulated sensor 'paper' has 8") and a tare rested on the paper's rest."""

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from conftest import assert_one_line_error, require_tool, run_cli, twin_and_another_unit
from fitgen.base.errors import InputError
from fitgen.physics.sensor import load_sensor

PRESET = Path(__file__).resolve().parents[1] / "fitgen" / "physics" / "presets" / "paper.toml"
ONE_CHIP = "ads1115@0x48:0-3"
POSE = (1.0, 0.0, -1.0)


@pytest.fixture(scope="module")
def four(tmp_path_factory):
    """(model, sensor file): the paper's ring with four elements, in volts, fitted on the slide scene."""
    d = tmp_path_factory.mktemp("four")
    sensor = d / "four.toml"
    sensor.write_text(PRESET.read_text().replace('name = "paper"', 'name = "four"')
                      .replace("count = 8", "count = 4").replace('kind = "raw"', 'kind = "gmr"'))
    data, model = d / "slide.csv", d / "four.json"
    for args in (("simulate", "--sensor", str(sensor), "--scene", "slide", "-o", str(data)),
                 ("fit", str(data), "-o", str(model), "--family", "all")):
        proc = run_cli("fitgen", *args)
        assert proc.returncode == 0, proc.stderr
    assert json.loads(model.read_text())["fit"]["held_out"]["sensor_file"] == str(sensor.resolve())
    return str(model), str(sensor)


def _estimates(lines: str, names=("dx", "dy", "dz")) -> np.ndarray:
    rows = [ln.split(",") for ln in lines.splitlines() if ln and ln[0] in "0123456789"]
    head = next(ln.split(",") for ln in lines.splitlines() if ln.startswith("t,"))
    return np.array([[float(r[head.index(n)]) for n in names] for r in rows])


def test_read_simulates_and_tares_onto_the_models_own_sensor(four):
    model, _ = four
    proc = run_cli("tactile-host", "read", "--model", model, "--adc", ONE_CHIP, "--simulate", "dx=1,dz=-1",
                   "--tare", "--count", "20")
    assert proc.returncode == 0, proc.stderr
    est = _estimates(proc.stdout)
    assert len(est) == 20 and np.all(np.abs(est - POSE) < 0.05), est
    # told another sensor, it is that one: the paper's eight elements against a map of four
    proc = run_cli("tactile-host", "read", "--model", model, "--adc", ONE_CHIP, "--simulate", "dx=1,dz=-1",
                   "--count", "3", "--sensor", "paper")
    assert proc.returncode == 2 and "the simulated sensor 'paper' has 8" in proc.stderr, proc.stderr


def test_arduino_build_measures_its_stack_on_the_models_own_sensor(four, tmp_path):
    for tool in ("arduino-builder", "avr-size", "avr-nm", "gcc", "pkg-config"):
        require_tool(tool)
    model, _ = four
    proc = run_cli("tactile-host", "arduino-build", "--model", model, "--adc", ONE_CHIP, "-o",
                   str(tmp_path / "TactilePose"), "--emulate", "dx=1,dz=-1")
    assert proc.returncode == 0, proc.stderr
    est = _estimates(proc.stdout)
    assert len(est) >= 3 and np.all(np.abs(est - POSE) < 0.05), proc.stdout
    # its manifest counts the model's elements, not the paper's eight
    assert "sentence=Pose of a magnetic tactile sensor from 4 GMR elements read by" in \
        (tmp_path / "TactilePose" / "library.properties").read_text()


def test_emulate_reads_the_models_own_sensor_over_i2c(four):
    require_tool("gcc")
    model, _ = four
    proc = run_cli("tactile-hil", "emulate", "--model", model, "--target", "host", "--adc", ONE_CHIP,
                   "--simulate", "dx=1,dz=-1", "--suite", "--vectors", "50", "--fuzz", "100")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "| stream | pass |" in proc.stdout and "sensor four" in proc.stdout, proc.stdout


def test_a_twin_copied_alone_tares_onto_the_rest_it_recorded(tmp_path):
    """A twin's model copied to a Pi without its unit file: the tare rested on the drawing's rest (--sensor's
    default), and was refused or bent every estimate. The model records its sensor's rest readings and a tare with
    no file to rest on takes them."""
    from fitgen.equations.model import load_model
    from fitgen.physics.sensor import load_sensor
    from fitgen.physics.transfer import readings

    data, unit, model = tmp_path / "u.csv", tmp_path / "u.unit.toml", tmp_path / "twin.json"
    for args in (("simulate", "--sensor", "paper", "--unit", "3", "--transfer", "gmr", "--scene", "slide", "-o",
                  str(data)), ("fit", str(data), "-o", str(model), "--family", "all")):
        proc = run_cli("fitgen", *args)
        assert proc.returncode == 0, proc.stderr
    own_rest = readings(load_sensor(str(unit)).with_transfer("gmr"), np.zeros(5), adc_bits=0)[0]
    np.testing.assert_array_equal(load_model(model).held_out_rest, own_rest)
    # its unit file here: the tare rests on it, named as the model's, not as a --sensor no one typed
    proc = run_cli("tactile-host", "read", "--model", str(model), "--adc", "ads1115@0x48:0-3,ads1115@0x49:0-3",
                   "--simulate", "0,0,0,0,0", "--tare", "--tare-samples", "64", "--count", "2")
    line = next(ln for ln in proc.stderr.splitlines() if "tare: offsets" in ln)
    assert proc.returncode == 0 and line.endswith(f"onto the rest readings of {unit.resolve()} (the model's)"), line
    unit.rename(tmp_path / "elsewhere.toml")  # not on the Pi
    proc = run_cli("tactile-host", "read", "--model", str(model), "--adc", "ads1115@0x48:0-3,ads1115@0x49:0-3",
                   "--simulate", "0,0,0,0,0", "--tare", "--tare-samples", "64", "--count", "2")
    assert proc.returncode == 0, proc.stderr
    line = next(ln for ln in proc.stderr.splitlines() if "tare: offsets" in ln)
    assert line.endswith("onto the rest readings of the model's own record"), line
    # the simulated sensor is the drawing (no file says otherwise): the offsets are the drawing's rest less the unit's
    paper_rest = readings(load_sensor("paper").with_transfer("gmr"), np.zeros(5), adc_bits=0)[0]
    offsets = np.array([float(x) for x in line.split("[mV] ")[1].split(" (")[0].split()])
    np.testing.assert_allclose(offsets, (paper_rest - own_rest) * 1e3, atol=0.3)
    assert np.abs(offsets).max() > 3  # a unit's rest is not the drawing's: the test tells them apart
    # ... which is another sensor than the twin's unit: said, though the unit file is not at hand (the model records
    # how far units' rest readings spread)
    assert "note: the tare's offsets reach" in proc.stderr and "is this the unit the model was fitted for?" in proc.stderr


def test_a_tare_onto_a_twin_from_another_unit_is_said(tmp_path):
    """A twin's tare with another unit resting on the bus: the offsets took up that unit's rest in silence, and its
    estimates erred by a millimetre. The model records how far the rest readings of units built to its drawing
    spread; offsets past a quarter of that are noted, a unit's own temperature drift of 10 degC is not."""
    from fitgen.fitting.holdout import rest_spread
    from fitgen.physics.transfer import readings

    twin = twin_and_another_unit(tmp_path)
    spread = twin.held_out_rest_spread
    # what the record says of units matches units simulate draws within the drawing's tolerances
    drawn = []
    for seed in range(20, 36):
        assert run_cli("fitgen", "simulate", "--sensor", "paper", "--unit", str(seed), "--transfer", "gmr", "--grid",
                       "dz=0", "-o", str(tmp_path / f"d{seed}.csv")).returncode == 0
        drawn.append(readings(load_sensor(str(tmp_path / f"d{seed}.unit.toml")).with_transfer("gmr"), np.zeros(5),
                              adc_bits=0)[0])
    assert 0.7 < np.sqrt(np.mean(np.var(drawn, axis=0))) / np.sqrt(np.mean(spread ** 2)) < 1.4
    said = []
    for unit, drift in (("u8", "ramp=0,start=25"), ("u7", "ramp=0,start=35"), ("u7", "ramp=0,start=25")):
        proc = run_cli("tactile-host", "read", "--model", str(tmp_path / "twin.json"), "--adc",
                       "ads1115@0x48:0-3,ads1115@0x49:0-3", "--sensor", str(tmp_path / f"{unit}.unit.toml"), "--rest",
                       str(tmp_path / "u7.unit.toml"), "--simulate", "0,0,0,0,0", "--sim-drift", drift, "--tare",
                       "--count", "1")
        assert proc.returncode == 0, proc.stderr
        said.append("is this the unit the model was fitted for?" in proc.stderr)
    assert said == [True, False, False]
    # a drawing's model records no spread: a unit's rest off the drawing's is what its tare is for
    assert rest_spread(load_sensor("paper").with_transfer("gmr")) is None


def test_identify_takes_the_drawing_the_capture_was_scheduled_for(tmp_path):
    """A drawing of one's own through schedule and capture: identify defaulted to paper, and refused the capture as
    'a unit far outside paper's tolerances'. The schedule records its drawing, the capture passes it on, and identify
    takes it unless told; told another, or with the file changed since, it says so."""
    drawing = tmp_path / "r9.toml"
    drawing.write_text(PRESET.read_text().replace('name = "paper"', 'name = "r9"')
                       .replace("radius = 10.0 ", "radius = 9.0 ").replace('kind = "raw"', 'kind = "gmr"'))
    sched, units, cap = tmp_path / "s.csv", tmp_path / "u.csv", tmp_path / "c.csv"
    for tool, *args in (("fitgen", "schedule", "--sensor", str(drawing), "--n", "40", "-o", str(sched)),
                        ("fitgen", "simulate", "--sensor", str(drawing), "--unit", "2", "--random", "3", "-o",
                         str(units)),
                        ("tactile-host", "capture", "--poses", str(sched), "--adc", "ads1115@0x48:0-3,ads1115@0x49:0-3",
                         "--sensor", str(tmp_path / "u.unit.toml"), "--simulate", "-o", str(cap))):
        proc = run_cli(tool, *args)
        assert proc.returncode == 0, proc.stderr
    made = json.loads((tmp_path / "c.csv.meta.json").read_text())["schedule_drawing"]
    assert made["sensor"] == "r9" and made["sensor_file"] == str(drawing.resolve())
    proc = run_cli("fitgen", "identify", str(cap), "-o", str(tmp_path / "unit.toml"))
    assert proc.returncode == 0, proc.stderr
    assert f"the drawing: {drawing.resolve()}, as the capture's schedule names it" in proc.stderr
    unit = (tmp_path / "unit.toml").read_text()
    assert 'drawing = "r9"' in unit and f'drawing_spec = "{drawing.resolve()}"' in unit, unit
    # -o onto the drawing taken from the record (no option names it), or onto a copy of a drawing: refused, kept
    copy = tmp_path / "copy.toml"
    shutil.copy(drawing, copy)
    before = drawing.read_text()
    for out, said in ((drawing, f"-o {drawing} is the drawing identify reads"),
                      (copy, f"-o {copy} is a drawing (sensor r9, no unit's traits): writing the unit there would "
                       "destroy it")):
        assert_one_line_error(run_cli("fitgen", "identify", str(cap), "-o", str(out)), 2, said)
        assert out.read_text() == before
    # the posterior beside the unit file over a model or a capture of its name: refused, kept (it was replaced)
    (tmp_path / "m.posterior.json").write_text('{"schema_version": 1, "inputs": ["v1"], "outputs": {}}')
    shutil.copy(cap, tmp_path / "k.posterior.json")
    shutil.copy(f"{cap}.meta.json", tmp_path / "k.posterior.json.meta.json")
    for stem, said in (("m", "a model: identify would write a unit's posterior over it"),
                       ("k", "a capture (rows measured on the sensor, as its meta says): identify would write over")):
        kept = (tmp_path / f"{stem}.posterior.json").read_text()
        assert_one_line_error(run_cli("fitgen", "identify", str(cap), "-o", str(tmp_path / f"{stem}.toml")), 2,
                              f"-o {tmp_path / stem}.toml writes the unit's posterior beside it, to "
                              f"{tmp_path / stem}.posterior.json, which is {said}")
        assert (tmp_path / f"{stem}.posterior.json").read_text() == kept and not (tmp_path / f"{stem}.toml").exists()
    proc = run_cli("fitgen", "identify", str(cap), "-o", str(tmp_path / "p.toml"), "--sensor", "paper")
    assert proc.returncode == 2 and f"note: the capture's schedule was made for {drawing.resolve()}; identifying " \
        "against --sensor paper" in proc.stderr, proc.stderr
    # a built unit where the drawing belongs: its one line, without the note on a --sensor other than the schedule's
    assert run_cli("fitgen", "simulate", "--sensor", "paper", "--unit", "1", "--grid", "dx=0", "-o",
                   str(tmp_path / "u1.csv")).returncode == 0
    assert_one_line_error(run_cli("fitgen", "identify", str(cap), "-o", str(tmp_path / "q.toml"), "--sensor",
                                  str(tmp_path / "u1.unit.toml")), 2, "is a built unit, not a drawing")
    # the capture moved to another folder with the drawing's file (captured on a Pi, identified on a laptop): the
    # file beside it taken, as the same hash; it had been identified against paper, noted in one line
    moved = tmp_path / "laptop"
    moved.mkdir()
    for f in (drawing, cap, Path(f"{cap}.meta.json")):
        shutil.copy(f, moved / f.name)
    drawing.rename(tmp_path / "elsewhere.toml")
    proc = run_cli("fitgen", "identify", str(moved / cap.name), "-o", str(moved / "unit.toml"))
    assert proc.returncode == 0, proc.stderr
    assert f"the drawing: {moved / drawing.name}, as the capture's schedule names it" in proc.stderr
    assert f'drawing_spec = "{moved / drawing.name}"' in (moved / "unit.toml").read_text()
    np.testing.assert_array_equal(load_sensor(moved / "unit.toml").positions, load_sensor(tmp_path / "unit.toml").positions)
    # its file changed since (or not found): refused, naming it; against paper the unit would be as far off as the
    # drawings are (r9 against paper is refused as unexplained, a 9.7 mm ring had been taken)
    (tmp_path / "elsewhere.toml").rename(drawing)
    drawing.write_text(drawing.read_text().replace("radius = 9.0 ", "radius = 9.5 "))
    (moved / drawing.name).unlink()
    assert_one_line_error(run_cli("fitgen", "identify", str(cap), "-o", str(tmp_path / "q.toml")), 2,
                          f"the capture's schedule was made for sensor r9 ({drawing.resolve()}), whose file is not here "
                          "as it was (moved without the capture, or changed since): give the drawing the unit was "
                          "built to as --sensor; nothing written")
    assert not (tmp_path / "q.toml").exists()
    # a check schedule records its drawing's file too, so a simulated check capture simulates that drawing
    proc = run_cli("fitgen", "schedule", "--sensor", str(drawing), "--check", "12", "-o", str(tmp_path / "cp.csv"))
    assert proc.returncode == 0, proc.stderr
    assert json.loads((tmp_path / "cp.csv.meta.json").read_text())["sensor_file"] == str(drawing.resolve())


def test_a_simulated_capture_simulates_the_drawing_its_schedule_was_made_for(four, tmp_path):
    """`capture --simulate` without --sensor simulated the paper's eight elements, so a schedule of a four-element
    layout was refused ('the simulated sensor paper has 8')."""
    _, sensor = four
    sched, cap = tmp_path / "s.csv", tmp_path / "c.csv"
    proc = run_cli("fitgen", "schedule", "--sensor", sensor, "--n", "12", "-o", str(sched))
    assert proc.returncode == 0, proc.stderr
    proc = run_cli("tactile-host", "capture", "--poses", str(sched), "--adc", ONE_CHIP, "--simulate", "-o", str(cap))
    assert proc.returncode == 0, proc.stderr
    meta = json.loads((tmp_path / "c.csv.meta.json").read_text())
    assert meta["source"] == f"simulated {Path(sensor).resolve()}" and meta["schedule_drawing"]["sensor"] == "four"


def test_fixed_point_takes_the_adc_of_the_models_own_sensor_file(tmp_path):
    """A file with an Uno's ADC (10 bits over 0..5 V): the fit held its fixed-point figures out at those codes, and
    codegen, predict and verify took the paper's 16-bit ADC over 0..3.3 V unless given --input-lsb, so the header
    clamped every 10-bit code a user fed it. They take the file's ADC now; a file changed since is not guessed."""
    sensor = tmp_path / "uno.toml"
    sensor.write_text(PRESET.read_text().replace('name = "paper"', 'name = "uno"').replace('kind = "raw"', 'kind = "gmr"')
                      .replace("adc_max = 3.3 ", "adc_max = 5.0 ").replace("adc_bits = 16 ", "adc_bits = 10 ")
                      .replace("noise = 0.0005        # V", "noise = 0.003        # V"))
    data, model = tmp_path / "slide.csv", tmp_path / "uno.json"
    for args in (("simulate", "--sensor", str(sensor), "--scene", "slide", "-o", str(data)),
                 ("fit", str(data), "-o", str(model), "--precision", "fixed")):
        proc = run_cli("fitgen", *args)
        assert proc.returncode == 0, proc.stderr
    lsb = 5.0 / 1023
    proc = run_cli("fitgen", "codegen", str(model), "--precision", "fixed", "-o", str(tmp_path / "c"))
    assert proc.returncode == 0, proc.stderr
    assert f"input LSB {lsb:g} V from sensor {sensor.resolve()} (gmr: 10-bit codes over 0..5 V" in proc.stderr
    define = next(ln for ln in (tmp_path / "c" / "tm_model.h").read_text().splitlines() if ln.startswith("#define TM_INPUT_LSB "))
    assert float(define.split()[-1]) == lsb
    proc = run_cli("fitgen", "predict", str(model), str(data), "--precision", "fixed", "-o", str(tmp_path / "p.csv"))
    assert proc.returncode == 0 and f"input LSB {lsb:g} V from sensor {sensor.resolve()}" in proc.stderr, proc.stderr
    assert "clamped" not in proc.stderr
    # the ADC the fit counted gets no word on its rounding; a coarser one does
    for given, said in ((f"{lsb:.6f}", False), (f"{2 * lsb:.6f}", True)):
        proc = run_cli("fitgen", "codegen", str(model), "--precision", "fixed", "--input-lsb", given, "-o",
                       str(tmp_path / "d"))
        assert proc.returncode == 0 and ("neither the fit nor the model file's figures count it" in proc.stderr) == said
    sensor.write_text(sensor.read_text().replace("adc_bits = 10 ", "adc_bits = 12 "))
    assert_one_line_error(run_cli("fitgen", "codegen", str(model), "--precision", "fixed", "-o", str(tmp_path / "e")),
                          2, f"the model was fitted on sensor {sensor.resolve()}, not found here as it was; give "
                          "--input-lsb (in V)")


def test_a_schedules_preset_drawn_otherwise_is_noted_and_a_file_of_its_name_refused(tmp_path):
    """A schedule made for the preset by another fitgen (its hash not this one's): identified against this one's,
    noted. A file named like the preset, gone since: refused as any drawing's file, not taken for the preset."""
    from fitgen.fitting.unitrecord import drawing_for

    made = {"sensor": "paper", "sensor_sha256": "0" * 64, "transfer": "gmr"}
    spec, said = drawing_for(None, {"schedule_drawing": made}, "c.csv")
    assert spec == "paper" and said == ("note: the capture's schedule was made for preset paper as another fitgen "
                                        "drew it; identifying against this one's (--sensor to say which)")
    gone = {**made, "sensor_file": str(tmp_path / "paper.toml")}
    with pytest.raises(InputError, match=r"^the capture's schedule was made for sensor paper \(.*paper\.toml\), whose "
                                         r"file is not here as it was"):
        drawing_for(None, {"schedule_drawing": gone}, "c.csv")
