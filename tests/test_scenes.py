"""Scenes carried through simulate, fit and codegen: only the outputs and poses a use needs."""

import json

import numpy as np
import pytest

from fitgen.c.codegen import render_header
from fitgen.equations.model import load_model
from fitgen.physics.scenes import PRESETS, load_scene
from fitgen.physics.sensor import load_sensor

from conftest import assert_one_line_error, run_cli

SMALL_FULL = """
name = "small-full"
outputs = ["dx", "dy", "dz", "thx", "thy"]
levels = 3
[ranges]
dx = [-1.5, 1.5]
dy = [-1.5, 1.5]
dz = [-2.0, 0.0]
thx = [-4.0, 4.0]
thy = [-4.0, 4.0]
"""


def test_scene_grids_hold_what_the_scene_holds():
    press = PRESETS["press"].poses()
    assert press.shape == (21, 5)
    assert np.all(press[:, [0, 1, 3, 4]] == 0)
    assert press[:, 2].min() == PRESETS["press"].ranges["dz"][0]
    slide = PRESETS["slide"].poses()
    assert slide.shape == (125, 5) and np.all(slide[:, 3:] == 0)
    assert PRESETS["full"].poses().shape == (5 ** 5, 5)


def test_press_scene_end_to_end(tmp_path):
    data, model_path = tmp_path / "press.csv", tmp_path / "press.json"
    proc = run_cli("fitgen", "simulate", "--scene", "press", "-o", str(data))
    assert proc.returncode == 0, proc.stderr
    meta = json.loads((tmp_path / "press.csv.meta.json").read_text())
    assert meta["scene"] == "press" and meta["scene_outputs"] == ["dz"] and meta["rows"] == 21
    proc = run_cli("fitgen", "fit", str(data), "-o", str(model_path))
    assert proc.returncode == 0, proc.stderr
    model = load_model(model_path)
    assert model.output_names == ("dz",)
    header = render_header(model, "float", "table")
    assert "#define TM_N_OUTPUTS 1" in header and "tm_terms_thx" not in header


def test_fit_refuses_a_scene_the_sensor_cannot_resolve(tmp_path):
    scene = tmp_path / "small.toml"
    scene.write_text(SMALL_FULL)
    data = tmp_path / "full.csv"
    assert run_cli("fitgen", "simulate", "--scene", str(scene), "-o", str(data)).returncode == 0
    proc = run_cli("fitgen", "fit", str(data), "-o", str(tmp_path / "m.json"))
    # the paper's single ring cannot tell tilt from slide at rest (docs/observe.md)
    assert_one_line_error(proc, 2, "cannot resolve")
    assert not (tmp_path / "m.json").exists()
    proc = run_cli("fitgen", "fit", str(data), "-o", str(tmp_path / "m.json"), "--force", "--max-terms", "6")
    assert proc.returncode == 0, proc.stderr
    assert load_model(tmp_path / "m.json").output_names == ("dx", "dy", "dz", "thx", "thy")


def test_observe_warns_for_unresolvable_scene_outputs():
    proc = run_cli("fitgen", "observe", "paper", "--scene", "full")
    assert proc.returncode == 0
    warned = {ln.split(" asks for ")[1].split(",")[0] for ln in proc.stderr.splitlines() if ln.startswith("warning:")}
    assert warned == {"dx", "dy", "thx", "thy"}
    proc = run_cli("fitgen", "observe", "paper", "--scene", "slide")
    assert proc.returncode == 0 and "warning" not in proc.stderr


def test_too_few_elements_are_pointed_at_scenes_they_can_pin(tmp_path):
    """One element cannot pin slide's three outputs: the advice offered slide itself among the scenes to use."""
    one = tmp_path / "one.toml"
    one.write_text('name = "one"\n[magnet]\ndiameter = 5.0\nheight = 1.0\npolarization = 1.45\n[board]\n'
                   'thickness = 1.5\ngap = 10.0\n[[elements.ring]]\ncount = 1\nradius = 9.0\naxis = "radial"\n'
                   '[transfer]\nkind = "gmr"\n[transfer.gmr]\nnoise = 0.0005\n')
    proc = run_cli("fitgen", "observe", str(one), "--scene", "slide")
    assert "1 readings cannot pin 3 pose components at once: a scene of at most 1 outputs (--scene press, a scene " \
           "file)" in proc.stdout + proc.stderr, proc.stdout + proc.stderr


