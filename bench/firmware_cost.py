"""Cost of the paper model on the emulated Cortex-M4 (QEMU mps2-an386, -icount) and HIL round trips.

    python bench/firmware_cost.py > /tmp/firmware.md

Prints markdown: per build, flash and RAM of the firmware image, instructions per estimate (BENCH
under -icount shift=0: two runs of different length, the difference per estimate), and the round
trip and batched throughput of EVAL over the emulator's TCP UART and the host build's pty.
"""

from __future__ import annotations

import sys

from fitgen.fit import FitSettings, fit_model
from fitgen.sensor import load_sensor
from fitgen.simulate import PAPER_GRIDS, grid_poses, simulate
from fitgen.terms import FAMILIES
from hil.emulate import bench_instructions, start_target
from hil.suite import check_timing
from host.device import Device

BUILDS = [("float", "table", False), ("float", "unrolled", False), ("float", "unrolled", True),
          ("double", "table", False), ("double", "unrolled", False)]


def main() -> None:
    print("fitting the paper models ...", file=sys.stderr)
    model = fit_model(simulate(load_sensor("paper"), grid_poses(PAPER_GRIDS["paper-sim"])), settings=FitSettings.exact())
    gmr = simulate(load_sensor("paper").with_transfer("gmr"), grid_poses(PAPER_GRIDS["paper-sim"]))
    fixed_model = fit_model(gmr, settings=FitSettings.exact(exponents=FAMILIES["no-roots"]))
    press = fit_model(simulate(load_sensor("paper"), grid_poses({"dz": [x / 10 for x in range(-20, 1)]})),
                      outputs=("dz",), settings=FitSettings.exact())
    rows = []
    runs = [(model, "paper", *b) for b in BUILDS] + [(fixed_model, "paper (gmr, no roots)", "fixed", "-", False),
                                                     (press, "press (dz only)", "float", "table", False),
                                                     (press, "press (dz only)", "float", "unrolled", False)]
    for m, name, precision, style, fma in runs:
        print(f"{name} {precision} {style}{' fma' if fma else ''} ...", file=sys.stderr)
        with start_target(m, "mps2", precision=precision, style=style if style != "-" else "table", fma=fma) as emu:
            with Device.open(emu.url, timeout=10) as dev:
                b = bench_instructions(dev)
                t = check_timing(dev, m, fixed=_fixed(m) if precision == "fixed" else None)
        terms = sum(len(e.terms) for e in m.equations)
        rows.append((name, precision, style + (" fma" if fma else ""), terms, emu.size["flash"], emu.size["ram"],
                     b["instructions"], t.figures))
    print("| model | precision | style | terms | flash (B) | RAM (B) | instructions per estimate | "
          "EVAL round trip, median (ms) | batched EVAL (estimates/s) |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for name, precision, style, terms, flash, ram, instr, fig in rows:
        print(f"| {name} | {precision} | {style} | {terms} | {flash:,} | {ram:,} | {instr:,.0f} | "
              f"{fig['rtt_ms_median']:.2f} | {fig['per_s']:,.0f} |")
    print("\nHost build over a pty (paper model, double, unrolled):\n")
    with start_target(model, "host", precision="double", style="unrolled") as fw:
        with Device.open(fw.url, timeout=5) as dev:
            b = bench_instructions(dev)
            t = check_timing(dev, model)
    print(f"- {b['ns']:.0f} ns per estimate on the host; EVAL round trip median {t.figures['rtt_ms_median']:.3f} ms, "
          f"batched {t.figures['per_s']:,.0f} estimates/s")


def _fixed(m):
    from fitgen.fixedpoint import build_fixed, default_input_scale

    lsb, off, _ = default_input_scale(m)
    return build_fixed(m, lsb, off)


if __name__ == "__main__":
    main()
