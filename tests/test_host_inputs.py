"""tactile-host as users get it wrong, and the temperature capture's bookkeeping: one line and exit status 2 (1 for
a device fault), no file destroyed, no compensation fitted from the wrong numbers."""

import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from conftest import TWO_CHIPS, assert_one_line_error, run_cli

WITH_TEMP = TWO_CHIPS + ",temp=ads1115@0x4a:0"
SCHEDULE = "dx,dy,dz\n0,0,0.2\n2,-2,0\n-2,-2,0\n0,-2,-2\n2,2,-2\n-2,2,-2\n"


def read(model_file, *extra, cwd=None):
    return run_cli("tactile-host", "read", "--model", model_file, "--adc", TWO_CHIPS, "--simulate", "dx=1",
                   "--count", "2", *extra, cwd=cwd)


def test_no_output_is_an_input_or_another_output(model_file, tmp_path):
    model = tmp_path / "m.json"
    shutil.copy(model_file, model)
    (tmp_path / "s.csv").write_text(SCHEDULE)
    before = model.read_bytes()
    for argv, said in ((["-o", str(model)], f"-o {model} is the input"),
                       (["--record", str(model)], f"--record {model} is the input"),
                       (["-o", str(tmp_path / "a"), "--record", str(tmp_path / "a")], "-o and --record name the same")):
        assert_one_line_error(read(str(model), *argv), 2, said)
    assert model.read_bytes() == before and not (tmp_path / "a").exists()
    proc = run_cli("tactile-host", "capture", "--poses", str(tmp_path / "s.csv"), "--adc", TWO_CHIPS, "--simulate",
                   "-o", str(tmp_path / "s.csv"))
    assert_one_line_error(proc, 2, "is the input")
    assert (tmp_path / "s.csv").read_text() == SCHEDULE


def test_no_output_replaces_another_kind_of_the_tools_json_files(model_file, tmp_path):
    """`fit -o` over a temperature compensation, `capture --temp-comp-output` or `noise -o` over a model: each wrote
    its own JSON over the other's, exit 0, and schedule, simulate, read or noise wrote over a capture. Refused in one
    line naming what the file is; a model over a model is a refit, taken."""
    model = tmp_path / "m.json"
    shutil.copy(model_file, model)
    assert capture_t(tmp_path, SCHEDULE, "15,25", "--samples", "2").returncode == 0
    comp, level = tmp_path / "cap.tempcomp.json", tmp_path / "cap.T15.csv"
    noise = tmp_path / "noise.json"
    assert run_cli("tactile-host", "noise", "--adc", TWO_CHIPS, "--simulate", "--seconds", "1", "-o",
                   str(noise)).returncode == 0
    kept = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    for tool, argv, said in (
            ("fitgen", ["fit", str(level), "-o", str(comp)], f"-o {comp} is a temperature compensation: fit would "
             "write a model over it"),
            ("fitgen", ["fit", str(level), "-o", str(noise)], f"-o {noise} is a noise record: fit would write a model"),
            ("tactile-host", ["noise", "--adc", TWO_CHIPS, "--simulate", "--seconds", "1", "-o", str(model)],
             f"-o {model} is a model: noise would write a noise record over it"),
            ("tactile-host", ["capture", "--poses", str(tmp_path / "s.csv"), "--adc", WITH_TEMP, "--simulate",
                              "--temperature", "15,25", "-o", str(tmp_path / "c2.csv"), "--temp-comp-output",
                              str(model)], f"--temp-comp-output {model} is a model: capture would write a temperature "
             "compensation over it"),
            ("tactile-host", ["read", "--model", model_file, "--adc", TWO_CHIPS, "--simulate", "dx=1", "--count", "1",
                              "--record", str(comp)], f"--record {comp} is a temperature compensation: read would "
             "write a run record over it"),
            # a capture (a level's file) is measured: no other command's output replaces it
            ("fitgen", ["schedule", "--n", "20", "-o", str(level)], f"-o {level} is a capture (rows measured on the "
             "sensor, as its meta says): schedule would write over it"),
            ("fitgen", ["simulate", "--random", "10", "-o", str(level)], f"-o {level} is a capture"),
            ("tactile-host", ["read", "--model", model_file, "--adc", TWO_CHIPS, "--simulate", "dx=1", "--count", "1",
                              "-o", str(level)], f"-o {level} is a capture"),
            ("tactile-host", ["noise", "--adc", TWO_CHIPS, "--simulate", "--seconds", "1", "-o", str(level)],
             f"-o {level}: the noise record is JSON: name it .json"),
            ("tactile-host", ["capture", "--poses", str(tmp_path / "s.csv"), "--adc", WITH_TEMP, "--simulate",
                              "--temperature", "15,25", "-o", str(tmp_path / "c2.csv"), "--temp-comp-output",
                              str(level)], f"--temp-comp-output {level}: the compensation is JSON: name it .json")):
        assert_one_line_error(run_cli(tool, *argv), 2, said)
        assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == kept
    sim = tmp_path / "sim.csv"
    assert run_cli("fitgen", "simulate", "--random", "100", "-o", str(sim)).returncode == 0
    # through a link, the file it leads to is what would be written over
    (tmp_path / "link.json").symlink_to(f"{level}.meta.json")
    assert_one_line_error(run_cli("fitgen", "fit", str(sim), "-o", str(tmp_path / "link.json")), 2,
                          f"-o {tmp_path / 'link.json'} is a dataset's meta: fit would write a model over it")
    proc = run_cli("fitgen", "fit", str(sim), "-o", str(model))
    assert proc.returncode == 0 and model.read_bytes() != kept["m.json"], proc.stderr


