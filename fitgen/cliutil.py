"""What every command-line tool here shares: one-line errors with exit status 2."""

from __future__ import annotations

import argparse
import sys

from .errors import InputError

EXIT_USAGE = 2
EXIT_CHECK_FAILED = 1


class Parser(argparse.ArgumentParser):
    """argparse with a one-line error (no usage dump) and exit status 2."""

    def error(self, message):  # noqa: D401 - argparse's hook
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message}\n")


def run(main_fn, argv=None, prog: str = "") -> int:
    """Call ``main_fn(argv)``; turn bad input into one line on stderr and exit status 2."""
    try:
        return int(main_fn(argv) or 0)
    except InputError as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print(f"{prog}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        return 0


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
