"""Recording a calibration dataset: averaging, the spread check, and no row lost or doubled across interruptions."""

import io
import json
import shlex

import numpy as np
import pytest

from fitgen.physics.dataset import load_dataset
from fitgen.base.errors import InputError
from fitgen.fitting.fit import fit_model
from fitgen.physics.transfer import readings
from host.adc import AdcArray
from host.capture import SpreadTooLarge, capture, load_schedule
from host.capturefile import header_line, prepare_output
from host.posewait import enter_waiter, trigger_waiter
from host.channelmap import parse_spec
from host.clock import VirtualClock
from host.simbus import SimBus

from conftest import assert_one_line_error, run_cli

TWO_1115 = "ads1115@0x48:0-3,ads1115@0x49:0-3"


def write_schedule(path, rows, columns=("dx", "dy", "dz")):
    path.write_text(",".join(columns) + "\n" + "".join(",".join(map(str, r)) + "\n" for r in rows))
    return path


def grid_rows():
    return [(dx, dy, dz) for dz in (0, -1, -2) for dy in (-1, 0, 1) for dx in (-2, 0, 2)]  # 27 poses


def rig(sensor, noise=0.0005, seed=0):
    cmap = parse_spec(TWO_1115)
    clock = VirtualClock()
    bus = SimBus.for_channel_map(cmap, sensor, None, clock=clock, noise=noise, seed=seed)
    return bus, AdcArray(bus, cmap, clock=clock), clock


def data_rows(path):
    lines = path.read_text().splitlines()
    return lines[0], [tuple(float(x) for x in ln.split(",")) for ln in lines[1:]]


def test_capture_writes_averaged_rows_in_the_dataset_format(sensor, tmp_path):
    sched = load_schedule(write_schedule(tmp_path / "s.csv", grid_rows()[:6]))
    bus, arr, clock = rig(sensor)
    out = tmp_path / "d.csv"
    res = capture(arr, sched, out, samples=16, wait=None, set_pose=bus.set_pose, clock=clock)
    assert res.complete and res.captured == 6 and res.before == 0
    ds = load_dataset(out)
    assert ds.target_names == ("dx", "dy", "dz") and ds.n_rows == 6
    np.testing.assert_array_equal(ds.targets, sched.values)
    truth = readings(sensor, sched.poses, adc_bits=0)
    # 16 samples of 0.5 mV noise: the mean is within 4 standard errors (plus half an LSB)
    assert np.max(np.abs(ds.inputs - truth)) < 4 * 0.0005 / 4 + 62.5e-6
    assert np.max(np.abs(ds.inputs - truth)) > 0  # and it is a noisy measurement, not the physics copied
    meta = json.loads((tmp_path / "d.csv.meta.json").read_text())
    assert meta["units"] == "V" and meta["rows"] == 6 and meta["samples_per_row"] == 16
    assert ds.meta["units"] == "V"  # what fitgen fit reads: a model in volts
    assert max(res.spreads) < 0.001


def test_a_spread_over_the_limit_is_measured_again_then_refused(sensor, tmp_path):
    sched = load_schedule(write_schedule(tmp_path / "s.csv", grid_rows()[:3]))
    bus, arr, clock = rig(sensor, noise=0.004)
    out = tmp_path / "d.csv"
    with pytest.raises(SpreadTooLarge, match=r"pose 1/3 \(dx=-2 dy=-1 dz=0\): v\d spreads .* in 3 tries"):
        capture(arr, sched, out, samples=8, max_spread=0.003, wait=None, set_pose=bus.set_pose, clock=clock)
    assert out.read_text() == header_line(8, ("dx", "dy", "dz"))  # no row for it
    transfers = bus.transfers
    bus.feed.noise = 0.0005  # the sensor has settled
    res = capture(arr, sched, out, samples=8, max_spread=0.003, wait=None, set_pose=bus.set_pose, clock=clock)
    assert res.complete and bus.transfers > transfers


class Interrupt(Exception):
    pass


def test_an_interruption_loses_and_doubles_no_row(sensor, tmp_path):
    rows = grid_rows()
    sched = load_schedule(write_schedule(tmp_path / "s.csv", rows))
    out = tmp_path / "d.csv"
    bus, arr, clock = rig(sensor)

    def stop_at(k):
        def wait(i, pose):
            if i == k:
                raise KeyboardInterrupt
            return True
        return wait

    with pytest.raises(KeyboardInterrupt):
        capture(arr, sched, out, samples=4, wait=stop_at(10), set_pose=bus.set_pose, clock=clock)
    assert len(data_rows(out)[1]) == 10
    # a write cut short by a power cut leaves a line without its newline
    with open(out, "a") as fh:
        fh.write("1.4812,1.52")
    with pytest.raises(KeyboardInterrupt):
        capture(arr, sched, out, samples=4, wait=stop_at(17), set_pose=bus.set_pose, clock=clock)
    visited = []
    res = capture(arr, sched, out, samples=4, wait=lambda i, p: visited.append(i) or True, set_pose=bus.set_pose,
                  clock=clock)
    assert res.before == 17 and res.captured == 10 and res.complete and not res.dropped_partial
    assert visited == list(range(17, 27))
    header, got = data_rows(out)
    assert [r[8:] for r in got] == [tuple(map(float, r)) for r in rows]  # every pose once, in schedule order
    truth = readings(sensor, sched.poses, adc_bits=0)
    assert np.max(np.abs(np.array(got)[:, :8] - truth)) < 0.002


def test_rows_of_another_schedule_are_named_as_poses(sensor, tmp_path):
    """Resuming into a file of another schedule's rows names the first foreign pose as progress names poses (it
    printed a Python dict of numpy floats)."""
    rows = grid_rows()
    out = tmp_path / "d.csv"
    bus, arr, clock = rig(sensor)
    capture(arr, load_schedule(write_schedule(tmp_path / "a.csv", rows[:3])), out, samples=4, set_pose=bus.set_pose,
            clock=clock)
    other = load_schedule(write_schedule(tmp_path / "b.csv", rows[3:6]))
    with pytest.raises(InputError) as err:
        capture(arr, other, out, samples=4, set_pose=bus.set_pose, clock=clock)
    first = " ".join(f"{c}={v:g}" for c, v in zip(("dx", "dy", "dz"), rows[0]))
    assert str(err.value).startswith(f"output {out} line 2: pose {first} is not in the "), str(err.value)