def test_a_schedule_is_written_over_only_by_a_schedule_of_its_kind(tmp_path):
    """`schedule --check -o schedule.csv` or `simulate -o schedule.csv` replaced the calibration schedule a capture's
    meta names, and the capture could no longer resume; a schedule made again with other options is taken."""
    cal, chk = tmp_path / "schedule.csv", tmp_path / "check.csv"
    for argv in (["--n", "12", "-o", str(cal)], ["--check", "5", "-o", str(chk)]):
        assert run_cli("fitgen", "schedule", *argv).returncode == 0
    kept = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    for argv, said in ((["schedule", "--check", "5", "-o", str(cal)], f"-o {cal} is a calibration schedule (poses for "
                        "tactile-host capture, as its meta says): schedule would write a check schedule over it"),
                       (["simulate", "--random", "10", "-o", str(cal)], "simulate would write a dataset over it"),
                       (["schedule", "--n", "12", "-o", str(chk)], f"-o {chk} is a check schedule")):
        assert_one_line_error(run_cli("fitgen", *argv), 2, said)
        assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == kept
    for argv in (["--n", "14", "-o", str(cal)], ["--check", "6", "-o", str(chk)]):
        assert run_cli("fitgen", "schedule", *argv).returncode == 0
    assert all(p.read_bytes() != kept[p.name] for p in (cal, chk))
    # nor a schedule over a dataset's readings (it had replaced them, and simulate then refused the name back)
    sim = tmp_path / "sim.csv"
    assert run_cli("fitgen", "simulate", "--random", "10", "-o", str(sim)).returncode == 0
    kept = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    for argv in (["--n", "12", "-o", str(sim)], ["--check", "5", "-o", str(sim)]):
        assert_one_line_error(run_cli("fitgen", "schedule", *argv), 2, f"-o {sim} is a dataset (its meta is beside "
                              "it): schedule would write a")
        assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == kept
    assert run_cli("fitgen", "simulate", "--random", "12", "-o", str(sim)).returncode == 0  # a dataset over it, as ever


def test_a_record_that_cannot_be_made_leaves_the_output_as_it_was(model_file, tmp_path):
    (tmp_path / "keep.csv").write_text("precious\n")
    assert_one_line_error(read(model_file, "-o", str(tmp_path / "keep.csv"), "--record",
                               str(tmp_path / "no" / "r.jsonl")), 2, "does not exist")
    assert (tmp_path / "keep.csv").read_text() == "precious\n"


@pytest.mark.parametrize("option, said", [(["--sim-noise", "nan"], "not a finite number"),
                                          (["--sim-offsets", "nan,0,0,0,0,0,0,0"], "give numbers within +-100 V"),
                                          (["--sim-drift", "ramp=nan"], "ramp must be a finite number"),
                                          (["--sim-drift", "seed=-1"], "seed must be a whole number >= 0")])
def test_simulation_options_that_are_not_numbers_are_one_line(model_file, option, said):
    assert_one_line_error(read(model_file, *option), 2, said)


def test_a_chip_silent_during_the_tare_is_one_line_and_status_1(model_file):
    proc = read(model_file, "--tare", "--sim-fault", "silent:0x49:40")
    assert_one_line_error(proc, 1, "ads1115@0x49 stays silent")
    assert "stopped before the first sample" in proc.stderr


def test_rest_readings_come_in_volts_and_from_a_schedules_lifted_row(model_file, tmp_path):
    assert run_cli("fitgen", "simulate", "--sensor", "paper", "--grid", "dx=0,1", "-o",
                   str(tmp_path / "mt.csv")).returncode == 0
    assert_one_line_error(read(model_file, "--tare", "--rest", str(tmp_path / "mt.csv")), 2,
                          "its readings are in mT; the ADCs give volts")
    (tmp_path / "s.csv").write_text(SCHEDULE)  # its rest row is lifted 0.2 mm off the skin, no row at pose 0
    assert run_cli("tactile-host", "capture", "--poses", str(tmp_path / "s.csv"), "--adc", TWO_CHIPS, "--simulate",
                   "-o", str(tmp_path / "lab.csv")).returncode == 0
    proc = read(model_file, "--tare", "--rest", str(tmp_path / "lab.csv"))
    assert proc.returncode == 0, proc.stderr


@pytest.mark.parametrize("edit", [lambda h: h.__setitem__("auto_zero", True),
                                  lambda h: h.__setitem__("tare", [0.0, 0.0, 0.0]),
                                  lambda h: h.__setitem__("temp_comp", {"t0": 25}),
                                  lambda h: h.__setitem__("outputs", 5),  # a traceback: len() of an int
                                  lambda h: h.__setitem__("n_inputs", "8"),  # "8 readings; the header says 8"
                                  # a start of one number: TypeError (iteration over a 0-d array), a traceback
                                  lambda h: h["auto_zero"].__setitem__("start", -1),
                                  lambda h: h["auto_zero"].__setitem__("start", [10 ** 400] * 8)])
def test_replay_of_a_header_edited_by_hand_is_one_line(model_file, tmp_path, edit):
    run = tmp_path / "az.jsonl"
    assert read(model_file, "--tare", "--auto-zero", "--record", str(run)).returncode == 0
    lines = run.read_text().splitlines()
    header = json.loads(lines[0])
    edit(header)
    run.write_text("\n".join([json.dumps(header)] + lines[1:]) + "\n")
    proc = run_cli("tactile-host", "replay", str(run))
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1 and "Traceback" not in proc.stderr, \
        proc.stderr


