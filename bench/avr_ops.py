"""Where a fixed-point estimate's cycles go on the ATmega328P: avr-gcc's int64 operations against the
header's AVR assembly, one operation at a time, and the uno plan's build with each routine taken out.

    PYTHONPATH=. python3 bench/avr_ops.py > /tmp/ops.md    # a few seconds; progress on stderr

Needs avr-gcc (apt: gcc-avr avr-libc), gcc, and libsimavr known to pkg-config (simavr libsimavr-dev
libelf-dev pkg-config); checked before anything is built.

Part 1 runs each operation once in simavr at 16 MHz between two GPIOR0 writes (the bracket's own 2
cycles taken off), its operands from volatile variables and its result stored to one (the loads
outside the bracket, the store inside): what the header's portable C spends on a term (an int32 x
int32 product in int64, the 64-bit rounding shift, the int64 sum) and on a reciprocal (an int64
division), and what its assembly spends (fitgen/c/avrasm.py). Part 2 builds the header of the model
bench/avr_cost.py measures (`fitgen fit --family no-roots`, the uno plan) into that bench's program,
then again with each routine's calls replaced by a copy of an operand (results wrong, cycles
telling), and prints the cycles per estimate over 20 inputs: the difference is the routine's share.
"""

from __future__ import annotations

import re
import tempfile
from pathlib import Path

import numpy as np

from benchutil import log, need_tools, parse_args, table
from fitgen import __version__
from fitgen.c import avrasm
from fitgen.c.avr import AVR_CC, F_CPU, MCU, _run, build_runner
from fitgen.c.codegen import _env, render_fixed_header
from fitgen.c.compiled import WARNING_FLAGS
from fitgen.equations.inputscale import plan_at
from fitgen.fitting.fit import FitSettings, fit_model
from fitgen.physics.sensor import load_sensor
from fitgen.physics.simulate import PAPER_GRIDS, grid_poses, simulate

# (what, the C between the brackets); a, b: int32, w: int64, d: a divisor; r32/r64: volatile results
OPS = [
    ("int64 product of two int32 (`(int64_t)a * b`)", "r64 = (int64_t)a * b;"),
    ("64-bit rounding shift by 5 (the header's `tm_rshr`)", "r64 = rshr(w, 5u);"),
    ("64-bit rounding shift by 30", "r64 = rshr(w, 30u);"),
    ("int64 sum", "r64 = w + (int64_t)a;"),
    ("a term in portable C: `acc += tm_rshr((int64_t)C * p, 5)`", "r64 = w + rshr((int64_t)a * b, 5u);"),
    ("a reciprocal in portable C: `(2^45 + d / 2) / d`", "r32 = (int32_t)((((int64_t)1 << 45) + d / 2) / d);"),
    ("assembly: a product rounded by 31 (`tm_avr_mulsh`)", "mulsh(a, b, 31, &o32); r32 = o32;"),
    ("assembly: a product rounded by 16", "mulsh(a, b, 16, &o32); r32 = o32;"),
    ("assembly: a reciprocal (`tm_avr_divr`, 2^45 / d)", "divr(d, 8192UL, 0UL, &o32); r32 = o32;"),
    ("assembly: `tm_avr_dot` over an empty table", "dot(&acc, v, t0); r64 = acc;"),
    ("assembly: `tm_avr_dot` over 10 terms, shift 0", "dot(&acc, v, t10s0); r64 = acc;"),
    ("assembly: `tm_avr_dot` over 10 terms, shift 8", "dot(&acc, v, t10s8); r64 = acc;"),
    ("assembly: `tm_avr_dot` over 10 terms, shift 5", "dot(&acc, v, t10s5); r64 = acc;"),
]


def _program() -> str:
    def table_of(shift: int) -> str:
        rows = [f"{4 * k}, 0, 0x{0x3A5B6C7D - 77 * k & 0xFF:02x}, 0x5b, 0x6c, 0x{0x3d + k:02x}, {shift & 255}"
                for k in range(10)]
        return "{ " + ", ".join(rows) + ", 0xFF, 0xFF }"

    def naked(sig: str, blocks) -> str:
        return (f"static void __attribute__((naked, noinline, noclone, used)) {sig}\n{{\n    __asm__ __volatile__(\n"
                f"{avrasm.c_literal(blocks)});\n}}\n")

    ops = "\n".join(f"    a = va; b = vb; w = vw; d = vd; acc = vw; B1; {code} B2;" for _, code in OPS)
    return f"""#include <avr/io.h>
#include <avr/pgmspace.h>
#include <avr/sleep.h>
#include <avr/interrupt.h>
#include <stdint.h>
#define U __attribute__((unused))
#define B1 do {{ __asm__ __volatile__("" ::: "memory"); GPIOR0 = 1; __asm__ __volatile__("" ::: "memory"); }} while (0)
#define B2 do {{ __asm__ __volatile__("" ::: "memory"); GPIOR0 = 2; __asm__ __volatile__("" ::: "memory"); }} while (0)
volatile int32_t va = 1234567891L, vb = -987654321L, vd = 36526L, r32;
volatile int64_t vw = 123456789012345LL, r64;
static inline int64_t rshr(int64_t x, unsigned s)
{{
    const uint64_t bias = (uint64_t)1 << 63;
    const uint64_t q = ((uint64_t)x + bias + ((uint64_t)1 << (s - 1u))) >> s;
    return (int64_t)q - (int64_t)(bias >> s);
}}
{naked("dot(int64_t *acc U, const int32_t *v U, const uint8_t *t U)", avrasm.dot())}
{naked("mulsh(int32_t a U, int32_t b U, int8_t s U, int32_t *out U)", avrasm.mulsh())}
{naked("divr(int32_t d U, uint32_t hi U, uint32_t add U, int32_t *out U)", avrasm.divr())}
static const uint8_t t0[] PROGMEM = {{ 0xFF, 0xFF }};
static const uint8_t t10s0[] PROGMEM = {table_of(0)};
static const uint8_t t10s8[] PROGMEM = {table_of(8)};
static const uint8_t t10s5[] PROGMEM = {table_of(5)};
int main(void)
{{
    int32_t a, b, d, o32, v[10];
    int64_t w, acc;
    uint8_t k;
    for (k = 0; k < 10u; ++k) {{
        v[k] = va - (int32_t)k * 1000003L;
    }}
    B1; B2;
{ops}
    cli();
    sleep_enable();
    sleep_cpu();
    return 0;
}}
"""


