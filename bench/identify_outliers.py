"""Does identify name the row of a capture that the physics does not explain, and only such a row? Does it refuse a
capture of a unit with a dead or a miswired element, and only such a capture?

bench/units.py's 20 units and their headline capture (40 D-optimal poses, 0.01 mm rig, rows of 16 samples, the readings
from magpylib: an independent field model), with an exact zero (scheduled for one) and with the zero off first contact
by 0.02 mm rms (scheduled as `fitgen schedule` does by default, its rows in contact pressed for that zero);
then the same captures with the indenter slipped in dx on one row (the first pressed deepest) by 0.05 to 0.5 mm,
its label unchanged. Per kind of capture: how many identify refuses (reduced chi-square over 3, the check before
rows were named: the baseline), how many name a row (a reading beyond 5 standard deviations,
fitgen.fitting.identify.OUTLIER_LIMIT; in the refusal's line when refused) and whether it is the slipped one first,
and the largest standardized residual of the slipped row and of the others (medians and the worst over the units).
Then the captures with an element that does not respond (element 3 reads a constant, its mean over the capture) and
with two elements' channels swapped (3 and 6; 3 and 4, neighbours) or the two ADCs exchanged (v5-v8 read in v1-v4
and the other way round): how many the chi-square refuses, and how many identify refuses
because only a unit far outside its tolerances explains them (a parameter beyond PRIOR_LIMIT = 5 prior spreads,
fitgen.fitting.verdict.check_explained), and what a refusal names as the one thing to blame: the element or pair
of elements whose readings, left out or exchanged, or the turn of the ring whose order, leave a capture that a unit
within its tolerances explains (fitgen.fitting.blame.blame). Before 2026-11-29 blame tried no turn of the ring, and
pairs only on captures with more than three rows standing out (the column beside it), so that neighbours swapped
and ADCs exchanged were refused without a cause. For every kind, the largest |parameter| in prior spreads.

    python bench/identify_outliers.py    # 47 minutes here sharing 2 cores with the test suite (2805 s)
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import units as U  # noqa: E402
from benchutil import fmt, log, parse_args, table  # noqa: E402
from fitgen.base.errors import InputError  # noqa: E402
from fitgen.fitting.identify import CHI2_LIMIT, OUTLIER_LIMIT, PRIOR_LIMIT, identify  # noqa: E402
from fitgen.fitting.verdict import check_explained  # noqa: E402

SLIPS = (0.0, 0.05, 0.1, 0.2, 0.5)  # mm in dx on one row


def dead(y: np.ndarray) -> np.ndarray:
    """Element 3 does not respond: it reads one constant (its mean over the capture), not a rail."""
    y = y.copy()
    y[:, 2] = y[:, 2].mean()
    return y


def swapped(y: np.ndarray) -> np.ndarray:
    """Elements 3 and 6 wired to each other's channels."""
    return y[:, [0, 1, 5, 3, 4, 2, 6, 7]]


def neighbours(y: np.ndarray) -> np.ndarray:
    """Elements 3 and 4, neighbours on the ring, wired to each other's channels."""
    return y[:, [0, 1, 3, 2, 4, 5, 6, 7]]


def adcs(y: np.ndarray) -> np.ndarray:
    """The two ADCs exchanged: elements 1-4 read in v5-v8 and 5-8 in v1-v4, the ring read turned by half."""
    return y[:, [4, 5, 6, 7, 0, 1, 2, 3]]


