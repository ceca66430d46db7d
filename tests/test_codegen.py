"""Generated C against the Python evaluation, through gcc (and qemu-arm for an ARM Linux build)."""

import dataclasses
import json
import subprocess
from pathlib import Path

import numpy as np
import pytest

from fitgen.c.codegen import render_header, write_header
from fitgen.base.errors import InputError
from fitgen.fitting.fit import fit_model
from fitgen.equations.model import Equation, Model, model_from_dict
from fitgen.physics.sensor import load_sensor
from fitgen.physics.simulate import PAPER_GRIDS, grid_poses, simulate
from fitgen.equations.terms import EXPONENTS, Term
from fitgen.c.compiled import CompiledModel
from fitgen.c.verify import verify

from conftest import assert_one_line_error, require_tool, run_cli, verify_on_arm_linux


@pytest.fixture(scope="module")
def paper_model():
    return fit_model(simulate(load_sensor("paper"), grid_poses(PAPER_GRIDS["paper-sim"])))


def every_kind_model(scale: float = 1.0) -> Model:
    """Every exponent kind of every element, bare d-terms and v*d products; power coefficients over
    1e-12..1e8, d-term coefficients over 1e-6..1e-2 (the d's themselves reach 1e13)."""
    rng = np.random.default_rng(3)
    n = 4

    def eq(name, terms, low, high):
        mags = 10 ** rng.uniform(low, high, len(terms))
        coefs = tuple(float(c) for c in scale * rng.choice([-1, 1], len(terms)) * mags)
        return Equation(name, float(rng.normal()), tuple(terms), coefs)

    powers = [Term(k, e) for k in range(1, n + 1) for e in EXPONENTS]
    d_terms = [Term(mult=d) for d in ("dx", "dy", "dz")] + [Term(k, "1", d) for k in range(1, n + 1) for d in ("dx", "dz")]
    eqs = (eq("dx", powers[:20], -12, 8), eq("dy", powers[20:], -12, 8), eq("dz", powers[::3], -12, 8),
           eq("thx", d_terms, -6, -2), eq("thy", powers[1::2], -12, 8))
    return Model(np.array([0.05, 0.5, 1.0, 2.0]), np.array([3.0, 2.5, 40.0, 2.0]), eqs)


@pytest.mark.parametrize("precision", ["double", "float"])
@pytest.mark.parametrize("style", ["table", "unrolled"])
def test_paper_model_matches_python(paper_model, precision, style):
    require_tool("gcc")
    res = verify(paper_model, precision, style, n_random=1500)
    assert res.ok, res.failures
    if precision == "double":
        # same operations in the same order: the C answer is the Python answer, to a few roundings at most
        assert np.all(res.max_ratio <= 1.0)
    else:
        # the float bound is not vacuous: the measured error reaches a visible part of it
        assert np.max(res.max_ratio) > 0.01


@pytest.mark.parametrize("precision", ["double", "float"])
@pytest.mark.parametrize("style", ["table", "unrolled"])
def test_every_term_kind_and_extreme_coefficients(precision, style):
    require_tool("gcc")
    model = every_kind_model(1e-6 if precision == "float" else 1.0)
    res = verify(model, precision, style, n_random=500)
    assert res.ok, res.failures
    assert res.nonfinite_outputs == 0


@pytest.mark.parametrize("precision, style", [("double", "table"), ("double", "unrolled"), ("float", "table"),
                                              ("float", "unrolled"), ("fixed", "")])
