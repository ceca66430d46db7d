"""The ``tactile-host`` command: tools that run beside hardware."""

from __future__ import annotations

import sys

from fitgen.cliutil import EXIT_CHECK_FAILED, Parser, run
from fitgen.errors import InputError


def cmd_verify(args) -> int:
    from fitgen.codegen import PRECISIONS, STYLES
    from fitgen.dataset import load_dataset
    from fitgen.model import load_model

    from .verify import verify

    model = load_model(args.model)
    precisions = PRECISIONS if args.precision == "both" else (args.precision,)
    styles = STYLES if args.style == "both" else (args.style,)
    extra = None
    if args.data:
        ds = load_dataset(args.data, min_rows=1)
        if ds.n_inputs != model.n_inputs:
            raise InputError(f"dataset {args.data} has {ds.n_inputs} inputs; the model takes {model.n_inputs}")
        extra = ds.inputs
    if args.vectors < 0:
        raise InputError("--vectors must be >= 0")
    ok = True
    for precision in precisions:
        for style in styles:
            res = verify(model, precision, style, cc=args.cc, runner=args.runner or "", prefix=args.prefix,
                         n_random=args.vectors, extra_inputs=extra)
            print(res.table())
            print("PASS" if res.ok else "FAIL: " + "; ".join(res.failures))
            print()
            ok &= res.ok
    return 0 if ok else EXIT_CHECK_FAILED


def build_parser() -> Parser:
    p = Parser(prog="tactile-host", description=__doc__)
    sub = p.add_subparsers(dest="command", required=True, parser_class=Parser)
    v = sub.add_parser("verify", help="compile the generated C and compare it with the Python evaluation")
    v.add_argument("model", metavar="MODEL")
    v.add_argument("--precision", default="both", choices=("double", "float", "both"))
    v.add_argument("--style", default="both", choices=("table", "unrolled", "both"))
    v.add_argument("--cc", default="gcc", help="C compiler command, with flags if needed (default gcc)")
    v.add_argument("--runner", help="prefix to run the binary with, e.g. qemu-arm")
    v.add_argument("--prefix", default="tm", help="C identifier prefix (default tm)")
    v.add_argument("--vectors", type=int, default=2000, help="random vectors inside the domain (default 2000)")
    v.add_argument("--data", help="also run the rows of this dataset")
    v.set_defaults(func=cmd_verify)
    return p


def _main(argv) -> int:
    args = build_parser().parse_args(argv)
    return args.func(args)


def main(argv=None) -> int:
    sys.exit(run(_main, argv, "tactile-host"))
