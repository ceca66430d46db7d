"""The live readout: engines, output lines, pacing, tare, retries, a silent chip, Ctrl-C."""

import io
import json
import re
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from fitgen.base.errors import InputError
from fitgen.physics.simulate import grid_poses, simulate
from fitgen.physics.transfer import readings
from host.adc import AdcArray, DeviceSilent
from host.channelmap import parse_spec
from host.clock import VirtualClock
from host.engine import CEngine, PythonEngine
from host.readout import LineFormat, Readout, RunRecord
from host.replay import load_run, replay
from host.rest import check_rest_reference, rest_reference, tare
from host.simbus import SimBus

from conftest import CLEARED, Terminal, assert_one_line_error, require_tool, run_cli

TWO_1115 = "ads1115@0x48:0-3,ads1115@0x49:0-3"
POSE = np.array([1.0, 0.5, -1.0, 0.0, 0.0])


@pytest.fixture(scope="module")
def c_engine(model):
    require_tool("gcc")
    eng = CEngine(model)
    yield eng
    eng.close()


def rig(sensor, pose=POSE, spec=TWO_1115, **kw):
    cmap = parse_spec(spec)
    clock = VirtualClock()
    bus = SimBus.for_channel_map(cmap, sensor, pose, clock=clock, **kw)
    return bus, AdcArray(bus, cmap, clock=clock), clock


def parse_csv(text):
    lines = text.splitlines()
    header = lines[0].split(",")
    return header, np.array([[float(x) for x in ln.split(",")] for ln in lines[1:]])


# --- engines -----------------------------------------------------------------------


def test_c_engine_gives_the_python_numbers(model, c_engine):
    rng = np.random.default_rng(2)
    lo, hi = model.input_min, model.input_max
    inputs = np.vstack([lo + (hi - lo) * rng.random((300, 8)),  # inside the domain
                        lo + (hi - lo) * rng.uniform(-0.5, 1.5, (100, 8))])  # partly outside: clamped
    py = PythonEngine(model)
    statuses = set()
    for row in inputs:
        (a, sa), (b, sb) = c_engine.estimate(row), py.estimate(row)
        assert sa == sb
        statuses.add(sa)
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12)
    assert 0 in statuses and len(statuses) > 10  # in-domain rows and many clamping masks were exercised
    bad = inputs[0].copy()
    bad[3] = np.nan
    out, status = c_engine.estimate(bad)
    assert status == -1 and not out.any()


def test_float_c_engine_is_close(sensor, model):
    require_tool("gcc")
    eng = CEngine(model, precision="float")
    try:
        row = readings(sensor, POSE, adc_bits=0)[0]
        a, _ = eng.estimate(row)
        b, _ = PythonEngine(model).estimate(row)
        assert not np.array_equal(a, b)
        np.testing.assert_allclose(a[:3], b[:3], atol=1e-3)  # mm
        np.testing.assert_allclose(a[3:], b[3:], atol=0.3)  # deg: the rotations' many terms cancel in float
    finally:
        eng.close()


# --- lines -------------------------------------------------------------------------


def test_csv_and_jsonl_lines():
    csv = LineFormat("csv", 3, ("dx", "dz"))
    assert csv.header == "t,v1,v2,v3,dx,dz,status\n"
    assert csv.line(12.5, [1.0, 2.0, 3.0], [0.1, -0.2], 4) == "12.500000,1.000000,2.000000,3.000000,0.1000,-0.2000,4\n"
    js = LineFormat("jsonl", 2, ("dx",))
    rec = json.loads(js.line(1.25, [1.5, 2.5], [0.125], 0))
    assert rec == {"t": 1.25, "v": [1.5, 2.5], "dx": 0.125, "status": 0}
    with pytest.raises(InputError):
        LineFormat("xml", 2, ("dx",))


# --- the loop ----------------------------------------------------------------------


