"""A capture's file on disk: its header and rows, the lock a run holds on it, its meta, and both read back so that a
run resumes where the last one stopped (host.capture takes the rows)."""

from __future__ import annotations

import fcntl
import json
import os
from collections import Counter
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fitgen import __version__
from fitgen.base.errors import InputError
from fitgen.base.fileio import open_output, real_file, write_atomic, write_target
from fitgen.base.texts import sha256_hex
from fitgen.physics.dataset import meta_path, read_text, row_degc


def header_line(n_inputs: int, columns: tuple[str, ...]) -> str:
    return ",".join([f"v{k}" for k in range(1, n_inputs + 1)] + list(columns)) + "\n"


def row_line(volts: np.ndarray, pose_values: np.ndarray) -> str:
    """Shortest round-trip text of each number (repr), as ``Dataset.to_csv_text`` writes them."""
    return ",".join(repr(float(x) + 0.0) for x in list(volts) + list(pose_values)) + "\n"


@dataclass
class ResumeState:
    done: np.ndarray  # (P,) bool: schedule poses already in the file
    rows: int  # complete rows found
    dropped_partial: bool = False  # a last line without its newline was removed


def _key(values) -> tuple:
    return tuple(round(float(x), 9) + 0.0 for x in values)


def prepare_output(path: str | Path, n_inputs: int, schedule, *, write: bool = True) -> ResumeState:
    """Create the output with its header, or read it back and work out which of ``schedule``'s poses (a
    host.capture.Schedule) are done.

    ``write=False`` only checks: nothing is created or repaired.
    """
    path = Path(path)
    write_target(path)  # a FIFO's or device's reading would hang or read nothing: no file to resume
    header = header_line(n_inputs, schedule.columns)
    n_poses = len(schedule.poses)
    if not path.exists() or path.stat().st_size == 0:
        # a folder of its meta's name had failed the first row, after the stage took its zero (a resume's meta is
        # check_resume's, which says what it holds)
        write_target(meta_path(path))
        if write:
            write_atomic(path, header)
        elif not path.parent.is_dir():
            raise InputError(f"cannot write {path}: folder {path.parent} does not exist")
        return ResumeState(np.zeros(n_poses, dtype=bool), 0)
    origin = f"output {path}"
    text = read_text(path, "output (to resume)")  # a byte-order mark (re-saved in a spreadsheet) taken off
    cut = not text.endswith("\n")  # the last write was cut short
    dropped = cut and text != header.rstrip("\n")  # a row torn: it never was one (else the header's line end)
    if cut:
        text = text[: text.rfind("\n") + 1] if dropped else header
    if not text.startswith(header):
        first = text.split("\n", 1)[0]
        raise InputError(f"{origin}: its header {first!r} is not {header.strip()!r}; it belongs to another "
                         "channel map or schedule (choose another -o)")
    if cut and write:
        write_atomic(path, text)
    counts: Counter = Counter()
    where: dict = {}
    width = n_inputs + len(schedule.columns)
    lines = text.split("\n")[1:-1]
    for lineno, line in enumerate(lines, start=2):
        if not line.strip():
            continue
        try:
            vals = [float(x) for x in line.split(",")]
        except ValueError:
            vals = []
        if len(vals) != width or not np.all(np.isfinite(vals)):
            raise InputError(f"{origin} line {lineno}: not a row of {width} numbers; repair or remove it to resume")
        counts[key := _key(vals[n_inputs:])] += 1
        where.setdefault(key, []).append(lineno)
    rows = sum(counts.values())
    done = np.zeros(n_poses, dtype=bool)
    for i, vals in enumerate(schedule.values):
        key = _key(vals)
        if counts[key] > 0:
            counts[key] -= 1
            done[i] = True
    extra = [k for k, c in counts.items() if c > 0]
    if extra:
        key, pose = extra[0], " ".join(f"{c}={v:g}" for c, v in zip(schedule.columns, extra[0]))  # as progress says
        if counts[key] < len(where[key]):  # the schedule has it, less often: rows copied, not another run's
            raise InputError(f"{origin} line(s) {', '.join(map(str, where[key][-counts[key]:]))}: pose {pose} more "
                             f"often than the {schedule.origin} has it: rows copied? delete those lines to resume")
        raise InputError(f"{origin} line {where[key][0]}: pose {pose} is not in the {schedule.origin}; it belongs to "
                         "another run (choose another -o)")
    return ResumeState(done, rows, dropped)


