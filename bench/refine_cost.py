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

BENCH cycles through 16 readings: the sensor's, noise-free, at 16 random poses in the grid's box (seed
READINGS_SEED; hil.firmware.render_firmware's bench_inputs), on which Python's refinement takes every step
whole. Beside them, the firmware's built-in vectors, each input swept apart from the others: readings no pose
gives, on which the equations' first estimate lies far outside the box and the step stops part-way (the
forward model's value not positive); the table's last column counts the steps Python takes whole on each.
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

READINGS_SEED = 7  # the poses BENCH's readings are simulated at (not the training data's seed 1)
N_VECTORS = 16  # the firmware's own BENCH vectors: as many, so that both sets cycle alike


def builtin_vectors(model) -> np.ndarray:
    """device.c's BENCH vectors: input i of vector k at (2m + 1) / 32 of its range, m = (k + 5 i) mod 16."""
    lo, hi = np.array(model.input_min), np.array(model.input_max)
    m = (np.arange(N_VECTORS)[:, None] + 5 * np.arange(model.n_inputs)[None, :]) % 16
    return lo + (hi - lo) * ((2 * m + 1) / 32)


def whole_steps(model, inputs) -> int:
    """Rows on which Python's float refinement moves the equations' estimate: its step went through."""
    base = dataclasses.replace(model, refine=None)
    return int(np.sum(np.any(model.predict(inputs, precision="float") != base.predict(inputs, precision="float"),
                             axis=1)))


def main() -> None:
    parse_args(__doc__)  # no options: one it does not know is refused, not ignored
    need_tools("qemu-system-arm", "arm-none-eabi-gcc", "arm-none-eabi-size")
    sensor = load_sensor("paper")
    grid = grid_poses(PAPER_GRIDS["paper-sim"])
    train = simulate(sensor, np.vstack([grid, random_poses(20000, box_of(grid), pose_rng(1))]))
    refined = fit_model(train, settings=FitSettings.family("harmonics", max_terms=30, refine=1), sensor=sensor)
    log("fitted")
    readings = simulate(sensor, random_poses(N_VECTORS, box_of(grid), pose_rng(READINGS_SEED))).inputs
    sets = (("readings at poses in the box", readings), ("built-in vectors", None))
    rows = []
    for name, model in (("equations alone", dataclasses.replace(refined, refine=None)), ("+ refine 1", refined)):
        for style in ("table", "unrolled"):
            for inputs_name, inputs in sets:
                with start_target(model, "mps2", precision="float", style=style, bench_inputs=inputs) as emu:
                    with Device.open(emu.url, timeout=5) as dev:
                        ins = bench_instructions(dev)["instructions"]
                taken = whole_steps(model, builtin_vectors(model) if inputs is None else inputs) \
                    if model.refine else None
                rows.append([name, style, inputs_name, f"{ins:,.0f}", f"{emu.size['flash']:,}",
                             f"{emu.size['ram']:,}", "-" if taken is None else f"{taken} of {N_VECTORS}"])
                log(f"{name}, {style}, {inputs_name} done")
    print("# The refinement's cost on the emulated Cortex-M4F (bench/refine_cost.py)\n")
    print(f"paper, harmonics max 30, {refined.refine.n_terms} forward terms, {len(refined.refine.monomials)} "
          f"monomials per step; float; BENCH's readings at {N_VECTORS} poses (seed {READINGS_SEED}).\n")
    print(table(["model", "style", "BENCH's inputs", "instructions per estimate (icount)", "flash (bytes)",
                 "RAM (bytes)", "whole steps (Python)"], rows))

if __name__ == "__main__":
    main()
