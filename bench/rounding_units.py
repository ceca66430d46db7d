"""A built unit's equations against verify's rounding gate: rounding's share of the held-out max error in float,
fitted with the drawing's rounding noise alone (before) and with the fit's check on validation poses (after).

verify (`tactile-host verify`, the HIL suite's "held-out accuracy", `fitgen tradeoff`) fails a header whose
rounding adds more than 5 % of the model's own noise-free held-out max error. The fit takes rounding as noise of
ROUNDING_FACTOR (8) unit roundoffs per term (fitgen.fitting.augment), set on the drawings' rings. A built unit's
equations take about three times the terms; fitgen.fitting.family.rounding_checked fits again with the rounding
noise doubled (at most twice) while the share on validation poses (seed 7919) is over 4 %.

Per unit of `paper` (gmr; units 1..U drawn by fitgen.physics.units.draw_unit) and the drawing: the dataset a twin
is fitted on (the paper-sim grid and 5,000 random poses, noise-free), fitted the default way (fit_auto with
FitSettings()) before (no check: ROUNDING_RETRIES 0) and after; held out as the model file is (2,000 random poses,
seed 2026, 5 noise draws at 0.5 mV) on the unit itself, in float by the numpy emulation that is bit-identical to
gcc's C. "share": the worst output's; "noisy max": the deployed figure, after over before per output.

    python bench/rounding_units.py --units 20    # 5 minutes here on 2 cores shared with the tests (286 s)
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import fitgen.fitting.family as family  # noqa: E402
from benchutil import log, parse_args, table  # noqa: E402
from fitgen.fitting.fit import FitSettings  # noqa: E402
from fitgen.fitting.holdout import box_of, deployed_errors, held_out_set  # noqa: E402
from fitgen.physics.pose import POSE_NAMES  # noqa: E402
from fitgen.physics.sensor import load_sensor  # noqa: E402
from fitgen.physics.simulate import grid_poses, parse_grid, pose_rng, random_poses, simulate  # noqa: E402
from fitgen.physics.units import draw_unit  # noqa: E402

GATE = 0.05  # verify's --max-share


def dataset(sensor):
    """The paper-sim grid and 5,000 random poses in its box (`fitgen simulate --grid paper-sim --random 5000`)."""
    grid = grid_poses(parse_grid("paper-sim"))
    poses = np.vstack([grid, random_poses(5000, box_of(grid), pose_rng(0))])
    return simulate(sensor, poses)


def fitted(ds, sensor, retries: int):
    """fit_auto with FitSettings(), the check allowed ``retries`` fits again; the model, its record, seconds."""
    family.ROUNDING_RETRIES = retries
    t = time.perf_counter()
    model, record = family.fit_auto(ds, None, FitSettings(), sensor)
    return model, record, time.perf_counter() - t


def main(argv: list[str] | None = None) -> int:
    args = parse_args(__doc__, lambda ap: ap.add_argument("--units", type=int, default=20,
                                                          help="units 1..U (default 20)"), argv)
    if args.units < 1:
        print("rounding_units.py: error: --units must be at least 1", file=sys.stderr)
        return 2
    drawing = load_sensor("paper").with_transfer("gmr")
    retries = family.ROUNDING_RETRIES
    rows, ratios, over = [], [], {"before": 0, "after": 0}
    for seed in [0, *range(1, args.units + 1)]:
        sensor = drawing if seed == 0 else draw_unit(drawing, seed)[0]
        name = "drawing" if seed == 0 else f"unit {seed}"
        log(f"{name}: simulating, fitting before and after")
        ds = dataset(sensor)
        held = held_out_set(sensor, box_of(ds.poses()), POSE_NAMES)
        got = {}
        for label, r in (("before", 0), ("after", retries)):
            model, record, secs = fitted(ds, sensor, r)
            err = deployed_errors(model, held, sensor, precisions=("float",))["float"]
            worst = max(err, key=lambda o: err[o]["share"])
            got[label] = (err, worst, record, secs)
            if seed and err[worst]["share"] > GATE:
                over[label] += 1
        (eb, wb, _, sb), (ea, wa, ra, sa) = got["before"], got["after"]
        ratio = [ea[o]["noisy_max"] / eb[o]["noisy_max"] for o in POSE_NAMES]
        if seed:
            ratios.append(ratio)
        factor = ra.get("rounding", {}).get("factor", 8)
        rows.append([name, f"{eb[wb]['share']:.1%} ({wb})", f"{ea[wa]['share']:.1%} ({wa})", f"{factor:g}",
                     *[f"{x:.3f}" for x in ratio], f"{sb:.1f} / {sa:.1f}"])
    print(f"paper, gmr; units 1..{args.units} and the drawing; held out on 2,000 poses (seed 2026), float, "
          "noise 0.5 mV (5 draws)\n")
    print(table(["sensor", "worst share, before", "worst share, after", "rounding noise [u]",
                 *[f"noisy max {o}, after / before" for o in POSE_NAMES], "fit s, before / after"], rows))
    r = np.array(ratios)
    print(f"\nunits whose float C fails verify's 5 % gate: {over['before']} of {args.units} before, "
          f"{over['after']} after")
    print("noisy max after / before over the units, per output (median; least, greatest): "
          + ", ".join(f"{o} {np.median(r[:, j]):.3f} ({r[:, j].min():.3f}, {r[:, j].max():.3f})"
                      for j, o in enumerate(POSE_NAMES)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
