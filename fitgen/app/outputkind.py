"""What kind of file an output names, and what it would replace: a slip of the name (a dataset called .json), a
capture, a dataset or another kind of the tools' JSON files written over."""

from __future__ import annotations

import os

from fitgen.app.cliutil import WRITES
from fitgen.base.errors import InputError

# per command and output option, the suffixes of the tools' other files (a model, a dataset, a sensor) than the one
# it writes, and what it writes: a slip of the name would replace one of them
_NOT_CSV = (".json", ".toml")
OUTPUT_KINDS = {("identify", "output"): ((".csv", ".json"), "the unit file is a sensor file in TOML: name it .toml "
                                         "(e.g. unit.toml)"),
                ("simulate", "output"): (_NOT_CSV, "simulate writes a dataset in CSV: name it .csv (its meta goes beside "
                                         "it)"),
                ("schedule", "output"): (_NOT_CSV, "schedule writes poses in CSV: name it .csv (its meta goes beside it)"),
                ("predict", "output"): (_NOT_CSV, "predict writes estimates in CSV: name it .csv"),
                ("report", "output"): ((".csv", ".json", ".toml"), "report writes Markdown: name it .md (e.g. "
                                       "report.md)"),
                ("fit", "output"): ((".csv", ".toml"), "fit writes a model in JSON: name it .json (e.g. model.json)"),
                ("capture", "output"): (_NOT_CSV, "capture writes rows in CSV: name it .csv (its meta goes beside it)"),
                ("capture", "temp_comp_output"): ((".csv", ".toml"), "the compensation is JSON: name it .json (e.g. "
                                                  "cap.tempcomp.json)"),
                ("noise", "output"): ((".csv", ".toml"), "the noise record is JSON: name it .json (e.g. noise.json)"),
                ("tempcomp-fit", "output"): ((".csv", ".toml"), "the compensation is JSON: name it .json (e.g. "
                                             "cap.tempcomp.json)"),
                ("run", "junit"): ((".csv", ".json", ".toml"), "the results are JUnit XML: name it .xml"),
                ("read", "output"): ((".toml",), "read writes its stream as CSV or JSONL: name it .csv or .jsonl"),
                ("read", "record"): ((".csv", ".toml"), "the run record is JSONL: name it .jsonl (e.g. run.jsonl)"),
                ("view", "record"): ((".csv", ".toml"), "the run record is JSONL: name it .jsonl (e.g. run.jsonl)"),
                ("replay", "output"): ((".csv", ".toml"), "replay writes a run record in JSONL: name it .jsonl (e.g. "
                                       "again.jsonl)"),
                ("stage-sim", "pose_file"): ((".csv", ".json", ".toml"), "the pose file is one line of text, which "
                                             "it rewrites at each move: name it .txt (e.g. pose.txt)")}


# the tools' JSON files, told by the keys each always holds; and the kind each command's output writes
JSON_KINDS = (("a model", ("schema_version", "inputs", "outputs")),
              ("a temperature compensation", ("t0", "offset_v_per_degc", "gain_per_degc")),
              ("a unit's posterior", ("covariance", "drawing_spec")),
              ("a noise record", ("recommended", "single_v")),
              ("a stage's record", ("flavor", "position", "zero")),
              ("a run record", ("run", "n_inputs", "outputs")))  # JSONL: told by its first line, the header
WRITES_JSON = {("fit", "output"): "a model", ("capture", "temp_comp_output"): "a temperature compensation",
               ("tempcomp-fit", "output"): "a temperature compensation", ("noise", "output"): "a noise record",
               ("read", "record"): "a run record", ("view", "record"): "a run record",
               ("replay", "output"): "a run record"}


# readings in a CSV and its meta, which may replace another dataset's (a schedule, poses alone, may not: over a
# dataset's readings it left a file neither fit nor simulate could take back)
DATASET_WRITERS = {("simulate", "output"), ("capture", "output")}


def is_capture(path) -> bool:
    """Whether ``path`` is a capture (rows measured by `tactile-host capture`), as the meta beside it says (a meta
    load_meta would refuse is still a capture's)."""
    return str(_meta_beside(path).get("generator", "")).startswith("tactile-host capture")


