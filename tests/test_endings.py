"""How a command ends when the world around it does: a disk that fills or a file size limit, a closed stream,
a hang-up, a signal between two renames. One line and a status, never a traceback, nothing half-written."""

from __future__ import annotations

import json
import os
import resource
import signal
import subprocess
import sys

import pytest
from conftest import TWO_CHIPS, assert_one_line_error

TOOLS = {"fitgen": "fitgen.app.cli", "tactile-host": "fitgen.app.host_cli"}


def run_limited(tool, *args, fsize=None, close=(), stdout=subprocess.PIPE):
    """``tool args`` as a subprocess, its files limited to ``fsize`` bytes (EFBIG past it, as a full disk gives
    ENOSPC) and the descriptors ``close`` closed before it starts (the shell's ``>&-``)."""

    def setup():
        signal.signal(signal.SIGHUP, signal.SIG_DFL)  # under nohup the suite ignores it, as nohup asks
        if fsize is not None:
            resource.setrlimit(resource.RLIMIT_FSIZE, (fsize, fsize))
        for fd in close:
            os.close(fd)

    code = f"import sys; from {TOOLS[tool]} import main; sys.argv[0] = {tool!r}; main()"
    # no bytecode written under the limit: CPython writes a .pyc by one raw write, and a short one (EFBIG past the
    # limit is a short write first) is renamed into place whole, to break every later import of that module
    env = dict(os.environ, PYTHONDONTWRITEBYTECODE="1")
    return subprocess.run([sys.executable, "-c", code, *args], stdout=stdout, stderr=subprocess.PIPE, text=True,
                          preexec_fn=setup, timeout=300, env=env)


def test_read_whose_output_file_fills_is_one_line(model_file, tmp_path):
    out = tmp_path / "s.csv"
    proc = run_limited("tactile-host", "read", "--model", model_file, "--adc", TWO_CHIPS, "--simulate", "motion",
                       "--count", "5000", "-o", str(out), fsize=20_000)
    assert_one_line_error(proc, 2, f"tactile-host read: error: cannot write {out}: File too large")
    assert 0 < out.stat().st_size <= 20_000


def test_read_whose_run_record_fills_is_one_line(model_file, tmp_path):
    run = tmp_path / "run.jsonl"
    proc = run_limited("tactile-host", "read", "--model", model_file, "--adc", TWO_CHIPS, "--simulate", "motion",
                       "--count", "5000", "--record", str(run), fsize=60_000)
    assert_one_line_error(proc, 2, f"tactile-host read: error: cannot write {run}: File too large")


def test_a_capture_whose_file_fills_keeps_its_rows_and_says_so_in_one_line(tmp_path):
    sched = tmp_path / "s.csv"
    sched.write_text("dx,dy,dz\n" + "".join(f"{dx},{dy},0\n" for dx in range(-3, 4) for dy in range(-3, 4)))
    out = tmp_path / "d.csv"
    proc = run_limited("tactile-host", "capture", "--poses", str(sched), "--adc", TWO_CHIPS, "-o", str(out),
                       "--simulate", "--samples", "2", fsize=4000)
    assert_one_line_error(proc, 2, f"tactile-host capture: error: cannot write {out}: File too large")
    lines = out.read_text().split("\n")
    assert 3 < len(lines) < 49
    meta = json.loads((tmp_path / "d.csv.meta.json").read_text())  # the meta counts the rows kept
    assert meta["rows"] == sum(1 for ln in lines[1:] if ln) - (not out.read_text().endswith("\n"))


def test_a_closed_standard_output_or_error_is_nowhere_to_write_not_a_traceback(tmp_path):
    """``>&-``: Python starts with sys.stdout (or stderr) None; what would go there goes nowhere, the work is
    done and the status is the command's."""
    proc = run_limited("fitgen", "observe", "--sensor", "paper", close=(1,), stdout=None)
    assert proc.returncode == 0 and "Traceback" not in proc.stderr and "error" not in proc.stderr, proc.stderr
    # stderr closed: the error line is lost (no stream), not printed on stdout where print(file=None) sends it
    proc = run_limited("fitgen", "fit", str(tmp_path / "nothere.csv"), "-o", str(tmp_path / "m.json"), close=(2,))
    assert proc.returncode == 2 and proc.stdout == ""
    out = tmp_path / "d.csv"
    proc = run_limited("fitgen", "simulate", "--random", "5", "-o", str(out), close=(1, 2), stdout=None)
    assert proc.returncode == 0 and out.is_file()


