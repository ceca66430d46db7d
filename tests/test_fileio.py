"""fitgen.base.fileio: what an output path may be. A device, FIFO or socket is refused, not replaced by a file; a
symlink is written through, the link kept."""

from __future__ import annotations

import argparse
import os
import re
import socket
import stat
import subprocess
import sys
import types
from contextlib import contextmanager

import pytest
from conftest import TWO_CHIPS, assert_one_line_error, run_cli

from fitgen.base.errors import InputError
from fitgen.base.fileio import check_folder, open_output, output_file, write_atomic, write_in_folder


@contextmanager
def fifo(path):
    """A FIFO at ``path`` with its read end held open, so that code which wrongly opens it to write does not block."""
    os.mkfifo(path)
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
    try:
        yield path
    finally:
        os.close(fd)


@contextmanager
def unix_socket(path):
    sock = socket.socket(socket.AF_UNIX)
    sock.bind(str(path))
    try:
        yield path
    finally:
        sock.close()


def null_device(path):
    if os.geteuid() != 0:
        pytest.skip("os.mknod of a device needs root (CI runs as root)")
    try:
        os.mknod(path, 0o600 | stat.S_IFCHR, os.makedev(1, 3))  # /dev/null's numbers: harmless if written
    except PermissionError:
        pytest.skip("os.mknod of a device needs CAP_MKNOD, which this container's root lacks")
    return path


def leftovers(folder):
    return sorted(p.name for p in folder.iterdir() if p.name.endswith(".tmp"))


WRITERS = {
    "output_file": lambda p: output_file(p),
    "write_atomic": lambda p: write_atomic(p, "new\n"),
    "open_output": lambda p: os.close(open_output(p)),
    "open_output append": lambda p: os.close(open_output(p, append=True)),
}


@pytest.mark.parametrize("writer", WRITERS)
def test_a_fifo_is_refused_and_stays_a_fifo(tmp_path, writer):
    with fifo(tmp_path / "pipe") as path:
        with pytest.raises(InputError, match=r"^cannot write .*pipe: it is a FIFO \(named pipe\), not a file; "):
            WRITERS[writer](path)
        assert stat.S_ISFIFO(os.lstat(path).st_mode)
    assert leftovers(tmp_path) == []


@pytest.mark.parametrize("writer", WRITERS)
def test_a_device_node_is_refused_and_stays_a_device(tmp_path, writer):
    path = null_device(tmp_path / "null")
    with pytest.raises(InputError, match=r"^cannot write .*null: it is a character device, not a file; give a file"):
        WRITERS[writer](path)
    assert stat.S_ISCHR(os.lstat(path).st_mode)
    assert leftovers(tmp_path) == []


@pytest.mark.parametrize("argv", [["fit", "/dev/zero", "-o", "m.json"], ["simulate", "--poses", "/dev/zero", "-o", "d.csv"],
                                  ["schedule", "--samples", "/dev/zero.json", "-o", "s.csv"]])
def test_an_endless_device_as_an_input_is_one_line_not_all_memory(tmp_path, argv):
    """/dev/zero given for a dataset, a pose file or a noise record was read to its end, which it has not, until
    the memory ran out; a pipe, which ends, still reads."""
    if argv[2] == "/dev/zero.json":
        os.symlink("/dev/zero", tmp_path / "zero.json")
        argv = [*argv[:2], "zero.json", *argv[3:]]
    proc = run_cli("fitgen", *argv, cwd=tmp_path)
    assert_one_line_error(proc, 2, "a character device, not a file")
    assert os.listdir(tmp_path) in ([], ["zero.json"])
    ok = run_cli("fitgen", "simulate", "--poses", "/dev/stdin", "-o", "d.csv", input="dx,dz\n0.5,-1\n", cwd=tmp_path)
    assert ok.returncode == 0, ok.stderr


@pytest.mark.parametrize("writer", WRITERS)
def test_a_socket_is_refused(tmp_path, writer):
    with unix_socket(tmp_path / "sock") as path:
        with pytest.raises(InputError, match="it is a socket, not a file"):
            WRITERS[writer](path)
        assert stat.S_ISSOCK(os.lstat(path).st_mode)


