"""Whether a model runs in float: its numbers and every value its terms take over the input domain within
float's range, and the domain as floats (rounded outward), which the float C and its Python emulation share."""

from __future__ import annotations

import numpy as np

from fitgen.equations.terms import element_powers

_TOP = float(np.finfo(np.float32).max)


def float_domain(model) -> tuple[np.ndarray, np.ndarray]:
    """The domain of ``model`` (a fitgen.equations.model.Model) as floats, rounded outward so that every double
    inside it stays inside."""
    with np.errstate(over="ignore"):  # beyond float's range: inf, refused where a literal is written
        lo = model.input_min.astype(np.float32)
        hi = model.input_max.astype(np.float32)
    lo = np.where(lo.astype(float) > model.input_min, np.nextafter(lo, np.float32(-np.inf)), lo)
    hi = np.where(hi.astype(float) < model.input_max, np.nextafter(hi, np.float32(np.inf)), hi)
    lo = np.where((model.input_min > 0) & (lo <= 0), np.float32(np.finfo(np.float32).tiny), lo)
    return lo.astype(float), hi.astype(float)


def float_problem(model) -> str:
    """Why ``model`` cannot run in float ('' when it can): a number of its equations or domain past float's
    range, which the float C cannot hold (its literal would be refused) and the float emulation would turn into
    inf; or a power of an input that float cannot hold at an end of the domain (a reading near 0 under a negative
    power: v^-e is 1/v^e, and v^e underflows to 0), where the float C would give inf or NaN."""
    for eq in model.equations:
        for x in (eq.intercept, *eq.coefficients):
            if not abs(x) <= _TOP:
                return (f"output {eq.name}: the coefficient {x:.4g} does not fit in a float (|x| <= {_TOP:.3g}): "
                        "readings on another scale than the sensor's? rescale them, or use double")
    for x in (*model.input_min, *model.input_max):
        if not abs(x) <= _TOP:
            return f"the input domain reaches {x:.4g}, past float's range: rescale the readings, or use double"
    if problem := _power_problem(model):
        return problem
    if any(t.harm for e in model.equations for t in e.terms):
        total = np.float32(0)
        for x in float_domain(model)[0].astype(np.float32):  # left to right, as the float C sums them
            total = total + x
        if not total > 0:
            return (f"the inputs' lowest sum is {float(total)!r} in float, which the harmonics divide by (> 0 "
                    "only in double): use double")
    if model.refine is not None:
        x = max(map(abs, model.refine.numbers()))
        if not x <= _TOP:
            return (f"refine: a weight, prior or forward coefficient of {x:.4g} does not fit in a float "
                    f"(|x| <= {_TOP:.3g}): use double")
    return ""


def _power_problem(model) -> str:
    """The first power of an input that, computed in float as the C computes it, is not finite at an end of the
    float domain (each power is monotone in |v| there: its ends bound it), or ''."""
    lo, hi = float_domain(model)
    ends = np.array([lo, hi], dtype=np.float32)
    for eq in model.equations:
        for t in eq.terms:
            if not t.element:
                continue
            with np.errstate(all="ignore"):  # inf and 0 are what is looked for
                vals = element_powers(ends[:, t.element - 1], t.exponent)
            if not np.all(np.isfinite(vals)):
                at = ends[int(np.argmin(np.isfinite(vals))), t.element - 1]
                return (f"output {eq.name}: its term {t.text} is not finite in float at v{t.element} = {float(at):.4g}, "
                        "an end of the inputs' range (a reading near 0, or one on another scale than the others?): "
                        "use double, or leave such readings out")
    return ""
