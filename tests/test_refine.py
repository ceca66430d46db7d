"""The refinement (fitgen.equations.refine): Gauss-Newton steps on a fitted forward model after the equations,
through the fit, the model file, the generated C (gcc, bit for bit), verify, the refusals, the cost
model and the firmware on the emulated Cortex-M4."""

import dataclasses
import json
import subprocess

import numpy as np
import pytest

from fitgen.c.calblob import to_blob
from fitgen.c.codegen import render_header
from fitgen.base.errors import InputError
from fitgen.fitting.fit import FitSettings, fit_model
from fitgen.fitting.holdout import box_of, held_out_set
from fitgen.equations.model import load_model, model_from_dict
from fitgen.physics.pose import POSE_NAMES
from fitgen.equations.rounding import U_FLOAT, error_bound
from fitgen.equations.refine import ForwardEquation
from fitgen.fitting.refine_fit import fit_forward, monomial_exponents
from fitgen.physics.sensor import load_sensor
from fitgen.physics.simulate import PAPER_GRIDS, grid_poses, pose_rng, random_poses, simulate
from fitgen.c.compiled import CompiledModel
from fitgen.c.cost import template_ops
from fitgen.c.verify import compare

from conftest import assert_c_equals_python, assert_one_line_error, emulated_suite, require_tool, run_cli

PAPER = load_sensor("paper")
GRID = grid_poses(PAPER_GRIDS["paper-sim"])
BOX = box_of(GRID)


@pytest.fixture(scope="module")
def train():
    # the grid has 3 levels of dz: random poses give the forward model the rest of the box
    return simulate(PAPER, np.vstack([GRID, random_poses(3000, BOX, pose_rng(1))]))


@pytest.fixture(scope="module")
def model(train):
    return fit_model(train, settings=FitSettings.family("all", max_terms=12, refine=2, refine_terms=12), sensor=PAPER)


@pytest.fixture(scope="module")
def held():
    return held_out_set(PAPER, BOX, POSE_NAMES, n=500, draws=2)


def _extremes(held):
    rng = np.random.default_rng(3)
    return np.vstack([held.clean[:200], held.noisy[:200], held.clean[:30] * 3, held.clean[:30] * 0.1,
                      held.clean[:30] * -2, np.full((1, 8), np.nan), rng.normal(0, 1e6, (20, 8))])


def test_refinement_beats_its_own_equations_on_held_out_poses(model, held):
    base = dataclasses.replace(model, refine=None)
    for readings, truth, precision in ((held.clean, held.truth, "double"), (held.noisy, held.noisy_truth, "float")):
        rms = {}
        for name, m in (("equations", base), ("refined", model)):
            err = m.predict(readings, precision=precision) - truth
            rms[name] = np.sqrt(np.mean(err**2, axis=0))
        # displacements: the forward model knows what the readings say; at least 1.25x better
        assert np.all(rms["refined"][:3] < 0.8 * rms["equations"][:3]), rms
    info = model.fit_info["refine"]
    assert info["transform"] == "cbrt" and max(info["terms"]) <= 12 and info["steps"] == 2
    # the prior couples slide and tilt: the equations' errors in dx and thy are correlated
    assert abs(info["prior_correlation"][0][4]) > 0.2


def test_forward_model_predicts_the_readings(model, held):
    pred = model.refine.forward_values(held.truth)
    rel = np.abs(pred - held.clean) / held.clean
    assert np.median(rel) < 2e-3, np.median(rel)
    assert len(monomial_exponents(5)) == 251 and monomial_exponents(2)[:5] == [
        (1, 0, 0, 0, 0), (0, 1, 0, 0, 0), (0, 0, 1, 0, 0), (0, 0, 0, 1, 0), (0, 0, 0, 0, 1)]


