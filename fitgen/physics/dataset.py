"""Datasets in the shared CSV format: columns v1..vN, then whichever of dx,dy,dz,thx,thy."""

from __future__ import annotations

import csv
import difflib
import hashlib
import io
import json
import math
import re
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fitgen.base.errors import InputError, RowError, is_finite_number, shown
from fitgen.base.fileio import read_text, real_file, write_all
from fitgen.base.texts import sha256_hex, text_kind
from fitgen.base.parse import DEGC, MAX_NOISE, MAX_ROW_SAMPLES
from fitgen.physics.pose import POSE_NAMES, off_skin

_INPUT_RE = re.compile(r"^v([1-9][0-9]*)$")


@dataclass
class Dataset:
    """Element readings ``inputs`` (n, N) and pose ``targets`` (n, len(target_names))."""

    inputs: np.ndarray
    targets: np.ndarray
    target_names: tuple[str, ...]
    meta: dict = field(default_factory=dict)

    def __post_init__(self):
        # one made in a notebook: said here, not as a broadcast or an index error deep in a fit
        self.inputs, self.targets = (np.asarray(self.inputs, dtype=float), np.asarray(self.targets, dtype=float))
        self.target_names = tuple(self.target_names)
        if self.inputs.ndim != 2 or self.targets.ndim != 2 or len(self.targets) != len(self.inputs):
            raise InputError(f"a dataset is inputs (n, N) and targets (n, T) of the same rows; got shapes "
                             f"{self.inputs.shape} and {self.targets.shape}")
        names = self.target_names
        if (self.targets.shape[1] != len(names) or any(t not in POSE_NAMES for t in names)
                or len(set(names)) < len(names)):
            raise InputError(f"a dataset's target_names are one distinct pose component ({', '.join(POSE_NAMES)}) "
                             f"per column of targets ({self.targets.shape[1]}); got {self.target_names}")

    @property
    def n_rows(self) -> int:
        return int(self.inputs.shape[0])

    @property
    def n_inputs(self) -> int:
        return int(self.inputs.shape[1])

    @property
    def columns(self) -> list[str]:
        return [f"v{k}" for k in range(1, self.n_inputs + 1)] + list(self.target_names)

    def target(self, name: str) -> np.ndarray:
        if name not in self.target_names:
            raise InputError(f"dataset has no column {name!r} (it has {', '.join(self.target_names) or 'none'})")
        return self.targets[:, self.target_names.index(name)]

    def poses(self) -> np.ndarray:
        """(n, 5) poses, components the dataset lacks set to 0."""
        out = np.zeros((self.n_rows, 5))
        for j, name in enumerate(self.target_names):
            out[:, POSE_NAMES.index(name)] = self.targets[:, j]
        return out

    def repeats(self) -> np.ndarray:
        """Indices (ascending) of the rows that repeat an earlier row exactly, every reading and label."""
        table = np.ascontiguousarray(np.hstack([self.inputs, self.targets]))
        first = np.unique(table.view(np.dtype((np.void, table.itemsize * table.shape[1]))).ravel(),
                          return_index=True)[1]
        return np.setdiff1d(np.arange(self.n_rows), first)

    def to_csv_text(self) -> str:
        table = np.hstack([self.inputs, self.targets]) + 0.0  # + 0.0 folds -0.0 into 0.0
        lines = [",".join(self.columns)]
        lines += [",".join(map(repr, row)) for row in table.tolist()]
        return "\n".join(lines) + "\n"

    @property
    def sha256(self) -> str:
        """The SHA-256 of :meth:`to_csv_text`; kept for the same values (fit_auto's two fits ask)."""
        # the key is a hash of the raw values, ~1/100 of the text's cost, so a changed array is never missed
        key = hashlib.blake2b(b"".join([np.ascontiguousarray(self.inputs).tobytes(),
                                        np.ascontiguousarray(self.targets).tobytes(),
                                        repr((self.inputs.shape, self.targets.shape, self.target_names)).encode()]),
                              digest_size=16).digest()
        cached = self.__dict__.get("_sha256")
        if cached is None or cached[0] != key:
            cached = self.__dict__["_sha256"] = (key, sha256_hex(self.to_csv_text()))
        return cached[1]

    def save(self, path: str | Path, meta: dict | None = None, beside=()) -> Path:
        """Write the CSV and, beside it, ``<path>.meta.json`` with provenance, and every ``(path, text)`` of
        ``beside`` (a unit's file): all or none (a CSV whose meta could not be written would be read as measured
        data)."""
        text = self.to_csv_text()
        info = dict(self.meta if meta is None else meta)
        info["dataset_sha256"] = sha256_hex(text)
        info["rows"] = self.n_rows
        info["columns"] = self.columns
        write_all([(path, text), (meta_path(path), json.dumps(info, indent=2, sort_keys=True) + "\n"), *beside])
        return Path(path)


