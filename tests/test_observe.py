from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import least_squares

from fitgen.physics.observe import (DEFAULT_ACCURACY, INSIDE, ObserveReport, analyse, corner_poses, cramer_rao,
                                    jacobian, observe)
from fitgen.physics.pose import POSE_NAMES, field_readings
from fitgen.physics.scenes import PRESETS
from fitgen.physics.sensor import load_sensor
from fitgen.physics.transfer import apply_transfer

from conftest import assert_one_line_error, run_cli

PAPER = load_sensor("paper")


def test_ring_cannot_tell_tilt_from_slide_at_rest():
    """At rest the tilt columns of the Jacobian are parallel to the slide columns: rank 3."""
    J = jacobian(PAPER, np.zeros(5))[0]
    s = np.linalg.svd(J, compute_uv=False)
    assert s[2] > 1e-3 * s[0]
    assert s[3] < 1e-8 * s[0] and s[4] < 1e-8 * s[0]
    # d/dthx is a multiple of d/dy
    cos = J[:, 1] @ J[:, 3] / np.linalg.norm(J[:, 1]) / np.linalg.norm(J[:, 3])
    assert abs(abs(cos) - 1) < 1e-9


def test_jacobian_matches_a_coarser_difference():
    pose = np.array([[1.0, -0.5, -1.5, 3.0, -2.0]])
    J = jacobian(PAPER, pose)[0]
    h = 1e-2
    for j in range(5):
        e = np.zeros(5)
        e[j] = h
        d = (field_readings(PAPER, pose + e) - field_readings(PAPER, pose - e))[0] / (2 * h)
        d = d * -1  # readings are |B . r|; B . r < 0 under the magnet
        np.testing.assert_allclose(J[:, j], d, rtol=2e-4, atol=1e-9)


def test_cramer_rao_bound_matches_monte_carlo():
    """The least-squares pose estimate from noisy readings scatters as the bound says."""
    pose = np.array([-2.0, -2.0, -2.0, -5.0, -5.0])
    noise = 0.0005
    bound = analyse(PAPER, pose, noise)[0].bounds
    clean = apply_transfer(PAPER, field_readings(PAPER, pose))[0]
    rng = np.random.default_rng(7)
    est = []
    for _ in range(150):
        meas = clean + rng.normal(0, noise, clean.shape)
        fit = least_squares(lambda p: apply_transfer(PAPER, field_readings(PAPER, p))[0] - meas,
                            pose, x_scale=[0.01, 0.01, 0.01, 0.3, 0.3])
        est.append(fit.x)
    std = np.std(np.array(est), axis=0)
    np.testing.assert_allclose(std, bound, rtol=0.2)


def test_batched_bounds_match_a_per_pose_inverse():
    """cramer_rao (one batched SVD) against noise * sqrt(diag((J^T J)^-1)) pose by pose; inf where singular."""
    ring = load_sensor("ring-vertical")
    poses = np.array([[0.0, 0, 0, 0, 0], [1.0, -0.5, -1.5, 3.0, -2.0], [-2, 2, -2, 5, -5]])
    got = cramer_rao(ring, poses, 0.0005)
    for p, b in zip(poses, got):
        J = jacobian(ring, p)[0]
        np.testing.assert_allclose(b, 0.0005 * np.sqrt(np.diag(np.linalg.inv(J.T @ J))), rtol=1e-9)
    np.testing.assert_array_equal(got, [r.bounds for r in analyse(ring, poses, 0.0005)])
    assert np.all(cramer_rao(PAPER, np.zeros((1, 5)), 0.0005)[0, 3:] > 1e6)  # rank 3 at rest: unbounded
    slide = cramer_rao(PAPER, np.zeros((1, 5)), 0.0005, ("dx", "dy", "dz"))
    assert np.all(np.isfinite(slide))  # tilt held fixed: the slide alone is resolvable


