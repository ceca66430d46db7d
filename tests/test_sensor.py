import math
import re

import numpy as np
import pytest

from fitgen.base.errors import InputError
from fitgen.base.texts import tomllib
from fitgen.physics.sensor import load_sensor, parse_sensor, preset_names
from importlib import resources

from conftest import assert_one_line_error, run_cli


def paper_dict_text():
    return resources.files("fitgen.physics.presets").joinpath("paper.toml").read_text()


def paper_dict():
    return tomllib.loads(resources.files("fitgen.physics.presets").joinpath("paper.toml").read_text())


def test_paper_preset_matches_conventions():
    s = load_sensor("paper")
    assert s.magnet.diameter == 6.0 and s.magnet.height == 1.0 and s.magnet.polarization == 1.32
    # magnet bottom 11.0 above the board top, elements on the 1.5 mm board's bottom face
    assert s.magnet.rest_center == (0.0, 0.0, 13.0)
    assert s.n_elements == 8
    for k in range(8):
        phi = math.radians(45 * k)
        np.testing.assert_allclose(s.positions[k], [10 * math.cos(phi), 10 * math.sin(phi), 0.0], atol=1e-12)
        np.testing.assert_allclose(s.axes[k], [math.cos(phi), math.sin(phi), 0.0], atol=1e-12)
    assert s.transfer == "raw" and s.units == "mT"
    assert "paper" in preset_names()


def test_hash_is_stable_and_sensitive():
    a, b = load_sensor("paper"), load_sensor("paper")
    assert a.sha256 == b.sha256
    d = paper_dict()
    d["magnet"]["polarization"] = 1.2
    assert parse_sensor(d).sha256 != a.sha256