def schedule_kind(path) -> str | None:
    """Which schedule ``path`` is, as the meta beside it says ('a calibration schedule' from fitgen schedule, 'a check
    schedule' from fitgen schedule --check), or None."""
    meta = _meta_beside(path)
    if meta.get("check") is True:
        return "a check schedule"
    return "a calibration schedule" if "criterion" in meta and "samples_per_row" in meta else None


def _meta_beside(path) -> dict:
    """The meta beside ``path`` as parsed (not loaded: load_meta checks and relocates what it reads); {} when there is
    none, or it is no JSON object (a FIFO is none: its open would wait for a writer)."""
    import json

    from fitgen.physics.dataset import meta_path

    beside = meta_path(path)
    if not beside.is_file():
        return {}
    try:
        with open(beside, "rb") as f:
            meta = json.loads(f.read(1 << 24))
    except (OSError, ValueError, RecursionError):
        return {}
    return meta if isinstance(meta, dict) else {}


def json_kind(path) -> str | None:
    """Which of the tools' JSON files ``path`` holds (JSON_KINDS; a dataset's meta by its name), or None."""
    import json

    if os.path.realpath(path).endswith(".meta.json"):  # through a link too: it is the file written over
        return "a dataset's meta"
    try:
        with open(path, "rb") as f:
            text = f.read(1 << 24)
    except OSError:
        return None
    try:
        doc = json.loads(text)
    except (ValueError, RecursionError):
        try:  # JSON lines (a run record): its first line
            doc = json.loads(text.split(b"\n", 1)[0])
        except (ValueError, RecursionError):
            return None
    return next((kind for kind, keys in JSON_KINDS if isinstance(doc, dict) and all(k in doc for k in keys)), None)


def check_output_kind(args) -> None:
    """InputError when an output is named as another kind of file than the command writes (a dataset called .json),
    or would replace a capture (measured rows) or another kind of the tools' JSON files (a model over a
    compensation)."""
    from pathlib import Path

    def flag(dest: str) -> str:
        return "-o" if dest == "output" else "--" + dest.replace("_", "-")

    command = getattr(args, "command", None)
    for (cmd, dest), (suffixes, said) in OUTPUT_KINDS.items():
        path = getattr(args, dest, None) if command == cmd else None
        if isinstance(path, str) and Path(path).suffix.lower() in suffixes:
            raise InputError(f"{flag(dest)} {path}: {said}")
    for dest in WRITES:
        path = getattr(args, dest, None)
        writes = WRITES_JSON.get((command, dest))
        if (command, dest) == ("schedule", "output"):
            writes = "a check schedule" if getattr(args, "check", None) is not None else "a calibration schedule"
        if isinstance(path, str) and (what := written_over(path, command, writes, (command, dest) in DATASET_WRITERS)):
            raise InputError(f"{flag(dest)} {path} {what}")


def written_over(path: str, command: str, writes: str | None, dataset: bool = False) -> str:
    """Why ``command`` may not write ``writes`` (one of JSON_KINDS, or None) over ``path``, as the end of a
    refusal ('' when it may): a capture (measured: only capture's own run adds to it), a dataset (its meta would
    describe our text) unless ``dataset`` (the command writes one), another kind of the tools' JSON files."""
    from pathlib import Path

    from fitgen.physics.dataset import meta_path

    if path == "-" or not Path(path).is_file():
        return ""
    if is_capture(path) and not (dataset and command == "capture"):
        return (f"is a capture (rows measured on the sensor, as its meta says): {command} would write over it; give "
                "another name")
    # a capture's meta names its schedule, and resuming it reads the schedule again: a check schedule or a dataset
    # typed over a calibration schedule had left the capture unable to resume
    if (kind := schedule_kind(path)) is not None and kind != writes:
        return (f"is {kind} (poses for tactile-host capture, as its meta says): {command} would write "
                f"{writes or ('a dataset' if dataset else 'another kind of file')} over it; give another name")
    if meta_path(path).is_file() and kind is None and not dataset:
        return (f"is a dataset (its meta is beside it): {command} would write {writes or 'another kind of file'} over "
                "it; give another name")
    kind = json_kind(path)
    if kind is not None and kind != writes:
        return f"is {kind}: {command} would write {writes or 'another kind of file'} over it; give another name"
    return ""