@pytest.mark.parametrize("writer", WRITERS)
def test_a_symlink_to_a_fifo_is_refused_and_kept(tmp_path, writer):
    with fifo(tmp_path / "pipe"):
        (tmp_path / "link").symlink_to("pipe")
        with pytest.raises(InputError, match=r"link: it is a symlink to pipe, a FIFO \(named pipe\), not a file"):
            WRITERS[writer](tmp_path / "link")
        assert os.readlink(tmp_path / "link") == "pipe" and stat.S_ISFIFO(os.lstat(tmp_path / "pipe").st_mode)


def test_write_in_folder_refuses_what_is_in_the_way_and_says_the_folder_was_right(tmp_path):
    """The user named the folder; the file's name is the tool's: the advice is to clear the way, not to name a file."""
    with fifo(tmp_path / "model.h"):
        with pytest.raises(InputError, match="a FIFO \\(named pipe\\) of that name is in the way; move it or give "
                                             "another folder"):
            write_in_folder(tmp_path, "model.h", "x")
        assert stat.S_ISFIFO(os.lstat(tmp_path / "model.h").st_mode)
    (tmp_path / "sub" / "model.h").mkdir(parents=True)
    with pytest.raises(InputError, match="model.h: a folder of that name is in the way") as info:
        write_in_folder(tmp_path / "sub", "model.h", "x")
    assert "give a file's path" not in str(info.value) and not os.listdir(tmp_path / "sub" / "model.h")
    assert write_in_folder(tmp_path / "new" / "deeper", "model.h", "x").read_text() == "x"


def test_write_atomic_writes_through_a_symlink_and_keeps_it(tmp_path):
    (tmp_path / "data").mkdir()
    (tmp_path / "data" / "real.csv").write_text("old\n")
    (tmp_path / "link.csv").symlink_to("data/real.csv")
    assert output_file(tmp_path / "link.csv") == tmp_path / "link.csv"
    assert write_atomic(tmp_path / "link.csv", "new\n") == tmp_path / "link.csv"
    assert os.readlink(tmp_path / "link.csv") == "data/real.csv"
    assert (tmp_path / "data" / "real.csv").read_text() == "new\n"
    assert leftovers(tmp_path) == leftovers(tmp_path / "data") == []


def test_write_atomic_through_a_dangling_symlink_makes_the_file_it_names(tmp_path):
    (tmp_path / "data").mkdir()
    (tmp_path / "link.csv").symlink_to("data/new.csv")
    output_file(tmp_path / "link.csv")
    write_atomic(tmp_path / "link.csv", "new\n")
    assert os.readlink(tmp_path / "link.csv") == "data/new.csv"
    assert (tmp_path / "data" / "new.csv").read_text() == "new\n"
    assert leftovers(tmp_path) == leftovers(tmp_path / "data") == []


@pytest.mark.parametrize("writer", WRITERS)
def test_a_link_to_an_open_descriptor_is_refused_and_its_file_kept(tmp_path, writer):
    """/dev/stdout redirected to a file leads there through /proc/self/fd: that file (a log the shell appends to)
    is not replaced; a link to the descriptor's link is refused the same way."""
    log = tmp_path / "log.txt"
    log.write_text("kept\n")
    with open(log, "a") as fh:
        (tmp_path / "out").symlink_to(f"/proc/self/fd/{fh.fileno()}")
        (tmp_path / "out2").symlink_to(tmp_path / "out")
        for name in ("out", "out2", f"/dev/fd/{fh.fileno()}", f"/proc/self/fd/{fh.fileno()}"):
            with pytest.raises(InputError, match="leads to an open file descriptor"):
                WRITERS[writer](tmp_path / name)
    assert log.read_text() == "kept\n" and os.path.islink(tmp_path / "out")


def test_a_path_under_a_file_or_a_missing_folder_is_said_as_before(tmp_path):
    (tmp_path / "file").write_text("x")
    for writer in WRITERS.values():
        with pytest.raises(InputError, match=r"file/x.csv: .*file is a file, not a folder$"):
            writer(tmp_path / "file" / "x.csv")
        with pytest.raises(InputError, match="no/x.csv: folder .*no does not exist$"):
            writer(tmp_path / "no" / "x.csv")