@pytest.mark.parametrize("kind", ["intercepts", "d-terms"])
def test_outputs_without_input_powers_compile_warning_free_and_match_python(paper_model, precision, style, kind):
    """Intercept-only outputs (constants), and bare d-terms only: no term reads an input's power, yet the
    header compiles under the warning flags (CompiledModel: -Werror, -O2) and answers what Python does."""
    require_tool("gcc")
    eqs = [Equation(e.name, e.intercept, (), ()) for e in paper_model.equations]
    if kind == "d-terms":
        eqs[3] = Equation("thx", 0.5, (Term(mult="dx"), Term(mult="dz")), (0.25, -2.0))
    model = dataclasses.replace(paper_model, equations=tuple(eqs))
    lo, hi = model.input_min, model.input_max
    rows = np.vstack([lo, hi, (lo + hi) / 2, hi * 3, lo / 2])
    if precision == "fixed":
        with CompiledModel(model, "fixed", input_lsb=1e-3) as cm:
            codes = cm.fixed.codes_of(rows)
            out, status = cm.predict_codes(codes)
            ref, ref_status = cm.fixed.predict_codes(codes)
            assert np.array_equal(out, ref) and np.array_equal(status, ref_status)
            err = np.abs(cm.fixed.to_real(out) - model.predict(cm.fixed.code_values(codes)))
            assert np.all(err <= cm.fixed.error_bound())
        return
    with CompiledModel(model, precision, style) as cm:
        out, status = cm.predict(rows)
    ref, ref_status = model.predict(rows, with_status=True, precision=precision)
    assert np.array_equal(out, ref), (out, ref)
    assert status.tolist() == [0, 0, 0, 255, 255] and np.array_equal(status, ref_status)


@pytest.mark.parametrize("precision", ["double", "float"])
@pytest.mark.parametrize("exponents", [("-1",), ("1", "-1"), ("-1", "1/2"), ("1", "-1", "1/4")])
def test_a_table_whose_powers_need_no_square_compiles_warning_free(paper_model, precision, exponents):
    """A table header declared v2 = v * v whenever a term took 1/v, which never reads it: a model of v, 1/v and
    roots only (press, --k 6, --family all) did not compile under -Werror (unused variable), and tradeoff left
    its points out with status 0."""
    require_tool("gcc")
    terms = tuple(Term(k + 1, e) for k, e in enumerate(exponents))
    eqs = [Equation(e.name, e.intercept, terms, tuple(0.5 / (j + 1) for j in range(len(terms))))
           for e in paper_model.equations]
    model = dataclasses.replace(paper_model, equations=tuple(eqs))
    lo, hi = model.input_min, model.input_max
    rows = np.vstack([lo, hi, (lo + hi) / 2])
    with CompiledModel(model, precision, "table") as cm:
        out, _ = cm.predict(rows)
    assert np.array_equal(out, model.predict(rows, precision=precision))


def test_generation_is_deterministic(paper_model, tmp_path):
    for precision in ("double", "float"):
        for style in ("table", "unrolled"):
            a = write_header(paper_model, tmp_path / "a", precision, style).read_bytes()
            b = write_header(paper_model, tmp_path / "b", precision, style).read_bytes()
            assert a == b
            assert paper_model.sha256.encode() in a
    assert render_header(paper_model) != render_header(paper_model, style="unrolled")


def test_literals_round_trip(paper_model):
    import re

    text = render_header(paper_model)
    lits = [float(x) for x in re.findall(r"(?<![\w.])-?\d+\.\d+(?:e-?\d+)?(?![\w.])", text)]
    coefs = [c for e in paper_model.equations for c in e.coefficients + (e.intercept,)]
    assert set(coefs) <= set(lits)
    ftext = render_header(paper_model, "float")
    flits = {np.float32(float(x)) for x in re.findall(r"(-?\d+\.\d+(?:e-?\d+)?)f", ftext)}
    assert {np.float32(c) for c in coefs} <= flits


def test_status_and_guard_through_c(paper_model):
    require_tool("gcc")
    with CompiledModel(paper_model, "float", "table") as cm:
        lo, hi = paper_model.input_min, paper_model.input_max
        mid = (lo + hi) / 2
        rows = np.vstack([mid, mid, mid, mid])
        rows[1, 0] = hi[0] * 5
        rows[2, 7] = -1.0
        rows[3, 3] = np.nan
        out, status = cm.predict(rows)
    assert status.tolist() == [0, 1, 1 << 7, -1]
    assert np.all(out[3] == 0) and np.all(np.isfinite(out))


