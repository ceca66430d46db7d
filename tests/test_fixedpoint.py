"""Fixed-point generation (integer ADC codes in, int32 out, no floating point): the C against the numpy
model of the same integer arithmetic, against double within the plan's bound, and the plan's proof."""

import json
import re
import subprocess
from dataclasses import replace

import numpy as np
import pytest

from fitgen.c.codegen import render_fixed_header, render_header, write_header
from fitgen.base.errors import InputError
from fitgen.fitting.fit import FitSettings, fit_model
from fitgen.equations.fixedpoint import BUDGET, INT32_MAX, INT32_MIN, build_fixed
from fitgen.equations.inputscale import default_input_scale, sensor_input_scale
from fitgen.equations.model import Equation, Model
from fitgen.physics.sensor import load_sensor
from fitgen.physics.simulate import PAPER_GRIDS, grid_poses, simulate
from fitgen.equations.terms import FAMILIES, Term
from fitgen.c.compiled import CompiledModel, compile_checked
from fitgen.c.verify import make_code_vectors, verify

from conftest import assert_one_line_error, require_tool, run_cli, verify_on_arm_linux

M0 = ["-mcpu=cortex-m0", "-mthumb", "-mfloat-abi=soft"]


@pytest.fixture(scope="module")
def paper_fixed_model():
    """The paper sensor in volts (16-bit ADC), fitted with integer powers only, the paper's way (the
    planner's figures below are this model's; tests/test_deployed.py covers the device's fit)."""
    ds = simulate(load_sensor("paper").with_transfer("gmr"), grid_poses(PAPER_GRIDS["paper-sim"]))
    return fit_model(ds, settings=FitSettings.exact(exponents=FAMILIES["no-roots"]))


@pytest.fixture(scope="module")
def plan(paper_fixed_model):
    lsb, off, _ = default_input_scale(paper_fixed_model)
    return build_fixed(paper_fixed_model, lsb, off)


@pytest.fixture(scope="module")
def compiled(paper_fixed_model):
    require_tool("gcc")
    with CompiledModel(paper_fixed_model, "fixed", cflags=["-Wconversion", "-Wsign-conversion"]) as cm:
        yield cm


def every_kind_model() -> Model:
    """Every integer power of every element, d-terms and v*d products, an element whose domain
    crosses zero (positive powers only there), coefficients over many decades."""
    rng = np.random.default_rng(7)
    lo = np.array([0.05, 0.5, -1.5, 2.0])
    hi = np.array([3.0, 2.5, 1.0, 40.0])

    def eq(name, terms, low, high):
        mags = 10 ** rng.uniform(low, high, len(terms))
        coefs = tuple(float(c) for c in rng.choice([-1, 1], len(terms)) * mags)
        return Equation(name, float(rng.normal()), tuple(terms), coefs)

    exps = ("1", "2", "3", "4", "-1", "-2", "-3", "-4")
    powers = [Term(k, e) for k in (1, 2, 4) for e in exps] + [Term(3, e) for e in ("1", "2", "3", "4")]
    d_terms = [Term(mult=d) for d in ("dx", "dy", "dz")] + [Term(k, "1", d) for k in (1, 2, 3, 4) for d in ("dx", "dz")]
    return Model(lo, hi, (eq("dx", powers[:14], -4, 0), eq("dy", powers[14:], -6, -2), eq("dz", powers[::3], -5, -1),
                          eq("thx", d_terms, -3, 0), eq("thy", powers[1::2] + d_terms[:4], -5, -1)), "V")


# --- the C against the numpy integer model ---------------------------------------------------------


def test_c_equals_numpy_integer_model(compiled, plan):
    codes, kinds = make_code_vectors(plan, n_random=3000, seed=1)
    assert "corner" in kinds and kinds.count("corner") == 2**8
    assert np.any(codes == INT32_MIN) and np.any(codes == INT32_MAX)
    out, status = compiled.predict_codes(codes)
    ref, ref_status = plan.predict_codes(codes)
    assert np.array_equal(status, ref_status)
    # the same integer operations in the same order: exact, not merely within 1 LSB
    assert np.array_equal(out, ref)
    assert out.dtype == np.int64 and np.all(np.abs(out) <= INT32_MAX)


def test_status_and_clamping_in_codes(compiled, plan):
    lo, hi = np.array(plan.code_min), np.array(plan.code_max)
    mid = (lo + hi) // 2
    rows = np.vstack([mid, lo, hi, mid, mid, mid, mid])
    rows[3, 0] = lo[0] - 1
    rows[4, 7] = hi[7] + 1
    rows[5, :] = INT32_MIN
    rows[6, 2] = INT32_MAX
    out, status = compiled.predict_codes(rows)
    assert status.tolist() == [0, 0, 0, 1, 1 << 7, 255, 1 << 2]
    # a clamped code gives the answer of the domain's edge
    edge = rows[3].copy()
    edge[0] = lo[0]
    assert np.array_equal(compiled.predict_codes(edge[None, :])[0][0], out[3])
    assert np.array_equal(out[5], compiled.predict_codes(lo[None, :])[0][0])


