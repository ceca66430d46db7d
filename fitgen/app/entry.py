"""The console scripts. Each imports its command's module under a Ctrl-C, SIGTERM and SIGHUP guard: the imports
(numpy's) take a moment, and a signal then ends the command as one at any other time does, in one line, not a
traceback."""

from __future__ import annotations

import sys
from importlib import import_module

from fitgen.app.cliutil import catch_ending, ended_by, restore


def _main(module: str, prog: str) -> None:
    previous = catch_ending()
    try:
        main = import_module(module).main
    except KeyboardInterrupt as exc:
        said, status = ended_by(exc)
        if sys.stderr is not None:  # closed (2>&-): print(file=None) would write on stdout
            print(f"{prog}: {said}", file=sys.stderr)
        sys.exit(status)
    restore(previous)  # the defaults again, which the command's run() saves and gives back at its end
    main()


def fitgen() -> None:
    _main("fitgen.app.cli", "fitgen")


def tactile_host() -> None:
    _main("fitgen.app.host_cli", "tactile-host")


def tactile_hil() -> None:
    _main("fitgen.app.hil_cli", "tactile-hil")
