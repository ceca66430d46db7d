"""Data and options as users get them wrong: each is one line on stderr, exit status 2, and nothing written."""

import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from fitgen.base.errors import InputError
from fitgen.equations.model import Equation, Model
from fitgen.equations.terms import Term
from fitgen.physics.sensor import load_sensor
from fitgen.physics.simulate import DEFAULT_RANGES, pose_rng, random_poses, simulate

from conftest import assert_one_line_error, run_cli


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    folder = tmp_path_factory.mktemp("bad")
    simulate(load_sensor("paper"), random_poses(60, DEFAULT_RANGES, pose_rng(1))).save(folder / "d.csv")
    return folder / "d.csv"


def files(folder):
    return sorted(p.name for p in folder.iterdir())


def test_an_output_that_is_a_folder_or_an_input_is_refused_before_the_work(data, tmp_path):
    d = str(data)
    for argv, said in ((["fit", d, "-o", d], "is the input"),
                       (["fit", d, "-o", str(tmp_path)], "it is a folder"),
                       (["identify", d, "-o", "."], "it is a folder"),
                       (["simulate", "--random", "3", "-o", ""], "-o is empty"),
                       (["observe", ""], "sensor is empty"), (["observe", "--ranges", " "], "--ranges is empty"),
                       (["simulate", "--poses", d, "-o", d], "is the input"),
                       # the dataset's meta is read with it: an identify or fit written over it lost the capture's
                       # noise figures, and the capture could not be read again
                       (["identify", d, "-o", d + ".meta.json"], f"is the input {d}.meta.json"),
                       (["fit", d, "-o", d + ".meta.json"], f"is the input {d}.meta.json")):
        before = files(data.parent)
        assert_one_line_error(run_cli("fitgen", *argv, cwd=tmp_path), contains=said)
        assert files(data.parent) == before and files(tmp_path) == []
    assert json.loads(Path(d + ".meta.json").read_text())["columns"][0] == "v1"


def test_a_constant_output_names_the_ones_to_fit(tmp_path):
    flat = random_poses(40, DEFAULT_RANGES, pose_rng(2)) * [1, 1, 1, 0, 0]
    simulate(load_sensor("paper"), flat).save(tmp_path / "flat.csv")
    assert_one_line_error(run_cli("fitgen", "fit", str(tmp_path / "flat.csv"), "-o", str(tmp_path / "m.json")),
                          contains="thx is 0 in every row: nothing to fit (fit the outputs that vary: --outputs "
                                   "dx,dy,dz)")
    assert not (tmp_path / "m.json").exists()
    # asked for one that does not vary alone: the ones that do are named from the data (it said no more)
    assert_one_line_error(run_cli("fitgen", "fit", str(tmp_path / "flat.csv"), "-o", str(tmp_path / "m.json"),
                                  "--outputs", "thy"),
                          contains="thy is 0 in every row: nothing to fit (fit the outputs that vary: --outputs "
                                   "dx,dy,dz)")


def test_quoted_numbers_read_as_numbers_and_an_unnamed_column_is_named(data, tmp_path):
    """An export that quotes every cell ("1.5") was refused as "cannot parse as CSV numbers", naming no line; one
    whose lines end in a comma (an empty last column) as "column : '' is not a number"."""
    from fitgen.physics.dataset import load_dataset

    head, *rows = data.read_text().splitlines()
    quoted = tmp_path / "quoted.csv"
    quoted.write_text("\n".join([head] + [",".join(f'"{c}"' for c in r.split(",")) for r in rows]) + "\n")
    assert np.array_equal(load_dataset(quoted).inputs, load_dataset(data).inputs)
    quoted.write_text(quoted.read_text().replace(rows[3].split(",")[1], "1,5", 1))
    assert_one_line_error(run_cli("fitgen", "fit", str(quoted), "-o", str(tmp_path / "m.json")),
                          contains="line 5, column v2: '1,5' is not a number")
    trailing = tmp_path / "trailing.csv"
    trailing.write_text("\n".join(ln + "," for ln in [head] + rows) + "\n")
    for argv, out in ((["fit", str(trailing)], "m.json"), (["simulate", "--poses", str(trailing)], "d.csv")):
        assert_one_line_error(run_cli("fitgen", *argv, "-o", str(tmp_path / out)),
                              contains=f"column {len(head.split(',')) + 1} of the header has no name (the line "
                                       "ends in a comma)")
        assert not (tmp_path / out).exists()


def test_a_dead_element_in_the_rows_is_refused_by_fit(data, tmp_path):
    """A column that reads one value on every row (a broken wire: 0 V, or a rail) had been fitted with a note, its
    domain that one value, into a model file that predict, codegen and report then refused: now fit refuses it,
    before the work, and writes nothing."""
    from fitgen.physics.dataset import load_dataset

    ds = load_dataset(data)
    for ks, value, said in (([2], 0.0, "v3 reads one value on every row (v3: 0)"),
                            ([6, 1], 3.3, "v2, v7 read one value on every row (v2: 3.3)")):
        rows = ds.inputs.copy()
        rows[:, ks] = value
        type(ds)(rows, ds.targets, ds.target_names).save(tmp_path / "dead.csv")  # no meta: a measured file
        proc = run_cli("fitgen", "fit", str(tmp_path / "dead.csv"), "-o", str(tmp_path / "m.json"))
        assert_one_line_error(proc, contains=said)
        assert "a dead element, a broken wire" in proc.stderr and not (tmp_path / "m.json").exists()
    proc = run_cli("fitgen", "fit", str(data), "-o", str(tmp_path / "m.json"))
    assert proc.returncode == 0 and "on every row" not in proc.stderr, proc.stderr


def test_a_channel_read_twice_is_said_by_fit(data, tmp_path):
    """v2 equal to v1 on every row (a channel map that lists one channel twice) was fitted in silence, both
    columns' terms kept side by side with equal weights."""
    from fitgen.physics.dataset import load_dataset

    ds = load_dataset(data)
    rows = ds.inputs.copy()
    rows[:, 1] = rows[:, 0]
    type(ds)(rows, ds.targets, ds.target_names).save(tmp_path / "twice.csv")
    proc = run_cli("fitgen", "fit", str(tmp_path / "twice.csv"), "-o", str(tmp_path / "m.json"))
    assert proc.returncode == 0, proc.stderr
    assert "note: v2 reads what v1 reads on every row: one ADC channel read twice" in proc.stderr, proc.stderr
    rows[:, 1] = rows[:, 0] * 2  # proportional, not the same: another element
    type(ds)(rows, ds.targets, ds.target_names).save(tmp_path / "twice.csv")
    proc = run_cli("fitgen", "fit", str(tmp_path / "twice.csv"), "-o", str(tmp_path / "m.json"))
    assert proc.returncode == 0 and "reads what" not in proc.stderr, proc.stderr


def test_rows_repeated_exactly_are_said_by_fit(data, tmp_path):
    """Every row twice was fitted in silence, though AIC then counts each repeat as a measurement of its own."""
    from fitgen.physics.dataset import load_dataset

    ds = load_dataset(data)
    twice = type(ds)(np.vstack([ds.inputs, ds.inputs[:7]]), np.vstack([ds.targets, ds.targets[:7]]), ds.target_names)
    twice.save(tmp_path / "twice.csv")  # no meta: a measured file
    proc = run_cli("fitgen", "fit", str(tmp_path / "twice.csv"), "-o", str(tmp_path / "m.json"))
    assert proc.returncode == 0, proc.stderr
    assert f"note: 7 of {ds.n_rows + 7} rows repeat another row exactly: the fit counts each as a measurement of " \
           "its own" in proc.stderr, proc.stderr
    proc = run_cli("fitgen", "fit", str(data), "-o", str(tmp_path / "m.json"))
    assert proc.returncode == 0 and "repeat another row" not in proc.stderr, proc.stderr


def test_simulate_leaves_no_unit_file_when_it_fails_and_refuses_poses_outside_the_sensor(tmp_path):
    assert_one_line_error(run_cli("fitgen", "simulate", "--unit", "3", "--random", "10", "--noise", "-1", "-o",
                                  str(tmp_path / "u.csv")), contains="--noise must be a finite number >= 0")
    # a grid keeps to the pose limits as --ranges does; a pose file's pose is refused by its readings
    assert_one_line_error(run_cli("fitgen", "simulate", "--grid", "dx=1e200", "-o", str(tmp_path / "far.csv")),
                          contains="grid 'dx=1e200': dx from 1e+200 to 1e+200 mm: a pose box's dx must lie within")
    assert files(tmp_path) == []
    (tmp_path / "far").mkdir()
    (tmp_path / "far" / "p.csv").write_text("dx,dy,dz\n1e200,0,0\n")
    assert_one_line_error(run_cli("fitgen", "simulate", "--poses", str(tmp_path / "far" / "p.csv"), "-o",
                                  str(tmp_path / "far.csv")),
                          contains="pose 1 (dx=1e+200 dy=0 dz=0 thx=0 thy=0) gives readings that are not finite")
    assert files(tmp_path) == ["far"] and files(tmp_path / "far") == ["p.csv"]


def test_pose_files_with_a_byte_order_mark_or_a_column_twice(tmp_path):
    (tmp_path / "bom.csv").write_bytes(b"\xef\xbb\xbfdx,dy,dz\n1.5,0,-1\n")  # a spreadsheet's "CSV UTF-8"
    proc = run_cli("fitgen", "simulate", "--poses", str(tmp_path / "bom.csv"), "-o", str(tmp_path / "s.csv"))
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "s.csv").read_text().splitlines()[1].split(",")[8:11] == ["1.5", "0.0", "-1.0"]
    (tmp_path / "dup.csv").write_text("dx,dy,dz,dx\n1,0,-1,2\n")
    assert_one_line_error(run_cli("fitgen", "simulate", "--poses", str(tmp_path / "dup.csv"), "-o",
                                  str(tmp_path / "t.csv")), contains="column dx appears twice")


@pytest.mark.parametrize("meta, said", [([], "not a dataset's meta"), ({"units": 5}, "units must be text, got 5"),
                                        ("{", "not JSON"), (b"{\xff}", "line 1 is not UTF-8 text (byte 0xff"),
                                        (None, "d.csv.meta.json: a folder, not a file")])  # was read as no meta