def test_a_second_ctrl_c_during_the_last_meta_write_leaves_the_meta_with_the_rows(sensor, tmp_path, monkeypatch):
    """A second SIGINT (``timeout -s INT`` sends two; a user presses Ctrl-C twice) landed in the final meta write of
    an interrupted capture: its rows were kept but its meta said 'rows: 0' and no noise, so a resume pooled
    noise over fewer rows than the file holds."""
    import signal

    from host import capture as cap

    sched = load_schedule(write_schedule(tmp_path / "s.csv", grid_rows()[:8]))
    out = tmp_path / "d.csv"
    bus, arr, clock = rig(sensor)
    real, calls = cap.write_meta, []

    def write_meta(path, info):
        calls.append(1)
        if len(calls) > 1:  # the write in capture's cleanup, after the first Ctrl-C below
            signal.raise_signal(signal.SIGINT)
        real(path, info)

    def wait(i, pose):
        if i == 5:
            raise KeyboardInterrupt
        return True

    monkeypatch.setattr(cap, "write_meta", write_meta)
    with pytest.raises(KeyboardInterrupt):
        capture(arr, sched, out, samples=4, wait=wait, set_pose=bus.set_pose, clock=clock)
    assert len(calls) == 2
    meta = json.loads((tmp_path / "d.csv.meta.json").read_text())
    assert len(data_rows(out)[1]) == 5 and meta["rows"] == 5 and meta["noise_rows"] == 5


def _eight_poses_with_a_thermistor(sensor, tmp_path):
    """A schedule of 8 poses, the output, a rig, and temperatures that rise a quarter degree per read."""
    sched = load_schedule(write_schedule(tmp_path / "s.csv", grid_rows()[:8]))
    return sched, tmp_path / "d.csv", rig(sensor), iter(np.arange(20.0, 40.0, 0.25))


def test_a_ctrl_c_while_a_row_is_synced_counts_the_row(sensor, tmp_path, monkeypatch):
    """A SIGINT landing in a row's fsync (strace's signal injection hit it) raised after the row was on disk but
    before it was counted: the meta's noise was pooled over one row fewer, and the row's temperature was dropped."""
    import signal

    from fitgen.physics.dataset import load_dataset, row_degc
    from host import capture as cap

    sched, out, (bus, arr, clock), degc = _eight_poses_with_a_thermistor(sensor, tmp_path)
    real, appended = cap.RowWriter.append, []

    def append(self, line):
        real(self, line)
        appended.append(line)
        if len(appended) == 3:
            signal.raise_signal(signal.SIGINT)

    monkeypatch.setattr(cap.RowWriter, "append", append)
    with pytest.raises(KeyboardInterrupt):
        capture(arr, sched, out, samples=4, set_pose=bus.set_pose, clock=clock, temperature=lambda: next(degc))
    ds = load_dataset(out)
    assert ds.n_rows == 3 and ds.meta["noise_rows"] == 3 and len(row_degc(ds.meta, 3)) == 3


def test_each_rows_temperature_stays_with_its_row_when_a_run_is_stopped(sensor, tmp_path, monkeypatch):
    """The meta takes a row's temperature before the row is written; a run stopped between the two keeps one per
    row written, and a resumed run appends to them."""
    from fitgen.physics.dataset import load_dataset, row_degc
    from host import capture as cap

    sched, out, (bus, arr, clock), degc = _eight_poses_with_a_thermistor(sensor, tmp_path)
    real, appended = cap.RowWriter.append, []

    def append(self, line):
        if len(appended) == 5:
            raise KeyboardInterrupt  # after the sixth row's temperature went into the meta
        appended.append(line)
        real(self, line)

    monkeypatch.setattr(cap.RowWriter, "append", append)
    with pytest.raises(KeyboardInterrupt):
        capture(arr, sched, out, samples=4, set_pose=bus.set_pose, clock=clock, temperature=lambda: next(degc))
    ds = load_dataset(out)
    assert ds.n_rows == 5 and row_degc(ds.meta, 5).tolist() == [20.125, 20.625, 21.125, 21.625, 22.125]
    monkeypatch.setattr(cap.RowWriter, "append", real)
    capture(arr, sched, out, samples=4, set_pose=bus.set_pose, clock=clock, temperature=lambda: next(degc))
    ds = load_dataset(out)
    assert ds.n_rows == 8 and row_degc(ds.meta, 8).tolist()[5:] == [23.125, 23.625, 24.125]


def test_a_row_deleted_to_be_taken_again_keeps_the_other_rows_temperatures(sensor, tmp_path):
    """A row deleted from the middle (identify names a knocked row to delete and take again): the resume took the
    first rows' worth of temperatures, so every row after the deleted one was given its predecessor's."""
    from fitgen.physics.dataset import load_dataset, row_degc

    sched, out, (bus, arr, clock), degc = _eight_poses_with_a_thermistor(sensor, tmp_path)
    capture(arr, sched, out, samples=4, set_pose=bus.set_pose, clock=clock, temperature=lambda: next(degc))
    before = row_degc(load_dataset(out).meta, 8).tolist()
    lines = out.read_text().splitlines(keepends=True)
    out.write_text("".join(lines[:3] + lines[4:]))  # row 3 deleted
    capture(arr, sched, out, samples=4, set_pose=bus.set_pose, clock=clock, temperature=lambda: next(degc))
    ds = load_dataset(out)
    assert ds.n_rows == 8 and row_degc(ds.meta, 8).tolist()[:7] == before[:2] + before[3:]
    assert row_degc(ds.meta, 8)[7] > before[7]  # taken again, later: the temperatures rise