def capture_t(tmp_path, schedule, temps, *extra, out="cap.csv"):
    (tmp_path / "s.csv").write_text(schedule)
    return run_cli("tactile-host", "capture", "--poses", str(tmp_path / "s.csv"), "--adc", WITH_TEMP, "--simulate",
                   "--temperature", temps, "-o", str(tmp_path / out), *extra)


def test_temperature_options_are_checked_before_the_capture(tmp_path):
    assert_one_line_error(capture_t(tmp_path, SCHEDULE, "15,25,35", "--t0", "20"), 2,
                          "--t0 20: give one of the temperatures captured (15, 25, 35)")
    assert_one_line_error(capture_t(tmp_path, SCHEDULE, "25,25.04"), 2, "at least 0.1 degC apart")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.csv"]


def test_a_resumed_level_keeps_its_own_temperature_and_a_pose_twice_is_one_pose(tmp_path):
    proc = capture_t(tmp_path, SCHEDULE, "15,25,35", "--t0", "35")
    assert proc.returncode == 0, proc.stderr
    first = json.loads((tmp_path / "cap.tempcomp.json").read_text())
    for stale in tmp_path.glob("cap.T35.csv*"):
        stale.unlink()
    proc = capture_t(tmp_path, SCHEDULE, "15,25,35", "--t0", "35")
    assert proc.returncode == 0, proc.stderr
    assert "6 poses at 25 degC (thermistor 25.00 degC)" in proc.stderr  # not the last level's 15
    again = json.loads((tmp_path / "cap.tempcomp.json").read_text())
    assert again["t0"] == first["t0"] == 35
    # the physics explains the rows as well as on the first run (a level labelled with another's temperature
    # left 14 mV rms unexplained)
    assert max(again["fit"]["residual_rms_v"]) < 2 * max(first["fit"]["residual_rms_v"]) < 1e-3
    # a row deleted to be taken again is taken at the file's end: matched by its pose, not its place (it had been
    # labelled the next pose's, and the compensation came out 25 % off with a residual of 300 mV)
    level = tmp_path / "cap.T25.csv"
    lines = level.read_text().splitlines(keepends=True)
    level.write_text("".join(lines[:2] + lines[3:]))
    proc = capture_t(tmp_path, SCHEDULE, "15,25,35", "--t0", "35")
    assert proc.returncode == 0 and "(1 captured now, 5 already there)" in proc.stderr, proc.stderr
    retaken = json.loads((tmp_path / "cap.tempcomp.json").read_text())
    assert max(retaken["fit"]["residual_rms_v"]) < 1e-3
    np.testing.assert_allclose(retaken["offset_v_per_degc"], again["offset_v_per_degc"], atol=1e-4)
    # a schedule that visits its one pose twice: offsets only, not a gain fitted from two equal rows
    proc = capture_t(tmp_path, "dx,dy,dz\n0,0,0.2\n0,0,0.2\n", "15,25", out="tw.csv")
    assert proc.returncode == 0, proc.stderr
    tw = json.loads((tmp_path / "tw.tempcomp.json").read_text())
    assert not tw["fit"]["gain_fitted"] and np.all(np.asarray(tw["gain_per_degc"]) == 0)
    assert np.max(np.abs(tw["offset_v_per_degc"])) < 0.01


def test_a_temperature_capture_resumes_only_as_it_was_taken(tmp_path):
    """A resumed `capture --temperature` added to each level's rows without the plain capture's checks: another
    unit's rows were mixed in (exit 0, a compensation that read dx 16.5), rows of another --samples, another map,
    or temperatures dropped. Each is refused in one line before any row, and the levels and compensation are kept."""
    from fitgen.physics.sensor import load_sensor
    from fitgen.physics.units import draw_unit, write_unit

    write_unit(tmp_path / "u3.unit.toml", draw_unit(load_sensor("paper").with_transfer("gmr"), 3)[0], "paper", {})
    proc = capture_t(tmp_path, SCHEDULE, "15,25", "--samples", "4")
    assert proc.returncode == 0, proc.stderr
    kept = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    swapped = WITH_TEMP.replace("0x48", "0x4X").replace("0x49", "0x48").replace("0x4X", "0x49")
    for extra, adc, said in ((["--sensor", str(tmp_path / "u3.unit.toml")], WITH_TEMP,
                              "its 6 rows were captured from simulated paper (sensor sha256 "),
                             ([], WITH_TEMP, "its 6 rows were captured with --samples 4, this run's is 16"),
                             ([], swapped, "its 6 rows were captured with --adc "),
                             ([], WITH_TEMP.rsplit(",", 1)[0], "its 6 rows were captured with a thermistor (temp= in "
                              "--adc), this run's --adc has none")):
        samples = [] if "16" in said else ["--samples", "4"]
        proc = run_cli("tactile-host", "capture", "--poses", str(tmp_path / "s.csv"), "--adc", adc, "--simulate",
                       "--temperature", "15,25", "-o", str(tmp_path / "cap.csv"), *samples, *extra)
        assert_one_line_error(proc, 2, said)
        assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == kept
    # the same run again takes no row, and says so of each level (it had said "6 poses at 15 degC" as if taken)
    proc = capture_t(tmp_path, SCHEDULE, "15,25", "--samples", "4")
    assert proc.returncode == 0, proc.stderr
    assert [ln.endswith("(0 captured now, 6 already there)") for ln in proc.stderr.splitlines()
            if " poses at " in ln] == [True, True], proc.stderr
    assert "now replaced" not in proc.stderr  # the same compensation again
    proc = capture_t(tmp_path, SCHEDULE, "25,15", "--samples", "4", "--sim-drift", "ramp=0,creep=0")
    assert proc.returncode == 0 and "now replaced" not in proc.stderr, proc.stderr  # the levels in another order
    assert "ramp was not simulated" not in proc.stderr  # a ramp of 0 is none
    assert f"next: --temp-comp {tmp_path / 'cap.tempcomp.json'} with read" in proc.stderr
    # -o named the levels' files, not one of its own: identify named only a missing file
    assert_one_line_error(run_cli("fitgen", "identify", str(tmp_path / "cap.csv"), "-o", str(tmp_path / "u.toml")),
                          2, f"{tmp_path / 'cap.csv'}: no such file; capture --temperature wrote one capture per "
                          "temperature under that name (cap.T15.csv, cap.T25.csv): give one of them")
    # other levels refit the compensation: the one it replaces is named (it went without a word)
    proc = capture_t(tmp_path, SCHEDULE, "15,25,35", "--samples", "4")
    assert proc.returncode == 0 and (f"note: {tmp_path / 'cap.tempcomp.json'} held a compensation about 15 degC, "
                                     "levels 15, 25, now replaced") in proc.stderr, proc.stderr