def test_a_broken_meta_is_said(data, tmp_path, meta, said):
    shutil.copy(data, tmp_path / "d.csv")
    mp = tmp_path / "d.csv.meta.json"
    if meta is None:
        mp.mkdir()
    else:
        mp.write_bytes(meta if isinstance(meta, bytes) else
                       (meta if isinstance(meta, str) else json.dumps(meta)).encode())
    proc = run_cli("fitgen", "fit", str(tmp_path / "d.csv"), "-o", str(tmp_path / "m.json"))
    assert_one_line_error(proc, contains=said)
    assert "not JSON" not in proc.stderr or said == "not JSON"


def test_text_in_another_encoding_is_named_with_its_line_and_the_fix(data, tmp_path):
    """A spreadsheet's 'Unicode text' (UTF-16) and a Latin-1 comment were refused as "'utf-8' codec can't decode
    byte 0xff in position 0": a byte offset, not the line or what to do."""
    text = data.read_text()
    (tmp_path / "u16.csv").write_text(text, encoding="utf-16")
    assert_one_line_error(run_cli("fitgen", "fit", str(tmp_path / "u16.csv"), "-o", str(tmp_path / "m.json")),
                          contains="u16.csv: UTF-16 text (a spreadsheet's 'Unicode text'): save it as UTF-8")
    lines = text.splitlines(keepends=True)
    (tmp_path / "latin.csv").write_bytes("".join(lines[:3] + ["# caf\u00e9\n"] + lines[3:]).encode("latin-1"))
    assert_one_line_error(run_cli("fitgen", "fit", str(tmp_path / "latin.csv"), "-o", str(tmp_path / "m.json")),
                          contains="latin.csv: line 4 is not UTF-8 text (byte 0xe9")
    (tmp_path / "bom.csv").write_bytes(b"\xef\xbb\xbf" + (tmp_path / "latin.csv").read_bytes())  # the same place
    assert_one_line_error(run_cli("fitgen", "fit", str(tmp_path / "bom.csv"), "-o", str(tmp_path / "m.json")),
                          contains="bom.csv: line 4 is not UTF-8 text (byte 0xe9")
    assert not (tmp_path / "m.json").exists()


def test_a_text_column_is_named_as_unknown_and_a_spreadsheets_empty_rows_are_no_rows(data, tmp_path):
    """A 'notes' column of text was refused as "line 2, column notes: 'ok' is not a number", where the column is
    what fit does not know; rows of bare commas, which spreadsheets leave below a table, as "'' is not a number"."""
    from fitgen.physics.dataset import load_dataset

    lines = data.read_text().splitlines()
    (tmp_path / "notes.csv").write_text(lines[0] + ",notes\n" + "".join(ln + ",ok\n" for ln in lines[1:]))
    assert_one_line_error(run_cli("fitgen", "fit", str(tmp_path / "notes.csv"), "-o", str(tmp_path / "m.json")),
                          contains="unknown column 'notes'")
    n = lines[0].count(",")
    (tmp_path / "commas.csv").write_text("\n".join(lines) + "\n" + ("," * n + "\n") * 3)
    assert load_dataset(tmp_path / "commas.csv").sha256 == load_dataset(data).sha256


def test_fit_options_and_columns_are_checked_before_the_fit(data, tmp_path):
    assert_one_line_error(run_cli("fitgen", "fit", str(data), "-o", str(tmp_path / "m.json"), "--held-out", "-1"),
                          contains="argument --held-out: must be >= 0")
    assert_one_line_error(run_cli("fitgen", "fit", str(data), "-o", str(tmp_path / "m.json"), "--noise", "1e300"),
                          contains="--noise 1e300 is no sensor's reading noise (at most 1000")
    lines = [",".join(ln.split(",")[:7] + ln.split(",")[8:]) for ln in data.read_text().splitlines()]
    (tmp_path / "d7.csv").write_text("\n".join(lines) + "\n")
    shutil.copy(str(data) + ".meta.json", tmp_path / "d7.csv.meta.json")
    assert_one_line_error(run_cli("fitgen", "fit", str(tmp_path / "d7.csv"), "-o", str(tmp_path / "m.json")),
                          contains="d7.csv has no v8 column, which its meta records")
    meta = json.loads((tmp_path / "d7.csv.meta.json").read_text())  # a meta that lists no columns: the sensor says
    (tmp_path / "d7.csv.meta.json").write_text(json.dumps({k: v for k, v in meta.items() if k != "columns"}))
    assert_one_line_error(run_cli("fitgen", "fit", str(tmp_path / "d7.csv"), "-o", str(tmp_path / "m.json")),
                          contains="the dataset has 7 input columns, its sensor paper 8 elements")
    assert not (tmp_path / "m.json").exists()


def test_predict_refuses_a_model_whose_float_sum_could_overflow(data, tmp_path):
    eqs = tuple(Equation(n, 0.0, (Term(1, "1"),), (1e300 if n == "dx" else 1.0,)) for n in ("dx", "dz"))
    path = Model(np.zeros(8), np.full(8, 2.0), eqs, "mT", {}).save(tmp_path / "m.json")
    assert_one_line_error(run_cli("fitgen", "predict", str(path), str(data), "-o", str(tmp_path / "e.csv"),
                                  "--precision", "float"), contains="output dx: its terms reach 2e+300")
    assert not (tmp_path / "e.csv").exists()


def test_a_power_float_cannot_hold_at_the_domains_end_is_refused_for_float(data, tmp_path):
    """A reading near 0 (one glitch row of 1e-20) under v1^-2, or a channel on a 1e-12 scale under v3^-4: the
    coefficients and the sums fit in float, but the power does not (1e40 is inf; v^4 underflows to 0 and 1/0 is
    inf), so fit wrote, and predict and codegen ran, a float model that gives inf and NaN with status 0."""
    lo = np.full(8, 0.5)
    for k, low, term, coef in ((1, 1e-20, "-2", 3.2e-40), (3, 6.98e-13, "-4", 3e-46)):
        lo_k = lo.copy()
        lo_k[k - 1] = low
        eqs = tuple(Equation(n, 0.1, (Term(k, term), Term(2, "1")), (coef, 1.0)) for n in ("dx", "dz"))
        model = Model(lo_k, np.full(8, 2.0), eqs, "mT", {})
        path = model.save(tmp_path / "m.json")
        said = (f"output dx: its term v{k}^{term} is not finite in float at v{k} = {low:.4g}, an end of the inputs' "
                "range")
        assert_one_line_error(run_cli("fitgen", "predict", str(path), str(data), "-o", str(tmp_path / "e.csv"),
                                      "--precision", "float"), contains=said)
        assert_one_line_error(run_cli("fitgen", "codegen", str(path), "-o", str(tmp_path / "c"), "--precision",
                                      "float"), contains=said)
        assert not (tmp_path / "e.csv").exists() and not (tmp_path / "c").exists()
        # in double it runs, finite at the domain's end
        assert np.all(np.isfinite(model.predict(np.where(np.arange(8) == k - 1, low, 1.0)[None, :])))


def test_a_reading_whose_power_overflows_the_fits_sums_is_named_in_one_line(tmp_path):
    """A reading of 1e-40: v1^-4 is 1e160, finite, but its square is not: numpy's overflow warnings came first, then
    a line that blamed the dx estimate the fit had made NaN, or a coefficient nan 'that does not fit in a float'
    whose suggested --precision double then failed too."""
    assert run_cli("fitgen", "simulate", "--sensor", "paper", "--random", "60", "--seed", "4", "-o",
                   str(tmp_path / "d.csv")).returncode == 0
    lines = (tmp_path / "d.csv").read_text().splitlines(keepends=True)
    lines[1] = "1e-40," + lines[1].split(",", 1)[1]
    (tmp_path / "d.csv").write_text("".join(lines))
    (tmp_path / "d.csv.meta.json").unlink()  # rows of one's own, as the glitch makes them
    for extra in ([], ["--outputs", "dx", "--precision", "double"]):
        assert_one_line_error(run_cli("fitgen", "fit", str(tmp_path / "d.csv"), "-o", str(tmp_path / "m.json"),
                                      "--held-out", "0", *extra),
                              contains="candidate term v1^-4 for dx is 1e+160, past the 1e+150 the fit's sums of "
                                       "squares hold, on data row 1")
    assert not (tmp_path / "m.json").exists()


def test_a_reading_of_0_or_less_says_which_powers_the_fit_was_not_offered(tmp_path):
    """One glitch reading of -0.5 withholds every negative and fractional power of its element (the terms rule),
    which had gone without a word; a family without such powers has nothing withheld to say."""
    assert run_cli("fitgen", "simulate", "--sensor", "paper", "--random", "80", "--seed", "4", "-o",
                   str(tmp_path / "d.csv")).returncode == 0
    lines = (tmp_path / "d.csv").read_text().splitlines(keepends=True)
    cells = lines[2].split(",")
    cells[3] = "-0.5"
    lines[2] = ",".join(cells)
    (tmp_path / "d.csv").write_text("".join(lines))
    (tmp_path / "d.csv.meta.json").unlink()
    base = ["fitgen", "fit", str(tmp_path / "d.csv"), "-o", str(tmp_path / "m.json"), "--held-out", "0"]
    proc = run_cli(*base)
    assert proc.returncode == 0, proc.stderr
    assert ("note: v4 reads 0 or less on some rows (v4: -0.5 on data row 2): the fit was not offered its powers -1, "
            "-2, -3, -4, 1/2, 1/3, 1/4, which need readings > 0") in proc.stderr, proc.stderr
    terms = {t for o in json.loads((tmp_path / "m.json").read_text())["outputs"] for t in o["terms"]}
    assert not any(t.startswith("v4^-") or t.startswith("v4^1/") for t in terms)
    proc = run_cli(*base, "--family", "integer")
    assert proc.returncode == 0 and "0 or less on some rows" not in proc.stderr, proc.stderr


