"""tactile-host noise and host.allan: the Allan deviation of rest readings against allantools (a peer no one here
wrote), white noise read as averaging down, flicker as not, the command's bad input, and its record as
fitgen schedule --samples reads it."""

from __future__ import annotations

import json
import os
import signal

import allantools
import numpy as np
import pytest

from fitgen.base.errors import InputError
from fitgen.base.progress import Progress
from fitgen.physics.sensor import load_sensor
from host.adc import AdcArray
from host.allan import CANDIDATES, EXCESS, MIN_AVERAGES, averaging, overlapping_adev
from host.channelmap import parse_spec
from host.clock import VirtualClock
from host.noiserun import SECONDS, record, record_text, told, verdict
from host.simbus import SimBus
from host.simsensor import Drift, Flicker

from conftest import TWO_CHIPS, Terminal, assert_one_line_error, interrupt_after_rename, run_cli

NOISE = 5e-4  # V: the paper's sensor file's white noise per sample


def _rest(seconds: float, *, flicker: float = 0.0, seed: int = 0, progress=None):
    clock = VirtualClock()
    bus = SimBus.for_channel_map(parse_spec(TWO_CHIPS), load_sensor("paper").with_transfer("gmr"), np.zeros(5),
                                 clock=clock, noise=NOISE, flicker=flicker, seed=seed)
    array = AdcArray(bus, parse_spec(TWO_CHIPS), clock=clock)
    array.probe()
    array.setup()
    return record(array, seconds, clock, progress=progress)


@pytest.mark.parametrize("kind", ["white", "random walk", "offset"])
def test_overlapping_allan_deviation_is_allantools(kind):
    rng = np.random.default_rng(3)
    x = rng.normal(0.0, 1e-3, (4000, 3))
    if kind == "random walk":
        x = np.cumsum(x, axis=0)
    if kind == "offset":  # a reading far from 0 with a tiny noise: the running sums must not lose it
        x = 2.5 + 1e-7 * x
    ms = np.array([1, 2, 7, 64, 333, 1999])
    ours = overlapping_adev(x, ms)
    for k in range(3):
        _, theirs, _, _ = allantools.oadev(x[:, k], rate=10.0, data_type="freq", taus=ms / 10.0)
        np.testing.assert_allclose(ours[:, k], theirs, rtol=1e-9)


def test_the_simulated_bus_reads_its_white_noise_as_white():
    x, rate = _rest(MIN_AVERAGES * 64 / 125.0)
    av = averaging(x, rate)
    assert av.candidates[:3] == (16, 32, 64)
    np.testing.assert_allclose(av.single, NOISE, rtol=0.05)
    assert np.all(np.abs(av.ratio - 1.0) < 0.2)
    assert av.averages_at_all


RATE = 141.0  # samples per second: two ADS1115s' single-shot rounds


