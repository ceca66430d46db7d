"""What runs on the device is as accurate as what the fit reports: noise- and precision-aware fitting,
the float emulation against gcc, held-out figures in the model file, and verify's rounding gate."""

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from fitgen.fitting.augment import NoiseGrams, noise_blocks, noise_gram, rounding_rows
from fitgen.physics.dataset import Dataset
from fitgen.fitting.fit import FitSettings, _d_jacobian, fit_model, noise_to_add, ring_harmonics
from fitgen.fitting.holdout import clean_readings, deployed_errors, held_out_set, unit_sets
from fitgen.physics.pose import POSE_NAMES
from fitgen.physics.sensor import load_sensor
from fitgen.physics.simulate import DEFAULT_RANGES, grid_poses, pose_rng, random_poses, simulate
from fitgen.fitting.stepwise import compress, stepwise
from fitgen.equations.terms import Term, candidate_terms, design_jacobian, design_matrix
from fitgen.c.compiled import CompiledModel

from conftest import assert_one_line_error, require_tool, run_cli

OUTPUTS = POSE_NAMES
# a small grid (675 poses) on which the exact fit's float rounding already exceeds its model error
GRID = grid_poses({"dx": [-2, -1, 0, 1, 2], "dy": [-2, -1, 0, 1, 2], "dz": [0, -1, -2], "thx": [-5, 0, 5],
                   "thy": [-5, 0, 5]})


def _rms(pred, truth):
    return np.sqrt(np.mean((pred - truth) ** 2, axis=0))


@pytest.mark.parametrize("layout", ["two-radii", "two-rings"])
def test_deployed_float_c_is_as_accurate_as_the_fit(layout):
    """bench/deployed.py's acceptance on a small grid: the float C built by gcc deviates from the double
    model by at most 5 % of the model's held-out max error, and with the sensor's noise its RMS error is
    within 1.15x a double model fitted on noisy replicas; the paper's procedure misses both."""
    require_tool("gcc")
    sensor = load_sensor(layout)
    held = held_out_set(sensor, DEFAULT_RANGES, OUTPUTS, n=500, draws=2)
    train = simulate(sensor, GRID)
    replicas = fit_model(simulate(sensor, np.tile(GRID, (4, 1)), noise=sensor.noise, seed=2),
                         settings=FitSettings.exact())
    baseline = _rms(replicas.predict(held.noisy), held.noisy_truth)
    shares, ratios = {}, {}
    for label, settings in (("exact", FitSettings.exact()), ("default", FitSettings())):
        model = fit_model(train, settings=settings)
        with CompiledModel(model, "float", "unrolled") as cm:
            clean = cm.predict(held.clean.astype(np.float32).astype(float))[0]
            noisy = cm.predict(held.noisy.astype(np.float32).astype(float))[0]
        ref = model.predict(held.clean)
        shares[label] = np.abs(clean - ref).max(axis=0) / np.abs(ref - held.truth).max(axis=0)
        ratios[label] = _rms(noisy, held.noisy_truth) / baseline
    assert shares["exact"].max() > 0.5  # the disease: rounding adds more than half the model's own error
    assert shares["default"].max() <= 0.05, shares["default"]
    assert ratios["default"].max() <= 1.15, ratios["default"]


def test_noise_aware_fit_matches_a_fit_on_noisy_replicas():
    """The expected-noise rows against the brute-force way: R noisy copies of the grid, searched with the
    penalty R * 2 (R copies multiply n; 2R keeps AIC's trade per pose the same). The paper ring's dz
    equation is where noise-free fitting amplifies noise most (docs/layouts.md)."""
    sensor = load_sensor("paper")
    grid = grid_poses({"dx": [-2, -1, 0, 1, 2], "dy": [-2, -1, 0, 1, 2], "dz": [0, -0.5, -1, -1.5, -2]})
    held = held_out_set(sensor, {**DEFAULT_RANGES, "thx": (0, 0), "thy": (0, 0)}, ("dx", "dy", "dz"), n=1000,
                        draws=3)
    noise_free = simulate(sensor, grid, targets=("dx", "dy", "dz"))
    aware = fit_model(noise_free, settings=FitSettings(precision=None))
    exact = fit_model(noise_free, settings=FitSettings.exact())
    copies = 16
    replicas = fit_model(simulate(sensor, np.tile(grid, (copies, 1)), noise=sensor.noise, seed=5,
                                  targets=("dx", "dy", "dz")), settings=FitSettings.exact(k=2.0 * copies))
    rms = {name: _rms(m.predict(held.noisy), held.noisy_truth) for name, m in
           (("aware", aware), ("exact", exact), ("replicas", replicas))}
    assert rms["exact"][2] > 3 * rms["replicas"][2]  # noise-free fitting amplifies the noise
    np.testing.assert_allclose(rms["aware"], rms["replicas"], rtol=0.05)
    for a, b in zip(aware.equations, replicas.equations):
        assert abs(len(a.terms) - len(b.terms)) <= 2, a.name