def test_identify_refuses_numbers_it_cannot_solve_with(tmp_path):
    sched = tmp_path / "s.csv"
    sched.write_text("dx,dy,dz\n" + "".join(f"{x},{y},{z}\n" for x in (-1, 1) for y in (-1, 1) for z in (-0.1, -1, -2)))
    assert run_cli("fitgen", "simulate", "--unit", "2", "--poses", str(sched), "--noise", "0.0005", "-o",
                   str(tmp_path / "cap.csv")).returncode == 0
    for extra, said in ((["--rig-error", "1e300"], "the rig error must be 0..0.5 mm (a printer's is 0.01-0.1)"),
                        (["--rig-error", "2"], "the rig error must be 0..0.5 mm"),
                        (["--zero-error", "5"], "the zero error must be 0..0.5 mm"),
                        (["--noise", "1e-12"], "cannot be solved for in floating point"),
                        (["--noise", "0"], "--noise must be a finite number > 0, got 0"),
                        (["--noise=-1"], "--noise must be a finite number > 0, got -1")):
        assert_one_line_error(run_cli("fitgen", "identify", str(tmp_path / "cap.csv"), "-o",
                                      str(tmp_path / "u.toml"), *extra), contains=said)
    assert not (tmp_path / "u.toml").exists() and not (tmp_path / "u.posterior.json").exists()


def test_fixed_point_names_a_domain_beyond_int32_codes_plainly(tmp_path):
    eqs = tuple(Equation(n, 0.0, (Term(1, "1"),), (1.0,)) for n in ("dx", "dz"))
    path = Model(np.full(8, 0.5), np.full(8, 2.0), eqs, "V", {}).save(tmp_path / "m.json")
    for lsb, offset in (("1e-10", "0"), ("0.0001", "1e9")):
        proc = run_cli("fitgen", "codegen", str(path), "-o", str(tmp_path / "c"), "--precision", "fixed",
                       "--input-lsb", lsb, "--input-offset", offset)
        assert_one_line_error(proc, contains="beyond int32")
        assert "np.float64" not in proc.stderr


def test_predict_float_from_codes_refuses_an_lsb_no_float_holds_and_keeps_quiet_on_huge_readings(tmp_path):
    eqs = tuple(Equation(n, 0.0, (Term(1, "1"),), (1.0,)) for n in ("dx", "dz"))
    path = Model(np.full(8, 0.5), np.full(8, 2.0), eqs, "V", {}).save(tmp_path / "m.json")
    (tmp_path / "v.csv").write_text(",".join(f"v{k}" for k in range(1, 9)) + "\n" + "1e308" + ",1" * 7 + "\n"
                                    + "1" * 1 + ",1" * 7 + "\n")
    for lsb in ("1e-46", "1e-40", "1e300"):  # 0, a subnormal and inf in float
        assert_one_line_error(run_cli("fitgen", "predict", str(path), str(tmp_path / "v.csv"), "-o",
                                      str(tmp_path / "p.csv"), "--precision", "float", "--input-lsb", lsb), 2,
                              "is beyond a float's normal range")
    proc = run_cli("fitgen", "predict", str(path), str(tmp_path / "v.csv"), "-o", str(tmp_path / "p.csv"),
                   "--precision", "float", "--input-lsb", "3e-5")
    assert proc.returncode == 0 and "Warning" not in proc.stderr and "1 row with no estimate" in proc.stderr, \
        proc.stderr


@pytest.fixture(scope="module")
def fitted(data):
    from fitgen.fitting.fit import fit_model
    from fitgen.physics.dataset import load_dataset

    return fit_model(load_dataset(data)).to_dict()


@pytest.mark.parametrize("edit", [lambda f: f["noise"].__setitem__("device", "0.0005"),
                                  lambda f: f["outputs"]["dx"].__setitem__("steps", "x"),
                                  lambda f: f.__setitem__("precision", None)])
def test_report_on_fit_notes_edited_by_hand_is_one_line(fitted, tmp_path, edit):
    data = json.loads(json.dumps(fitted))
    edit(data["fit"])
    (tmp_path / "m.json").write_text(json.dumps(data))
    assert_one_line_error(run_cli("fitgen", "report", str(tmp_path / "m.json")),
                          contains="its fit notes are not as fitgen fit writes them")


@pytest.mark.parametrize("edit, said", [
    (lambda f: f.__setitem__("held_out", "none"), "fit.held_out must be an object, got 'none'"),
    (lambda f: f.__setitem__("precision", "float"), "fit.precision must be an object, got 'float'"),
    (lambda f: f.__setitem__("held_out", {"box": {"dx": [2, -2]}}), "fit.held_out.box.dx must be [low, high]"),
    (lambda f: f.__setitem__("held_out", {"rest": 1.5}), "fit.held_out.rest must be a list of readings"),
    # what a tare's note reads: a negative or NaN spread would note every tare, or none, in silence
    (lambda f: f.__setitem__("held_out", {"rest_spread": [0.1, -0.1]}), "fit.held_out.rest_spread must be a list of "
                                                                         "spreads (>= 0)"),
    # JSON holds integers past float's range: float() of one raised, a traceback
    (lambda f: f.__setitem__("held_out", {"box": {"dx": [0, 10 ** 400]}}), "fit.held_out.box.dx must be [low, high]"),
    # a held-out record whose seed is no whole number: read by verify and tactile-hil run, a traceback
    (lambda f: f.__setitem__("held_out", {"sensor": "paper", "box": {}, "poses": 10, "seed": 1.5}),
     "fit.held_out.seed must be a whole number >= 0"),
    # a hash that is a list: fitgen check's TypeError (unhashable), a traceback
    (lambda f: f.__setitem__("sensor_sha256", ["ab"]), "fit.sensor_sha256 must be a hash (text)"),
    # labels no simulation knows: verify said "labels are the stage's or the magnet's" without the file or field
    (lambda f: f.__setitem__("held_out", {"labels": "xyz"}), "fit.held_out.labels must be 'stage' or 'magnet'"),
    # figures report printed as they were ('-5', 'nan') and check compared with
    (lambda f: f.__setitem__("held_out", {"errors": {"float": {"dx": {"max": -5}}}}),
     "fit.held_out.errors.float.dx.max must be an error figure (a number >= 0), got -5"),
    (lambda f: f.__setitem__("held_out", {"errors": {"float": {"dx": 0.1}}}),
     "fit.held_out.errors.float.dx must be an object of error figures, got 0.1"),
    (lambda f: f.__setitem__("held_out", {"noise": -1.0}), "fit.held_out.noise must be a noise figure"),
    (lambda f: f["noise"].__setitem__("device", "x"), "fit.noise.device must be a noise figure (a number >= 0), "
                                                      "got 'x'")])
def test_fit_notes_edited_where_commands_read_them_are_refused_as_the_model_is_loaded(fitted, data, tmp_path, edit,
                                                                                       said):
    """Notes that predict, codegen and the readouts read (the held-out box, the precision) were read as tables far
    from the file: a traceback, after predict had written its output. Refused where the file is read, in one line."""
    model = json.loads(json.dumps(fitted))
    edit(model["fit"])
    (tmp_path / "m.json").write_text(json.dumps(model))
    for argv in (["predict", str(tmp_path / "m.json"), str(data), "-o", str(tmp_path / "e.csv")],
                 ["codegen", str(tmp_path / "m.json"), "-o", str(tmp_path / "c")]):
        assert_one_line_error(run_cli("fitgen", *argv), 2, said)
        assert "its fit notes are not as fitgen fit writes them" in run_cli("fitgen", *argv).stderr
    assert files(tmp_path) == ["m.json"]


def test_a_file_written_into_a_folder_by_its_own_name_is_not_the_input(fitted, data, tmp_path):
    """codegen -o DIR wrote DIR/tm_model.h over a model file of that name, and report --plot DIR its estimate_dx.png
    over a dataset of that name; both exited 0, the input gone."""
    folder = tmp_path / "out"
    folder.mkdir()
    model = folder / "tm_model.h"
    model.write_text(json.dumps(fitted))
    for precision in ("double", "fixed"):
        assert_one_line_error(run_cli("fitgen", "codegen", str(model), "-o", str(folder), "--precision", precision),
                              contains=f"the file written {model} is the input {model}: writing it would destroy it")
        assert json.loads(model.read_text()) == fitted
    proc = run_cli("fitgen", "codegen", str(model), "-o", str(folder), "--prefix", "other")
    assert proc.returncode == 0 and (folder / "other_model.h").is_file(), proc.stderr
    shutil.copy(data, folder / "estimate_dx.png")
    proc = run_cli("fitgen", "report", str(model), "--data", str(folder / "estimate_dx.png"), "--plot", str(folder))
    assert_one_line_error(proc, contains=f"--plot writes {folder / 'estimate_dx.png'} is the input")
    assert (folder / "estimate_dx.png").read_text() == data.read_text()


def test_predict_reads_its_data_once_so_a_pipe_works(fitted, data, tmp_path):
    """The rows' labels were read in a second pass after the estimates were written: from a pipe it found nothing,
    exit 2 with the output on disk."""
    (tmp_path / "m.json").write_text(json.dumps(fitted))
    proc = run_cli("fitgen", "predict", str(tmp_path / "m.json"), "/dev/stdin", "-o", str(tmp_path / "e.csv"),
                   input=data.read_text())
    assert proc.returncode == 0, proc.stderr
    assert len((tmp_path / "e.csv").read_text().splitlines()) == len(data.read_text().splitlines())


def test_comment_lines_before_the_header_are_skipped_as_in_the_body(data, tmp_path):
    """ReadPose's tared output starts with "# tare: ..."; it was read as the header ("15 fields, the header has 1")
    while a comment in the body was skipped. A bad cell is still named by its line in the file."""
    from fitgen.physics.dataset import parse_table

    text = data.read_text()
    names, table = parse_table("# tare: offsets [mV] -0.04\n" + text, "d")
    assert names == parse_table(text, "d")[0] and table.shape == parse_table(text, "d")[1].shape
    with pytest.raises(InputError, match="d line 4, column v2: 'x' is not a number"):
        parse_table("# a\n# b\nv1,v2\n1,x\n", "d")


def test_a_models_input_names_that_are_not_its_inputs_are_refused(fitted, data, tmp_path):
    model = json.loads(json.dumps(fitted))
    model["inputs"]["names"] = ["a", "b"]
    (tmp_path / "m.json").write_text(json.dumps(model))
    assert_one_line_error(run_cli("fitgen", "predict", str(tmp_path / "m.json"), str(data), "-o",
                                  str(tmp_path / "e.csv")), 2, "inputs.names must be v1..v8 for its 8 inputs")


