"""What every command-line tool here shares: one-line errors with exit status 2, the entry point, Ctrl-C."""

from __future__ import annotations

import argparse
import math
import re
import signal
import sys

from fitgen.base.errors import InputError

EXIT_USAGE = 2
EXIT_CHECK_FAILED = 1


class Parser(argparse.ArgumentParser):
    """argparse with a one-line error (no usage dump) and exit status 2."""

    def __init__(self, *args, **kw):
        super().__init__(*args, **kw)
        # argparse takes '-1e-3' for an option (its pattern knows no exponent): '--input-offset -1e-3' failed; and
        # a list led by a negative number too: '--temperature -10,25' failed where '--temperature=-10,25' worked
        number = r"(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?"
        self._negative_number_matcher = re.compile(rf"^-{number}(\s*,\s*(-?{number})?)*$")

    def error(self, message):  # noqa: D401 - argparse's hook
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message}\n")


def finite(text: str) -> float:
    """An argparse type: a finite number."""
    try:
        x = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not math.isfinite(x):
        raise argparse.ArgumentTypeError(f"{text!r} is not a finite number")
    return x


def count(text: str) -> int:
    """An argparse type: a whole number >= 0."""
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if n < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {n}")
    return n


def noise_volts(text: str) -> float:
    """An argparse type: a noise figure, a finite number >= 0."""
    x = finite(text)
    if x < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {x:g}")
    return x


def tcp_port(text: str) -> int:
    """An argparse type: a TCP port number, 1..65535."""
    n = count(text)
    if not 0 < n < 65536:
        raise argparse.ArgumentTypeError(f"{n} is not a TCP port number (1..65535)")
    return n


def seconds(text: str) -> float:
    """An argparse type: a time limit in seconds, > 0 and at most an hour."""
    from fitgen.base.parse import LONGEST_WAIT, parse_positive

    try:
        return parse_positive(text, "seconds", most=LONGEST_WAIT)
    except InputError as exc:
        raise argparse.ArgumentTypeError(str(exc).removeprefix("seconds ")) from None


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised where the program is, so that its temporary files and half-written outputs are cleaned up
    as for Ctrl-C (the default action ends the process with no cleanup at all)."""


def _terminate(signum, frame):
    raise Terminated()


def run(main_fn, argv=None, prog: str = "") -> int:
    """Call ``main_fn(argv)``; turn bad input into one line on stderr and exit status 2."""
    previous = signal.signal(signal.SIGTERM, _terminate) if _main_thread() else None
    try:
        return int(main_fn(argv) or 0)
    except InputError as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt as exc:
        print(f"{prog}: {'terminated' if isinstance(exc, Terminated) else 'interrupted'}", file=sys.stderr)
        return 143 if isinstance(exc, Terminated) else 130
    except BrokenPipeError:
        return 0
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


def _main_thread() -> bool:
    import threading

    return threading.current_thread() is threading.main_thread()


def command_main(build_parser, argv, prog: str, check=None):
    """A command's entry point: parse ``argv`` with ``build_parser()``, let ``check(args)`` refuse option
    combinations, call the chosen subcommand's ``func(args)``; exit with its status (:func:`run`)."""

    def main_fn(argv) -> int:
        args = build_parser().parse_args(argv)
        if check is not None:
            check(args)
        return args.func(args)

    sys.exit(run(main_fn, argv, prog))


class StopFlag:
    """SIGINT and SIGTERM set a flag a loop checks between steps (the handlers are restored on exit)."""

    def __init__(self):
        self.stopped = False

    def __call__(self) -> bool:
        return self.stopped

    def __enter__(self):
        def handler(signum, frame):
            self.stopped = True

        self._old = {s: signal.signal(s, handler) for s in (signal.SIGINT, signal.SIGTERM)}
        return self

    def __exit__(self, *exc):
        for s, h in self._old.items():
            signal.signal(s, h)


WRITES = ("output", "record", "temp_comp_output", "pose_file")  # the files a command writes
READS = ("model", "run", "tempcomp", "adc", "temp_comp", "rest", "poses", "data", "replay", "sensor", "sim_sensor",
         "capture")  # and those it reads: never one of the written


def check_written(args, files=()) -> None:
    """Every file a command writes, checked before the work: no folder, none of its inputs, no two alike.
    ``files``: the commands whose ``-o`` is a file (for the others it is a folder)."""
    import os
    from pathlib import Path

    from fitgen.base.fileio import check_folder, output_file

    inputs = [p for p in (getattr(args, n, None) for n in READS) if isinstance(p, str) and Path(p).is_file()]
    written = []
    for name in WRITES:
        path = getattr(args, name, None)
        if not isinstance(path, str) or path == "-":
            continue
        if name == "output" and args.func not in files:  # a folder the command makes
            check_folder(path)
            continue
        flag = "-o" if name == "output" else f"--{name.replace('_', '-')}"
        output_file(path, inputs, flag)
        for other_flag, other in written:
            if os.path.abspath(other) == os.path.abspath(path):
                raise InputError(f"{other_flag} and {flag} name the same file {path}: give two")
        written.append((flag, path))


def check_not_empty(args) -> None:
    """An option given as an empty string is refused (it would otherwise fall back to its default unsaid)."""
    for name, value in vars(args).items():
        if isinstance(value, str) and not value.strip():
            flag = ("-o" if name == "output" else name.removesuffix("_pos") if name.endswith("_pos")
                    else "--" + name.replace("_", "-"))
            raise InputError(f"{flag} is empty")