def test_design_jacobian_against_finite_differences():
    sensor = load_sensor("paper")
    v = simulate(sensor, random_poses(20, DEFAULT_RANGES, pose_rng(3))).inputs
    d = np.random.default_rng(0).normal(size=(20, 3))
    d_jac = np.random.default_rng(1).normal(size=(20, 3, 8))
    terms = candidate_terms(8, "thx")
    jac = design_jacobian(terms, v, d, d_jac)
    h = 1e-6
    for k in range(8):
        step = np.zeros(8)
        step[k] = h
        # d moves with the inputs as the device's displacement estimates do: d + d_jac . dv
        up = design_matrix(terms, v + step, d + d_jac[:, :, k] * h)
        down = design_matrix(terms, v - step, d - d_jac[:, :, k] * h)
        np.testing.assert_allclose(jac[:, k, :], (up - down) / (2 * h), rtol=1e-5, atol=1e-6)


def test_noise_rows_give_the_expected_rss_exactly_for_linear_terms():
    """For v_k^1 terms the first-order expectation is exact: E||y - X(v+e)b||^2 = ||y - Xb||^2 + n sigma^2 |b|^2."""
    rng = np.random.default_rng(2)
    v = rng.uniform(0.5, 1.5, (200, 3))
    y = rng.normal(size=200)
    terms = [Term(k, "1") for k in (1, 2, 3)]
    X = design_matrix(terms, v)
    sigma = 0.1
    R = compress(X, y, extra=noise_blocks(terms, v, sigma))
    b = np.array([0.3, -1.2, 2.0])
    coef = np.concatenate([[0.7], b, [-1.0]])  # intercept, terms, y
    expected = np.sum((y - 0.7 - X @ b) ** 2) + 200 * sigma**2 * np.sum(b**2)
    assert np.sum((R @ coef) ** 2) == pytest.approx(expected, rel=1e-12)
    # rounding rows: (u ||column||)^2 per coefficient squared
    R2 = compress(X, y, extra=[rounding_rows(compress(X, y), 1e-3)])
    norms = np.concatenate([[np.sqrt(200)], np.linalg.norm(X, axis=0)])
    expected2 = np.sum((y - 0.7 - X @ b) ** 2) + np.sum((1e-3 * norms * coef[:-1]) ** 2)
    assert np.sum((R2 @ coef) ** 2) == pytest.approx(expected2, rel=1e-12)


