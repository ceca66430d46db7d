"""The one exception type that command-line tools turn into a single line and exit status 2."""

from __future__ import annotations

import math
import numbers


class InputError(ValueError):
    """Bad input from a user: a file, an option or a value. The message is shown as is."""


class RowError(InputError):
    """InputError about the data row ``row`` (from 0) of the rows a step was given, so that a caller that left
    rows out before can say it as the file numbers it (:meth:`numbered`)."""

    def __init__(self, before: str, row: int, after: str):
        self.before, self.row, self.after = before, row, after
        super().__init__(f"{before}{row + 1}{after}")

    def numbered(self, number: int) -> str:
        return f"{self.before}{number}{self.after}"


def is_whole_number(val) -> bool:
    """Whether ``val`` is a whole number as Python or numpy holds one (np.int64(3)), not a bool nor a float (40.0:
    range() and numpy's seeds refuse it deep inside)."""
    return isinstance(val, numbers.Integral) and not isinstance(val, bool)


def is_finite_number(val) -> bool:
    """Whether ``val`` is a finite JSON number (not a bool), or a numpy one a notebook passes (np.float32(6)); an
    integer past float's range is not (JSON holds any, and float() of it raises)."""
    if isinstance(val, bool) or not isinstance(val, numbers.Real):
        return False
    try:
        return math.isfinite(val)
    except OverflowError:
        return False


def shown(val, width: int = 60) -> str:
    """``repr(val)`` for a refusal's one line, cut to ``width`` characters (a number of 4,000 digits had filled a
    screen); an integer past the digits Python converts (repr raises on it) said as such."""
    try:
        text = repr(val)
    except ValueError:
        return "an integer of too many digits"
    return text if len(text) <= width else text[:width - 3] + "..."


def check_seed(seed, what: str = "a seed") -> None:
    """InputError naming ``what`` unless ``seed`` is a whole number >= 0 (numpy's SeedSequence says no seed's name)."""
    if not (is_whole_number(seed) and seed >= 0):
        raise InputError(f"{what} must be a whole number >= 0, got {shown(seed)}")


def finite_number(val, where: str) -> float:
    """``val`` as a float if it is a finite JSON number (not a bool); else InputError naming ``where``."""
    if not is_finite_number(val):
        raise InputError(f"{where} must be a finite number, got {shown(val)}")
    return float(val)


KINDS = {dict: "an object", list: "a list"}


def of_kind(val, kind: type, where: str, fix: str = ""):
    """``val`` if it is a ``kind``; else InputError naming ``where`` (then ``fix``: what to do)."""
    if not isinstance(val, kind):
        raise InputError(f"{where} must be {KINDS.get(kind, kind.__name__)}, got {shown(val)}{fix}")
    return val


def required(obj: dict, key: str, where: str, kind: type | None = None, fix: str = ""):
    """``obj[key]``, a file's entry at ``where``; InputError naming it where it is missing or not a ``kind``."""
    if key not in obj:
        raise InputError(f"{where} is missing{fix}")
    return obj[key] if kind is None else of_kind(obj[key], kind, where, fix)
