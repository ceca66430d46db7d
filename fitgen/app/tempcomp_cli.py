"""``tactile-host tempcomp-c`` and ``tempcomp-fit``: a temperature compensation as C, and fitted from captures each
taken at one temperature. A thin layer over host.temperature and host.tempfit."""

from __future__ import annotations

import sys

from fitgen.base.fileio import write_in_folder


def cmd_tempcomp_c(args) -> int:
    from host.temperature import load_tempcomp, render_c

    tc = load_tempcomp(args.tempcomp)
    path = write_in_folder(args.output, f"{args.prefix}_tempcomp.h", render_c(tc, args.prefix, args.precision),
                           [args.tempcomp])
    print(f"wrote {path} ({tc.n} elements about {tc.t0:g} degC, {args.precision}); call "
          f"{args.prefix}_tempcomp(v, degc) on the readings before {args.prefix}_estimate, from a model header of "
          f"the same precision (fitgen codegen --precision {args.precision})", file=sys.stderr)
    return 0


def cmd_tempcomp_fit(args) -> int:
    from host.tempfit import captures_tempcomp

    tc, notes = captures_tempcomp(args.captures, args.t0)
    tc.save(args.output)
    lo, hi = tc.fitted_range
    print(f"wrote {args.output}: temperature compensation about {tc.t0:g} degC from {len(args.captures)} captures "
          f"read at {lo:g} to {hi:g} degC (offsets up to {abs(tc.offset).max() * 1e3:.3g} mV/degC, gains up to "
          f"{abs(tc.gain).max() * 100:.3g} %/degC; residual up to {max(tc.info['residual_rms_v']) * 1e3:.3g} mV rms)",
          file=sys.stderr)
    for note in notes:
        print(f"tactile-host tempcomp-fit: note: {note}", file=sys.stderr)
    return 0


def add_tempcomp(sub) -> None:
    """The ``tempcomp-c`` and ``tempcomp-fit`` subcommands under ``sub``."""
    from fitgen.app.cliutil import finite

    tcc = sub.add_parser("tempcomp-c", help="the temperature compensation as a C99 header (<prefix>_tempcomp.h)")
    tcc.add_argument("tempcomp", metavar="FILE.json", help="from tactile-host capture --temperature or tempcomp-fit")
    tcc.add_argument("-o", "--output", required=True, metavar="DIR", help="folder for <prefix>_tempcomp.h")
    tcc.add_argument("--precision", default="float", choices=("float", "double"), help="C arithmetic (default float)")
    tcc.add_argument("--prefix", default="tm", help="C identifier prefix (default tm)")
    tcc.set_defaults(func=cmd_tempcomp_c)
    tf = sub.add_parser("tempcomp-fit", help="the temperature compensation from captures each taken at one "
                                             "temperature (a stage's: capture --stage cannot take --temperature)")
    tf.add_argument("captures", nargs="+", metavar="CAPTURE.csv", help="captures of one schedule, sensor and "
                    "channel map, each at its own temperature as its thermistor recorded it (temp= in --adc)")
    tf.add_argument("-o", "--output", required=True, metavar="FILE.json", help="the compensation to write")
    tf.add_argument("--t0", type=finite, help="the calibration temperature: one of the captures' (default: the one "
                    "nearest their median)")
    tf.set_defaults(func=cmd_tempcomp_fit)
