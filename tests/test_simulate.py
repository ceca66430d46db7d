import json
import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from fitgen.physics.dataset import load_dataset
from fitgen.base.errors import InputError
from fitgen.physics.sensor import load_sensor
from fitgen.physics.simulate import PAPER_GRIDS, grid_poses, parse_grid, pose_rng, random_poses, simulate, parse_ranges
from fitgen.physics.transfer import quantise

from conftest import assert_one_line_error, run_cli

PAPER_TOML = Path(__file__).resolve().parents[1] / "fitgen" / "physics" / "presets" / "paper.toml"


def test_paper_grids_sizes_and_levels():
    sim = grid_poses(PAPER_GRIDS["paper-sim"])
    exp = grid_poses(PAPER_GRIDS["paper-exp"])
    assert sim.shape == (1875, 5) and exp.shape == (450, 5)
    assert sorted(set(sim[:, 2])) == [-2, -1, 0]
    assert sorted(set(exp[:, 3])) == [-5, 0, 5]
    assert len({tuple(r) for r in sim}) == 1875


def test_cli_writes_paper_sim(tmp_path):
    out = tmp_path / "sim.csv"
    proc = run_cli("fitgen", "simulate", "--sensor", "paper", "--grid", "paper-sim", "-o", str(out))
    assert proc.returncode == 0, proc.stderr
    lines = out.read_text().splitlines()
    assert lines[0] == "v1,v2,v3,v4,v5,v6,v7,v8,dx,dy,dz,thx,thy"
    assert len(lines) == 1876
    ds = load_dataset(out)
    assert ds.meta["sensor_sha256"] == load_sensor("paper").sha256
    assert ds.meta["dataset_sha256"] == ds.sha256
    # at rest every element of the symmetric ring reads the same
    rest = np.all(ds.poses() == 0, axis=1)
    assert rest.sum() == 1
    v = ds.inputs[rest][0]
    np.testing.assert_allclose(v, v[0], rtol=1e-12)
    assert 0.5 < v[0] < 1.5  # about 1 mT: inside the AA003-02's linear range (0.2-1.4 mT)


def test_deterministic_for_a_seed(tmp_path):
    a, b, c = (tmp_path / n for n in ("a.csv", "b.csv", "c.csv"))
    for path, seed in ((a, 3), (b, 3), (c, 4)):
        proc = run_cli("fitgen", "simulate", "--random", "50", "--seed", str(seed), "--noise", "0.001", "-o", str(path))
        assert proc.returncode == 0, proc.stderr
    assert a.read_bytes() == b.read_bytes()
    assert a.read_bytes() != c.read_bytes()


def test_noise_has_the_requested_rms():
    s = load_sensor("paper")
    poses = np.zeros((20000, 5))
    clean = simulate(s, poses).inputs
    noisy = simulate(s, poses, noise=0.01, seed=1).inputs
    assert abs(np.std(noisy - clean) / 0.01 - 1) < 0.02


def test_gmr_transfer_quantises_and_saturates():
    s = load_sensor("paper").with_transfer("gmr")
    ds = simulate(s, grid_poses(PAPER_GRIDS["paper-sim"]))
    g = s.gmr
    lsb = (g.adc_max - g.adc_min) / (2**g.adc_bits - 1)
    codes = (ds.inputs - g.adc_min) / lsb
    np.testing.assert_allclose(codes, np.round(codes), atol=1e-6)
    assert np.all(ds.inputs <= g.adc_max)
    # volts follow |B| linearly below saturation
    raw = simulate(load_sensor("paper"), grid_poses(PAPER_GRIDS["paper-sim"])).inputs
    k = g.supply * g.sensitivity * 1e-3 * 10 * g.gain
    np.testing.assert_allclose(ds.inputs, g.offset + k * np.minimum(raw, g.saturation), atol=lsb)