def test_readout_streams_timestamped_estimates_at_a_rate(sensor, model, c_engine):
    bus, arr, clock = rig(sensor)
    sink = io.StringIO()
    fmt = LineFormat("csv", 8, model.output_names)
    sink.write(fmt.header)
    stats = Readout(arr, c_engine, sink, fmt, clock=clock).run(rate=50, count=40)
    header, table = parse_csv(sink.getvalue())
    assert header == ["t"] + [f"v{k}" for k in range(1, 9)] + list(model.output_names) + ["status"]
    assert len(table) == 40 and stats.samples == 40
    np.testing.assert_allclose(np.diff(table[:, 0]), 0.02, atol=1e-5)  # paced on the clock
    assert stats.rate == pytest.approx(50, rel=0.02) and stats.late == 0
    np.testing.assert_allclose(table[:, 1:9], readings(sensor, POSE, adc_bits=0).repeat(40, 0), atol=1e-4)
    assert np.all(np.abs(table[:, 9:12] - POSE[:3]) < 0.15)
    assert np.all(table[:, -1] == 0)


def test_estimates_far_outside_the_fitted_pose_box_are_counted_as_predict_counts_them(sensor, model):
    """A sample estimated outside the model's fitted pose box by more than its width (the drawing's model on a built
    unit reads so) is counted and said in the summary, as `fitgen predict` says it of a dataset's rows."""
    import dataclasses

    def boxed(dx):
        return dataclasses.replace(model, fit_info={**model.fit_info, "held_out": {"box": {"dx": dx, "dz": [-2, 0]}}})

    for dx, far in (([-2, 2], False), ([0, 0.2], True)):  # POSE's dx 1 lies 0.8 past a box 0.2 wide
        bus, arr, clock = rig(sensor)
        m = boxed(dx)
        sink, seen, warned = io.StringIO(), [], []
        stats = Readout(arr, PythonEngine(m), sink, LineFormat("csv", 8, m.output_names), clock=clock,
                        observer=seen.append, warn=warned.append).run(count=10)
        # said at the first such sample, once: a live run may last hours before its summary
        assert warned == (["sample 1 estimated outside the pose box the model was fitted in by more than its width: "
                           "another sensor than the model's? a built unit needs its own calibration "
                           "(docs/calibration.md); the summary counts every such sample"] if far else [])
        _, table = parse_csv(LineFormat("csv", 8, m.output_names).header + sink.getvalue())
        assert stats.far == (10 if far else 0) == int(m.far_outside(table[:, 9:14]).sum())
        assert [s["far"] for s in seen] == [far] * 10  # what the live page warns of
        assert ("estimated outside the pose box the model was fitted in" in stats.summary()) == far


def test_a_far_estimate_from_a_read_held_up_is_not_blamed_on_another_sensor(sensor, model, tmp_path):
    """A read the machine held up between its conversions (a loaded machine: 0.1-0.2 s stalls) gives a moving
    sensor's channels at two poses, which a model can read as a pose 100 mm away: counted and said as a read held
    up, where it had said "another sensor than the model's?"; a held-up read estimated inside the box, nothing."""
    import dataclasses

    for dx, far in (([0, 0.2], True), ([-2, 2], False)):  # POSE's dx 1 lies 0.8 past a box 0.2 wide
        bus, arr, clock = rig(sensor)
        m = dataclasses.replace(model, fit_info={**model.fit_info, "held_out": {"box": {"dx": dx, "dz": [-2, 0]}}})
        read, calls = arr.read_volts, []

        def held_up():  # the 3rd and 7th reads: held up 0.2 s after their first conversions
            calls.append(1)
            if len(calls) in (3, 7):
                clock.sleep(0.2)
            return read()

        arr.read_volts = held_up
        seen, warned, run = [], [], io.StringIO()
        record = RunRecord(run, {"model": m.sha256, "outputs": list(m.output_names), "n_inputs": 8,
                                 "model_file": m.to_dict()})
        stats = Readout(arr, PythonEngine(m), io.StringIO(), LineFormat("csv", 8, m.output_names), clock=clock,
                        observer=seen.append, warn=warned.append, record=record).run(count=10)
        assert (stats.far, stats.far_held) == ((8, 2) if far else (0, 0))
        # replayed, the record's read times tell the same reads apart (a record had no timings: all 10 "another
        # sensor's"); a record without them, as older runs, counts every far one so
        (tmp_path / "run.jsonl").write_text(run.getvalue())
        res = replay(load_run(tmp_path / "run.jsonl"))
        assert res.held.tolist() == [k in (2, 6) for k in range(10)] and [res.sample(k)["held"] for k in (1, 2)] == \
            [False, True]
        said = res.report()
        assert ("warning: 8 of 10 samples estimated outside" in said and "warning: 2 of 10 samples estimated outside "
                "the pose box the model was fitted in by more than its width, from a read held up" in said) == far, said
        lines = [json.loads(ln) for ln in run.getvalue().splitlines()]
        (tmp_path / "old.jsonl").write_text("".join(json.dumps({k: v for k, v in ln.items() if k != "read_s"}) + "\n"
                                                    for ln in lines))
        assert ("warning: 10 of 10 samples estimated outside" in replay(load_run(tmp_path / "old.jsonl")).report()) \
            == far
        assert [s["held"] for s in seen] == [k in (2, 6) for k in range(10)] and [s["far"] for s in seen] == [far] * 10
        assert len(warned) == (2 if far else 0), warned
        if far:
            assert warned[1].startswith("sample 3 estimated outside the pose box the model was fitted in by more than "
                                        "its width, from a read held up between its conversions") and " ms where a " \
                "read takes " in warned[1] and "another sensor" not in warned[1]
            assert "; 2 estimated outside the pose box the model was fitted in by more than its width, from a read " \
                "held up" in stats.summary() and "; 8 estimated outside" in stats.summary()