def lock_path(output: str | Path) -> Path:
    """``<output>.lock`` beside the file ``output`` is or leads to: two names of one file take one lock."""
    return Path(str(real_file(output)) + ".lock")


@contextmanager
def output_lock(output: str | Path):
    """Hold ``output`` for one capture run; InputError (one line) when another run holds it.

    An exclusive flock on ``<output>.lock`` (the output itself may not exist yet), which the kernel releases
    when the process ends, however it ends: a killed run leaves at most the empty file, and the next run takes
    it over. The file is removed at the end, while still held.
    """
    path = lock_path(output)
    while True:
        try:
            fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as exc:
            raise InputError(f"cannot write {path}: {exc.strerror}") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as exc:
            os.close(fd)
            if isinstance(exc, BlockingIOError):
                raise InputError(f"output {output}: another capture is writing it (it holds {path.name}): let it "
                                 "end, or choose another -o") from None
            raise InputError(f"cannot lock {path}: {exc.strerror}") from None
        try:
            held, named = os.fstat(fd), os.stat(path)
        except FileNotFoundError:
            held = named = None
        if held is not None and (held.st_dev, held.st_ino) == (named.st_dev, named.st_ino):
            break
        os.close(fd)  # the run that held it removed the file between our open and our lock: take a new one
    try:
        yield
    finally:
        path.unlink(missing_ok=True)
        os.close(fd)


class RowWriter:
    """Appends complete lines: one write of the whole line, then fsync."""

    def __init__(self, path: str | Path):
        self.path = path
        self.fd = open_output(path, append=True)

    def append(self, line: str) -> None:
        """``line`` written and synced; InputError naming the file when the disk refuses it (full, a size limit):
        a part written is a partial row, dropped by the next run."""
        data = line.encode()
        try:
            while data:
                n = os.write(self.fd, data)
                data = data[n:]
            os.fsync(self.fd)
        except OSError as exc:
            raise InputError(f"cannot write {self.path}: {exc.strerror or exc}") from None

    def close(self) -> None:
        if self.fd is not None:
            os.close(self.fd)
            self.fd = None


ROW_DIGEST = 12  # hex digits of each row's sha256 a meta keeps: rows told apart, at a sixth of a row's length


def _row_lines(text: str) -> list[tuple[int, str]]:
    """(line number, text) of each complete row of a capture's ``text``: not the header, not a blank line, not a
    last line without its line end (a torn row, which the next run drops)."""
    lines = text.split("\n")[1:-1]  # the piece after the last line end is no complete line
    return [(n, line.strip()) for n, line in enumerate(lines, start=2) if line.strip()]


def _digest(line: str) -> str:
    return sha256_hex(line)[:ROW_DIGEST]


def row_digests(text: str) -> list[str]:
    """Each complete row of a capture's ``text`` as its sha256's first ROW_DIGEST hex digits, in order: which rows
    a meta speaks for, so that a resume tells its rows from another capture's, and each row's temperature stays
    with its row when rows before it are deleted to be taken again."""
    return [_digest(line) for _, line in _row_lines(text)]


def recorded_places(output, prior: dict) -> list | None:
    """For each complete row of ``output``, its place among the rows its meta ``prior`` recorded (``row_sha256``),
    or None for a row written after the meta last was (a run killed outright leaves its last seconds' rows so); None
    for a meta that records no rows' hashes (one written before they were recorded). InputError when the meta speaks
    for other rows: a row it does not record before one it does, or none of the rows it records."""
    got = prior.get("row_sha256")
    if not isinstance(got, list) or not all(isinstance(d, str) for d in got):
        return None
    where: dict = {}
    for i, digest in enumerate(got):
        where.setdefault(digest, []).append(i)
    rows = _row_lines(read_text(output, "output (to resume)"))
    places = [where[d].pop(0) if where.get(d := _digest(line)) else None for _, line in rows]
    late = next((k for k, p in enumerate(places) if p is None), len(places))  # the rows after its last rewrite
    stray = next((k for k in range(late, len(places)) if places[k] is not None), None)
    name, fix = meta_path(output).name, ("restore the rows and their meta from one copy to resume, or choose "
                                         "another -o")
    if stray is not None:
        raise InputError(f"output {output} line {rows[late][0]}: a row its meta ({name}) does not record, before "
                         f"one it does (line {rows[stray][0]}): the meta is another capture's, or the row was "
                         f"edited; {fix}")
    if got and rows and late == 0:
        raise InputError(f"output {output}: its meta ({name}) records none of its {len(rows)} rows: it is another "
                         f"capture's; {fix}")
    return places