def test_identifiers_and_bad_models_refused(paper_model, tmp_path):
    for bad in ("int", "1tm", "a-b", "x" * 40, "tm__x", "static"):
        with pytest.raises(InputError):
            render_header(paper_model, prefix=bad)
    path = tmp_path / "m.json"
    paper_model.save(path)
    data = json.loads(path.read_text())
    data["outputs"][0]["coefficients"][0] = 1e200
    huge = tmp_path / "huge.json"
    huge.write_text(json.dumps(data))
    assert_one_line_error(run_cli("fitgen", "codegen", str(huge), "-o", str(tmp_path / "c")), contains="limit")
    # a name that would inject text is refused before any C is written
    data = json.loads(path.read_text())
    data["outputs"][0]["name"] = 'dx"; system("rm'
    with pytest.raises(InputError):
        model_from_dict(data)
    for prefix, said in (("for", "keyword"), ("main", "a name C reserves"), ("a_", "would hold '__'"),
                         ("p" * 17, "at most 16 characters"), ("p-q", "at most 16 characters"),
                         ("sig", "(SIG_...) would start as names the C library reserves"),
                         ("enc", "(ENC_...)"), ("e1", "(E1_..."), ("lc", "(LC_..."),
                         ("fe", "(FE_..."), ("sigma", "(SIGMA_..."), ("prix", "(PRIX_..."),
                         # Tm's macros and include guard were tm's: the second header compiled to nothing
                         ("Tm", "give it in lower case ('tm')"), ("priX", "give it in lower case")):
        assert_one_line_error(run_cli("fitgen", "codegen", str(path), "-o", str(tmp_path / "c"), "--prefix", prefix),
                              contains=said)
    assert not (tmp_path / "c").exists() or not list((tmp_path / "c").iterdir())


def test_codegen_and_verify_cli(paper_model, tmp_path):
    require_tool("gcc")
    path = tmp_path / "m.json"
    paper_model.save(path)
    proc = run_cli("fitgen", "codegen", str(path), "-o", str(tmp_path / "out"), "--precision", "float",
                   "--style", "unrolled", "--prefix", "pad")
    assert proc.returncode == 0, proc.stderr
    assert "typedef float pad_real;" in (tmp_path / "out" / "pad_model.h").read_text()
    proc = run_cli("tactile-host", "verify", str(path), "--vectors", "200")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert proc.stdout.count("PASS") == 4
    assert_one_line_error(run_cli("tactile-host", "verify", str(path), "--cc", "no-such-cc"), contains="not found")


def test_codegen_writes_over_its_own_header_only(tmp_path):
    """A header of the user's own named as codegen's output (DIR/tm_model.h) was replaced without a word; the header
    an earlier codegen wrote, in any precision, is replaced as before."""
    path = Path(__file__).parent / "data" / "model_gcc_fuses_at_O3.json"  # no roots: fixed point takes it
    out = tmp_path / "out"
    out.mkdir()
    (out / "tm_model.h").write_text("/* my own estimator */\n")
    for extra in ([], ["--precision", "fixed", "--input-lsb", "1e-4"]):
        assert_one_line_error(run_cli("fitgen", "codegen", str(path), "-o", str(out), *extra), 2,
                              f"cannot write {out / 'tm_model.h'}: a file of that name is there which no fitgen "
                              "codegen wrote; move it or give another folder")
        assert (out / "tm_model.h").read_text() == "/* my own estimator */\n"
    (out / "tm_model.h").unlink()
    for extra in (["--precision", "fixed", "--input-lsb", "1e-4"], ["--precision", "float"], []):
        proc = run_cli("fitgen", "codegen", str(path), "-o", str(out), *extra)
        assert proc.returncode == 0 and (extra[1:2] or ["double"])[0] in proc.stderr, proc.stderr


def test_verify_bounds_the_random_vectors(paper_model, tmp_path):
    """A count of vectors that could not be held is one line and status 2, not a MemoryError."""
    path = paper_model.save(tmp_path / "m.json")
    for n in ("100000000000", "100001", "-1"):
        assert_one_line_error(run_cli("tactile-host", "verify", str(path), "--vectors", n),
                              contains="--vectors must be a whole number from 0 to 100,000")