@pytest.mark.parametrize("args, msg", [
    (["--scene", "press", "--grid", "paper-sim"], "--scene sets the poses"),
    (["--scene", "nope"], "not a preset"),
])
def test_simulate_scene_bad_options(tmp_path, args, msg):
    assert_one_line_error(run_cli("fitgen", "simulate", *args, "-o", str(tmp_path / "x.csv")), 2, msg)


def test_fit_scene_with_outputs_is_refused_and_outputs_win_over_the_datas_scene(tmp_path):
    data = tmp_path / "p.csv"
    assert run_cli("fitgen", "simulate", "--scene", "press", "-o", str(data)).returncode == 0
    assert_one_line_error(run_cli("fitgen", "fit", str(data), "-o", str(tmp_path / "m.json"), "--outputs", "dz",
                                  "--scene", "press"), 2, "not both")
    # the scene the data were simulated for gives way to --outputs (fit's own advice names them)
    proc = run_cli("fitgen", "fit", str(data), "-o", str(tmp_path / "m.json"), "--outputs", "dz")
    assert proc.returncode == 0, proc.stderr
    assert [o["name"] for o in json.loads((tmp_path / "m.json").read_text())["outputs"]] == ["dz"]


def test_a_scene_file_is_found_from_another_folder_and_a_scene_too_large_or_holding_an_output_is_refused(tmp_path):
    (tmp_path / "data").mkdir()
    (tmp_path / "s.toml").write_text('outputs = ["dz"]\nlevels = 30\n[ranges]\ndx = [0, 0]\ndy = [0, 0]\nthx = [0, 0]\n'
                                     'thy = [0, 0]\n')
    assert run_cli("fitgen", "simulate", "--scene", "s.toml", "-o", "data/s.csv", cwd=tmp_path).returncode == 0
    proc = run_cli("fitgen", "fit", "s.csv", "-o", "m.json", "--sensor", "paper", cwd=tmp_path / "data")
    assert proc.returncode == 0, proc.stderr
    # the scene file edited after simulating: the data no longer hold what it names, and fit says so
    (tmp_path / "s.toml").write_text('outputs = ["dx", "dz"]\nlevels = 30\n[ranges]\ndy = [0, 0]\nthx = [0, 0]\n'
                                     'thy = [0, 0]\n')
    assert_one_line_error(run_cli("fitgen", "fit", "s.csv", "-o", "m2.json", "--sensor", "paper",
                                  cwd=tmp_path / "data"), 2, "names dx,dz now, but s.csv was simulated when it "
                          "named dz: simulate again, or give --outputs")
    assert not (tmp_path / "data" / "m2.json").exists()
    assert run_cli("fitgen", "fit", "s.csv", "-o", "m2.json", "--outputs", "dz", cwd=tmp_path / "data").returncode == 0
    (tmp_path / "big.toml").write_text('outputs = ["dz"]\nlevels = 101\n')
    assert_one_line_error(run_cli("fitgen", "simulate", "--scene", str(tmp_path / "big.toml"), "-o",
                                  str(tmp_path / "b.csv")), 2, "make 10,510,100,501 poses (at most 1,000,000)")
    (tmp_path / "adir.toml").mkdir()  # it said "no such file"
    assert_one_line_error(run_cli("fitgen", "observe", "--scene", str(tmp_path / "adir.toml")), 2,
                          f"scene file {tmp_path / 'adir.toml'}: a folder, not a file")
    (tmp_path / "huge.toml").write_text(f'outputs = ["dz"]\n[ranges]\ndz = [-{10 ** 400}, 0]\n')  # OverflowError
    assert_one_line_error(run_cli("fitgen", "observe", "--scene", str(tmp_path / "huge.toml")), 2,
                          "'ranges.dz' must be [low, high], finite, with low <= high")
    (tmp_path / "held.toml").write_text('outputs = ["dx", "dz"]\n[ranges]\ndx = [0, 0]\n')
    assert_one_line_error(run_cli("fitgen", "observe", "--scene", str(tmp_path / "held.toml")), 2,
                          "output dx is held at 0")
    assert_one_line_error(run_cli("fitgen", "simulate", "--scene", "press", "--seed", "-1", "-o",
                                  str(tmp_path / "b.csv")), 2, "--seed")
    assert not (tmp_path / "b.csv").exists()