HUGE = 1e30  # a reading or label beyond it is a typo or a unit error; its powers would overflow


def refuse_huge(ds: Dataset) -> Dataset:
    """``ds``; InputError naming the first reading or label beyond HUGE, where it is (not as a term that is not
    finite, a cast's overflow, or an error whose square is not)."""
    for values, names in ((ds.inputs, [f"v{k + 1}" for k in range(ds.n_inputs)]), (ds.targets, ds.target_names)):
        big = np.argwhere(np.abs(values) > HUGE)
        if big.size:
            r, c = big[0]
            raise InputError(f"data row {r + 1}, column {names[c]}, holds {values[r, c]:g}: beyond any reading or pose")
    return ds


def load_capture(path: str | Path) -> Dataset:
    """:func:`load_dataset` for identify and check, which read a capture's rows as the unit's physics: a reading
    or label beyond HUGE refused where it is (:func:`refuse_huge`), and a pose column its meta records but its CSV
    no longer has (they read a column left out as that axis at 0 on every row, and blamed the physics or the unit
    for it)."""
    ds = load_dataset(path)
    refuse_huge(ds)
    _refuse_gone(ds.meta, ds.columns, path, poses=True)
    total = ds.meta.get("schedule_poses")
    # capture writes each of its schedule's poses once
    if type(total) is int and ds.n_rows > total and len(copies := ds.repeats().tolist()):
        raise InputError(f"{path} holds {ds.n_rows} rows for the {total} poses of its schedule, and data row(s) "
                         f"{', '.join(str(r + 1) for r in copies[:5])}{', ...' if len(copies) > 5 else ''} repeat "
                         "earlier rows to the last digit: copies, each of which would count as a measurement of its "
                         "own; delete them")
    return ds


def _refuse_gone(meta: dict, names, path, poses: bool) -> None:
    """InputError when a column ``meta`` records is not among ``names`` (the CSV's): a reading column, or with
    ``poses`` a pose column, removed since the file was written."""
    recorded = meta.get("columns")
    gone = [c for c in recorded if c not in names and (_INPUT_RE.match(str(c)) or poses and c in POSE_NAMES)] \
        if isinstance(recorded, list) else []
    if gone:
        what = "a pose column removed since it was written reads as that axis at 0 on every row" \
            if gone[0] in POSE_NAMES else "a reading column removed since it was written leaves its element out"
        raise InputError(f"{path} has no {', '.join(map(str, gone))} column, which its meta records: {what}; use the "
                         "file as it was written")


def stage_labelled(ds: Dataset) -> bool:
    """Whether ``ds``'s labels are a stage's displacements: a capture (``samples_per_row`` in its meta) or a
    built unit simulated with the stage's labels."""
    return _stage_meta(ds.meta)


def _stage_meta(meta: dict) -> bool:
    return "samples_per_row" in meta or meta.get("labels") == "stage"


def rows_on_the_skin(ds: Dataset, none_left: str | None = None) -> tuple[Dataset, int]:
    """``ds`` without the rows its stage lifted off the skin, and how many were left out. Such a row reads the
    magnet at rest (fitgen.physics.pose.off_skin): it helps identify a unit, but its label is no contact pose
    for an estimator to learn. A dataset neither a stage's nor fitgen simulate's is returned as it is.
    ``none_left``: the InputError's message when every row was lifted."""
    keep = _on_the_skin(ds)
    if keep.all():
        return ds, 0
    if none_left is not None and not keep.any():
        raise InputError(none_left)
    return Dataset(ds.inputs[keep], ds.targets[keep], ds.target_names, dict(ds.meta)), int(np.sum(~keep))


def _on_the_skin(ds: Dataset) -> np.ndarray:
    # fitgen simulate's rows read at rest there too (its note says fit leaves them out); a CSV of one's own may
    # count dz into the skin as positive, so its rows are kept
    simulated = str(ds.meta.get("generator", "")).startswith("fitgen ")
    if not (stage_labelled(ds) or simulated) or "dz" not in ds.target_names:
        return np.ones(ds.n_rows, bool)
    return ~off_skin(ds.poses())