@pytest.mark.parametrize("edit, said", [
    ({"units": "furlongs"}, "units must be mT or V, got 'furlongs'"),
    ({"noise": -1}, "noise must be a noise figure 0..1000 (or one per element), got -1"),
    ({"row_noise": [0.001]}, "row_noise gives 1 figure(s) for 8 elements"),
    ({"samples_per_row": 0}, "samples_per_row must be a whole number 1..10000, got 0"),
    ({"noise": 10 ** 400}, "noise must be a noise figure 0..1000 (or one per element)"),
    # a figure past any sensor's, squared, overflowed in the fit or identify (which blamed the unit file it wrote)
    ({"sample_noise": [5e-4] * 7 + [1e308]}, "sample_noise must be a noise figure 0..1000 (or one per element), got "
                                               "1e+308 for element 8"),
    # the fit wrote a model codegen and report then refused, as often as it was fitted again
    ({"sensor_sha256": [1, 2]}, "d.csv.meta.json: sensor_sha256 must be text, got [1, 2]"),
    ({"labels": 0}, "d.csv.meta.json: labels must be text, got 0"),
    # figures a capture never writes, taken as the rows' own: a fit added no noise, identify wrote 5 V into the unit
    ({"samples_per_row": 16, "sample_noise": [5.0] * 8, "row_noise": [1.25e-4] * 8},
     "sample_noise must be row_noise times sqrt(samples_per_row 16), as a capture writes it, got [5.0"),
    ({"noise": 500}, "noise 500 puts more noise in a row than all the rows' readings span"),
    ({"samples_per_row": 4, "sample_noise": [60.0] * 8, "row_noise": [30.0] * 8},
     "row_noise 30 puts more noise in a row than all the rows' readings span"),
    # identify blamed the unit file it was writing for the capture's temperature
    ({"thermistor_degc": 1e300}, "thermistor_degc must be a temperature -40..125 degC, got 1e+300"),
    ({"row_degc": [25.0] * 59 + [-500.0]}, "row_degc must be a list of temperatures -40..125 degC, one per row, "
                                           "got -500.0 for row 60")])
def test_a_meta_figure_the_fit_reads_that_is_not_as_written_is_refused(data, tmp_path, edit, said):
    """A meta edited by hand was fitted on without a word: a model in 'furlongs' no other command would read, or
    a noise of -1 recorded as the data's own."""
    shutil.copy(data, tmp_path / "d.csv")
    meta = json.loads(Path(f"{data}.meta.json").read_text())
    (tmp_path / "d.csv.meta.json").write_text(json.dumps({**meta, **edit}))
    assert_one_line_error(run_cli("fitgen", "fit", str(tmp_path / "d.csv"), "-o", str(tmp_path / "m.json")), 2,
                          said)
    assert not (tmp_path / "m.json").exists()


@pytest.mark.parametrize("argv, said", [
    (["simulate", "--random", "5000001", "-o", "d.csv"], "--random must be at most 5,000,000 poses"),
    (["fit", "D", "-o", "m.json", "--held-out", "5000001"], "--held-out must be at most 5,000,000 poses"),
    (["simulate", "--grid", "paper-sim", "--ranges", "dx=-1:1", "-o", "d.csv"],
     "--ranges is the box of --random poses: give --random N with it"),
    (["simulate", "--random", "10", "--noise", "1e300", "-o", "d.csv"], "--noise 1e300 is no sensor's reading noise"),
    # a CSV without a meta: it was taken, fitted for, and recorded in the model (with a meta it was refused)
    (["fit", "D", "-o", "m.json", "--noise", "1e300"], "--noise 1e300 is no sensor's reading noise (at most 1000"),
    (["schedule", "--samples", "1000000000", "-o", "s.csv"], "--samples must be at most 10000"),
    # a count past float's range: "a file name is too long" (--samples may name a file), or math.isfinite's traceback
    (["schedule", "--samples", "1" + "0" * 300, "-o", "s.csv"], "--samples must be at most 10000, got 1000000000")])
def test_counts_past_any_machines_memory_or_patience_are_refused_before_the_work(data, tmp_path, argv, said):
    """A count of 1e12 poses ran out of memory in a traceback; 1e9 samples per row made a capture that never ends."""
    proc = run_cli("fitgen", *[str(data) if a == "D" else a for a in argv], cwd=tmp_path)
    assert_one_line_error(proc, 2, said)
    assert files(tmp_path) == []


def test_absurd_coefficients_are_refused_in_one_line_without_numpys_warning(fitted, data, tmp_path):
    model = json.loads(json.dumps(fitted))
    model["outputs"][0]["coefficients"][:2] = [1e308, 1e308]
    (tmp_path / "m.json").write_text(json.dumps(model))
    proc = run_cli("fitgen", "predict", str(tmp_path / "m.json"), str(data), "-o", str(tmp_path / "e.csv"))
    assert_one_line_error(proc, 2, "its terms reach inf in the input domain")


@pytest.mark.parametrize("where", ["coefficients", "harmonics"])
def test_read_and_replay_refuse_an_overflowing_model_as_predict_does(model_file, tmp_path, where):
    """read and replay took such a model and streamed inf and NaN estimates with status 0."""
    run = tmp_path / "r.jsonl"
    read = ("tactile-host", "read", "--adc", "ads1115@0x48:0-3,ads1115@0x49:0-3", "--simulate", "0,0,-1,0,0",
            "--count", "3")
    assert run_cli(*read, "--model", model_file, "--record", str(run), "-o", str(tmp_path / "r.csv")).returncode == 0
    model = json.loads(Path(model_file).read_text())
    if where == "coefficients":
        model["outputs"][0]["coefficients"][:2] = [1e308, 1e308]
    else:
        model["inputs"]["harmonics"] = {"hc1": [1e308] * 2 + [0.0] * 6}
        model["outputs"][0]["terms"][0] = "hc1*hr"
    (tmp_path / "m.json").write_text(json.dumps(model))
    for proc in (run_cli(*read, "--model", str(tmp_path / "m.json"), "-o", str(tmp_path / "e.csv")),
                 run_cli("tactile-host", "replay", str(run), "--model", str(tmp_path / "m.json"),
                         "-o", str(tmp_path / "e.jsonl"))):
        assert_one_line_error(proc, 2, "output dx: its terms reach")
        assert not (tmp_path / "e.csv").exists() and not (tmp_path / "e.jsonl").exists()


def test_a_huge_cell_is_named_where_it_is(data, tmp_path):
    lines = data.read_text().splitlines()
    cells = lines[3].split(",")
    cells[3] = "1e300"
    (tmp_path / "d.csv").write_text("\n".join(lines[:3] + [",".join(cells)] + lines[4:]) + "\n")
    assert_one_line_error(run_cli("fitgen", "fit", str(tmp_path / "d.csv"), "-o", str(tmp_path / "m.json")),
                          contains="data row 3, column v4, holds 1e+300")


def test_a_stray_quote_or_a_cell_past_the_csv_modules_limit_is_named_where_it_is(fitted, data, tmp_path):
    """The cell finder read the whole text with the csv module: a stray quote took the rest of a file over 128 KiB
    for one field, and so did a long cell, past the module's limit (csv.Error, a traceback). Line by line now."""
    lines = data.read_text().splitlines()
    lines = lines[:1] + lines[1:] * 40  # 2,400 rows: over the limit after line 11
    bad = tmp_path / "d.csv"
    bad.write_text("\n".join(lines[:10] + ['"' + lines[10]] + lines[11:]) + "\n")
    (tmp_path / "m.json").write_text(json.dumps(fitted))
    proc = run_cli("fitgen", "predict", str(tmp_path / "m.json"), str(bad), "-o", str(tmp_path / "e.csv"))
    assert_one_line_error(proc,
                          contains=f"{bad} line 11: 1 fields, the header has {len(lines[0].split(','))}")
    cells = lines[4].split(",")
    cells[2] = "7" * 200_000
    bad.write_text("\n".join(lines[:4] + [",".join(cells)] + lines[5:]) + "\n")
    proc = run_cli("fitgen", "fit", str(bad), "-o", str(tmp_path / "f.json"))
    assert_one_line_error(proc, contains=f"{bad} line 5, column v3: '7777")
    assert len(proc.stderr) < 300 and not (tmp_path / "f.json").exists()


def test_fit_on_a_capture_with_rows_off_the_skin_refuses_in_one_line_numbered_as_in_the_file(data, tmp_path):
    """A capture's rest rows (dz > 0) are left out before the fit: its note came first, so a refusal was two lines,
    and a huge cell after a rest row was numbered among the rows kept, one too low."""
    lines = data.read_text().splitlines()
    header = lines[0].split(",")
    rest = lines[1].split(",")
    rest[header.index("dz")] = "0.2"
    cells = lines[4].split(",")
    cells[header.index("v2")] = "1e300"
    (tmp_path / "c.csv").write_text("\n".join([lines[0], ",".join(rest)] + lines[2:4] + [",".join(cells)]
                                              + lines[5:]) + "\n")
    (tmp_path / "c.csv.meta.json").write_text(json.dumps({"samples_per_row": 16, "units": "mT"}))
    fit = ("fitgen", "fit", str(tmp_path / "c.csv"), "-o", str(tmp_path / "m.json"))
    assert_one_line_error(run_cli(*fit), 2, "data row 4, column v2, holds 1e+300")
    (tmp_path / "c.csv").write_text("\n".join([lines[0], ",".join(rest)] + lines[2:]) + "\n")
    assert_one_line_error(run_cli(*fit, "--outputs", "dx,dq"), 2, "--outputs")
    assert_one_line_error(run_cli(*fit, "--force"), 2, "--force applies to a scene's outputs")
    assert not (tmp_path / "m.json").exists()


def test_report_names_a_huge_label_where_it_is(fitted, data, tmp_path):
    """A label of 1e308 mm: report squared it into numpy's overflow warning and an error table of inf."""
    lines = data.read_text().splitlines()
    cells = lines[4].split(",")
    cells[lines[0].split(",").index("dx")] = "1e308"
    (tmp_path / "d.csv").write_text("\n".join(lines[:4] + [",".join(cells)] + lines[5:]) + "\n")
    (tmp_path / "m.json").write_text(json.dumps(fitted))
    assert_one_line_error(run_cli("fitgen", "report", str(tmp_path / "m.json"), "--data", str(tmp_path / "d.csv"),
                                  "-o", str(tmp_path / "r.md")), contains="data row 4, column dx, holds 1e+308")
    assert not (tmp_path / "r.md").exists()