def test_code_domain_matches_value_domain(paper_fixed_model, plan):
    # the model was fitted on 16-bit codes: its domain is a whole number of codes, kept exactly
    vals = plan.input_offset + plan.input_lsb * np.array(plan.code_min, dtype=float)
    assert np.allclose(vals, paper_fixed_model.input_min, rtol=1e-12, atol=0)
    vals = plan.input_offset + plan.input_lsb * np.array(plan.code_max, dtype=float)
    assert np.allclose(vals, paper_fixed_model.input_max, rtol=1e-12, atol=0)
    # otherwise rounded inward: every code inside has its value inside the model's domain
    m = Model(paper_fixed_model.input_min + 0.3e-4, paper_fixed_model.input_max - 0.3e-4,
              paper_fixed_model.equations, "V")
    fm = build_fixed(m, plan.input_lsb)
    assert np.all(fm.input_lsb * np.array(fm.code_min) >= m.input_min)
    assert np.all(fm.input_lsb * np.array(fm.code_max) <= m.input_max)
    assert np.all(fm.input_lsb * (np.array(fm.code_min) - 1) < m.input_min)


# --- against double ---------------------------------------------------------------------------------


def test_against_double_within_bound(paper_fixed_model, plan):
    require_tool("gcc")
    res = verify(paper_fixed_model, "fixed", "unrolled", n_random=2000, seed=2)
    assert res.ok, res.failures
    assert np.all(res.max_lsb_diff == 0)
    assert np.all(res.max_ratio <= 1.0)
    # the bound is not vacuous: the measured error reaches a visible part of it ...
    assert np.min(res.max_ratio) > 0.05
    # ... and it is small in the outputs' units
    bound = dict(zip(plan.output_names, plan.error_bound()))
    assert bound["dx"] < 1e-6 and bound["dy"] < 1e-6 and bound["dz"] < 1e-4
    assert bound["thx"] < 2e-3 and bound["thy"] < 2e-3


def test_every_kind_offset_and_negative_domain():
    """A non-integral offset (u in Q(f) with f > 0), an odd LSB, all integer powers, d-terms."""
    require_tool("gcc")
    model = every_kind_model()
    res = verify(model, "fixed", "unrolled", n_random=1500, input_lsb=1.7e-4, input_offset=-0.123456789)
    assert res.ok, res.failures
    assert np.all(res.max_lsb_diff == 0)
    fm = build_fixed(model, 1.7e-4, -0.123456789)
    assert fm.op("u1").frac_bits > 0  # the offset is not a whole number of codes
    assert fm.op("u3").lo < 0 < fm.op("u3").hi
    assert {op.kind for op in fm.ops} == {"input", "mul", "recip", "init", "term", "out"}


# --- the proof -------------------------------------------------------------------------------------


def _check_trace(fm, codes):
    out, _, tr = fm.predict_codes(codes, trace=True)
    out_x, _, tr_x = fm.predict_codes(codes, trace=True, exact=True)
    # the int64 evaluation never wrapped around: it equals the evaluation on unbounded integers
    assert np.array_equal(out, out_x.astype(np.int64))
    for op in fm.ops:
        # the plan's claims lie inside the budgets ...
        assert -BUDGET[op.bits] <= op.lo <= op.hi <= BUDGET[op.bits], op
        assert -BUDGET[64] <= op.wide_lo <= op.wide_hi <= BUDGET[64], op
        val, wide = tr_x[op.name]
        # ... and every value computed at the test points lies inside the plan's proven range
        assert np.all((val >= op.lo) & (val <= op.hi)), (op.name, val.min(), val.max(), op.lo, op.hi)
        if wide is not None:
            assert np.all((wide >= op.wide_lo) & (wide <= op.wide_hi)), op.name
        assert np.array_equal(tr[op.name][0], val.astype(np.int64))


def test_proof_holds_at_corners_and_edges(plan):
    codes, kinds = make_code_vectors(plan, n_random=500, seed=3)
    _check_trace(plan, codes)
    corners = codes[[k == "corner" for k in kinds]]
    assert len(corners) == 256
    # the ranges are not loose for the powers: their extremes are reached at the domain's corners
    _, _, tr = plan.predict_codes(corners, trace=True)
    for op in plan.ops:
        if op.kind in ("input", "recip") or (op.kind == "mul" and not op.name.startswith("vd")):
            assert tr[op.name][0].min() == op.lo and tr[op.name][0].max() == op.hi, op.name


def test_proof_every_kind():
    fm = build_fixed(every_kind_model(), 1.7e-4, -0.123456789)
    codes, _ = make_code_vectors(fm, n_random=500, seed=4)
    _check_trace(fm, codes)


def test_error_bound_holds_on_numpy_model(plan, paper_fixed_model):
    codes, _ = make_code_vectors(plan, n_random=4000, seed=5)
    out, _ = plan.predict_codes(codes)
    ref = plan.reference_model().predict(plan.code_values(codes))
    err = np.abs(plan.to_real(out) - ref).max(axis=0)
    assert np.all(err <= plan.error_bound())
    assert np.all(err > 0)


# --- the header ------------------------------------------------------------------------------------


def _code_only(text: str) -> str:
    text = re.sub(r"/\*.*?\*/", "", text, flags=re.S)
    return "\n".join(ln for ln in text.splitlines() if not ln.lstrip().startswith("#define"))


