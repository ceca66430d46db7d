"""What a text is: its hash, its canonical JSON, whether it reads as TOML, JSON or CSV, and TOML read with one
line for what it is not."""

from __future__ import annotations

import hashlib
import json
import sys

if sys.version_info >= (3, 11):  # the one place the TOML parser is chosen: the loaders import it from here
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

from fitgen.base.errors import InputError


def canonical_json(obj) -> str:
    """JSON with sorted keys and no spacing variation, for hashing."""
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), allow_nan=False)


def sha256_hex(data: str | bytes) -> str:
    raw = data.encode() if isinstance(data, str) else data
    return hashlib.sha256(raw).hexdigest()


def text_kind(text: str) -> str:
    """What a text a loader could not read reads as, for the refusal to name it: "toml" (keys in TOML: a sensor or
    unit file), "json" (a model or a meta file), "csv" (a comma in its first line, comments and blank lines
    skipped: a dataset), or "" for none of these."""
    first = next((ln.strip() for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")), "")
    if first.startswith("[") or "=" in first:
        try:
            if tomllib.loads(text):
                return "toml"
        except ValueError:  # TOMLDecodeError is one
            pass
    if first.startswith("{"):  # no TOML starts so
        return "json"
    if first.startswith("[") or "=" in first:  # a TOML file with a slip (a bracket dropped) unless JSON reads it
        try:
            json.loads(text)
            return "json"
        except ValueError:
            return ""
    return "csv" if "," in first else ""


def load_toml(text: str, origin: str, kind: str) -> dict:
    """``text`` read as TOML; else InputError naming what it reads as (JSON, CSV) or what the parser says. An
    integer past the 4,300 digits Python converts is tomllib's plain ValueError, not TOMLDecodeError: caught too."""
    try:
        return tomllib.loads(text)
    except ValueError as exc:
        seen = {"json": "JSON (a model or meta file?)", "csv": "CSV (a dataset?)"}.get(text_kind(text))
        # the int limit's advice (call sys.set_int_max_str_digits) is not the user's to take
        raise InputError(f"{origin}: " + (f"{seen}, not a {kind} (TOML)" if seen
                                          else f"not valid TOML: {str(exc).split(';')[0]}")) from None