def main() -> None:
    parse_args(__doc__)  # no options: one it does not know is refused, not ignored
    ctx = U.Ctx(U.N_HELD_QUICK, U.DRAWS, U.N_RANDOM, (U.HEAD,))
    U.CTX = ctx
    ctx.make_schedules()
    rows, slipped = [], []
    for zero in (0.0, U.ZERO_SIM):
        labels = ctx.schedules[(*U.HEAD, U.ZEROED) if zero else U.HEAD]  # scheduled for the zero it has
        deep = int(np.nonzero(labels[:, 2] == labels[:, 2].min())[0][0])
        shifted = labels[deep:deep + 1].copy()
        slipped.append(f"row {deep + 1} (" + " ".join(f"{a}={v:g}" for a, v in zip(("dx", "dy", "dz"), labels[deep]))
                       + f") with the zero {'off' if zero else 'exact'}")
        caps = []
        for seed in range(1, U.N_UNITS + 1):
            unit, _ = U.draw_unit(ctx.drawing, seed)
            caps.append((unit, U.capture(unit, labels, U.HEAD[1], [seed, U.HEAD[0], 3], zero=zero)))
        faults = [(f"slip {slip:g} mm" if slip else "none", slip, None) for slip in SLIPS]
        faults += [("element 3 dead", 0.0, dead), ("elements 3 and 6 swapped", 0.0, swapped),
                   ("elements 3 and 4 swapped", 0.0, neighbours), ("two ADCs exchanged", 0.0, adcs)] if not zero else []
        for kind, slip, fault in faults:
            refused, beyond, blamed, named, right, own, others, zmax, many = 0, 0, [], 0, 0, [], [], [], 0
            for unit, y in caps:
                y = y.copy() if fault is None else fault(y)
                if slip:
                    shifted[0, 0] = labels[deep, 0] + slip
                    both = U.magpylib_readings(unit, np.vstack([shifted, labels[deep:deep + 1]]))
                    y[deep] += both[0] - both[1]
                ident = identify(ctx.drawing, y, labels, ctx.noise / np.sqrt(U.SAMPLES), rig_error=U.HEAD[1],
                                 zero_error=U.ZERO_SIM if zero else 0.0)
                refused += ident.reduced_chi2 > CHI2_LIMIT  # refused, it names the row in its one line
                beyond += ident.reduced_chi2 <= CHI2_LIMIT and bool(ident.outside_tolerances())  # the next refusal
                try:
                    check_explained(ident, "the capture", U.PRESET, "the bench's")
                except InputError as exc:
                    found = re.search(r"elements? (\d+)(?: and (\d+))? \(v", str(exc))
                    turned = re.search(r"\(the ring ([^)]*)\)", str(exc))
                    blamed += ([" and ".join(g for g in found.groups() if g)] if found
                               else [f"the ring {turned.group(1)}"] if turned else [])
                zmax.append(np.abs(ident.space.in_spreads(ident.theta)).max())
                worst = ident.row_worst
                out = [i for i, _ in ident.outlying_rows()]
                named += bool(out)
                many += len(out) > 3  # before 2026-11-29 blame tried pairs only then
                right += out[:1] == [deep]
                own.append(worst[deep])
                others.append(np.delete(worst, deep).max())
            n = len(caps)
            rows.append([f"{zero:g}", kind, f"{refused} of {n}", f"{beyond} of {n}",
                         ", ".join(f"{blamed.count(k)} x {k}" for k in sorted(set(blamed))) or "none",
                         f"{many} of {n}",
                         f"{fmt(np.median(zmax))} / {fmt(np.max(zmax))}", f"{named} of {n}",
                         f"{right} of {n}" if slip else "-", f"{fmt(np.median(own))} / {fmt(np.max(own))}",
                         f"{fmt(np.median(others))} / {fmt(np.max(others))}"])
            log(f"zero {zero:g} mm, {kind}")
    print("## Captures the physics does not explain: rows named, captures refused\n")
    print(f"{U.N_UNITS} units of `{U.PRESET}` in `{U.TRANSFER}`, the headline capture ({U.HEAD[0]} poses, "
          f"{U.HEAD[1]:g} mm rig, magpylib's readings), scheduled for the zero it has (exact, or off by "
          f"{U.ZERO_SIM:g} mm rms: fitgen schedule's default); the slipped row is {' and '.join(slipped)}. "
          f"A row is named "
          f"beyond {OUTLIER_LIMIT:g} standard deviations; a capture is refused over a reduced chi-square of "
          f"{CHI2_LIMIT:g} (the baseline, which says nothing of which row; a refusal now names the row that stands out "
          f"most); the captures it passes are refused when a parameter lies beyond {PRIOR_LIMIT:g} prior spreads (a unit "
          "within its tolerances is drawn within 3). The largest |parameter| in prior spreads and the largest "
          "standardized residual: median / worst over the captures.\n")
    print(table(["zero off [mm rms]", "what is wrong", "refused (chi-square)", "refused (beyond the tolerances)",
                 "refusals naming what to blame", "more than 3 rows standing out",
                 "largest parameter [prior sd]", "captures naming a row",
                 "naming the slipped row first", "the slipped row", "every other row"], rows))


if __name__ == "__main__":
    main()
