"""A temperature compensation with its own unit or another: where the note that asks "is it this unit's
compensation?" falls between them (host.tempunit.rest_note, docs/live.md, "Drift").

Each unit drifts its own way (host.simsensor.Drift.typical: about 1 mV/degC offset, -0.1 %/degC gain, one draw per
unit). Per unit, its compensation is fitted as `capture --temperature 15,25,35` fits it (host.temperature.fit_tempcomp,
t0 25 degC) from rows at rest and at one press, each averaged over 16 samples of 0.5 mV noise, and records its rest
readings at t0. The note compares them, taken to the temperature the unit was identified at, with the unit's rest
there: past TARE_UNIT_SHARE of the rms spread of rest readings over units built within the drawing's [tolerances]
(fitgen.fitting.holdout.drawing_rest_spread), the limit read's tare uses. Per drawing: the limit; the unit's own
compensation, the unit identified at 15, 25 and 35 degC (largest offset, share flagged); another unit's compensation
on it (least and median offset, share missed, which before it was 100 %: nothing was said).

    python bench/tempcomp_units.py                    # paper and two-rings, 200 pairs: a few seconds
    python bench/tempcomp_units.py --pairs 1000
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from benchutil import parse_args, table  # noqa: E402
from fitgen.fitting.holdout import drawing_rest_spread  # noqa: E402
from fitgen.physics.sensor import load_sensor  # noqa: E402
from fitgen.physics.units import UnitSpace  # noqa: E402
from host.rest import unit_limit  # noqa: E402
from host.simsensor import Drift  # noqa: E402
from host.temperature import fit_tempcomp  # noqa: E402
from host.tempunit import rest_note  # noqa: E402

LEVELS = (15.0, 25.0, 35.0)
IDENTIFIED_AT = (15.0, 25.0, 35.0)
ROW_NOISE = 0.5e-3 / 4.0  # V: 0.5 mV per sample over 16


def rms(x, axis=None):
    return np.sqrt(np.mean(np.square(x), axis=axis))


def compensation(drift: Drift, poses: np.ndarray, rng):
    """What capture --temperature fits for a unit reading ``poses`` (rest first) under ``drift``."""
    rows = np.vstack([drift.steady(T).apply(poses, 0.0) for T in LEVELS])
    rows = rows + rng.normal(0.0, ROW_NOISE, rows.shape)
    ids = np.tile(np.arange(len(poses)), len(LEVELS))
    return fit_tempcomp(rows, ids, np.repeat(LEVELS, len(poses)), t0=25.0, rest=0)


def offset(tc, rest, degc) -> float:
    return float(rms(tc.reading_at(tc.rest_v, degc) - rest))


def row(drawing_name: str, pairs: int) -> list[str]:
    drawing = load_sensor(drawing_name).with_transfer("gmr")
    space = UnitSpace.of(drawing)
    spread = drawing_rest_spread(drawing)
    limit = unit_limit(spread)[1]
    rng = np.random.default_rng(7)
    thetas = np.array([space.draw(rng) for _ in range(2 * pairs)])
    # at rest and pressed 1 mm down at 1 mm in x: two poses tell gain from offset
    seen = space.readings(thetas, np.array([[0.0] * 5, [1.0, 0.0, -1.0, 0.0, 0.0]]))
    comps = [compensation(Drift.typical(drawing.n_elements, seed=k), seen[k], rng) for k in range(2 * pairs)]
    cells = [drawing_name, f"{limit * 1e3:.1f}"]
    for degc in IDENTIFIED_AT:  # the unit's rest where it was identified, its own drift included
        own = []
        for k in range(pairs):
            rest = Drift.typical(drawing.n_elements, seed=k).steady(degc).apply(seen[k][0], 0.0)
            own.append((offset(comps[k], rest, degc), bool(rest_note(comps[k], rest, spread, "c", "u", degc))))
        worst, flagged = max(o for o, _ in own), np.mean([f for _, f in own])
        cells.append(f"{worst * 1e3:.2f} / {flagged:.0%}")
    other, missed = [], []
    for k in range(pairs):
        rest = seen[k][0]  # identified at t0; the other unit's compensation is k + pairs's
        other.append(offset(comps[k + pairs], rest, 25.0))
        missed.append(not rest_note(comps[k + pairs], rest, spread, "c", "u", 25.0))
    cells += [f"{min(other) * 1e3:.0f}", f"{np.median(other) * 1e3:.0f}", f"{np.mean(missed):.1%} (100%)"]
    return cells


def main() -> None:
    def options(ap):
        ap.add_argument("--pairs", type=int, default=200)
        ap.add_argument("--drawings", default="paper,two-rings")

    args = parse_args(__doc__, options)
    head = (["drawing", "note past (mV rms)"]
            + [f"own, identified at {d:g} degC: largest mV / flagged" for d in IDENTIFIED_AT]
            + ["another unit's: least (mV)", "median (mV)", "missed (before: no note)"])
    print(table(head, [row(name, args.pairs) for name in args.drawings.split(",")]))


if __name__ == "__main__":
    main()