@pytest.mark.parametrize("sig, status, said", [(signal.SIGTERM, 143, "terminated"), (signal.SIGHUP, 129, "hung up")])
def test_a_signal_ends_a_command_cleaned_up_unless_it_is_ignored(capsys, sig, status, said):
    """SIGTERM (timeout, systemd, kill) and SIGHUP (the terminal or ssh session closed) are raised where the
    program is, so that every with-block's cleanup runs: no temporary folder is left, and the status is the
    shell's (128 + the signal). A signal ignored (nohup's SIGHUP) stays ignored."""
    import tempfile
    from pathlib import Path

    from fitgen.app.cliutil import run

    made = []

    def work(argv):
        with tempfile.TemporaryDirectory(prefix="fitgen-test-term-") as tmp:
            made.append(Path(tmp))
            os.kill(os.getpid(), sig)
            for _ in range(1000):  # the handler runs between bytecodes
                pass
        return 0

    before = signal.getsignal(sig)
    try:
        signal.signal(sig, signal.SIG_DFL)  # as a command starts, unless nohup (or another) ignores it
        assert run(work, [], "fitgen") == status
        assert made and not made[0].exists()
        assert capsys.readouterr().err.strip() == f"fitgen: {said}"
        assert signal.getsignal(sig) is signal.SIG_DFL
        signal.signal(sig, signal.SIG_IGN)
        assert run(work, [], "fitgen") == 0 and not made[1].exists()
        assert capsys.readouterr().err == ""
        assert signal.getsignal(sig) is signal.SIG_IGN
    finally:
        signal.signal(sig, before)


@pytest.mark.parametrize("name, status, said", [("INT", 130, "interrupted"), ("TERM", 143, "terminated"),
                                                ("HUP", 129, "hung up")])
def test_a_capture_stopped_by_a_signal_keeps_its_rows_and_says_which(tmp_path, name, status, said):
    sched = tmp_path / "s.csv"
    sched.write_text("dx,dy,dz\n" + "".join(f"{dx},0,0\n" for dx in range(5)))
    out = tmp_path / "d.csv"
    proc = run_limited("tactile-host", "capture", "--poses", str(sched), "--adc", TWO_CHIPS, "-o", str(out),
                       "--simulate", "--samples", "2", "--trigger",
                       f'if [ "$TM_POSE_INDEX" = 3 ]; then kill -{name} $PPID; sleep 5; fi')
    assert proc.returncode == status, proc.stderr
    assert proc.stderr.strip() == (f"tactile-host capture: {said}; the rows written so far are kept in {out}: "
                                   "run the same command again to resume")
    assert len(out.read_text().splitlines()) == 3