def test_a_resume_refuses_another_captures_meta_and_keeps_rows_written_after_its_own(sensor, tmp_path):
    """A meta copied from another capture beside the rows: its noise figures were pooled into this run's, as if they
    spoke for these rows. Rows written after the meta's last rewrite (a run killed outright) still resume."""
    sched = load_schedule(write_schedule(tmp_path / "s.csv", grid_rows()[:6]))
    out, other = tmp_path / "d.csv", tmp_path / "e.csv"
    for path, seed in ((out, 0), (other, 1)):
        bus, arr, clock = rig(sensor, seed=seed)
        capture(arr, sched, path, samples=4, wait=lambda i, p: i < 4, set_pose=bus.set_pose, clock=clock)
    meta = (tmp_path / "d.csv.meta.json").read_text()
    (tmp_path / "d.csv.meta.json").write_text((tmp_path / "e.csv.meta.json").read_text())
    bus, arr, clock = rig(sensor, seed=2)
    with pytest.raises(InputError, match=r"output .*d\.csv: its meta \(d\.csv\.meta\.json\) records none of its 4 "
                                         "rows: it is another capture's; restore the rows and their meta from one "
                                         "copy to resume, or choose another -o"):
        capture(arr, sched, out, samples=4, set_pose=bus.set_pose, clock=clock)
    assert len(data_rows(out)[1]) == 4
    # the meta of its first 3 rows (a run killed outright after the fourth): resumed
    lines = out.read_text().splitlines(keepends=True)
    first = json.loads(meta)
    first["row_sha256"] = first["row_sha256"][:3]
    (tmp_path / "d.csv.meta.json").write_text(json.dumps(first))
    capture(arr, sched, out, samples=4, set_pose=bus.set_pose, clock=clock)
    assert len(data_rows(out)[1]) == 6 and json.loads((tmp_path / "d.csv.meta.json").read_text())["noise_rows"] == 6
    # a row the meta does not record, before rows it does: edited, or another capture's
    out.write_text("".join(lines[:2] + [lines[2].replace(",", ",1", 1)] + lines[3:]))
    (tmp_path / "d.csv.meta.json").write_text(meta)
    with pytest.raises(InputError, match=r"d\.csv line 3: a row its meta \(d\.csv\.meta\.json\) does not record, "
                                         r"before one it does \(line 4\): the meta is another capture's, or the row "
                                         "was edited"):
        capture(arr, sched, out, samples=4, set_pose=bus.set_pose, clock=clock)


def test_a_pose_scheduled_twice_is_captured_twice(sensor, tmp_path):
    rows = [(0, 0, 0), (1, 0, -1), (0, 0, 0), (1, 0, -1)]
    sched = load_schedule(write_schedule(tmp_path / "s.csv", rows))
    out = tmp_path / "d.csv"
    bus, arr, clock = rig(sensor)
    capture(arr, sched, out, samples=2, wait=lambda i, p: i < 3, set_pose=bus.set_pose, clock=clock)
    state = prepare_output(out, 8, sched)
    assert state.done.tolist() == [True, True, True, False]
    capture(arr, sched, out, samples=2, wait=None, set_pose=bus.set_pose, clock=clock)
    assert [r[8:] for r in data_rows(out)[1]] == [tuple(map(float, r)) for r in rows]


def test_an_output_from_another_run_is_refused(sensor, tmp_path):
    sched = load_schedule(write_schedule(tmp_path / "s.csv", grid_rows()[:4]))
    out = tmp_path / "d.csv"
    out.write_text(header_line(8, ("dx", "dz")))
    with pytest.raises(InputError, match="belongs to another channel map or schedule"):
        prepare_output(out, 8, sched)
    out.write_text(header_line(8, ("dx", "dy", "dz")) + ",".join(["1.5"] * 8 + ["9", "9", "9"]) + "\n")
    with pytest.raises(InputError, match="line 2: pose .* is not"):
        prepare_output(out, 8, sched)
    out.write_text(header_line(8, ("dx", "dy", "dz")) + "1.5,2\n")
    with pytest.raises(InputError, match="line 2: not a row of 11 numbers"):
        prepare_output(out, 8, sched)
    # rows of the schedule's, copied: the copies named, to delete (it named line 2, a good row, and told to choose
    # another -o, which throws the capture away)
    rows = [",".join(["1.5"] * 8 + [f"{v:g}" for v in (r[0], r[1], r[2])]) + "\n" for r in grid_rows()[:4]]
    out.write_text(header_line(8, ("dx", "dy", "dz")) + "".join(rows[:3] + rows[:2]))
    with pytest.raises(InputError, match=r"line\(s\) 5: pose .* more often than the schedule .* has it: rows copied\? "
                                         "delete those lines to resume"):
        prepare_output(out, 8, sched)
    # a header alone whose line end was never written: resumed from the start, not called another run's
    out.write_text(header_line(8, ("dx", "dy", "dz")).rstrip("\n"))
    assert prepare_output(out, 8, sched).rows == 0 and out.read_text() == header_line(8, ("dx", "dy", "dz"))


def test_enter_and_trigger_waiters(tmp_path):
    sched = load_schedule(write_schedule(tmp_path / "s.csv", [(1, 0, -1), (2, 0, -1), (0, 0, 0.2)]))
    err = io.StringIO()
    wait = enter_waiter(sched, io.StringIO("\n\nq\n"), err)
    assert wait(0, sched.poses[0]) is True and wait(2, sched.poses[2]) is True and wait(1, sched.poses[1]) is False
    assert "pose 1/3: dx=1 dy=0 dz=-1; set it, then press Enter" in err.getvalue()
    # a schedule's rest row (fitgen schedule) says what it asks of a hand-set stage
    assert "pose 3/3: dx=0 dy=0 dz=0.2 (the indenter lifted off the skin: the sensor at rest); set it" in err.getvalue()
    assert enter_waiter(sched, io.StringIO(""), err)(0, sched.poses[0]) is False  # end of input stops
    log = tmp_path / "log"
    wait = trigger_waiter(f'echo "$TM_POSE_INDEX/$TM_POSE_COUNT $TM_DX $TM_DZ" >> {shlex.quote(str(log))}', sched)
    assert wait(1, sched.poses[1]) is True
    assert log.read_text() == "2/3 2.0 -1.0\n"


def test_a_trigger_is_killed_and_reaped_even_when_an_interrupted_wait_left_popens_lock_held():
    """A Ctrl-C landing just after Popen.wait's non-blocking acquire of its internal lock leaves the lock held
    (CPython's subprocess); killing the trigger's group must still reap it at once, not block on that lock."""
    import subprocess
    import threading

    from host.posewait import _kill_group

    proc = subprocess.Popen(["sleep", "30"], start_new_session=True)
    assert proc._waitpid_lock.acquire(False)  # as the interrupted wait left it
    done = threading.Thread(target=_kill_group, args=(proc,), daemon=True)
    done.start()
    done.join(20)
    alive = done.is_alive()
    proc._waitpid_lock.release()
    if alive:
        proc.kill()
    assert not alive, "_kill_group blocked on Popen's wait lock"
    assert proc.returncode == -9 and proc.poll() == -9