def test_past_linear_is_where_the_reading_stops_following_the_field():
    """past_linear against the transfer itself: a reading it calls linear moves when |B| grows a little, one it
    calls past does not (saturated, or on the ADC's top rail; a unit's gains and offsets included)."""
    from fitgen.physics.transfer import apply_transfer, past_linear
    from fitgen.physics.units import draw_unit

    paper = load_sensor("paper")
    gmr = paper.with_transfer("gmr")
    low_rail = replace(gmr, gmr=replace(gmr.gmr, adc_max=2.5))  # the rail below saturation's 3.1 V
    b = -np.linspace(0.01, 3.0, 600)[:, None] * np.ones((1, 8))
    for s in (gmr, low_rail, draw_unit(gmr, 3)[0]):
        past = past_linear(s, b)
        moved = apply_transfer(s, b * 1.001, adc_bits=0) != apply_transfer(s, b, adc_bits=0)
        assert past.any() and (~past).any()
        np.testing.assert_array_equal(past, ~moved)
    assert not past_linear(paper, b).any()  # raw and not quantised: it follows any field


def test_simulate_and_fit_say_where_the_readings_do_not_carry_the_pose(tmp_path):
    """A layout of one's own whose elements saturate at rest: simulate and fit wrote their files and said nothing
    (a 2 mm model that a held-out table alone shows); simulate says it, fit refuses rows whose every element
    reads one value, and the drawing's own press gets neither."""
    near = tmp_path / "near.toml"  # the paper's ring with the magnet 5 mm nearer: 3.5 mT at rest, past 2
    near.write_text(PAPER_TOML.read_text().replace("gap = 11.0", "gap = 6.0"))
    for sensor, says in ((str(near), True), ("paper", False)):
        data, model = tmp_path / "d.csv", tmp_path / "m.json"
        proc = run_cli("fitgen", "simulate", "--sensor", sensor, "--transfer", "gmr", "--scene", "press",
                       "-o", str(data))
        assert proc.returncode == 0, proc.stderr
        assert ("note: 21 of 21 rows (100%) have an element past its linear range" in proc.stderr) == says, \
            proc.stderr
        assert ("`fitgen observe --sensor " + sensor + " --transfer gmr` tells" in proc.stderr) == says, proc.stderr
        proc = run_cli("fitgen", "fit", str(data), "-o", str(model), "--force")
        if says:  # every element on its rail in every row: a model of constants, whose file no reader takes
            assert_one_line_error(proc, 2, "v1, v2, v3, v4, v5, v6, v7, v8 read one value on every row")
            assert "or an element saturated throughout" in proc.stderr and not model.exists()
        else:
            assert proc.returncode == 0 and "dz's equation leaves" not in proc.stderr, proc.stderr


def test_simulate_says_when_adc_bits_give_a_raw_transfer_a_full_scale_its_readings_clip_at(tmp_path):
    """--adc-bits on the raw transfer gives it a converter whose full scale (2 mT) a magnet 5 mm nearer passes at
    rest: every row was clipped there without a word, as the gmr transfer's rails are said."""
    near = tmp_path / "near.toml"
    near.write_text(PAPER_TOML.read_text().replace("gap = 11.0", "gap = 6.0"))
    args = ["fitgen", "simulate", "--sensor", str(near), "--transfer", "raw", "--scene", "press"]
    proc = run_cli(*args, "--adc-bits", "10", "-o", str(tmp_path / "q.csv"))
    assert proc.returncode == 0, proc.stderr
    assert "note: 21 of 21 rows (100%) have an element past its linear range" in proc.stderr, proc.stderr
    assert f"`fitgen observe --sensor {near} --transfer raw` tells" in proc.stderr
    quiet = run_cli(*args, "-o", str(tmp_path / "r.csv"))
    assert quiet.returncode == 0 and "past its linear range" not in quiet.stderr  # not quantised: follows any field


