"""Model files, the fit's two stages, predict and report, and bad input on every path."""

import dataclasses
import json

import numpy as np
import pytest

from fitgen.app.report import format_report
from fitgen.base.errors import InputError
from fitgen.fitting.fit import FitSettings, fit_model
from fitgen.equations.model import load_model, model_from_dict
from fitgen.physics.sensor import load_sensor
from fitgen.physics.simulate import DEFAULT_RANGES, PAPER_GRIDS, grid_poses, pose_rng, random_poses, simulate
from fitgen.equations.terms import Term, candidate_terms, design_matrix, element_powers, parse_term, EXPONENTS

from conftest import assert_one_line_error, run_cli

PAPER = load_sensor("paper")


@pytest.fixture(scope="module")
def paper_fit(tmp_path_factory):
    folder = tmp_path_factory.mktemp("fit")
    ds = simulate(PAPER, grid_poses(PAPER_GRIDS["paper-sim"]))
    ds.save(folder / "sim.csv")
    proc = run_cli("fitgen", "fit", str(folder / "sim.csv"), "-o", str(folder / "m.json"), "--family", "all")
    assert proc.returncode == 0, proc.stderr
    return folder, ds, load_model(folder / "m.json")


def test_terms_round_trip_and_powers():
    for out in ("dx", "thx"):
        for t in candidate_terms(8, out):
            assert parse_term(t.text) == t
    assert len(candidate_terms(8, "dx")) == 88 and len(candidate_terms(8, "thy")) == 88 + 3 + 24
    v = np.array([0.3, 1.0, 2.7])
    for e in EXPONENTS:
        num, _, den = e.partition("/")
        np.testing.assert_allclose(element_powers(v, e), v ** (float(num) / float(den or 1)), rtol=1e-14)
    for bad in ("v0^1", "v1^5", "v1^-1/2", "x", "v1*dq", "v2^1*dx", ""):
        with pytest.raises(InputError):
            parse_term(bad)


def test_nonpositive_inputs_never_meet_negative_or_root_powers():
    cands = candidate_terms(3, "dz", positive=np.array([True, False, True]))
    assert not any(t.element == 2 and t.needs_positive for t in cands)
    assert Term(2, "3") in cands


def test_model_file_round_trip_and_prediction(paper_fit):
    folder, ds, model = paper_fit
    again = load_model(folder / "m.json")
    assert again.sha256 == model.sha256
    np.testing.assert_array_equal(again.predict(ds.inputs), model.predict(ds.inputs))
    info = model.fit_info
    assert info["dataset_sha256"] == ds.sha256 and info["dataset_rows"] == 1875
    assert info["sensor_sha256"] == PAPER.sha256
    for name in model.output_names:
        o = info["outputs"][name]
        assert o["steps"][0][0] == "" and o["condition"] > 1
        assert o["aic"] == pytest.approx(o["steps"][-1][1])
    # the ring's symmetry: dy's terms are dx's under one of the ring's 16 rotations and reflections
    dx = {(t.element, t.exponent) for t in model.equation("dx").terms}
    dy = {(t.element, t.exponent) for t in model.equation("dy").terms}
    images = [{((s * (k - 1) + r) % 8 + 1, e) for k, e in dx} for s in (1, -1) for r in range(8)]
    assert dy in images
    # the file's dict is the model's copy: editing it (as tests and tools that write a variant do) leaves the
    # model, which a session-wide fixture shares, as it was
    before = json.dumps(model.fit_info, sort_keys=True)
    d = model.to_dict()
    d["fit"]["outputs"]["dx"]["steps"].clear()
    d["fit"]["dataset_rows"] = 0
    assert json.dumps(model.fit_info, sort_keys=True) == before


def test_rotations_use_the_fitted_displacements(paper_fit):
    _, ds, model = paper_fit
    thx = model.equation("thx")
    assert thx.uses_d
    # evaluating by hand with the model's own displacement estimates gives the model's output
    pred = model.predict(ds.inputs)
    d = pred[:, :3]
    by_hand = thx.intercept + design_matrix(list(thx.terms), ds.inputs, d) @ np.array(thx.coefficients)
    np.testing.assert_allclose(pred[:, 3], by_hand, rtol=1e-12, atol=1e-7)  # terms reach 1e6: order of summation
    assert model.fit_info["d_terms"] == "estimated"