def test_the_forward_model_takes_no_exchanges_at_the_cap(held):
    """At the cap, the search's exchanges traded the forward model's terms for dx^5 and dz^3, which fit the grid's
    three levels of dz as well: between them its readings were 3 % off (median), and refined poses 3-10x worse."""
    forward = fit_forward(simulate(PAPER, GRID))
    assert max(len(eq.exponents) for eq in forward.refinement.forward) == forward.max_terms  # at the cap
    rel = np.abs(forward.refinement.forward_values(held.truth) - held.clean) / held.clean
    assert np.median(rel) < 2e-3, np.median(rel)


def test_a_refinement_worse_than_its_equations_on_the_rows_is_said(tmp_path):
    """A forward model of 5 terms per element under equations capped at 1 term pulled thy's estimate further off
    (training RMS 3.8 against the equations' 3.45 deg), and the note called the refined estimate "the equation"."""
    data, out = tmp_path / "g.csv", tmp_path / "m.json"
    simulate(PAPER, GRID).save(data)
    proc = run_cli("fitgen", "fit", str(data), "-o", str(out), "--refine", "1", "--refine-terms", "5", "--max-terms",
                   "1", "--held-out", "0")
    assert proc.returncode == 0, proc.stderr
    info = load_model(out).fit_info["outputs"]
    worse = {o for o, i in info.items()
             if i["model_training_error"]["rms"] > 1.05 * i["equations_training_error"]["rms"]}
    said = {ln.split()[4] for ln in proc.stderr.splitlines() if ln.startswith("note: the refinement leaves")}
    assert worse and said == worse, (said, worse)
    assert "'s refined estimate leaves" in proc.stderr and "'s equation leaves" not in proc.stderr


def test_generated_c_is_python_bit_for_bit(model, held):
    x = _extremes(held)
    assert_c_equals_python(model, x)
    with CompiledModel(model, "double", "unrolled", fma=True) as cm:
        out, _ = cm.predict(x)
    np.testing.assert_array_equal(out, model.predict(x, fma=True))
    text = render_header(model, "float", "table")
    assert "tm_refine(x, out);" in text and "pow(" not in text.replace("never pow()", "") and "malloc" not in text


def test_verify_holds_the_c_to_the_emulation(model, held):
    require_tool("gcc")
    x = _extremes(held)
    with CompiledModel(model, "float", "table") as cm:
        res = compare(model, cm, x, held_out=(held.clean, held.truth))
    assert res.ok, res.failures
    # another refinement compiled in: verify sees it
    other = dataclasses.replace(model, refine=dataclasses.replace(model.refine, steps=1))
    with CompiledModel(other, "float", "table") as cm:
        res = compare(model, cm, x)
    assert not res.ok and "bit for bit" in res.failures[0]
    with pytest.raises(InputError, match="refinement"):
        error_bound(model, held.clean, U_FLOAT)


def test_identity_transform_when_a_reading_is_not_positive(train):
    v = train.inputs.copy()
    v[:, 2] -= v[:, 2].min() + 0.05  # element 3 reads <= 0 somewhere: no v^(-1/3)
    ds = type(train)(v, train.targets, train.target_names, train.meta)
    m = fit_model(ds, settings=FitSettings.family("integer", max_terms=8, refine=1, refine_terms=8), sensor=PAPER)
    assert m.refine.transform == "identity"
    assert_c_equals_python(m, np.vstack([v[::40], v[:10] * 5]))


def test_a_step_that_cannot_be_taken_keeps_the_pose(model, held):
    require_tool("gcc")
    r = model.refine
    # t_k = -1 everywhere: 1 / t^3 is not a reading, so no step is taken
    bad = dataclasses.replace(r, forward=tuple(ForwardEquation(-1.0, eq.exponents, (0.0,) * len(eq.exponents))
                                               for eq in r.forward))
    m = dataclasses.replace(model, refine=bad)
    base = dataclasses.replace(model, refine=None)
    x = held.clean[:50]
    np.testing.assert_array_equal(m.predict(x), base.predict(x))
    with CompiledModel(m, "double", "table") as cm:
        np.testing.assert_array_equal(cm.predict(x)[0], base.predict(x))