def _cycles(runner: Path, elf: Path, n: int) -> np.ndarray:
    proc = _run([str(runner), str(elf), str(200_000_000)], "the AVR program in simavr")
    cyc = [int(ln.split()[1]) for ln in proc.stderr.splitlines() if ln.startswith("CYCLES ")]
    if len(cyc) != n + 1:
        raise RuntimeError(f"simavr counted {len(cyc)} brackets, expected {n + 1}")
    return np.array(cyc[1:]) - cyc[0]


def main() -> None:
    parse_args(__doc__)  # no options: one it does not know is refused, not ignored
    need_tools("avr-gcc", "gcc", libs=("simavr",))
    work = Path(tempfile.mkdtemp(prefix="fitgen-avr-ops-"))
    runner = build_runner(work)
    log("one operation at a time ...")
    (work / "ops.c").write_text(_program())
    _run([AVR_CC, f"-mmcu={MCU}", *WARNING_FLAGS, "-O2", str(work / "ops.c"), "-o", str(work / "ops.elf")],
         "building the operations' program")
    ops = _cycles(runner, work / "ops.elf", len(OPS))
    print(f"ATmega328P at {F_CPU / 1e6:g} MHz in simavr, avr-gcc -O2; cycles of one operation (its result's store "
          "included):\n")
    print(table(["operation", "cycles"], [[what, f"{c:,}"] for (what, _), c in zip(OPS, ops)]))

    log("the uno plan's build with each routine taken out ...")
    ds = simulate(load_sensor("paper").with_transfer("gmr"), grid_poses(PAPER_GRIDS["paper-sim"]))
    model = fit_model(ds, settings=FitSettings.family("no-roots"))
    fm = plan_at(model, mul_bits=16)[0]
    rng = np.random.default_rng(0)
    codes = rng.integers(np.array(fm.code_min), np.array(fm.code_max) + 1, size=(20, model.n_inputs))
    header = render_fixed_header(fm)
    counts = {k: len(re.findall(rf"^    tm_avr_{k}\(", header, re.M)) for k in ("dot", "mulsh", "divr")}
    variants = [("the uno plan's header as generated", header, None),
                ("without the term sums (tm_avr_dot)", re.sub(r"tm_avr_dot\(&acc, val, tm_dot_\w+\);", "", header),
                 f"{sum(len(e.terms) for e in model.equations)} terms in {counts['dot']} calls"),
                ("without the products (tm_avr_mulsh)",
                 re.sub(r"tm_avr_mulsh\((val\[\d+\]), val\[\d+\], \d+, &(val\[\d+\])\);", r"\2 = \1;", header),
                 f"{counts['mulsh']} calls"),
                ("without the reciprocals (tm_avr_divr)",
                 re.sub(r"tm_avr_divr\((val\[\d+\]), [^;]*, &(val\[\d+\])\);", r"\2 = \1;", header),
                 f"{counts['divr']} calls"),
                ("without the outputs' int64 rounding (C)", re.sub(r"\(int32_t\)tm_rshr\(acc, \d+u\)", "(int32_t)acc",
                                                                   header), f"{len(fm.outputs)} outputs")]
    main_c = _env().get_template("avr/bench_main.c.j2").render(
        n=len(codes), rows=[[f"INT32_C({int(x)})" for x in r] for r in codes], version=__version__)
    (work / "bench_main.c").write_text(main_c)
    rows, base = [], None
    for what, text, calls in variants:
        (work / "tm_model.h").write_text(text)
        _run([AVR_CC, f"-mmcu={MCU}", f"-DF_CPU={F_CPU}UL", "-std=c99", "-O2", "-I", str(work),
              str(work / "bench_main.c"), "-o", str(work / "bench.elf")], "building the estimate's program")
        mean = float(np.mean(_cycles(runner, work / "bench.elf", len(codes))))
        base = mean if base is None else base
        share = "-" if calls is None else f"{base - mean:,.0f} ({calls}: {(base - mean) / int(calls.split()[0]):,.0f} each)"
        rows.append([what, f"{mean:,.0f}", share])
    print(f"\nCycles per estimate of the model bench/avr_cost.py measures (no-roots, the uno plan), {len(codes)} "
          "inputs, and what each routine takes:\n")
    print(table(["build", "cycles per estimate", "the routine's share"], rows))


if __name__ == "__main__":
    main()