def test_the_fit_note_names_causes_that_hold(tmp_path):
    """The note said "as elements past their linear range or fewer elements than outputs make it" wherever an
    equation left half its output's spread: also on the paper's own ring and procedure, where neither holds and
    its tilts leave about half. Now it names a cause that holds, or, where the equation is near a constant, the
    noise it is fitted for; the paper's procedure gets no note."""
    data, model = tmp_path / "d.csv", tmp_path / "m.json"
    proc = run_cli("fitgen", "simulate", "--sensor", "paper", "--transfer", "gmr", "--random", "300", "--seed", "3",
                   "-o", str(data))
    assert proc.returncode == 0 and "linear range" not in proc.stderr, proc.stderr
    noise = load_sensor("paper").gmr.noise
    said = {}
    for extra in ((), ("--noise", "0")):
        proc = run_cli("fitgen", "fit", str(data), "-o", str(model), "--family", "integer", *extra)
        assert proc.returncode == 0, proc.stderr
        said[extra] = [ln for ln in proc.stderr.splitlines() if "of its spread" in ln]
        assert not any("linear range" in ln or "elements for" in ln for ln in said[extra]), proc.stderr
    # on random poses the paper's terms leave a tilt near a constant, more so against the device's noise
    assert said[()] and all("close to a constant; against the " f"{noise:.3g} V rms of reading noise it is fitted "
                            "for, the readings barely carry" in ln for ln in said[()]), said
    assert said[("--noise", "0")] and not any("noise" in ln for ln in said[("--noise", "0")]), said
    assert "without the displacement terms" not in proc.stderr
    # a tilt fitted without dx, dy and dz has no displacement terms: said, and its near-constant blamed on that
    proc = run_cli("fitgen", "fit", str(data), "-o", str(model), "--family", "integer", "--outputs", "dy,thx")
    assert proc.returncode == 0, proc.stderr
    assert ("note: thx fitted without the displacement terms eq. 1 gives a tilt (they take dx, dy and dz from their "
            "own equations, and the fit has no dx, dz): fit --outputs dx,dy,dz,thx to have them") in proc.stderr
    assert "barely carry" not in proc.stderr
    # a penalty that admits no term leaves the tilts constant: that is said, not blamed on the readings
    proc = run_cli("fitgen", "fit", str(data), "-o", str(model), "--family", "integer", "--k", "bic",
                   "--held-out", "0")
    assert proc.returncode == 0, proc.stderr
    assert re.search(r"note: thx's equation leaves 100% of its spread .*: it has no terms, as the penalty per term "
                     r"\(k = 5\.7\) admitted none; a smaller --k \(aic: 2\) may admit some", proc.stderr), proc.stderr
    # a cap that leaves a tilt near a constant is named, not the readings (they carry thx uncapped); where the search
    # stopped short of the cap (thy: 3 terms of 4), the cap is not blamed, the stop is said
    proc = run_cli("fitgen", "fit", str(data), "-o", str(model), "--family", "all", "--max-terms", "4",
                   "--held-out", "0")
    assert proc.returncode == 0, proc.stderr
    capped = {ln.split("'")[0][6:]: ln for ln in proc.stderr.splitlines() if "of its spread" in ln}
    assert sorted(capped) == ["thx", "thy"], capped
    assert "close to a constant within --max-terms 4, which may be too few terms for thx" in capped["thx"]
    assert "close to a constant with 3 of the 4 terms --max-terms allows: the search stopped" in capped["thy"]
    assert "barely carry" not in proc.stderr
    # the paper's procedure on its grid: its tilts leave about half their spread, as the paper's do; no note
    for argv in (("simulate", "--sensor", "paper", "--grid", "paper-sim", "-o", str(data)),
                 ("fit", str(data), "--noise", "0", "-o", str(model))):
        proc = run_cli("fitgen", *argv)
        assert proc.returncode == 0 and "of its spread" not in proc.stderr, proc.stderr
    fit = json.loads(model.read_text())["fit"]["outputs"]["thx"]["model_training_error"]["rms"]
    assert fit > 0.45 * load_dataset(data).target("thx").std()  # the case the old note named saturation


def test_quantise_is_within_half_lsb():
    x = np.linspace(0, 1, 1001)
    q = quantise(x, 0.0, 1.0, 8)
    assert np.max(np.abs(q - x)) <= 0.5 / 255 + 1e-15
    assert len(np.unique(q)) == 256


def test_rows_above_first_contact_are_said_to_read_the_sensor_at_rest(tmp_path):
    """A grid reaching above first contact wrote readings at rest under labels that move, without a word."""
    out = tmp_path / "up.csv"
    proc = run_cli("fitgen", "simulate", "--sensor", "paper", "--grid", "dz=0,0.5,1 dx=0,1", "-o", str(out))
    assert proc.returncode == 0, proc.stderr
    assert ("note: 4 of 6 rows lie above first contact (dz > 0.05 mm): the indenter is off the skin there, and they "
            "read the sensor at rest (fitgen fit leaves them out)") in proc.stderr
    rows = load_dataset(out)
    up = rows.poses()[:, 2] > 0
    assert np.all(rows.inputs[up] == rows.inputs[~up & (rows.poses()[:, 0] == 0)][0])
    assert "above first contact" not in run_cli("fitgen", "simulate", "--sensor", "paper", "--grid", "dz=0,-1",
                                                "-o", str(tmp_path / "down.csv")).stderr