def test_domain_clamp_and_status():
    ds = simulate(PAPER, random_poses(300, DEFAULT_RANGES, pose_rng(3)))
    model = fit_model(ds, ("dz",))
    v = ds.inputs[:4].copy()
    v[1, 2] = model.input_max[2] * 10
    v[2, 0] = model.input_min[0] * 0.1
    v[3, 5] = np.nan
    out, status = model.predict(v, with_status=True)
    assert status.tolist() == [0, 1 << 2, 1 << 0, -1]
    assert out[3, 0] == 0.0 and np.all(np.isfinite(out))
    clamped = v[1].copy()
    clamped[2] = model.input_max[2]
    assert out[1, 0] == pytest.approx(model.predict(clamped[None])[0, 0], rel=1e-12)


def test_cap_and_bic_give_smaller_models():
    ds = simulate(PAPER, random_poses(800, DEFAULT_RANGES, pose_rng(4)), noise=0.0005, seed=4)
    aic = fit_model(ds, ("dz",))
    bic = fit_model(ds, ("dz",), FitSettings(k="bic"))
    cap = fit_model(ds, ("dz",), FitSettings(max_terms=8))
    n_aic, n_bic, n_cap = (len(m.equation("dz").terms) for m in (aic, bic, cap))
    assert n_bic <= n_aic and n_cap <= 8
    assert bic.fit_info["settings"]["k"] == pytest.approx(np.log(800))


def test_a_cap_below_eq1_starts_from_its_best_terms_not_its_first():
    """--max-terms 6 cut eq. 1 to its first six terms (elements 1-3 alone) and, at the cap, the search could not
    move: dx never saw elements 4-8. The cap now drops eq. 1's terms one at a time, each the one whose removal
    raises the RSS least, and the equation starts from what is left."""
    from fitgen.equations.terms import design_matrix, initial_terms

    ds = simulate(PAPER, random_poses(800, DEFAULT_RANGES, pose_rng(4)), noise=0.0005, seed=4)
    m = fit_model(ds, ("dx",), FitSettings.exact(max_terms=6))
    info = m.fit_info["outputs"]["dx"]
    assert len(info["initial_over_cap"]) == 10
    eq1 = initial_terms(8)
    kept = [t for t in eq1 if t.text not in info["initial_over_cap"]]
    assert len(kept) == 6 and {t.element for t in kept} - {1, 2, 3}  # not the first three elements'
    # the first six of eq. 1 fit the rows worse than the six the cap kept, and worse than the equation chosen
    y = ds.target("dx")
    first = design_matrix(eq1[:6], ds.inputs)
    rss_first = float(np.sum((y - np.c_[np.ones(len(y)), first] @ np.linalg.lstsq(
        np.c_[np.ones(len(y)), first], y, rcond=None)[0]) ** 2))
    rss_chosen = float(np.sum((m.predict(ds.inputs)[:, 0] - y) ** 2))
    assert rss_chosen < 0.5 * rss_first, (rss_chosen, rss_first)


def test_the_summary_and_report_name_the_criterion_the_cap_and_the_cut_of_eq1(tmp_path):
    """--k bic --max-terms 6 printed BIC values as "AIC", and the report said neither k nor the cap, nor which of
    eq. 1's terms the cap had cut before the trace's first move."""
    data = tmp_path / "d.csv"
    simulate(PAPER, random_poses(300, DEFAULT_RANGES, pose_rng(4)), noise=0.0005, seed=4).save(data)
    for k, crit in (("bic", "BIC"), ("6", "AIC (k = 6)"), ("aic", "AIC")):
        model = tmp_path / f"m{k}.json"
        proc = run_cli("fitgen", "fit", str(data), "-o", str(model), "--k", k, "--max-terms", "6", "--outputs", "dx",
                       "--held-out", "0")
        assert proc.returncode == 0 and f"dx: 6 terms, {crit} -" in proc.stderr, proc.stderr
        text = run_cli("fitgen", "report", str(model)).stdout
        cut = load_model(model).fit_info["outputs"]["dx"]["initial_over_cap"]
        head = next(line for line in text.splitlines() if line.startswith("| output"))
        assert [c.strip() for c in head.split("|")[1:-1]] == ["output", "terms", crit, "steps", "cond"], head
        assert f"### {crit} trace" in text, text
        assert f"from eq. 1 on {crit}, at most 6 terms per output (--max-terms)" in text
        assert len(cut) == 10 and f"(eq. 1 without {', '.join(cut)});" in text


def test_true_d_option(tmp_path):
    ds = simulate(PAPER, random_poses(400, DEFAULT_RANGES, pose_rng(8)))
    m = fit_model(ds, settings=FitSettings(d_source="true"))
    assert m.fit_info["d_terms"] == "true"
    m2 = fit_model(ds, ("dx", "thx"))  # without all three displacements there are no d-terms
    assert not m2.equation("thx").uses_d and m2.fit_info["d_terms"] == "none"