@contextmanager
def numbered_as_in(loaded: Dataset):
    """A RowError raised within about the rows :func:`rows_on_the_skin` kept of ``loaded`` names the row as
    ``loaded``'s file numbers it."""
    try:
        yield
    except RowError as e:
        raise InputError(e.numbered(int(np.flatnonzero(_on_the_skin(loaded))[e.row]) + 1)) from None


def meta_path(path: str | Path) -> Path:
    """``<path>.meta.json`` beside the file ``path`` is, or leads to through a symlink (found by either name)."""
    return Path(str(real_file(path)) + ".meta.json")


def _header(names: list[str], origin: str) -> tuple[int, tuple[str, ...]]:
    n_in = 0
    for name in names:
        m = _INPUT_RE.match(name)
        if not m:
            break
        n_in += 1
        if int(m.group(1)) != n_in:
            raise InputError(f"{origin}: input columns must be v1..vN in order; found {name!r} at position {n_in}")
    rest = names[n_in:]
    if n_in == 0:
        raise InputError(f"{origin}: no input columns (expected v1..vN first, header is {','.join(names)!r})")
    for name in rest:
        if name not in POSE_NAMES:
            raise InputError(f"{origin}: unknown column {name!r} (after v1..v{n_in} only {', '.join(POSE_NAMES)})")
    order = [POSE_NAMES.index(n) for n in rest]
    if order != sorted(order):
        raise InputError(f"{origin}: pose columns must be in the order {','.join(POSE_NAMES)}")
    return n_in, tuple(rest)


def _cells(line: str) -> list[str]:
    """One line's cells as the csv module reads them (quoted numbers too), a line at a time: read as one text, a
    stray quote took the rest of the file for one field, past the module's limit (csv.Error, a traceback)."""
    try:
        return next(csv.reader([line]), [])
    except csv.Error:  # a field past the limit within the line
        return line.split(",")


def _find_bad_cell(text: str, names: list[str], origin: str) -> InputError:
    header = None
    for lineno, row in enumerate(map(_cells, text.splitlines()), start=1):
        if not any(c.strip() for c in row) or row[0].lstrip().startswith("#"):  # blank, or a comment, as the reader
            continue
        if header is None:
            header = lineno
            continue
        if len(row) != len(names):
            return InputError(f"{origin} line {lineno}: {len(row)} fields, the header has {len(names)}")
        for name, cell in zip(names, row):
            try:
                val = float(cell)
            except ValueError:
                return InputError(f"{origin} line {lineno}, column {name}: {shown(cell.strip())} is not a number")
            if not math.isfinite(val):
                return InputError(f"{origin} line {lineno}, column {name}: {shown(cell.strip())} is not a finite "
                                  "number")
    return InputError(f"{origin}: cannot parse as CSV numbers")


DATASET_IS = "a dataset is a CSV with the header v1,...,vN,dx,dy,dz,thx,thy"