def test_fewer_readings_than_components_have_no_finite_bound():
    d = PAPER.source | {"elements": {"ring": [{"count": 4, "radius": 10.0}]}}
    from fitgen.physics.sensor import parse_sensor

    four = parse_sensor(d)
    assert np.all(np.isinf(cramer_rao(four, np.array([[0.5, 0.5, -1, 1, 1]]), 0.0005)))
    # and the verdicts say so, each with a direction the readings cannot see (they raised a shape error)
    for count in (1, 3, 4):
        words = observe(parse_sensor(PAPER.source | {"elements": {"ring": [{"count": count, "radius": 10.0}]}}),
                        PRESETS["full"].ranges).verdicts()
        assert len(words) == 5 and all("NOT resolvable" in w and "(bound inf" in w for w in words), words
        assert all("the readings barely change along " in w for w in words)
        assert all(f"{count} readings cannot pin 5 pose components at once" in w for w in words), words
    # three of them can be pinned by four readings: no such words where they are not resolved
    four_slide = observe(four, PRESETS["slide"].ranges, ("dx", "dy", "dz")).verdicts()
    assert not any("cannot pin" in w for w in four_slide), four_slide


def test_a_component_clear_of_the_blind_directions_keeps_its_bound():
    """A ring of six at rest cannot tell slides from tilts (two zero singular values), yet sees a press: every
    bound was inf there, and dz was called not resolvable along a direction with no dz in it. dz's bound is the
    pseudo-inverse's, as a Fisher information singular elsewhere allows; the blind components stay inf."""
    from fitgen.physics.sensor import parse_sensor

    six = parse_sensor(PAPER.source | {"magnet": {"diameter": 5.0, "height": 2.0, "polarization": 1.2},
                                       "board": {"thickness": 1.5, "gap": 9.0},
                                       "elements": {"ring": [{"count": 6, "radius": 8.0}]}})
    rest = np.zeros((1, 5))
    J = jacobian(six, rest)[0]
    s = np.linalg.svd(J, compute_uv=False)
    assert s[-1] < 1e-12 * s[0] and s[-2] < 1e-10 * s[0] and s[-3] > 1e-3 * s[0]  # blind in two directions
    bound = cramer_rao(six, rest, 0.0005)[0]
    assert np.all(np.isinf(bound[[0, 1, 3, 4]]))
    fisher = J.T @ J
    want = 0.0005 * np.sqrt(np.linalg.pinv(fisher, rcond=1e-12)[2, 2])  # the seen directions' s^2 > 1e-6 s0^2
    assert np.isfinite(bound[2]) and bound[2] == pytest.approx(want, rel=1e-6)
    words = observe(six, PRESETS["full"].ranges).verdicts()
    assert not any(w.startswith("dz: NOT resolvable") for w in words), words


def test_a_raw_transfers_adc_clips_what_observe_differentiates():
    """observe takes readings without the ADC's rounding (adc_bits=0), which in the raw transfer also dropped the
    ADC's range: a file whose readings pass its full scale was called resolvable where simulate and fit saw every
    element on the rail."""
    from fitgen.physics.sensor import parse_sensor

    small = parse_sensor(PAPER.source | {"transfer": {"kind": "raw", "raw": {"noise": 0.0005, "full_scale": 0.5,
                                                                               "adc_bits": 8}}})
    poses = np.array([[0.0, 0.0, -2.0, 0.0, 0.0]])
    raw = field_readings(small, poses)
    assert np.abs(raw).max() > 0.5  # past the ADC's range
    clipped = apply_transfer(small, raw, adc_bits=0)
    assert clipped.max() == 0.5 and np.all(clipped <= 0.5)
    J = jacobian(small, poses)[0]
    assert np.all(J[np.abs(raw[0]) > 0.5 + 1e-3] == 0)  # a railed element reads nothing of the pose
    words = observe(small, {"dx": (0.0, 0.0), "dy": (0.0, 0.0), "dz": (-2.0, -2.0), "thx": (0.0, 0.0),
                            "thy": (0.0, 0.0)}, ("dz",)).verdicts()
    assert words[0].startswith("dz: NOT resolvable") and "8 of 8 elements there are past their linear range" \
        in words[0], words