def test_verify_refuses_a_domain_past_what_the_c_sums_in_one_line_before_its_vectors(paper_model, tmp_path):
    """A domain reaching 1e308: numpy's three overflow warnings (the vectors reach past it) came before the
    refusal codegen gives."""
    import json

    data = json.loads(paper_model.save(tmp_path / "m.json").read_text())
    data["inputs"]["max"] = [1e308] * len(data["inputs"]["max"])
    (tmp_path / "m.json").write_text(json.dumps(data))
    for precision in ("double", "float", "both"):
        assert_one_line_error(run_cli("tactile-host", "verify", str(tmp_path / "m.json"), "--precision", precision),
                              contains="its terms reach inf in the input domain")


def test_verify_refuses_data_in_other_units_than_the_model_takes(paper_model, tmp_path):
    """--data's readings are checked against the model's units as read --model checks the ADCs' volts."""
    path = paper_model.save(tmp_path / "m.json")  # mT
    assert run_cli("fitgen", "simulate", "--transfer", "gmr", "--grid", "dx=0,1", "-o",
                   str(tmp_path / "v.csv")).returncode == 0
    assert_one_line_error(run_cli("tactile-host", "verify", str(path), "--data", str(tmp_path / "v.csv")),
                          contains="the model takes inputs in mT; dataset " + str(tmp_path / "v.csv") +
                          "'s readings are in V: fit it on a dataset in V (fitgen simulate --transfer gmr, or "
                          "tactile-host capture), or give readings in mT")


def test_verify_takes_readings_past_floats_range_as_the_c_does_without_numpys_warning(paper_model, tmp_path):
    """A --data reading of 1e39 is inf in the float C and in its reference alike (status -1 in both): numpy's
    overflow warning came before a PASS that was right."""
    path = paper_model.save(tmp_path / "m.json")
    assert run_cli("fitgen", "simulate", "--grid", "dx=0,1", "-o", str(tmp_path / "d.csv")).returncode == 0
    lines = (tmp_path / "d.csv").read_text().splitlines()
    lines[1] = ",".join(["1e39"] + lines[1].split(",")[1:])
    (tmp_path / "d.csv").write_text("\n".join(lines) + "\n")
    proc = run_cli("tactile-host", "verify", str(path), "--data", str(tmp_path / "d.csv"), "--precision", "float",
                   "--vectors", "0", "--no-held-out")
    assert proc.returncode == 0 and "PASS" in proc.stdout, proc.stdout + proc.stderr
    assert "Warning" not in proc.stderr, proc.stderr


@pytest.mark.parametrize("cc", ["gcc", "clang"])
def test_a_file_that_includes_the_headers_without_calling_them_compiles_warning_free(paper_model, tmp_path, cc):
    """A second translation unit that needs only TM_N_INPUTS (or the compensation's count) is warning-free."""
    require_tool(cc)
    from fitgen.c.compiled import compile_checked
    from fitgen.equations.fixedpoint import build_fixed
    from fitgen.c.codegen import render_fixed_header
    from host.temperature import TempComp, render_c

    (tmp_path / "tm_tempcomp.h").write_text(render_c(TempComp(25.0, np.full(8, 1e-4), np.full(8, 2e-3))))
    headers = {f"{p}_{s}": render_header(paper_model, p, s) for p in ("double", "float") for s in ("table", "unrolled")}
    integer = [Equation(e.name, e.intercept, (Term(1, "1"),), (1.0,)) for e in paper_model.equations]
    fixed = build_fixed(dataclasses.replace(paper_model, equations=tuple(integer)), 1e-4, 0.0, 32)
    headers["fixed"] = render_fixed_header(fixed, "tm")
    for name, text in headers.items():
        (tmp_path / "tm_model.h").write_text(text)
        src = tmp_path / "count.c"
        src.write_text('#include "tm_model.h"\n#include "tm_tempcomp.h"\nint n_inputs(void);\n'
                       "int n_inputs(void) { return TM_N_INPUTS + TM_TEMPCOMP_N; }\n")
        compile_checked(cc, [src], tmp_path / f"{name}.o", tmp_path, link=False)