def parse_table(text: str, origin: str, header=None, expected: str = DATASET_IS) -> tuple[list[str], np.ndarray]:
    """Header names (each once) and a finite float table from CSV text; errors name line and column.
    ``header(names)``: checks the names before the cells are read (an unknown column is then said as such, not as
    its first cell that is not a number). ``expected``: what the file should be, for a refusal of JSON or TOML."""
    lines = text.splitlines()
    if not lines or not lines[0].strip():
        raise InputError(f"{origin}: empty file (or a blank first line); {expected}")
    kind = text_kind(text)
    if kind == "toml":
        raise InputError(f"{origin}: TOML, not CSV (a sensor or unit file? those go to --sensor); {expected}")
    if kind == "json":
        raise InputError(f"{origin}: JSON, not CSV (a model, meta or noise file?); {expected}")
    # comment lines before the header are skipped as those in the body are (an Arduino's "# tare: ..." line)
    lines = lines[next((k for k, ln in enumerate(lines) if ln.strip() and not ln.lstrip().startswith("#")),
                       len(lines) - 1):]
    names = [c.strip() for c in _cells(lines[0])]
    sep = next((s for s in ";\t" if len(names) == 1 and s in lines[0]), None)
    if sep is not None:  # a spreadsheet's export in a locale whose decimal point is a comma
        raise InputError(f"{origin}: its header is separated by {sep!r}, not commas: a dataset is comma-separated "
                         "with '.' as the decimal point (export it so, e.g. as 'CSV UTF-8 (comma delimited)')")
    if "" in names:  # a spreadsheet's export with a trailing comma, or an index column without a name
        k = names.index("")
        raise InputError(f"{origin}: column {k + 1} of the header has no name"
                         + (" (the line ends in a comma)" if k == len(names) - 1 else "")
                         + ": remove the empty column, or name it")
    twice = next((n for n in names if names.count(n) > 1), None)
    if twice is not None:
        raise InputError(f"{origin}: column {twice} appears twice")
    if header is not None:
        header(names)
    # blank lines, and a spreadsheet's empty rows (",,,,"), are no rows
    body = [ln for ln in lines[1:] if ln.replace(",", "").strip()]
    if not body:
        raise InputError(f"{origin}: a header and no data rows (a run stopped before its first row?); {expected}, "
                         "one row per line under it")
    try:
        # quoted numbers ("1.5"), as some exporters write every cell, read as the csv module reads them
        table = np.loadtxt(io.StringIO("\n".join(body)), delimiter=",", ndmin=2, dtype=float, quotechar='"')
    except ValueError:
        raise _find_bad_cell(text, names, origin) from None
    if table.shape[1] != len(names) or not np.all(np.isfinite(table)):
        raise _find_bad_cell(text, names, origin)
    return names, table


META_TEXT = ("units", "sensor", "sensor_file", "scene_spec", "drawing", "transfer", "sensor_sha256",
             "labels")  # keys read as text (or null)
META_OBJECTS = ("schedule_drawing", "schedule_stage")  # a capture's copy of its schedule's records (identify, check)
READING_UNITS = ("mT", "V")  # the field at the elements (transfer raw) or their voltages (gmr)
# noise figures the fit reads from a meta (V or mT): one number, or one per element
META_NOISE = ("noise", "row_noise", "sample_noise")


def load_dataset(path: str | Path, *, min_rows: int = 2) -> Dataset:
    """Read and validate a dataset CSV (and its ``.meta.json`` if present)."""
    origin = f"dataset {path}"
    text = read_text(path, "dataset")
    if "\n" in text and not text.endswith("\n") and _captured(path):  # a header alone: no row to tear
        # capture ends every row it writes with its line: one without was torn as a run stopped, and a tear in its
        # last cell still reads as a row, at a pose the stage never took (capture's resume drops it)
        raise InputError(f"{origin}: its last line, line {text.count(chr(10)) + 1}, has no line end: a row torn as "
                         "the capture stopped; the same capture command run again takes it anew (or delete the line)")
    names, table = parse_table(text, origin, lambda names: _header(names, origin))
    n_in, targets = _header(names, origin)
    if table.shape[0] < min_rows:
        raise InputError(f"{origin}: {table.shape[0]} data row(s); at least {min_rows} needed")
    meta = load_meta(path)
    # a stage's rows read a pose column left out as 0 (a rest row lifted off the skin as one in contact)
    _refuse_gone(meta, names, path, poses=_stage_meta(meta))
    _check_meta_numbers(meta, meta_path(path))  # what fit, identify and check read: a schedule's is capture's
    for key in META_NOISE:
        if isinstance(meta.get(key), list) and len(meta[key]) != n_in:
            raise InputError(f"{meta_path(path)}: {key} gives {len(meta[key])} figure(s) for {n_in} elements; "
                             "repair or remove it")
    _check_noise_against_rows(meta, table[:, :n_in], meta_path(path))
    return Dataset(table[:, :n_in].copy(), table[:, n_in:].copy(), targets, meta)


def _captured(path) -> bool:
    """Whether the meta beside ``path`` says `tactile-host capture` wrote it (a meta that cannot be read: no)."""
    try:
        return str(load_meta(path).get("generator", "")).startswith("tactile-host capture")
    except InputError:
        return False