def test_a_verdict_names_the_elements_past_their_linear_range():
    """Elements saturated at rest read the same whatever the pose: the verdict said only that the readings barely
    change along dx, which reads as a layout's blind direction; it names the saturated elements."""
    from fitgen.physics.sensor import parse_sensor
    from fitgen.physics.transfer import linear_top

    gmr = PAPER.with_transfer("gmr")
    near = parse_sensor(PAPER.source | {"board": dict(PAPER.source["board"], gap=6.0),  # the magnet 5 mm nearer
                                        "transfer": dict(PAPER.source["transfer"], kind="gmr")})
    rest = field_readings(near, np.zeros((1, 5)))
    assert np.all(np.abs(rest) > linear_top(near))  # the premise: every element saturated at rest
    rep = observe(near, PRESETS["press"].ranges, ("dz",))
    rest_result = rep.results[0]
    assert not np.any(rest_result.pose) and rest_result.past_linear == 8
    words = rep.verdicts()[0]
    assert "dz: NOT resolvable" in words and "8 of 8 elements there are past their linear range" in words, words
    # the drawing's own ring in gmr: no element past it at rest, and no such words
    assert observe(gmr, PRESETS["press"].ranges, ("dz",)).results[0].past_linear == 0


def test_a_verdict_quotes_the_worst_pose_not_the_first():
    rep = observe(PAPER, PRESETS["full"].ranges, noise=0.05)
    j = rep.components.index("dz")
    worst = max(rep.results, key=lambda r: r.bounds[j])
    words = next(w for w in rep.verdicts() if w.startswith("dz:"))
    assert f"bound {worst.bounds[j]:.3g} mm at {' '.join(f'{v:g}' for v in worst.pose)};" in words
    assert worst.bounds[j] > 5 * rep.results[0].bounds[j]  # at rest dz is seen best: the first pose is not it


def test_verdicts_for_the_paper_layout():
    rep = observe(PAPER, PRESETS["full"].ranges)
    assert len(rep.results) == 33 + INSIDE and rep.inside == INSIDE  # rest + 2^5 corners, poses inside
    assert rep.unresolved() == ["dx", "dy", "thx", "thy"]  # at rest, jointly with tilt
    words = "\n".join(rep.verdicts())
    assert "dz: resolvable" in words and "thx: NOT resolvable" in words
    slide = observe(PAPER, PRESETS["slide"].ranges, ("dx", "dy", "dz"))
    assert slide.unresolved() == []
    assert len(slide.results) == 9 + INSIDE  # rest + 2^3 corners (tilt held at 0)
    assert len(slide.table().splitlines()) == 2 + 9  # the corners tabled, the poses inside judged
    # one component has one singular value: no second column to fill with nan, and nothing estimated jointly
    press = observe(PAPER, PRESETS["press"].ranges, ("dz",))
    assert press.table().splitlines()[0].split() == ["pose", "(dx", "dy", "dz", "thx", "thy)", "s_min", "dz", "[mm]"]
    assert "nan" not in press.text() and "dz estimated alone" in press.text()