@pytest.mark.parametrize("option, said", [(["--precision", "float"], "--precision goes with --engine c"),
                                          (["--rest", "paper"], "--rest goes with --tare or --auto-zero"),
                                          (["--rest-hold", "5"], "--rest-hold goes with --auto-zero"),
                                          (["--auto-zero", "--tare-samples", "1"], "--tare-samples 5 or more"),
                                          # typed as their defaults, they are still typed, and would do nothing
                                          (["--cc", "gcc"], "--cc goes with --engine c"),
                                          (["--precision", "double"], "--precision goes with --engine c"),
                                          (["--tare-samples", "50"], "--tare-samples goes with --tare or --auto-zero"),
                                          (["--rest-band", "0.08,1.5"], "--rest-band goes with --auto-zero")])
def test_an_option_without_the_one_it_needs_is_refused(model_file, option, said):
    assert_one_line_error(read(model_file, *option), 2, said)


@pytest.mark.parametrize("option", [["--count"], ["--retries"], ["--tare", "--tare-samples"]])
def test_a_count_past_floats_range_is_one_line(model_file, option):
    """--count 10**400: math.isfinite of the integer raised OverflowError, a traceback."""
    bound = "at most 100" if option == ["--retries"] else "a whole number below 2^63"  # --retries has its own
    assert_one_line_error(read(model_file, *option, "1" + "0" * 400), 2,
                          f"{option[-1]} must be {bound}, got 10000000000000000000... (401 digits)")


@pytest.mark.parametrize("option", [[], ["--tare"]])
def test_a_simulated_pose_through_the_board_is_named_as_given(model_file, option):
    """One pose from --simulate was called "pose 1", as if from a list; it is named as the option gave it, before
    a tare rests on the sensor."""
    proc = run_cli("tactile-host", "read", "--model", model_file, "--adc", TWO_CHIPS, "--simulate", "dx=1,dz=-100",
                   "--count", "1", *option)
    assert_one_line_error(proc, 2, "--simulate dx=1,dz=-100 (dx=1 dy=0 dz=-100")
    assert "pose 1" not in proc.stderr and "tare" not in proc.stderr


def test_view_hold_without_replay_is_refused(model_file):
    assert_one_line_error(run_cli("tactile-host", "view", "--model", model_file, "--adc", TWO_CHIPS, "--simulate",
                                  "dx=1", "--count", "1", "--port", "0", "--hold"), 2, "--hold goes with --replay")


def test_a_slow_rate_takes_no_sample_after_the_duration(model_file, tmp_path):
    proc = run_cli("tactile-host", "read", "--model", model_file, "--adc", TWO_CHIPS, "--simulate", "dx=1",
                   "--rate", "0.1", "--duration", "1", "-o", str(tmp_path / "s.csv"))
    assert proc.returncode == 0, proc.stderr
    assert len((tmp_path / "s.csv").read_text().splitlines()) == 2  # the header and the sample at t = 0 only


def test_a_rate_slower_than_a_sample_an_hour_is_refused(model_file, tmp_path):
    """1e-9 Hz would read one sample and then wait 30 years for the next."""
    out = tmp_path / "s.csv"
    assert_one_line_error(run_cli("tactile-host", "read", "--model", model_file, "--adc", TWO_CHIPS, "--simulate",
                                  "dx=1", "--rate", "1e-9", "--count", "2", "-o", str(out)), 2,
                          "--rate must be at least 1/3600 (a sample an hour), got 1e-9")
    assert not out.exists()


def test_a_run_of_the_c_engine_in_float_replays_exactly(model_file, tmp_path):
    run = tmp_path / "cf.jsonl"
    proc = run_cli("tactile-host", "read", "--model", model_file, "--adc", TWO_CHIPS, "--simulate", "motion",
                   "--engine", "c", "--precision", "float", "--count", "30", "--record", str(run), "-o",
                   str(tmp_path / "s.csv"))
    assert proc.returncode == 0, proc.stderr
    header = json.loads(run.read_text().splitlines()[0])
    assert header["engine"] == "c" and header["precision"] == "float"
    proc = run_cli("tactile-host", "replay", str(run))
    assert proc.returncode == 0 and "estimates identical to the recorded ones" in proc.stdout, proc.stdout