def test_the_rate_achieved_is_the_samples_pace_not_samples_over_the_run(sensor, model):
    """n samples paced at R Hz span n - 1 periods: the rate the summary reports is R, however few the samples
    (2 samples at 1 Hz read 2.0 Hz when counted over the run); one sample has no rate to report."""
    for rate, count in ((1.0, 2), (2.0, 5), (10.0, 10)):
        bus, arr, clock = rig(sensor)
        reader = Readout(arr, PythonEngine(model), io.StringIO(), LineFormat("csv", 8, model.output_names),
                         clock=clock)
        stats = reader.run(rate=rate, count=count)
        assert stats.rate == pytest.approx(rate, rel=1e-6) and f"({rate:.1f} Hz)" in stats.summary()
    stats = reader.run(count=1)
    assert stats.rate == 0 and "Hz" not in stats.summary()


def test_a_rate_above_what_the_converters_allow_counts_late_samples(sensor, model):
    bus, arr, clock = rig(sensor)
    reader = Readout(arr, PythonEngine(model), io.StringIO(), LineFormat("csv", 8, model.output_names), clock=clock)
    stats = reader.run(rate=1000, count=30)  # 8 elements on 2 chips at 860 SPS: about 135 Hz
    assert stats.late > 20
    assert 100 < stats.rate < 150


def test_duration_and_stop_end_the_run(sensor, model):
    bus, arr, clock = rig(sensor)
    reader = Readout(arr, PythonEngine(model), io.StringIO(), LineFormat("jsonl", 8, model.output_names),
                     clock=clock)
    stats = reader.run(duration=0.5)
    assert 0.5 <= stats.elapsed < 0.52 and stats.samples > 50
    calls = []
    stats = reader.run(stop=lambda: calls.append(1) or len(calls) > 5)
    assert stats.samples == 5 and len(calls) == 6


def test_tare_corrects_element_offsets(sensor, model, c_engine):
    offsets = np.array([0.02, -0.015, 0.01, 0.0, -0.02, 0.012, 0.0, -0.008])  # amplifier offsets, V
    bus, arr, clock = rig(sensor, pose=np.zeros(5), offsets=offsets, noise=0.0005)
    reference = rest_reference("paper", 8)
    t = tare(arr, reference, 40)
    np.testing.assert_allclose(t.offsets, offsets, atol=3e-4)
    bus.set_pose(POSE)
    fmt = LineFormat("csv", 8, model.output_names)
    results = {}
    for name, off in (("raw", None), ("tared", t.offsets)):
        sink = io.StringIO()
        Readout(arr, c_engine, sink, fmt, clock=clock, offsets=off).run(count=20)
        results[name] = np.abs(parse_csv(fmt.header + sink.getvalue())[1][:, 9:12].mean(axis=0) - POSE[:3])
    assert results["tared"].max() < 0.15
    assert results["raw"].max() > 3 * results["tared"].max()


