"""Option values every layer parses the same way."""

from __future__ import annotations

import math

from fitgen.base.errors import InputError


def parse_assignments(spec: str, allowed, what: str) -> dict[str, float]:
    """``a=1 b=2`` (space, comma or semicolon separated) into a dict of floats."""
    out = {}
    for part in spec.replace(",", " ").replace(";", " ").split():
        name, sep, value = part.partition("=")
        if not sep or name not in allowed:
            raise InputError(f"{what} {spec!r}: expected NAME=NUMBER with NAME in {', '.join(allowed)}")
        try:
            out[name] = float(value)
        except ValueError:
            raise InputError(f"{what} {spec!r}: {value!r} is not a number") from None
    return out


def parse_numbers(text: str) -> list[float] | None:
    """Numbers separated by commas or spaces; None when one of them is not a number."""
    try:
        return [float(x) for x in text.replace(",", " ").split()]
    except ValueError:
        return None


def parse_positive(text: str, what: str, *, integer: bool = False, zero: bool = False):
    """An option's number, > 0 (>= 0 with ``zero``), whole with ``integer``; else InputError naming ``what``."""
    try:
        val = int(text) if integer else float(text)
    except ValueError:
        raise InputError(f"{what} {text!r} is not a{' whole' if integer else ''} number") from None
    if not math.isfinite(val) or val < 0 or (val == 0 and not zero):
        raise InputError(f"{what} must be {'>= 0' if zero else '> 0'}, got {text}")
    return val