def test_a_replay_says_it_left_out_a_last_line_cut_short(model_file, tmp_path):
    """A run stopped mid-write leaves its last line unfinished: replay leaves it out and says so; a line cut
    short before the last is refused."""
    run = tmp_path / "r.jsonl"
    assert read(model_file, "--record", str(run)).returncode == 0
    lines = run.read_text().splitlines()
    run.write_text("\n".join(lines) + "\n" + lines[-1][:25])
    proc = run_cli("tactile-host", "replay", str(run))
    assert proc.returncode == 0, proc.stderr
    assert "replayed 2 samples" in proc.stdout
    assert f"note: its last line (line {len(lines) + 1}) was cut short, as a stopped run leaves one: left out" in \
        proc.stdout
    whole = tmp_path / "whole.jsonl"
    whole.write_text("\n".join(lines) + "\n")
    proc = run_cli("tactile-host", "replay", str(whole))
    assert proc.returncode == 0 and "replayed 2 samples" in proc.stdout and "cut short" not in proc.stdout
    proc = run_cli("tactile-host", "view", "--replay", str(run), "--port", "0")  # the page's replay says it too
    assert proc.returncode == 0 and "tactile-host view: note: its last line" in proc.stderr, proc.stderr
    run.write_text("\n".join(lines[:-1] + [lines[-1][:25], lines[-1]]) + "\n")
    assert_one_line_error(run_cli("tactile-host", "replay", str(run)), 2, f"line {len(lines)} is not a sample")
    # a last line damaged but whole (its newline written after it) is damage, not a stop's: refused as any other
    run.write_text("\n".join(lines[:-1] + [lines[-1].replace('"status": 0', '"status": "x"')]) + "\n")
    assert '"status": "x"' in run.read_text()
    assert_one_line_error(run_cli("tactile-host", "replay", str(run)), 2, f"line {len(lines)} is not a sample")
    # and a time past a float's range (JSON's integers have none): an OverflowError, a traceback
    big = json.loads(lines[-1])
    big["t"] = 10 ** 400
    run.write_text("\n".join(lines[:-1] + [json.dumps(big)]) + "\n")
    assert_one_line_error(run_cli("tactile-host", "replay", str(run)), 2, f"line {len(lines)} is not a sample")
    # numbers read never records: they had replayed silently, status 0
    for key, value in (("t", float("nan")), ("raw", [1e308] * len(big["raw"])), ("temp", float("inf"))):
        bad = {**json.loads(lines[-1]), key: value}
        run.write_text("\n".join(lines[:-1] + [json.dumps(bad)]) + "\n")
        assert_one_line_error(run_cli("tactile-host", "replay", str(run)), 2,
                              f"line {len(lines)} is not a sample read records (its time must be finite")


def test_a_replay_plays_over_a_clock_step_and_view_refuses_readout_options(model_file, tmp_path):
    from host.replay import play_times

    t = np.array([0.0, 0.1, 0.2, 3600.3, 3600.4, 3600.3, 3600.5])  # an NTP step forward, then one back
    np.testing.assert_allclose(play_times(t), [0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.7], atol=1e-9)
    run = tmp_path / "r.jsonl"
    assert read(model_file, "--record", str(run)).returncode == 0
    for option in (["--count", "5"], ["--duration", "2"], ["--record", str(tmp_path / "x.jsonl")],
                   ["--engine", "python"], ["--cc", "gcc"], ["--rest-hold", "1"]):
        assert_one_line_error(run_cli("tactile-host", "view", "--replay", str(run), "--port", "0", *option), 2,
                              "does not apply to --replay")
    assert not (tmp_path / "x.jsonl").exists()


def test_view_replay_refuses_every_bus_and_simulation_option(model_file, tmp_path):
    """An option a replay would ignore is refused, even typed as its default; those it takes still play."""
    run = tmp_path / "r.jsonl"
    assert read(model_file, "--record", str(run)).returncode == 0
    for option in (["--sim-drift", "ramp=5"], ["--sim-noise", "0.01"], ["--sim-fault", "nack:0.5"],
                   ["--sim-offsets", "0,0,0,0,0,0,0,0"], ["--thermistor", "beta=3950"], ["--bus", "3"],
                   ["--vref", "internal"], ["--mode", "single"], ["--pga", "4.096"], ["--data-rate", "860"],
                   ["--seed", "0"], ["--sensor", "paper"], ["--retries", "5"]):
        assert_one_line_error(run_cli("tactile-host", "view", "--replay", str(run), "--port", "0", *option), 2,
                              f"{option[0]} does not apply to --replay")
    proc = run_cli("tactile-host", "view", "--replay", str(run), "--model", model_file, "--host", "127.0.0.1",
                   "--port", "0")
    assert proc.returncode == 0 and "replay of" in proc.stderr, proc.stderr
    assert re.search(r"tactile-host view: done: played (\d+) of \1 samples$", proc.stderr.strip()), proc.stderr


def test_view_help_says_what_port_0_does_and_gives_the_docs_drift_example():
    text = " ".join(run_cli("tactile-host", "view", "--help").stdout.split())  # argparse wraps at any width
    assert "TCP port (default 8765; 0 picks a free one)" in text
    example = re.search(r"a faster one: ([\w=.,]+)\)", text).group(1)
    assert f"`--sim-drift {example}`" in (Path(__file__).resolve().parent.parent / "docs" / "live.md").read_text()