def test_write_all_finishes_its_renames_before_a_signal_that_comes_between_them(tmp_path, monkeypatch):
    """A Ctrl-C between two renames is delivered after the last: every file new (and the command ends as
    interrupted), never a new file beside an old one."""
    import fitgen.base.fileio as fileio

    real = os.replace
    calls = []

    def replace_then_ctrl_c(src, dst):
        real(src, dst)
        calls.append(dst)
        if len(calls) == 1:
            os.kill(os.getpid(), signal.SIGINT)
            for _ in range(1000):  # where the handler would run
                pass

    monkeypatch.setattr(fileio.os, "replace", replace_then_ctrl_c)
    for name in ("a.csv", "a.csv.meta.json"):
        (tmp_path / name).write_text("old")
    with pytest.raises(KeyboardInterrupt):
        fileio.write_all([(tmp_path / "a.csv", "new"), (tmp_path / "a.csv.meta.json", "new")])
    assert len(calls) == 2
    assert [(tmp_path / n).read_text() for n in ("a.csv", "a.csv.meta.json")] == ["new", "new"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.csv", "a.csv.meta.json"]


def test_schedule_writes_its_poses_and_its_meta_both_or_neither(tmp_path):
    """A meta that cannot be written leaves no schedule without one (capture would take it for another kind)."""
    from conftest import run_cli

    (tmp_path / "s.csv.meta.json").mkdir()
    proc = run_cli("fitgen", "schedule", "--sensor", "paper", "-o", str(tmp_path / "s.csv"))
    assert_one_line_error(proc, 2, "s.csv.meta.json")
    assert not (tmp_path / "s.csv").exists()


def test_schedule_refuses_to_write_over_the_noise_file_it_reads(tmp_path):
    from conftest import run_cli

    noise = tmp_path / "noise.json"
    assert run_cli("tactile-host", "noise", "--adc", TWO_CHIPS, "--simulate", "--seconds", "1", "-o",
                   str(noise)).returncode == 0
    before = noise.read_bytes()
    proc = run_cli("fitgen", "schedule", "--sensor", "paper", "--samples", str(noise), "-o", str(noise))
    assert_one_line_error(proc, 2, f"-o {noise} is the input {noise}")
    assert noise.read_bytes() == before


@pytest.mark.parametrize("levels", [[], ["--temperature", "20,30"]])
def test_a_finished_capture_run_again_leaves_its_meta_as_it_was(tmp_path, levels):
    """A run with nothing left to capture (every temperature's level done) is no run: no meta counts it."""
    from conftest import run_cli

    sched = tmp_path / "s.csv"
    sched.write_text("dx,dy,dz\n0,0,0\n1,0,0\n")
    args = ["capture", "--poses", str(sched), "--adc", TWO_CHIPS, "-o", str(tmp_path / "d.csv"), "--simulate",
            "--samples", "2", *levels]
    assert run_cli("tactile-host", *args).returncode == 0
    metas = sorted(tmp_path.glob("*.meta.json"))
    assert len(metas) == (2 if levels else 1)
    before = [m.read_bytes() for m in metas]
    proc = run_cli("tactile-host", *args)
    assert proc.returncode == 0, proc.stderr
    assert [m.read_bytes() for m in metas] == before and all(json.loads(m)["runs"] == 1 for m in before)


def test_a_capture_refused_its_output_leaves_the_meta_as_it_was(sensor, tmp_path, monkeypatch):
    """An output that cannot be appended to (read-only, to a user other than root) is refused before the meta
    is touched: an earlier run's meta kept byte for byte, none made where there was none."""
    import host.capturefile as capture_mod
    from fitgen.base.errors import InputError
    from host.capture import capture, load_schedule
    from test_capture import rig

    def refused(path, append=False):
        raise InputError(f"cannot append to {path}: Permission denied")

    sched_path = tmp_path / "s.csv"
    sched_path.write_text("dx,dy,dz\n0,0,0\n1,0,0\n")
    sched = load_schedule(sched_path)
    bus, arr, clock = rig(sensor)
    out = tmp_path / "d.csv"
    capture(arr, load_schedule(sched_path), out, samples=2, set_pose=bus.set_pose, clock=clock)
    meta = (tmp_path / "d.csv.meta.json").read_bytes()
    sched_path.write_text("dx,dy,dz\n0,0,0\n1,0,0\n2,0,0\n")  # one pose more to capture
    monkeypatch.setattr(capture_mod, "open_output", refused)
    with pytest.raises(InputError, match="Permission denied"):
        capture(arr, load_schedule(sched_path), out, samples=2, set_pose=bus.set_pose, clock=clock)
    assert (tmp_path / "d.csv.meta.json").read_bytes() == meta
    other = tmp_path / "e.csv"
    with pytest.raises(InputError, match="Permission denied"):
        capture(arr, sched, other, samples=2, set_pose=bus.set_pose, clock=clock)
    assert not (tmp_path / "e.csv.meta.json").exists()


def test_codegen_whose_header_cannot_be_written_leaves_no_folder(model_file, tmp_path):
    folder = tmp_path / "new" / "gen"
    proc = run_limited("fitgen", "codegen", model_file, "-o", str(folder), fsize=200)
    assert_one_line_error(proc, 2, "File too large")
    assert not (tmp_path / "new").exists()


def test_a_pi_build_that_fails_names_the_generated_file_not_its_staging_copy(model_file, tmp_path):
    """The compiler's line names the source it was given, the staged copy, which goes with the failed build: said
    by the generated file's name."""
    from conftest import run_cli

    cc = tmp_path / "badcc"
    cc.write_text('#!/bin/sh\nfor a; do case "$a" in *tm_pi.c) echo "$a:1:1: error: no luck" >&2;; esac; done\n'
                  "exit 1\n")
    cc.chmod(0o755)
    out = tmp_path / "pi"
    proc = run_cli("tactile-host", "pi-build", "--model", model_file, "--adc", TWO_CHIPS, "--cc", str(cc), "-o",
                   str(out))
    assert_one_line_error(proc, 2, "building the Pi program failed: tm_pi.c:1:1: error: no luck")
    assert ".partial" not in proc.stderr and not out.exists()


def test_a_signal_whose_handler_runs_as_the_handlers_go_back_leaves_none_of_write_all_s_installed(tmp_path,
                                                                                                  monkeypatch):
    """signal.signal runs a pending handler before it swaps, and raises its exception without swapping: each
    handler is put back all the same, and the exception comes after (a later SIGTERM or hang-up still ends the
    command, not a handler of write_all's that drops it)."""
    import fitgen.base.fileio as fileio
    import fitgen.base.signals as signals

    real = signal.signal
    before = {s: signal.getsignal(s) for s in signals.HELD_SIGNALS}
    swaps = []

    def swap_once_interrupted(sig, handler):
        swaps.append(sig)
        if len(swaps) == len(before) + 2:  # the second handler put back: a Ctrl-C's handler runs first
            raise KeyboardInterrupt
        return real(sig, handler)

    monkeypatch.setattr(signals.signal, "signal", swap_once_interrupted)
    with pytest.raises(KeyboardInterrupt):
        fileio.write_all([(tmp_path / "a.csv", "new"), (tmp_path / "a.csv.meta.json", "new")])
    assert {s: signal.getsignal(s) for s in signals.HELD_SIGNALS} == before
    assert (tmp_path / "a.csv").read_text() == "new" == (tmp_path / "a.csv.meta.json").read_text()


def _gone(pid: int) -> bool:
    """Whether process ``pid`` has ended (absent, or a zombie its new parent has not reaped yet)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] == "Z"
    except FileNotFoundError:
        return True


@pytest.mark.parametrize("cut", ["timeout", "ctrl-c"])
def test_a_tool_cut_short_gets_sigterm_to_clean_up_and_its_children_end_with_it(tmp_path, cut):
    """A compiler interrupted (Ctrl-C, a signal, its time limit) by subprocess.run got SIGKILL at once and left its
    temporary files (gcc's cc*.s in $TMPDIR); run_captured sends SIGTERM to the tool's whole process group first,
    so a shell's trap runs, and the child it started (gcc's cc1) ends too."""
    import threading
    import time

    from fitgen.base.children import run_captured

    script = (f"trap 'touch {tmp_path}/cleaned; exit 1' TERM; sleep 60 & echo $! > {tmp_path}/child; "
              f"touch {tmp_path}/started; wait")
    if cut == "timeout":
        with pytest.raises(subprocess.TimeoutExpired):
            run_captured(["sh", "-c", script], timeout=1.0)
    else:
        def interrupt():
            while not (tmp_path / "started").exists():
                time.sleep(0.01)
            os.kill(os.getpid(), signal.SIGINT)  # as a terminal's Ctrl-C reaches this process

        threading.Thread(target=interrupt, daemon=True).start()
        with pytest.raises(KeyboardInterrupt):
            run_captured(["sh", "-c", script], timeout=60)
    assert (tmp_path / "cleaned").exists()
    child = int((tmp_path / "child").read_text())
    deadline = time.monotonic() + 5
    while not _gone(child) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert _gone(child)
    # and a tool that ends by itself answers as subprocess.run does
    done = run_captured(["sh", "-c", "read x; echo out $x; echo err >&2; exit 3"], input="in\n")
    assert (done.returncode, done.stdout, done.stderr) == (3, "out in\n", "err\n")


def test_a_build_of_the_generated_c_that_fails_leaves_no_folder(model_file, tmp_path, monkeypatch):
    """tactile-host verify's build in a temporary folder: a compiler that fails (or a Ctrl-C during it, which ends
    the same way) removed the folder only when the garbage collector got to it, and never when the signal then
    ended the process; the folder goes with the failure now."""
    import tempfile

    from fitgen.base.errors import InputError
    from fitgen.c.compiled import CompiledModel
    from fitgen.equations.model import load_model

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    try:
        CompiledModel(load_model(model_file), "float", cc="false")
    except InputError as exc:
        failure = exc  # held, as a command's error handler holds it while it says it and ends
    assert "failed on the generated code" in str(failure)
    assert list(tmp_path.iterdir()) == []
    with CompiledModel(load_model(model_file), "float") as built:  # and a build that succeeds keeps it until closed
        assert built.binary.is_file() and built.dir.parent == tmp_path
    assert list(tmp_path.iterdir()) == []