def test_ctrl_c_at_a_prompt_ends_its_line_and_goes_on():
    """What is written after Ctrl-C at a prompt (the capture's last line) starts a line of its own."""
    from host.prompt import ask_line

    class Interrupted:
        def readline(self):
            raise KeyboardInterrupt

    err = io.StringIO()
    with pytest.raises(KeyboardInterrupt):
        ask_line(Interrupted(), err, "pose 1/3: set it, then press Enter ")
    assert err.getvalue() == "pose 1/3: set it, then press Enter \n"


# --- command line ------------------------------------------------------------------


def test_capture_command_killed_midway_resumes_without_loss_or_duplicates(tmp_path):
    rows = grid_rows()
    sched = write_schedule(tmp_path / "s.csv", rows)
    out = tmp_path / "d.csv"
    # the trigger kills the capture outright (SIGKILL, as a power cut would) when pose 9 is due
    kill = 'if [ "$TM_POSE_INDEX" = 9 ]; then kill -9 $PPID; sleep 5; fi'
    args = ["capture", "--poses", str(sched), "--adc", TWO_1115, "-o", str(out), "--simulate", "--samples", "4"]
    proc = run_cli("tactile-host", *args, "--trigger", kill)
    assert proc.returncode == -9
    assert len(data_rows(out)[1]) == 8
    proc = run_cli("tactile-host", *args, "--trigger", "true")
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr.strip() == (f"tactile-host capture: 27/27 poses in {out} (19 captured now, 8 already there)\n"
                                   f"tactile-host capture: next: fitgen identify {out} --sensor DRAWING -o "
                                   f"{tmp_path / 'unit.toml'} "
                                   "(the unit's physics from these rows)")  # a schedule without meta names none
    header, got = data_rows(out)
    assert header == "v1,v2,v3,v4,v5,v6,v7,v8,dx,dy,dz"
    assert [r[8:] for r in got] == [tuple(map(float, r)) for r in rows]
    # a finished dataset fits: a model in volts
    model = fit_model(load_dataset(out))
    assert model.input_units == "V"
    meta = (tmp_path / "d.csv.meta.json").read_text()
    proc = run_cli("tactile-host", *args)  # nothing left to do: the meta stays as the runs that took the rows left it
    assert proc.returncode == 0 and "27/27 poses in" in proc.stderr and "nothing to capture" in proc.stderr
    assert (tmp_path / "d.csv.meta.json").read_text() == meta
    # rows to add, but through another channel map or averaging another number of samples: refused
    write_schedule(sched, rows + [(0.25, 0.25, -0.25)])
    other = ["--adc", "ads1115@0x49:0-3,ads1115@0x48:0-3"]
    for extra, said in ((other, "captured with --adc ads1115@0x48:0,1,2,3,ads1115@0x49:0,1,2,3, this run's is"),
                        (["--samples", "8"], "captured with --samples 4, this run's is 8"),
                        # the elements' map alone was compared: rows read without a thermistor gained a temperature,
                        # and the other way round a resume dropped theirs from the meta
                        (["--adc", TWO_1115 + ",temp=ads1115@0x4a:0"],
                         "its 27 rows were captured without a thermistor (temp= in --adc), this run's --adc reads one")):
        assert_one_line_error(run_cli("tactile-host", *args, *extra, "--trigger", "true"), 2, said)
    assert (tmp_path / "d.csv.meta.json").read_text() == meta and len(data_rows(out)[1]) == 27


def test_capture_command_a_failing_trigger_is_one_line_status_1_and_rows_are_kept(tmp_path):
    sched = write_schedule(tmp_path / "s.csv", grid_rows()[:5])
    out = tmp_path / "d.csv"
    proc = run_cli("tactile-host", "capture", "--poses", str(sched), "--adc", TWO_1115, "-o", str(out), "--simulate",
                   "--samples", "2", "--trigger", '[ "$TM_POSE_INDEX" -lt 4 ]')
    assert_one_line_error(proc, 1, "exit status 1 at pose 4/5")
    assert "run the same command again to resume" in proc.stderr
    assert len(data_rows(out)[1]) == 3


def test_capture_command_a_hung_trigger_is_killed_at_its_time_limit_and_rows_are_kept(tmp_path):
    import time

    sched = write_schedule(tmp_path / "s.csv", grid_rows()[:5])
    out = tmp_path / "d.csv"
    t0 = time.monotonic()
    # the shell's child too: if it lived on, it would hold the output pipe (and this call) for 30 s
    proc = run_cli("tactile-host", "capture", "--poses", str(sched), "--adc", TWO_1115, "-o", str(out), "--simulate",
                   "--samples", "2", "--trigger", '[ "$TM_POSE_INDEX" -lt 4 ] || { sleep 30; true; }',
                   "--trigger-timeout", "1")
    assert time.monotonic() - t0 < 20
    assert_one_line_error(proc, 1, "did not exit within 1 s (--trigger-timeout) at pose 4/5")
    assert "run the same command again to resume" in proc.stderr
    assert len(data_rows(out)[1]) == 3
    assert_one_line_error(run_cli("tactile-host", "capture", "--poses", str(sched), "--adc", TWO_1115, "-o", str(out),
                                  "--simulate", "--trigger-timeout", "5"), 2, "--trigger-timeout goes with --trigger")


def test_capture_command_ctrl_c_after_rows_says_they_are_kept(tmp_path):
    sched = write_schedule(tmp_path / "s.csv", grid_rows()[:5])
    out = tmp_path / "d.csv"
    proc = run_cli("tactile-host", "capture", "--poses", str(sched), "--adc", TWO_1115, "-o", str(out), "--simulate",
                   "--samples", "2", "--trigger", 'if [ "$TM_POSE_INDEX" = 3 ]; then kill -INT $PPID; sleep 5; fi')
    assert proc.returncode == 130, proc.stderr
    assert proc.stderr.strip() == (f"tactile-host capture: interrupted; the rows written so far are kept in {out}: "
                                   "run the same command again to resume")
    assert len(data_rows(out)[1]) == 2