def test_the_noise_gram_is_the_noise_rows_folded_by_qr():
    """The default fit's noise rows enter as their Gram matrix: on the paper ring, with the harmonics'
    and the d-terms' candidates of thx, the triangle is the one a QR of the stacked rows (noise_blocks)
    gives, and the search chooses alike. The Gram is the same whether d's gradient comes from the
    stage-1 equations' own rows or from evaluating them, and whether the parts without d are shared."""
    sensor = load_sensor("paper")
    ds = simulate(sensor, random_poses(300, DEFAULT_RANGES, pose_rng(4)))
    stage1 = fit_model(ds, ("dx", "dy", "dz"), FitSettings.family("harmonics"), sensor=sensor)
    v, harmonics, sigma = ds.inputs, ring_harmonics(ds, sensor), sensor.noise
    d = stage1.predict(v)
    d_jac = _d_jacobian(stage1.equations, v, harmonics)
    terms = candidate_terms(8, "thx", positive=v.min(axis=0) > 0, harmonics=harmonics, harmonic_degree=3)
    X, y = design_matrix(terms, v, d, harmonics), ds.target("thx")
    rounding = rounding_rows(compress(X, y), 8 * 2.0**-24)
    plain = compress(X, y, extra=[rounding, *noise_blocks(terms, v, sigma, d, d_jac, harmonics=harmonics)])
    gram = noise_gram(terms, v, sigma, d, d_jac, rows=128, harmonics=harmonics)
    size = np.sqrt(np.diag(gram))
    evaluated = noise_gram(terms, v, sigma, d, lambda lo, hi: d_jac(lo, hi), harmonics=harmonics)
    shared = NoiseGrams(v, sigma, harmonics, scope=terms[::-1]).gram(terms, d, d_jac)
    for other in (evaluated, shared):
        assert np.all(np.abs(other - gram) <= 1e-12 * np.outer(size, size))
    folded = compress(X, y, extra=[rounding], gram=gram)
    col = np.linalg.norm(plain, axis=0)
    assert np.all(np.abs(folded.T @ folded - plain.T @ plain) <= 1e-12 * np.outer(col, col))
    init = [terms.index(Term(k, e)) for k in range(1, 9) for e in ("-1", "-2")]
    a, b = (stepwise(None, y, init, compressed=R) for R in (plain, folded))
    assert a.selected == b.selected and len(a.selected) > 10
    assert a.aic == pytest.approx(b.aic, rel=1e-10)


def test_noise_is_never_counted_twice():
    sensor = load_sensor("paper")
    poses = random_poses(50, DEFAULT_RANGES, pose_rng(1))
    clean, noisy = simulate(sensor, poses), simulate(sensor, poses, noise=sensor.noise, seed=1)
    assert noise_to_add(clean, FitSettings())["added"] == pytest.approx(sensor.noise)
    assert noise_to_add(noisy, FitSettings())["added"] == 0.0
    half = simulate(sensor, poses, noise=0.0003, seed=1)
    assert noise_to_add(half, FitSettings())["added"] == pytest.approx(0.0004)
    measured = Dataset(clean.inputs, clean.targets, clean.target_names, {})  # no record: measured data
    info = noise_to_add(measured, FitSettings(noise=0.001))
    assert info["added"] == 0.0 and "measured" in info["why"]
    assert noise_to_add(clean, FitSettings(noise=0.002))["added"] == pytest.approx(0.002)


def test_noise_zero_is_the_papers_procedure(tmp_path):
    """`fitgen fit --noise 0` writes the same equations as FitSettings.exact() (what R's step() checks)."""
    sensor = load_sensor("paper")
    ds = simulate(sensor, random_poses(300, DEFAULT_RANGES, pose_rng(9)))
    ds.save(tmp_path / "d.csv")
    proc = run_cli("fitgen", "fit", str(tmp_path / "d.csv"), "-o", str(tmp_path / "m.json"), "--noise", "0",
                   "--held-out", "0")
    assert proc.returncode == 0, proc.stderr
    written = json.loads((tmp_path / "m.json").read_text())
    exact = fit_model(ds, settings=FitSettings.exact()).to_dict()
    assert written["outputs"] == exact["outputs"]
    assert written["fit"]["precision"]["target"] is None and written["fit"]["noise"]["added"] == 0.0
    default = fit_model(ds).to_dict()
    assert default["outputs"] != exact["outputs"]


@pytest.mark.bitexact
def test_float_emulation_is_bit_identical_to_gcc():
    require_tool("gcc")
    sensor = load_sensor("two-radii")
    model = fit_model(simulate(sensor, GRID), settings=FitSettings.exact())
    assert {t.exponent for e in model.equations for t in e.terms} >= {"1/2", "1/3", "-4"}
    v = simulate(sensor, random_poses(400, DEFAULT_RANGES, pose_rng(4))).inputs
    v = np.vstack([v, v * 1.7, v * 0.4])  # and clamped rows
    for style in ("table", "unrolled"):
        with CompiledModel(model, "float", style) as cm:
            c, status = cm.predict(v)
        py, py_status = model.predict(v, with_status=True, precision="float")
        np.testing.assert_array_equal(c, py)
        np.testing.assert_array_equal(status, py_status)