@pytest.mark.parametrize(
    "mutate, key",
    [
        (lambda d: d["magnet"].__setitem__("diamter", 6.0), "magnet.diamter"),
        (lambda d: d["magnet"].pop("height"), "magnet.height"),
        (lambda d: d["magnet"].__setitem__("diameter", -6.0), "magnet.diameter"),
        (lambda d: d["board"].__setitem__("gap", 0), "board.gap"),
        (lambda d: d["elements"]["ring"][0].__setitem__("radius", "ten"), "elements.ring[0].radius"),
        (lambda d: d["elements"]["ring"][0].__setitem__("axis", "sideways"), "elements.ring[0].axis"),
        (lambda d: d["transfer"]["gmr"].__setitem__("adc_max", -1.0), "adc_max"),
        # volts past any amplifier's: the ADC's step overflowed downstream
        (lambda d: d["transfer"]["gmr"].__setitem__("adc_max", 1e308), "'transfer.gmr.adc_max' must be <= 100"),
        (lambda d: d["transfer"]["gmr"].__setitem__("adc_min", -1e308), "'transfer.gmr.adc_min' must be >= -100"),
        (lambda d: d["transfer"]["gmr"].__setitem__("offset", 1e300), "'transfer.gmr.offset' must be <= 100"),
        # a noise no sensor has: simulate wrote rows with it, and the fit then refused them
        (lambda d: d["transfer"]["gmr"].__setitem__("noise", 1e308), "'transfer.gmr.noise' must be <= 1000"),
        (lambda d: d["transfer"].setdefault("raw", {}).__setitem__("noise", 1e308),
         "'transfer.raw.noise' must be <= 1000"),
        # lengths and a polarization past any sensor's: observe's SVD failed in a traceback on z = 1e200
        (lambda d: d["elements"]["ring"][0].__setitem__("z", 1e200), "the elements' places must be within +-1000 mm"),
        (lambda d: d["elements"]["ring"][0].__setitem__("radius", 1e308), "must be within +-1000 mm, got 1e+308"),
        (lambda d: d["magnet"].__setitem__("polarization", 1e30), "'magnet.polarization' must be within +-10 T"),
        # and below any sensor's: observe's field overflowed (numpy's warnings, then SVD's LinAlgError traceback) on a
        # magnet 1e-300 mm across; the others gave readings of 1e-300, on a rail, or that never change
        (lambda d: d["magnet"].__setitem__("diameter", 1e-300), "'magnet.diameter' must be >= 0.001, got 1e-300"),
        (lambda d: d["magnet"].__setitem__("height", 1e-300), "'magnet.height' must be >= 0.001"),
        (lambda d: d.setdefault("stage", {}).__setitem__("map", [[1e308, 0, 0], [0, 1, 0], [0, 0, 1]]),
         "'stage.map' must be within +-10, got 1e+308"),
        (lambda d: d.setdefault("ambient", {}).__setitem__("field", [1e308, 0, 0]),
         "'ambient.field' must be within +-1000 mT"),
        (lambda d: d["transfer"]["gmr"].__setitem__("supply", 1e308), "'transfer.gmr.supply' must be <= 100"),
        (lambda d: d["transfer"]["gmr"].__setitem__("sensitivity", 1e308), "'transfer.gmr.sensitivity' must be <="),
        (lambda d: d["transfer"]["gmr"].__setitem__("saturation", 1e-300), "'transfer.gmr.saturation' must be >="),
        (lambda d: d["transfer"]["gmr"].__setitem__("adc_max", 1e-300), "must be at least 0.001 V above"),
        # TOML integers past float's range: math.isfinite raised OverflowError, a traceback
        (lambda d: d["magnet"].__setitem__("polarization", 10 ** 400), "'magnet.polarization' must be a finite"),
        (lambda d: d["travel"].__setitem__("dz", [-10 ** 400, 0]), "'travel.dz' must be a list of 2 finite numbers"),
        (lambda d: d["magnet"].__setitem__("offset", [0, 0, 10 ** 400]), "'magnet.offset' must be a list of 3"),
        (lambda d: d["elements"]["ring"][0].__setitem__("elevation", 95.0), "elements.ring[0].elevation"),
        (lambda d: d["elements"]["ring"][0].update(axis="z", elevation=10.0), "elements.ring[0].elevation"),
        (lambda d: d.__setitem__("colour", "red"), "colour"),
        (lambda d: d["transfer"].__setitem__("kind", "hall"), "transfer.kind"),
        # a misspelt required key: said missing, with the misspelling (it was "must be a whole number, got None")
        (lambda d: d["elements"]["ring"][0].__setitem__("cont", d["elements"]["ring"][0].pop("count")),
         "missing key 'elements.ring[0].count' (is 'elements.ring[0].cont' a misspelling of it?)"),
        (lambda d: d["magnet"].__setitem__("hieght", d["magnet"].pop("height")),
         "missing key 'magnet.height' (is 'magnet.hieght' a misspelling of it?)"),
        # [travel]: per stage axis [lo, hi] mm from first contact, 0 between them; dz never above the skin
        (lambda d: d["travel"].__setitem__("dx", [3.0, -3.0]), "'travel.dx' must be [lo, hi]"),
        (lambda d: d["travel"].__setitem__("dx", [1.0, 3.0]), "'travel.dx' must be [lo, hi]"),
        (lambda d: d["travel"].__setitem__("dy", [-30.0, 3.0]), "both within 20 mm"),
        (lambda d: d["travel"].__setitem__("dy", [-3.0]), "'travel.dy' must be a list of 2 finite numbers"),
        (lambda d: d["travel"].__setitem__("dz", [-3.0, 0.5]), "'travel.dz' must lie within (-11, 0] mm"),
        (lambda d: d["travel"].__setitem__("dz", [-11.0, 0.0]), "at -11 the magnet meets the board"),
        (lambda d: d["travel"].__setitem__("thx", [-5.0, 5.0]), "unknown key 'travel.thx'"),
    ],
)
def test_bad_sensor_files_name_the_key(mutate, key):
    d = paper_dict()
    mutate(d)
    with pytest.raises(InputError, match=re.escape(key)):
        parse_sensor(d)


def test_element_inside_magnet_is_rejected():
    d = paper_dict()
    d["elements"]["list"] = [{"position": [0.0, 0.0, 13.2], "axis": [0, 0, 1]}]
    with pytest.raises(InputError, match="element 9 .* inside the magnet"):
        parse_sensor(d)


def test_explicit_elements_and_rings_combine():
    d = paper_dict()
    d["elements"]["ring"].append({"count": 4, "radius": 5.0, "z": 2.0, "axis": "z"})
    d["elements"]["list"] = [{"position": [1.0, 2.0, 0.0], "axis": [0, 3, 4]}]
    s = parse_sensor(d)
    assert s.n_elements == 13
    np.testing.assert_allclose(s.axes[-1], [0, 0.6, 0.8])
    np.testing.assert_allclose(s.axes[8:12], np.tile([0, 0, 1.0], (4, 1)))


