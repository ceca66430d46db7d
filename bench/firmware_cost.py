"""Cost of the paper model on the emulated Cortex-M4 (QEMU mps2-an386) and Cortex-M0 (QEMU microbit, nRF51),
both under -icount, on the Arduino Uno (simavr's ATmega328P, cycles), and HIL round trips.

    python bench/firmware_cost.py > /tmp/firmware.md    # under a minute on 2 cores; progress on stderr

Needs qemu-system-arm and arm-none-eabi-gcc/size with newlib (apt: qemu-system-arm gcc-arm-none-eabi
libnewlib-arm-none-eabi) for the Cortex-M builds, gcc for the host build, avr-gcc/size/nm and libsimavr
known to pkg-config (gcc-avr binutils-avr avr-libc simavr libsimavr-dev libelf-dev pkg-config) for the
Uno; all checked before the fits.

Prints markdown: per build and core, flash and RAM of the firmware image, instructions per estimate
(BENCH under -icount shift=0: two runs of different length, the difference per estimate), and the
round trip (median of 200 one-vector EVALs) and batched throughput of EVAL over the emulator's TCP UART
and the host build's pty. The batched figure is the median of BATCHES timings of one 400-vector EVAL
(hil.suite.check_timing); it still moves with the machine's load from run to run; the instruction counts do not.
The same fixed-point build runs on both cores; a second table counts its 64-bit products and
divisions (the fixed-point plan's operations), which the M0 computes in library calls
(__aeabi_lmul, __aeabi_ldivmod) and the M4 in single instructions (SMULL) or a short sequence.
"""

from __future__ import annotations

import sys

from benchutil import need_tools, parse_args
from fitgen.base.errors import InputError
from fitgen.fitting.fit import FitSettings, fit_model
from fitgen.physics.sensor import load_sensor
from fitgen.physics.simulate import PAPER_GRIDS, grid_poses, simulate
from fitgen.equations.terms import FAMILIES
from hil.emulate import bench_instructions, start_target
from hil.suite import check_timing
from host.device import Device

CORES = {"mps2": "Cortex-M4F", "microbit": "Cortex-M0"}
BATCHES = 7  # timings of one batched EVAL per build: their median is the figure
BUILDS = [("float", "table", False), ("float", "unrolled", False), ("float", "unrolled", True),
          ("double", "table", False), ("double", "unrolled", False)]