def test_a_second_capture_on_the_same_output_is_refused_while_the_first_runs(tmp_path):
    """The first run holds its output from before reading it to after its last row; a second, on the same -o, is
    one line and exit 2, and the first's rows are neither interleaved nor doubled."""
    import subprocess
    import sys
    import time

    sched = write_schedule(tmp_path / "s.csv", grid_rows()[:4])
    out, paused, go = tmp_path / "d.csv", tmp_path / "paused", tmp_path / "go"
    args = ["capture", "--poses", str(sched), "--adc", TWO_1115, "-o", str(out), "--simulate", "--samples", "2"]
    # the first run's trigger holds it at pose 2 until the test says go
    hold = (f'if [ "$TM_POSE_INDEX" = 2 ]; then touch {shlex.quote(str(paused))}; '
            f'while [ ! -e {shlex.quote(str(go))} ]; do sleep 0.05; done; fi')
    code = "import sys; from fitgen.app.host_cli import main; sys.argv[0] = 'tactile-host'; main()"
    first = subprocess.Popen([sys.executable, "-c", code, *args, "--trigger", hold], stderr=subprocess.PIPE, text=True)
    try:
        t0 = time.monotonic()
        while not paused.exists():
            assert first.poll() is None and time.monotonic() - t0 < 60, first.stderr.read()
            time.sleep(0.05)
        assert_one_line_error(run_cli("tactile-host", *args), 2,
                              f"output {out}: another capture is writing it (it holds d.csv.lock): let it end, or "
                              "choose another -o")
        assert_one_line_error(run_cli("tactile-host", *args, "--temperature", "20,30"), 2, "another capture")
        assert len(data_rows(out)[1]) == 1
        go.touch()
        assert first.wait(timeout=60) == 0, first.stderr.read()
    finally:
        if first.poll() is None:
            first.kill()
            first.wait()
    assert [r[8:] for r in data_rows(out)[1]] == [tuple(map(float, r)) for r in grid_rows()[:4]]
    assert json.loads((tmp_path / "d.csv.meta.json").read_text())["runs"] == 1
    assert not (tmp_path / "d.csv.lock").exists()  # released and removed with the run


def test_one_file_by_two_names_takes_one_lock_and_a_temperature_run_holds_each_file(tmp_path):
    """The lock is the file's, not the name's: a link to a file being captured is refused; a --temperature run
    holds each temperature's file too, so a plain capture into one is another run."""
    from host.capturefile import output_lock

    (tmp_path / "real.csv").write_text("")
    (tmp_path / "link.csv").symlink_to("real.csv")
    with output_lock(tmp_path / "real.csv"):
        with pytest.raises(InputError, match="another capture is writing it"):
            with output_lock(tmp_path / "link.csv"):
                pass
    sched = write_schedule(tmp_path / "s.csv", grid_rows()[:2])
    with output_lock(tmp_path / "cap.T15.csv"):
        assert_one_line_error(run_cli("tactile-host", "capture", "--poses", str(sched), "--adc", TWO_1115, "--simulate",
                                      "--temperature", "15,25", "-o", str(tmp_path / "cap.csv")), 2,
                              "another capture is writing it")


def test_a_stopped_run_says_what_its_files_hold(tmp_path):
    """No file: nothing was written; a header written but no row (stopped at pose 1): no row was captured."""
    from host.capturerun import kept

    out = tmp_path / "d.csv"
    assert kept([out], "kept") == "nothing was written"
    out.write_text("v1,v2,dx\n")
    assert kept([out], "kept") == f"no row was captured ({out}: the header only)"
    out.write_text("v1,v2,dx\n0.1,0.2,1\n")
    assert kept([tmp_path / "other.csv", out], "kept") == "kept"


def test_a_killed_runs_lock_does_not_block_the_next(tmp_path):
    """The kernel drops a killed process's flock: the file it leaves is taken over, then removed."""
    import subprocess
    import sys

    from host.capturefile import output_lock

    out = tmp_path / "d.csv"
    code = (f"import os\nfrom host.capturefile import output_lock\nwith output_lock({str(out)!r}):\n"
            "    os.kill(os.getpid(), 9)")
    assert subprocess.run([sys.executable, "-c", code]).returncode == -9
    assert (tmp_path / "d.csv.lock").exists()
    sched = write_schedule(tmp_path / "s.csv", grid_rows()[:2])
    proc = run_cli("tactile-host", "capture", "--poses", str(sched), "--adc", TWO_1115, "-o", str(out), "--simulate",
                   "--samples", "2")
    assert proc.returncode == 0, proc.stderr
    assert len(data_rows(out)[1]) == 2 and not (tmp_path / "d.csv.lock").exists()
    with output_lock(out):  # held here, as a run in another process holds it
        with pytest.raises(InputError, match="another capture is writing it"):
            with output_lock(out):
                pass
    with output_lock(out):  # released
        pass


def test_a_simulated_capture_resumes_with_its_units_file_by_any_path_and_not_with_another_unit(tmp_path):
    """--sensor is compared as the sensor it loads (its description's hash), not as the text typed: the same unit's
    file by another relative path, or moved, resumes; another unit is refused in one line."""
    from fitgen.physics.sensor import load_sensor
    from fitgen.physics.units import draw_unit, write_unit

    drawing = load_sensor("paper").with_transfer("gmr")
    for seed in (7, 8):
        write_unit(tmp_path / f"unit{seed}.unit.toml", draw_unit(drawing, seed)[0], "paper", {"seed": seed})
    (tmp_path / "sub").mkdir()
    write_schedule(tmp_path / "s.csv", grid_rows()[:6])
    args = ["capture", "--poses", "s.csv", "--adc", TWO_1115, "-o", "d.csv", "--simulate", "--samples", "2"]
    stop_at = ["--trigger", '[ "$TM_POSE_INDEX" -lt {} ]']
    proc = run_cli("tactile-host", *args, "--sensor", "unit7.unit.toml", stop_at[0], stop_at[1].format(3),
                   cwd=tmp_path)
    assert proc.returncode == 1 and len(data_rows(tmp_path / "d.csv")[1]) == 2, proc.stderr
    up = [a.replace("s.csv", "../s.csv").replace("d.csv", "../d.csv") for a in args]
    proc = run_cli("tactile-host", *up, "--sensor", "../unit7.unit.toml", stop_at[0], stop_at[1].format(5),
                   cwd=tmp_path / "sub")
    assert proc.returncode == 1 and "exit status 1 at pose 5/6" in proc.stderr, proc.stderr
    assert len(data_rows(tmp_path / "d.csv")[1]) == 4
    assert_one_line_error(run_cli("tactile-host", *up, "--sensor", "../unit8.unit.toml", cwd=tmp_path / "sub"), 2,
                          "its 4 rows were captured from simulated ../unit7.unit.toml (sensor sha256 ")
    (tmp_path / "unit7.unit.toml").rename(tmp_path / "sub" / "moved.toml")
    proc = run_cli("tactile-host", *up, "--sensor", "moved.toml", cwd=tmp_path / "sub")
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr.strip().splitlines()[0] == ("tactile-host capture: 6/6 poses in ../d.csv (2 captured now, 4 "
                                                   "already there)")
    assert [r[8:] for r in data_rows(tmp_path / "d.csv")[1]] == [tuple(map(float, r)) for r in grid_rows()[:6]]
    meta = json.loads((tmp_path / "d.csv.meta.json").read_text())
    assert meta["runs"] == 3 and meta["sensor_sha256"] == load_sensor(tmp_path / "sub" / "moved.toml").sha256