def test_header_api_and_no_floating_point(paper_fixed_model, plan):
    text = render_header(paper_fixed_model, "fixed")
    for needle in ("#define TM_FIXED_POINT 1", "#define TM_N_INPUTS 8", "#define TM_N_OUTPUTS 5",
                   "#define TM_STATUS_NONFINITE (-1)", "#define TM_PRECISION_FLOAT 0", "#define TM_FMA 0",
                   "typedef int32_t tm_input;", "typedef int32_t tm_output;", "static const signed char tm_out_frac_bits",
                   "static const int32_t tm_input_min[TM_N_INPUTS]", "#define TM_INPUT_LSB 5.03547722590981",
                   "TM_API int tm_estimate(const tm_input in[TM_N_INPUTS], tm_output out[TM_N_OUTPUTS])",
                   f"#define TM_MODEL_HASH \"{paper_fixed_model.sha256}\"", "#include <stdint.h>"):
        assert needle in text, needle
    assert re.findall(r"#include <(\w+)\.h>", text) == ["stdint"]
    code = _code_only(text)
    assert not re.search(r"\b(float|double|math)\b", code)
    assert not re.search(r"\d\.\d", code)  # no floating literal
    assert f"#define TM_OUT_FRAC_BITS {{ {', '.join(str(f) for f in plan.out_frac_bits)} }}" in text


def test_generation_is_deterministic(paper_fixed_model, tmp_path):
    a = write_header(paper_fixed_model, tmp_path / "a", "fixed").read_bytes()
    b = write_header(paper_fixed_model, tmp_path / "b", "fixed").read_bytes()
    assert a == b
    lsb, off, _ = default_input_scale(paper_fixed_model)
    assert render_fixed_header(build_fixed(paper_fixed_model, lsb, off)).encode() == a
    assert render_header(paper_fixed_model, "fixed", prefix="pad") != a.decode()


def test_cortex_m0_build_has_no_floating_point(paper_fixed_model, tmp_path):
    require_tool("arm-none-eabi-gcc")
    require_tool("arm-none-eabi-nm")
    write_header(paper_fixed_model, tmp_path, "fixed")
    src = tmp_path / "use.c"
    src.write_text('#include "tm_model.h"\nint use(const tm_input *in, tm_output *out);\n'
                   "int use(const tm_input *in, tm_output *out) { return tm_estimate(in, out); }\n")
    obj = tmp_path / "use.o"
    compile_checked("arm-none-eabi-gcc", [src], obj, tmp_path, M0 + ["-Wconversion", "-Wsign-conversion"], link=False)
    nm = subprocess.run(["arm-none-eabi-nm", str(obj)], capture_output=True, text=True, check=True).stdout
    undefined = [ln.split()[-1] for ln in nm.splitlines() if ln.split()[0] == "U"]
    assert undefined, nm  # the 64-bit integer helpers
    for sym in undefined:
        assert not re.match(r"__aeabi_[fd]|__aeabi_[ilu]+2[fd]|__(add|sub|mul|div|cmp|fix|float)[sd]f|__.*[sd]f\d", sym), sym
        assert sym in ("__aeabi_lmul", "__aeabi_ldivmod", "__aeabi_llsr", "__aeabi_llsl", "__aeabi_lasr",
                       "__aeabi_uldivmod", "__aeabi_idiv", "__aeabi_uidiv"), sym
    size = subprocess.run(["arm-none-eabi-size", str(obj)], capture_output=True, text=True, check=True)
    text_bytes = int(size.stdout.splitlines()[1].split()[0])
    assert 500 < text_bytes < 32000


def test_native_build_warning_free_with_conversion_warnings(compiled):
    # the fixture compiled with -Wconversion -Wsign-conversion on top of the project's flags (and -Werror)
    assert compiled.binary.exists()


# --- refusals and the command line -------------------------------------------------------------------


def test_refusals(paper_fixed_model, tmp_path):
    roots = Model(np.array([0.5, 0.5]), np.array([2.0, 2.0]),
                  (Equation("dx", 0.1, (Term(1, "1/2"), Term(2, "-1")), (1.0, 2.0)),), "V")
    with pytest.raises(InputError, match="no-roots"):
        build_fixed(roots, 1e-4)
    for bad in (0.0, -1e-4, float("nan"), float("inf")):
        with pytest.raises(InputError, match="LSB"):
            build_fixed(paper_fixed_model, bad)
    with pytest.raises(InputError, match="no whole ADC code"):
        build_fixed(Model(np.array([1.00001]), np.array([1.00002]), (Equation("dx", 0.0, (Term(1, "1"),), (1.0,)),)),
                    1e-3)
    huge = Model(np.array([1.0]), np.array([2.0]), (Equation("dx", 0.0, (Term(1, "4"),), (1e12,)),), "V")
    with pytest.raises(InputError, match="LSB over 1 mm"):
        build_fixed(huge, 1e-3)
    # a positive domain never reaches code 0, even when its floor is within a millionth of a code of it
    tiny = Model(np.array([1e-12]), np.array([2.0]), (Equation("dx", 0.0, (Term(1, "-1"),), (1e-6,)),), "V")
    assert build_fixed(tiny, 1e-3).code_min == (1,)
    with pytest.raises(InputError, match="--input-lsb"):
        default_input_scale(Model(np.array([1.0]), np.array([2.0]), (Equation("dx", 0.0, (), ()),), "mT"))
    with pytest.raises(InputError, match="fma"):
        render_header(paper_fixed_model, "fixed", fma=True)
    with pytest.raises(InputError):
        render_header(paper_fixed_model, "fixed", prefix="int")