def test_symlinks_in_a_loop_are_one_line(tmp_path):
    (tmp_path / "a").symlink_to("b")
    (tmp_path / "b").symlink_to("a")
    for writer in WRITERS.values():
        with pytest.raises(InputError, match="cannot write .*a: Too many levels of symbolic links"):
            writer(tmp_path / "a")
    assert os.readlink(tmp_path / "a") == "b"


def test_open_output_writes_a_file_in_place_and_through_a_symlink(tmp_path):
    (tmp_path / "rows.csv").write_text("old header\n")
    (tmp_path / "link.csv").symlink_to("rows.csv")
    with os.fdopen(open_output(tmp_path / "link.csv", append=True), "w") as fh:
        fh.write("row\n")
    assert (tmp_path / "rows.csv").read_text() == "old header\nrow\n"
    with os.fdopen(open_output(tmp_path / "link.csv"), "w") as fh:  # emptied, not appended to
        fh.write("new\n")
    assert (tmp_path / "rows.csv").read_text() == "new\n" and os.path.islink(tmp_path / "link.csv")
    with os.fdopen(open_output(tmp_path / "fresh.csv"), "w") as fh:
        fh.write("x\n")
    assert (tmp_path / "fresh.csv").read_text() == "x\n"
    with pytest.raises(InputError, match="cannot append to .*missing.csv: No such file"):
        open_output(tmp_path / "missing.csv", append=True)


def test_a_capture_a_run_record_and_a_pose_file_refuse_a_fifo(tmp_path):
    import numpy as np

    from host.capture import Schedule
    from host.capturefile import RowWriter, prepare_output
    from host.session import ReadoutSession
    from host.stageserver import PoseFile

    with fifo(tmp_path / "rows.csv") as path:
        for write in (False, True):  # the check before the capture, then the capture's own
            with pytest.raises(InputError, match="it is a FIFO"):
                prepare_output(path, 8, Schedule(np.zeros((2, 5)), ("dz",)), write=write)
        with pytest.raises(InputError, match="it is a FIFO"):
            RowWriter(path)
        with pytest.raises(InputError, match="it is a FIFO"):
            ReadoutSession.record(types.SimpleNamespace(), path)  # refused before the session is looked at
        with pytest.raises(InputError, match="it is a FIFO"):
            PoseFile(path)
        assert stat.S_ISFIFO(os.lstat(path).st_mode)
    (tmp_path / "pose.txt").symlink_to("real.txt")
    PoseFile(tmp_path / "pose.txt").set_pose([1, 2, -1, 0, 0])
    assert os.readlink(tmp_path / "pose.txt") == "real.txt"
    assert (tmp_path / "real.txt").read_text() == "1.0,2.0,-1.0,0.0,0.0\n"


def test_a_pose_file_interrupted_between_its_write_and_rename_keeps_the_last_pose_and_no_temporary(tmp_path,
                                                                                                   monkeypatch):
    """stage-sim's pose file: a signal after the temporary's write left a stray .pose.txt.PID.tmp beside it."""
    from host import stageserver

    pose = stageserver.PoseFile(tmp_path / "pose.txt")
    pose.set_pose([1, 2, -1, 0, 0])

    def interrupted(src, dst):
        raise KeyboardInterrupt

    monkeypatch.setattr(stageserver.os, "replace", interrupted)
    with pytest.raises(KeyboardInterrupt):
        pose.set_pose([3, 0, 0, 0, 0])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["pose.txt"]
    assert (tmp_path / "pose.txt").read_text() == "1.0,2.0,-1.0,0.0,0.0\n"

    def immutable(src, dst):  # chattr +i, or a read-only mount: stage-sim ended in PermissionError's traceback
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(stageserver.os, "replace", immutable)
    with pytest.raises(InputError, match="^cannot write .*pose.txt: Operation not permitted$"):
        pose.set_pose([3, 0, 0, 0, 0])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["pose.txt"]


