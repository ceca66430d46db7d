"""The commands' standard streams as shells hand them over: an ASCII terminal, a reader gone, a full log disk."""

import os
import subprocess
import sys

from conftest import assert_one_line_error

from fitgen.app.cliutil import EXIT_PIPE

FITGEN = [sys.executable, "-c", "import sys; from fitgen.app.cli import main; sys.argv[0] = 'fitgen'; main()"]


def test_a_path_an_ascii_stdout_cannot_encode_is_escaped_not_a_traceback(model_file, tmp_path):
    """report names the model on stdout: 'm é.json' to a C-locale terminal raised UnicodeEncodeError."""
    named = tmp_path / "m é.json"
    named.write_bytes(open(model_file, "rb").read())
    proc = subprocess.run([*FITGEN, "report", str(named)], capture_output=True, text=True, timeout=120,
                          env={**os.environ, "PYTHONIOENCODING": "ascii"})
    assert proc.returncode == 0 and "Traceback" not in proc.stderr, proc.stderr
    assert proc.stdout.startswith("## Report") and "m \\xe9.json" in proc.stdout.splitlines()[0]


def test_a_reader_gone_is_said_by_the_status_sigpipe_gives():
    """`fitgen check ... | true` under pipefail read 0 although the check failed: a cut output gives no verdict,
    so the status is 141, as cat's or git's, never a success."""
    read, write = os.pipe()
    os.close(read)  # the reader is gone before the first line
    try:
        proc = subprocess.run([*FITGEN, "observe", "--sensor", "paper"], stdout=write, stderr=subprocess.PIPE,
                              text=True, timeout=120)
    finally:
        os.close(write)
    assert proc.returncode == EXIT_PIPE == 141, proc.stderr
    assert "Traceback" not in proc.stderr and "Exception ignored" not in proc.stderr, proc.stderr


def test_a_stderr_that_cannot_be_written_keeps_the_command_s_status(tmp_path):
    """2>>log on a full disk: the work done exits 0, bad input 2; a failed diagnostic had made both 1."""
    out = tmp_path / "s.csv"
    with open("/dev/full", "w") as full:
        done = subprocess.run([*FITGEN, "simulate", "--sensor", "paper", "--random", "5", "-o", str(out)],
                              stdout=subprocess.PIPE, stderr=full, text=True, timeout=120)
        refused = subprocess.run([*FITGEN, "predict", str(tmp_path / "none.json"), str(out), "-o",
                                  str(tmp_path / "p.csv")], stdout=subprocess.PIPE, stderr=full, text=True, timeout=120)
    assert done.returncode == 0 and len(out.read_text().splitlines()) == 6
    assert refused.returncode == 2 and not (tmp_path / "p.csv").exists()
    # the same refusal to a stderr that takes it: one line
    assert_one_line_error(subprocess.run([*FITGEN, "predict", str(tmp_path / "none.json"), str(out), "-o",
                                          str(tmp_path / "p.csv")], capture_output=True, text=True, timeout=120),
                          2, "no such file")