def test_predict_and_report_cli(paper_fit, tmp_path):
    folder, ds, model = paper_fit
    out = tmp_path / "pred.csv"
    proc = run_cli("fitgen", "predict", str(folder / "m.json"), str(folder / "sim.csv"), "-o", str(out))
    assert proc.returncode == 0, proc.stderr
    lines = out.read_text().splitlines()
    assert lines[0] == "dx,dy,dz,thx,thy,status" and len(lines) == 1876
    table = np.array([[float(x) for x in ln.split(",")] for ln in lines[1:]])
    np.testing.assert_array_equal(table[:, :5], model.predict(ds.inputs))
    proc = run_cli("fitgen", "report", str(folder / "m.json"), "--data", str(folder / "sim.csv"), "--paper",
                   "--plot", str(tmp_path / "plots"), "--sensor", "paper")
    assert proc.returncode == 0, proc.stderr
    assert "max error per dz level" in proc.stdout and "paper sim max" in proc.stdout
    assert f"Model {model.sha256[:12]}: 5 outputs, 8 inputs (mT)" in proc.stdout
    written = run_cli("fitgen", "report", str(folder / "m.json"), "-o", str(tmp_path / "w.md"))  # said, as by the rest
    assert written.returncode == 0 and written.stderr.strip() == f"wrote {tmp_path / 'w.md'}" and not written.stdout
    one = dataclasses.replace(model, equations=model.equations[:1], fit_info={})  # said in the singular
    assert f"Model {one.sha256[:12]}: 1 output, 8 inputs" in format_report(one)
    assert (tmp_path / "plots" / "estimate_thx.png").stat().st_size > 1000
    assert (tmp_path / "plots" / "sweep_thx.png").exists()
    # what --plot needs is checked before the report is written: one line, nothing written
    (tmp_path / "file").write_text("x")
    for extra, msg in ((["--data", str(folder / "sim.csv"), "--plot", str(tmp_path / "file" / "sub")], "cannot create"),
                       (["--plot", str(tmp_path / "p2")], "--plot needs --data"),
                       (["--data", str(folder / "sim.csv"), "--plot", str(tmp_path / "p3"), "--sensor", "nosuch"],
                        "nosuch")):
        proc = run_cli("fitgen", "report", str(folder / "m.json"), "-o", str(tmp_path / "r.md"), *extra)
        assert_one_line_error(proc, 2, msg)
        assert not (tmp_path / "r.md").exists()
    # a model of no rotation has no sweep to draw: --sensor would be ignored
    dataclasses.replace(model, equations=model.equations[:3]).save(tmp_path / "d.json")
    proc = run_cli("fitgen", "report", str(tmp_path / "d.json"), "--data", str(folder / "sim.csv"), "--plot",
                   str(tmp_path / "p4"), "--sensor", "paper", "-o", str(tmp_path / "r.md"))
    assert_one_line_error(proc, 2, "estimates no rotation (dx, dy, dz): leave --sensor out")
    assert not (tmp_path / "r.md").exists() and not (tmp_path / "p4").exists()


def test_report_shows_progress_through_its_figures_on_a_terminal(paper_fit, tmp_path, monkeypatch):
    """report --plot draws for seconds (7 figures, about 5 s): on a terminal a bar moves through them, figure by
    figure, and is cleared at the end."""
    import sys

    from conftest import CLEARED, Terminal
    from fitgen.app import cli

    folder = paper_fit[0]
    argv = ["report", str(folder / "m.json"), "--data", str(folder / "sim.csv"), "--plot", str(tmp_path / "p"),
            "--sensor", "paper", "-o", str(tmp_path / "r.md")]
    term = Terminal()
    monkeypatch.setattr(sys, "stderr", term)
    with pytest.raises(SystemExit) as stop:
        cli.main(argv)
    assert stop.value.code == 0, term.text
    bars = [t for t in term.text.split("\r") if t.startswith("plots [")]
    assert bars and "1/7" in bars[0] and "drawing estimate_dx.png" in bars[0], term.text  # at once: the first is slow
    assert "7/7" in bars[-1] and "drawing sweep_thy.png" in bars[-1]
    assert CLEARED in term.text and sorted(p.name for p in (tmp_path / "p").iterdir())[-1] == "sweep_thy.png"