def main() -> None:
    parse_args(__doc__)  # no options: one it does not know is refused, not ignored
    need_tools("qemu-system-arm", "arm-none-eabi-gcc", "arm-none-eabi-size", "gcc", "avr-gcc", "avr-size",
               "avr-nm", libs=("simavr",))
    print("fitting the paper models ...", file=sys.stderr)
    model = fit_model(simulate(load_sensor("paper"), grid_poses(PAPER_GRIDS["paper-sim"])), settings=FitSettings.exact())
    gmr = simulate(load_sensor("paper").with_transfer("gmr"), grid_poses(PAPER_GRIDS["paper-sim"]))
    fixed_model = fit_model(gmr, settings=FitSettings.exact(exponents=FAMILIES["no-roots"]))
    press = fit_model(simulate(load_sensor("paper"), grid_poses({"dz": [x / 10 for x in range(-20, 1)]})),
                      outputs=("dz",), settings=FitSettings.exact())
    rows = []
    runs = [(model, "paper", *b, "mps2") for b in BUILDS] + [
        (fixed_model, "paper (gmr, no roots)", "fixed", "-", False, "mps2"),
        (fixed_model, "paper (gmr, no roots)", "fixed", "-", False, "microbit"),
        (press, "press (dz only)", "float", "table", False, "mps2"),
        (press, "press (dz only)", "float", "unrolled", False, "mps2")]
    for m, name, precision, style, fma, target in runs:
        print(f"{name} {precision} {style}{' fma' if fma else ''} on {target} ...", file=sys.stderr)
        with start_target(m, target, precision=precision, style=style if style != "-" else "table", fma=fma) as emu:
            with Device.open(emu.url, timeout=10) as dev:
                b = bench_instructions(dev)
                t = check_timing(dev, m, fixed=_fixed(m) if precision == "fixed" else None, batches=BATCHES)
        terms = sum(len(e.terms) for e in m.equations)
        rows.append((name, precision, style + (" fma" if fma else ""), CORES[target], terms, emu.size["flash"],
                     emu.size["ram"], b["instructions"], t.figures))
    print("| model | precision | style | core | terms | flash (B) | RAM (B) | instructions per estimate | "
          f"EVAL round trip, median (ms) | batched EVAL, median of {BATCHES} timings of 400 vectors (estimates/s) |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for name, precision, style, core, terms, flash, ram, instr, fig in rows:
        print(f"| {name} | {precision} | {style} | {core} | {terms} | {flash:,} | {ram:,} | {instr:,.0f} | "
              f"{fig['rtt_ms_median']:.2f} | {fig['per_s']:,.0f} |")
    print(f"\nRound trip: the median of 200 one-vector EVALs. Batched: the median of {BATCHES} timings of one "
          "400-vector EVAL per build (hil.suite.check_timing), which moves with the machine's load; the instruction "
          "counts do not.")
    fixed_rows = {core: instr for name, precision, _, core, _, _, _, instr, _ in rows if precision == "fixed"}
    kinds = [op.kind for op in _fixed(fixed_model).ops]
    products, divisions = kinds.count("mul") + kinds.count("term"), kinds.count("recip")
    m0, m4 = fixed_rows["Cortex-M0"], fixed_rows["Cortex-M4F"]
    print("\nThe fixed-point build on both cores (the same C, the same integers):\n")
    print("| 64-bit products per estimate | 64-bit divisions per estimate | instructions, Cortex-M4F | "
          "instructions, Cortex-M0 | M0 / M4F | extra M0 instructions per product or division |")
    print("| --- | --- | --- | --- | --- | --- |")
    print(f"| {products} | {divisions} | {m4:,.0f} | {m0:,.0f} | {m0 / m4:.1f}x | "
          f"{(m0 - m4) / max(products + divisions, 1):.0f} |")
    uno_table(gmr, fixed_model)
    print("\nHost build over a pty (paper model, double, unrolled):\n")
    with start_target(model, "host", precision="double", style="unrolled") as fw:
        with Device.open(fw.url, timeout=5) as dev:
            b = bench_instructions(dev)
            t = check_timing(dev, model, batches=BATCHES)
    print(f"- {b['ns']:.0f} ns per estimate on the host; EVAL round trip median {t.figures['rtt_ms_median']:.3f} ms, "
          f"batched {t.figures['per_s']:,.0f} estimates/s (the median of {BATCHES} timings of one 400-vector EVAL)")


def uno_table(gmr, fixed_model) -> None:
    """The reference firmware on the Arduino Uno (simavr's ATmega328P): cycles per estimate (BENCH's ticks are
    the CPU's cycles), flash, static RAM and the stack's measured peak, beside the Uno's limits."""
    # FitSettings(): the 11 power kinds, no harmonics (`fitgen fit --family all`: 160 terms with AVX-512, else 155)
    default = fit_model(gmr)
    builds = [(default, "paper (gmr, powers)", "float", "table"), (default, "paper (gmr, powers)", "float", "unrolled"),
              (fixed_model, "paper (gmr, no roots)", "fixed", "-")]
    print("\nThe Arduino Uno (ATmega328P at 16 MHz in simavr; `tactile-hil emulate --target uno`; flash "
          "32,256 B once the bootloader has its 512, RAM 2,048 B):\n")
    print("| model | precision | style | terms | flash (B) | static RAM (B) | stack peak (B) | RAM with stack (B) | "
          "cycles per estimate | estimates/s at 16 MHz | EVAL round trip, median (ms) |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for m, name, precision, style in builds:
        print(f"{name} {precision} {style} on the Uno ...", file=sys.stderr)
        try:
            emu = start_target(m, "uno", precision=precision, style=style if style != "-" else "table")
        except InputError as exc:
            print(f"| {name} | {precision} | {style} | {sum(len(e.terms) for e in m.equations)} | does not build: "
                  f"{exc} | | | | | | |")
            continue
        with emu:
            with Device.open(emu.url, timeout=10) as dev:
                b = bench_instructions(dev, 10, 60)
                t = check_timing(dev, m, n_single=50, n_batch=100, fixed=_fixed(m) if precision == "fixed" else None)
        cycles = b["ticks_per_estimate"]
        print(f"| {name} | {precision} | {style} | {sum(len(e.terms) for e in m.equations)} | {emu.size['flash']:,} | "
              f"{emu.size['ram']:,} | {emu.stack_peak:,} | {emu.size['ram'] + emu.stack_peak:,} | {cycles:,.0f} | "
              f"{b['tick_hz'] / cycles:,.0f} | {t.figures['rtt_ms_median']:.2f} |")


def _fixed(m):
    from fitgen.equations.fixedpoint import build_fixed
    from fitgen.equations.inputscale import default_input_scale

    lsb, off, _ = default_input_scale(m)
    return build_fixed(m, lsb, off)


if __name__ == "__main__":
    main()