def test_rest_reference_from_a_dataset(sensor, tmp_path):
    ds = simulate(sensor, grid_poses({"dx": [-1, 0, 1], "dz": [0, -1]}))
    ds.save(tmp_path / "d.csv")
    np.testing.assert_allclose(rest_reference(str(tmp_path / "d.csv"), 8), readings(sensor, np.zeros(5))[0])
    simulate(sensor, grid_poses({"dx": [-1, 1], "dz": [0, -1]})).save(tmp_path / "e.csv")
    with pytest.raises(InputError, match="no row at rest"):
        rest_reference(str(tmp_path / "e.csv"), 8)
    with pytest.raises(InputError, match="model takes 4"):
        rest_reference("paper", 4)


def test_a_tare_onto_another_sensors_rest_is_refused(model, model_file, sensor, tmp_path):
    """A unit's readings tared onto the drawing's rest (or the drawing's model tared onto a unit's) bent every
    estimate silently: the model reads the target itself far from rest, and the readout says so before it starts."""
    from fitgen.physics.units import draw_unit, write_unit

    unit = write_unit(tmp_path / "unit-7.toml", draw_unit(sensor, 7)[0], "paper")
    with pytest.raises(InputError, match=r"reads the rest readings of --rest u as .*far from rest"):
        check_rest_reference(model, rest_reference(str(unit), 8), "--rest u")
    check_rest_reference(model, rest_reference("paper", 8), "--sensor paper")  # its own: quiet
    # readings outside the fitted inputs are clamped, and their estimate may read as rest (a two-ring model at the
    # paper's rest read dz -0.28 mm, with four inputs clamped): the readings are held to the domain too
    from fitgen.equations.model import Equation, Model

    flat = Model(np.full(8, 1.0), np.full(8, 2.0), tuple(Equation(o, 0.0, (), ()) for o in ("dx", "dz")), "V", {})
    check_rest_reference(flat, np.r_[np.full(4, 1.5), np.full(4, 0.95)], "--rest near")  # within 10 % of the span
    with pytest.raises(InputError, match=r"^the rest readings of --rest far lie outside the readings the model was "
                                         r"fitted on \(v5, v6, v7, v8 beyond 10% of their span\)"):
        check_rest_reference(flat, np.r_[np.full(4, 1.5), np.full(4, 0.8)], "--rest far")
    for extra in (["--tare", "--rest", str(unit)], ["--auto-zero", "--sensor", str(unit)]):
        proc = run_cli("tactile-host", "read", "--model", model_file, "--adc", TWO_1115, "--count", "3",
                       "--simulate", "0,0,0,0,0", "-o", str(tmp_path / "out.csv"), *extra)
        assert_one_line_error(proc, contains="far from rest: they are another sensor's")
        assert not (tmp_path / "out.csv").exists()


def test_transient_errors_are_retried_and_counted_without_losing_samples(sensor, model, c_engine):
    bus, arr, clock = rig(sensor)
    bus.inject("nack", rate=0.03)
    bus.inject("timeout", rate=0.01)
    bus.inject("stuck", address=0x49, rate=0.02)
    sink = io.StringIO()
    fmt = LineFormat("csv", 8, model.output_names)
    stats = Readout(arr, c_engine, sink, fmt, clock=clock).run(count=60)
    e = stats.errors
    assert stats.samples == 60 and len(sink.getvalue().splitlines()) == 60
    assert e.nack == bus.injected["nack"] > 0 and e.timeout == bus.injected["timeout"] > 0
    assert e.stuck == bus.injected["stuck"] > 0 and e.resets == e.stuck
    assert e.retries == e.total
    table = parse_csv(fmt.header + sink.getvalue())[1]
    np.testing.assert_allclose(table[:, 1:9], readings(sensor, POSE, adc_bits=0).repeat(60, 0), atol=1e-4)
    assert "I2C errors" in stats.summary() and f"nack {e.nack}" in stats.summary()


def test_a_chip_that_goes_silent_ends_the_run_with_the_statistics(sensor, model):
    bus, arr, clock = rig(sensor)
    bus.inject("nack", address=0x49, after=12 * 10)  # 12 transfers to 0x49 a sample: gone during the 11th
    reader = Readout(arr, PythonEngine(model), io.StringIO(), LineFormat("csv", 8, model.output_names), clock=clock)
    with pytest.raises(DeviceSilent, match="ads1115@0x49 stays silent") as info:
        reader.run(count=100, rate=2.0)
    assert info.value.stats.samples == 10
    # the pace of the 10 samples written, not of 11 begun: the last was never counted
    assert info.value.stats.rate == pytest.approx(2.0, rel=1e-6) and "10 samples" in info.value.stats.summary()