def test_observe_ranges_override_the_scenes_box_and_bad_figures_are_refused():
    proc = run_cli("fitgen", "observe", "--scene", "slide", "--ranges", "dz=-1:0")
    assert proc.returncode == 0, proc.stderr
    rows = [ln.split()[:5] for ln in proc.stdout.splitlines() if ln[:1] in "-0123456789" and not ln.startswith("--")
            and len(ln.split()) > 5]
    assert rows and {r[3] for r in rows} == {"0"} and {r[2] for r in rows} <= {"0", "-1"}  # no tilt, dz in -1:0
    for argv, said in ((["--noise", "0"], "--noise must be > 0"), (["--accuracy", "dx=-1"], "finite number > 0"),
                       (["--accuracy", "dy=nan"], "finite number > 0"), (["--noise", "inf"], "finite number")):
        assert_one_line_error(run_cli("fitgen", "observe", *argv), 2, said)


def test_scene_toml_levels_and_unresolved_check_agree_with_observe(tmp_path):
    scene = tmp_path / "s.toml"
    scene.write_text(SMALL_FULL)
    s = load_scene(str(scene))
    assert s.poses().shape == (3 ** 5, 5)
    from fitgen.physics.scenes import unresolved_warnings

    assert unresolved_warnings(load_sensor("paper"), PRESETS["slide"]) == []
    assert len(unresolved_warnings(load_sensor("paper"), s)) == 4


def test_fit_checks_the_scene_at_the_noise_it_is_given(tmp_path):
    """A sensor file without a noise figure: fit's check that the sensor resolves the scene refused it and pointed
    at observe, though --noise was given to fit; it now takes --noise, and says to give it."""
    (tmp_path / "ring.toml").write_text('name = "ring6"\n[magnet]\ndiameter = 5.0\nheight = 1.0\npolarization = 1.45\n'
                                        '[board]\nthickness = 1.5\ngap = 10.0\n[[elements.ring]]\ncount = 6\n'
                                        'radius = 9.0\naxis = "radial"\n[transfer]\nkind = "gmr"\n')
    data = tmp_path / "d.csv"
    assert run_cli("fitgen", "simulate", "--sensor", str(tmp_path / "ring.toml"), "--scene", "press", "-o",
                   str(data)).returncode == 0
    assert_one_line_error(run_cli("fitgen", "fit", str(data), "-o", str(tmp_path / "m.json")), 2,
                          "sensor ring6 gives no noise figure for its gmr transfer (noise missing or 0 in "
                          "[transfer.gmr]): add it to the file, or give --noise;")
    proc = run_cli("fitgen", "fit", str(data), "-o", str(tmp_path / "m.json"), "--noise", "0.0005")
    assert proc.returncode == 0, proc.stderr
    assert load_model(tmp_path / "m.json").output_names == ("dz",)