@pytest.mark.parametrize("edit, said", [
    (lambda m: m["outputs"][0]["terms"].__setitem__(0, "v99^-1"), "refers to input v99; the model has 8"),
    (lambda m: m["outputs"][0]["terms"].__setitem__(0, "zz"), "outputs[0].terms: not a term: 'zz'"),
    # a term of an output's own estimate passed; report, predict, codegen and verify then raised KeyError
    (lambda m: m["outputs"][0]["terms"].__setitem__(0, "v1*dx"), "output dx term v1*dx needs output dx computed "
                                                                 "before it"),
    (lambda m: m["outputs"][2]["terms"].__setitem__(0, "dz"), "output dz term dz needs output dz computed before it"),
    (lambda m: m["outputs"][0].__setitem__("terms", "v1"), "outputs[0].terms must be a list, got 'v1'"),
    (lambda m: m["outputs"][0]["terms"].__setitem__(0, 5), "outputs[0].terms: 5 is not a term"),
    (lambda m: m["inputs"]["min"].__setitem__(0, 99.0), "input v1 has min > max"),
    # predict read -564 mm at every row, check called it 'as predicted', verify passed
    (lambda m: m["inputs"]["min"].__setitem__(0, m["inputs"]["max"][0]), "input v1 has min = max: a domain of no "
                                                                          "width"),
    # a symbol from_azimuths drops: predict, check and read raised TypeError, codegen wrote C gcc refused
    (lambda m: m["inputs"].__setitem__("harmonics", {"hc1": [0] * 8}), "inputs.harmonics.hc1: every weight is 0"),
    # an integer past float's range: math.isfinite raised OverflowError, a traceback
    (lambda m: m["inputs"]["min"].__setitem__(0, 10 ** 400), "inputs.min must be a finite number, got 1000"),
    (lambda m: m.__setitem__("outputs", []), "no outputs"),
    # it said inputs.names must be v1..v7 for its 7 inputs, of names that were right
    (lambda m: m["inputs"]["min"].pop(), "inputs.min has 7 values and inputs.max 8: one per input"),
    # read by nothing, so an edit to "m" or "in" converted nothing and no one said so
    (lambda m: m["outputs"][0].__setitem__("unit", "in"), "outputs[0].unit: dx is estimated in mm, not 'in'")])
def test_a_model_file_edited_by_hand_is_named_in_its_refusal(fitted, tmp_path, edit, said):
    data = json.loads(json.dumps(fitted))
    edit(data)
    (tmp_path / "m.json").write_text(json.dumps(data))
    assert_one_line_error(run_cli("fitgen", "report", str(tmp_path / "m.json")),
                          contains=f"model file {tmp_path / 'm.json'}: ")
    assert said in run_cli("fitgen", "report", str(tmp_path / "m.json")).stderr


@pytest.mark.parametrize("edit, said", [
    (lambda m: m.pop("inputs"), "inputs is missing"),
    (lambda m: m["inputs"].pop("max"), "inputs.max is missing"),
    (lambda m: m["outputs"][1].pop("name"), "outputs[1].name is missing"),
    (lambda m: m["outputs"][0].pop("intercept"), "outputs[0].intercept is missing"),
    (lambda m: m["outputs"][0].pop("coefficients"), "outputs[0].coefficients is missing"),
    (lambda m: m.__setitem__("inputs", []), "inputs must be an object, got []"),
    (lambda m: m["outputs"].__setitem__(0, []), "outputs[0] must be an object, got []"),
    (lambda m: m["inputs"].__setitem__("min", 5), "inputs.min must be a list, got 5"),
    (lambda m: m.__setitem__("outputs", {"dx": 1}), "outputs must be a list")])
def test_a_model_file_missing_a_field_names_it(fitted, edit, said):
    """A field deleted or of another kind had said only Python's exception (malformed model (KeyError: 'inputs')),
    naming neither where it is nor what to do."""
    from fitgen.equations.model import model_from_dict

    data = json.loads(json.dumps(fitted))
    edit(data)
    with pytest.raises(InputError) as err:
        model_from_dict(data, "model file m.json")
    assert str(err.value).startswith(f"model file m.json: {said}") and "Error" not in str(err.value)
    assert str(err.value).endswith("(fit the model again, or restore the file)")


def test_report_refuses_data_without_the_outputs_and_leaves_no_plot_folder_when_refused(fitted, data, tmp_path):
    (tmp_path / "m.json").write_text(json.dumps(fitted))
    readings = [",".join(line.split(",")[:8]) for line in data.read_text().splitlines()]
    (tmp_path / "readings.csv").write_text("\n".join(readings) + "\n")
    model = str(tmp_path / "m.json")
    assert_one_line_error(run_cli("fitgen", "report", model, "--data", str(tmp_path / "readings.csv")),
                          contains="readings.csv: no column of the model's outputs (dx, dy, dz, thx, thy)")
    for argv in (["--data", str(tmp_path / "readings.csv")], ["--data", str(data), "--sensor", "nosuch"]):
        assert_one_line_error(run_cli("fitgen", "report", str(tmp_path / "m.json"), "--plot", str(tmp_path / "P"),
                                      *argv))
        assert not (tmp_path / "P").exists()
    (tmp_path / "F").write_text("")
    assert_one_line_error(run_cli("fitgen", "report", str(tmp_path / "m.json"), "--data", str(data), "--plot",
                                  str(tmp_path / "F")), contains="it is a file; give a folder")


def test_report_writes_its_figures_and_the_report_together_or_none(fitted, data, tmp_path, monkeypatch, capsys):
    """A figure that cannot be written, or a plot folder that cannot be made, leaves no report: neither the file
    nor the report on standard output."""
    from fitgen.app import cli, plots

    (tmp_path / "m.json").write_text(json.dumps(fitted))
    model, report = str(tmp_path / "m.json"), tmp_path / "r.md"
    (tmp_path / "P" / "estimate_dy.png").mkdir(parents=True)  # the second figure: the first would be written
    for out in (["-o", str(report)], []):
        proc = run_cli("fitgen", "report", model, "--data", str(data), "--plot", str(tmp_path / "P"), *out)
        assert proc.stdout == "" and not report.exists() and files(tmp_path / "P") == ["estimate_dy.png"], out
        assert_one_line_error(proc, contains=f"cannot write {tmp_path / 'P' / 'estimate_dy.png'}: it is a folder")
    # a plot folder that the checks before the work let through but that cannot be made (as /proc/x was for
    # root): no report
    monkeypatch.setattr(plots, "require", lambda folder: Path(folder))
    (tmp_path / "file").write_text("x")
    with pytest.raises(SystemExit) as stop:
        cli.main(["report", model, "--data", str(data), "--plot", str(tmp_path / "file" / "sub"), "-o", str(report)])
    assert not report.exists()
    assert stop.value.code == 2 and f"cannot create {tmp_path / 'file' / 'sub'}" in capsys.readouterr().err


def test_write_all_writes_every_file_or_none(tmp_path):
    from fitgen.base.fileio import write_all
    from fitgen.base.errors import InputError

    (tmp_path / "old.txt").write_text("before")
    (tmp_path / "taken").mkdir()
    with pytest.raises(InputError, match="cannot write .*taken: it is a folder"):
        write_all([(tmp_path / "old.txt", "after"), (tmp_path / "new" / "sub" / "a.png", b"png"),
                   (tmp_path / "taken", "x")])
    # the file there before is as it was, the folders made for the others are gone, no temporary is left
    assert (tmp_path / "old.txt").read_text() == "before" and files(tmp_path) == ["old.txt", "taken"]
    paths = write_all([(tmp_path / "old.txt", "after"), (tmp_path / "new" / "sub" / "a.png", b"png")])
    assert paths == [tmp_path / "old.txt", tmp_path / "new" / "sub" / "a.png"]
    assert (tmp_path / "old.txt").read_text() == "after" and paths[1].read_bytes() == b"png"
    assert files(tmp_path) == ["new", "old.txt", "taken"] and files(tmp_path / "new" / "sub") == ["a.png"]
    # a symlink is written through, as write_atomic writes it: the link stays
    (tmp_path / "link.txt").symlink_to(tmp_path / "old.txt")
    write_all([(tmp_path / "link.txt", "through")])
    assert (tmp_path / "link.txt").is_symlink() and (tmp_path / "old.txt").read_text() == "through"
    # one file named twice (here through the link): the second replaced the first unsaid
    with pytest.raises(InputError, match="link.txt name the same file: give two"):
        write_all([(tmp_path / "old.txt", "first"), (tmp_path / "link.txt", "second")])
    assert (tmp_path / "old.txt").read_text() == "through"


def test_fit_refuses_to_hold_out_on_another_sensor_than_the_datas(data, tmp_path):
    proc = run_cli("fitgen", "fit", str(data), "-o", str(tmp_path / "m.json"), "--sensor", "ring-vertical")
    assert_one_line_error(proc, contains="simulated with sensor paper (sha256 ")
    assert not (tmp_path / "m.json").exists()


def test_report_sweeps_only_on_the_sensor_the_model_was_fitted_on(fitted, data, tmp_path):
    (tmp_path / "m.json").write_text(json.dumps(fitted))
    model = str(tmp_path / "m.json")
    assert_one_line_error(run_cli("fitgen", "report", model, "--data", str(data), "--plot", str(tmp_path / "p"),
                                  "--sensor", "two-rings"), contains="--sensor two-rings: the model was fitted on "
                                                                     "another sensor")
    assert_one_line_error(run_cli("fitgen", "report", model, "--sensor", "paper"), contains="goes with --plot")
    assert_one_line_error(run_cli("fitgen", "report", model, "--paper"), contains="--paper goes with --data")
    assert not (tmp_path / "p").exists()