@pytest.mark.parametrize("text, msg", [
    ("v1,v2,dx\n1,2,3\n", "at least"),  # a single row
    ("v1,v2,dx\n1,2,3\n1,abc,3\n", "line 3, column v2"),
    ("v1,v2,dx\n1,2,3\n1,nan,3\n", "not a finite number"),
    ("v1,v3,dx\n1,2,3\n1,2,3\n", "v1..vN"),
    ("v1,v2,dq\n1,2,3\n1,2,3\n", "unknown column"),
    ("v1,v2\n1,2\n3,4\n5,6\n", "no pose columns"),
    ("v1,v2,dx\n1,2\n3,4,5\n", "fields"),
    ("", "empty file (or a blank first line); a dataset is a CSV with the header v1,...,vN,dx,dy,dz,thx,thy"),
    ("v1,v2,dx\n\n,,\n", "a header and no data rows (a run stopped before its first row?); a dataset is a CSV with "
                          "the header v1,...,vN,dx,dy,dz,thx,thy, one row per line under it"),
])
def test_malformed_csv_one_line(tmp_path, text, msg):
    data = tmp_path / "d.csv"
    data.write_text(text)
    assert_one_line_error(run_cli("fitgen", "fit", str(data), "-o", str(tmp_path / "m.json")), contains=msg)
    assert not (tmp_path / "m.json").exists()


def test_more_terms_than_rows(tmp_path):
    ds = simulate(PAPER, random_poses(10, DEFAULT_RANGES, pose_rng(1)))
    ds.save(tmp_path / "small.csv")
    assert_one_line_error(run_cli("fitgen", "fit", str(tmp_path / "small.csv"), "-o", str(tmp_path / "m.json")),
                          contains="rows")


def test_terms_near_the_rows_are_said_and_an_unknown_noise_is_said_plainly(tmp_path):
    """A fit whose equations near the row count (a short capture, single samples, no noise known) says so;
    the report's line says what is not known in words, not 'unknown rms (unknown)'."""
    ds = simulate(PAPER, random_poses(37, DEFAULT_RANGES, pose_rng(3)))
    ds.meta = {"units": "mT", "source": "hardware", "samples_per_row": 1}
    path = ds.save(tmp_path / "c.csv", ds.meta)
    proc = run_cli("fitgen", "fit", str(path), "-o", str(tmp_path / "m.json"), "--held-out", "0")
    assert proc.returncode == 0, proc.stderr
    model = load_model(tmp_path / "m.json")
    worst = max(model.equations, key=lambda e: len(e.terms))
    assert len(worst.terms) + 1 > 37 / 3
    assert f"note: {worst.name} has {len(worst.terms)} terms on 37 rows" in proc.stderr
    rep = run_cli("fitgen", "report", str(tmp_path / "m.json"))
    assert ("fitted for: reading noise unknown (no --noise, no sensor, and the capture did not measure it), data's "
            "own noise not recorded (the rows taken to carry the device's own), added in expectation 0 mT (no device "
            "noise known)") in rep.stdout, rep.stdout
    big = run_cli("fitgen", "fit", str(tmp_path / "c.csv"), "-o", str(tmp_path / "m2.json"), "--held-out", "0",
                  "--max-terms", "5")
    assert big.returncode == 0 and "terms on 37 rows" not in big.stderr


def test_a_symmetric_scene_fits_without_false_alarms(tmp_path):
    """The press scene (dx, dy and tilt held at 0) read elements alike by the ring's symmetry, and its 21 rows
    carry dz's 10 terms: fit said 'one ADC channel read twice' and 'threads these rows' on the README's own
    command. Held out as trained, nothing is said; the same rows without a held-out figure are still warned of, and
    simulated rows off a scene name the symmetry, not the wiring."""
    data = tmp_path / "press.csv"
    assert run_cli("fitgen", "simulate", "--scene", "press", "-o", str(data)).returncode == 0
    proc = run_cli("fitgen", "fit", str(data), "-o", str(tmp_path / "p.json"))
    assert proc.returncode == 0, proc.stderr
    assert "note: v" not in proc.stderr and "terms on 21 rows" not in proc.stderr, proc.stderr
    proc = run_cli("fitgen", "fit", str(data), "-o", str(tmp_path / "p0.json"), "--held-out", "0")
    assert proc.returncode == 0 and "terms on 21 rows: it threads these rows" in proc.stderr, proc.stderr
    line = tmp_path / "line.csv"
    assert run_cli("fitgen", "simulate", "--grid", "dx=0 dy=0 dz=-2:0:25", "-o", str(line)).returncode == 0
    proc = run_cli("fitgen", "fit", str(line), "-o", str(tmp_path / "l.json"), "--outputs", "dz", "--held-out", "0")
    assert proc.returncode == 0, proc.stderr
    assert "v3 reads what v1 reads" in proc.stderr and "the simulated poses keep the magnet where" in proc.stderr
    assert "read twice" not in proc.stderr