def test_default_input_scale(paper_fixed_model):
    lsb, off, source = default_input_scale(paper_fixed_model)
    assert lsb == 3.3 / 65535 and off == 0.0 and "paper" in source
    anon = Model(paper_fixed_model.input_min, paper_fixed_model.input_max, paper_fixed_model.equations, "V")
    assert default_input_scale(anon)[:2] == (3.3 / 65535, 0.0)
    # fitted on a capture (volts) whose simulated sensor was the paper preset in mT, as its meta's hash says: the
    # preset's mT step was taken for a code of these volts
    raw = load_sensor("paper").with_transfer("raw")
    captured = replace(anon, fit_info={"sensor_sha256": raw.sha256})
    assert raw.units == "mT" and default_input_scale(captured)[:2] == (3.3 / 65535, 0.0)
    assert default_input_scale(replace(anon, input_units="mT", fit_info={"sensor_sha256": raw.sha256}))[:2] == \
        sensor_input_scale(raw)[:2]


def test_codegen_cli(paper_fixed_model, tmp_path):
    path = tmp_path / "m.json"
    paper_fixed_model.save(path)
    proc = run_cli("fitgen", "codegen", str(path), "-o", str(tmp_path / "out"), "--precision", "fixed",
                   "--prefix", "pad")
    assert proc.returncode == 0, proc.stderr
    text = (tmp_path / "out" / "pad_model.h").read_text()
    assert "typedef int32_t pad_input;" in text and "#define PAD_FIXED_POINT 1" in text
    proc = run_cli("fitgen", "codegen", str(path), "-o", str(tmp_path / "o2"), "--precision", "fixed",
                   "--input-lsb", "1e-4", "--input-offset", "0.5")
    assert proc.returncode == 0, proc.stderr
    assert "#define TM_INPUT_OFFSET 0.5" in (tmp_path / "o2" / "tm_model.h").read_text()
    # bad input: one line, exit status 2
    assert_one_line_error(run_cli("fitgen", "codegen", str(path), "-o", str(tmp_path / "x"), "--precision", "fixed",
                                  "--input-lsb", "0"), contains="LSB")
    assert_one_line_error(run_cli("fitgen", "codegen", str(path), "-o", str(tmp_path / "x"), "--precision", "fixed",
                                  "--input-lsb", "abc"), contains="not a number")
    # an LSB in the wrong unit (V for mV) leaves each input a code or two: the header would give one pose
    span = float(np.min(paper_fixed_model.input_max - paper_fixed_model.input_min))
    proc = run_cli("fitgen", "codegen", str(path), "-o", str(tmp_path / "x"), "--precision", "fixed",
                   "--input-lsb", repr(span / 8))
    assert_one_line_error(proc, 2, "fewer than 16: every reading would give one of a handful of poses")
    assert not (tmp_path / "x").exists()
    assert_one_line_error(run_cli("fitgen", "codegen", str(path), "-o", str(tmp_path / "x"), "--input-lsb", "1e-4"),
                          contains="apply to --precision fixed only, and this header is double")
    # a model fitted for fixed point, its header by default another precision: the fix said (--precision fixed)
    fitted = json.loads(path.read_text())
    fitted["fit"]["precision"]["target"] = "fixed"
    (tmp_path / "f.json").write_text(json.dumps(fitted))
    assert_one_line_error(run_cli("fitgen", "codegen", str(tmp_path / "f.json"), "-o", str(tmp_path / "x"),
                                  "--input-lsb", "1e-4", "--target", "mps2"), 2,
                          "--input-lsb and --input-offset apply to --precision fixed only, and this header is double "
                          "(the model was fitted for fixed point: give --precision fixed)")
    for option in (["--style", "unrolled"], ["--style", "table"], ["--fma"]):  # fixed point has one layout
        assert_one_line_error(run_cli("fitgen", "codegen", str(path), "-o", str(tmp_path / "x"), "--precision",
                                      "fixed", *option), 2, f"{option[0]} does not apply to --precision fixed")
        # verify too: it took --style with fixed and passed it over
        assert_one_line_error(run_cli("tactile-host", "verify", str(path), "--precision", "fixed", *option), 2,
                              f"{option[0]} does not apply to --precision fixed")
    assert not (tmp_path / "x").exists()
    data = json.loads(path.read_text())
    data["outputs"][0]["terms"][0] = "v1^1/2"
    roots = tmp_path / "roots.json"
    roots.write_text(json.dumps(data))
    assert_one_line_error(run_cli("fitgen", "codegen", str(roots), "-o", str(tmp_path / "x"), "--precision", "fixed"),
                          contains="--family no-roots")
    data = json.loads(path.read_text())
    data["inputs"]["units"] = "mT"
    data["fit"] = {}
    mt = tmp_path / "mt.json"
    mt.write_text(json.dumps(data))
    assert_one_line_error(run_cli("fitgen", "codegen", str(mt), "-o", str(tmp_path / "x"), "--precision", "fixed"),
                          contains="--input-lsb")
    # an LSB so fine that the codes pass float's range: said with the codes, not an OverflowError
    assert_one_line_error(run_cli("fitgen", "codegen", str(path), "-o", str(tmp_path / "x"), "--precision", "fixed",
                                  "--input-lsb", "1e-310"), 2, "e+310 at LSB 1e-310, offset 0.0: beyond int32")
    assert not (tmp_path / "x").exists()
    # an output whose coefficients are all near float's least: its accumulator's Q format is the finest allowed
    data = json.loads(path.read_text())
    data["outputs"][4]["coefficients"] = [1e-310] * len(data["outputs"][4]["coefficients"])
    data["outputs"][4]["intercept"] = 0.0
    tiny = tmp_path / "tiny.json"
    tiny.write_text(json.dumps(data))
    proc = run_cli("fitgen", "codegen", str(tiny), "-o", str(tmp_path / "t"), "--precision", "fixed")
    assert proc.returncode == 0 and "thy Q100" in proc.stderr, proc.stderr