def test_far_outside_in_c_flags_the_estimates_python_does(paper_model, tmp_path):
    """tm_far_outside(out), in the float, double and fixed-point headers, is 1 exactly for the estimates
    Model.far_outside flags (outside the fitted pose box by more than its width), at the bounds too in fixed
    point (an int32 out against a real bound: ceil below, floor above); without a box it is always 0."""
    require_tool("gcc")
    from fitgen.c.codegen import render_fixed_header
    from fitgen.c.compiled import compile_checked
    from fitgen.equations.fixedpoint import build_fixed

    box = {"dx": [-2.0, 1.9], "dz": [-2.0, 0.0], "thx": [-5.0, 5.0]}  # dy, thy: no box, never flagged
    boxed = dataclasses.replace(paper_model, fit_info={**paper_model.fit_info, "held_out": {"box": box}})
    integer = [Equation(e.name, e.intercept, (Term(1, "1"),), (1.0,)) for e in boxed.equations]
    fm = build_fixed(dataclasses.replace(boxed, equations=tuple(integer)), 1e-4, 0.0, 32)
    _, lo, hi = boxed.far_bounds()
    rng = np.random.default_rng(8)
    est = rng.uniform(-20, 20, (400, 5))
    est = est[np.all(np.abs(est[:, [0, 2, 3]][:, :, None] - np.stack([lo, hi], 1)[None]) > 1e-3, axis=(1, 2))]
    scale = 2.0 ** np.array(fm.out_frac_bits)
    codes = np.clip(np.round(est * scale), 1 - 2**31, 2**31 - 1).astype(np.int64)  # what an int32 out can hold
    edges = np.zeros((6, 5), dtype=np.int64)  # each bound's code and its neighbours, in dx
    edges[:, 0] = [np.ceil(lo[0] * scale[0]) - 1, np.ceil(lo[0] * scale[0]), np.ceil(lo[0] * scale[0]) + 1,
                   np.floor(hi[0] * scale[0]) - 1, np.floor(hi[0] * scale[0]), np.floor(hi[0] * scale[0]) + 1]
    codes = np.vstack([codes, edges])
    # a float out at a bound's nearest float and its neighbours, in dx: the header rounded -5.9 down and 5.8 up to
    # those floats, which lie beyond the bounds, and did not flag them
    near = np.float32([lo[0], hi[0]])
    f_edges = np.zeros((6, 5))
    f_edges[:, 0] = np.concatenate([np.nextafter(near, np.float32(-np.inf)), near,
                                    np.nextafter(near, np.float32(np.inf))])
    as_floats = np.vstack([est, f_edges]).astype(np.float32).astype(float)
    for name, text, rows, fmt, want in (
            ("float", render_header(boxed, "float"), as_floats, "%f", boxed.far_outside(as_floats)),
            ("double", render_header(boxed, "double"), est, "%lf", boxed.far_outside(est)),
            ("fixed", render_fixed_header(fm), codes, "%ld", boxed.far_outside(codes / scale)),
            ("nobox", render_header(paper_model, "double"), est, "%lf", np.zeros(len(est), bool))):
        folder = tmp_path / name
        folder.mkdir()
        (folder / "tm_model.h").write_text(text)
        kind = "long" if name == "fixed" else "double" if fmt == "%lf" else "float"
        (folder / "far.c").write_text(
            '#include <stdio.h>\n#include "tm_model.h"\nint main(void)\n{\n'
            f"    {kind} x[TM_N_OUTPUTS];\n    tm_output out[TM_N_OUTPUTS];\n    int k;\n"
            f'    while (scanf("{fmt} {fmt} {fmt} {fmt} {fmt}", &x[0], &x[1], &x[2], &x[3], &x[4]) == 5) {{\n'
            f"        for (k = 0; k < TM_N_OUTPUTS; ++k) {{\n            out[k] = (tm_output)x[k];\n        }}\n"
            '        printf("%d\\n", tm_far_outside(out));\n    }\n    return 0;\n}\n')
        compile_checked("gcc", [folder / "far.c"], folder / "far", folder)
        lines = "".join(" ".join(repr(int(v)) if name == "fixed" else repr(float(v)) for v in r) + "\n" for r in rows)
        got = subprocess.run([str(folder / "far")], input=lines, capture_output=True, text=True, check=True).stdout
        assert np.array_equal(np.array(got.split(), dtype=int).astype(bool), want), name
        assert want.any() == (name != "nobox") and not want.all()
        assert (f"#define TM_HAS_POSE_BOX {int(name != 'nobox')}") in text
    # a bound no int32 in the output's Q format can pass: that side's test is left out, not clamped into range
    from fitgen.c.codegen import _fixed_far

    wide = dataclasses.replace(boxed, fit_info={"held_out": {"box": {**box, "thx": [-1e6, 1e6]}}})
    fw = build_fixed(dataclasses.replace(wide, equations=tuple(integer)), 1e-4, 0.0, 32)
    assert _fixed_far(fw)[3] == (None, None) and _fixed_far(fw)[0] == _fixed_far(fm)[0]
    assert "/* thx */" not in render_fixed_header(fw) and "/* dx */" in render_fixed_header(fw)