def test_view_names_the_option_it_misses_and_a_port_in_host_points_at_port(model_file):
    for given, said in ((["--model", model_file], "view needs --adc (or --replay RUN.jsonl)"),
                        (["--adc", TWO_CHIPS], "view needs --model (or --replay RUN.jsonl)"),
                        ([], "view needs --model and --adc (or --replay RUN.jsonl)")):
        assert_one_line_error(run_cli("tactile-host", "view", "--port", "0", *given), 2, said)
    for host, said in (("127.0.0.1:8765", "the port goes in --port (--host 127.0.0.1 --port 8765)"),
                       ("[::1]:8765", "the port goes in --port (--host ::1 --port 8765)"),
                       # said as an address it could not resolve, where the same without brackets serves
                       ("[::1]", "--host [::1]: give the address without brackets (--host ::1)"),
                       # a byte no terminal decoded: the socket's "encoding of hostname failed", a traceback
                       ("\udcff", "--host '?': not a host name or address")):
        assert_one_line_error(run_cli("tactile-host", "view", "--model", model_file, "--adc", TWO_CHIPS, "--simulate",
                                      "dx=1", "--count", "1", "--host", host), 2, said)


def test_temperature_options_without_temperature_are_refused(tmp_path):
    (tmp_path / "s.csv").write_text(SCHEDULE)
    for option in (["--t0", "20"], ["--temp-comp-output", str(tmp_path / "tc.json")]):
        proc = run_cli("tactile-host", "capture", "--poses", str(tmp_path / "s.csv"), "--adc", TWO_CHIPS,
                       "--simulate", "-o", str(tmp_path / "c.csv"), *option)
        assert_one_line_error(proc, 2, "goes with --temperature")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.csv"]


@pytest.mark.parametrize("module", ["fitgen.app.cli", "fitgen.app.host_cli", "fitgen.app.hil_cli"])
def test_every_option_and_argument_says_what_it_is_in_help(module):
    """`-h` of every command says what each of its arguments is: stage-sim's --flavor and --seed, verify's --style,
    predict's MODEL and others were listed bare."""
    import argparse
    from importlib import import_module

    bare = []
    for group in (a for a in import_module(module).build_parser()._actions
                  if isinstance(a, argparse._SubParsersAction)):
        for name, parser in group.choices.items():
            bare += [f"{name} {'/'.join(a.option_strings) or a.metavar or a.dest}" for a in parser._actions
                     if not isinstance(a, argparse._HelpAction) and not (a.help or "").strip()]
    assert bare == []


def test_a_simulated_read_says_when_the_model_s_own_sensor_is_not_here(model_file, tmp_path):
    """A twin whose unit file was moved away: read --simulate simulated the paper drawing in its place, without a
    word, and its estimates were degrees off; a note says so. The drawing's own model simulates it unsaid."""
    data = json.loads(Path(model_file).read_text())
    assert "note:" not in read(model_file).stderr
    gone = str(tmp_path / "gone" / "unit.toml")
    data.setdefault("fit", {}).setdefault("held_out", {}).update({"sensor": "unit", "sensor_file": gone})
    (tmp_path / "twin.json").write_text(json.dumps(data))
    proc = read(str(tmp_path / "twin.json"))
    assert proc.returncode == 0, proc.stderr
    assert (f"tactile-host read: note: the model was fitted on {gone}, not found here as it was: simulating paper; "
            "give --sensor") in proc.stderr
    assert "note:" not in read(str(tmp_path / "twin.json"), "--sensor", "paper").stderr  # said: no note


def test_a_replay_with_a_model_of_fewer_outputs_compares_the_ones_both_have(model, model_file, tmp_path):
    """A run recorded with dx..thy replayed with a model of dx, dy, dz: it said "other outputs: no differences
    computed" though three are shared; the shared ones are compared by name."""
    import dataclasses

    run = tmp_path / "r.jsonl"
    assert read(model_file, "--record", str(run)).returncode == 0
    three = dataclasses.replace(model, equations=model.equations[:3]).save(tmp_path / "three.json")
    proc = run_cli("tactile-host", "replay", str(run), "--model", str(three))
    assert proc.returncode == 0, proc.stderr
    assert f"the recorded run has outputs {', '.join(model.output_names)}: differences in dx, dy, dz" in proc.stdout
    rows = [ln for ln in proc.stdout.splitlines() if ln.startswith("| d")]
    assert [ln.split(" | ")[0] for ln in rows] == ["| dx", "| dy", "| dz"]
    assert all(float(ln.split(" | ")[1]) == 0.0 for ln in rows), rows  # the same equations: no difference


def test_a_replay_report_matches_outputs_by_name_when_as_many_differ():
    """A model of as many outputs as the run's, other ones: the report took the recorded columns by the model's
    names and failed on a name the run lacks; it compares the shared ones by name."""
    from host.replay import ReplayResult

    z = np.zeros((3, 3))
    res = ReplayResult(np.arange(3.0), z, z[:, 0], z, np.ones((3, 3)), np.zeros(3, int), np.zeros((3, 3)),
                       ("dx", "dz", "thx"), "0" * 64, False, [], [], {}, ("dx", "dy", "dz"))
    text = res.report()
    assert "the recorded run has outputs dx, dy, dz: differences in dx, dz" in text
    assert [ln.split(" | ")[0] for ln in text.splitlines() if ln.startswith("| d")] == ["| dx", "| dz"]