def test_predict_cli_fixed_equals_the_c(paper_fixed_model, compiled, plan, tmp_path):
    """`fitgen predict --precision fixed` answers what the fixed header computes: from values rounded to
    codes as the ADC would, or from the codes themselves (--codes)."""
    from fitgen.physics.dataset import Dataset

    path = tmp_path / "m.json"
    paper_fixed_model.save(path)
    rng = np.random.default_rng(3)
    lo, hi = paper_fixed_model.input_min, paper_fixed_model.input_max
    values = rng.uniform(lo - 0.1 * (hi - lo), hi + 0.1 * (hi - lo), (300, paper_fixed_model.n_inputs))
    codes = plan.codes_of(values)
    c_out, c_status = compiled.predict(codes)
    assert np.any(c_status > 0) and np.any(c_status == 0)
    for name, table, extra in (("values", values, []), ("codes", codes.astype(float), ["--codes"])):
        Dataset(table, np.zeros((len(table), 0)), ()).save(tmp_path / f"{name}.csv")
        proc = run_cli("fitgen", "predict", str(path), str(tmp_path / f"{name}.csv"), "-o",
                       str(tmp_path / f"{name}-est.csv"), "--precision", "fixed", *extra)
        assert proc.returncode == 0, proc.stderr
        assert ("codes as given" if extra else "rounded to ADC codes") in proc.stderr
        est = np.loadtxt(tmp_path / f"{name}-est.csv", delimiter=",", skiprows=1, ndmin=2)
        np.testing.assert_array_equal(est[:, -1].astype(int), c_status)
        np.testing.assert_array_equal(est[:, :-1], c_out)
    # the C's own scale options: another LSB gives other codes, hence other outputs
    proc = run_cli("fitgen", "predict", str(path), str(tmp_path / "values.csv"), "-o", str(tmp_path / "l.csv"),
                   "--precision", "fixed", "--input-lsb", "1e-4")
    assert proc.returncode == 0, proc.stderr
    assert not np.array_equal(np.loadtxt(tmp_path / "l.csv", delimiter=",", skiprows=1)[:, :-1], c_out)
    # bad input: one line, exit status 2, nothing written
    assert_one_line_error(run_cli("fitgen", "predict", str(path), str(tmp_path / "values.csv"), "-o",
                                  str(tmp_path / "x.csv"), "--precision", "fixed", "--codes"), contains="whole numbers")
    assert_one_line_error(run_cli("fitgen", "predict", str(path), str(tmp_path / "values.csv"), "-o",
                                  str(tmp_path / "x.csv"), "--codes", "--precision", "float"), contains="fixed only")
    assert not (tmp_path / "x.csv").exists()
    # codes are what fixed point takes: --codes alone is --precision fixed (it was refused as 'fixed only')
    proc = run_cli("fitgen", "predict", str(path), str(tmp_path / "codes.csv"), "-o", str(tmp_path / "c.csv"),
                   "--codes")
    assert proc.returncode == 0 and (tmp_path / "c.csv").read_text() == (tmp_path / "codes-est.csv").read_text()


