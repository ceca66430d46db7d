"""The ``tactile-hil`` command: hardware-in-the-loop checks (see issue 6; not yet built)."""

from __future__ import annotations

import sys

from fitgen.cliutil import Parser, run


def build_parser() -> Parser:
    p = Parser(prog="tactile-hil", description=__doc__)
    p.add_subparsers(dest="command", required=True, parser_class=Parser)
    return p


def _main(argv) -> int:
    build_parser().parse_args(argv)
    return 0


def main(argv=None) -> int:
    sys.exit(run(_main, argv, "tactile-hil"))