def test_verify_says_in_one_line_what_is_wrong_with_the_compiler_or_runner(paper_model, tmp_path):
    require_tool("gcc")
    require_tool("arm-linux-gnueabihf-gcc")
    path = paper_model.save(tmp_path / "m.json")

    def verify_with(*opts, contains):
        assert_one_line_error(run_cli("tactile-host", "verify", str(path), "--vectors", "50", *opts),
                              contains=contains)

    verify_with("--cc", "", contains="--cc is empty")
    verify_with("--cc", "'gcc", contains="No closing quotation")
    verify_with("--runner", "false", contains="failed (exit status 1")
    verify_with("--runner", "true", contains="answered 0 lines")
    verify_with("--cc", "arm-linux-gnueabihf-gcc", contains="cannot run here")
    verify_with("--cc", "arm-linux-gnueabihf-gcc", "--runner", "qemu-arm", contains="-static in --cc")
    verify_with("--runner", "qemu-arm", contains="with a cross-compiler, e.g. --cc 'arm-linux-gnueabihf-gcc -static'")
    # the compiler's first lines say where the header was included from; the line shown is the error
    verify_with("--cc", "gcc -Dfabsf=", contains="error: expected")


def test_verify_catches_a_wrong_compiler_result(paper_model, tmp_path):
    """A C build that computes something else (here: a C library whose sqrt is a cube root) fails the check with
    status 1. (-ffast-math no longer does: the header's pragmas keep its arithmetic, test_roots.py)"""
    require_tool("gcc")
    assert any(t.exponent in ("1/2", "1/4") for e in paper_model.equations for t in e.terms)
    path = tmp_path / "m.json"
    paper_model.save(path)
    proc = run_cli("tactile-host", "verify", str(path), "--precision", "double", "--style", "unrolled",
                   "--cc", "gcc -Dsqrt=cbrt -DTM_API=static", "--vectors", "300")
    assert proc.returncode == 1, proc.stdout + proc.stderr
    assert "FAIL" in proc.stdout


def test_arm_linux_build_under_qemu(paper_model):
    verify_on_arm_linux(paper_model, "float", "table")
    verify_on_arm_linux(paper_model, "double", "unrolled")


@pytest.mark.parametrize("cpu", [["-mcpu=cortex-m4", "-mthumb", "-mfloat-abi=hard", "-mfpu=fpv4-sp-d16"],
                                 ["-mcpu=cortex-m0", "-mthumb", "-mfloat-abi=soft"]])