def test_a_sensor_file_without_noise_is_said_not_fitted_silently_for_none(tmp_path):
    """A sensor file that leaves its noise out reads 0: the fit was the paper's noise-free procedure without a word,
    and its equations amplify the device's noise. It warns; --noise 0, which means it, does not."""
    import re
    from pathlib import Path

    text = (Path(__file__).resolve().parents[1] / "fitgen" / "physics" / "presets" / "paper.toml").read_text()
    quiet = tmp_path / "quiet.toml"
    quiet.write_text(re.sub(r"(?m)^noise\s*=.*\n", "", text).replace('name = "paper"', 'name = "quiet"'))
    data = tmp_path / "g.csv"
    proc = run_cli("fitgen", "simulate", "--sensor", str(quiet), "--grid", "dx=-2:2:5 dy=-2:2:5 dz=0,-1,-2", "-o",
                   str(data))
    assert proc.returncode == 0, proc.stderr
    fit = ("fitgen", "fit", str(data), "-o", str(tmp_path / "m.json"), "--outputs", "dx,dy,dz", "--held-out", "0")
    proc = run_cli(*fit)
    assert proc.returncode == 0 and "warning: sensor quiet gives no noise figure" in proc.stderr, proc.stderr
    proc = run_cli(*fit, "--noise", "0")
    assert proc.returncode == 0 and "warning" not in proc.stderr, proc.stderr


def test_the_papers_procedure_is_held_out_with_the_sensors_noise(tmp_path):
    """--noise 0 fits the data as given, noise-free, as the paper did; the device still reads the sensor's noise, and
    the deployed figures are with it (conventions.md). They were held out with none: the 'with noise' columns
    equalled the noise-free ones, and the paper's procedure looked fit for a device."""
    import json

    data = tmp_path / "g.csv"
    proc = run_cli("fitgen", "simulate", "--sensor", "paper", "--grid", "paper-sim", "-o", str(data))
    assert proc.returncode == 0, proc.stderr
    proc = run_cli("fitgen", "fit", str(data), "-o", str(tmp_path / "m.json"), "--noise", "0", "--held-out", "300",
                   "--outputs", "dx,dy,dz")
    assert proc.returncode == 0, proc.stderr
    rec = json.loads((tmp_path / "m.json").read_text())["fit"]["held_out"]
    assert rec["noise"] == PAPER.noise > 0 and "noise 0.0005 mT rms" in proc.stdout + proc.stderr
    for o in ("dx", "dy", "dz"):
        e = rec["errors"]["double"][o]
        assert e["noisy_rms"] > 1.02 * e["rms"], (o, e)  # held out with none, the two were equal


def test_rows_without_a_meta_are_held_out_on_the_sensor_in_their_units(tmp_path):
    """Readings in volts with no meta, --sensor paper --units V: the fit held them out on the paper preset's raw
    transfer (mT), and printed errors of metres and thousands of degrees; the data's units say which transfer."""
    import json

    data = tmp_path / "v.csv"
    proc = run_cli("fitgen", "simulate", "--sensor", "paper", "--transfer", "gmr", "--grid", "paper-sim", "-o",
                   str(data))
    assert proc.returncode == 0, proc.stderr
    (tmp_path / "v.csv.meta.json").unlink()
    proc = run_cli("fitgen", "fit", str(data), "--sensor", "paper", "--units", "V", "-o", str(tmp_path / "m.json"),
                   "--held-out", "200", "--outputs", "dx,dy,dz")
    assert proc.returncode == 0, proc.stderr
    rec = json.loads((tmp_path / "m.json").read_text())["fit"]["held_out"]
    assert rec["transfer"] == "gmr" and rec["noise"] == load_sensor("paper").with_transfer("gmr").noise
    assert all(e["max"] < 0.5 for e in rec["errors"]["double"].values()), rec["errors"]["double"]