def test_a_compensation_from_captures_each_at_one_temperature_is_the_one_capture_temperature_fits(tmp_path):
    """`capture --stage` cannot take --temperature, and nothing fitted a compensation from captures taken one
    temperature at a time: a stage's user had none. tempcomp-fit fits it from them (each capture's thermistor), as
    capture --temperature fits it from its levels; captures that do not go together are refused in one line."""
    from host.temperature import load_tempcomp

    assert capture_t(tmp_path, SCHEDULE, "15,25,35", "--samples", "16", "--seed", "3").returncode == 0
    for T in (15, 25, 35):
        proc = run_cli("tactile-host", "capture", "--poses", str(tmp_path / "s.csv"), "--adc", WITH_TEMP, "--simulate",
                       "--samples", "16", "--sim-drift", f"ramp=0,creep=0,start={T},seed=3", "-o",
                       str(tmp_path / f"one{T}.csv"))
        assert proc.returncode == 0, proc.stderr
    caps = [str(tmp_path / f"one{T}.csv") for T in (15, 25, 35)]
    swapped = WITH_TEMP.replace("0x48", "0x4X").replace("0x49", "0x48").replace("0x4X", "0x49")
    proc = run_cli("tactile-host", "capture", "--poses", str(tmp_path / "s.csv"), "--adc", swapped, "--simulate",
                   "--samples", "4", "--sim-drift", "ramp=0,creep=0,start=35", "-o", str(tmp_path / "sw.csv"))
    assert proc.returncode == 0, proc.stderr
    proc = run_cli("tactile-host", "tempcomp-fit", *caps, "-o", str(tmp_path / "fit.json"))
    assert proc.returncode == 0 and "temperature compensation about 25 degC from 3 captures read at 15 to 35" in \
        proc.stderr, proc.stderr
    ours, levels = load_tempcomp(tmp_path / "fit.json"), load_tempcomp(tmp_path / "cap.tempcomp.json")
    assert ours.t0 == levels.t0 == 25 and ours.info["adc"] == levels.info["adc"]
    # the same drift, other noise: offsets of up to 2.6 mV/degC agree to the noise's 0.1 mV/degC, rest readings to
    # a fraction of a mV
    np.testing.assert_allclose(ours.offset, levels.offset, atol=1e-4)
    np.testing.assert_allclose(ours.gain, levels.gain, atol=1e-4)
    np.testing.assert_allclose(ours.rest_v, levels.rest_v, atol=5e-4)
    assert np.max(np.abs(levels.offset)) > 1e-3  # a drift to find, not zeros agreeing
    # each row at its own temperature: a capture whose rows warmed from 15.2 to 19 degC is fitted as read (taken
    # at its start, 15, the gains had come out 31 % off)
    proc = run_cli("tactile-host", "capture", "--poses", str(tmp_path / "s.csv"), "--adc", WITH_TEMP, "--simulate",
                   "--samples", "16", "--sim-drift", "ramp=4,over=2,creep=0,start=15,seed=3", "-o",
                   str(tmp_path / "warm.csv"))
    assert proc.returncode == 0, proc.stderr
    proc = run_cli("tactile-host", "tempcomp-fit", str(tmp_path / "warm.csv"), *caps[1:], "-o", str(tmp_path / "w.json"))
    assert proc.returncode == 0 and "read at 15.2 to 35 degC" in proc.stderr, proc.stderr
    np.testing.assert_allclose(load_tempcomp(tmp_path / "w.json").gain, levels.gain, atol=1e-4)
    # a capture stopped early (1 of 6 poses), or of another schedule, shares too few poses: refused (a pose at one
    # temperature tells nothing of its drift; the offsets had come out 5.6 mV/degC off)
    proc = run_cli("tactile-host", "capture", "--poses", str(tmp_path / "s.csv"), "--adc", WITH_TEMP, "--simulate",
                   "--samples", "4", "--sim-drift", "ramp=0,creep=0,start=35,seed=3", "-o", str(tmp_path / "short.csv"),
                   "--trigger", '[ "$TM_POSE_INDEX" -lt 2 ]')
    assert proc.returncode == 1, proc.stderr
    for argv, said in (([caps[0]], "give two or more captures"),
                       ([caps[0], str(tmp_path / "short.csv")], "short.csv holds other poses than"),
                       ([*caps, caps[1]], f"{caps[1]} holds the same rows as {caps[1]}: give each capture once"),
                       ([caps[0], str(tmp_path / "cap.T15.csv")], "the captures were all read at 15.0 degC"),
                       ([*caps, str(tmp_path / "cap.tempcomp.json")], "cap.tempcomp.json"),
                       ([caps[0], str(tmp_path / "sw.csv")], "was captured through another channel map (--adc)")):
        assert_one_line_error(run_cli("tactile-host", "tempcomp-fit", *argv, "-o", str(tmp_path / "x.json")), 2, said)
    assert not (tmp_path / "x.json").exists()
    assert_one_line_error(run_cli("tactile-host", "tempcomp-fit", *caps, "-o", caps[0]), 2, f"-o {caps[0]} is the input")
    # a capture whose meta records no channel map, or that has no meta: its map was compared only when it came
    # second (first, it was the reference, and any map passed), and no meta was called "another channel map"
    meta = json.loads(Path(caps[0] + ".meta.json").read_text())
    (tmp_path / "bare.csv").write_text(Path(caps[0]).read_text())
    (tmp_path / "bare.csv.meta.json").write_text(json.dumps({k: v for k, v in meta.items() if k != "adc"}))
    (tmp_path / "none.csv").write_text(Path(caps[0]).read_text())
    for first, said in (("bare.csv", f"bare.csv's meta records no channel map (--adc), which {caps[1]}'s does"),
                        ("none.csv", "none.csv has no meta (none.csv.meta.json), which says at what temperature")):
        assert_one_line_error(run_cli("tactile-host", "tempcomp-fit", str(tmp_path / first), *caps[1:], "-o",
                                      str(tmp_path / "x.json")), 2, said)
    assert not (tmp_path / "x.json").exists()


