"""The library as a notebook meets it: inputs that a CLI never passes (its parser refuses them first) give one
clear InputError, or are taken as documented, rather than a numpy error deep inside or a plausible wrong figure."""

import re

import numpy as np
import pytest

from conftest import run_cli
from fitgen.base.errors import InputError
from fitgen.fitting.family import fit_device
from fitgen.fitting.fit import FitSettings
from fitgen.physics.dataset import Dataset, load_dataset
from fitgen.physics.observe import observe
from fitgen.physics.scenes import PRESETS
from fitgen.physics.simulate import DEFAULT_RANGES, pose_rng, random_poses, simulate


def test_simulate_refuses_targets_that_drop_a_moving_pose_column_and_bad_noise(sensor):
    """A dataset's missing pose columns read as 0: targets=("dz",) on poses that slide too had made fit hold the
    model out on a box of dx = dy = 0, its file saying 0.026 mm where it errs 0.077."""
    poses = PRESETS["slide"].poses()
    with pytest.raises(InputError, match="targets leave out dx, dy, which the poses move in"):
        simulate(sensor, poses, targets=("dz",))
    ds = simulate(sensor, poses, targets=("dx", "dy", "dz"))  # thx, thy stay 0: nothing lost
    assert simulate(sensor, poses[:3], noise=np.float32(1e-4)).meta["noise"] == pytest.approx(1e-4)
    assert np.array_equal(ds.poses(), poses)
    for bad, said in (({"targets": ("x",)}, "targets must be distinct pose components"),
                      ({"targets": ("dx", "dx", "dy", "dz")}, "targets must be distinct pose components"),
                      ({"noise": np.full(8, 5e-4)}, "noise must be a number >= 0"),
                      ({"noise": None}, "noise must be a number >= 0"),
                      ({"noise": -1e-4}, "noise must be a number >= 0")):
        with pytest.raises(InputError, match=said):
            simulate(sensor, poses, **bad)


def test_datasets_settings_and_pose_boxes_made_in_python_are_checked_where_made():
    v, y = np.ones((4, 8)), np.zeros((4, 2))
    for args, said in (((v, y[:3], ("dx", "dy")), "of the same rows"),
                       ((v, y, ("dx",)), "one distinct pose component"),
                       ((v, y, ("x", "y")), "one distinct pose component"),
                       ((v, y, ("dx", "dx")), "one distinct pose component"),
                       ((v[0], y, ("dx", "dy")), "of the same rows")):
        with pytest.raises(InputError, match=said):
            Dataset(*args)
    listed = Dataset(v.tolist(), y.tolist(), ["dx", "dy"])  # lists: taken as arrays
    assert listed.n_rows == 4 and listed.poses().shape == (4, 5) and listed.target_names == ("dx", "dy")
    assert FitSettings(k="aic").penalty(100) == 2.0 and FitSettings(k="bic").penalty(100) == pytest.approx(np.log(100))
    for bad, said in (({"k": "aicc"}, "k, the penalty per term"), ({"k": 0}, "k, the penalty per term"),
                      ({"max_terms": 0}, "max_terms is None or a whole number >= 1"),
                      ({"max_terms": -1}, "max_terms is None or a whole number >= 1")):
        with pytest.raises(InputError, match=said):
            FitSettings(**bad)
    assert FitSettings(max_terms=np.int64(5)).max_terms == 5
    assert FitSettings(k=np.float32(6)).penalty(10) == 6.0 and FitSettings(k=np.int64(6)).penalty(10) == 6.0
    poses = random_poses(50, {"dx": (-1, 1)}, pose_rng(1))  # the others stay 0, as a dataset's missing columns
    assert np.all(np.abs(poses[:, 0]) <= 1) and np.ptp(poses[:, 0]) > 1 and not poses[:, 1:].any()
    with pytest.raises(InputError, match="ranges name x, no pose component"):
        random_poses(5, {"x": (0, 1)}, pose_rng(1))


def test_observe_refuses_a_noise_that_is_no_noise(sensor, tmp_path):
    for bad in (-0.01, float("nan")):  # -0.01 had been taken as 0.01
        with pytest.raises(InputError, match="noise must be a number >= 0"):
            observe(sensor, DEFAULT_RANGES, ("dx",), noise=bad)
    # 0 is fit --noise 0's, the paper's procedure, whose scene check observes without noise: a scene's data fitted
    # so (a refusal of 0 had refused it, naming a noise the user never gave)
    data = tmp_path / "press.csv"
    assert run_cli("fitgen", "simulate", "--sensor", "paper", "--scene", "press", "-o", str(data)).returncode == 0
    proc = run_cli("fitgen", "fit", str(data), "--noise", "0", "--held-out", "0", "-o", str(tmp_path / "m.json"))
    assert proc.returncode == 0, proc.stderr


