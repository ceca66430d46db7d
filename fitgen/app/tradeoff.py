"""``fitgen tradeoff``: its arguments (the knobs' value lists, the accuracy target) and the command
(the sweep is fitgen.c.tradeoff's, its report fitgen.app.tradeoff_report's)."""

from __future__ import annotations

import sys

from fitgen.base.errors import InputError
from fitgen.base.parse import MAX_PENALTY, parse_assignments, parse_penalty
from fitgen.c.codegen import STYLES
from fitgen.c.tradeoff import FAMILY_NAMES, default_target
from fitgen.equations.refine import MAX_STEPS
from fitgen.equations.rounding import PRECISIONS
from fitgen.physics.pose import POSE_LIMITS, POSE_NAMES

MAX_JOBS = 64  # builds measured at once: past the cores any machine here has, each a compiler and an emulator


def parse_knob_list(name: str, spec: str) -> list:
    """A comma-separated list of one knob's values (``--k aic,6``, ``--max-terms none,8`` ...)."""
    out = []
    for part in (x.strip() for x in spec.split(",")):
        if name == "k":
            try:
                val = parse_penalty(part)
            except ValueError:
                raise InputError(f"--k takes aic, bic or numbers > 0 and at most {MAX_PENALTY:g}, "
                                 f"got {part!r}") from None
        elif name == "refine":
            if not (part.isdigit() and int(part) <= MAX_STEPS):
                raise InputError(f"--refine takes step counts from 0 to {MAX_STEPS}, got {part!r}")
            val = int(part)
        elif name == "max_terms":
            if part == "none":
                val = None
            elif part.isdigit() and int(part) >= 1:
                val = int(part)
            else:
                raise InputError(f"--max-terms takes 'none' or whole numbers >= 1, got {part!r}")
        else:
            allowed = {"family": FAMILY_NAMES, "precision": PRECISIONS, "style": STYLES}[name]
            if part not in allowed:
                raise InputError(f"--{name} takes values from {', '.join(allowed)}, got {part!r}")
            val = part
        if val not in out:
            out.append(val)
    return out


def parse_target(spec: str | None, outputs: tuple[str, ...]) -> dict[str, float]:
    """``dz=0.1 thx=2`` for the scene's outputs; the rest from fitgen.physics.observe.DEFAULT_ACCURACY."""
    target = default_target(outputs)
    if spec is not None:
        given = parse_assignments(spec, POSE_NAMES, "--target")
        if not given:
            raise InputError(f"--target {spec!r}: expected NAME=NUMBER, e.g. 'dz=0.1 thx=2'")
        for name, value in given.items():
            if name not in outputs:
                raise InputError(f"--target names {name}, which the scene does not estimate "
                                 f"(its outputs: {', '.join(outputs)})")
            limit = POSE_LIMITS[POSE_NAMES.index(name)]  # an error past the pose limits is no accuracy
            if not 0 < value <= limit:
                raise InputError(f"--target {name} must be a number > 0 and at most {limit:g}, got {value:g}")
            target[name] = value
    return target


def _why_empty(knobs: dict) -> str:
    """Why the given knobs leave no point to sweep: the rules (fitgen.c.tradeoff.left_out) that left their
    combinations out, each once, rather than every rule."""
    from fitgen.c.tradeoff import combinations, left_out

    why = dict.fromkeys(left_out(k) for k in combinations(**knobs))
    return "; ".join(w for w in why if w) or "no combination of the values given is one the sweep runs"


def run_tradeoff(args, sensor) -> int:
    """The command: parse the knobs, sweep, write the report; exit status 1 when rounding is over its share."""
    from fitgen.app.cliutil import EXIT_CHECK_FAILED, STYLE_WITH_FIXED
    from fitgen.app.tradeoff_report import write_outputs
    from fitgen.base.fileio import check_folder
    from fitgen.base.progress import Progress
    from fitgen.c.tradeoff import grid_from, quick_grid, sweep
    from fitgen.physics.scenes import load_scene

    knobs = {name: parse_knob_list(name, getattr(args, name)) for name in ("k", "max_terms", "family", "precision",
                                                                         "style", "refine")
             if getattr(args, name) is not None}
    if not 1 <= args.jobs <= MAX_JOBS:
        raise InputError(f"--jobs must be 1..{MAX_JOBS}, got {args.jobs}")
    if "style" in knobs and knobs.get("precision") == ["fixed"]:  # it would be swept in its one style, unsaid
        raise InputError(f"{STYLE_WITH_FIXED}: leave --style out")
    scene = load_scene(args.scene)
    target = parse_target(args.target, scene.outputs)
    grid = grid_from(**knobs) if args.full or knobs else quick_grid()
    if not grid:
        raise InputError(f"nothing to sweep: {_why_empty(knobs)} (pick other --family, --precision or --refine)")
    if not 0 < args.max_share <= 1:
        raise InputError(f"--max-share must be a share in (0, 1] of the model's held-out max error, got "
                         f"{args.max_share:g}")
    check_folder(args.output)  # -o is first written after the sweep, minutes from now
    bar = Progress("tradeoff", len(grid))
    with bar:
        result = sweep(sensor, scene, grid, target=target, seed=args.seed, jobs=args.jobs,
                       progress=lambda note, total: (setattr(bar, 'total', total), bar.update(1, note)), max_share=args.max_share, core=args.core)
    result.given = (args.sensor, *(("--transfer", args.transfer) if args.transfer else ()))
    result.scene_given = args.scene
    paths, text = write_outputs(result, args.output)
    print(text, end="")
    print("wrote " + ", ".join(str(p) for p in paths), file=sys.stderr)
    if result.over_share:
        print(f"FAIL: rounding adds more than {100 * args.max_share:.3g} % of the model's held-out max error at points "
              + ", ".join(str(i + 1) for i in result.over_share), file=sys.stderr)
        return EXIT_CHECK_FAILED
    return 0