def test_a_compensation_fitted_across_too_little_temperature_says_so_and_damaged_temperatures_are_refused(tmp_path):
    """Levels 0.1 degC apart gave offsets 5.6 mV/degC where the drift is 0.4, with exit 0 and no word: the fit now
    carries its coefficients' standard errors to where the readouts use it without a note, and notes an error past
    twice the rows' residual (not for 15, 25, 35). tempcomp-fit took a capture whose row_degc or thermistor_degc
    was damaged at another temperature in silence, and its --t0 refusal spoke of "the capture"."""
    import json

    from host.temperature import load_tempcomp

    for temps, noted in (("15,25,35", False), ("25,25.1", True)):
        out = f"c{temps.count(',')}{noted}.csv"
        proc = capture_t(tmp_path, SCHEDULE, temps, "--samples", "4", "--seed", "3", out=out)
        assert proc.returncode == 0, proc.stderr
        assert ("temperatures span 0.1 degC, too little for the rows' noise" in proc.stderr) == noted, proc.stderr
        tc = load_tempcomp(tmp_path / out.replace(".csv", ".tempcomp.json"))
        assert len(tc.info["drift_se_v_per_degc"]) == tc.n
    caps = [str(tmp_path / f"c2False.T{T}.csv") for T in (15, 25, 35)]
    proc = run_cli("tactile-host", "tempcomp-fit", str(tmp_path / "c1True.T25.csv"), str(tmp_path / "c1True.T25.1.csv"),
                   "-o", str(tmp_path / "near.json"))
    assert proc.returncode == 0 and "note: the compensation's temperatures span 0.1 degC" in proc.stderr, proc.stderr
    proc = run_cli("tactile-host", "tempcomp-fit", *caps, "-o", str(tmp_path / "far.json"))
    assert proc.returncode == 0 and "too little" not in proc.stderr, proc.stderr
    assert_one_line_error(run_cli("tactile-host", "tempcomp-fit", *caps, "--t0", "20", "-o", str(tmp_path / "x.json")),
                          2, "t0 20 degC is not a temperature of the captures (15, 25, 35)")
    meta = tmp_path / "c2False.T15.csv.meta.json"
    good = json.loads(meta.read_text())
    for key, bad in (("row_degc", [15.0] * 5), ("thermistor_degc", "warm")):  # 6 rows
        meta.write_text(json.dumps({**{k: v for k, v in good.items() if k != "row_degc"}, key: bad}))
        assert_one_line_error(run_cli("tactile-host", "tempcomp-fit", *caps, "-o", str(tmp_path / "x.json")), 2,
                              f"c2False.T15.csv's meta has a {key} that is not")
    assert not (tmp_path / "x.json").exists()


def test_a_rest_captures_damaged_row_temperatures_are_read_as_none_recorded(tmp_path):
    """rest_degc took len() of row_degc, which a damaged meta holds as a number: a traceback in read --tare."""
    from host.rest import rest_degc

    cap = tmp_path / "c.csv"
    cap.write_text("v1,dx\n1,0\n")
    for row_degc, said in ((5, 30.0), ([31.0], 31.0)):
        (tmp_path / "c.csv.meta.json").write_text(json.dumps({"row_degc": row_degc, "thermistor_degc": 30.0}))
        assert rest_degc(str(cap)) == said


def test_a_tare_on_a_model_fitted_where_the_sensor_never_rests_says_so(tmp_path):
    """A scene pressed 0.5-1.5 mm throughout: its model cannot read rest, and the tare's refusal had called the
    model's own sensor 'another sensor's' and advised a --rest that failed the same way."""
    (tmp_path / "tilt.toml").write_text('name = "tilt"\noutputs = ["dx", "thx", "thy"]\n[ranges]\ndx = [-1.5, 1.5]\n'
                                        'dy = [0, 0]\ndz = [-1.5, -0.5]\nthx = [-5, 5]\nthy = [-5, 5]\n')
    for argv in (["simulate", "--scene", str(tmp_path / "tilt.toml"), "--transfer", "gmr", "-o", "t.csv"],
                 ["fit", "t.csv", "-o", "t.json", "--family", "no-roots", "--force", "--max-terms", "4",
                  "--held-out", "50"]):
        proc = run_cli("fitgen", *argv, cwd=tmp_path)
        assert proc.returncode == 0, proc.stderr
    for rest in ([], ["--rest", "paper"]):
        assert_one_line_error(run_cli("tactile-host", "read", "--model", "t.json", "--adc", TWO_CHIPS, "--simulate",
                                      "dx=0.5,dz=-1", "--tare", "--count", "1", *rest, cwd=tmp_path),
                              2, "the model was fitted on poses that never rest (dz -1.5..-0.5)")
    # random poses in the default box: dz's drawn top stops short of 0 (-0.0006 mm), and that is rest enough
    for argv in (["simulate", "--transfer", "gmr", "--random", "400", "-o", "r.csv"],
                 ["fit", "r.csv", "-o", "r.json", "--family", "no-roots", "--max-terms", "6", "--held-out", "50"]):
        assert run_cli("fitgen", *argv, cwd=tmp_path).returncode == 0
    proc = run_cli("tactile-host", "read", "--model", "r.json", "--adc", TWO_CHIPS, "--simulate", "dx=0.5,dz=-1",
                   "--tare", "--count", "1", cwd=tmp_path)
    assert proc.returncode == 0 and "tare: offsets" in proc.stderr, proc.stderr