def test_a_model_past_floats_range_runs_in_double_only(tmp_path):
    """Readings a billion times the sensor's give coefficients past float's range: a fit for float refuses them
    (or auto takes the family that runs in float), predict in float refuses as codegen does, double keeps them;
    rows edited after their meta was written are not held out on the meta's sensor."""
    import json

    ds = simulate(PAPER, grid_poses(PAPER_GRIDS["paper-sim"]))
    path = ds.save(tmp_path / "s.csv")
    meta = json.loads((tmp_path / "s.csv.meta.json").read_text())
    ds.inputs = ds.inputs * 1e9
    big = ds.save(tmp_path / "big.csv")
    (tmp_path / "big.csv.meta.json").unlink()
    proc = run_cli("fitgen", "fit", str(big), "-o", str(tmp_path / "m.json"), "--family", "all")
    assert_one_line_error(proc, 2, "does not fit in a float (|x| <= 3.4e+38): readings on another scale")
    assert "RuntimeWarning" not in proc.stderr and not (tmp_path / "m.json").exists()
    assert run_cli("fitgen", "fit", str(big), "-o", str(tmp_path / "d.json"), "--family", "all", "--precision",
                   "double").returncode == 0
    for prec, ok in (("float", False), ("double", True)):
        proc = run_cli("fitgen", "predict", str(tmp_path / "d.json"), str(big), "-o", str(tmp_path / "p.csv"),
                       "--precision", prec)
        assert (proc.returncode == 0) == ok and ("does not fit in a float" in proc.stderr) != ok, proc.stderr
    # auto on the sensor: the family whose equations run in float, and why
    proc = run_cli("fitgen", "fit", str(big), "-o", str(tmp_path / "a.json"), "--sensor", "paper", "--held-out", "50")
    assert proc.returncode == 0 and "RuntimeWarning" not in proc.stderr, proc.stderr
    fam = json.loads((tmp_path / "a.json").read_text())["fit"]["family"]
    assert fam["name"] == "harmonics" and fam["why"].startswith("the powers' equations cannot run in float")
    # the simulated meta kept beside rows edited since: its sensor is not taken to hold out on
    (tmp_path / "big.csv.meta.json").write_text(json.dumps(meta))
    proc = run_cli("fitgen", "fit", str(big), "-o", str(tmp_path / "e.json"), "--precision", "double")
    assert proc.returncode == 0 and "big.csv's rows are not the ones its meta was written for" in proc.stderr
    assert "held_out" not in json.loads((tmp_path / "e.json").read_text())["fit"]
    assert "rows are not the ones" not in run_cli("fitgen", "fit", str(path), "-o", str(tmp_path / "f.json"),
                                                  "--held-out", "0", "--family", "all").stderr