@pytest.mark.parametrize("scale", [1e308, 1e-320])
def test_an_axis_written_near_floats_limits_is_the_direction_it_names(scale):
    """[1e308, 1e308, 0]'s norm overflowed (numpy's warning) and the element's axis read as zeros: a dead element
    without a word; [1e-320, ..]'s underflowed."""
    d = paper_dict()
    d["elements"]["list"] = [{"position": [1.0, 2.0, 0.0], "axis": [scale, scale, 0.0]}]
    with np.errstate(all="raise"):
        s = parse_sensor(d)
    np.testing.assert_allclose(s.axes[-1], [math.sqrt(0.5), math.sqrt(0.5), 0.0], rtol=1e-15)


def test_a_ring_start_of_many_turns_is_the_angle_it_names():
    """start = 1e308 left every element at the first's place (1e308 + 45 deg is 1e308), refused as elements sharing
    a position; a start of whole turns more is the same ring."""
    d = paper_dict()
    ring = d["elements"]["ring"][0]
    base = parse_sensor(d)
    for start in (360.0 * 3 + ring.get("start", 0.0), 1e308):
        d["elements"]["ring"][0] = {**ring, "start": start}
        s = parse_sensor(d)
        if start < 1e300:
            np.testing.assert_allclose(s.positions, base.positions, atol=1e-12)
        assert len({tuple(np.round(p, 9)) for p in s.positions}) == s.n_elements
        phi = np.degrees(np.arctan2(s.positions[:8, 1], s.positions[:8, 0]))
        np.testing.assert_allclose(np.diff(np.unwrap(np.radians(phi))), np.radians(45.0), atol=1e-12)


def test_elevation_raises_a_ring_axis_toward_the_normal():
    d = paper_dict()
    d["elements"]["ring"] = [{"count": 4, "radius": 10.0, "axis": "radial", "elevation": 30.0},
                             {"count": 4, "radius": 10.0, "start": 45.0, "axis": "tangential", "elevation": -90.0}]
    s = parse_sensor(d)
    phi = np.radians([0.0, 90.0, 180.0, 270.0])
    c = math.cos(math.radians(30.0))
    np.testing.assert_allclose(s.axes[:4], np.column_stack([c * np.cos(phi), c * np.sin(phi), np.full(4, 0.5)]),
                               atol=1e-15)
    np.testing.assert_allclose(s.axes[4:], np.tile([0.0, 0.0, -1.0], (4, 1)), atol=1e-15)  # straight down
    d["elements"]["ring"][0]["elevation"] = 0.0
    np.testing.assert_array_equal(parse_sensor(d).axes[:4], load_sensor("paper").axes[::2])


