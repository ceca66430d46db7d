"""The header on the ATmega328P (Arduino Uno): codegen --target, avr-gcc builds, estimates in simavr against Python."""

import subprocess

import numpy as np
import pytest

from fitgen.c.codegen import render_header
from fitgen.equations.terms import FAMILIES
from fitgen.fitting.fit import FitSettings, fit_model
from fitgen.physics.sensor import load_sensor
from fitgen.physics.simulate import PAPER_GRIDS, grid_poses, simulate

from conftest import assert_one_line_error, require_tool, run_cli

STRICT = ["-Wall", "-Wextra", "-Werror", "-pedantic", "-Wdouble-promotion", "-Wfloat-conversion", "-O2"]
USE = ("#include \"tm_model.h\"\nint use(const tm_input *i, tm_output *o);\n"
       "int use(const tm_input *i, tm_output *o) { return tm_estimate(i, o); }\n")


@pytest.fixture(scope="module")
def small_model():
    """A no-roots model of the paper sensor in volts (as the ADCs read it), 6 terms per output at most."""
    ds = simulate(load_sensor("paper").with_transfer("gmr"), grid_poses(PAPER_GRIDS["paper-sim"]))
    return fit_model(ds, settings=FitSettings.exact(exponents=FAMILIES["no-roots"], max_terms=6))


@pytest.fixture(scope="module")
def model_file(small_model, tmp_path_factory):
    return str(small_model.save(tmp_path_factory.mktemp("avr") / "model.json"))


def test_uno_refuses_a_double_header(model_file, tmp_path):
    for args in (["--precision", "double", "--target", "uno"], ["--target", "uno"]):
        proc = run_cli("fitgen", "codegen", model_file, "-o", str(tmp_path / "x"), *args)
        assert_one_line_error(proc, contains="target uno")
        assert "double is 32 bits" in proc.stderr
        assert not (tmp_path / "x" / "tm_model.h").exists()
    # the table's other rows: the Cortex-M0 runs fixed point only, the Pi no fixed point, the M4F all three
    assert_one_line_error(run_cli("fitgen", "codegen", model_file, "-o", str(tmp_path / "y"), "--precision", "float",
                                  "--target", "microbit"), contains="target microbit")
    assert_one_line_error(run_cli("fitgen", "codegen", model_file, "-o", str(tmp_path / "y"), "--precision", "fixed",
                                  "--target", "pi"), contains="target pi")
    for precision, target in (("float", "uno"), ("fixed", "uno"), ("double", "mps2"), ("double", "pi")):
        proc = run_cli("fitgen", "codegen", model_file, "-o", str(tmp_path / precision), "--precision", precision,
                       "--target", target)
        assert proc.returncode == 0, proc.stderr
    # the header does not depend on the target: one header builds everywhere
    plain = run_cli("fitgen", "codegen", model_file, "-o", str(tmp_path / "plain"), "--precision", "float")
    assert plain.returncode == 0
    assert (tmp_path / "plain" / "tm_model.h").read_bytes() == (tmp_path / "float" / "tm_model.h").read_bytes()


def _compile(cc, folder, suffix, flags):
    src = folder / f"use.{suffix}"
    src.write_text(USE)
    obj = folder / f"use_{suffix}.o"
    proc = subprocess.run([cc, *flags, *STRICT, "-I", str(folder), "-c", str(src), "-o", str(obj)],
                          capture_output=True, text=True)
    return proc, obj


def test_double_header_fails_on_avr_with_its_reason(small_model, tmp_path):
    require_tool("avr-gcc")
    require_tool("gcc")
    (tmp_path / "tm_model.h").write_text(render_header(small_model, "double"))
    proc, _ = _compile("avr-gcc", tmp_path, "c", ["-mmcu=atmega328p", "-std=c99"])
    assert proc.returncode != 0
    first = next(ln for ln in proc.stderr.splitlines() if "error" in ln)
    assert "#error" in first and "double-precision header" in first and "DBL_MANT_DIG != 53" in first, first
    # the same header builds where double has 53 bits: the check is not always on
    proc, _ = _compile("gcc", tmp_path, "c", ["-std=c99"])
    assert proc.returncode == 0, proc.stderr


@pytest.mark.parametrize("precision,style", [("float", "table"), ("float", "unrolled"), ("fixed", "table")])
def test_header_builds_warning_free_for_atmega328p_tables_in_flash(small_model, tmp_path, precision, style):
    require_tool("avr-gcc")
    require_tool("avr-g++")
    require_tool("avr-size")
    (tmp_path / "tm_model.h").write_text(render_header(small_model, precision, style, target="uno"))
    for cc, suffix, std in (("avr-gcc", "c", "-std=c99"), ("avr-g++", "cpp", "-std=gnu++11")):
        proc, obj = _compile(cc, tmp_path, suffix, ["-mmcu=atmega328p", std])
        assert proc.returncode == 0, proc.stderr
        assert proc.stderr == ""
        # avr-gcc puts const data in RAM (.data) unless it is PROGMEM: nothing of the header's is there
        text, data, bss = (int(x) for x in subprocess.run(["avr-size", str(obj)], capture_output=True, text=True,
                                                          check=True).stdout.splitlines()[1].split()[:3])
        assert data == 0 and bss == 0 and text > 0


def test_estimates_in_simavr_equal_python(small_model):
    """float (both styles) bit for bit with Model.predict(precision='float'); fixed point with the plan's integers;
    inside and outside the domain (the status bits too); cycles counted for every estimate."""
    for tool in ("avr-gcc", "avr-size", "gcc", "pkg-config"):
        require_tool(tool)
    from fitgen.c.avr import fits_uno, run_on_avr
    from fitgen.equations.fixedpoint import plan_at

    rng = np.random.default_rng(5)
    lo, hi = small_model.input_min, small_model.input_max
    span = hi - lo
    x = lo + rng.uniform(-0.1, 1.1, (24, small_model.n_inputs)) * span  # a tenth beyond each end: clamped too
    ref, ref_status = small_model.predict(x.astype(np.float32).astype(float), with_status=True, precision="float")
    assert np.any(ref_status > 0) and np.any(ref_status == 0)
    for style in ("table", "unrolled"):
        run = run_on_avr(small_model, x, "float", style)
        np.testing.assert_array_equal(run.status, ref_status)
        np.testing.assert_array_equal(run.outputs, ref)
        assert len(run.cycles) == len(x) and np.all(run.cycles > 1000) and fits_uno(run)
    for mul_bits in (16, 32):
        fm = plan_at(small_model, None, None, mul_bits)[0]
        codes = np.round(np.clip(x, 0, None) / fm.input_lsb)
        run = run_on_avr(small_model, codes, "fixed", mul_bits=mul_bits)
        want, want_status = fm.predict_codes(codes)
        np.testing.assert_array_equal(run.status, want_status)
        np.testing.assert_array_equal(run.outputs, want)
        assert np.all(run.cycles > 1000) and fits_uno(run)
