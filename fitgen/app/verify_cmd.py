"""``tactile-host verify``: the generated C compiled and run against the Python evaluator, build by build."""

from __future__ import annotations

from fitgen.app.cliutil import EXIT_CHECK_FAILED, STYLE_WITH_FIXED
from fitgen.base.errors import InputError
from fitgen.base.progress import Progress


def cmd_verify(args) -> int:
    """Each build's check as a table, then PASS or FAIL; exit status 1 when one fails."""
    from fitgen.c.codegen import STYLES, check_magnitudes
    from fitgen.equations.model import load_model

    from fitgen.c.verify import check_vectors, data_inputs, held_out_from_args, no_held_out_note, verify

    check_vectors(args.vectors)
    model = load_model(args.model)
    precisions = ("double", "float") if args.precision == "both" else (args.precision,)
    if args.style is not None and args.precision == "fixed":  # as codegen refuses it
        raise InputError(STYLE_WITH_FIXED)
    styles = STYLES if args.style in (None, "both") else (args.style,)
    if (args.input_lsb is not None or args.input_offset is not None) and args.precision != "fixed":
        raise InputError("--input-lsb and --input-offset apply to --precision fixed only")
    if args.fma and args.precision == "fixed":
        raise InputError("--fma does not apply to --precision fixed")
    for precision in precisions:  # refused before the work (verify's vectors past the domain would overflow)
        if precision != "fixed":
            check_magnitudes(model, precision)
    extra = data_inputs(model, args.data) if args.data else None
    # the fixed-point header has one form (straight-line code): checked once
    builds = [(p, s) for p in precisions for s in (("unrolled",) if p == "fixed" else styles)]
    ok = True
    with Progress("verify", len(builds) + 1) as bar:
        bar.update(0, "held-out readings")
        held_out = held_out_from_args(model, args)
        for precision, style in builds:
            bar.update(1, f"{precision}" + ("" if precision == "fixed" else f"/{style}"))
            res = verify(model, precision, style, cc=args.cc, runner=args.runner or "", prefix=args.prefix,
                         n_random=args.vectors, extra_inputs=extra, fma=args.fma, input_lsb=args.input_lsb,
                         input_offset=args.input_offset, held_out=held_out, max_share=args.max_share)
            bar.close()  # the bar's line gives way to the table; the next update draws it again
            print(res.table())
            if held_out is None and not args.no_held_out:
                print(no_held_out_note(model))
            print("PASS" if res.ok else "FAIL: " + "; ".join(res.failures))
            print(flush=True)
            ok &= res.ok
    return 0 if ok else EXIT_CHECK_FAILED