def test_bad_sensor_file_cli(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("name = 'x'\n[magnet]\ndiameter = -1\nheight = 1\n")
    proc = run_cli("fitgen", "simulate", "--sensor", str(bad), "-o", str(tmp_path / "o.csv"))
    assert_one_line_error(proc, contains="magnet.diameter")
    assert not (tmp_path / "o.csv").exists()
    bad.write_text("this is = = not toml")
    assert_one_line_error(run_cli("fitgen", "observe", str(bad)), contains="not valid TOML")
    # a model or a dataset given for the sensor: named as what it is
    # a TOML file with a bracket dropped had been named JSON, the parser's line and column lost
    for text, said in (('{"schema_version": 1}\n', "JSON (a model or meta file?), not a sensor file (TOML)"),
                       ('[1, 2]\n', "JSON (a model or meta file?), not a sensor file (TOML)"),
                       ("v1,v2,dz\n1,2,3\n", "CSV (a dataset?), not a sensor file (TOML)"),
                       ('[magnet\ndiameter = 1\n', "not valid TOML: Expected ']' at the end of a table declaration "
                                                   "(at line 1, column 8)"),
                       ('name = "x"\n[magnet]\noffset = [0, 0\n', "not valid TOML: ")):
        bad.write_text(text)
        assert_one_line_error(run_cli("fitgen", "observe", str(bad)), contains=f"sensor file {bad}: {said}")
    assert_one_line_error(run_cli("fitgen", "observe", "--sensor", "nope"), contains="not a preset")
    assert_one_line_error(run_cli("fitgen", "observe", "--sensor", str(tmp_path)),
                          contains=f"sensor {str(tmp_path)!r}: a folder, not a sensor file")


def test_a_toml_file_holding_an_integer_of_too_many_digits_is_refused_in_one_line(tmp_path):
    """tomllib raises a plain ValueError, not its TOMLDecodeError, for an integer past the 4,300 digits Python
    converts: the sensor, scene and channel map loaders had let it through as a traceback. One just short of the
    limit reads, and is said cut short."""
    from host.channelmap import load_map_file

    too_many, many = "1" + "0" * 5000, "1" + "0" * 4000
    sensor = tmp_path / "s.toml"
    sensor.write_text(paper_dict_text().replace("diameter = 6.0", f"diameter = {too_many}", 1))
    assert_one_line_error(run_cli("fitgen", "observe", "--sensor", str(sensor)),
                          contains=f"sensor file {sensor}: not valid TOML: Exceeds the limit (4300 digits)")
    sensor.write_text(paper_dict_text().replace("diameter = 6.0", f"diameter = {many}", 1))
    proc = run_cli("fitgen", "observe", "--sensor", str(sensor))
    assert_one_line_error(proc, contains="'magnet.diameter' must be a finite number, got 1000000")
    assert proc.stderr.rstrip().endswith("got 1" + "0" * 56 + "..."), proc.stderr  # 60 characters, not 4,001
    scene = tmp_path / "scene.toml"
    scene.write_text(f'name = "x"\noutputs = ["dz"]\nlevels = {too_many}\n')
    assert_one_line_error(run_cli("fitgen", "observe", "--scene", str(scene)),
                          contains=f"scene file {scene}: not valid TOML: Exceeds the limit (4300 digits)")
    cmap = tmp_path / "map.toml"
    cmap.write_text(f"bus = {too_many}\n")
    with pytest.raises(InputError, match="channel map .*: not valid TOML: Exceeds the limit"):
        load_map_file(cmap)
    cmap.write_text(f'bus = -{many}\n[[chip]]\ntype = "ads1115"\naddress = 0x48\n')
    with pytest.raises(InputError, match=r"bus must be a whole number 0\.\.1048575 \(/dev/i2c-N\), "
                                         r"got -1000+\.\.\.$"):
        load_map_file(cmap)
    cmap.write_text(f'[temperature]\ninput = "ads1115@0x4a:0"\nbeta = {many}\n[[chip]]\ntype = "ads1115"\naddress = 0x48\n')
    with pytest.raises(InputError, match="beta, r25, series and vref must be finite numbers > 0"):  # OverflowError
        load_map_file(cmap)
    # a model or a dataset given for a scene: named as for a sensor
    scene.write_text('{"schema_version": 1}\n')
    assert_one_line_error(run_cli("fitgen", "observe", "--scene", str(scene)),
                          contains=f"scene file {scene}: JSON (a model or meta file?), not a scene file (TOML)")


def test_travel_is_read_written_and_left_out_of_the_hash(tmp_path):
    """[travel] says where a capture may move the skin: a unit's file keeps it (a twin schedules as its drawing
    does), and, being no physics, it leaves the sensor's hash as it is."""
    from fitgen.physics.units import draw_unit, write_unit

    paper = load_sensor("paper")
    assert paper.travel == {"dx": (-3.0, 3.0), "dy": (-3.0, 3.0), "dz": (-3.0, 0.0)}
    d = paper_dict()
    d["travel"] = {"dz": [-1.5, 0.0]}
    narrow = parse_sensor(d)
    assert narrow.travel == {"dz": (-1.5, 0.0)} and narrow.sha256 == paper.sha256
    del d["travel"]
    assert parse_sensor(d).travel == {}
    unit, _ = draw_unit(narrow, 3)
    back = load_sensor(write_unit(tmp_path / "u.toml", unit, "paper"))
    assert back.travel == narrow.travel and back.sha256 == unit.sha256


def test_a_sensor_file_through_a_pipe_is_told_as_such_not_as_missing(tmp_path):
    """<(cat unit.toml) was said to be no such file; a pipe reads once, and a dataset's meta names the file to
    read again, so the path is asked for."""
    import os

    os.mkfifo(tmp_path / "unit.toml")  # nothing writes it: a read would block, so none may happen
    with pytest.raises(InputError, match=r"^sensor '.*unit.toml': not a regular file \(a pipe or a device\): give "
                                         r"the sensor file's path$"):
        load_sensor(tmp_path / "unit.toml")
    with pytest.raises(InputError, match="no such file, and not a preset"):
        load_sensor(tmp_path / "none.toml")