def test_bad_model_files(paper_fit, tmp_path):
    folder, _, _ = paper_fit
    data = json.loads((folder / "m.json").read_text())
    cases = {
        "version": ({**data, "schema_version": 2}, "schema_version 2"),
        "version-bool": ({**data, "schema_version": True}, "schema_version True is not supported"),  # True == 1
        # no sensor's pose: fixed codegen's bounds overflowed (a traceback), float's named no field
        "box": ({**data, "fit": {**data["fit"], "held_out": {**data["fit"].get("held_out", {}),
                                                             "box": {"dx": [-1e300, 1e300]}}}}, "within +-10000"),
        "term": ({**data, "outputs": [{**data["outputs"][0], "terms": ["v9^7"] + data["outputs"][0]["terms"][1:]}]},
                 "not a term"),
        "nan": ({**data, "outputs": [{**data["outputs"][0], "intercept": "NaN"}]}, "finite"),
        "units": ({**data, "inputs": {**data["inputs"], "units": "furlongs"}}, "inputs.units must be mT or V"),
        "meta": (json.loads((folder / "sim.csv.meta.json").read_text()), "not a model but a dataset's meta file"),
    }
    for name, (content, msg) in cases.items():
        path = tmp_path / f"{name}.json"
        path.write_text(json.dumps(content))
        assert_one_line_error(run_cli("fitgen", "predict", str(path), str(folder / "sim.csv"), "-o",
                                      str(tmp_path / "p.csv")), contains=msg)
    # the wrong file in each place: a folder for a model, a model for a dataset
    assert_one_line_error(run_cli("fitgen", "predict", str(folder), str(folder / "sim.csv"), "-o",
                                  str(tmp_path / "p.csv")), contains=f"model file {folder}: a folder, not a file")
    assert_one_line_error(run_cli("fitgen", "fit", str(folder / "m.json"), "-o", str(tmp_path / "x.json")),
                          contains="m.json: JSON, not CSV (a model, meta or noise file?); a dataset is a CSV with")
    # and for poses: what poses are (a noise record given to capture --poses had been told what a dataset is)
    assert_one_line_error(run_cli("fitgen", "simulate", "--poses", str(folder / "m.json"), "-o",
                                  str(tmp_path / "q.csv")),
                          contains="m.json: JSON, not CSV (a model, meta or noise file?); poses are a CSV with any of "
                                   "the columns dx,dy,dz,thx,thy, as fitgen schedule writes them")
    # a sensor or unit file for a dataset: fitgen simulate --unit writes one beside its data, which opens with a comment
    unit = tmp_path / "u.unit.toml"
    assert run_cli("fitgen", "simulate", "--unit", "3", "--random", "5", "-o", str(tmp_path / "u.csv")).returncode == 0
    for arg in (unit, "paper_bare.toml"):
        if arg == "paper_bare.toml":  # a table first, as a hand-written sensor file may open
            arg = tmp_path / arg
            arg.write_text('[magnet]\ndiameter = 5.0\n')
        assert_one_line_error(run_cli("fitgen", "fit", str(arg), "-o", str(tmp_path / "x.json")),
                              contains=f"{arg}: TOML, not CSV (a sensor or unit file? those go to --sensor)")
    (tmp_path / "junk.json").write_text("{not json")
    assert_one_line_error(run_cli("fitgen", "report", str(tmp_path / "junk.json")), contains="not valid JSON")
    # a dataset or a sensor file given where the model goes (predict's arguments swapped): named as what it is
    (tmp_path / "d.csv").write_text("v1,v2,dz\n1,2,3\n")
    (tmp_path / "s.toml").write_text("# a sensor, a comment with, commas\n[magnet]\ndiameter = 5.0\n")
    for name, said in (("d.csv", "CSV (a dataset?)"), ("s.toml", "TOML (a sensor file?)")):
        assert_one_line_error(run_cli("fitgen", "report", str(tmp_path / name)), 2,
                              f"model file {tmp_path / name}: {said}, not a model (JSON, as fitgen fit writes it)")
    with pytest.raises(InputError, match="needs v1 > 0"):
        bad = json.loads(json.dumps(data))
        bad["inputs"]["min"][0] = 0.0
        model_from_dict(bad)
    assert_one_line_error(run_cli("fitgen", "fit", str(folder / "sim.csv"), "-o", str(tmp_path / "x.json"),
                                  "--k", "-1"), contains="--k")
    assert_one_line_error(run_cli("fitgen", "fit", str(folder / "sim.csv"), "-o", str(tmp_path / "x.json"),
                                  "--outputs", "dq"), contains="--outputs")


def test_fit_by_blocks_of_rows_is_the_fit_of_all_rows(monkeypatch):
    """The candidate columns are built and compressed a block of rows at a time, the training error and
    Model.predict likewise: blocks of 97 rows give the equations of one block of all 1,500."""
    import fitgen.fitting.fit as fit_mod
    import fitgen.equations.model as model_mod

    ds = simulate(PAPER, random_poses(1500, DEFAULT_RANGES, pose_rng(11)))
    whole = fit_model(ds)
    monkeypatch.setattr(fit_mod, "ROWS", 97)
    monkeypatch.setattr(model_mod, "_ROWS", 97)
    blocks = fit_model(ds)
    for a, b in zip(whole.equations, blocks.equations):
        assert a.terms == b.terms, a.name
        np.testing.assert_allclose(b.coefficients, a.coefficients, rtol=1e-6, atol=1e-9)
    by_blocks = blocks.predict(ds.inputs)
    np.testing.assert_allclose(by_blocks, whole.predict(ds.inputs), atol=1e-9)
    monkeypatch.setattr(model_mod, "_ROWS", 10**9)
    np.testing.assert_array_equal(by_blocks, blocks.predict(ds.inputs))  # row by row arithmetic: bit-identical


