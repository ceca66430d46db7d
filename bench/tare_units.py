"""A twin's tare, with its own unit resting on the bus or another: where the note that asks "is this the unit the
model was fitted for?" falls between them (host.rest.another_unit_note, docs/calibration.md, step 8).

A tare maps whatever rests on the bus onto the twin's rest. Its offsets are one unit's drift, or another unit's rest
less this one's. The note compares their rms over the elements with TARE_UNIT_SHARE of the rms spread of the rest
readings over units built within the drawing's [tolerances] (fitgen.fitting.holdout.rest_spread, what `fitgen fit`
records for a twin). Per drawing: the threshold; pairs of units drawn within the tolerances, their rest readings'
rms difference (noise-free, gmr volts) and the share the note misses; one unit's temperature drift at 5, 10, 20 and
30 degC from its capture (host.simsensor.Drift.typical's coefficients: about 1 mV/degC offset, -0.1 %/degC gain, one
draw per unit) and the share the note wrongly flags.

    python bench/tare_units.py                    # paper and two-rings, 200 pairs: a few seconds
    python bench/tare_units.py --pairs 1000
"""

from __future__ import annotations

import argparse

import numpy as np

from fitgen.fitting.holdout import rest_spread
from fitgen.physics.sensor import load_sensor
from fitgen.physics.units import UnitSpace, draw_unit
from host.rest import TARE_UNIT_SHARE
from host.simsensor import Drift

DEGC = (5.0, 10.0, 20.0, 30.0)


def rms(x, axis=None):
    return np.sqrt(np.mean(np.square(x), axis=axis))


def row(drawing_name: str, pairs: int) -> list[str]:
    drawing = load_sensor(drawing_name).with_transfer("gmr")
    space = UnitSpace.of(drawing)
    unit = draw_unit(drawing, 1)[0]
    # as fit records it for a twin of this drawing (the unit file's [unit] table names the drawing)
    unit.source["unit"] = {"drawing": drawing_name}
    threshold = TARE_UNIT_SHARE * rms(rest_spread(unit))
    rng = np.random.default_rng(5)
    rest = space.readings(np.array([space.draw(rng) for _ in range(2 * pairs)]), np.zeros((1, 5)))[:, 0, :]
    between = rms(rest[:pairs] - rest[pairs:], axis=1)
    cells = [drawing_name, f"{threshold * 1e3:.1f}", f"{between.min() * 1e3:.0f}",
             f"{np.median(between) * 1e3:.0f}", f"{np.mean(between <= threshold):.1%} (100%)"]
    for dT in DEGC:
        drift = np.array([rms(Drift.typical(drawing.n_elements, seed=k).steady(25.0 + dT).apply(r, 0.0) - r)
                          for k, r in enumerate(rest[:pairs])])
        cells.append(f"{np.median(drift) * 1e3:.1f} / {np.mean(drift > threshold):.0%}")
    return cells


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--pairs", type=int, default=200)
    ap.add_argument("--drawings", default="paper,two-rings")
    args = ap.parse_args()
    head = (["drawing", "note past (mV rms)", "other unit: least (mV)", "median (mV)", "missed (before: no note)"]
            + [f"drift {d:g} degC: median mV / flagged" for d in DEGC])
    print("| " + " | ".join(head) + " |")
    print("|" + "---|" * len(head))
    for name in args.drawings.split(","):
        print("| " + " | ".join(row(name, args.pairs)) + " |")


if __name__ == "__main__":
    main()