def test_model_file_round_trip_and_validation(model, tmp_path):
    path = model.save(tmp_path / "r.json")
    back = load_model(path)
    assert back.refine == model.refine and back.sha256 == model.sha256
    assert dataclasses.replace(model, refine=None).sha256 != model.sha256
    data = json.loads(path.read_text())
    cases = [
        (lambda d: d["refine"].__setitem__("steps", 0), "steps must be an integer"),
        (lambda d: d["refine"].__setitem__("transform", "log"), "transform must be one of"),
        (lambda d: d["refine"]["prior_precision"][0].__setitem__(1, 1.0), "symmetric 5x5"),
        (lambda d: d["refine"]["forward"].pop(), "one equation per input"),
        (lambda d: d["refine"]["forward"][0]["exponents"].__setitem__(0, [0, 0, 0, 0, 0]), "not 5 powers"),
        (lambda d: d["refine"]["forward"][0]["exponents"][0].__setitem__(0, [1]), "not 5 powers"),
        (lambda d: d["refine"]["prior_precision"].__setitem__(0, []), "symmetric 5x5"),
        # flat: it is a list of numbers, which the line had said it must be
        (lambda d: d["refine"].__setitem__("prior_precision", [0.0] * 5), "prior_precision must be a matrix"),
        (lambda d: d["refine"]["forward"][0]["coefficients"].pop(), "exponents but"),
        (lambda d: d["refine"].__setitem__("pose_max", d["refine"]["pose_min"]), "pose_min < pose_max"),
        (lambda d: d["refine"]["weights"].__setitem__(0, -1.0), "weights must be > 0"),
        (lambda d: d["refine"].__setitem__("weights", "x"), "must be a list"),
        (lambda d: d["outputs"].pop(), "needs the outputs"),
    ]
    for change, msg in cases:
        d = json.loads(json.dumps(data))
        change(d)
        with pytest.raises(InputError, match=msg):
            model_from_dict(d, "m")


def test_absurd_refinement_numbers_are_refused_where_the_estimates_would_be_nonsense(model, train, tmp_path):
    # a fitted refinement sits far inside the bounds, so they refuse only what no fit writes
    bound = np.maximum(np.abs(model.input_min), np.abs(model.input_max))
    assert 0 < model.refine.magnitude(bound) < 1e10
    data = json.loads(model.save(tmp_path / "r.json").read_text())
    rows = tmp_path / "rows.csv"
    train.save(rows)
    n_forward = len(data["refine"]["forward"][0]["coefficients"])
    cases = [  # (change, precision, message): each had predicted a pose with status 0
        (lambda r: r.__setitem__("weights", [1e308] * len(r["weights"])), "double", "steps reach inf"),
        (lambda r: r["forward"][0].__setitem__("coefficients", [1e300] * n_forward), "double", "over the double limit"),
        (lambda r: r.__setitem__("prior_precision", (1e200 * np.eye(5)).tolist()), "double", "steps reach 1e+200"),
        (lambda r: r["weights"].__setitem__(0, 1e39), "float", "over the float limit"),
        (lambda r: r.__setitem__("pose_max", [1e308] * 5), "double", "must lie within -1000..1000 mm"),
    ]
    for change, precision, msg in cases:
        d = json.loads(json.dumps(data))
        change(d["refine"])
        bad = tmp_path / "bad.json"
        bad.write_text(json.dumps(d))
        out = tmp_path / "p.csv"
        proc = run_cli("fitgen", "predict", str(bad), str(rows), "-o", str(out), "--precision", precision)
        assert_one_line_error(proc, contains=msg)
        assert not out.exists()
    # the one weight past float's range is still a model in double, and is refused in float by codegen too
    d = json.loads(json.dumps(data))
    d["refine"]["weights"][0] = 1e39
    bad.write_text(json.dumps(d))
    assert run_cli("fitgen", "predict", str(bad), str(rows), "-o", str(tmp_path / "p.csv")).returncode == 0
    proc = run_cli("fitgen", "codegen", str(bad), "-o", str(tmp_path / "gen"), "--precision", "float")
    assert_one_line_error(proc, contains="refine: a weight, prior or forward coefficient of 1e+39 does not fit in a "
                                         "float")
    # data past the pose limits are refused by the fit, which would write a refinement the loader refuses
    targets = train.targets.copy()
    targets[:, train.target_names.index("thy")] *= 1e3
    far = dataclasses.replace(train, targets=targets)
    with pytest.raises(InputError, match="--refine: the data's poses: thy"):
        fit_model(far, settings=FitSettings.family("all", max_terms=5, refine=1, refine_terms=5), sensor=PAPER)