def write_meta(path: str | Path, info: dict) -> None:
    text = Path(path).read_text()
    meta = dict(info)
    meta.update({"dataset_sha256": sha256_hex(text), "rows": max(text.count("\n") - 1, 0),
                 "row_sha256": row_digests(text), "columns": text.split("\n", 1)[0].split(","), "units": "V",
                 "generator": f"tactile-host capture (fitgen {__version__})"})
    write_atomic(meta_path(path), json.dumps(meta, indent=2, sort_keys=True) + "\n")


def prior_meta(output, rows: int) -> dict:
    """The meta of ``output``'s ``rows`` rows so far ({} without rows). InputError when they have none, or one
    that cannot be read: it is all that says which sensor, channels and samples they were taken with, and a
    resume would write this run's over it as if it spoke for them."""
    if rows == 0:
        return {}
    path, these = meta_path(output), "its row" if rows == 1 else f"its {rows} rows"
    if not path.exists():
        raise InputError(f"output {output}: no meta ({path.name}) says what {these} {'was' if rows == 1 else 'were'} "
                         "captured with: restore it to resume, or choose another -o")
    try:
        meta = json.loads(read_text(path, "meta"))
    except (InputError, ValueError, RecursionError) as exc:
        why = str(exc).splitlines()[0] if isinstance(exc, InputError) else "not JSON"
        raise InputError(f"output {output}: the meta of {these} cannot be read ({why}): repair it from a "
                         "copy to resume, or choose another -o") from None
    if not isinstance(meta, dict):
        raise InputError(f"output {output}: the meta of {these} is not a JSON object: repair it from a copy "
                         "to resume, or choose another -o")
    recorded_places(output, meta)  # its noise figures and temperatures would be pooled with this run's
    return meta


def prior_row_degc(output, prior: dict, rows: int) -> list | None:
    """The temperatures an earlier run recorded for ``output``'s ``rows`` rows kept, each its own row's (rows
    deleted, and a row recorded but not finished, dropped), to append to; [] without rows, None when they are not
    recorded for every row (rows of an older capture, or of a run without a thermistor), so that no list speaks
    for rows it does not cover."""
    if rows == 0:
        return []
    got = prior.get("row_degc")
    if not isinstance(got, list):
        return None
    places = recorded_places(output, prior)
    if places is not None:
        each, late = [], len(prior["row_sha256"])
        for p in places:
            if p is None:  # a row written after the meta: the temperature recorded before it, past the meta's rows
                p, late = late, late + 1
            each.append(got[p] if p < len(got) else None)
        got = each
    kept = row_degc({"row_degc": got[:rows]}, rows)
    return None if kept is None else kept.tolist()


def check_resume(output: str | Path, rows: int, this: dict) -> None:
    """Refuse to add to ``output``'s ``rows`` rows taken otherwise: through another channel map, from another
    source, or averaging another number of samples (the meta speaks for every row with one of each). A simulated
    sensor is told by its description's hash (``sensor_sha256``) when both runs recorded one: the same unit's
    file, by another path or moved, is the same source."""
    prior = prior_meta(output, rows)
    if "sensor_sha256" in prior and "sensor_sha256" in this:
        if prior["sensor_sha256"] != this["sensor_sha256"]:
            raise InputError(f"output {output}: its {rows} rows were captured from {prior.get('source')} (sensor "
                             f"sha256 {str(prior['sensor_sha256'])[:12]}), this run's {this.get('source')} is "
                             f"another sensor ({this['sensor_sha256'][:12]}): resume with the same, or choose "
                             "another -o")
        prior = {k: v for k, v in prior.items() if k != "source"}  # the paths typed may differ
    for key, option in (("adc", "--adc"), ("source", "a source"), ("samples_per_row", "--samples")):
        if key in prior and key in this and prior[key] != this[key]:
            was = prior[key] if type(prior[key]) is type(this[key]) else repr(prior[key])  # '16', not 16
            raise InputError(f"output {output}: its {rows} rows were captured with {option} {was}, this run's "
                             f"is {this[key]}: resume with the same, or choose another -o")
