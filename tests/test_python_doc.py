"""docs/python.md runs as written: its ```python blocks, in order in one namespace in a fresh folder, make what the
document says they make; its ```sh lines, the commands each block mirrors, make the same model, estimates and
header; and the header computes the float estimates the document shows, bit for bit."""

import contextlib
import io
import json
import re
import shlex
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from conftest import require_tool, run_cli

DOC = Path(__file__).resolve().parents[1] / "docs" / "python.md"
STRICT = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-Wdouble-promotion", "-Wfloat-conversion"]
# the document's own bar for a resolvable component (fitgen.physics.observe.DEFAULT_ACCURACY: 0.1 mm)
SANE_MM = 0.1


def _blocks(lang: str) -> list[str]:
    return re.findall(rf"^```{lang}\n(.*?)^```[ \t]*$", DOC.read_text(), re.S | re.M)


def _sections() -> list[str]:
    return re.split(r"^## ", DOC.read_text(), flags=re.M)[1:]


@pytest.fixture(scope="module")
def doc(tmp_path_factory):
    """(namespace, folder, stdout per block) after running the document's python blocks in order."""
    folder = tmp_path_factory.mktemp("python-doc")
    ns = {"__name__": "docs_python"}
    printed = []
    with pytest.MonkeyPatch.context() as mp:
        mp.chdir(folder)
        for i, code in enumerate(_blocks("python"), start=1):
            out = io.StringIO()
            with contextlib.redirect_stdout(out):
                exec(compile(code, f"{DOC}: python block {i}", "exec"), ns)
            printed.append(out.getvalue())
    return ns, folder, printed


def test_the_document_has_one_python_block_per_section():
    blocks = _blocks("python")
    assert len(blocks) >= 5, f"{DOC} has {len(blocks)} python blocks"
    assert [s.count("```python") for s in _sections()] == [1] * len(blocks)
    # no other way of marking Python code that the test would not run
    assert DOC.read_text().count("```") == 2 * (len(blocks) + len(_blocks("sh")))


def test_the_sensor_is_the_file_written_in_volts(doc):
    from fitgen.physics.sensor import load_sensor

    ns, folder, printed = doc
    sensor = ns["sensor"]
    assert load_sensor(folder / "mine.toml").sha256 == sensor.sha256
    assert sensor.transfer == "gmr" and sensor.units == "V" and sensor.noise > 0
    assert ns["paper"].name == "paper" and ns["paper"].units == "V"
    assert f"{sensor.name}: {sensor.n_elements} elements, transfer gmr" in printed[0]


def test_observe_says_what_the_prose_says(doc):
    ns, _, printed = doc
    assert ns["reports"]["full"].unresolved()  # a single ring does not tell tilt from slide
    assert ns["reports"]["slide"].unresolved() == []
    assert ns["scene"].name == "slide"
    assert "scene slide: cannot resolve nothing" in printed[1]


def test_the_model_is_fitted_for_the_device_and_saved(doc):
    from fitgen.equations.model import load_model

    ns, folder, printed = doc
    model, sensor = ns["model"], ns["sensor"]
    assert load_model(folder / "slide.json").sha256 == model.sha256
    assert model.input_units == "V" and model.output_names == ns["scene"].outputs
    info = model.fit_info
    assert info["noise"]["device"] == sensor.noise and info["precision"]["target"] == "float"
    assert info["family"]["auto"] and info["family"]["name"] in ("all", "harmonics")
    held = info["held_out"]
    assert held["poses"] == 500 and held["noise"] == sensor.noise
    assert held["sensor_sha256"] == sensor.sha256
    for o in model.output_names:
        e = held["errors"]["float"][o]["noisy_max"]
        assert 0 < e < SANE_MM, (o, e)
        assert f"{o}: max error {e:.3g} mm with noise, float" in printed[2]


def test_the_estimates_are_the_float_models_on_new_poses(doc):
    from fitgen.equations.model import load_model

    ns, folder, printed = doc
    model, test, est = ns["model"], ns["test"], ns["est"]
    assert est.shape == (test.n_rows, len(model.output_names)) and test.n_rows >= 100
    assert np.array_equal(est, model.predict(test.inputs, precision="float"))
    assert np.array_equal(est, load_model(folder / "slide.json").predict(test.inputs, precision="float"))
    assert not np.array_equal(est, model.predict(test.inputs))  # float, not double
    train_poses = {tuple(p) for p in ns["train"].poses()}
    assert not any(tuple(p) in train_poses for p in test.poses())
    held = model.fit_info["held_out"]["errors"]["float"]
    for j, o in enumerate(model.output_names):
        e = ns["max_err"][o]
        assert e == np.abs(est[:, j] - test.target(o)).max()
        assert np.isfinite(e) and 0 < e < SANE_MM, (o, e)
        # the same kind of figure as the held-out record's, on other poses and noise draws: the same order
        assert held[o]["noisy_max"] / 4 < e < 4 * held[o]["noisy_max"], (o, e, held[o]["noisy_max"])
        assert f"{o}: max error {e:.3g} mm" in printed[3]