def test_readings_in_other_units_than_the_models_are_refused_by_predict_and_report(fitted, data, tmp_path):
    """The model takes mT; readings whose meta says V are refused in one line (the check tactile-host read makes)."""
    model = str(tmp_path / "m.json")
    (tmp_path / "m.json").write_text(json.dumps(fitted))
    volts = tmp_path / "v.csv"
    simulate(load_sensor("paper").with_transfer("gmr"), random_poses(20, DEFAULT_RANGES, pose_rng(2))).save(volts)
    said = f"model {model} takes inputs in mT; {volts}'s readings are in V"
    assert_one_line_error(run_cli("fitgen", "predict", model, str(volts), "-o", str(tmp_path / "e.csv")), contains=said)
    assert not (tmp_path / "e.csv").exists()
    assert_one_line_error(run_cli("fitgen", "report", model, "--data", str(volts)), contains=said)
    # readings in the model's units pass, and so do readings whose units are not recorded (no meta file)
    shutil.copy(volts, tmp_path / "bare.csv")
    for readings in (data, tmp_path / "bare.csv"):
        assert run_cli("fitgen", "predict", model, str(readings), "-o", str(tmp_path / "e.csv")).returncode == 0
        assert run_cli("fitgen", "report", model, "--data", str(readings)).returncode == 0


def test_predict_says_which_rows_have_no_estimate_without_numpy_warnings(fitted, data, tmp_path):
    (tmp_path / "m.json").write_text(json.dumps(fitted))
    lines = [",".join(ln.split(",")[:8]) for ln in data.read_text().splitlines()[:4]]
    lines[2] = "1e39," + lines[2].split(",", 1)[1]  # finite in double, beyond float's range
    (tmp_path / "r.csv").write_text("\n".join(lines) + "\n")
    proc = run_cli("fitgen", "predict", str(tmp_path / "m.json"), str(tmp_path / "r.csv"), "-o",
                   str(tmp_path / "p.csv"), "--precision", "float")
    assert proc.returncode == 0 and proc.stderr.strip().splitlines() == [
        f"wrote 3 estimates to {tmp_path / 'p.csv'} (1 row with no estimate (status -1: a reading not finite in "
        "float))"], proc.stderr
    assert [ln.rsplit(",", 1)[1] for ln in (tmp_path / "p.csv").read_text().splitlines()[1:]] == ["0", "-1", "0"]


def test_fit_refuses_refine_terms_below_five_without_refine_too(data, tmp_path):
    assert_one_line_error(run_cli("fitgen", "fit", str(data), "-o", str(tmp_path / "m.json"), "--refine-terms", "3"),
                          contains="--refine-terms must be >= 5")


@pytest.mark.parametrize("args, said", [
    (["--refine-terms", "10"], "--refine-terms caps the forward model of --refine STEPS: without --refine it would "
                               "be ignored"),
    (["--refine", "0", "--refine-terms", "30"], "without --refine it would be ignored"),
    (["--true-d", "--no-d-terms"], "--true-d and --no-d-terms contradict each other"),
    (["--true-d", "--outputs", "dx,dz"], "--true-d shapes the rotations' d-terms, which a fit of thx or thy with dx, "
                                         "dy and dz has, not this one (dx, dz): it would be ignored"),
    (["--no-d-terms", "--outputs", "dz"], "--no-d-terms shapes the rotations' d-terms"),
    (["--true-d", "--outputs", "dx,thx"], "not this one (dx, thx): it would be ignored"),  # no d without dy, dz
    (["--force"], "d.csv names no scene, so it would be ignored"),
    (["--force", "--outputs", "dx"], "--force applies to a scene's outputs (--scene, or the scene the data were "
                                     "simulated for): --outputs names them here, so it would be ignored"),
])
def test_fit_refuses_options_that_would_be_ignored_or_contradict(data, tmp_path, args, said):
    assert_one_line_error(run_cli("fitgen", "fit", str(data), "-o", str(tmp_path / "m.json"), *args),
                          contains=said)
    assert not (tmp_path / "m.json").exists()


def test_fit_settings_fill_the_refine_cap_the_help_states():
    import argparse

    from fitgen.app.cli import build_parser
    from fitgen.app.options import fit_settings

    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction)).choices["fit"]
    assert "cap on the forward model's terms per element (default 30)" in " ".join(sub.format_help().split())
    args = sub.parse_args(["d.csv", "-o", "m.json", "--refine", "1"])
    assert args.refine_terms is None and fit_settings(args).refine_terms == 30
    assert fit_settings(sub.parse_args(["d.csv", "-o", "m.json", "--refine", "1", "--refine-terms", "9"])
                        ).refine_terms == 9



def test_fit_takes_the_units_of_data_without_meta_from_units(data, tmp_path):
    bare = tmp_path / "bare.csv"
    bare.write_text(data.read_text())  # the rows without their meta file, as a user's own CSV comes
    proc = run_cli("fitgen", "fit", str(bare), "-o", str(tmp_path / "v.json"), "--outputs", "dz", "--units", "V")
    assert proc.returncode == 0, proc.stderr
    assert json.loads((tmp_path / "v.json").read_text())["inputs"]["units"] == "V"
    proc = run_cli("fitgen", "fit", str(bare), "-o", str(tmp_path / "m.json"), "--outputs", "dz")
    assert proc.returncode == 0 and "no meta saying its readings' units: taken as mT" in proc.stderr
    assert_one_line_error(run_cli("fitgen", "fit", str(data), "-o", str(tmp_path / "x.json"), "--units", "V"),
                          contains="meta says its readings are in mT")


@pytest.mark.parametrize("tool, args", [("fitgen", ["observe", "--sensor", "paper"]), ("fitgen", ["--help"]),
                                        ("tactile-host", ["read", "--adc", "ads1115@0x48:0-3,ads1115@0x49:0-3",
                                                          "--simulate", "motion", "--duration", "0.3"])])
def test_a_standard_output_that_cannot_be_written_is_one_line(tmp_path, tool, args):
    """A full disk behind standard output (> /dev/full) is said in one line with status 2, not a traceback."""
    import subprocess
    import sys

    if tool == "tactile-host":  # a model in volts, as the ADCs give
        assert run_cli("fitgen", "simulate", "--sensor", "paper", "--transfer", "gmr", "--grid", "paper-exp", "-o",
                       str(tmp_path / "d.csv")).returncode == 0
        assert run_cli("fitgen", "fit", str(tmp_path / "d.csv"), "-o", str(tmp_path / "m.json"), "--held-out", "100",
                       "--family", "no-roots").returncode == 0
        args = [*args, "--model", str(tmp_path / "m.json")]
    module = {"fitgen": "fitgen.app.cli", "tactile-host": "fitgen.app.host_cli"}[tool]
    with open("/dev/full", "w") as full:
        proc = subprocess.run([sys.executable, "-c", f"import sys; from {module} import main; sys.argv[0] = {tool!r}; "
                               "main()", *args], stdout=full, stderr=subprocess.PIPE, text=True, timeout=120)
    prog = tool if args[0].startswith("-") else f"{tool} {args[0]}"  # the subcommand's name, once parsed
    assert_one_line_error(proc, 2, f"{prog}: error: cannot write standard output: No space left on device")


@pytest.mark.parametrize("args", [["fit", "nothere.csv", "-o", "m.json"], ["fit", "--k"],
                                  ["simulate", "--sensor", "nothere.toml", "-o", "d.csv"],
                                  ["fit", "d.csv", "-o", "m.json", "--bogus", "x"]])
def test_every_error_line_of_a_subcommand_starts_with_its_name(args, tmp_path):
    """argparse's lines said "fitgen fit: error:" and the command's own "fitgen: error:"; both now name it."""
    proc = run_cli("fitgen", *args, cwd=tmp_path)
    assert_one_line_error(proc, 2)
    assert proc.stderr.startswith(f"fitgen {args[0]}: error: "), proc.stderr
    if "--bogus" in args:  # the top parser said these, after its own name alone
        assert proc.stderr.strip() == "fitgen fit: error: unrecognized arguments: --bogus x"


@pytest.mark.parametrize("tool, command", [("fitgen", "simulate"), ("tactile-host", "read"), ("tactile-hil", "emulate")])
def test_a_command_given_nothing_lists_its_subcommands(tool, command):
    """`fitgen` alone said one line, "the following arguments are required: command", and named none."""
    proc = run_cli(tool)
    assert proc.returncode == 2 and proc.stderr.startswith(f"usage: {tool}") and command in proc.stderr, proc.stderr
    assert "thin layer" not in proc.stderr  # the module's docstring is not the command's description


@pytest.mark.parametrize("args, said", [
    (["simulate", "--random", "5", "-o", "d.json"], "-o d.json: simulate writes a dataset in CSV: name it .csv"),
    (["simulate", "--random", "5", "-o", "d.toml"], "-o d.toml: simulate writes a dataset in CSV"),
    (["fit", "nothere.csv", "-o", "m.csv"], "-o m.csv: fit writes a model in JSON: name it .json"),
    (["identify", "nothere.csv", "-o", "u.json"], "-o u.json: the unit file is a sensor file in TOML: name it .toml"),
    # these wrote over a model named by a slip: schedule's CSV, the suite's XML, stage-sim's pose line
    (["schedule", "--n", "10", "-o", "model.json"], "-o model.json: schedule writes poses in CSV: name it .csv"),
    (["predict", "nothere.json", "nothere.csv", "-o", "e.toml"], "-o e.toml: predict writes estimates in CSV"),
    (["report", "nothere.json", "-o", "sim.csv"], "-o sim.csv: report writes Markdown: name it .md"),
    (["tactile-hil", "run", "--model", "m.json", "--port", "socket://localhost:1", "--junit", "model.json"],
     "--junit model.json: the results are JUnit XML: name it .xml"),
    (["tactile-host", "stage-sim", "--pose-file", "model.json"], "--pose-file model.json: the pose file is one line"),
])
def test_an_output_named_as_another_kind_of_file_is_refused_before_the_work(args, said, tmp_path):
    """simulate -o x.json wrote CSV into a .json file without a word (identify refused a .csv unit file already)."""
    tool, args = (args[0], args[1:]) if args[0].startswith("tactile") else ("fitgen", args)
    assert_one_line_error(run_cli(tool, *args, cwd=tmp_path), 2, said)
    assert list(tmp_path.iterdir()) == []