def test_grid_and_range_specs():
    lv = parse_grid("dx=-1:1:3 dz=0,-1")
    assert grid_poses(lv).shape == (6, 5)
    with pytest.raises(InputError):
        parse_grid("dq=1:2:3")
    with pytest.raises(InputError):
        parse_grid("dx=1:2")
    with pytest.raises(InputError, match=r"grid 'paper-simm': not a preset \(paper-sim, paper-exp\)"):
        parse_grid("paper-simm")  # a preset's name mistyped: the names there are
    # a grid past the pose limits --ranges keeps to: thx = 1e6 deg had been simulated
    with pytest.raises(InputError, match="thx must lie within -180..180 deg"):
        parse_grid("dx=0,1 thx=0,1e6")
    r = parse_ranges("dz=-3:0")
    p = random_poses(1000, r, pose_rng(0))
    assert p[:, 2].min() >= -3 and p[:, 2].max() <= 0
    with pytest.raises(InputError):
        parse_ranges("dx=2:1")


def test_poses_keep_the_magnet_above_the_board_and_boxes_stay_finite(tmp_path):
    """Every reading goes through the check: the magnet's lowest point, its tilt included, may come within a hair of
    the board's top face, not onto it; a unit's magnet moves as its stage map says; a scene's box is held to the
    range limits as --ranges is."""
    import dataclasses

    from fitgen.physics.pose import check_above_board, field_readings
    from fitgen.physics.scenes import load_scene

    paper = load_sensor("paper")  # centre 13 mm above the board's bottom face, 1 mm thick, board 1.5 mm thick
    assert check_above_board(paper, [0, 0, -10.99, 0, 0])[0, 2] == pytest.approx(2.01)
    for dz in (-11.0, -13.0, -20.0):
        with pytest.raises(InputError, match="pose 2 .*on or below the board's top face"):
            field_readings(paper, [[0, 0, -2, 0, 0], [1, 0, dz, 0, 0]])
    # tilted 20 deg, the rim drops 3 sin 20 + 0.5 cos 20 = 1.5 mm: 0.5 mm above the face at rest height 2 mm
    field_readings(paper, [0, 0, -10.5, 0, 0])
    with pytest.raises(InputError, match=r"pose 1 \(dx=0 dy=0 dz=-10.5 thx=20 thy=0\) puts the magnet's lowest point "
                                         r"at z = 1.00"):
        field_readings(paper, [0, 0, -10.5, 20, 0])
    # a unit's magnet follows the stage by half in z: the stage may press twice as far
    unit = dataclasses.replace(paper, stage_map=np.diag([1.0, 1.0, 0.5]))
    assert not unit.is_drawing
    assert np.all(np.isfinite(field_readings(unit, [0, 0, -21.9, 0, 0])))
    with pytest.raises(InputError, match="board's top face"):
        field_readings(unit, [0, 0, -22.0, 0, 0])
    with pytest.raises(InputError, match="thx must lie within -180..180 deg"):
        parse_ranges("thx=-181:0")
    (tmp_path / "far.toml").write_text('outputs = ["dz"]\n[ranges]\ndz = [-inf, 0.0]\n')
    with pytest.raises(InputError, match="far.toml: dz from -inf to 0 mm"):
        load_scene(str(tmp_path / "far.toml"))


def test_poses_file(tmp_path):
    poses = tmp_path / "p.csv"
    poses.write_text("dz,thx\n-1,0\n-2,5\n")
    out = tmp_path / "o.csv"
    assert run_cli("fitgen", "simulate", "--poses", str(poses), "-o", str(out)).returncode == 0
    ds = load_dataset(out)
    np.testing.assert_array_equal(ds.poses(), [[0, 0, -1, 0, 0], [0, 0, -2, 5, 0]])