def test_fit_on_a_capture_adds_the_single_sample_noise_less_the_rows(tmp_path):
    """Rows averaged over S samples carry the device's noise over sqrt(S): the fit adds what they lack, says
    why in the model file, and honours --noise; the device's noise is what the capture measured per sample,
    also when a drawing with another figure is given."""
    import json

    from conftest import run_cli
    from fitgen.physics.sensor import load_sensor
    from fitgen.physics.simulate import PAPER_GRIDS, grid_poses, simulate

    ds = simulate(load_sensor("paper").with_transfer("gmr"), grid_poses(PAPER_GRIDS["paper-exp"]))
    capture = {"units": "V", "source": "hardware", "samples_per_row": 16, "row_noise": [0.000125] * 8,
               "sample_noise": [0.0005] * 8}
    cases = [(capture, [], 0.0005, 0.000125), (capture, ["--noise", "0.001"], 0.001, 0.000125),
             ({k: v for k, v in capture.items() if k != "row_noise"}, [], 0.0005, 0.0005 / 4),
             ({"units": "V", "source": "hardware"}, ["--noise", "0.001"], 0.001, None),
             # a unit noisier than its drawing: what the capture measured wins over the drawing's figure
             ({**capture, "sample_noise": [0.001] * 8, "row_noise": [0.00025] * 8}, ["--sensor", "paper"], 0.001,
              0.00025)]
    for i, (meta, extra, device, data) in enumerate(cases):
        ds.meta = dict(meta)
        path = ds.save(tmp_path / f"c{i}.csv", meta)
        proc = run_cli("fitgen", "fit", str(path), "-o", str(tmp_path / f"m{i}.json"), "--held-out", "0",
                       "--family", "no-roots", *extra)
        assert proc.returncode == 0, proc.stderr
        noise = json.loads((tmp_path / f"m{i}.json").read_text())["fit"]["noise"]
        assert noise["device"] == pytest.approx(device) and (noise["data"] == pytest.approx(data) if data else
                                                             noise["data"] is None)
        expected = np.sqrt(device**2 - data**2) if data else 0.0
        assert noise["added"] == pytest.approx(expected), noise
        assert noise["why"]
        if "sample_noise" in meta and not extra[:1] == ["--noise"]:
            assert noise["device_source"] == "measured by the capture (single samples)"


@pytest.mark.parametrize("argv, work", [
    (["fit", "{data}", "-o", "{out}"], "fitgen.app.cli.cmd_fit"),
    (["identify", "{data}", "-o", "{out}"], "fitgen.app.calibrate_cli.cmd_identify"),
    (["schedule", "--n", "10", "-o", "{out}"], "fitgen.app.calibrate_cli.cmd_schedule"),
    (["simulate", "--random", "5", "-o", "{out}"], "fitgen.app.cli.cmd_simulate"),
    (["predict", "{model}", "{data}", "-o", "{out}"], "fitgen.app.cli.cmd_predict"),
    (["report", "{model}", "-o", "{out}"], "fitgen.app.cli.cmd_report"),
])
def test_an_output_in_a_missing_folder_is_said_before_the_work(argv, work, tmp_path, monkeypatch, capsys):
    from importlib import import_module

    from fitgen.app import cli

    # the command must not run (build_parser binds the patched one, where it is defined and where cli's check of
    # the output names it): its work would come before the write
    module, name = work.rsplit(".", 1)
    ran = lambda args: pytest.fail(f"{work} ran")  # noqa: E731
    for where in {import_module(module), cli}:
        monkeypatch.setattr(where, name, ran)
    names = {"data": str(tmp_path / "d.csv"), "model": str(tmp_path / "m.json"), "out": str(tmp_path / "no" / "x")}
    with pytest.raises(SystemExit) as stop:
        cli.main([a.format(**names) for a in argv])
    assert stop.value.code == 2 and f"folder {tmp_path / 'no'} does not exist" in capsys.readouterr().err


def test_a_penalty_past_any_datasets_is_refused_and_the_largest_taken_prints_in_a_few_digits(tmp_path):
    """--k 1e300 printed each equation's AIC as a 300-digit number (then as 1e+300) for a model of no terms, and
    1e308 ended in 'the model holds a non-finite number'; past 100 (BIC's at 10^43 rows) it is refused."""
    data = tmp_path / "press.csv"
    assert run_cli("fitgen", "simulate", "--scene", "press", "-o", str(data)).returncode == 0
    for k in ("1e300", "1e308", "100.5"):
        proc = run_cli("fitgen", "fit", str(data), "--k", k, "--held-out", "0", "-o", str(tmp_path / "m.json"))
        assert_one_line_error(proc, 2, f"--k must be a number > 0 and at most 100, got {k}")
        assert not (tmp_path / "m.json").exists()
    proc = run_cli("fitgen", "fit", str(data), "--k", "100", "--held-out", "0", "-o", str(tmp_path / "m.json"))
    assert proc.returncode == 0, proc.stderr
    line = next(ln for ln in (proc.stdout + proc.stderr).splitlines() if ln.startswith("dz: "))
    crit, value = line.split(",")[1].strip().rsplit(" ", 1)  # "AIC (k = 100) 38.64"
    assert crit == "AIC (k = 100)" and len(value) <= 10, line
    proc = run_cli("fitgen", "tradeoff", "paper", "--scene", "press", "--k", "1e308", "-o", str(tmp_path / "t"))
    assert_one_line_error(proc, 2, "--k takes aic, bic or numbers > 0 and at most 100, got '1e308'")