def test_an_output_over_a_dataset_is_refused(model_file, tmp_path):
    """predict -o other.csv wrote estimates over a dataset and left its meta beside them (which then spoke for the
    estimates); report -o x.md over one wrote Markdown. simulate over its own kind writes as ever."""
    sim = run_cli("fitgen", "simulate", "--random", "20", "-o", str(tmp_path / "other.csv"))
    assert sim.returncode == 0, sim.stderr
    other = tmp_path / "other.csv"
    kept = other.read_bytes()
    run_cli("fitgen", "simulate", "--random", "20", "--seed", "2", "-o", str(tmp_path / "d.csv"))
    assert_one_line_error(run_cli("fitgen", "predict", model_file, str(tmp_path / "d.csv"), "-o", str(other)), 2,
                          f"-o {other} is a dataset (its meta is beside it): predict would write another kind of "
                          "file over it")
    (tmp_path / "notes.md").write_bytes(kept)
    (tmp_path / "notes.md.meta.json").write_bytes((tmp_path / "other.csv.meta.json").read_bytes())
    assert_one_line_error(run_cli("fitgen", "report", model_file, "-o", str(tmp_path / "notes.md")), 2,
                          "is a dataset (its meta is beside it): report would write")
    assert other.read_bytes() == kept and (tmp_path / "notes.md").read_bytes() == kept
    assert run_cli("fitgen", "simulate", "--random", "20", "-o", str(other)).returncode == 0


def test_codes_that_are_not_whole_or_beyond_int32_are_named_by_row_and_column(tmp_path):
    from fitgen.equations.fixedpoint import build_fixed
    from fitgen.base.errors import InputError

    model = Model(np.zeros(2) + 1.0, np.zeros(2) + 2.0, (Equation("dz", 0.5, (Term(1, "1"),), (2.0,)),), "V")
    fm = build_fixed(model, 1e-4, 0.0, 32)
    with pytest.raises(InputError, match=r"whole numbers \(row 2, v2: 1.5\)"):
        fm.clamp_codes(np.array([[1.0, 2.0], [3.0, 1.5]]))
    with pytest.raises(InputError, match=r"int32 \(row 1, v1: 3000000000\)"):
        fm.clamp_codes(np.array([[3e9, 2.0]]))


@pytest.mark.parametrize("script,prog", [("fitgen", "fitgen"), ("tactile_host", "tactile-host"),
                                         ("tactile_hil", "tactile-hil")])
def test_a_ctrl_c_while_a_command_starts_is_one_line(script, prog):
    """The console scripts (fitgen.app.entry): a Ctrl-C while the command's modules are imported (numpy's import
    takes a moment) is 'interrupted' and status 130, as at any other time, not a traceback."""
    import subprocess
    import sys

    code = ("import fitgen.app.entry as e\n"
            "def interrupted(name):\n    raise KeyboardInterrupt\n"
            f"e.import_module = interrupted\ne.{script}()\n")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert_one_line_error(proc, 130, f"{prog}: interrupted")
    # earlier still, in the guard's own import (a Ctrl-C 80 ms after start had shown cliutil's 'import math')
    code = ("import sys\nclass Stop:\n    def find_spec(self, name, *a):\n"
            "        if name == 'fitgen.app.cliutil':\n            raise KeyboardInterrupt\n"
            f"sys.meta_path.insert(0, Stop())\nimport fitgen.app.entry as e\ne.{script}()\n")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert_one_line_error(proc, 130, f"{prog}: interrupted")


def test_a_ctrl_c_after_the_last_line_leaves_the_commands_status(tmp_path):
    """A Ctrl-C in the tens of milliseconds the interpreter takes to shut down, after the command's last line, had
    ended it by SIGINT with no line (the shell's 130): the work was done and said, its status stands. One that
    lands before the command has returned is its 'interrupted', as at any other time."""
    import signal
    import subprocess
    import sys

    code = "import sys; from fitgen.app.entry import fitgen; sys.argv[0] = 'fitgen'; fitgen()"
    for k in range(3):
        out = tmp_path / f"s{k}.csv"
        proc = subprocess.Popen([sys.executable, "-c", code, "simulate", "--sensor", "paper", "--random", "5", "-o",
                                 str(out)], stderr=subprocess.PIPE, text=True)
        first = proc.stderr.readline()
        proc.send_signal(signal.SIGINT)
        rest = proc.stderr.read()
        status = proc.wait(timeout=60)
        assert first.startswith("wrote 5 rows") and out.is_file(), first + rest
        assert (status, rest) == (0, "") or (status == 130 and rest == "fitgen simulate: interrupted\n"), \
            (status, rest)


@pytest.mark.parametrize("sep", [";", "\t"])
def test_a_spreadsheets_export_with_another_separator_is_named(data, tmp_path, sep):
    """A locale whose decimal point is a comma exports ';' (or tabs): it read as 'line 2: 14 fields, the header
    has 1', which names neither the separator nor the fix."""
    other = tmp_path / "other.csv"
    other.write_text(data.read_text().replace(",", sep))
    for argv in (["fit", str(other), "-o", str(tmp_path / "m.json")],
                 ["identify", str(other), "-o", str(tmp_path / "u.toml")]):
        assert_one_line_error(run_cli("fitgen", *argv), contains=f"its header is separated by {sep!r}, not commas")
    assert files(tmp_path) == ["other.csv"]


@pytest.mark.parametrize("cmd", [("fitgen", "simulate", "--n", "20"),  # --noise's prefix: 20 V of noise, unsaid
                                 ("fitgen", "schedule", "--check", "5", "--se", "1"),
                                 ("tactile-host", "capture", "--simulate", "--adc", "ads1115@0x48:0-3", "--poses",
                                  "s.csv", "--samp", "3"),
                                 ("tactile-hil", "emulate", "--model", "m.json", "--sim", "paper")])
def test_a_long_option_shortened_is_refused_not_read_as_the_one_it_begins(cmd, tmp_path):
    out = tmp_path / "out.csv"
    proc = run_cli(*cmd, "-o", str(out))
    assert_one_line_error(proc, contains=f"unrecognized arguments: {cmd[-2]} {cmd[-1]}")
    assert not out.exists()


def test_a_file_name_too_long_and_brackets_nested_too_deep_are_one_line(tmp_path):
    """Path.is_file() raises on a name over 255 bytes (it returns False for a missing file), and the JSON and TOML
    parsers recurse per bracket: both came out as tracebacks, in every command that takes a file."""
    long = tmp_path / ("a" * 300 + ".csv")
    for argv in (("fitgen", "simulate", "--sensor", "paper", "--grid", "paper-exp", "-o", str(long)),
                 ("fitgen", "fit", str(long), "-o", str(tmp_path / "m.json"))):
        assert_one_line_error(run_cli(*argv), contains="a file name is too long for this system")
    (tmp_path / "deep.json").write_text("[" * 100000 + "]" * 100000)
    (tmp_path / "deep.toml").write_text("a = " + "[" * 100000 + "]" * 100000)
    for argv in (("fitgen", "codegen", str(tmp_path / "deep.json"), "-o", str(tmp_path / "c")),
                 ("fitgen", "simulate", "--sensor", str(tmp_path / "deep.toml"), "--grid", "dx=0", "-o",
                  str(tmp_path / "d.csv")),
                 ("tactile-host", "replay", str(tmp_path / "deep.json")),
                 ("tactile-hil", "run", "--port", "socket://127.0.0.1:9", "--model", str(tmp_path / "deep.json"))):
        assert_one_line_error(run_cli(*argv), contains="an input file nests brackets too deeply to read")
    assert sorted(f.name for f in tmp_path.iterdir()) == ["deep.json", "deep.toml"]


def test_a_huge_reading_is_one_line_in_identify_and_check(data, model_file, tmp_path):
    """fit refused a reading beyond 1e30 where it is; identify gave a traceback from least_squares (residuals not
    finite) or warnings and 'residuals infx the noise', check a cast's overflow warning before its verdict."""
    from fitgen.physics.dataset import load_dataset

    ds = load_dataset(data)
    rows = ds.inputs.copy()
    rows[3, 1] = 1e308
    type(ds)(rows, ds.targets, ds.target_names).save(tmp_path / "huge.csv")
    for argv in (("identify", str(tmp_path / "huge.csv"), "--sensor", "paper", "-o", str(tmp_path / "u.toml")),
                 ("check", model_file, str(tmp_path / "huge.csv")),
                 ("fit", str(tmp_path / "huge.csv"), "-o", str(tmp_path / "m.json"))):
        assert_one_line_error(run_cli("fitgen", *argv), contains="data row 4, column v2, holds 1e+308: beyond any "
                                                                 "reading or pose")
    assert files(tmp_path) == ["huge.csv", "huge.csv.meta.json"]
    # a reading too close to 0 for a negative power: one line naming term and row (numpy's warnings came first)
    rows[3, 1] = 1e-320
    type(ds)(rows, ds.targets, ds.target_names).save(tmp_path / "huge.csv")
    assert_one_line_error(run_cli("fitgen", "fit", str(tmp_path / "huge.csv"), "-o", str(tmp_path / "m.json")),
                          contains="candidate term v2^-1 for dx is not finite on data row 4 (an input too close to 0?)")
    # numbered as in the file when a stage's rest row before it was left out (it said row 3)
    poses = ds.targets.copy()
    poses[0, ds.target_names.index("dz")] = 0.2
    type(ds)(rows, poses, ds.target_names, {"samples_per_row": 16}).save(tmp_path / "huge.csv")
    out = run_cli("fitgen", "fit", str(tmp_path / "huge.csv"), "-o", str(tmp_path / "m.json"))
    assert "left out 1 row(s) lifted off the skin" in out.stderr
    assert out.stderr.strip().splitlines()[-1].endswith("is not finite on data row 4 (an input too close to 0?)")
    assert out.returncode == 2 and not (tmp_path / "m.json").exists()


def test_more_inputs_than_the_c_status_holds_are_said_by_fit(tmp_path):
    """31 elements fitted without a word; codegen then refused the model (the status mask holds 30 bits)."""
    from fitgen.physics.dataset import Dataset

    rng = np.random.default_rng(0)
    v = rng.uniform(1, 2, (300, 31))
    Dataset(v, (v[:, 0] - v[:, 1])[:, None], ("dz",)).save(tmp_path / "w.csv")
    proc = run_cli("fitgen", "fit", str(tmp_path / "w.csv"), "--family", "integer", "-o", str(tmp_path / "m.json"))
    assert proc.returncode == 0, proc.stderr
    assert "note: 31 inputs: the generated C's status holds one bit per input, at most 30" in proc.stderr
    holds = "the generated C's status (one bit per input, in a C int) holds at most 30"
    for precision in ("double", "fixed"):  # fixed point's was written, to fail its static assertion in gcc
        assert_one_line_error(run_cli("fitgen", "codegen", str(tmp_path / "m.json"), "-o", str(tmp_path / "c"),
                                      "--precision", precision), contains=holds)
    assert not (tmp_path / "c").exists()
    # predict computes what codegen writes: it printed estimates with a status of 2**31 - 1 for C never written
    assert_one_line_error(run_cli("fitgen", "predict", str(tmp_path / "m.json"), str(tmp_path / "w.csv"),
                                  "-o", str(tmp_path / "e.csv")), contains=holds)
    assert not (tmp_path / "e.csv").exists()