def test_fit_for_fixed_point_gives_what_fixed_point_runs(tmp_path):
    """`fitgen fit --precision fixed` searches only what fixed point can run (auto: no-roots or integer,
    chosen on validation in fixed point), so codegen --precision fixed takes the model; what can never run
    in fixed point is refused in one line before any fitting."""
    data, model = tmp_path / "d.csv", tmp_path / "m.json"
    proc = run_cli("fitgen", "simulate", "--sensor", "paper", "--transfer", "gmr", "--grid", "paper-exp", "-o", str(data))
    assert proc.returncode == 0, proc.stderr
    proc = run_cli("fitgen", "fit", str(data), "--precision", "fixed", "--held-out", "200", "-o", str(model))
    assert proc.returncode == 0, proc.stderr
    info = json.loads(model.read_text())["fit"]
    assert info["family"]["name"] in ("no-roots", "integer") and info["family"]["auto"]
    assert "fixed" in info["family"]["why"] and set(info["family"]["validation_rms"]) == {"no-roots", "integer"}
    assert info["precision"]["target"] == "fixed" and "unavailable" not in info["held_out"]["errors"]["fixed"]
    proc = run_cli("fitgen", "codegen", str(model), "-o", str(tmp_path / "c"), "--precision", "fixed")
    assert proc.returncode == 0, proc.stderr
    for extra, message in ((["--refine", "1"], "no refinement"), (["--family", "harmonics"], "--family no-roots"),
                           (["--family", "all", "--noise", "0"], "--family no-roots")):
        proc = run_cli("fitgen", "fit", str(data), "--precision", "fixed", "-o", str(tmp_path / "x.json"), *extra)
        assert_one_line_error(proc, contains=message)
    assert not (tmp_path / "x.json").exists()


def test_verify_cli(paper_fixed_model, tmp_path):
    require_tool("gcc")
    path = tmp_path / "m.json"
    paper_fixed_model.save(path)
    proc = run_cli("tactile-host", "verify", str(path), "--precision", "fixed", "--vectors", "300")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert proc.stdout.count("PASS") == 1 and "\nfixed: " in "\n" + proc.stdout and "LSB" in proc.stdout
    # the vectors it counts are the ones it compared, held-out check or not
    bare = run_cli("tactile-host", "verify", str(path), "--precision", "fixed", "--vectors", "300", "--no-held-out")
    count = re.compile(r"(\d+) vectors")
    assert count.search(bare.stdout) and count.search(proc.stdout)[1] == count.search(bare.stdout)[1], proc.stdout
    assert_one_line_error(run_cli("tactile-host", "verify", str(path), "--precision", "fixed", "--fma"),
                          contains="fma")
    # an explicit scale works too; a wrong one (not the sensor's codes) still verifies its own plan
    proc = run_cli("tactile-host", "verify", str(path), "--precision", "fixed", "--vectors", "200",
                   "--input-lsb", "5e-05", "--input-offset", "0.001")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert_one_line_error(run_cli("tactile-host", "verify", str(path), "--precision", "double", "--input-lsb", "1"),
                          contains="fixed only")


def test_arm_linux_build_under_qemu(paper_fixed_model):
    """32-bit ARM (its own 64-bit multiply, shift and divide helpers) gives the same integers."""
    res = verify_on_arm_linux(paper_fixed_model, "fixed", "unrolled")
    assert np.all(res.max_lsb_diff == 0)


def test_verify_catches_a_wrong_c_result(paper_fixed_model):
    """A build whose arithmetic differs (here: the rounding helper replaced by truncation) fails."""
    require_tool("gcc")
    from fitgen.c.verify import compare_fixed

    with CompiledModel(paper_fixed_model, "fixed") as cm:
        text = cm.header.read_text().replace("((uint64_t)1 << (s - 1u))", "0u")
        cm.header.write_text(text)
        compile_checked("gcc", [cm.dir / "tm_vectors.c"], cm.binary, cm.dir)
        codes, _ = make_code_vectors(cm.fixed, n_random=300)
        res = compare_fixed(paper_fixed_model, cm, codes)
    assert not res.ok
    assert any("LSB" in f for f in res.failures)


# --- the plan for a 16-bit multiply (--target uno) ----------------------------------------------------


def narrow_chain_model() -> Model:
    """dx small enough for 16-bit products on powers no other output uses (16x16->32 power chains, a
    reciprocal into 16 bits); dy's cancelling terms need 32 bits; no fit notes (the budget is 1% of
    fitgen.physics.observe.DEFAULT_ACCURACY)."""
    lo, hi = np.array([1.0, 0.8]), np.array([2.0, 3.0])
    dx = Equation("dx", 0.1, (Term(1, "-2"), Term(1, "3"), Term(1, "-4"), Term(1, "1")), (0.01, 0.002, -0.004, 0.03))
    dy = Equation("dy", -3.0, (Term(2, "-1"), Term(2, "-2"), Term(2, "2"), Term(2, "1")), (400.0, -300.0, 20.0, 0.5))
    return Model(lo, hi, (dx, dy), "V")


@pytest.fixture(scope="module")
def small_model():
    """6 terms per output at most: most outputs fit 16-bit products within their budget."""
    ds = simulate(load_sensor("paper").with_transfer("gmr"), grid_poses(PAPER_GRIDS["paper-sim"]))
    return fit_model(ds, settings=FitSettings.exact(exponents=FAMILIES["no-roots"], max_terms=6))


def _uno_cases(paper_fixed_model, small_model):
    lsb, off, _ = default_input_scale(paper_fixed_model)
    return [(paper_fixed_model, lsb, off), (small_model, lsb, off), (every_kind_model(), 1.7e-4, -0.123456789),
            (narrow_chain_model(), 1e-4, 0.0)]