def test_blobs_and_fixed_point_refuse_in_one_line(model, tmp_path):
    with pytest.raises(InputError, match="no refinement"):
        to_blob(model)
    path = model.save(tmp_path / "r.json")
    proc = run_cli("fitgen", "codegen", str(path), "-o", str(tmp_path / "gen"), "--precision", "fixed",
                   "--input-lsb", "1e-4")
    assert_one_line_error(proc)
    assert not (tmp_path / "gen" / "tm_model.h").exists()


def test_the_steps_are_counted(model):
    extra = template_ops(model, "unrolled") - template_ops(dataclasses.replace(model, refine=None), "unrolled")
    steps = model.refine.steps
    assert extra["sqrt"] == 5 * steps
    assert extra["mul"] >= steps * 6 * model.refine.n_terms
    assert extra["div"] >= steps * (2 * model.n_inputs + 10)


def test_cli_fit_predict_codegen_and_bad_input(tmp_path, train):
    data = tmp_path / "train.csv"
    train.save(data)
    out = tmp_path / "m.json"
    proc = run_cli("fitgen", "fit", str(data), "-o", str(out), "--family", "all", "--max-terms", "8", "--refine", "1",
                   "--refine-terms", "8", "--held-out", "200")
    assert proc.returncode == 0, proc.stderr
    m = load_model(out)
    assert m.refine is not None and m.refine.steps == 1 and max(len(e.exponents) for e in m.refine.forward) <= 8
    held = m.fit_info["held_out"]["errors"]
    assert "refine" in m.fit_info and held["float"]["dx"]["noisy_rms"] > 0
    proc = run_cli("fitgen", "codegen", str(out), "-o", str(tmp_path / "gen"), "--precision", "float")
    assert proc.returncode == 0, proc.stderr
    assert "tm_refine" in (tmp_path / "gen" / "tm_model.h").read_text()
    for args, msg in ((["--refine", "9"], "0 (none) to 8"), (["--refine", "1", "--refine-terms", "3"], ">= 5"),
                      (["--refine", "1", "--outputs", "dx"], "whole pose")):
        proc = run_cli("fitgen", "fit", str(data), "-o", str(tmp_path / "bad.json"), "--family", "all", *args)
        assert_one_line_error(proc, contains=msg)
        assert not (tmp_path / "bad.json").exists()


def test_data_that_never_move_a_component_are_refused(tmp_path):
    flat = simulate(PAPER, grid_poses({"dx": [-1, 0, 1], "dy": [-1, 0, 1], "dz": [0, -1, -2], "thx": [-5, 0, 5],
                                       "thy": [0]}))
    data = tmp_path / "flat.csv"
    flat.save(data)
    proc = run_cli("fitgen", "fit", str(data), "-o", str(tmp_path / "m.json"), "--family", "all", "--max-terms", "5",
                   "--refine", "1", "--held-out", "0")
    assert_one_line_error(proc, contains="thy never varies")
    assert not (tmp_path / "m.json").exists()