# --- command line ------------------------------------------------------------------


def test_a_simulated_pose_or_noise_past_any_sensor_is_one_line(model_file, tmp_path):
    """dx=1e308 made the simulated field NaN and the simulated ADC a traceback (cannot convert NaN to integer), as
    did --sim-flicker 1e308; fitgen simulate refused the same pose in one line."""
    for extra, said in ((("--simulate", "dx=1e308"), "--simulate pose 'dx=1e308': dx from 1e+308 to 1e+308 mm: a pose "
                                                     "box's dx must lie within -1000..1000 mm"),
                        (("--simulate", "dx=1,dz=-1", "--sim-flicker", "1e308"),
                         "argument --sim-flicker: must be >= 0 and at most 1000 V, got 1e+308")):
        proc = run_cli("tactile-host", "read", "--model", model_file, "--adc", TWO_1115, "--count", "2", *extra)
        assert_one_line_error(proc, contains=said)
    assert_one_line_error(run_cli("tactile-host", "noise", "--adc", TWO_1115, "--simulate", "--seconds", "5",
                                  "--sim-noise", "2e3", "-o", str(tmp_path / "n.json")),
                          contains="argument --sim-noise: must be >= 0 and at most 1000 V, got 2000")
    assert list(tmp_path.iterdir()) == []


def test_a_tare_of_one_sample_says_it_measured_no_spread(model_file, tmp_path):
    """--tare-samples 1 printed "spread up to 0.00 mV rms", which reads as a sensor without noise."""
    said = {}
    for n in ("1", "2"):
        proc = run_cli("tactile-host", "read", "--model", model_file, "--adc", TWO_1115, "--simulate", "dx=1",
                       "--count", "1", "--tare", "--tare-samples", n, "-o", str(tmp_path / "s.csv"))
        assert proc.returncode == 0, proc.stderr
        said[n] = proc.stderr.splitlines()[0]
    assert "(one sample: no spread)" in said["1"] and "0.00 mV" not in said["1"], said["1"]
    assert re.search(r"\(spread up to \d+\.\d\d mV rms\)", said["2"]) and "0.00 mV" not in said["2"], said["2"]


def test_read_command_with_the_c_engine_to_a_jsonl_file(model_file, tmp_path):
    require_tool("gcc")
    out = tmp_path / "stream.jsonl"
    proc = run_cli("tactile-host", "read", "--model", model_file, "--adc", TWO_1115, "--simulate", "dx=1,dy=0.5,dz=-1",
                   "--engine", "c", "--format", "jsonl", "-o", str(out), "--count", "15", "--tare",
                   "--sim-offsets", "0.02,0,0,-0.01,0,0,0.01,0")
    assert proc.returncode == 0, proc.stderr
    lines = proc.stderr.splitlines()
    assert lines[0].startswith("tactile-host read: tare: offsets [mV] ") and len(lines) == 2
    measured = [float(x) for x in lines[0].split("[mV] ")[1].split(" (")[0].split()]
    np.testing.assert_allclose(measured, [20, 0, 0, -10, 0, 0, 10, 0], atol=0.5)
    assert lines[1].startswith("tactile-host read: done: 15 samples in")
    recs = [json.loads(ln) for ln in out.read_text().splitlines()]
    assert len(recs) == 15
    est = np.array([[r["dx"], r["dy"], r["dz"]] for r in recs]).mean(axis=0)
    assert np.all(np.abs(est - [1.0, 0.5, -1.0]) < 0.2)
    assert all(len(r["v"]) == 8 and r["status"] == 0 for r in recs)
    assert np.all(np.diff([r["t"] for r in recs]) > 0)


