"""The console scripts. Each imports its command's module under a Ctrl-C guard: the imports (numpy's) take a
moment, and a Ctrl-C then ends the command as one at any other time does, in one line, not a traceback."""

from __future__ import annotations

import sys
from importlib import import_module

EXIT_INTERRUPTED = 130


def _main(module: str, prog: str) -> None:
    try:
        main = import_module(module).main
    except KeyboardInterrupt:
        print(f"{prog}: interrupted", file=sys.stderr)
        sys.exit(EXIT_INTERRUPTED)
    main()


def fitgen() -> None:
    _main("fitgen.app.cli", "fitgen")


def tactile_host() -> None:
    _main("fitgen.app.host_cli", "tactile-host")


def tactile_hil() -> None:
    _main("fitgen.app.hil_cli", "tactile-hil")
