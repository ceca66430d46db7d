"""The console scripts. Each imports its command's module under a Ctrl-C, SIGTERM and SIGHUP guard: the imports
(numpy's) take a moment, and a signal then ends the command as one at any other time does, in one line, not a
traceback."""

from __future__ import annotations

import sys
from importlib import import_module


def _main(module: str, prog: str) -> None:
    try:  # under Python's own Ctrl-C until cliutil's guard is in place: nothing here imported before it
        util = import_module("fitgen.app.cliutil")
    except KeyboardInterrupt:
        _end(prog, "interrupted", 130)
    previous = util.catch_ending()
    try:
        main = import_module(module).main
    except KeyboardInterrupt as exc:
        _end(prog, *util.ended_by(exc))
    util.restore(previous)  # the defaults again, which the command's run() saves and gives back at its end
    try:
        main()
    except SystemExit:
        # the command has said its last line and chosen its status: a signal in the tens of milliseconds the
        # interpreter takes to shut down had ended it by SIGINT with no line, its work done
        util.ignore_ending()
        raise


def _end(prog: str, said: str, status: int) -> None:
    if sys.stderr is not None:  # closed (2>&-): print(file=None) would write on stdout
        print(f"{prog}: {said}", file=sys.stderr)
    sys.exit(status)


def fitgen() -> None:
    _main("fitgen.app.cli", "fitgen")


def tactile_host() -> None:
    _main("fitgen.app.host_cli", "tactile-host")


def tactile_hil() -> None:
    _main("fitgen.app.hil_cli", "tactile-hil")