def test_two_outputs_naming_one_file_through_a_symlink_are_refused(tmp_path):
    from fitgen.app.cliutil import check_written

    def cmd(args):
        pass

    (tmp_path / "link.csv").symlink_to("out.csv")
    args = argparse.Namespace(func=cmd, output=str(tmp_path / "out.csv"), record=str(tmp_path / "link.csv"))
    with pytest.raises(InputError, match="-o and --record name the same file"):
        check_written(args, files=(cmd,))


def test_check_folder_probes_what_permissions_do_not_tell(tmp_path):
    if not os.path.isdir("/proc/self"):
        pytest.skip("no /proc")
    with pytest.raises(InputError, match=r"^cannot create /proc/x/y: /proc takes no new folder"):
        check_folder("/proc/x/y")  # root passes os.access there, yet /proc takes no folder
    with fifo(tmp_path / "pipe"):
        with pytest.raises(InputError, match=r"-o .*pipe: it is a FIFO \(named pipe\); give a folder"):
            check_folder(tmp_path / "pipe")
    (tmp_path / "dangling").symlink_to("nowhere")
    with pytest.raises(InputError, match="dangling is not a folder"):
        check_folder(tmp_path / "dangling" / "sub")
    assert check_folder(tmp_path / "new" / "sub") == tmp_path / "new" / "sub"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dangling", "pipe"]  # nothing made, no probe left


def test_simulate_to_a_fifo_is_one_line_before_the_work(tmp_path):
    with fifo(tmp_path / "out.csv") as path:
        proc = run_cli("fitgen", "simulate", "--random", "5", "-o", str(path))
        assert_one_line_error(proc, 2, "it is a FIFO (named pipe), not a file; give a file's path")
        assert stat.S_ISFIFO(os.lstat(path).st_mode)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.csv"]  # no out.csv.meta.json


def test_a_dataset_and_its_meta_are_written_both_or_neither(tmp_path):
    """A meta that cannot be written leaves no CSV behind, which fit would read as measured data, nor an old
    one replaced."""
    (tmp_path / "old.csv").write_text("old\n")
    with fifo(tmp_path / "old.csv.meta.json"), fifo(tmp_path / "new.csv.meta.json"):
        for name in ("old.csv", "new.csv"):
            proc = run_cli("fitgen", "simulate", "--random", "5", "-o", str(tmp_path / name))
            assert_one_line_error(proc, 2, f"{name}.meta.json: it is a FIFO (named pipe)")
    assert (tmp_path / "old.csv").read_text() == "old\n" and not (tmp_path / "new.csv").exists()
    assert leftovers(tmp_path) == []


def test_simulate_through_a_symlink_writes_the_file_and_keeps_the_link(tmp_path):
    (tmp_path / "real.csv").write_text("old\n")
    (tmp_path / "link.csv").symlink_to("real.csv")
    proc = run_cli("fitgen", "simulate", "--random", "5", "-o", str(tmp_path / "link.csv"))
    assert proc.returncode == 0, proc.stderr
    assert os.readlink(tmp_path / "link.csv") == "real.csv"
    assert (tmp_path / "real.csv").read_text().startswith("v1,")


def test_files_beside_an_output_go_beside_the_file_a_link_leads_to(tmp_path):
    """A dataset written through a link has its meta beside the file written, read back by either name."""
    from fitgen.physics.dataset import load_dataset, meta_path

    (tmp_path / "runs").mkdir()
    assert run_cli("fitgen", "simulate", "--grid", "dx=0,1", "-o", str(tmp_path / "runs" / "real.csv")).returncode == 0
    (tmp_path / "latest.csv").symlink_to("runs/real.csv")
    proc = run_cli("fitgen", "simulate", "--sensor", "ring-vertical", "--grid", "dx=0,1,2", "-o",
                   str(tmp_path / "latest.csv"))
    assert proc.returncode == 0, proc.stderr
    assert meta_path(tmp_path / "latest.csv") == meta_path(tmp_path / "runs" / "real.csv")
    assert not (tmp_path / "latest.csv.meta.json").exists()
    for name in ("latest.csv", "runs/real.csv"):
        ds = load_dataset(tmp_path / name)
        assert ds.n_rows == 3 and ds.meta["sensor"] == "ring-vertical", name