@pytest.fixture(scope="module")
def fitted_files(tmp_path_factory):
    """ring-vertical's paper-sim grid, fitted the paper's way (--noise 0, the paper's power kinds) and the default way."""
    folder = tmp_path_factory.mktemp("deployed")
    proc = run_cli("fitgen", "simulate", "--sensor", "ring-vertical", "--grid", "paper-sim", "-o",
                   str(folder / "sim.csv"))
    assert proc.returncode == 0, proc.stderr
    for name, extra in (("exact", ["--noise", "0", "--family", "all"]), ("default", [])):
        proc = run_cli("fitgen", "fit", str(folder / "sim.csv"), "-o", str(folder / f"{name}.json"), *extra)
        assert proc.returncode == 0, proc.stderr
    return folder


def test_model_file_says_what_its_numbers_assume(fitted_files):
    from fitgen.equations.model import load_model

    model = load_model(fitted_files / "default.json")
    info = model.fit_info
    assert info["noise"]["device"] == 0.0005 and info["noise"]["added"] == 0.0005
    assert info["precision"]["target"] == "float"
    rec = info["held_out"]
    assert rec["poses"] == 2000 and rec["noise"] == 0.0005 and rec["sensor"] == "ring-vertical"
    assert "unavailable" in rec["errors"]["fixed"]  # the fit uses roots
    for prec in ("double", "float"):
        for o in OUTPUTS:
            e = rec["errors"][prec][o]
            assert 0 < e["rms"] <= e["max"] and e["noisy_rms"] > 0
    # the figures are reproducible from the record: the same held-out readings, the same double error
    readings, truth = clean_readings(model)
    err = np.abs(model.predict(readings) - truth).max(axis=0)
    np.testing.assert_allclose(err, [rec["errors"]["double"][o]["max"] for o in OUTPUTS], rtol=1e-12)
    proc = run_cli("fitgen", "report", str(fitted_files / "default.json"))
    assert "precision float" in proc.stdout and "rounding's share" in proc.stdout


def test_verify_fails_when_float_rounding_exceeds_the_share(fitted_files):
    require_tool("gcc")
    bad = run_cli("tactile-host", "verify", str(fitted_files / "exact.json"), "--precision", "float",
                  "--style", "unrolled")
    assert bad.returncode == 1, bad.stdout
    assert "rounding adds" in bad.stdout and "over the 5% allowed" in bad.stdout
    good = run_cli("tactile-host", "verify", str(fitted_files / "default.json"), "--precision", "float",
                   "--style", "unrolled")
    assert good.returncode == 0, good.stdout
    assert "rounding's share" in good.stdout
    # the share is an option: a looser gate lets the paper's equations through in double, not in float
    loose = run_cli("tactile-host", "verify", str(fitted_files / "exact.json"), "--precision", "double",
                    "--style", "table", "--max-share", "0.01")
    assert loose.returncode == 0, loose.stdout
    assert_one_line_error(run_cli("tactile-host", "verify", str(fitted_files / "exact.json"), "--max-share", "-1"),
                          contains="--max-share")
    # another sensor's held-out readings are not the model's: refused as fitgen report refuses it
    assert_one_line_error(run_cli("tactile-host", "verify", str(fitted_files / "default.json"), "--sensor", "two-rings",
                                  "--precision", "float", "--style", "unrolled"),
                          contains="--sensor two-rings: the model was fitted on another sensor")