def _check_noise_against_rows(meta: dict, inputs: np.ndarray, mp) -> None:
    """InputError when a meta's noise in a row is more than all the rows' readings span: ten rows or more of such
    noise would spread wider (a typo's figure, which a fit would take as the rows' own and add none)."""
    if inputs.shape[0] < 10:
        return
    span = float(np.ptp(inputs))
    n = meta.get("samples_per_row") or 1
    for key in META_NOISE:
        if meta.get(key) is None:
            continue
        top = float(np.max(meta[key]))
        if top / (np.sqrt(n) if key == "sample_noise" else 1.0) > span:
            raise InputError(f"{mp}: {key} {top:g} puts more noise in a row than all the rows' readings span "
                             f"({span:.3g}); repair or remove it")


def load_meta(path: str | Path) -> dict:
    """The dataset's ``<path>.meta.json`` as written by :meth:`Dataset.save`; {} when there is none."""
    mp = meta_path(path)
    if not mp.exists():  # a folder of that name is said by read_text, not taken for no meta
        return {}
    text = read_text(mp, "dataset meta")  # its InputError is a ValueError: said as it is, not as JSON's
    try:
        meta = json.loads(text)
    except ValueError as exc:
        raise InputError(f"{mp}: not JSON ({exc}); repair or remove it") from None
    if not isinstance(meta, dict):
        raise InputError(f"{mp}: not a dataset's meta (a JSON object); repair or remove it")
    for key in META_TEXT:
        if not isinstance(meta.get(key), (str, type(None))):
            raise InputError(f"{mp}: {key} must be text, got {meta[key]!r:.60}; repair or remove it")
    for key in META_OBJECTS:  # else read as none recorded: identify took paper and the default stage errors unsaid
        if not isinstance(meta.get(key), (dict, type(None))):
            raise InputError(f"{mp}: {key} must be an object (the schedule's record, as capture copies it), got "
                             f"{meta[key]!r:.60}; repair or remove it")
    from fitgen.physics.relocate import relocated_meta

    return relocated_meta(meta, mp.parent)  # a folder moved with its unit's file: found beside the data


def noise_figures_agree(sample_noise, row_noise, samples: int) -> bool:
    """Whether a meta's per-sample and per-row noise are one measurement's, as a capture writes them (every row
    averages ``samples``: the row's is the sample's over sqrt(samples), to 1 %)."""
    each, row = np.asarray(sample_noise, dtype=float), np.asarray(row_noise, dtype=float)
    return not np.any(np.abs(each / np.sqrt(samples) - row) > 0.01 * row + 1e-12)


def _check_meta_numbers(meta: dict, mp) -> None:
    """InputError (one line) for a meta figure the fit and identify read that is not as the tools write it."""
    def refuse(key: str, what: str, got=None) -> None:
        got = f"{meta[key]!r:.60}" if got is None else got
        raise InputError(f"{mp}: {key} must be {what}, got {got}; repair or remove it")

    if meta.get("units") not in (None, *READING_UNITS):
        refuse("units", " or ".join(READING_UNITS))

    def figure(x) -> bool:  # past MAX_NOISE no sensor's, and its square overflows
        return is_finite_number(x) and 0 <= x <= MAX_NOISE

    for key in META_NOISE:
        x = meta.get(key)
        if x is not None and not (figure(x) or isinstance(x, list) and x and all(figure(v) for v in x)):
            bad = next(((k, v) for k, v in enumerate(x) if not figure(v)), None) if isinstance(x, list) else None
            refuse(key, f"a noise figure 0..{MAX_NOISE:g} (or one per element)",
                   None if bad is None else f"{bad[1]!r:.60} for element {bad[0] + 1}")
    n = meta.get("samples_per_row")
    if n is not None and not (isinstance(n, int) and not isinstance(n, bool) and 1 <= n <= MAX_ROW_SAMPLES):
        refuse("samples_per_row", f"a whole number 1..{MAX_ROW_SAMPLES}")
    each, row = meta.get("sample_noise"), meta.get("row_noise")
    if n is not None and each is not None and row is not None:  # a capture writes both from the same samples
        each_a, row_a = np.asarray(each, dtype=float), np.asarray(row, dtype=float)
        same = each_a.shape == row_a.shape or not each_a.ndim or not row_a.ndim  # else load_dataset says the count
        if same and not noise_figures_agree(each_a, row_a, n):
            refuse("sample_noise", f"row_noise times sqrt(samples_per_row {n}), as a capture writes it",
                   f"{each!r:.60} beside row_noise {row!r:.60}")

    def absurd(x) -> bool:  # a number no thermistor reads (what is no number at all is noted where it is read)
        return is_finite_number(x) and not DEGC[0] <= x <= DEGC[1]

    span = f"{DEGC[0]:g}..{DEGC[1]:g} degC"
    if absurd(meta.get("thermistor_degc")):
        refuse("thermistor_degc", f"a temperature {span}")
    t = meta.get("row_degc")
    if isinstance(t, list) and any(absurd(x) for x in t):
        refuse("row_degc", f"a list of temperatures {span}, one per row",
               next(f"{x!r} for row {k + 1}" for k, x in enumerate(t) if absurd(x)))