def test_ctrl_c_while_writing_leaves_no_temporary_and_no_folder(tmp_path, monkeypatch):
    from fitgen.base.fileio import write_all

    def interrupted(fd):
        raise KeyboardInterrupt

    monkeypatch.setattr(os, "fsync", interrupted)
    (tmp_path / "old.txt").write_text("old")
    with pytest.raises(KeyboardInterrupt):
        write_all([(tmp_path / "new" / "a.png", b"a"), (tmp_path / "old.txt", "new")])
    with pytest.raises(KeyboardInterrupt):
        write_atomic(tmp_path / "old.txt", "new")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["old.txt"] and (tmp_path / "old.txt").read_text() == "old"


def test_a_dash_is_stdout_where_the_command_writes_there_and_refused_elsewhere(model_file, tmp_path):
    """`-o -` is the command's stdout where -o left out is (read, report); elsewhere, and for --record, it is one
    line, never a file named '-' in the working folder."""
    sim = ("--adc", TWO_CHIPS, "--simulate", "dx=1", "--count", "3")
    proc = run_cli("tactile-host", "read", "--model", model_file, *sim, "-o", "-", cwd=tmp_path)
    assert proc.returncode == 0 and len(proc.stdout.splitlines()) == 4, proc.stdout + proc.stderr
    proc = run_cli("fitgen", "report", model_file, "-o", "-", cwd=tmp_path)
    assert proc.returncode == 0 and proc.stdout.startswith("## Report"), proc.stderr
    run = tmp_path / "run.jsonl"
    assert run_cli("tactile-host", "read", "--model", model_file, *sim, "--record", str(run), "-o",
                   str(tmp_path / "s.csv")).returncode == 0
    assert_one_line_error(run_cli("tactile-host", "replay", str(run), "-o", "-", cwd=tmp_path), 2,
                          "-o -: give a file name")
    assert_one_line_error(run_cli("tactile-host", "read", "--model", model_file, *sim, "--record", "-",
                                  cwd=tmp_path), 2, "--record -: give a file name")
    # codegen's -o is the folder it writes its header into
    assert_one_line_error(run_cli("fitgen", "codegen", model_file, "-o", "-", cwd=tmp_path), 2,
                          "-o -: give a folder name")
    assert not (tmp_path / "-").exists()


def test_a_run_record_is_not_written_over_by_another_kind(model_file, tmp_path):
    """A recorded run (the only input replay takes, not to be taken again on hardware) was replaced by read's CSV
    stream or a noise record, and a unit's TOML by a run record, each with exit 0."""
    sim = ("--adc", TWO_CHIPS, "--simulate", "dx=1", "--count", "3")
    run, unit = tmp_path / "run.jsonl", tmp_path / "unit.toml"
    assert run_cli("tactile-host", "read", "--model", model_file, *sim, "--record", str(run), "-o",
                   str(tmp_path / "s.csv")).returncode == 0
    kept = run.read_bytes()
    assert_one_line_error(run_cli("tactile-host", "read", "--model", model_file, *sim, "--format", "jsonl", "-o",
                                  str(run)), 2, f"-o {run} is a run record")
    assert_one_line_error(run_cli("tactile-host", "noise", "--adc", TWO_CHIPS, "--simulate", "--seconds", "1", "-o",
                                  str(run)), 2, "noise would write a noise record over it")
    assert run.read_bytes() == kept
    unit.write_text("kept")
    assert_one_line_error(run_cli("tactile-host", "read", "--model", model_file, *sim, "--record", str(unit)), 2,
                          "the run record is JSONL")
    assert unit.read_text() == "kept"
    # replay's -o is a run record too: named .toml it replaced a channel map or a unit file
    assert_one_line_error(run_cli("tactile-host", "replay", str(run), "-o", str(unit)), 2,
                          "replay writes a run record in JSONL")
    assert unit.read_text() == "kept"
    # a run recorded again over its own name, and replay's record, are the same kind: written as before
    assert run_cli("tactile-host", "read", "--model", model_file, *sim, "--record", str(run), "-o",
                   str(tmp_path / "s.csv")).returncode == 0
    assert run_cli("tactile-host", "replay", str(run), "-o", str(tmp_path / "again.jsonl")).returncode == 0