def test_fit_device_fits_the_family_its_settings_name_and_reads_units_from_the_sensor(sensor, tmp_path):
    """fit_device's family had defaulted to auto, which replaced the settings' candidates without a word (integer
    asked, harmonics fitted); a dataset made in numpy without a meta was recorded as mT whatever the sensor read."""
    from fitgen.physics.simulate import grid_poses

    train = simulate(sensor, grid_poses({"dx": [-2, -1, 0, 1, 2], "dy": [-1, 0, 1], "dz": [0, -1, -2]}))
    for settings, name in ((FitSettings.family("integer"), "integer"), (FitSettings.family("no-roots"), "no-roots"),
                           (FitSettings(), "auto")):
        record = fit_device(train, ("dx",), settings, sensor, held_out=0).fit_info["family"]
        assert record["name"] == name or (name == "auto" and record["auto"]), record
    assert fit_device(train, ("dx",), FitSettings.family("integer"), sensor, "no-roots",
                      held_out=0).fit_info["family"]["name"] == "no-roots"  # a family named wins, as documented
    with pytest.raises(InputError, match="no named family"):
        fit_device(train, ("dx",), FitSettings(exponents=("1", "2")), sensor, held_out=0)
    bare = Dataset(train.inputs, train.targets, train.target_names)  # no meta: made in numpy
    assert fit_device(bare, ("dx",), FitSettings(), sensor, held_out=0).input_units == "V"
    # made by hand: of no rows (numpy's 'zero-size array'), of another sensor's elements (fitted with its noise)
    # and of one row, every input one value: too few rows, not a dead element (a scene's rows nearly all lifted)
    for ds, said in ((Dataset(train.inputs[:0], train.targets[:0], train.target_names), "no rows"),
                     (Dataset(train.inputs[:1], train.targets[:1], train.target_names), "one row: too few to fit"),
                     (Dataset(train.inputs[:, :5], train.targets, train.target_names), "8 elements; the data have 5")):
        with pytest.raises(InputError, match=said):
            fit_device(ds, ("dx",), FitSettings(), sensor, "all", held_out=0)
    # numpy's numbers, as np.arange gives them: the model had fitted, then failed to save (int64 not serializable)
    model = fit_device(train, ("dx",), FitSettings(max_terms=np.int64(3), noise=np.float32(1e-3), k=np.float64(2)),
                       sensor, "all", held_out=0)
    model.save(tmp_path / "m.json")


def test_fit_leaves_out_rows_fitgen_simulate_lifted_off_the_skin(tmp_path):
    """simulate notes that fit leaves out rows above first contact (they read the sensor at rest); fit did so only
    for a capture's or a unit's rows, and fitted a drawing's with their labels (dx 2 mm at rest)."""
    data = tmp_path / "lift.csv"
    proc = run_cli("fitgen", "simulate", "--sensor", "paper", "--grid", "dx=-2:2:5 dy=-2:2:5 dz=-1:1:5",
                   "-o", str(data))
    assert proc.returncode == 0 and "(fitgen fit leaves them out)" in proc.stderr, proc.stderr
    proc = run_cli("fitgen", "fit", str(data), "--held-out", "0", "--outputs", "dx", "-o", str(tmp_path / "m.json"))
    assert proc.returncode == 0 and "left out 50 row(s) lifted off the skin" in proc.stdout + proc.stderr, proc.stderr
    from fitgen.equations.model import load_model

    assert load_model(tmp_path / "m.json").fit_info["dataset_rows"] == 125 - 50
    assert load_dataset(data).n_rows == 125


@pytest.mark.parametrize("bad", [10 ** 400, [10 ** 400] * 8, "0.001", [[1e-3]] * 8, float("nan")],
                         ids=["huge", "huge-each", "text", "nested", "nan"])
def test_a_reading_noise_past_floats_range_or_of_another_shape_is_one_line(bad):
    """identify's and check's noise per element: an integer too large for a float had raised OverflowError."""
    from fitgen.fitting.capturecheck import element_noise

    with pytest.raises(InputError, match="the rows' noise"):
        element_noise(bad, 8, "the rows' noise")
    assert np.array_equal(element_noise(2, 3, "noise"), [2.0, 2.0, 2.0])


def test_counts_seeds_noise_and_accuracies_from_a_notebook_are_one_inputerror(sensor):
    """A count of 40.0, a seed of -1 or 1.5, a noise of 0, an accuracy of one figure or of -1: numpy's, range()'s
    or SeedSequence's errors from deep inside, a sensor file blamed, or 'NOT resolvable to -1 mm'."""
    from fitgen.fitting.schedule import check_schedule, schedule
    from fitgen.physics.units import draw_unit

    for call, said in ((lambda: pose_rng(-1), "a seed must be a whole number >= 0, got -1"),
                       (lambda: draw_unit(sensor, True), "a unit's seed must be a whole number >= 0, got True"),
                       (lambda: pose_rng(1.5), "a seed must be a whole number >= 0, got 1.5"),
                       (lambda: random_poses(10.0, DEFAULT_RANGES, pose_rng(1)), "whole number 1..5,000,000, got 10.0"),
                       (lambda: schedule(sensor, 40.0), "--n must be a whole number 10..10000"),
                       (lambda: schedule(sensor, 12, noise=0), "noise, the rows' reading noise, must be a finite"),
                       (lambda: check_schedule(sensor, 30.0), "--check must be a whole number 1..10000"),
                       (lambda: check_schedule(sensor, 5, seed=-1), "a seed must be a whole number >= 0"),
                       (lambda: observe(sensor, DEFAULT_RANGES, accuracy=0.001), "accuracy is a dict of pose"),
                       (lambda: observe(sensor, DEFAULT_RANGES, accuracy={"dx": -1}), "accuracy dx must be a finite")):
        with pytest.raises(InputError, match=re.escape(said)):
            call()
    ds = simulate(sensor, random_poses(np.int64(30), DEFAULT_RANGES, pose_rng(np.int64(2))))  # numpy's whole numbers
    with pytest.raises(InputError, match="held_out must be a whole number of poses >= 0, got 2.5"):
        fit_device(ds, ("dx",), FitSettings(), sensor, "all", held_out=2.5)
