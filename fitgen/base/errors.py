"""The one exception type that command-line tools turn into a single line and exit status 2."""

import math


class InputError(ValueError):
    """Bad input from a user: a file, an option or a value. The message is shown as is."""


def finite_number(val, where: str) -> float:
    """``val`` as a float if it is a finite JSON number (not a bool); else InputError naming ``where``."""
    if isinstance(val, bool) or not isinstance(val, (int, float)) or not math.isfinite(val):
        raise InputError(f"{where} must be a finite number, got {val!r}")
    return float(val)
