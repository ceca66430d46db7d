"""Cycles per estimate on the ATmega328P (Arduino Uno) in simavr, float and fixed point, with the AVR's
results held against Python's.

    PYTHONPATH=. python3 bench/avr_cost.py > /tmp/avr.md

The paper sensor in volts (its gmr transfer, as the ADCs read it), fitted as `fitgen fit --family
no-roots` fits it (noise- and float-aware), and as `fitgen fit --family all` for the float rows with
roots. 200 random poses in the paper grid's box, with reading noise, are the inputs (float: the
volts rounded to float; fixed: the volts rounded to the sensor's ADC codes). Each build runs all 200
in libsimavr at 16 MHz (fitgen.c.avr.run_on_avr); the cycles are simavr's count between two GPIOR0
writes around tm_estimate. Prints a markdown table; its flash is the whole program's less the
inputs (4 bytes each), its static RAM the program's .data + .bss (the stack not counted).
"""

from __future__ import annotations

import numpy as np

from benchutil import log, table
from fitgen.c.avr import F_CPU, run_on_avr
from fitgen.equations.fixedpoint import plan_at
from fitgen.fitting.fit import FitSettings, fit_model
from fitgen.physics.pose import POSE_NAMES
from fitgen.physics.sensor import load_sensor
from fitgen.physics.simulate import PAPER_GRIDS, grid_poses, random_poses, simulate

N = 200


def main() -> None:
    sensor = load_sensor("paper").with_transfer("gmr")
    grid = grid_poses(PAPER_GRIDS["paper-sim"])
    ds = simulate(sensor, grid)
    log("fitting the no-roots and all-powers models ...")
    models = {"no-roots": fit_model(ds, settings=FitSettings.family("no-roots")),
              "all": fit_model(ds, settings=FitSettings.family("all"))}
    rng = np.random.default_rng(0)
    box = {k: (float(grid[:, i].min()), float(grid[:, i].max())) for i, k in enumerate(POSE_NAMES)}
    x = simulate(sensor, random_poses(N, box, rng), noise=sensor.noise, seed=1).inputs
    rows = []
    builds = [("no-roots", "fixed", "-"), ("no-roots", "float", "table"), ("no-roots", "float", "unrolled"),
              ("all", "float", "table"), ("all", "float", "unrolled")]
    for family, precision, style in builds:
        m = models[family]
        log(f"{family} {precision} {style} in simavr ...")
        if precision == "fixed":
            fm = plan_at(m, None, None)[0]
            codes = np.round(x / fm.input_lsb)
            run = run_on_avr(m, codes, "fixed")
            want, want_status = fm.predict_codes(codes)
            check = "`fitgen predict --precision fixed --codes`"
        else:
            run = run_on_avr(m, x, "float", style)
            want, want_status = m.predict(x.astype(np.float32).astype(float), with_status=True, precision="float")
            check = "`fitgen predict --precision float`"
        same = int(np.sum(np.all(run.outputs == want, axis=1) & (run.status == want_status)))
        terms = sum(len(e.terms) for e in m.equations)
        rows.append([family, precision, style, str(terms), f"{run.flash - 4 * x.size:,}", f"{run.ram:,}",
                     f"{np.mean(run.cycles):,.0f}", f"{np.min(run.cycles):,}", f"{np.max(run.cycles):,}",
                     f"{run.per_second():,.0f}", f"{same}/{N} bit for bit with {check}"])
    print(f"ATmega328P at {F_CPU / 1e6:g} MHz in simavr, {N} estimates per build (avr-gcc -O2, "
          "tables and inputs in flash):\n")
    print(table(["family", "precision", "style", "terms", "flash without the inputs (B)", "static RAM (B)",
                 "cycles per estimate, mean", "min", "max", "estimates/s at 16 MHz", "results"], rows))


if __name__ == "__main__":
    main()