def test_the_header_compiles_and_computes_the_float_estimates(doc, tmp_path):
    gcc = require_tool("gcc")
    ns, folder, _ = doc
    header = folder / "c" / "tm_model.h"
    assert folder / ns["header"] == header and header.is_file()  # written where the notebook runs
    assert ns["model"].sha256 in header.read_text()
    proc = subprocess.run([gcc, *STRICT, "-fsyntax-only", "-x", "c", str(header)], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    # the header's promise (and the document's): fitgen predict --precision float, bit for bit
    main = tmp_path / "main.c"
    main.write_text(f'#include "{header}"\n#include <stdio.h>\n#include <stdlib.h>\n'
                    "int main(void) {\n  double x; tm_real in[TM_N_INPUTS], out[TM_N_OUTPUTS];\n"
                    "  for (;;) {\n    for (int k = 0; k < TM_N_INPUTS; k++) {\n"
                    "      if (scanf(\"%lf\", &x) != 1) return 0;\n      in[k] = (tm_real)x;\n    }\n"
                    "    tm_estimate(in, out);\n"
                    "    for (int j = 0; j < TM_N_OUTPUTS; j++) printf(\"%.9g \", (double)out[j]);\n"
                    "    printf(\"\\n\");\n  }\n}\n")
    exe = tmp_path / "est"
    proc = subprocess.run([gcc, "-std=c99", "-O2", str(main), "-o", str(exe), "-lm"], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    text = "\n".join(" ".join(repr(float(v)) for v in row) for row in ns["test"].inputs) + "\n"
    run = subprocess.run([str(exe)], input=text, capture_output=True, text=True, timeout=60)
    c_est = np.array([[float(v) for v in line.split()] for line in run.stdout.splitlines()])
    assert np.array_equal(c_est.astype(np.float32), ns["est"].astype(np.float32))


def test_a_built_unit_is_far_worse_served_than_the_drawing(doc):
    ns, _, printed = doc
    model, held = ns["model"], ns["model"].fit_info["held_out"]
    assert not ns["unit"].is_drawing and ns["unit"].sha256 != ns["sensor"].sha256
    assert np.array_equal(ns["on_unit"].poses(), ns["test"].poses())
    for j, o in enumerate(model.output_names):
        unit, drawing = ns["unit_err"][o], ns["max_err"][o]
        assert unit == np.abs(ns["unit_est"][:, j] - ns["on_unit"].target(o)).max()
        assert np.isfinite(unit) and unit > 5 * drawing, (o, unit, drawing)
        # the record's units say so too
        assert held["uncalibrated"]["errors"][o]["noisy_max"] > 5 * held["errors"]["float"][o]["noisy_max"], o
        assert f"{o}: max error {unit:.3g} on unit 7, {drawing:.3g} on the drawing" in printed[5]


def test_the_twin_of_a_short_capture_serves_the_unit_as_its_file_says(doc):
    """Section 7: the capture is explained to its noise, the magnet's offset is found within its standard errors,
    and the twin's model errs on unit 7 by a tenth of the drawing's model or less, no worse than its file says."""
    from fitgen.fitting.identify import derived_at
    from fitgen.physics.sensor import load_sensor
    from fitgen.physics.units import draw_unit

    ns, folder, printed = doc
    ident, sensor = ns["ident"], ns["sensor"]
    assert ns["stage_poses"].shape == (40, 5) and not ns["stage_poses"][:, 3:].any()  # three axes, no tilt
    assert ident.chi2 < 2 * ident.dof
    assert f"residual chi-square {ident.chi2:.1f} on {ident.dof:.1f} degrees of freedom" in printed[6]
    _, theta = draw_unit(sensor, 7)
    truth = derived_at(ident.space, theta)
    offsets = [(n, v, se) for n, (v, se) in ident.derived().items() if "offset" in n]
    assert len(offsets) == 3
    for name, value, se in offsets:
        assert abs(value - truth[name]) < 3.5 * se, (name, value, truth[name], se)
        assert f"{name}: {value:+.3f} +- {se:.3f}" in printed[6]
    twin = load_sensor(folder / "twin.toml")
    assert twin.sha256 == ns["twin"].sha256 and not twin.is_drawing
    assert (folder / "twin.posterior.json").is_file() and folder / ns["posterior_file"] == folder / "twin.posterior.json"
    held = ns["twin_model"].fit_info["held_out"]
    assert held["sensor_sha256"] == twin.sha256 and "posterior" in held  # widened by the identification
    for j, o in enumerate(ns["model"].output_names):
        got, says = ns["twin_err"][o], held["errors"]["float"][o]["noisy_max"]
        assert got == np.abs(ns["twin_est"][:, j] - ns["on_unit"].target(o)).max()
        assert got < ns["unit_err"][o] / 10, (o, got, ns["unit_err"][o])
        assert got < 1.3 * says, (o, got, says)
        assert f"{o}: max error {got:.3g} on unit 7 with its twin's model (the twin's file says {says:.3g})" \
            in printed[6]


def test_the_check_passes_the_twin_and_fails_the_drawings_model(doc):
    """Section 8: the twin's model on unit 7's check capture within what its identification predicts, the drawing's
    model beyond every prediction in each output."""
    ns, _, printed = doc
    twin, drawing = ns["checks"]["twin's"], ns["checks"]["drawing's"]
    assert twin.rows == 30 and twin.units == 8 and drawing.units == 1
    assert twin.failed() == [] and drawing.failed() == list(drawing.outputs)
    for o in twin.outputs:
        assert twin.measured[o]["max"] < twin.predicted(o, "max")[2] < drawing.measured[o]["max"] / 3
        assert f"twin's model, {o}: max error {twin.measured[o]['max']:.3g}, predicted up to " in printed[7]
    assert "twin's model: as predicted" in printed[7] and "drawing's model: fails on dx, dy, dz" in printed[7]


def _estimates(path: Path) -> np.ndarray:
    lines = path.read_text().splitlines()
    return np.array([[float(v) for v in line.split(",")[:-1]] for line in lines[1:]])


def test_the_sh_lines_make_the_same(doc, tmp_path):
    """The commands the document says each block mirrors, run as written, make the same model (by hash), held-out
    figures, estimates and header; and `fitgen fit` on the dataset the python wrote finds its sensor and scene."""
    from fitgen.equations.model import load_model

    ns, folder, _ = doc
    shutil.copy(folder / "mine.toml", tmp_path / "mine.toml")
    lines = [ln.strip() for block in _blocks("sh") for ln in block.splitlines() if ln.strip()]
    assert len(lines) >= 5 and all(ln.startswith("fitgen ") for ln in lines), lines
    for line in lines:
        proc = run_cli(*shlex.split(line), cwd=tmp_path)
        assert proc.returncode == 0, f"{line}: {proc.stderr}"
    model = load_model(tmp_path / "slide.json")
    assert model.sha256 == ns["model"].sha256
    assert json.dumps(model.fit_info["held_out"]["errors"]) == json.dumps(ns["model"].fit_info["held_out"]["errors"])
    assert model.fit_info["family"] == ns["model"].fit_info["family"]
    assert np.array_equal(_estimates(tmp_path / "est.csv"), ns["est"])
    assert np.array_equal(_estimates(tmp_path / "unit7-est.csv"), ns["unit_est"])
    assert (tmp_path / "c" / "tm_model.h").read_text() == (folder / "c" / "tm_model.h").read_text()
    # section 7: the same capture, the same twin (the unit files differ in provenance only), the same estimates
    from fitgen.physics.dataset import load_dataset

    assert np.array_equal(load_dataset(tmp_path / "capture.csv").inputs, ns["capture"].inputs)
    twin = load_model(tmp_path / "twin.json")
    assert twin.sha256 == ns["twin_model"].sha256
    assert json.dumps(twin.fit_info["held_out"]["errors"]) == json.dumps(ns["twin_model"].fit_info["held_out"]["errors"])
    assert np.array_equal(_estimates(tmp_path / "twin-est.csv"), ns["twin_est"])
    # section 8: the same check poses and rows; `fitgen check` passes (status 0 above) and prints the twin's figures
    assert np.array_equal(load_dataset(tmp_path / "check.csv").inputs, ns["check_capture"].inputs)
    proc = run_cli("fitgen", "fit", str(folder / "slide.csv"), "-o", str(tmp_path / "again.json"), "--held-out", "0")
    assert proc.returncode == 0, proc.stderr
    assert load_model(tmp_path / "again.json").sha256 == ns["model"].sha256


def test_the_twin_saved_from_python_refuses_its_own_capture_as_a_check(doc):
    """The unit file section 7 saves knows its capture as the CLI's does: `fitgen check` on the capture the twin was
    identified on is refused (it passed, the capture's hash missing from a unit file saved from Python)."""
    from conftest import assert_one_line_error
    from fitgen.physics.dataset import load_dataset

    _, folder, _ = doc
    record = json.loads((folder / "twin.posterior.json").read_text())
    assert record["capture_sha256"] == load_dataset(folder / "capture.csv").sha256
    proc = run_cli("fitgen", "check", "twin.json", "capture.csv", cwd=folder)
    assert_one_line_error(proc, 2, "capture.csv is the capture")


def test_a_unit_file_re_saved_with_a_byte_order_mark_keeps_its_posterior(doc):
    """load_sensor took the unit file with a BOM, but the posterior's reader did not and said there was none: the
    twin's held-out figures and check's predictions lost the identification's uncertainty without a word."""
    from fitgen.fitting.unitrecord import load_posterior

    _, folder, _ = doc
    bom = folder / "twin-bom.toml"
    bom.write_bytes(b"\xef\xbb\xbf" + (folder / "twin.toml").read_bytes())
    assert load_posterior(bom) is not None and load_posterior(bom) == load_posterior(folder / "twin.toml")
