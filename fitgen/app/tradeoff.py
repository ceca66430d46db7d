"""The arguments of ``fitgen tradeoff``: the knobs' value lists and the accuracy target
(the sweep is fitgen.c.tradeoff's, its report fitgen.app.tradeoff_report's)."""

from __future__ import annotations

import math

from fitgen.base.errors import InputError
from fitgen.base.parse import parse_assignments, parse_penalty
from fitgen.c.codegen import STYLES
from fitgen.c.tradeoff import FAMILY_NAMES, default_target
from fitgen.equations.refine import MAX_STEPS
from fitgen.equations.rounding import PRECISIONS
from fitgen.physics.pose import POSE_NAMES


def parse_knob_list(name: str, spec: str) -> list:
    """A comma-separated list of one knob's values (``--k aic,6``, ``--max-terms none,8`` ...)."""
    out = []
    for part in (x.strip() for x in spec.split(",")):
        if name == "k":
            try:
                val = parse_penalty(part)
            except ValueError:
                raise InputError(f"--k takes aic, bic or numbers > 0, got {part!r}") from None
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
            if not (value > 0 and math.isfinite(value)):
                raise InputError(f"--target {name} must be a finite number > 0, got {value:g}")
            target[name] = value
    return target