def test_full_suite_on_emulated_cortex_m4(model, held):
    res = emulated_suite(model, (held.clean, held.truth), "table", n=300)
    assert res.ok, res.table()
    assert {"eval", "held-out accuracy", "flash", "fuzz"} <= {c.name for c in res.checks}


def test_auto_fits_the_forward_model_once_and_refines_as_the_chosen_family_would(train, monkeypatch):
    """`--family auto --refine`: the forward model depends on the data alone, so both families share one fit,
    and the kept model's refinement is the one fitting that family directly gives (its prior, from the
    equations' residuals, to rounding: the families share their compressed rows, fitgen.fitting.shared)."""
    import fitgen.fitting.refine_fit as refine_fit
    from fitgen.fitting.family import fit_auto

    calls = []
    real = refine_fit.fit_forward
    monkeypatch.setattr(refine_fit, "fit_forward", lambda *a, **k: calls.append(1) or real(*a, **k))
    settings = FitSettings(max_terms=8, refine=1, refine_terms=8)
    model, family = fit_auto(train, None, settings, PAPER)
    assert len(calls) == 1
    direct = fit_model(train, settings=settings.with_family(family["name"]), sensor=PAPER)
    assert len(calls) == 2  # the direct fit fits its own
    assert [e.terms for e in model.equations] == [e.terms for e in direct.equations]
    prior, direct_prior = np.array(model.refine.prior), np.array(direct.refine.prior)
    scale = np.sqrt(np.outer(np.diag(direct_prior), np.diag(direct_prior)))
    assert np.all(np.abs(prior - direct_prior) <= 1e-12 * scale)
    assert dataclasses.replace(model.refine, prior=direct.refine.prior) == direct.refine
    with pytest.raises(ValueError, match="other data"):
        refine_fit.fit_refinement(simulate(PAPER, GRID), model, steps=1, noise=0.0005, max_terms=8,
                                  forward=refine_fit.fit_forward(train, max_terms=8))


def test_codegen_for_the_uno_refuses_a_refinement_in_one_line(model, tmp_path):
    """Its forward model's tables and solve do not fit the ATmega328P: refused, not written to fail in avr-gcc."""
    with pytest.raises(InputError, match="target uno: a refinement's forward model and solve do not fit"):
        render_header(model, "float", "table", target="uno")
    render_header(model, "float", "table", target="mps2")  # a core with room: written as ever
    proc = run_cli("fitgen", "codegen", str(model.save(tmp_path / "r.json")), "-o", str(tmp_path / "u"),
                   "--target", "uno", "--precision", "float")
    assert_one_line_error(proc, 2, "fit without --refine")
    assert not (tmp_path / "u").exists()
    # predict computes what codegen writes: it printed the uno's estimates for a header codegen refuses
    data = simulate(PAPER, GRID[:20]).save(tmp_path / "d.csv")
    assert_one_line_error(run_cli("fitgen", "predict", str(tmp_path / "r.json"), str(data), "--target", "uno",
                                  "--precision", "float", "-o", str(tmp_path / "e.csv")), 2, "fit without --refine")


