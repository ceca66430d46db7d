"""Atomic file writes and content hashes: nothing half-written, identical input gives identical bytes."""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
from pathlib import Path

from fitgen.base.errors import InputError


def folder_of(path: str | os.PathLike) -> Path:
    """The folder ``path`` is to be written in; one line (InputError) when it does not exist, which a command
    checks before its work, not after it."""
    path = Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise InputError(f"cannot write {path}: {folder} is a file, not a folder" if folder.exists()
                         else f"cannot write {path}: folder {folder} does not exist")
    return folder


def output_file(path: str | os.PathLike, inputs=(), flag: str = "-o") -> Path:
    """``path`` checked as a file to write before the work: a name, not a folder, in a folder that exists and
    takes a new file, and none of the command's ``inputs`` (which it would overwrite); InputError otherwise."""
    path = Path(path)
    if path.name in ("", ".", "..") or path.is_dir():
        raise InputError(f"cannot write {path}: it is a folder; give a file name")
    # a file made and removed as write_atomic will make it: permissions do not tell (root passes os.access, and
    # /proc refuses new files to root too), and an output written last would fail after all the work
    try:
        fd, tmp = tempfile.mkstemp(dir=folder_of(path), prefix=f".{path.name}.", suffix=".tmp")
    except OSError as exc:
        raise InputError(f"cannot write {path}: {exc.strerror}") from None
    os.close(fd)
    os.unlink(tmp)
    for given in inputs:
        if given is not None and path.exists() and Path(given).exists() and os.path.samefile(given, path):
            raise InputError(f"{flag} {path} is the input {given}: writing it would destroy it; give another name")
    return path


def write_atomic(path: str | os.PathLike, data: str | bytes) -> Path:
    """Write ``data`` to ``path`` through a temporary file in the same folder and a rename."""
    path = Path(path)
    folder = folder_of(path)
    raw = data.encode() if isinstance(data, str) else data
    try:
        fd, tmp = tempfile.mkstemp(dir=folder, prefix=f".{path.name}.", suffix=".tmp")
    except OSError as exc:
        raise InputError(f"cannot write {path}: {exc.strerror}") from None
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(raw)
            fh.flush()
            os.fsync(fh.fileno())
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except OSError as exc:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise InputError(f"cannot write {path}: {exc.strerror}") from None
    return path


def make_folder(folder: str | os.PathLike) -> Path:
    """``folder``, created (and its parents) when missing; one line (InputError) when it cannot be."""
    folder = Path(folder)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"cannot create {folder}: {exc.strerror}") from None
    return folder


def check_folder(folder: str | os.PathLike, flag: str = "-o") -> Path:
    """``folder`` checked as one a command will make and write into, without making it (so that a command refused
    later leaves none behind): a name, not a file, under a folder that can be written; InputError otherwise."""
    path = Path(folder)
    if not str(folder).strip():
        raise InputError(f"{flag} is empty: give a folder")
    if path.exists() and not path.is_dir():
        raise InputError(f"{flag} {path}: it is a file; give a folder")
    base = path.absolute()
    while not base.exists():
        base = base.parent
    if not base.is_dir() or not os.access(base, os.W_OK | os.X_OK):
        raise InputError(f"cannot create {path}: {base} is {'not a folder' if not base.is_dir() else 'read-only'}")
    return path


def write_in_folder(folder: str | os.PathLike, name: str, data: str | bytes) -> Path:
    """:func:`write_atomic` into ``folder/name``, creating ``folder`` (and its parents) when missing."""
    return write_atomic(make_folder(folder) / name, data)


def canonical_json(obj) -> str:
    """JSON with sorted keys and no spacing variation, for hashing."""
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), allow_nan=False)


def sha256_hex(data: str | bytes) -> str:
    raw = data.encode() if isinstance(data, str) else data
    return hashlib.sha256(raw).hexdigest()


def read_text(path: str | os.PathLike, what: str) -> str:
    """A text file's content; a missing or unreadable file is an InputError naming ``what``."""
    try:
        return Path(path).read_text(encoding="utf-8-sig")  # -sig: the byte-order mark spreadsheets write
    except FileNotFoundError:
        raise InputError(f"{what} {path}: no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{what} {path}: cannot read: {exc}") from None