def test_uno_plan_kinds_and_budgets(paper_fixed_model, small_model):
    """Each output on 16x16->32 products, or 32x32->64 with byte-aligned shifts, or as in the 32-bit plan,
    and every bound within its budget: 1% of the model's max training error, never below the 32-bit bound."""
    from fitgen.equations.fixednarrow import NARROW_SHARE, reference_errors

    seen = set()
    for model, lsb, off in _uno_cases(paper_fixed_model, small_model):
        wide, fm = build_fixed(model, lsb, off), build_fixed(model, lsb, off, 16)
        assert fm.mul_bits == 16 and wide.mul_bits == 32
        ref = reference_errors(model)
        for o, w, b in zip(fm.outputs, wide.outputs, fm.budget):
            assert b == max(w.error_bound, NARROW_SHARE * ref[o.name])
            assert o.error_bound <= b
            seen.add("16" if o.acc_bits == 32 else "aligned" if o.aligned else "32")
            if o.acc_bits == 32:
                assert {op.bits for op in fm.ops if op.kind in ("init", "term") and op.index == o.index} == {32}
            if o.aligned:
                assert all(op.shift % 8 == 0 for op in fm.ops if op.kind == "term" and op.index == o.index)
        for op in fm.ops:
            if op.kind in ("init", "term", "out"):  # an int32 accumulator: 16x16->32 products
                assert (op.prod_bits == 32) == (fm.outputs[op.index].acc_bits == 32)
            else:
                assert (op.prod_bits == 32) == (op.kind == "narrow" or (op.kind in ("mul", "recip") and op.bits == 16))
            if op.kind == "mul" and op.prod_bits == 32:
                assert all(fm.op(a).bits == 16 for a in op.args)  # 16x16->32
    assert seen == {"16", "aligned", "32"}
    kinds = {(op.kind, op.bits) for op in build_fixed(narrow_chain_model(), 1e-4, 0.0, 16).ops}
    assert {("mul", 16), ("recip", 16), ("narrow", 16)} <= kinds  # a power chain computed in 16 bits
    assert ("p1_P3" in {op.name for op in build_fixed(narrow_chain_model(), 1e-4, 0.0, 16).ops
                        if op.bits == 16 and op.kind == "mul"})


def test_uno_plan_changes_nothing_without_a_budget(paper_fixed_model, small_model):
    """With no room for rounding (share 0) the plan for a 16-bit multiply is the 32-bit plan, op for op."""
    from fitgen.equations import fixedpoint as fp
    from fitgen.equations.fixednarrow import plan_narrow

    for model, lsb, off in _uno_cases(paper_fixed_model, small_model):
        L, O = fp._exact(lsb), fp._exact(off)
        cmin, cmax = fp._code_bounds(model, L, O)
        fm = plan_narrow(model, lambda n, a: fp._plan(model, L, O, cmin, cmax, n, a), share=0.0)
        assert fm.ops == build_fixed(model, lsb, off).ops and fm.outputs == build_fixed(model, lsb, off).outputs


def test_uno_plan_proof_and_bound(paper_fixed_model, small_model):
    """The proven ranges hold at the domain's corners and edges (int16 values too, no int64 wrap-around),
    and the error bound holds against double on the numpy model of the uno plan."""
    for model, lsb, off in _uno_cases(paper_fixed_model, small_model):
        fm = build_fixed(model, lsb, off, 16)
        codes, _ = make_code_vectors(fm, n_random=800, seed=6)
        _check_trace(fm, codes)
        for op in fm.ops:
            if op.bits == 16:
                assert -INT16 <= op.lo <= op.hi <= INT16
        out, _ = fm.predict_codes(codes)
        ref = fm.reference_model().predict(fm.code_values(codes))
        err = np.abs(fm.to_real(out) - ref).max(axis=0)
        assert np.all(err <= fm.error_bound()), (err, fm.error_bound())


INT16 = 2**15 - 1


def test_uno_plan_c_equals_numpy(paper_fixed_model, small_model):
    """The uno plan's header built natively (its portable C) answers the numpy model's integers exactly."""
    require_tool("gcc")
    for model, lsb, off in _uno_cases(paper_fixed_model, small_model):
        with CompiledModel(model, "fixed", input_lsb=lsb, input_offset=off, mul_bits=16,
                           cflags=["-Wconversion", "-Wsign-conversion"]) as cm:
            codes, kinds = make_code_vectors(cm.fixed, n_random=1500, seed=7)
            assert np.any(codes == INT32_MIN) and np.any(codes == INT32_MAX)
            out, status = cm.predict_codes(codes)
            ref, ref_status = cm.fixed.predict_codes(codes)
            assert np.array_equal(status, ref_status) and np.array_equal(out, ref)


