"""The choice among a trade-off sweep's measured points (fitgen.c.tradeoff): the Pareto front on (cost, score),
the recommendation, and the points left out of both because they estimate an output no better than a constant."""

from __future__ import annotations

import math

import numpy as np

ACCURACY_TIE = 0.01  # when no point meets the target: scores within 1 % of the best count as equal


def pareto_front(cost: list[float], score: list[float]) -> list[int]:
    """Indices of the points no other point dominates (lower or equal in both, lower in one),
    in order of cost. Points equal in both are all on the front; a NaN or None is never on it."""
    ok = [i for i in range(len(cost)) if cost[i] is not None and score[i] is not None
          and math.isfinite(cost[i]) and math.isfinite(score[i])]
    front = []
    for i in ok:
        dominated = any(cost[j] <= cost[i] and score[j] <= score[i] and (cost[j] < cost[i] or score[j] < score[i])
                        for j in ok)
        if not dominated:
            front.append(i)
    return sorted(front, key=lambda i: (cost[i], score[i], i))


def recommend(cost: list[float], score: list[float], flash: list[float | None],
              close: float = ACCURACY_TIE) -> tuple[int | None, bool]:
    """(index, met): the fewest instructions among points with score <= 1 (ties: less flash, then
    the lower score); if none meets the target, met False and the most accurate point, where scores
    within a factor ``1 + close`` of the best count as equal (then: fewer instructions, less flash).
    (None, False) when no point was measured."""
    def val(x):
        return math.inf if x is None or not math.isfinite(x) else x

    ok = [i for i in range(len(cost)) if math.isfinite(val(cost[i])) and math.isfinite(val(score[i]))]
    if not ok:
        return None, False
    meet = [i for i in ok if score[i] <= 1.0]
    if meet:
        return min(meet, key=lambda i: (cost[i], val(flash[i]), score[i], i)), True
    best = min(score[i] for i in ok)
    near = [i for i in ok if score[i] <= best * (1 + close)]
    return min(near, key=lambda i: (cost[i], val(flash[i]), score[i], i)), False


def constant_outputs(points: list, outputs, truth: np.ndarray, skip: list[int]) -> list[int]:
    """The measured points (not in ``skip``) that estimate some output no better than a constant: its equation has
    no terms, or its RMS error with noise is no less than the spread (std) of its held-out truth, which the
    constant at the truth's mean reaches. Such a point can meet a loose target on a wide box (a constant tilt
    on +-5 deg is 2.9 deg rms) while estimating nothing; each gets a note."""
    spread = {o: float(np.std(truth[:, j])) for j, o in enumerate(outputs)}
    found = []
    for i, p in enumerate(points):
        if p.score is None or i in skip:
            continue
        flat = [o for o in outputs if p.terms_per_output.get(o, 0) == 0 or p.errors[o]["noisy_rms"] >= spread[o]]
        if flat:
            o = flat[0]
            why = "has no terms (a constant)" if p.terms_per_output.get(o, 0) == 0 else "does no better than a constant"
            p.note = (f"{o} {why}: RMS {p.errors[o]['noisy_rms']:.3g} with noise against its spread "
                      f"{spread[o]:.3g} over the held-out poses: not recommended")
            found.append(i)
    return found
