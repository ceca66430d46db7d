"""How far the refinement's prior should trust the equations: its scale chosen on validation poses.

Run:

    python bench/refine_prior.py > out.md      # about 2 minutes on 2 cores; progress on stderr

Per layout (paper, ring-vertical; transfer raw): the harmonics family capped at 30 terms, fitted on
the paper-sim grid followed by 20,000 random poses (seed 1), then one refinement step
(fitgen.equations.refine) whose prior covariance is prior_scale^2 times the equations' expected error
covariance, for several prior scales. Judged on the validation poses of fitgen.fitting.family (1,000
random poses, seed 7919, 2 noise draws; not the held-out seed 2026 that every reported figure
uses), float arithmetic: the noisy RMS per output and their geometric mean. fitgen.fitting.refine_fit's
PRIOR_SCALE is the scale this table favours.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from benchutil import fmt, log, parse_args, table

from fitgen.fitting.family import VALIDATION_DRAWS, VALIDATION_POSES, VALIDATION_SEED
from fitgen.fitting.fit import FitSettings, fit_model
from fitgen.fitting.holdout import box_of, held_out_set
from fitgen.physics.pose import POSE_NAMES
from fitgen.fitting.refine_fit import PRIOR_SCALE, fit_refinement
from fitgen.physics.sensor import load_sensor
from fitgen.physics.simulate import PAPER_GRIDS, grid_poses, pose_rng, random_poses, simulate

SCALES = (0.5, 1.0, 1.5, 2.0, 3.0, 4.0)


def run_layout(layout: str) -> str:
    sensor = load_sensor(layout)
    grid = grid_poses(PAPER_GRIDS["paper-sim"])
    box = box_of(grid)
    train = simulate(sensor, np.vstack([grid, random_poses(20000, box, pose_rng(1))]))
    model = fit_model(train, settings=FitSettings.family("harmonics", max_terms=30), sensor=sensor)
    val = held_out_set(sensor, box, POSE_NAMES, n=VALIDATION_POSES, seed=VALIDATION_SEED, draws=VALIDATION_DRAWS)
    log(f"{layout}: equations fitted")

    def row(name, m):
        err = m.predict(val.noisy, precision="float") - val.noisy_truth
        rms = np.sqrt(np.mean(err**2, axis=0))
        return [name] + [fmt(x) for x in rms] + [fmt(float(np.exp(np.mean(np.log(rms)))))]

    rows = [row("equations alone", model)]
    ref = None
    for scale in SCALES:
        ref, _ = fit_refinement(train, model, steps=1, noise=sensor.noise, prior_scale=scale)
        rows.append(row(f"refine 1, prior scale {scale:g}" + (" (default)" if scale == PRIOR_SCALE else ""),
                        dataclasses.replace(model, refine=ref)))
        log(f"{layout}: scale {scale:g} done")
    head = ["fit"] + [f"{o} RMS, noise" for o in POSE_NAMES] + ["geometric mean"]
    return f"## {layout}\n\n" + table(head, rows) + "\n"


def main() -> None:
    parse_args(__doc__)  # no options: one it does not know is refused, not ignored
    print("# The refinement's prior scale on validation poses (bench/refine_prior.py)\n")
    print(f"Noisy RMS errors (mm, deg) on {VALIDATION_POSES} validation poses x {VALIDATION_DRAWS} noise draws "
          f"(seed {VALIDATION_SEED}), float.\n")
    for layout in ("paper", "ring-vertical"):
        print(run_layout(layout))
    log("done")


if __name__ == "__main__":
    main()