def test_uno_codegen_and_predict_cli(small_model, tmp_path):
    """codegen --target uno writes the uno plan (named in the header) and predict --target uno answers what
    it computes; without --target both are the 32-bit plan's; a bad --target is one line, exit status 2."""
    require_tool("gcc")
    from fitgen.physics.dataset import Dataset

    path = tmp_path / "m.json"
    small_model.save(path)
    for target in ("uno", None):
        extra = ["--target", target] if target else []
        proc = run_cli("fitgen", "codegen", str(path), "-o", str(tmp_path / f"c{target}"), "--precision", "fixed",
                       *extra)
        assert proc.returncode == 0, proc.stderr
        assert ("16-bit multiply" in proc.stderr) == (target == "uno")
    uno, plain = ((tmp_path / f"c{t}" / "tm_model.h").read_text() for t in ("uno", None))
    assert " * Plan: for a 16-bit multiply (--target uno)" in uno and "16x16->32 products" in uno
    assert " * Plan: 32x32->64 products" in plain and uno != plain
    with CompiledModel(small_model, "fixed", mul_bits=16) as cm:
        assert cm.header.read_text() == uno
        rng = np.random.default_rng(8)
        lo, hi = small_model.input_min, small_model.input_max
        values = rng.uniform(lo - 0.1 * (hi - lo), hi + 0.1 * (hi - lo), (300, small_model.n_inputs))
        c_out, c_status = cm.predict(cm.fixed.codes_of(values))
    Dataset(values, np.zeros((len(values), 0)), ()).save(tmp_path / "v.csv")
    for target, same in (("uno", True), (None, False)):
        proc = run_cli("fitgen", "predict", str(path), str(tmp_path / "v.csv"), "-o", str(tmp_path / "e.csv"),
                       "--precision", "fixed", *(["--target", target] if target else []))
        assert proc.returncode == 0, proc.stderr
        est = np.loadtxt(tmp_path / "e.csv", delimiter=",", skiprows=1, ndmin=2)
        np.testing.assert_array_equal(est[:, -1].astype(int), c_status)
        assert np.array_equal(est[:, :-1], c_out) == same
    for cmd in (["codegen", str(path), "-o", str(tmp_path / "x")],
                ["predict", str(path), str(tmp_path / "v.csv"), "-o", str(tmp_path / "x.csv")]):
        assert_one_line_error(run_cli("fitgen", *cmd, "--precision", "fixed", "--target", "z80"), contains="--target")
        assert_one_line_error(run_cli("fitgen", *cmd, "--precision", "double", "--target", "uno"),
                              contains="target uno")
    assert not (tmp_path / "x").exists() and not (tmp_path / "x.csv").exists()


def test_predict_on_a_target_defaults_to_the_precision_codegen_writes(small_model, tmp_path):
    """predict --target without --precision computes in what codegen --target writes (fitgen.c.targets
    .default_precision): on the uno the precision the model was fitted for if it runs it, else float; double
    without a target or on one that runs double."""
    from fitgen.physics.dataset import Dataset

    rng = np.random.default_rng(3)
    values = rng.uniform(small_model.input_min, small_model.input_max, (200, small_model.n_inputs))
    Dataset(values, np.zeros((len(values), 0)), ()).save(tmp_path / "v.csv")
    doc, est = small_model.to_dict(), {}
    for fitted, target, expect in ((None, "uno", "float"), ("double", "uno", "float"), ("fixed", "uno", "fixed"),
                                   ("fixed", None, "double"), ("fixed", "pi", "double")):
        doc["fit"]["precision"]["target"] = fitted
        path = tmp_path / "m.json"
        path.write_text(json.dumps(doc))
        extra = ["--target", target] if target else []
        proc = run_cli("fitgen", "codegen", str(path), "-o", str(tmp_path / "c"), *extra)
        assert proc.returncode == 0 and f"({'fixed point' if expect == 'fixed' else expect}," in proc.stderr, \
            proc.stderr
        for name, given in (("default", []), ("given", ["--precision", expect])):
            proc = run_cli("fitgen", "predict", str(path), str(tmp_path / "v.csv"), "-o", str(tmp_path / f"{name}.csv"),
                           *extra, *given)
            assert proc.returncode == 0, proc.stderr
        est[expect] = (tmp_path / "default.csv").read_text()
        assert est[expect] == (tmp_path / "given.csv").read_text()
    assert len(set(est.values())) == 3  # the three precisions' estimates differ: the comparison above tells them apart


def test_codegen_says_when_the_adcs_rounding_is_large_beside_the_noise_fitted_for(tmp_path):
    """A 12-bit converter over 3.3 V (0.81 mV codes) rounds each reading by 0.23 mV rms, about half the 0.5 mV the
    model was fitted for: codegen wrote its header without a word. The sensor's own 16-bit codes stay quiet."""
    from conftest import run_cli

    data, model = tmp_path / "d.csv", tmp_path / "m.json"
    for argv in (("simulate", "--sensor", "paper", "--transfer", "gmr", "--random", "300", "-o", str(data)),
                 ("fit", str(data), "--family", "integer", "--precision", "fixed", "-o", str(model))):
        proc = run_cli("fitgen", *argv)
        assert proc.returncode == 0, proc.stderr
    noise = load_sensor("paper").gmr.noise
    for lsb, said in ((3.3 / 4095, True), (None, False), (0.000125, False)):
        proc = run_cli("fitgen", "codegen", str(model), "-o", str(tmp_path / "c"), "--precision", "fixed",
                       *(("--input-lsb", repr(lsb)) if lsb else ()))
        assert proc.returncode == 0, proc.stderr
        line = (f"note: codes of {lsb:.3g} V round each reading by {lsb / np.sqrt(12):.3g} V rms, "
                f"{lsb / np.sqrt(12) / noise:.0%} of the {noise:.3g} V rms of reading noise the model was fitted for"
                if lsb else "note:")
        assert (line in proc.stderr) == said, proc.stderr
