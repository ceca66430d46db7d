"""What the refinement costs on a Cortex-M4F: the same equations with and without one step, in the
reference firmware on the emulated core (QEMU mps2-an386, -icount).

Run:

    python bench/refine_cost.py > out.md      # about 1 minute; progress on stderr

Needs qemu-system-arm and arm-none-eabi-gcc/size with newlib (apt: qemu-system-arm gcc-arm-none-eabi
libnewlib-arm-none-eabi); checked before the fit.

The model: the paper layout, the harmonics family capped at 30 terms, fitted on the paper-sim grid
followed by 20,000 random poses (seed 1), with `refine=1` (at most 30 forward terms per element),
as in bench/harmonics.py's `+ refine 1, dense` row; the baseline is the same model with the
refinement removed. Instructions per estimate from BENCH under -icount shift=0 (two runs of
different length, the difference per estimate); flash and RAM of the firmware image.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from benchutil import log, need_tools, parse_args, table

from fitgen.fitting.fit import FitSettings, fit_model
from fitgen.fitting.holdout import box_of
from fitgen.physics.sensor import load_sensor
from fitgen.physics.simulate import PAPER_GRIDS, grid_poses, pose_rng, random_poses, simulate
from hil.emulate import bench_instructions, start_target
from host.device import Device


def main() -> None:
    parse_args(__doc__)  # no options: one it does not know is refused, not ignored
    need_tools("qemu-system-arm", "arm-none-eabi-gcc", "arm-none-eabi-size")
    sensor = load_sensor("paper")
    grid = grid_poses(PAPER_GRIDS["paper-sim"])
    train = simulate(sensor, np.vstack([grid, random_poses(20000, box_of(grid), pose_rng(1))]))
    refined = fit_model(train, settings=FitSettings.family("harmonics", max_terms=30, refine=1), sensor=sensor)
    log("fitted")
    rows = []
    for name, model in (("equations alone", dataclasses.replace(refined, refine=None)), ("+ refine 1", refined)):
        for style in ("table", "unrolled"):
            with start_target(model, "mps2", precision="float", style=style) as emu:
                with Device.open(emu.url, timeout=5) as dev:
                    ins = bench_instructions(dev)["instructions"]
            rows.append([name, style, f"{ins:,.0f}", f"{emu.size['flash']:,}", f"{emu.size['ram']:,}"])
            log(f"{name}, {style} done")
    print("# The refinement's cost on the emulated Cortex-M4F (bench/refine_cost.py)\n")
    print(f"paper, harmonics max 30, {refined.refine.n_terms} forward terms, {len(refined.refine.monomials)} "
          "monomials per step; float.\n")
    print(table(["model", "style", "instructions per estimate (icount)", "flash (bytes)", "RAM (bytes)"], rows))


if __name__ == "__main__":
    main()