def test_an_uno_status_holds_fifteen_inputs(tmp_path):
    """avr-gcc's int is 16 bits: a 16-input model for the Uno was written, to fail its static assertion."""
    from fitgen.physics.dataset import Dataset

    v = np.random.default_rng(0).uniform(1, 2, (300, 16))
    Dataset(v, (v[:, 0] - v[:, 1])[:, None], ("dz",)).save(tmp_path / "w.csv")
    assert run_cli("fitgen", "fit", str(tmp_path / "w.csv"), "--family", "integer",
                   "-o", str(tmp_path / "m.json")).returncode == 0
    for cmd in (["codegen", str(tmp_path / "m.json"), "-o", str(tmp_path / "c")],
                ["predict", str(tmp_path / "m.json"), str(tmp_path / "w.csv"), "-o", str(tmp_path / "e.csv")]):
        assert_one_line_error(run_cli("fitgen", *cmd, "--target", "uno", "--precision", "float"),
                              contains="status (one bit per input, in target uno's 16-bit int) holds at most 15")
    assert run_cli("fitgen", "codegen", str(tmp_path / "m.json"), "-o", str(tmp_path / "c"),
                   "--target", "mps2").returncode == 0


def test_a_pose_column_removed_since_the_meta_is_refused_by_identify_and_check(data, model_file, tmp_path):
    """A capture whose dz column was cut (the meta kept) read as dz 0 on every row: identify refused it as physics
    it cannot explain after a minute of fault trials, check told the user to calibrate a unit that was fine."""
    shutil.copy(str(data) + ".meta.json", tmp_path / "cut.csv.meta.json")
    header = data.read_text().splitlines()[0].split(",")
    keep = [i for i, c in enumerate(header) if c != "dz"]
    (tmp_path / "cut.csv").write_text("".join(",".join(line.split(",")[i] for i in keep) + "\n"
                                              for line in data.read_text().splitlines()))
    runs = (("identify", str(tmp_path / "cut.csv"), "--sensor", "paper", "-o", str(tmp_path / "u.toml")),
            ("check", model_file, str(tmp_path / "cut.csv")), ("fit", str(tmp_path / "cut.csv"), "-o",
                                                                str(tmp_path / "m.json")))
    for argv in runs[:2]:
        assert_one_line_error(run_cli("fitgen", *argv), contains=f"{tmp_path / 'cut.csv'} has no dz column, which "
                                                                 "its meta records")
    # fit on a stage's rows too (it had trained the rows lifted off the skin as rows in contact); a simulated
    # dataset's label cut is an output left out, which fit takes
    meta = json.loads((tmp_path / "cut.csv.meta.json").read_text())
    (tmp_path / "cut.csv.meta.json").write_text(json.dumps({**meta, "labels": "stage"}))
    assert_one_line_error(run_cli("fitgen", *runs[2]), contains="has no dz column, which its meta records")
    (tmp_path / "cut.csv.meta.json").write_text(json.dumps(meta))
    assert run_cli("fitgen", *runs[2], "--held-out", "0").returncode == 0
    (tmp_path / "m.json").unlink()
    # the last reading column cut: blamed on the meta's noise figures, whose removal led to a model of 7 inputs
    last = max(i for i, c in enumerate(header) if c.startswith("v"))
    (tmp_path / "cut.csv").write_text("".join(",".join(c for i, c in enumerate(line.split(",")) if i != last) + "\n"
                                              for line in data.read_text().splitlines()))
    for argv in runs:
        assert_one_line_error(run_cli("fitgen", *argv), contains=f"has no {header[last]} column, which its meta "
                                                                 "records: a reading column removed")
    assert files(tmp_path) == ["cut.csv", "cut.csv.meta.json"]


def test_the_librarys_entry_points_refuse_bad_arrays_in_their_own_words(device_model):
    """From Python, identify, check, observe, Model.predict and fit_tempcomp raised numpy's and scipy's errors
    (IndexError, a broadcast ValueError, KeyError 'dy', 'Residuals are not finite') on rows that do not match
    their poses, a NaN reading or a box that leaves a component out; each is now an InputError saying what."""
    from fitgen.base.errors import InputError
    from fitgen.fitting.check import check
    from fitgen.fitting.identify import identify
    from fitgen.fitting.schedule import schedule
    from fitgen.physics.observe import observe
    from fitgen.physics.scenes import PRESETS
    from fitgen.physics.sensor import load_sensor
    from fitgen.physics.simulate import simulate
    from host.temperature import fit_tempcomp

    sensor = load_sensor("paper").with_transfer("gmr")
    poses, _ = schedule(sensor, 40, noise=sensor.noise / 4)
    X = simulate(sensor, poses).inputs
    nan = X.copy()
    nan[3, 2] = np.nan
    cases = [
        (lambda: identify(sensor, X, poses[:30], 1.25e-4), "40 rows of readings and 30 poses"),
        (lambda: identify(sensor, X, poses[:, :3], 1.25e-4), "must be (rows, elements) and (rows, 5"),
        (lambda: identify(sensor, nan, poses, 1.25e-4), "row 4's reading v3 is nan"),
        (lambda: check(device_model, X, poses[:30], sensor, 1.25e-4), "40 rows of readings and 30 poses"),
        (lambda: check(device_model, X, poses, sensor, -1e-4), "reading noise must be finite and >= 0"),
        (lambda: check(device_model, X, poses, sensor, None), "must be finite and >= 0, got None"),
        (lambda: check(device_model, X, poses, sensor, np.full(3, 1e-4)), "gives 3 figures for 8 elements"),
        (lambda: identify(sensor, X, poses, np.full(5, 1e-4)), "gives 5 figures for 8 elements"),
        (lambda: identify(sensor, X, poses, 0.0), "reading noise (--noise, or a sensor file's figure) must be"),
        (lambda: observe(sensor, PRESETS["slide"].ranges, ("dx", "zz")), "got dx, zz"),
        (lambda: observe(sensor, {"dx": (-2, 2)}, ("dx",)), "gives no range for dy"),
        (lambda: observe(sensor, {**PRESETS["slide"].ranges, "dx": (2, -2)}, ("dx",)), "lo must not exceed hi"),
        (lambda: observe(sensor, PRESETS["slide"].ranges, ()), "got none"),
        (lambda: device_model.predict(np.zeros((3, 8, 1))), "a 1-D or 2-D array"),
        (lambda: fit_tempcomp(X, np.arange(40), np.full(39, 25.0)), "a pose id and a temperature each"),
        (lambda: fit_tempcomp(X[0], np.arange(1), np.full(1, 25.0)), "a pose id and a temperature each"),
    ]
    for call, said in cases:
        with pytest.raises(InputError, match=re.escape(said)):
            call()


def test_a_held_out_record_edited_by_hand_is_one_line_where_it_is_simulated_again(data, tmp_path):
    """verify and tactile-hil run simulate the model's held-out set again from its record: a box without every pose
    component raised KeyError there, and rest readings that are text raised ValueError in read --tare (tracebacks);
    the box is said in one line where it is read, the rest as the model is loaded."""
    from fitgen.fitting.fit import fit_model
    from fitgen.fitting.holdout import fitted_held_out
    from fitgen.physics.dataset import load_dataset

    ds = load_dataset(data)
    model = fit_model(ds)
    model.fit_info["held_out"] = fitted_held_out(model, load_sensor("paper"), ds, 20)
    good = model.to_dict()
    for edit, argv, said in (
            (lambda h: h.__setitem__("box", {"dx": [-1, 1]}), ["tactile-host", "verify"],
             "fit.held_out.box gives no range for dy, dz, thx, thy"),
            (lambda h: h.__setitem__("rest", ["a"] * 8), ["fitgen", "report"], "fit.held_out.rest must be a list")):
        d = json.loads(json.dumps(good))
        edit(d["fit"]["held_out"])
        (tmp_path / "m.json").write_text(json.dumps(d))
        assert_one_line_error(run_cli(*argv, str(tmp_path / "m.json")), 2, said)


def test_too_few_rows_for_the_initial_equation_say_why_a_cap_needs_them_too(tmp_path):
    """A cap starts from eq. 1 cut down by its fit, so 8 rows are too few for --max-terms 2 as for none: the refusal
    had named eq. 1's 17 coefficients without a word on the cap of 2."""
    data = tmp_path / "tiny.csv"
    assert run_cli("fitgen", "simulate", "--random", "8", "-o", str(data)).returncode == 0
    head = ("8 rows cannot fit the 17 coefficients of the initial equation for dx and leave the two residual degrees "
            "of freedom the search starts with")
    for cap, said in (([], f"{head}; give at least 19 rows"),
                      (["--max-terms", "2"], f"{head} (--max-terms cuts it down by its fit); give at least 19 rows")):
        assert_one_line_error(run_cli("fitgen", "fit", str(data), "-o", str(tmp_path / "m.json"), *cap), 2, said)


def test_a_dataset_of_rows_off_the_skin_alone_is_one_line_in_fit_and_report(fitted, tmp_path):
    """Every row lifted off the skin: fit noted the rows it left out, then refused a dataset of no rows; report
    noted them before its refusal. Each is now the refusal alone, saying why."""
    off = tmp_path / "off.csv"
    assert run_cli("fitgen", "simulate", "--grid", "dx=0,1 dz=0.2", "-o", str(off)).returncode == 0
    (tmp_path / "m.json").write_text(json.dumps(fitted))
    for argv, what in ((["fit", str(off), "-o", str(tmp_path / "new.json")], "fit"),
                       (["report", str(tmp_path / "m.json"), "--data", str(off)], "report on")):
        assert_one_line_error(run_cli("fitgen", *argv), 2, f"{off}: every row is lifted off the skin, so no contact "
                              f"pose to {what}")
    assert not (tmp_path / "new.json").exists()