def test_a_ctrl_c_between_the_record_and_the_output_starts_both(model_file, tmp_path, monkeypatch):
    """A signal after --record's file was started, before -o's: the old recording was emptied and the old -o kept,
    a new run's record beside an old run's estimates."""
    import signal

    from fitgen.app import host_cli
    from host import session

    out, run = tmp_path / "est.csv", tmp_path / "run.jsonl"
    out.write_text("the last run's\n")
    run.write_text("the last run's\n")
    real = session.OutputText

    def opened(path, *args, **kwargs):
        text = real(path, *args, **kwargs)
        signal.raise_signal(signal.SIGINT)
        return text

    monkeypatch.setattr(session, "OutputText", opened)
    with pytest.raises(SystemExit) as stop:
        host_cli.main(["read", "--model", model_file, "--adc", TWO_1115, "--simulate", "0,0,-1,0,0", "--count", "3",
                       "-o", str(out), "--record", str(run)])
    assert stop.value.code == 130
    assert out.read_text() != "the last run's\n" and run.read_text() != "the last run's\n"


def test_the_tare_shows_progress_on_a_terminal(model_file, tmp_path, monkeypatch):
    """A tare of many samples at a low data rate takes seconds: on a terminal a bar counts them."""
    from fitgen.app.host_cli import main

    term = Terminal()
    monkeypatch.setattr(sys, "stderr", term)
    with pytest.raises(SystemExit) as done:
        main(["read", "--model", model_file, "--adc", TWO_1115, "--simulate", "dz=-1", "--tare",
              "--tare-samples", "120", "--count", "2", "-o", str(tmp_path / "out.csv")])
    assert done.value.code == 0, term.text
    bars = re.findall(r"\rtactile-host read: tare \[[# ]*\] (\d+)/120", term.text)
    assert bars and bars[-1] == "120", term.text
    assert CLEARED + "tactile-host read: tare: offsets [mV]" in term.text  # the bar is cleared before the line


def test_read_command_ends_on_a_silent_chip_with_one_line_and_status_1(model_file):
    proc = run_cli("tactile-host", "read", "--model", model_file, "--adc", TWO_1115, "--simulate", "dz=-1",
                   "--sim-fault", "silent:0x48:100", "--count", "1000")
    assert_one_line_error(proc, 1, "ads1115@0x48 stays silent: Remote I/O error (errno 121) on all 5 tries; "
                                   "stopped after")
    assert len(proc.stdout.splitlines()) >= 5  # the samples before it are all there, whole


def test_view_ends_on_a_silent_chip_saying_how_far_it_read(model_file):
    proc = run_cli("tactile-host", "view", "--model", model_file, "--adc", TWO_1115, "--simulate", "dz=-1",
                   "--sim-fault", "silent:0x48:100", "--count", "1000", "--port", "0")
    assert proc.returncode == 1 and "Traceback" not in proc.stderr, proc.stderr
    last = proc.stderr.strip().splitlines()[-1]
    assert re.fullmatch(r"tactile-host view: error: ads1115@0x48 stays silent: .*; stopped after \d+ samples .*",
                        last), last


def test_read_command_stops_cleanly_on_ctrl_c(model_file):
    code = "import sys; from fitgen.app.host_cli import main; sys.argv[0] = 'tactile-host'; main()"
    proc = subprocess.Popen([sys.executable, "-c", code, "read", "--model", model_file, "--adc", TWO_1115,
                             "--simulate", "dx=0.5", "--rate", "100"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        first = [proc.stdout.readline() for _ in range(6)]  # the header and 5 samples: it is running
        assert first[0].startswith("t,v1")
        time.sleep(0.1)
        proc.send_signal(signal.SIGINT)
        rest, err = proc.communicate(timeout=30)
    finally:
        proc.kill()
    assert proc.returncode == 0, err
    assert "Traceback" not in err
    summary = err.strip().splitlines()
    assert len(summary) == 1 and summary[0].startswith("tactile-host read: stopped: ")
    n = int(summary[0].split("stopped: ")[1].split()[0])
    body = (("".join(first) + rest).splitlines())[1:]
    assert len(body) == n >= 5
    assert all(len(ln.split(",")) == 15 for ln in body)  # every line whole
    assert " Hz)" in summary[0] and "I2C errors 0" in summary[0]


def test_the_tare_samples_help_gives_the_default_the_readout_takes():
    """The help's default is written as a literal (the parser stays light); it is the constant read and view use."""
    from host.rest import TARE_SAMPLES

    for cmd in ("read", "view"):
        proc = run_cli("tactile-host", cmd, "--help")
        assert proc.returncode == 0, proc.stderr
        assert f"(default {TARE_SAMPLES})" in " ".join(proc.stdout.split()), cmd