def test_make_folder_names_the_file_in_its_way(tmp_path):
    from fitgen.base.fileio import make_folder

    (tmp_path / "afile").write_text("x")
    for folder in (tmp_path / "afile", tmp_path / "afile" / "sub"):
        with pytest.raises(InputError, match=f"^cannot create {re.escape(str(folder))}: "
                                             f"{re.escape(str(tmp_path / 'afile'))} is a file; give a folder$"):
            make_folder(folder)
    assert (tmp_path / "afile").read_text() == "x"


def test_a_name_ending_in_a_slash_asks_for_a_folder_and_writes_no_file(tmp_path):
    """Path drops a trailing slash: `-o new/` had written a file named `new`."""
    with pytest.raises(InputError, match=r"^cannot write .*new/: a name ending in / is a folder's; give a file name$"):
        output_file(str(tmp_path / "new") + "/")
    assert list(tmp_path.iterdir()) == []


def test_an_input_named_with_a_slash_is_still_told_from_the_output(tmp_path):
    """The loaders read `data.csv/` as data.csv; samefile on the string raised NotADirectoryError (a traceback)."""
    (tmp_path / "d.csv").write_text("x\n")
    (tmp_path / "out.csv").write_text("old\n")
    assert output_file(tmp_path / "out.csv", inputs=[str(tmp_path / "d.csv") + "/"]) == tmp_path / "out.csv"
    with pytest.raises(InputError, match="is the input"):
        output_file(tmp_path / "d.csv", inputs=[str(tmp_path / "d.csv") + "/"])


def test_a_folder_named_in_a_removed_working_folder_is_one_line(tmp_path, monkeypatch):
    gone = tmp_path / "gone"
    gone.mkdir()
    monkeypatch.chdir(gone)
    gone.rmdir()
    with pytest.raises(InputError, match=r"^cannot create out: the working folder is gone .*give an absolute path$"):
        check_folder("out")
    assert check_folder(tmp_path / "out") == tmp_path / "out"


def test_a_replaced_file_keeps_its_mode_and_a_new_one_follows_the_umask(tmp_path, model_file):
    """A calibration kept private (0600) stayed private only until the first rewrite; a new file was 0644
    whatever the umask."""
    private = tmp_path / "private.csv"
    private.write_text("old\n")
    private.chmod(0o600)
    write_atomic(private, "new\n")
    assert stat.S_IMODE(private.stat().st_mode) == 0o600 and private.read_text() == "new\n"
    for mask, mode in ((0o077, 0o600), (0o002, 0o664), (0o022, 0o644)):
        out = tmp_path / f"umask{mask:03o}"
        proc = subprocess.run([sys.executable, "-c", "from fitgen.app.cli import main; main()", "codegen", model_file,
                               "-o", str(out)],
                              capture_output=True, text=True, umask=mask, timeout=120)
        assert proc.returncode == 0, proc.stderr
        assert stat.S_IMODE((out / "tm_model.h").stat().st_mode) == mode, (oct(mask), proc.stderr)
        assert stat.S_IMODE(out.stat().st_mode) == 0o777 & ~mask


@pytest.mark.parametrize("length", [241, 250, 255])
def test_a_legal_name_up_to_the_file_system_s_255_bytes_is_written(tmp_path, length):
    """The temporary beside it adds 14 bytes to the name: one of 242-255 bytes had been refused as too long."""
    name = "é" * ((length - 4) // 2) + "b" * ((length - 4) % 2) + ".csv"  # two-byte letters: bytes are counted
    assert len(os.fsencode(name)) == length
    output_file(tmp_path / name)
    write_atomic(tmp_path / name, "x\n")
    assert (tmp_path / name).read_text() == "x\n" and [p.name for p in tmp_path.iterdir()] == [name]