def test_a_scene_grid_grows_to_the_rows_a_fit_of_its_sensor_needs(tmp_path):
    """press holds 21 rows, and a ring of ten elements has 20 initial terms: simulate --scene press wrote rows fit
    refused ("give at least 23 rows"), and tradeoff, which takes no row count, could not run. The grid's levels grow
    to the rows needed; the presets' sensors (eight elements) keep their grids."""
    from fitgen.fitting.fit import rows_needed

    press, slide = PRESETS["press"], PRESETS["slide"]
    assert press.with_rows(rows_needed(8)) is press and len(press.poses()) == 21
    assert press.with_rows(rows_needed(10)).levels == 23 == rows_needed(10)
    assert slide.with_rows(126).levels == 6 and slide.with_rows(125) is slide  # 6^3 free poses
    ten = tmp_path / "ten.toml"
    ten.write_text('name = "ten"\n[magnet]\ndiameter = 5.0\nheight = 1.0\npolarization = 1.45\n[board]\n'
                   'thickness = 1.5\ngap = 10.0\n[[elements.ring]]\ncount = 10\nradius = 9.0\naxis = "radial"\n'
                   '[transfer]\nkind = "gmr"\n[transfer.gmr]\nnoise = 0.0005\n')
    data = tmp_path / "d.csv"
    proc = run_cli("fitgen", "simulate", "--sensor", str(ten), "--scene", "press", "-o", str(data))
    assert proc.returncode == 0 and "wrote 23 rows" in proc.stderr, proc.stderr
    proc = run_cli("fitgen", "fit", str(data), "-o", str(tmp_path / "m.json"))
    assert proc.returncode == 0, proc.stderr
    proc = run_cli("fitgen", "tradeoff", str(ten), "--scene", "press", "--family", "integer", "--precision", "float",
                   "--k", "aic", "--max-terms", "6", "--style", "unrolled", "-o", str(tmp_path / "t"))
    assert proc.returncode == 0 and (tmp_path / "t" / "tradeoff.csv").is_file(), proc.stderr


def test_a_scene_grid_raised_and_a_box_past_the_travel_are_said(tmp_path):
    """simulate raised a scene file's levels for the fit's rows without a word, and took a box 20 mm wide, past the
    paper sensor's 3 mm of travel, as readily as one within it; observe said nothing of the travel either."""
    scene = tmp_path / "wide.toml"
    scene.write_text('outputs = ["dx"]\nlevels = 3\n[ranges]\ndx = [-20, 20]\ndy = [0, 0]\ndz = [-0.3, -0.3]\n'
                     'thx = [0, 0]\nthy = [0, 0]\n')
    proc = run_cli("fitgen", "simulate", "--scene", str(scene), "-o", str(tmp_path / "w.csv"))
    assert proc.returncode == 0, proc.stderr
    assert "note: scene wide: its grid takes 19 levels per moving component, not its 3" in proc.stderr
    travel = "its box reaches past the sensor's travel ([travel] of its file): dx -20..20 mm (travel -3..3)"
    assert f"note: scene wide: {travel}" in proc.stderr
    proc = run_cli("fitgen", "observe", "--scene", str(scene))
    assert proc.returncode == 0 and f"note: scene wide: {travel}" in proc.stderr, proc.stderr
    # within the travel and at levels enough: nothing said
    scene.write_text(scene.read_text().replace("[-20, 20]", "[-2, 2]").replace("levels = 3", "levels = 19"))
    proc = run_cli("fitgen", "simulate", "--scene", str(scene), "-o", str(tmp_path / "w.csv"))
    assert proc.returncode == 0 and "note:" not in proc.stderr, proc.stderr
    assert "note:" not in run_cli("fitgen", "observe", "--scene", str(scene)).stderr


def test_a_scene_given_as_a_scene_or_named_empty(tmp_path):
    """load_scene(PRESETS['slide']), as docs/python.md hands a Scene out, had raised 'unhashable type: dict'; a
    file's name = "" had printed 'scene :' in every line."""
    from fitgen.base.errors import InputError
    from fitgen.physics.posesource import choose_poses
    from fitgen.physics.scenes import PRESETS, load_scene
    from fitgen.physics.sensor import load_sensor

    assert load_scene(PRESETS["slide"]) is PRESETS["slide"]
    poses, info = choose_poses(scene=PRESETS["slide"], sensor=load_sensor("paper"))
    assert len(poses) and not poses[:, 3:].any() and info["scene_spec"] == "slide"  # no tilt; fit finds it by name
    (tmp_path / "s.toml").write_text('name = ""\noutputs = ["dx"]\n')
    with pytest.raises(InputError, match="'name' must be a string, not empty"):
        load_scene(str(tmp_path / "s.toml"))
