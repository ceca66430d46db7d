"""Cycles per estimate on the ATmega328P (Arduino Uno) in simavr, float and fixed point, with the AVR's
results held against Python's and the fixed-point plans' accuracy against the double model.

    PYTHONPATH=. python3 bench/avr_cost.py > /tmp/avr.md    # about 10 s; progress on stderr

Needs avr-gcc and avr-size (apt: gcc-avr binutils-avr avr-libc), gcc, and libsimavr known to pkg-config
(simavr libsimavr-dev libelf-dev pkg-config); checked before the fits.

The paper sensor in volts (its gmr transfer, as the ADCs read it), fitted as `fitgen fit --family
no-roots` fits it (noise- and float-aware), with `--max-terms 6` too (a model small enough for 16x16->32
products), and as `fitgen fit --family all` for the float rows with roots. 200 random poses in the paper grid's box, with reading noise, are the inputs (float: the
volts rounded to float; fixed: the volts rounded to the sensor's ADC codes). Each build runs all 200
in libsimavr at 16 MHz (fitgen.c.avr.run_on_avr); the cycles are simavr's count between two GPIOR0
writes around tm_estimate. Fixed point in three builds of the same model: the plan for the Uno's
16-bit multiply (`--target uno`: 16x16->32 products or byte-aligned 32x32->64 sums where each output's
error bound allows, fitgen.equations.fixednarrow), the 32-bit plan (every product 32x32->64, as on a
Cortex-M), both with the header's AVR assembly for the 32x32->64 products (fitgen/c/avrasm.py), and the
32-bit plan through the header's portable C (TM_PORTABLE_C: avr-gcc's 64-bit library calls), which is
what the header was before the assembly. Prints two markdown tables: the costs (flash: the whole
program less the inputs, 4 bytes each; static RAM: .data + .bss, the stack not counted) and each
build's largest deviation from the double model on the same inputs, per output.
"""

from __future__ import annotations

import numpy as np

from benchutil import fmt, log, need_tools, parse_args, table
from fitgen.c.avr import F_CPU, run_on_avr
from fitgen.c.targets import TARGETS
from fitgen.equations.inputscale import plan_at
from fitgen.fitting.fit import FitSettings, fit_model
from fitgen.physics.pose import POSE_NAMES, POSE_UNITS
from fitgen.physics.sensor import load_sensor
from fitgen.physics.simulate import PAPER_GRIDS, grid_poses, random_poses, simulate

N = 200
UNO_BITS = TARGETS["uno"].mul_bits
SMALL = "no-roots --max-terms 6"
# (model, precision, style, the fixed plan's multiply width, portable C)
BUILDS = [(fam, *b) for fam in ("no-roots", SMALL) for b in (
    ("fixed", "-", UNO_BITS, False), ("fixed", "-", 32, False), ("fixed", "-", 32, True), ("float", "table", None, False),
    ("float", "unrolled", None, False))] + [("all", "float", "table", None, False), ("all", "float", "unrolled", None, False)]


def _label(precision: str, mul_bits: int | None, portable: bool) -> str:
    if precision != "fixed":
        return precision
    plan = "uno plan (`--target uno`)" if mul_bits == UNO_BITS else "32-bit plan"
    return f"fixed, {plan}, " + ("portable C" if portable else "AVR assembly")


def _kind(o) -> str:
    return "16x16->32" if o.acc_bits == 32 else "32x32->64 byte-aligned" if o.aligned else "32x32->64"


def main() -> None:
    parse_args(__doc__)  # no options: one it does not know is refused, not ignored
    need_tools("avr-gcc", "avr-size", "gcc", libs=("simavr",))
    sensor = load_sensor("paper").with_transfer("gmr")
    grid = grid_poses(PAPER_GRIDS["paper-sim"])
    ds = simulate(sensor, grid)
    log("fitting the no-roots and all-powers models ...")
    models = {"no-roots": fit_model(ds, settings=FitSettings.family("no-roots")),
              SMALL: fit_model(ds, settings=FitSettings.family("no-roots", max_terms=6)),
              "all": fit_model(ds, settings=FitSettings.family("all"))}
    rng = np.random.default_rng(0)
    box = {k: (float(grid[:, i].min()), float(grid[:, i].max())) for i, k in enumerate(POSE_NAMES)}
    x = simulate(sensor, random_poses(N, box, rng), noise=sensor.noise, seed=1).inputs
    rows, acc_rows, plan_rows = [], [], []
    for family, precision, style, mul_bits, portable in BUILDS:
        m = models[family]
        label = _label(precision, mul_bits, portable)
        log(f"{family} {label} {style} in simavr ...")
        if precision == "fixed":
            fm = plan_at(m, None, None, mul_bits)[0]
            codes = np.round(x / fm.input_lsb)
            run = run_on_avr(m, codes, "fixed", mul_bits=mul_bits, portable=portable)
            want, want_status = fm.predict_codes(codes)
            got = fm.to_real(run.outputs)
            double = fm.reference_model().predict(fm.code_values(codes))
            check = "`fitgen predict --precision fixed --codes" + (" --target uno`" if mul_bits == UNO_BITS else "`")
            bound = [f"{b:.2g}" for b in fm.error_bound()]
            if mul_bits == UNO_BITS:
                plan_rows.append([family] + [f"{_kind(o)}, {o.error_bound:.2g} / {b:.2g}"
                                             for o, b in zip(fm.outputs, fm.budget)])
        else:
            xf = x.astype(np.float32).astype(float)
            run = run_on_avr(m, x, "float", style)
            want, want_status = m.predict(xf, with_status=True, precision="float")
            got, double = run.outputs, m.predict(xf)
            check = "`fitgen predict --precision float`"
            bound = ["-"] * len(m.output_names)
        same = int(np.sum(np.all(run.outputs == want, axis=1) & (run.status == want_status)))
        terms = sum(len(e.terms) for e in m.equations)
        rows.append([family, label, style, str(terms), f"{run.flash - 4 * x.size:,}", f"{run.ram:,}",
                     f"{np.mean(run.cycles):,.0f}", f"{np.min(run.cycles):,}", f"{np.max(run.cycles):,}",
                     f"{run.per_second():,.0f}", f"{same}/{N} bit for bit with {check}"])
        dev = np.abs(got - double).max(axis=0)
        acc_rows.append([family, label, style] + [f"{fmt(d)} ({b})" for d, b in zip(dev, bound)])
    print(f"ATmega328P at {F_CPU / 1e6:g} MHz in simavr, {N} estimates per build (avr-gcc -O2, "
          "tables and inputs in flash):\n")
    print(table(["model", "precision", "style", "terms", "flash without the inputs (B)", "static RAM (B)",
                 "cycles per estimate, mean", "min", "max", "estimates/s at 16 MHz", "results"], rows))
    units = dict(zip(POSE_NAMES, POSE_UNITS))
    print(f"\nLargest deviation from the double model on the same {N} inputs (fixed: the values of the codes the "
          "C took; float: the readings rounded to float), per output, and in brackets the fixed plan's proven "
          "bound on it:\n")
    print(table(["model", "precision", "style"] + [f"{o} [{units[o]}]" for o in models["no-roots"].output_names],
                acc_rows))
    print("\nThe uno plan, output by output (fitgen.equations.fixednarrow: 16x16->32 products where every bound "
          "stays within its budget, 1% of the model's max training error; else byte-aligned 32x32->64 sums if they "
          "do; else the 32-bit plan's):\n")
    print(table(["model"] + [f"{o}: kind, bound / budget" for o in models["no-roots"].output_names], plan_rows))


if __name__ == "__main__":
    main()
