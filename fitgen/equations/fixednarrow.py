"""Which outputs of a fixed-point plan run on 16x16->32 products, for cores with a 16-bit multiply (8-bit AVR).

On the ATmega328P a 32x32->64 product costs a library call of ~200 cycles, a 16x16->32 one a few MUL
instructions. :func:`plan_narrow` starts from the 32-bit plan (every product 32x32->64) and moves
whole outputs, in the model's order, onto int16 operands and coefficients with an int32
accumulator, keeping a move when every output's proven error bound stays within
:func:`narrow_budget`. The bounds are the planner's own (fitgen.equations.fixedpoint): each
narrowing rounds a value to 16 bits and that rounding is carried through like any other.
"""

from __future__ import annotations

import math
from dataclasses import replace

from fitgen.base.errors import InputError
from fitgen.equations.fixedmodel import FixedModel
from fitgen.equations.model import Model

# the share of the model's own max error (on its training data) that rounding to 16 bits may add
NARROW_SHARE = 0.01


def reference_errors(model: Model) -> dict[str, float]:
    """Per output, the model's max error on its training data (its fit notes), or where the notes hold
    none, fitgen.physics.observe.DEFAULT_ACCURACY (0.1 mm, 1 deg)."""
    from fitgen.physics.observe import DEFAULT_ACCURACY

    def get(d, key):
        return d.get(key) if isinstance(d, dict) else None

    out = {}
    for eq in model.equations:
        err = get(get(get(get(model.fit_info, "outputs"), eq.name), "model_training_error"), "max")
        ok = isinstance(err, (int, float)) and math.isfinite(err) and err > 0
        out[eq.name] = float(err) if ok else DEFAULT_ACCURACY.get(eq.name, 0.1)
    return out


def narrow_budget(model: Model, wide: FixedModel, share: float = NARROW_SHARE) -> dict[str, float]:
    """Per output, the error bound a 16-bit plan may reach: ``share`` of :func:`reference_errors`, and never
    less than the 32-bit plan's own bound (where that is already larger, the output stays 32-bit)."""
    ref = reference_errors(model)
    return {o.name: max(o.error_bound, share * ref[o.name]) for o in wide.outputs}


def plan_narrow(model: Model, plan, share: float = NARROW_SHARE) -> FixedModel:
    """The plan for a 16-bit multiply. ``plan(narrow, aligned)`` is the planner with the outputs named in
    the frozenset ``narrow`` on 16-bit operands and those in ``aligned`` with byte-aligned term shifts
    (fitgen.equations.fixedpoint._plan). Output by output, in the model's order: 16-bit if every bound
    stays within budget, else 32-bit with byte-aligned shifts if they do, else as the 32-bit plan."""
    best = plan(frozenset(), frozenset())
    budget = narrow_budget(model, best, share)
    narrow: frozenset = frozenset()
    aligned: frozenset = frozenset()
    for eq in model.equations:
        for trial in ((narrow | {eq.name}, aligned), (narrow, aligned | {eq.name})):
            try:
                fm = plan(*trial)
            except InputError:
                continue  # its terms do not fit an int32 accumulator with an LSB of at most 1 unit
            if all(o.error_bound <= budget[o.name] for o in fm.outputs):
                (narrow, aligned), best = trial, fm
                break
    return replace(best, mul_bits=16, budget=tuple(budget[o.name] for o in best.outputs))