def test_a_units_default_fit_passes_verifys_rounding_gate(tmp_path, monkeypatch):
    """A built unit's equations take three times the drawing's terms, and with the drawing's rounding noise their
    float rounding passed verify's 5 % gate (unit 2: thx). The default fit takes such a fit again with the rounding
    noise doubled (fitgen.fitting.family.rounding_checked): gcc's float C of the model it writes passes the gate."""
    require_tool("gcc")
    import fitgen.fitting.family as family
    from fitgen.physics.dataset import load_dataset

    data, out = tmp_path / "u.csv", tmp_path / "u.json"
    proc = run_cli("fitgen", "simulate", "--sensor", "paper", "--transfer", "gmr", "--unit", "2", "--grid",
                   "paper-sim", "--random", "5000", "-o", str(data))
    assert proc.returncode == 0, proc.stderr
    unit = load_sensor(tmp_path / "u.unit.toml")
    ds = load_dataset(data)
    held = held_out_set(unit, DEFAULT_RANGES, OUTPUTS, n=2000, draws=0)

    def c_share(model):
        with CompiledModel(model, "float", "unrolled") as cm:
            clean = cm.predict(held.clean.astype(np.float32).astype(float))[0]
        ref = model.predict(held.clean)
        return np.abs(clean - ref).max(axis=0) / np.abs(ref - held.truth).max(axis=0)

    monkeypatch.setattr(family, "ROUNDING_RETRIES", 0)  # the fit as it was: the drawing's rounding noise alone
    before, record = family.fit_auto(ds, None, FitSettings(), unit)
    assert "rounding" not in record
    assert c_share(before).max() > 0.05, c_share(before)
    monkeypatch.undo()
    proc = run_cli("fitgen", "fit", str(data), "-o", str(out))
    assert proc.returncode == 0, proc.stderr
    assert "rounding: the float rounding's share" in proc.stderr
    info = json.loads(out.read_text())["fit"]
    assert info["family"]["rounding"]["factor"] >= 16 and info["precision"]["rounding_noise"] >= 16 * 2.0**-24
    from fitgen.equations.model import load_model

    assert c_share(load_model(out)).max() <= 0.05
    proc = run_cli("tactile-host", "verify", str(out), "--precision", "float", "--style", "unrolled")
    assert proc.returncode == 0, proc.stdout


def test_verify_says_why_it_measured_no_share(fitted_files, tmp_path):
    """A model file without a held_out record: verify names that, and refuses a --sensor it could not use."""
    require_tool("gcc")
    raw = json.loads((fitted_files / "default.json").read_text())
    del raw["fit"]["held_out"]
    bare = tmp_path / "bare.json"
    bare.write_text(json.dumps(raw))
    proc = run_cli("tactile-host", "verify", str(bare), "--precision", "float", "--style", "unrolled",
                   "--vectors", "200")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "rounding's share not measured: the model file has no held_out record" in proc.stdout
    assert_one_line_error(run_cli("tactile-host", "verify", str(bare), "--sensor", "ring-vertical"),
                          contains="--sensor ring-vertical: the model file has no held_out record")
    # the record names a sensor this machine does not have: verify asks for its file
    raw = json.loads((fitted_files / "default.json").read_text())
    raw["fit"]["held_out"]["sensor"] = "my-own-sensor"
    (tmp_path / "foreign.json").write_text(json.dumps(raw))
    proc = run_cli("tactile-host", "verify", str(tmp_path / "foreign.json"), "--precision", "double", "--style",
                   "table", "--vectors", "200")
    assert proc.returncode == 0 and "is not known here (give its file with --sensor)" in proc.stdout
    # the held-out check's own options with --no-held-out would be ignored: refused
    for extra in (["--sensor", "ring-vertical"], ["--max-share", "0.05"]):
        assert_one_line_error(run_cli("tactile-host", "verify", str(fitted_files / "default.json"), "--no-held-out",
                                      *extra), contains=f"{extra[0]} is the held-out check's: with --no-held-out")


def test_deployed_errors_fixed_point_within_share():
    """A no-roots fit for a fixed-point target: its integer arithmetic keeps the share small too."""
    from fitgen.equations.terms import FAMILIES

    sensor = load_sensor("two-radii").with_transfer("gmr")
    model = fit_model(simulate(sensor, GRID), settings=FitSettings(precision="fixed", exponents=FAMILIES["no-roots"]))
    held = held_out_set(sensor, DEFAULT_RANGES, OUTPUTS, n=300, draws=1)
    errs = deployed_errors(model, held, sensor)
    assert max(errs["fixed"][o]["share"] for o in OUTPUTS) <= 0.05
    assert max(errs["float"][o]["share"] for o in OUTPUTS) <= 0.05


