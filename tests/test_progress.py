"""The progress line: drawn on a terminal only, within its width, with no escape a dumb terminal would print."""

import fcntl
import os
import pty
import select
import struct
import termios

from conftest import CLEARED, Terminal
from fitgen.base.progress import Progress


def _drawn_on_a_terminal(columns: int, label: str, note: str) -> str:
    """What a Progress writes to a pseudo-terminal ``columns`` wide (the kernel's window size, as a real terminal
    sets it)."""
    master, slave = pty.openpty()
    try:
        fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, columns, 0, 0))
        attrs = termios.tcgetattr(slave)
        attrs[1] &= ~termios.OPOST  # bytes as written: no newline translation to read through
        termios.tcsetattr(slave, termios.TCSANOW, attrs)
        with os.fdopen(os.dup(slave), "w") as stream:
            with Progress(label, 3, stream=stream, min_interval=0.0) as bar:
                for _ in range(3):
                    bar.update(note=note)
        text = b""
        while select.select([master], [], [], 0.5)[0]:  # a pty hands over its bytes in pieces
            text += os.read(master, 65536)
        return text.decode()
    finally:
        os.close(master)
        os.close(slave)


def test_a_line_is_cut_to_the_terminal_s_width(monkeypatch):
    """A note longer than the terminal would wrap, and each redraw would then leave a stale row behind."""
    monkeypatch.delenv("COLUMNS", raising=False)
    text = _drawn_on_a_terminal(40, "fit", "held-out: 8 units built within the drawing's tolerances")
    lines = text.split("\r")[1:]
    assert len(lines) == 5, text  # three updates, the erase, the return to the line's start
    assert all(len(line) <= 39 for line in lines), [len(line) for line in lines]
    assert lines[0].startswith("fit [########") and "1/3" in lines[0]
    assert lines[2].startswith("fit [" + "#" * 24 + "] 3/3")
    assert lines[3] == " " * 39 and lines[4] == ""


def test_no_escape_sequence_reaches_the_terminal(monkeypatch):
    """TERM=dumb (an editor's shell, a serial console) prints ESC [ K as text: spaces erase instead."""
    monkeypatch.delenv("COLUMNS", raising=False)
    text = _drawn_on_a_terminal(100, "plots", "drawing estimate_dx.png")
    assert "\033" not in text and "plots [" in text
    assert text.endswith("\r" + " " * 99 + "\r")


def test_columns_sets_the_width_as_shutil_reads_it(monkeypatch):
    monkeypatch.setenv("COLUMNS", "30")
    text = _drawn_on_a_terminal(100, "fit", "x" * 100)
    assert max(len(line) for line in text.split("\r")) == 29


def test_silent_off_a_terminal_and_80_columns_where_the_width_is_unknown(tmp_path, monkeypatch):
    monkeypatch.delenv("COLUMNS", raising=False)
    with open(tmp_path / "log", "w") as log, Progress("fit", 2, stream=log, min_interval=0.0) as bar:
        bar.update(2)
    assert (tmp_path / "log").read_text() == ""
    term = Terminal()  # says it is a terminal but has no window size
    with Progress("fit", 2, stream=term, min_interval=0.0) as bar:
        bar.update(2, "x" * 200)
    assert term.text.endswith(CLEARED) and max(len(line) for line in term.text.split("\r")) == 79


def test_a_terminal_of_no_width_draws_80_columns(monkeypatch):
    """A serial console's tty is 0x0 until `stty cols` sizes it: the bar shrank to one character per redraw."""
    monkeypatch.delenv("COLUMNS", raising=False)
    text = _drawn_on_a_terminal(0, "fit", "x" * 200)
    assert max(len(line) for line in text.split("\r")) == 79 and "fit [" in text


def test_schedule_moves_its_note_through_the_candidates_information():
    """schedule's candidates' information (10,292 over five axes, 13 s here) held one note; the bar now moves its
    note with each chunk."""
    import numpy as np

    from fitgen.fitting.schedule import CHUNK, schedule
    from fitgen.physics.sensor import load_sensor

    notes = []
    schedule(load_sensor("paper"), 10, axes=("dx", "dy", "dz", "thx", "thy"),
             progress=lambda done, total, note: notes.append((done, note)))
    told = [n for d, n in notes if d == 0 and n.startswith("candidates ")]
    count = int(told[0].split("/")[1].replace(",", ""))
    assert len(told) == -(-count // CHUNK) > 1 and told[-1] == f"candidates {(len(told) - 1) * CHUNK:,}/{count:,}"
    assert np.all(np.diff([d for d, _ in notes]) >= 0)


def test_simulate_shows_its_notes_step_on_a_terminal(tmp_path, monkeypatch):
    """simulate's second pass over its rows (the linear range, 8 s on a million) ran after the bar had cleared."""
    import sys

    import pytest

    from fitgen.app import cli

    import itertools

    term = Terminal()
    monkeypatch.setattr(sys, "stderr", term)
    clock = itertools.count()  # a second between updates: every one drawn
    monkeypatch.setattr("fitgen.base.progress.time.monotonic", lambda: float(next(clock)))
    with pytest.raises(SystemExit) as stop:
        cli.main(["simulate", "--random", "200", "-o", str(tmp_path / "x.csv")])
    assert stop.value.code == 0, term.text
    bars = [t for t in term.text.split("\r") if t.startswith("simulate [")]
    assert "2/3" in bars[-1] and "elements' linear range" in bars[-1], term.text
    assert term.text.index(CLEARED) < term.text.index("wrote 200 rows")  # the notes after the bar, not under it


def test_predict_report_and_fit_say_they_read_and_write_a_large_file(tmp_path, monkeypatch):
    """Reading 300,000 rows takes seconds (5 s here), writing their estimates 2.5: predict, report and fit had
    shown nothing before their first line."""
    import sys

    import pytest

    from fitgen.app import cli
    from fitgen.physics.sensor import load_sensor
    from fitgen.physics.simulate import PAPER_GRIDS, grid_poses, simulate

    monkeypatch.setenv("COLUMNS", "400")  # the notes whole, long paths and all
    data, model = str(tmp_path / "d.csv"), str(tmp_path / "m.json")
    simulate(load_sensor("paper"), grid_poses(PAPER_GRIDS["paper-exp"])).save(data)
    for argv, said in ((["fit", data, "-o", model, "--outputs", "dx", "--max-terms", "2", "--held-out", "0"],
                        ("fit", f"reading {data}")),
                       (["predict", model, data, "-o", str(tmp_path / "e.csv")],
                        ("predict", f"reading {data}", f"writing {tmp_path / 'e.csv'}")),
                       (["report", model, "--data", data, "-o", str(tmp_path / "r.md")],
                        ("report", f"reading {data}"))):
        term = Terminal()
        monkeypatch.setattr(sys, "stderr", term)
        with pytest.raises(SystemExit) as stop:
            cli.main(argv)
        assert stop.value.code == 0, term.text
        bars = [t for t in term.text.split("\r") if t.startswith(f"{said[0]} [")]
        for note in said[1:]:
            assert any(b.rstrip().endswith(note) for b in bars), term.text