def _stream(level: float, seconds: float = SECONDS, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    x = rng.normal(0.0, NOISE, (int(seconds * RATE), 8))
    if level:
        f = Flicker(level, 8, np.random.default_rng(seed + 1))
        x += np.array([f.at(i / RATE) for i in range(len(x))])
    return x


def test_white_noise_read_for_the_default_time_is_told_to_average_128_samples():
    av = averaging(_stream(0.0), RATE)
    assert av.candidates == CANDIDATES
    assert av.recommended() == 256
    assert av.flicker_share(128) <= EXCESS
    assert f"--samples {av.recommended()}" in verdict(av)
    # with the recording written, the schedule is told to read it: the count and the noise it measured
    assert verdict(av, "n.json").endswith("fitgen schedule ... --samples n.json (which takes 256, and the noise "
                                          "measured here)")


def test_a_short_recording_cannot_tell_128_samples_safe():
    av = averaging(_stream(0.0, 120.0), RATE)
    assert av.recommended() < 128  # the flicker floor, read to 4x the variance, could be what 128 cannot stand


@pytest.mark.parametrize("level,told", [(0.01e-3, 32), (0.025e-3, 16)])
def test_flicker_too_small_to_see_in_a_row_keeps_the_rows_short(level, told):
    """Flicker of 2-5 % of the white noise: a row of 128 carries only 1-15 % more noise than it records, yet
    bench/noise_averaging.py shows such flicker costs 128 samples all they gain. Its floor is read, and fewer
    samples per row are told: the most whose share is within EXCESS, else the default 16."""
    av = averaging(_stream(level), RATE)
    assert np.sqrt(av.flicker[0]) == pytest.approx(level, rel=0.25)
    assert av.averages_at_all  # no row shows it: the ratio at 16 is within WHITE_RATIO
    assert av.recommended() == told
    assert (av.flicker_share(told) <= EXCESS or told == 16) and av.flicker_share(2 * told) > EXCESS
    assert f"--samples {told}" in verdict(av) if told > 16 else "keep 16 samples per row" in verdict(av)


def test_flicker_keeps_its_level_whatever_the_averaging():
    """The simulated 1/f noise: its Allan deviation stays near its level from 0.3 s to 100 s (allantools reads it)."""
    level, dt = 1e-4, 0.05
    f = Flicker(level, 4, np.random.default_rng(1))
    x = np.array([f.at(i * dt) for i in range(60_000)])  # 50 minutes
    taus = np.array([0.3, 1.0, 10.0, 100.0])
    for k in range(4):
        _, dev, _, _ = allantools.oadev(x[:, k], rate=1 / dt, data_type="freq", taus=taus)
        assert np.all(np.abs(dev / level - 1.0) < 0.3), dev / level


def test_flicker_on_the_simulated_bus_does_not_average_down():
    """--sim-flicker at half the white noise: even rows of 16 carry more noise than they record, and the verdict
    says so."""
    x, rate = _rest(MIN_AVERAGES * 16 / 125.0, flicker=NOISE / 2)
    av = averaging(x, rate, candidates=(16,))
    assert not av.averages_at_all
    assert av.recommended() == 16
    assert "does not average down even over 16 samples" in verdict(av)


def test_the_recording_shows_its_progress_on_a_terminal():
    term = Terminal()
    with Progress("noise", 20, stream=term, min_interval=0.0) as bar:
        x, _ = _rest(2.0, progress=bar)
    assert "noise [" in term.text and f"{len(x)} samples" in term.text
    assert "20/20" in term.text  # the bar counts tenths of a second: full when the time is up


@pytest.mark.parametrize("x,rate,what", [
    (np.ones((100, 8)), 100.0, "element 1, 2, 3, 4, 5, 6, 7, 8 reads the same value"),
    (np.zeros((2, 8)), 100.0, "at least 3 samples"),
    (np.full((100, 8), np.nan), 100.0, "not finite"),
    (np.random.default_rng(0).normal(size=(100, 8)), 0.0, "sample rate"),
])
def test_a_recording_that_cannot_be_read_is_refused(x, rate, what):
    with pytest.raises(InputError, match=what):
        averaging(x, rate)


def test_the_command_writes_its_verdict_and_plot(tmp_path):
    out, plots = tmp_path / "noise.json", tmp_path / "img"
    r = run_cli("tactile-host", "noise", "--adc", TWO_CHIPS, "--simulate", "--seconds", "3", "-o", str(out),
                "--plot", str(plots))
    assert r.returncode == 0, r.stderr
    meta = json.loads(out.read_text())
    assert meta["source"] == "simulated paper" and meta["samples"] > 100
    assert meta["too_short"] == [s for s in CANDIDATES if s not in meta["candidates"]]
    assert "| samples per row |" in r.stdout and "record" in r.stdout
    assert (plots / "allan.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_record_named_as_the_plot_is_refused_before_the_recording(tmp_path):
    """noise -o img/allan.png --plot img: ten minutes of reading, then the plot written over the record."""
    plots = tmp_path / "img"
    plots.mkdir()
    r = run_cli("tactile-host", "noise", "--adc", TWO_CHIPS, "--simulate", "--seconds", "60",
                "-o", str(plots / "allan.png"), "--plot", str(plots))
    assert_one_line_error(r, 2, f"-o {plots / 'allan.png'} is the plot --plot {plots} writes: give another name")
    assert "samples of every element" not in r.stdout and not any(plots.iterdir())


def test_a_ctrl_c_between_the_record_and_its_plot_leaves_both_new(tmp_path, monkeypatch):
    """A signal landing after the record was renamed into place, before the plot was, left a new record beside
    the old run's plot (SIGTERM 15-250 ms after a first one, 10 runs in 10)."""
    from fitgen.app import host_cli

    out, plots = tmp_path / "noise.json", tmp_path / "img"
    plots.mkdir()
    out.write_text("old record")
    (plots / "allan.png").write_bytes(b"old plot")
    renamed = interrupt_after_rename(monkeypatch)
    with pytest.raises(SystemExit) as stop:
        host_cli.main(["noise", "--adc", TWO_CHIPS, "--simulate", "--seconds", "1", "-o", str(out),
                       "--plot", str(plots)])
    assert stop.value.code == 130 and len(renamed) == 2
    assert json.loads(out.read_text())["source"] == "simulated paper"
    assert (plots / "allan.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize("sig, status, said", [(signal.SIGINT, 130, "interrupted"), (signal.SIGTERM, 143, "terminated"),
                                                (signal.SIGHUP, 129, "hung up")])
def test_a_recording_stopped_early_writes_nothing(tmp_path, monkeypatch, capsys, sig, status, said):
    """Ctrl-C during a re-run wrote its few samples' record over a whole one (candidates [], which schedule then
    refused) and its plot, with exit 0. The status is the signal's, as every command's (SIGTERM and SIGHUP had
    ended it with 130)."""
    from fitgen.app import host_cli
    from host import noiserun

    out, plots = tmp_path / "noise.json", tmp_path / "img"
    plots.mkdir()
    out.write_text("old record")
    (plots / "allan.png").write_bytes(b"old plot")
    run = noiserun.run_noise

    def stopped(args, stop):  # the signal lands as the recording ends
        av = run(args, stop)
        os.kill(os.getpid(), sig)
        for _ in range(1000):  # the handler runs between bytecodes
            pass
        return av

    monkeypatch.setattr(noiserun, "run_noise", stopped)
    with pytest.raises(SystemExit) as end:
        host_cli.main(["noise", "--adc", TWO_CHIPS, "--simulate", "--seconds", "1", "-o", str(out),
                       "--plot", str(plots)])
    assert end.value.code == status
    assert capsys.readouterr().err.splitlines()[-1].startswith(f"tactile-host noise: {said}: ")
    assert out.read_text() == "old record" and (plots / "allan.png").read_bytes() == b"old plot"


@pytest.mark.parametrize("args,what", [
    (["--seconds", "0"], "--seconds"),
    (["--seconds", "nan"], "--seconds"),
    (["--sim-flicker", "0.0001"], "--sim-flicker needs --simulate"),
    (["--sensor", "paper"], "--sensor goes with --simulate"),  # it names what a simulation simulates, no more
    (["--seed", "3"], "--seed needs --simulate"),
    (["--simulate", "--sim-flicker", "-1"], "--sim-flicker"),
    # it records the elements only: a thermistor's settings were taken and ignored
    (["--simulate", "--thermistor", "beta=3000,r25=10000,series=10000,vref=3.3"], "no thermistor"),
    (["--simulate", "--adc", TWO_CHIPS + ",temp=ads7828@0x4b:0"], "drop temp= from --adc"),
])
def test_bad_input_is_one_line_and_nothing_written(tmp_path, args, what):
    out = tmp_path / "noise.json"
    r = run_cli("tactile-host", "noise", "--adc", TWO_CHIPS, "--bus", "99", "-o", str(out), *args)
    assert_one_line_error(r, contains=what)
    assert not out.exists()


def test_a_clipped_input_is_refused_in_one_line(tmp_path):
    out = tmp_path / "noise.json"
    r = run_cli("tactile-host", "noise", "--adc", TWO_CHIPS, "--simulate", "--seconds", "1", "-o", str(out),
                "--pga", "2.048", "--sim-offsets", "0,0,1,0,0,0,0,0")  # 1.5 V at rest, 1 V more: past 2.048
    assert_one_line_error(r, contains="element 3 read at its converter's full scale")
    assert not out.exists()


def test_a_chip_that_falls_silent_ends_the_recording_in_one_line(tmp_path):
    out = tmp_path / "noise.json"
    r = run_cli("tactile-host", "noise", "--adc", TWO_CHIPS, "--simulate", "--seconds", "5", "-o", str(out),
                "--sim-fault", "silent:0x49:200")
    assert_one_line_error(r, status=1, contains="nothing written")
    assert not out.exists()


def test_a_sensor_still_warming_up_is_told_to_wait():
    """The simulated drift (host.simsensor.Drift.typical: about 1 mV/degC per element, 5 degC over 10 minutes) moves
    the offsets by more than a row's noise over a capture: the verdict says so before anything about averaging."""
    clock = VirtualClock()
    cmap = parse_spec(TWO_CHIPS)
    bus = SimBus.for_channel_map(cmap, load_sensor("paper").with_transfer("gmr"), np.zeros(5), clock=clock,
                                 noise=NOISE, drift=Drift.typical(8, creep_tau=60.0))
    array = AdcArray(bus, cmap, clock=clock)
    array.probe()
    array.setup()
    av = averaging(*record(array, 30.0, clock))
    assert av.drifts()
    assert verdict(av).startswith("the readings drift: e")
    steady = averaging(_stream(0.0, 120.0), RATE)
    assert not steady.drifts() and not verdict(steady).startswith("the readings drift")


def test_a_short_recording_of_white_noise_does_not_read_as_drift():
    """30 s read 16-64 samples per row; white noise's slope over so short a recording is near the drift limit, so
    the slope is taken three standard errors low. A real warm-up (test above) still reads as drift."""
    told = [averaging(_stream(0.0, 30.0, seed=s), RATE) for s in range(20)]
    assert [av.drifts() for av in told] == [False] * 20
    assert all(not verdict(av).startswith("the readings drift") for av in told)


def _record(tmp_path, x, name="noise.json"):
    path = tmp_path / name
    path.write_text(record_text(averaging(x, RATE), "test"))
    return path


def test_a_schedule_is_made_for_what_the_record_tells(tmp_path):
    """`fitgen schedule --samples noise.json`: the samples per row the recording recommends and the noise it
    measured, the same schedule as when both are given by hand, and the meta says where they came from."""
    rec = _record(tmp_path, _stream(0.0, seed=3))
    told_s, single = told(rec)
    sigma = float(np.sqrt(np.mean(single ** 2)))
    assert told_s == averaging(_stream(0.0, seed=3), RATE).recommended() == 256
    assert sigma == pytest.approx(NOISE, rel=0.02)
    common = ("--sensor", "paper", "--n", "12", "--limits", "dx=-1:1 dy=-1:1 dz=-1:0")
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    r = run_cli("fitgen", "schedule", *common, "--samples", str(rec), "-o", str(a))
    assert r.returncode == 0, r.stderr
    assert f"made for 256 samples per row (told by {rec}) and {sigma:.3g} V rms per sample" in r.stderr
    assert run_cli("fitgen", "schedule", *common, "--samples", "256", "--noise", repr(sigma),
                   "-o", str(b)).returncode == 0
    assert a.read_text() == b.read_text()
    meta = json.loads((tmp_path / "a.csv.meta.json").read_text())
    assert meta["samples_per_row"] == 256 and meta["samples_from"] == str(rec)
    assert meta["noise_per_sample"] == pytest.approx(sigma, rel=1e-12)
    # --noise given beside the record wins over the record's noise
    c = tmp_path / "c.csv"
    r = run_cli("fitgen", "schedule", *common, "--samples", str(rec), "--noise", "0.002", "-o", str(c))
    assert r.returncode == 0, r.stderr
    assert json.loads((tmp_path / "c.csv.meta.json").read_text())["noise_per_sample"] == 0.002


def _edited(tmp_path, **changes):
    path = _record(tmp_path, _stream(0.0, 120.0))  # long enough that its slope reads no drift
    rec = json.loads(path.read_text())
    path.write_text(json.dumps({**rec, **changes}))
    return path


def _written(path, data: bytes):
    path.write_bytes(data)
    return path


@pytest.mark.parametrize("make,extra,what", [
    (lambda p: _record(p, _stream(0.0, 3.0)), (), "too short to read 16 samples per row"),
    (lambda p: _record(p, _stream(0.0, 60.0) + 2e-5 * np.arange(int(60 * RATE))[:, None] / RATE), (),
     "its readings drift"),
    (lambda p: _record(p, _stream(NOISE, 60.0)), (), "does not average down even over 16 samples"),
    (lambda p: _edited(p, single_v=[NOISE] * 4), (), "records 4 elements, the sensor paper has 8"),
    (lambda p: _edited(p, recommended=None), (), "is not a record tactile-host noise -o wrote (a field that is not "
                                                 "what such a record holds)"),
    # JSON's integers past a float's range: an OverflowError, a traceback
    (lambda p: _edited(p, ratio=[[10 ** 400]]), (), "is not a record tactile-host noise -o wrote (a field"),
    # another command's JSON, or a list: Python's exception names leaked ("KeyError: 'recommended'")
    (lambda p: _written(p / "m.json", b'{"single_v": [0.001]}'), (), "m.json is not a record tactile-host noise -o "
                                                                      "wrote (it has no 'recommended')"),
    (lambda p: _written(p / "l.json", b"[1, 2]"), (), "l.json is not a record tactile-host noise -o wrote (not a "
                                                       "JSON object)"),
    (lambda p: _written(p / "t.json", b"nope"), (), "t.json is not a record tactile-host noise -o wrote (not JSON)"),
    # a file that is no .json: it was called "not a whole number"
    (lambda p: _written(p / "c.csv", b"v1,dx\n1,0\n"), (), "--samples {p}/c.csv: a count, or the .json record "
                                                            "tactile-host noise -o writes; this file is neither"),
    (lambda p: _record(p, _stream(0.0, 120.0)), ("--transfer", "raw"), "measured volts and the schedule is for mT"),
    (lambda p: p / "absent.json", (), "noise record {p}/absent.json: no such file"),
    # figures no ADC reads: 1e300 overflowed the schedule's weights in numpy warnings, 1e-300 read as no noise
    (lambda p: _edited(p, single_v=[1e300] * 8), (), "its recommendation, candidates, ratios, noise or drift are off"),
    # a hand edit read as something it does not say: 16.7 as 16, a NaN ratio as one that averages down
    (lambda p: _edited(p, recommended=16.7), (), "its recommendation, candidates, ratios, noise or drift are off"),
    (lambda p: _edited(p, recommended="16"), (), "its recommendation, candidates, ratios, noise or drift are off"),
    (lambda p: _edited(p, candidates=[16], ratio=[[float("nan")] * 8]), (), "its recommendation, candidates, ratios, noise or drift"),
    (lambda p: _edited(p, candidates="x"), (), "its recommendation, candidates, ratios, noise or drift are off"),
    (lambda p: _edited(p, single_v=[1e-300] * 8), (), "its recommendation, candidates, ratios, noise or drift are off"),
    (lambda p: (p / "folder.json").mkdir() or p / "folder.json", (), "folder.json: a folder, not a file"),
    (lambda p: _written(p / "r.json", b'{"a": "\xe9"}'), (), "line 1 is not UTF-8 text"),
])
def test_a_record_that_tells_no_rows_is_refused(tmp_path, make, extra, what):
    out = tmp_path / "s.csv"
    r = run_cli("fitgen", "schedule", "--n", "12", "--samples", str(make(tmp_path)), *extra, "-o", str(out))
    assert_one_line_error(r, 2, what.format(p=tmp_path))
    assert not out.exists() and not (tmp_path / "s.csv.meta.json").exists()


def test_the_time_told_to_record_is_enough_to_read_the_rows():
    """"record at least 8 s" after 8 s at 95 samples a second: the time was rounded to the nearest second, not up,
    and a recording of the time said was still too short."""
    from host.allan import CANDIDATES, needed_samples
    from host.noiserun import _seconds

    for rate in (95.0, 95.1, 107.5, 215.0, 860.0):
        for s in CANDIDATES:
            told = _seconds(needed_samples(s), rate)
            assert told * rate >= needed_samples(s) and (told - 1) * rate < needed_samples(s)
