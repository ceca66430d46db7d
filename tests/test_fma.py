"""The numpy fused multiply-add against the C library's fma(), and generated C with fma() against Python."""

import ctypes
import ctypes.util

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fitgen.equations.fma import fma
from fitgen.fitting.fit import fit_model
from fitgen.physics.sensor import load_sensor
from fitgen.physics.simulate import PAPER_GRIDS, grid_poses, simulate
from fitgen.c.verify import verify

from conftest import require_tool


@pytest.fixture(scope="module")
def libm_fma():
    libm = ctypes.CDLL(ctypes.util.find_library("m") or "libm.so.6")
    f = libm.fma
    f.restype = ctypes.c_double
    f.argtypes = [ctypes.c_double] * 3
    return np.vectorize(f, otypes=[float])


def test_matches_libm_on_hard_cases(libm_fma):
    rng = np.random.default_rng(7)
    n = 20000
    a = rng.normal(size=n) * 10.0 ** rng.integers(-12, 12, n)
    b = rng.normal(size=n) * 10.0 ** rng.integers(-12, 12, n)
    # c near -a*b: heavy cancellation, where a separate rounding of the product shows
    c = -a * b * (1 + rng.normal(size=n) * 10.0 ** rng.integers(-17, 0, n))
    c[::4] = rng.normal(size=n)[::4]
    got = fma(a, b, c)
    assert np.array_equal(got, libm_fma(a, b, c))
    # and the test is not vacuous: the unfused expression differs on most of these
    assert np.mean(got != a * b + c) > 0.5


finite = st.floats(min_value=-1e30, max_value=1e30, allow_nan=False, allow_infinity=False).filter(
    lambda x: x == 0 or abs(x) > 1e-30)


@settings(max_examples=2000, deadline=None)
@given(finite, finite, finite)
def test_matches_libm_property(libm_fma, a, b, c):
    assert fma(a, b, c).tobytes() == np.float64(libm_fma(a, b, c)).tobytes()


def test_specials_follow_ieee(libm_fma):
    a = np.array([np.inf, np.nan, 1.0, 0.0, -0.0, 2.0, 1e308])
    b = np.array([2.0, 1.0, np.inf, 5.0, 5.0, 3.0, 10.0])
    c = np.array([1.0, 1.0, -np.inf, -0.0, -0.0, -6.0, 0.0])
    with np.errstate(all="ignore"):
        got, ref = fma(a, b, c), libm_fma(a, b, c)
    assert np.array_equal(np.isnan(got), np.isnan(ref))
    same = ~np.isnan(ref)
    assert np.array_equal(np.signbit(got[same]), np.signbit(ref[same]))
    assert np.array_equal(got[same], ref[same])


@pytest.fixture(scope="module")
def paper_model():
    return fit_model(simulate(load_sensor("paper"), grid_poses(PAPER_GRIDS["paper-sim"])))


@pytest.mark.parametrize("style", ["table", "unrolled"])
def test_fma_double_c_is_bit_identical_to_python(paper_model, style):
    require_tool("gcc")
    res = verify(paper_model, "double", style, n_random=1500, fma=True)
    assert res.ok, res.failures
    assert np.all(res.max_error == 0.0)


def test_fma_changes_the_answer_and_python_follows(paper_model):
    # the unfused reference is not bit-identical to the fused C: the fma path is really taken
    X = paper_model.input_min + (paper_model.input_max - paper_model.input_min) * np.random.default_rng(1).random((500, 8))
    assert np.any(paper_model.predict(X, fma=True) != paper_model.predict(X))


@pytest.mark.parametrize("style", ["table", "unrolled"])
def test_fma_float_within_bound(paper_model, style):
    require_tool("gcc")
    res = verify(paper_model, "float", style, n_random=1000, fma=True)
    assert res.ok, res.failures


def test_the_header_claims_bits_only_where_python_follows_them(paper_model):
    """A float header with fma had said it equals `fitgen predict --precision float` bit for bit, which has no
    fused multiply-add (Model.predict refuses float with fma): it differs on most rows, within the bound."""
    from fitgen.c.codegen import render_header

    X = paper_model.input_min + (paper_model.input_max - paper_model.input_min) * np.random.default_rng(2).random(
        (20, 8))
    with pytest.raises(Exception, match="no fused multiply-add"):
        paper_model.predict(X, precision="float", fma=True)
    said = {(p, f): render_header(paper_model, p, fma=f) for p in ("double", "float") for f in (False, True)}
    assert "bit for bit" not in said["float", True] and "within the float rounding bound" in said["float", True]
    for key in (("double", False), ("double", True), ("float", False)):
        assert "bit for bit on every core" in said[key], key
    # fitgen predict has no fma: a double fma header equals the library's fma evaluation, not the command's
    assert "Results equal `fitgen predict" not in said["double", True] and "Model.predict(..., fma=True) bit for bit" \
        in said["double", True]


def test_fmaf_is_one_instruction_on_cortex_m4f(paper_model, tmp_path):
    require_tool("arm-none-eabi-gcc")
    import subprocess

    from fitgen.c.codegen import write_header
    from fitgen.c.compiled import compile_checked

    write_header(paper_model, tmp_path, "float", "unrolled", fma=True)
    src = tmp_path / "use.c"
    src.write_text('#include "tm_model.h"\nint use(const tm_real *in, tm_real *out);\n'
                   "int use(const tm_real *in, tm_real *out) { return tm_estimate(in, out); }\n")
    obj = tmp_path / "use.o"
    compile_checked("arm-none-eabi-gcc", [src], obj, tmp_path,
                    ["-mcpu=cortex-m4", "-mthumb", "-mfloat-abi=hard", "-mfpu=fpv4-sp-d16"], link=False)
    dis = subprocess.run(["arm-none-eabi-objdump", "-dr", str(obj)], capture_output=True, text=True, check=True).stdout
    n_terms = sum(len(eq.terms) for eq in paper_model.equations)
    assert dis.count("vfma.f32") == n_terms
    assert "<fmaf>" not in dis and "R_ARM_THM_CALL\tfmaf" not in dis  # no library call


def test_codegen_and_verify_cli_with_fma(paper_model, tmp_path):
    require_tool("gcc")
    from conftest import run_cli

    path = paper_model.save(tmp_path / "m.json")
    proc = run_cli("fitgen", "codegen", str(path), "-o", str(tmp_path / "c"), "--style", "unrolled", "--fma")
    assert proc.returncode == 0, proc.stderr
    text = (tmp_path / "c" / "tm_model.h").read_text()
    assert "#define TM_FMA 1" in text and "acc = TM_FMA_OP(" in text
    proc = run_cli("tactile-host", "verify", str(path), "--precision", "double", "--style", "table", "--fma",
                   "--vectors", "200")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "PASS" in proc.stdout