def test_cli_table_and_words(tmp_path):
    proc = run_cli("fitgen", "observe", "--sensor", "paper")
    assert proc.returncode == 0, proc.stderr
    assert "s_min" in proc.stdout and "thx [deg]" in proc.stdout
    assert "NOT resolvable" in proc.stdout
    proc = run_cli("fitgen", "observe", "paper", "--scene", "press", "--accuracy", "dz=0.0001")
    assert proc.returncode == 0 and "dz: NOT resolvable" in proc.stdout
    assert_one_line_error(run_cli("fitgen", "observe", "--accuracy", "dz=abc"), contains="not a number")
    assert_one_line_error(run_cli("fitgen", "observe", "--scene", "slide", "--accuracy", "thx=0.5"),
                          contains="an accuracy is asked for thx, which is not among the outputs estimated (dx,dy,dz)")
    assert_one_line_error(run_cli("fitgen", "observe", "--scene", "nosuch"), contains="scene")
    # a box past reason overflowed the field into a LinAlgError; one through the board was analysed
    assert_one_line_error(run_cli("fitgen", "observe", "--ranges", "dx=-1e300:1e300"), contains="within -1000..1000")
    # a box the user gave that reaches the board is said of the box, not of a pose number in it
    assert_one_line_error(run_cli("fitgen", "observe", "--ranges", "dz=-20:-10"),
                          contains="observe: the pose box reaches the board: at its corner dx=-2 dy=-2 dz=-20 thx=-5 "
                                   "thy=-5 the magnet's lowest point is 9.37 mm into it")
    proc = run_cli("fitgen", "simulate", "--ranges", "dz=-30:0", "--random", "10", "-o", str(tmp_path / "x.csv"))
    assert_one_line_error(proc, 2, "--ranges 'dz=-30:0': the pose box reaches the board: at its corner dx=-2 dy=-2 "
                                   "dz=-30 thx=-5 thy=-5")
    assert_one_line_error(run_cli("fitgen", "observe", "--ranges", "dx=-inf:2"),
                          contains="dx='-inf:2': LOW and HIGH must be finite numbers")
    # a box a hair above the board: the pose is legal, its central differences are not; the pose is named
    assert_one_line_error(run_cli("fitgen", "observe", "--ranges", "dx=0:0 dy=0:0 dz=-10.99995:-5 thx=0:0 thy=0:0"),
                          contains="pose 2 (dx=0 dy=0 dz=-10.99995 thx=0 thy=0) puts the magnet within 0.0001 mm")


def test_a_box_that_leaves_rest_out_says_which_pose_it_examined_for_rest():
    """corner_poses moves rest into the box: the verdict names that pose, not rest."""
    ranges = dict(PRESETS["slide"].ranges, dx=(1.0, 2.0), dy=(1.0, 2.0), dz=(-2.0, -1.0))
    words = "\n".join(observe(PAPER, ranges, ("dx", "dy", "dz")).verdicts())
    assert "at the box's pose nearest rest (dx=1 dy=1 dz=-1 thx=0 thy=0) and every corner" in words, words
    assert "at rest" not in words
    one = dict(ranges, dx=(0.0, 0.0), dy=(0.0, 0.0), dz=(-1.0, -1.0))  # a box of one pose: no other corner
    words = "\n".join(observe(PAPER, one, ("dz",)).verdicts())
    assert "at the box's pose nearest rest (dx=0 dy=0 dz=-1 thx=0 thy=0), and at" in words, words
    # a box with rest in it: as before
    words = "\n".join(observe(PAPER, PRESETS["slide"].ranges, ("dx", "dy", "dz")).verdicts())
    assert words.count("at rest and every corner, and at 200 random poses inside the box.") == 3, words


def test_a_layout_blind_inside_the_box_is_not_resolvable_though_every_corner_is():
    """The two rings in gmr saturate inside the full box (infinite bounds at about a third of random poses there)
    while every corner sees: the verdict, and fit's scene check with it, must look inside."""
    two = load_sensor("two-rings").with_transfer("gmr")
    corners = ObserveReport(POSE_NAMES, two.noise, two.units, dict(DEFAULT_ACCURACY),
                            analyse(two, corner_poses(PRESETS["full"].ranges), two.noise, POSE_NAMES))
    assert corners.unresolved() == []
    assert observe(two, PRESETS["full"].ranges).unresolved() == list(POSE_NAMES)