def load_inputs(path: str | Path, n_inputs: int) -> np.ndarray:
    """The columns v1..v<n_inputs> of a CSV (others ignored): the inputs of a model that takes them."""
    return load_inputs_and_labels(path, n_inputs)[0]


def load_inputs_and_labels(path: str | Path, n_inputs: int) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """:func:`load_inputs`, and the pose columns (dx..thy) the CSV has by name ({} for none), from one read (a pipe
    reads once). A readout's lines (a ``status`` column: ``tactile-host read``'s, ReadPose's) carry a device's
    estimates under those names, not poses: no labels then."""
    origin = f"dataset {path}"
    names, table = parse_table(read_text(path, "dataset"), origin)
    cols = [f"v{k}" for k in range(1, n_inputs + 1)]
    missing = [c for c in cols if c not in names]
    if missing:
        raise InputError(f"{origin}: missing column {missing[0]} (the model takes {cols[0]}..{cols[-1]})")
    labels = {} if "status" in names else {n: table[:, names.index(n)] for n in POSE_NAMES if n in names}
    return table[:, [names.index(c) for c in cols]], labels


def estimates_csv(output_names, estimates: np.ndarray, status: np.ndarray) -> str:
    """Estimates as CSV: a column per output (numbers that round-trip), then the status per row."""
    header = ",".join(list(output_names) + ["status"])
    lines = [header] + [",".join(map(repr, row)) + f",{int(s)}" for row, s in zip(estimates.tolist(), status)]
    return "\n".join(lines) + "\n"


def pose_table(text: str, origin: str) -> tuple[np.ndarray, tuple[str, ...]]:
    """Poses (P, 5) from CSV text with any of the columns dx,dy,dz,thx,thy (missing = 0) and the ones it names,
    in that order. Input columns v1.. (a dataset's) are passed over; any other column is refused, so that a
    misspelt one (dzz, DZ) is not read as a pose held at 0."""
    names, table = parse_table(text, origin, expected="poses are a CSV with any of the columns dx,dy,dz,thx,thy, "
                                                      "as fitgen schedule writes them")
    for name in names:
        if name not in POSE_NAMES and not re.fullmatch(r"v[1-9]\d*", name):
            close = difflib.get_close_matches(name.lower(), POSE_NAMES, n=1, cutoff=0.6)
            raise InputError(f"{origin}: unknown column {name!r}" + (f" (did you mean {close[0]}?)" if close else "")
                             + f"; pose columns are {','.join(POSE_NAMES)}")
    columns = tuple(n for n in POSE_NAMES if n in names)
    if not columns:
        raise InputError(f"{origin}: none of the columns {','.join(POSE_NAMES)}")
    out = np.zeros((table.shape[0], 5))
    for name in columns:
        out[:, POSE_NAMES.index(name)] = table[:, names.index(name)]
    return out, columns


def load_poses(path: str | Path) -> np.ndarray:
    """Poses from a CSV with any of the columns dx,dy,dz,thx,thy (:func:`pose_table`)."""
    return pose_table(read_text(path, "poses"), f"poses {path}")[0]


def thermistor_degc(meta: dict) -> float | None:
    """The temperature a capture's rows were taken at, as its meta records it (``thermistor_degc``: tactile-host
    capture with a thermistor in its channel map), or None."""
    t = meta.get("thermistor_degc") if isinstance(meta, dict) else None
    return float(t) if is_finite_number(t) else None


def row_degc(meta: dict, rows: int) -> np.ndarray | None:
    """Each of a capture's ``rows`` rows' temperature as its meta records it (``row_degc``: tactile-host capture
    reads its thermistor about every row), or None where it records none for some row."""
    t = meta.get("row_degc") if isinstance(meta, dict) else None
    if not isinstance(t, list) or len(t) != rows or not all(is_finite_number(x) for x in t):
        return None
    return np.asarray(t, dtype=float)