def test_clean_readings_needs_a_known_sensor(fitted_files):
    from fitgen.equations.model import load_model

    model = load_model(fitted_files / "default.json")
    assert clean_readings(dataclasses.replace(model, fit_info={})) is None  # no record
    foreign = dataclasses.replace(model, fit_info={"held_out": {**model.fit_info["held_out"], "sensor": "my-own-sensor"}})
    assert clean_readings(foreign) is None
    assert clean_readings(foreign, load_sensor("ring-vertical")) is not None  # named by the user


def test_units_held_out_together_share_poses_but_not_noise():
    """A median over units is a median over noise realisations too: the same poses and noise-free readings
    for the same sensor, each unit its own draws, none repeated; held_out_set's default seeds for unit 0."""
    sensor = load_sensor("paper")
    sets = unit_sets([sensor] * 3, DEFAULT_RANGES, OUTPUTS, noise=None, n=50, seed=7, draws=2)
    assert [h.spec["noise_seeds"] for h in sets] == [[8, 9], [10, 11], [12, 13]]
    alone = held_out_set(sensor, DEFAULT_RANGES, OUTPUTS, n=50, seed=7, draws=2)
    np.testing.assert_array_equal(sets[0].noisy, alone.noisy)
    for h in sets[1:]:
        np.testing.assert_array_equal(h.clean, sets[0].clean)
        np.testing.assert_array_equal(h.truth, sets[0].truth)
        assert np.mean(h.noisy == sets[0].noisy) < 0.05  # equal only where ADC codes coincide


@pytest.mark.parametrize("layout", ["paper", "ring-vertical"])
def test_float_bound_holds_and_is_within_10x_of_the_measured_worst_case(layout):
    """The a-priori float bound (fitgen.equations.rounding) is never below the measured error and, since a d-term's
    share is taken per displacement, within 10x of the measured worst case on every output (it was
    15-30x on long rotation equations with d-terms)."""
    require_tool("gcc")
    from fitgen.c.verify import verify

    model = fit_model(simulate(load_sensor(layout), GRID))
    res = verify(model, "float", "unrolled", n_random=1000)
    assert res.ok, res.failures
    assert np.all(res.max_ratio <= 1.0)
    assert np.all(res.tightness() <= 10.0), res.tightness()
    assert any(t.mult for e in model.equations for t in e.terms)  # the d-terms are there


def test_a_drawing_of_ones_own_is_found_again_by_verify(tmp_path):
    """A layout in the user's own sensor file: the model recorded its name but not its file, so verify, the HIL
    suite and flash's sensor id could not simulate its held-out readings again without --sensor. The file is
    recorded (and the report still says drawing); a file since changed is not taken."""
    require_tool("gcc")
    mine = tmp_path / "mine.toml"
    mine.write_text((Path(__file__).resolve().parents[1] / "fitgen/physics/presets/paper.toml").read_text()
                    .replace('name = "paper"', 'name = "mine"'))
    data, model = tmp_path / "press.csv", tmp_path / "press.json"
    for args in (("simulate", "--sensor", str(mine), "--scene", "press", "-o", str(data)),
                 ("fit", str(data), "-o", str(model))):
        proc = run_cli("fitgen", *args)
        assert proc.returncode == 0, proc.stderr
    held = json.loads(model.read_text())["fit"]["held_out"]
    assert held["sensor_file"] == str(mine.resolve()) and held["drawing"] is True
    verify = ("tactile-host", "verify", str(model), "--precision", "float", "--vectors", "200")
    proc = run_cli(*verify, cwd=Path(__file__).resolve().parents[1])  # from another folder than the file's
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "rounding's share" in proc.stdout and "not measured" not in proc.stdout, proc.stdout
    proc = run_cli("fitgen", "report", str(model))
    assert "on the drawing mine: a built unit differs from it" in proc.stdout, proc.stdout
    mine.write_text(mine.read_text().replace("radius = 10.0", "radius = 10.5"))  # another sensor now
    proc = run_cli(*verify)
    assert proc.returncode == 0 and "rounding's share not measured: the sensor the model file's held_out record " \
        "names is not known here" in proc.stdout, proc.stdout