def test_a_huge_noise_gives_infinite_bounds_without_numpy_warnings(recwarn):
    rep = observe(PAPER, PRESETS["press"].ranges, noise=1e300)
    assert "dz" in rep.unresolved() and not [w for w in recwarn if issubclass(w.category, RuntimeWarning)]
    # from the command line it is a slip of the exponent, refused as simulate and a sensor file refuse it
    assert_one_line_error(run_cli("fitgen", "observe", "--noise", "1e300", "--scene", "press"), 2,
                          "--noise 1e300 is no sensor's reading noise (at most 1000")
    assert run_cli("fitgen", "observe", "--noise", "1000", "--scene", "press").returncode == 0


def test_a_sensor_file_without_a_noise_figure_is_not_judged_noise_free(tmp_path):
    """A file that leaves noise out reads 0, and every component came out 'resolvable: bound at most 0 mm'."""
    import re

    text = (Path(__file__).resolve().parents[1] / "fitgen" / "physics" / "presets" / "paper.toml").read_text()
    quiet = tmp_path / "quiet.toml"
    quiet.write_text(re.sub(r"(?m)^noise\s*=.*\n", "", text))
    assert_one_line_error(run_cli("fitgen", "observe", "--sensor", str(quiet)), 2,
                          "sensor paper gives no noise figure for its raw transfer (noise missing or 0 in "
                          "[transfer.raw])")
    proc = run_cli("fitgen", "observe", "--sensor", str(quiet), "--noise", "0.0005")
    assert proc.returncode == 0 and "dx: NOT resolvable" in proc.stdout  # the ring is blind to dx at rest
    # simulate's "the sensor's noise" of such a file added none without a word
    out = tmp_path / "r.csv"
    assert_one_line_error(run_cli("fitgen", "simulate", "--sensor", str(quiet), "--noise", "sensor", "--random", "5",
                                  "-o", str(out)), 2,
                          "--noise sensor: sensor paper gives no noise figure for its raw transfer")
    assert not out.exists()


def test_the_adcs_steps_count_as_reading_noise():
    """A 10-bit converter's steps (3.2 mV, 0.93 mV rms) outweigh the elements' 0.5 mV: the bound counts both, as
    the scatter of least-squares estimates over nearby poses (the rounding differs pose to pose) shows; the
    elements' noise alone promised half that."""
    from dataclasses import replace

    gmr = PAPER.with_transfer("gmr")
    coarse = replace(gmr, gmr=replace(gmr.gmr, adc_bits=10))
    report = observe(coarse, PRESETS["full"].ranges)
    lsb = (coarse.gmr.adc_max - coarse.gmr.adc_min) / 1023
    assert report.noise == np.hypot(coarse.gmr.noise, lsb / np.sqrt(12)) and report.noise > 2 * coarse.gmr.noise
    pose = np.array([-2.0, -2.0, -2.0, -5.0, -5.0])
    bound = analyse(coarse, pose, report.noise)[0].bounds
    rng = np.random.default_rng(9)
    errors = []
    for _ in range(300):
        truth = pose + rng.uniform(-1, 1, 5) * [0.2, 0.2, 0.2, 0.5, 0.5]
        meas = apply_transfer(coarse, field_readings(coarse, truth), noise=coarse.gmr.noise, rng=rng)[0]
        fit = least_squares(lambda p: apply_transfer(coarse, field_readings(coarse, p), adc_bits=0)[0] - meas,
                            truth, x_scale=[0.01, 0.01, 0.01, 0.3, 0.3])
        errors.append(fit.x - truth)
    rms = np.sqrt(np.mean(np.square(errors), axis=0))
    np.testing.assert_allclose(rms, bound, rtol=0.25)
    assert np.all(rms > 1.6 * analyse(coarse, pose, coarse.gmr.noise)[0].bounds)
    # and the CLI says what it counted
    proc = run_cli("fitgen", "observe", "--sensor", "paper", "--transfer", "gmr")
    assert proc.returncode == 0 and "reading noise 0.0005 V rms (element noise 0.0005 and the ADC's 5.04e-05 V " \
        "steps, 1.45e-05 rms)" in proc.stdout, proc.stdout