def test_a_simulated_capture_is_fitted_with_the_sensor_it_was_read_from(tmp_path):
    """A simulated capture records its sensor file's hash as read (paper's: raw), its rows are in volts: fit with
    --sensor paper holds out on it (it was refused as 'sensor None', another sensor); another sensor is refused in
    words that name no None."""
    write_schedule(tmp_path / "s.csv", grid_rows())
    proc = run_cli("tactile-host", "capture", "--poses", "s.csv", "--adc", TWO_1115, "-o", "c.csv", "--simulate",
                   "--sensor", "paper", "--samples", "2", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    proc = run_cli("fitgen", "fit", "c.csv", "--sensor", "paper", "--held-out", "100", "-o", "m.json", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    held = json.loads((tmp_path / "m.json").read_text())["fit"]["held_out"]
    assert held["sensor"] == "paper" and held["transfer"] == "gmr"
    proc = run_cli("fitgen", "fit", "c.csv", "--sensor", "two-rings", "-o", "m2.json", cwd=tmp_path)
    assert_one_line_error(proc, 2, "the dataset was read from another sensor (sha256 ")
    assert "None" not in proc.stderr and not (tmp_path / "m2.json").exists()


def test_capture_averages_as_many_samples_as_the_schedule_was_made_for(tmp_path):
    """`fitgen schedule --samples S` designs its poses for rows averaged over S samples and says so in its meta:
    capture takes S unless --samples says otherwise, and 16 for a schedule that names none."""
    sched = write_schedule(tmp_path / "s.csv", grid_rows()[:2])
    args = ["capture", "--poses", str(sched), "--adc", TWO_1115, "--simulate"]

    def samples_of(out, *extra):
        proc = run_cli("tactile-host", *args, "-o", str(tmp_path / out), *extra)
        assert proc.returncode == 0, proc.stderr
        return json.loads((tmp_path / f"{out}.meta.json").read_text())["samples_per_row"]

    assert samples_of("plain.csv") == 16
    (tmp_path / "s.csv.meta.json").write_text(json.dumps({"samples_per_row": 5, "distinct_poses": 2}))
    assert samples_of("designed.csv") == 5
    assert samples_of("given.csv", "--samples", "3") == 3
    for bad in ("5", 0, 2.5, True, 10 ** 9):
        (tmp_path / "s.csv.meta.json").write_text(json.dumps({"samples_per_row": bad}))
        assert_one_line_error(run_cli("tactile-host", *args, "-o", str(tmp_path / "bad.csv")), 2,
                              f"samples_per_row must be {'at most 10000' if bad == 10 ** 9 else 'a whole number >= 1'}, "
                              f"got {bad!r}; repair it, or give --samples")
        assert not (tmp_path / "bad.csv").exists()
    assert samples_of("given-anyway.csv", "--samples", "2") == 2  # what the user gives is not the meta's to refuse


def test_a_schedule_pose_past_any_sensors_reach_is_refused_before_the_first_row(tmp_path):
    """Its sixth row at dx = 1e308: five rows were captured, then the capture stopped with status 2 beside a partial
    file and its meta."""
    sched = write_schedule(tmp_path / "s.csv", grid_rows()[:5] + [(1e308, 0, -1)])
    proc = run_cli("tactile-host", "capture", "--poses", str(sched), "--adc", TWO_1115, "--simulate", "-o",
                   str(tmp_path / "d.csv"))
    assert_one_line_error(proc, 2, "dx from -2 to 1e+308 mm: a pose box's dx must lie within -1000..1000 mm")
    assert not list(tmp_path.glob("d.csv*"))


@pytest.mark.parametrize("key, bad, said", [
    ("rig_error", float("nan"), "must be 0..0.5 mm"), ("zero_error", 3.0, "must be 0..0.5 mm"),
    ("rig_error", "0.01", "must be 0..0.5 mm"),
    # copied as they were into the meta: check read "yes" as not given, identify a transfer abc as a file changed
    ("rig_error_given", "yes", "must be true or false"), ("transfer", "abc", "must be raw or gmr"),
    ("sensor_sha256", 7, "must be text")])
def test_a_schedule_whose_records_identify_or_check_refuse_is_refused_before_the_capture(tmp_path, key, bad, said):
    """The capture copied them into its meta, and identify refused them only once every row had been taken."""
    sched = write_schedule(tmp_path / "s.csv", grid_rows()[:2])
    (tmp_path / "s.csv.meta.json").write_text(json.dumps({"rig_error": 0.01, "zero_error": 0.02, "sensor": "paper",
                                                          key: bad}))
    proc = run_cli("tactile-host", "capture", "--poses", str(sched), "--adc", TWO_1115, "--simulate", "-o",
                   str(tmp_path / "d.csv"))
    assert_one_line_error(proc, 2, f"s.csv.meta.json: {key} {said}, got {bad!r}; repair")
    assert not (tmp_path / "d.csv").exists()


@pytest.mark.parametrize("extra, message", [
    (["--samples", "0"], "--samples must be a whole number >= 1, got 0"),
    (["--max-spread", "x"], "--max-spread 'x' is not a number"),
    (["--max-spread", "1e308"], "--max-spread must be at most 1000"),
    (["--tries", "99999999999"], "--tries must be at most 100"),
    (["--retries", "1000"], "--retries must be at most 100"),
    (["--adc", "ads1115@0x48:0-3,ads7829@0x49"], "unknown chip 'ads7829'"),
    (["--bus", "99"], "/dev/i2c-99 does not exist"),
    (["--bus", "99", "--seed", "2"], "--seed needs --simulate"),
    (["--simulate", "--bus", "99"], "--bus does not go with --simulate"),
    (["--adc", "ads1115@0x48:0-3"], "the channel map reads 4 elements; the simulated sensor 'paper' has 8: give the "
                                    "sensor file whose elements the map reads (tactile-host's --sensor;"),
])
def test_capture_command_bad_input_is_one_line_exit_2(tmp_path, extra, message):
    sched = write_schedule(tmp_path / "s.csv", grid_rows()[:2])
    args = ["capture", "--poses", str(sched), "--adc", TWO_1115, "-o", str(tmp_path / "d.csv")]
    if "--bus" not in extra:
        args.append("--simulate")
    proc = run_cli("tactile-host", *args, *extra)
    assert_one_line_error(proc, 2, message)
    assert not (tmp_path / "d.csv").exists()


def test_a_capture_named_as_another_kind_of_file_is_refused(tmp_path):
    """capture -o x.json or x.toml wrote CSV under the name of a model or a sensor file (fit and identify, told the
    name, read them as the wrong kind)."""
    write_schedule(tmp_path / "s.csv", grid_rows()[:2])
    for name in ("x.json", "x.TOML"):
        proc = run_cli("tactile-host", "capture", "--poses", "s.csv", "--adc", TWO_1115, "--simulate", "-o", name,
                       cwd=tmp_path)
        assert_one_line_error(proc, 2, f"-o {name}: capture writes rows in CSV: name it .csv (its meta goes beside it)")
    assert sorted(f.name for f in tmp_path.iterdir()) == ["s.csv"]


def test_capture_command_missing_schedule(tmp_path):
    proc = run_cli("tactile-host", "capture", "--poses", str(tmp_path / "none.csv"), "--adc", TWO_1115,
                   "-o", str(tmp_path / "d.csv"), "--simulate")
    assert_one_line_error(proc, 2, "no such file")


@pytest.mark.parametrize("header, said", [("dx,dy,dzz", "unknown column 'dzz' (did you mean dz?)"),
                                          ("dx,dy,DZ", "unknown column 'DZ' (did you mean dz?)"),
                                          ("row,dx,dz", "unknown column 'row'; pose columns are dx,dy,dz,thx,thy")])
def test_a_schedule_column_that_is_no_pose_is_refused_not_held_at_0(tmp_path, header, said):
    """A misspelt dz was dropped: the stage never pressed and the capture said it was done."""
    sched = tmp_path / "s.csv"
    sched.write_text(header + "\n0,0,0\n1,0,-1\n")
    for cmd in (["tactile-host", "capture", "--poses", str(sched), "--adc", TWO_1115, "-o", str(tmp_path / "d.csv"),
                 "--simulate"], ["fitgen", "simulate", "--poses", str(sched), "-o", str(tmp_path / "d.csv")]):
        assert_one_line_error(run_cli(*cmd), 2, said)
        assert not (tmp_path / "d.csv").exists()
    data = tmp_path / "data.csv"  # a dataset's inputs v1.. are passed over: its poses are read
    data.write_text("v1,v2,dx,dz\n1.0,2.0,0.5,-1\n")
    assert load_schedule(data).columns == ("dx", "dz") and load_schedule(data).poses[0, 2] == -1


def test_a_capture_re_saved_with_a_byte_order_mark_resumes(tmp_path):
    """A partial capture opened and saved in a spreadsheet gains a BOM: the resume read its header as '\\ufeffv1,..'
    and refused it as another channel map's."""
    spec = "ads1115@0x48:0-3,ads1115@0x49:0-3"
    assert run_cli("fitgen", "schedule", "--sensor", "paper", "--n", "12", "-o", str(tmp_path / "s.csv")).returncode == 0
    cap = tmp_path / "cap.csv"
    args = ["tactile-host", "capture", "--poses", str(tmp_path / "s.csv"), "--adc", spec, "--simulate", "--samples",
            "2", "-o", str(cap)]
    assert run_cli(*args).returncode == 0
    whole = cap.read_text().splitlines(keepends=True)
    cap.write_bytes(b"\xef\xbb\xbf" + "".join(whole[:6]).encode())
    proc = run_cli(*args)
    assert proc.returncode == 0, proc.stderr
    assert load_dataset(cap).n_rows == len(whole) - 1


def test_a_finished_capture_names_the_next_step_from_its_schedule(tmp_path):
    """A calibration capture: identify, with the drawing its schedule was made for; a check capture (fitgen schedule
    --check): fitgen check (docs/calibration.md, "The workflow")."""
    spec = "ads1115@0x48:0-3,ads1115@0x49:0-3"
    for kind, extra in (("s", ["--n", "12"]), ("c", ["--check", "6"])):
        assert run_cli("fitgen", "schedule", "--sensor", "paper", *extra, "-o", str(tmp_path / f"{kind}.csv")
                       ).returncode == 0
        cap = tmp_path / f"{kind}-cap.csv"
        proc = run_cli("tactile-host", "capture", "--poses", str(tmp_path / f"{kind}.csv"), "--adc", spec,
                       "--simulate", "--samples", "2", "-o", str(cap))
        assert proc.returncode == 0, proc.stderr
        said = proc.stderr.strip().splitlines()[-1]
        assert said == ({"s": f"tactile-host capture: next: fitgen identify {cap} --sensor paper -o "
                              f"{tmp_path / 'unit.toml'} (the unit's physics from these rows)",
                         "c": f"tactile-host capture: next: fitgen check {tmp_path / 'twin.json'} {cap} (the twin's "
                              "model, named as identify's next step names it, on these poses against what identify "
                              "predicts)"}
                        [kind]), said
    # a check capture given to identify: a note that its rows are a check's (they could no longer check the twin)
    assert [json.loads((tmp_path / f"{k}-cap.csv.meta.json").read_text()).get("schedule_check") for k in "sc"] == \
        [None, True]
    proc = run_cli("fitgen", "identify", str(tmp_path / "c-cap.csv"), "-o", str(tmp_path / "c-unit.toml"))
    assert (f"identify: note: {tmp_path / 'c-cap.csv'} was captured on a check schedule (fitgen schedule --check)"
            in proc.stderr), proc.stderr
    # a capture given as the schedule: its poses taken, with a note that its schedule's record is not (identify
    # would take the default drawing and stage errors); a schedule is taken without one
    proc = run_cli("tactile-host", "capture", "--poses", str(tmp_path / "s-cap.csv"), "--adc", spec, "--simulate",
                   "--samples", "2", "-o", str(tmp_path / "again.csv"))
    said = (f"tactile-host capture: note: --poses {tmp_path / 's-cap.csv'} is a capture, not a schedule: its poses "
            f"are taken, but not what its schedule {tmp_path / 's.csv'} recorded")
    assert proc.returncode == 0 and said in proc.stderr, proc.stderr
    assert "note:" not in run_cli("tactile-host", "capture", "--poses", str(tmp_path / "s.csv"), "--adc", spec,
                                  "--simulate", "--samples", "2", "-o", str(tmp_path / "once.csv")).stderr
    # a batch of units in one folder: with a unit.toml there, the next one's own name (it replaced the first's)
    (tmp_path / "unit.toml").write_text("")
    proc = run_cli("tactile-host", "capture", "--poses", str(tmp_path / "s.csv"), "--adc", spec, "--simulate",
                   "--samples", "2", "-o", "u2.csv", cwd=tmp_path)
    assert proc.returncode == 0 and proc.stderr.strip().splitlines()[-1] == (
        "tactile-host capture: next: fitgen identify u2.csv --sensor paper -o u2.unit.toml (the unit's physics from "
        "these rows)"), proc.stderr
    # a unit in its own folder, named with a space: its files beside its capture, quoted for the shell
    (tmp_path / "unit 3").mkdir()
    proc = run_cli("tactile-host", "capture", "--poses", str(tmp_path / "s.csv"), "--adc", spec, "--simulate",
                   "--samples", "2", "-o", "unit 3/u3.csv", cwd=tmp_path)
    assert proc.returncode == 0 and proc.stderr.strip().splitlines()[-1] == (
        "tactile-host capture: next: fitgen identify 'unit 3/u3.csv' --sensor paper -o 'unit 3/unit.toml' (the "
        "unit's physics from these rows)"), proc.stderr


def test_an_earlier_runs_noise_figures_past_any_count_start_anew():
    """A resumed capture pools on from the meta's noise figures; a noise_rows past a float's range (JSON's integers
    have none) raised OverflowError, a traceback, where other damage starts the pool anew."""
    from host.capture import NoiseStats

    figures = {"sample_noise": [5e-4] * 8, "row_noise": [1.25e-4] * 8, "samples_per_row": 16}
    assert NoiseStats.from_meta({"noise_rows": 4, **figures}, 8).rows == 4
    for rows in (10 ** 400, 10 ** 12, 0, "4"):
        assert NoiseStats.from_meta({"noise_rows": rows, **figures}, 8).rows == (4 if rows == "4" else 0)
    # figures no capture writes (1e200's square overflowed, with numpy's warning on the terminal, and Infinity went
    # into the meta; 5 V per sample beside 0.125 mV per row went on into identify's unit): this run's stand alone
    for bad in (1e200, -1.0, float("nan"), 5.0):
        assert NoiseStats.from_meta({"noise_rows": 4, **figures, "sample_noise": [bad] * 8}, 8).rows == 0
    assert NoiseStats.from_meta({"noise_rows": 4, **figures, "samples_per_row": 4}, 8).rows == 0


@pytest.mark.parametrize("edit", [{"runs": 1e400}, {"duration_s": 10 ** 400}, {"duration_s": -1e400},
                                  {"runs": -5}])
def test_a_resume_over_an_earlier_runs_damaged_counts_counts_anew(sensor, tmp_path, edit):
    """The meta's run count and duration, edited past a float's range or below 0: a resume raised OverflowError
    (a traceback) or wrote -Infinity into the meta; it counts anew, as for other damage."""
    sched = load_schedule(write_schedule(tmp_path / "s.csv", grid_rows()[:4]))
    out = tmp_path / "d.csv"
    bus, arr, clock = rig(sensor)
    assert capture(arr, sched, out, samples=2, clock=clock, set_pose=bus.set_pose).captured == 4
    out.write_text("".join(out.read_text().splitlines(keepends=True)[:3]))  # two rows to take again
    meta_file = tmp_path / "d.csv.meta.json"
    meta_file.write_text(json.dumps({**json.loads(meta_file.read_text()), **edit}))
    res = capture(arr, sched, out, samples=2, clock=clock, set_pose=bus.set_pose)
    assert res.complete
    meta = json.loads(meta_file.read_text())
    assert meta["runs"] == 1 and 0 <= meta["duration_s"] < 1e6, meta


@pytest.mark.parametrize("damage, said", [
    ("remove", "no meta (d.csv.meta.json) says what its 2 rows were captured with"),
    ("{\"samples_per_row\": 2,", "the meta of its 2 rows cannot be read (not JSON)"),
    ("[1, 2]", "the meta of its 2 rows is not a JSON object"),
    ("folder", "the meta of its 2 rows cannot be read (")])
def test_a_resume_over_rows_whose_meta_is_lost_or_damaged_is_refused_and_keeps_them(tmp_path, damage, said):
    """Such a resume wrote this run's meta over them, as if its sensor, channels and samples were theirs."""
    sched = write_schedule(tmp_path / "s.csv", grid_rows()[:4])
    out, meta_file = tmp_path / "d.csv", tmp_path / "d.csv.meta.json"
    args = ["capture", "--poses", str(sched), "--adc", TWO_1115, "-o", str(out), "--simulate", "--samples", "2"]
    assert run_cli("tactile-host", *args).returncode == 0
    out.write_text("".join(out.read_text().splitlines(keepends=True)[:3]))  # two rows to take again
    meta_file.unlink()
    if damage == "folder":
        meta_file.mkdir()
    elif damage != "remove":
        meta_file.write_text(damage)
    rows = out.read_text()
    assert_one_line_error(run_cli("tactile-host", *args), 2, f"output {out}: {said}")
    assert out.read_text() == rows
    assert (meta_file.is_dir() if damage == "folder" else
            not meta_file.exists() if damage == "remove" else meta_file.read_text() == damage)


def test_a_simulated_capture_checks_every_pose_before_the_first_row(tmp_path):
    """A schedule pose that drives the magnet through the board was found only when its turn came, after rows were
    written, and called pose 1 (the bus checks one pose at a time); it is refused first, numbered as in the file."""
    sched = tmp_path / "s.csv"
    sched.write_text("dx,dy,dz\n0,0,0.2\n1,1,-1\n3,-3,-39\n1,-1,-1\n")
    proc = run_cli("tactile-host", "capture", "--poses", str(sched), "--adc", TWO_1115, "--simulate", "--samples",
                   "2", "-o", str(tmp_path / "c.csv"))
    assert_one_line_error(proc, 2, f"{sched}: pose 3 (dx=3 dy=-3 dz=-39 thx=0 thy=0) puts the magnet's lowest point")
    assert sorted(f.name for f in tmp_path.iterdir()) == ["s.csv"]