def test_grid_then_random_poses(tmp_path):
    out = tmp_path / "o.csv"
    proc = run_cli("fitgen", "simulate", "--grid", "dx=-1,1 dz=0,-2", "--random", "7", "--seed", "3", "-o", str(out))
    assert proc.returncode == 0, proc.stderr
    poses = load_dataset(out).poses()
    np.testing.assert_array_equal(poses[:4, [0, 2]], [[-1, 0], [-1, -2], [1, 0], [1, -2]])
    alone = tmp_path / "r.csv"
    assert run_cli("fitgen", "simulate", "--random", "7", "--seed", "3", "-o", str(alone)).returncode == 0
    np.testing.assert_array_equal(poses[4:], load_dataset(alone).poses())


@pytest.mark.parametrize("args, text", [
    (["--grid", "dx=a:b:c"], "grid"),
    (["--grid", "paper-huge"], "grid"),
    (["--random", "0"], "random"),
    (["--noise", "-1"], "noise"),
    (["--adc-bits", "99"], "adc-bits"),
    (["--grid", "paper-sim", "--poses", "p.csv"], "one of"),
    (["--random", "5", "--poses", "p.csv"], "one of"),
    (["--bogus"], "unrecognized"),
    # the magnet's bottom face (11 mm above the board at rest) on the board's top face: into the board
    (["--grid", "dz=-11 dx=0 dy=0"], "on or below the board's top face (z = 1.5 mm"),
    (["--random", "5", "--ranges", "dz=-14:-12"], "the pose box reaches the board: at its corner"),
    (["--random", "5", "--ranges", "dx=-1e300:1e300"], "dx must lie within -1000..1000 mm"),
    (["--random", "5", "--ranges", "thy=-1e999:0"], "thy from -inf to 0 deg"),
])
def test_bad_options_one_line(tmp_path, args, text):
    out = tmp_path / "o.csv"
    assert_one_line_error(run_cli("fitgen", "simulate", *args, "-o", str(out)), contains=text)
    assert not out.exists()


def test_unwritable_output(tmp_path):
    assert_one_line_error(run_cli("fitgen", "simulate", "-o", str(tmp_path / "no" / "such" / "dir.csv")),
                          contains="cannot write")
    # a folder where the file should go: the rename fails, nothing is left behind
    target = tmp_path / "taken"
    target.mkdir()
    assert_one_line_error(run_cli("fitgen", "simulate", "-o", str(target)), contains="cannot write")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["taken"]


def test_fit_holds_out_and_plans_fixed_point_through_the_adc_simulate_read_the_rows_with(tmp_path):
    """simulate --adc-bits 6 was dropped by fit: its held-out figures were of an ADC-less sensor (thx max 5.4 deg
    where the rows' 6-bit ADC errs 8.1), and codegen --precision fixed planned 16-bit codes over the 64 the rows
    had. Now the model is the one fitted on the same rows from a sensor file whose transfer has that ADC."""
    from conftest import run_cli
    from fitgen.equations.model import load_model

    own = tmp_path / "six.toml"
    text = PAPER_TOML.read_text()
    assert "adc_bits = 0  " in text
    own.write_text(text.replace("adc_bits = 0  ", "adc_bits = 6  ", 1))
    models = {}
    for name, how in (("option", ["--sensor", "paper", "--adc-bits", "6"]), ("file", ["--sensor", str(own)])):
        for argv in (["simulate", *how, "--grid", "paper-exp", "-o", f"{name}.csv"],
                     ["fit", f"{name}.csv", "-o", f"{name}.json", "--outputs", "dx", "--max-terms", "6", "--family",
                      "no-roots"],
                     ["codegen", f"{name}.json", "--precision", "fixed", "-o", name]):
            proc = run_cli("fitgen", *argv, cwd=tmp_path)
            assert proc.returncode == 0, proc.stderr
        models[name] = load_model(tmp_path / f"{name}.json").fit_info["held_out"]
        assert "input LSB 0.031746 mT" in proc.stderr, proc.stderr
    assert (tmp_path / "option.csv").read_text() == (tmp_path / "file.csv").read_text()
    assert models["option"]["adc_bits"] == 6 and "adc_bits" not in models["file"]  # the file's own says it
    assert models["option"]["errors"] == models["file"]["errors"]
    # the record names the preset as its file is (a moved folder finds a file by that hash), and the drawing's
    # units flashed uncalibrated are read through the same ADC
    assert models["option"]["sensor_sha256"] == load_sensor("paper").sha256
    assert models["option"]["uncalibrated"] == models["file"]["uncalibrated"]
