"""A real unit calibrated from a short capture, end to end, as a user runs it: a unit drawn with `--unit`,
`fitgen schedule`, a capture through a simulated GRBL stage (backlash, repeatability, the unit's own
stage-to-magnet map), `fitgen identify`, `fitgen simulate` on the identified unit, `fitgen fit`, `fitgen codegen`
and the float C built by gcc, held out on the true unit."""

from __future__ import annotations

import json

import numpy as np

from conftest import require_tool, run_cli
from fitgen.physics.dataset import load_dataset
from fitgen.equations.model import load_model
from fitgen.physics.sensor import load_sensor
from fitgen.physics.simulate import pose_rng, random_poses, simulate
from fitgen.physics.transfer import readings
from host.capture import load_schedule
from fitgen.c.compiled import CompiledModel
from host.stagesim import simulated_stage_capture

BOX = {"dx": (-1.5, 1.5), "dy": (-1.5, 1.5), "dz": (-1.5, 0.0), "thx": (0.0, 0.0), "thy": (0.0, 0.0)}


def test_schedule_capture_identify_simulate_fit_codegen(tmp_path):
    require_tool("gcc")
    # a unit, drawn within the paper drawing's tolerances; its magnet follows the stage through its own map
    proc = run_cli("fitgen", "simulate", "--sensor", "paper", "--transfer", "gmr", "--unit", "41", "--grid", "dx=0",
                   "-o", str(tmp_path / "draw.csv"))
    assert proc.returncode == 0, proc.stderr
    unit = load_sensor(tmp_path / "draw.unit.toml")
    assert not np.allclose(unit.stage_map, np.eye(3))
    proc = run_cli("fitgen", "schedule", "--sensor", "paper", "--transfer", "gmr", "--n", "30", "--limits",
                   "dx=-1.5:1.5 dy=-1.5:1.5 dz=-1.5:0", "-o", str(tmp_path / "schedule.csv"))
    assert proc.returncode == 0, proc.stderr

    # the capture: two ADS1115s on a simulated bus read the unit; a simulated GRBL moves it (the rig's own map
    # is the identity: the unit's file carries the map), with backlash and 5 um repeatability
    res = simulated_stage_capture(unit, load_schedule(tmp_path / "schedule.csv"), tmp_path / "capture.csv",
                                  flavor="grbl", seed=4)
    assert res.complete and res.captured == 30

    proc = run_cli("fitgen", "identify", str(tmp_path / "capture.csv"), "--sensor", "paper", "--rig-error", "0.02",
                   "-o", str(tmp_path / "twin.toml"))
    assert proc.returncode == 0, proc.stderr
    post = json.loads((tmp_path / "twin.posterior.json").read_text())
    assert 0.3 < post["chi2"] / post["dof"] < 2.0  # the capture's own noise (measured) explains the residuals
    # the unit's single-sample noise, as the capture measured it, is the twin's
    sample_noise = json.loads((tmp_path / "capture.csv.meta.json").read_text())["sample_noise"]
    unit_noise = load_sensor(tmp_path / "twin.toml").noise
    assert unit_noise == np.sqrt(np.mean(np.square(sample_noise))) and abs(unit_noise / 0.0005 - 1) < 0.05
    # the twin's data: the stage's box (a three-axis scene, so no tilt), a grid and random poses
    proc = run_cli("fitgen", "simulate", "--sensor", str(tmp_path / "twin.toml"), "--grid",
                   "dx=-1.5:1.5:7 dy=-1.5:1.5:7 dz=-1.5:0:4", "--random", "1500", "--ranges",
                   "dx=-1.5:1.5 dy=-1.5:1.5 dz=-1.5:0 thx=0:0 thy=0:0", "-o", str(tmp_path / "twin.csv"))
    assert proc.returncode == 0, proc.stderr
    for name, data in (("twin", "twin.csv"), ("drawing", None)):
        if data is None:  # the drawing's model, the way a user without a capture would fit it
            simulate(load_sensor("paper").with_transfer("gmr"), load_dataset(tmp_path / "twin.csv").poses()).save(
                tmp_path / "drawing.csv")
            data = "drawing.csv"
        proc = run_cli("fitgen", "fit", str(tmp_path / data), "-o", str(tmp_path / f"{name}.json"), "--family",
                       "no-roots", "--outputs", "dx,dy,dz", "--held-out", "200")
        assert proc.returncode == 0, proc.stderr
    twin_fit = load_model(tmp_path / "twin.json").fit_info
    assert twin_fit["noise"]["device"] == unit_noise and twin_fit["noise"]["device_source"] == "sensor twin"
    proc = run_cli("fitgen", "codegen", str(tmp_path / "twin.json"), "--precision", "float", "-o", str(tmp_path / "c"))
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "c" / "tm_model.h").is_file()

    # held out on the true unit: random stage poses in the box (no tilt: a three-axis stage's scene)
    poses = random_poses(400, BOX, pose_rng(99))
    truth = readings(unit, poses, noise=0.0005, rng=np.random.default_rng(5))
    twin = load_model(tmp_path / "twin.json")
    with CompiledModel(twin, "float", "table") as cm:
        est, _ = cm.predict(truth)
    np.testing.assert_array_equal(est, twin.predict(truth, precision="float"))
    drawing_est = load_model(tmp_path / "drawing.json").predict(truth, precision="float")
    err = np.abs(est - poses[:, :3]).max(axis=0)
    drawing_err = np.abs(drawing_est - poses[:, :3]).max(axis=0)
    assert np.all(err < 0.1), err  # mm, a no-roots fit on 1,700 simulated rows of the twin
    assert np.all(err < drawing_err / 3), (err, drawing_err)