def test_the_prefixes_refused_as_clashing_are_the_words_the_headers_share(model, train, tmp_path):
    """tm and tm_status in one program: each header defined TM_STATUS_NONFINITE (tm_r and tm_r_term alike). The
    refused words are read here from headers of every kind, so a template's new name cannot slip past the list."""
    import re

    from fitgen.c.cgen import CLASHING_TAILS

    plain = fit_model(train, settings=FitSettings.family("integer", max_terms=8))
    texts = [render_header(m, p, s, "tm", fma=f) for m in (model, plain) for p in ("double", "float")
             for s in ("table", "unrolled") for f in (False, True)]  # one text for every core
    texts.append(render_header(plain, "fixed", target="uno"))
    texts.append(render_header(plain, "fixed"))
    names = {n[3:] for text in texts for n in re.findall(r"\b(?:tm|TM)_\w+", text)}
    shared = {}  # case kept: TM_RD_REAL (a macro) and tm_rd_real (tm_rd's real type) are two names
    for a in names:
        for b in names:
            if a.endswith("_" + b):
                shared.setdefault(a[:-len(b) - 1].lower(), set()).add(a)
    assert set(shared) == set(CLASHING_TAILS) and all(CLASHING_TAILS[w] in shared[w] for w in shared)
    path = model.save(tmp_path / "m.json")
    for prefix, both in (("tm_status", "TM_STATUS_NONFINITE"), ("tm_r", "tm_r_term"),
                         ("x_require", "X_REQUIRE_GENERATOR_VERSION_NUM")):
        assert_one_line_error(run_cli("fitgen", "codegen", str(path), "-o", str(tmp_path / "c"), "--prefix", prefix),
                              2, f"({both} is both headers')")
    # the peer: two headers of prefixes the check lets through compile side by side in one program
    require_tool("gcc")
    for prefix in ("tm", "tm_stat", "tm_rd"):
        assert run_cli("fitgen", "codegen", str(path), "-o", str(tmp_path / "c"), "--prefix", prefix,
                       "--precision", "float").returncode == 0
    (tmp_path / "c" / "both.c").write_text(
        '#include "tm_model.h"\n#include "tm_stat_model.h"\n#include "tm_rd_model.h"\n'
        "int main(void) { return TM_N_INPUTS + TM_STAT_N_INPUTS + TM_RD_N_INPUTS == 24 ? 0 : 1; }\n")
    proc = subprocess.run(["gcc", "-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "both.c", "-lm",
                           "-o", "both"], cwd=tmp_path / "c", capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    assert subprocess.run([str(tmp_path / "c" / "both")]).returncode == 0


def test_bench_counts_a_whole_step_on_readings_a_pose_gives(train, held):
    """BENCH's built-in vectors move each input apart from the others: readings no pose gives, on which a
    refinement's step can stop part-way (its forward model undefined at the equations' far-off estimate), so that
    bench/refine_cost.py had timed the step it gave up. Given readings, BENCH cycles through those: on readings of
    poses in the box every step is whole, and costs at least its operations; on rows where Python's step gives up,
    less by more than those."""
    require_tool("qemu-system-arm")
    require_tool("arm-none-eabi-gcc")
    from hil.emulate import bench_instructions, start_target
    from host.device import Device

    model = fit_model(train, settings=FitSettings.family("harmonics", max_terms=12, refine=1, refine_terms=12),
                      sensor=PAPER)
    base = dataclasses.replace(model, refine=None)
    lo, hi = np.array(model.input_min), np.array(model.input_max)
    # ~150 rows of these stop part-way: room for another machine's fit (BLAS kernels move its last bits) to stop fewer
    swept = lo + (hi - lo) * np.random.default_rng(0).random((20000, model.n_inputs))
    stops = np.all(model.predict(swept, precision="float") == base.predict(swept, precision="float"), axis=1)
    taken, given_up = held.clean[:16], swept[stops][:16]
    assert len(given_up) == 16 and not np.any(np.all(
        model.predict(taken, precision="float") == base.predict(taken, precision="float"), axis=1))
    step = sum((template_ops(model, "table") - template_ops(base, "table")).values())
    cost = {}
    for name, rows in (("taken", taken), ("given up", given_up)):
        for m in (base, model):
            with start_target(m, "mps2", style="table", bench_inputs=rows) as emu:
                with Device.open(emu.url, timeout=5) as dev:
                    cost[name, m is model] = bench_instructions(dev)["instructions"]
    whole, part = (cost[name, True] - cost[name, False] for name in ("taken", "given up"))
    assert whole >= step and part < whole - step, (whole, step, part)  # a step's table loops: 7x its operations
    with pytest.raises(InputError, match="1..16 rows of the model's 8 inputs"):
        start_target(model, "mps2", bench_inputs=taken[:, :4])
