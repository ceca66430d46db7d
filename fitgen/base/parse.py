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
        if name in out:
            raise InputError(f"{what} {spec!r}: {name} is given twice")
        try:
            out[name] = float(value)
        except ValueError:
            raise InputError(f"{what} {spec!r}: {value!r} is not a number") from None
    return out


def parse_numbers(text: str) -> list[float] | None:
    """Numbers separated by commas or spaces; None when one of them is not a number or an item between commas is
    empty ('15,,35' is a slip, not 15,35)."""
    if "," in text and any(not part.strip() for part in text.split(",")):
        return None
    try:
        return [float(x) for x in text.replace(",", " ").split()]
    except ValueError:
        return None


LONGEST_WAIT = 3600.0  # s: a time limit or pause beyond an hour is a slip of the keyboard (and 1e300 overflows sleep)
LONGEST_RUN = 30 * 86400.0  # s: a recording's --duration; a month of drift is the longest anyone records
MAX_TRIES = 100  # tries per I2C transfer or per pose: past them a silent chip or a shaking stage is not waited out
# samples averaged per captured row: 10,000 is a minute a row at the ADCs' fastest, far past where flicker stops the
# gain (tactile-host noise); beyond it a capture would never finish a row
MAX_ROW_SAMPLES = 10_000
DEGC = (-40.0, 125.0)  # degC: a thermistor's reading the tools take (an NTC's usual rated range)


def parse_positive(text: str, what: str, *, integer: bool = False, zero: bool = False, most: float | None = None):
    """An option's number, > 0 (>= 0 with ``zero``, <= ``most`` if given), whole with ``integer``; else
    InputError naming ``what``."""
    try:
        val = int(text) if integer else float(text)
    except ValueError:
        raise InputError(f"{what} {text!r:.40} is not a{' whole' if integer else ''} number") from None
    if integer and val >= 2 ** 63:  # no count is as large, and math.isfinite of an int past float's range raises
        bound = f"at most {most:g}" if most is not None else "a whole number below 2^63"
        raise InputError(f"{what} must be {bound}, got {str(text).strip()[:20]}... ({len(str(val))} digits)")
    if not math.isfinite(val) or val < 0 or (val == 0 and not zero):
        bound = ("a whole number " + (">= 0" if zero else ">= 1")) if integer else \
            ("a finite number " + (">= 0" if zero else "> 0"))
        raise InputError(f"{what} must be {bound}, got {text}")
    if most is not None and val > most:
        raise InputError(f"{what} must be at most {most:g}, got {text}")
    return val


class OutOfRange(ValueError):
    """A number, but outside the values the option takes."""


# a penalty per term past it admits no term on any dataset (BIC's log(n) reaches 100 at 10^43 rows): a slip, whose
# 1e300 wrote a model of no terms and 1e308 one "holding a non-finite number"
MAX_PENALTY = 100.0


def parse_penalty(text: str) -> str | float:
    """A penalty per term: ``aic`` or ``bic`` (as given) or a number > 0, at most MAX_PENALTY.

    ValueError when ``text`` is none of these; :class:`OutOfRange` (a ValueError) when it is a
    number out of that range, so that a caller can word the two apart.
    """
    if text in ("aic", "bic"):
        return text
    k = float(text)
    if not (0 < k <= MAX_PENALTY):
        raise OutOfRange(text)
    return k


MAX_NOISE = 1000.0  # V or mT rms: past every reading a sensor gives (a slip of the exponent): readings of it overflow


def parse_noise(text: str, finite: bool = True) -> float:
    """A noise figure: a number >= 0, and finite unless ``finite`` is False.

    ValueError when ``text`` is no number; :class:`OutOfRange` when the number is out of range.
    """
    noise = float(text)
    if not (noise >= 0 and (noise != math.inf or not finite)):
        raise OutOfRange(text)
    return noise


def parse_names(spec: str, allowed, what: str) -> tuple[str, ...]:
    """``a,b`` (comma separated) into a tuple of names, at least one, each one of ``allowed``."""
    names = tuple(x.strip() for x in spec.split(",") if x.strip())
    if not names or any(n not in allowed for n in names):
        raise InputError(f"{what} takes names from {','.join(allowed)}, got {spec!r}")
    return names