@pytest.mark.parametrize("precision", ["double", "float"])
def test_cortex_m_builds_warning_free(paper_model, tmp_path, cpu, precision):
    require_tool("arm-none-eabi-gcc")
    from fitgen.c.compiled import compile_checked

    for style in ("table", "unrolled"):
        write_header(paper_model, tmp_path, precision, style)
        src = tmp_path / "use.c"
        src.write_text('#include "tm_model.h"\nint use(const tm_real *in, tm_real *out);\n'
                       "int use(const tm_real *in, tm_real *out) { return tm_estimate(in, out); }\n")
        obj = tmp_path / f"use_{style}.o"
        compile_checked("arm-none-eabi-gcc", [src], obj, tmp_path, cpu, link=False)
        size = subprocess.run(["arm-none-eabi-size", str(obj)], capture_output=True, text=True, check=True)
        text_bytes = int(size.stdout.splitlines()[1].split()[0])
        assert 100 < text_bytes < 64000


def test_c_strings_take_plain_text_and_a_lossy_one_shows_the_rest_as_question_marks():
    """pi-build compiles the rest readings' source into tm_pi's tare line: a file's name may hold what no C string
    should (a quote, a backslash, a newline). Its '?' stand-in was itself refused, so a --rest path with a '~' or
    a quote stopped pi-build."""
    from fitgen.c.cgen import c_string

    assert c_string("--rest paper") == '"--rest paper"'
    for bad in ('a"b', "a\\b", "line\nbreak", "caf\u00e9"):
        with pytest.raises(InputError):
            c_string(bad)
    assert c_string('/tmp/my "unit"\\1~.toml', lossy=True) == '"/tmp/my _unit__1_.toml"'
    # tm_pi's tare line names "the model's" rest: its apostrophe became '_' ("the model_s")
    assert c_string("paper (the model's)", lossy=True) == '"paper (the model\'s)"'
    gcc, literal = require_tool("gcc"), c_string("it's")
    proc = subprocess.run([gcc, "-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-Wtrigraphs", "-x", "c",
                           "-fsyntax-only", "-"], input=f"const char *s = {literal};\n", text=True, capture_output=True)
    assert proc.returncode == 0, proc.stderr


@pytest.mark.parametrize("precision", ["double", "float", "fixed"])
def test_an_exported_estimator_has_a_prototype_and_links_as_c_from_cpp(paper_model, tmp_path, precision):
    """With TM_API defined empty (readout.md's way to export it) -Wmissing-prototypes failed the build: there was
    no declaration before the definition; and C++ mangled the name, so a C file calling it did not link."""
    from fitgen.equations.model import load_model

    require_tool("gcc")
    require_tool("g++")
    model = load_model(Path(__file__).parent / "data" / "model_gcc_fuses_at_O3.json") if precision == "fixed" \
        else paper_model  # the paper model has roots; the stored one (no-roots) has none
    write_header(model, tmp_path, precision=precision)
    (tmp_path / "ext.c").write_text('#define TM_API\n#include "tm_model.h"\n')
    (tmp_path / "ext.cpp").write_text('#define TM_API\n#include "tm_model.h"\n')
    strict = ["-Wall", "-Wextra", "-Werror", "-I", str(tmp_path), "-c"]
    for cmd in (["gcc", "-std=c99", "-pedantic", "-Wmissing-prototypes", "-Wredundant-decls", *strict,
                 str(tmp_path / "ext.c"), "-o", str(tmp_path / "c.o")],
                ["g++", "-std=c++17", "-Wmissing-declarations", "-Wredundant-decls", *strict, str(tmp_path / "ext.cpp"),
                 "-o", str(tmp_path / "cpp.o")]):
        proc = subprocess.run(cmd, capture_output=True, text=True)
        assert proc.returncode == 0, proc.stderr
    for obj in ("c.o", "cpp.o"):
        symbols = subprocess.run(["nm", str(tmp_path / obj)], capture_output=True, text=True).stdout.split()
        assert "tm_estimate" in symbols, (obj, symbols)
