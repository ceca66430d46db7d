"""Cost of one estimate: the generated C (both styles, both precisions) beside the Python evaluator.

Run: ``python bench/eval.py > /tmp/eval.md`` (markdown on stdout, progress on stderr; about
25 s on 2 cores). Needs gcc, valgrind and objdump; arm-none-eabi-gcc/size/nm for the Cortex-M4F
sizes (that part is skipped when they are missing). Tables and their reading:
docs/eval-benchmark.md.

The model is the paper model: fit_model on the paper-sim grid (1,875 poses, no noise) of the
``paper`` sensor; 5 outputs, 8 inputs. Inputs are 4,096 vectors uniform in the model's
input box (seed 2026), the same for every measurement.

1. ns per estimate of the generated C: the header written by fitgen.c.codegen.write_header,
   included by a bench program (fitgen.c.cost.C_BENCH) built with gcc -O2 and fitgen.c.compiled's
   WARNING_FLAGS. tm_estimate is kept out of line (TM_API = static noinline noclone) so
   that every estimate is a call, as on a device. Each build first calibrates how many
   estimates take ~0.2 s; then 11 rounds run each of the 4 builds once in turn (a process
   per run, one warm-up pass over the 4,096 vectors, then that many estimates timed with
   clock_gettime(CLOCK_MONOTONIC)); median, min and max of the 11 per build.
   The time includes the bench loop: the call, summing the status and the 5 outputs into a
   double that ends in a volatile.
2. The Python evaluator: Model.predict(row[None]) one row per call (median of 2,000 calls,
   perf_counter_ns around each), and Model.predict(X) on 100,000 rows (median of 5),
   per estimate.
3. The floor of floating-point operations: 2 per term (multiply by the coefficient, add)
   plus 1 per distinct (element, power) a term needs, v^1 excepted (it is the input
   itself); operations by kind as the templates write them; and as executed (counted).
4. Instructions per estimate with callgrind (x86-64): the bench program run for N1 = 1,000
   and N2 = 11,000 estimates; (Ir(N2) - Ir(N1)) / (N2 - N1) from the "totals:" lines, which
   removes start-up and input reading. Also the instructions inside tm_estimate alone
   (the callgrind cost lines of that function and of what it calls) and their mix by
   instruction kind (callgrind --dump-instr, mnemonics from objdump). N1 is run twice to
   show that the counts repeat exactly.
5. The issue's target: unrolled style within 1.5x of the floor in instructions.
6. Cortex-M4F sizes: arm-none-eabi-gcc -mcpu=cortex-m4 -mthumb -mfloat-abi=hard
   -mfpu=fpv4-sp-d16 -O2 -c (plus WARNING_FLAGS, -fstack-usage) of a file whose non-static
   function calls the static tm_estimate (gcc inlines it there); arm-none-eabi-size of the
   .o, the stack frame from -fstack-usage, the symbols the .o leaves undefined (library
   code not in the .o), and the flash the whole thing adds to a linked newlib program
   (nosys.specs, --gc-sections) over an empty main.
"""

from __future__ import annotations

import platform
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchutil import need_tools, parse_args, table

from fitgen.c.codegen import STYLES
from fitgen.fitting.fit import FitSettings, fit_model
from fitgen.equations.model import Model
from fitgen.physics.sensor import load_sensor
from fitgen.physics.simulate import PAPER_GRIDS, grid_poses, simulate
from fitgen.c import cost
from fitgen.c.compiled import WARNING_FLAGS
from fitgen.c.cost import ARM_CC, FMA_KIND, MIX_KINDS, N1, N2, floor_counts, instruction_counts, run, template_ops

N_VECTORS = cost.NVEC
SEED = 2026
TIME_SECONDS = 0.2
TIME_REPEATS = 11
PY_SINGLE_CALLS = 2000
PY_ROWS = 100_000
PY_VECTOR_REPEATS = 5
# (style, precision, fma): the four plain builds, then the unrolled style with fused multiply-adds,
# built for a core that has them (x86-64-v3) and without errno checks after sqrt (safe: see the header)
PRECISIONS = ("double", "float")  # fixed point: fitgen tradeoff (its cost on a Cortex-M0)
VARIANTS = [(s, p, False) for s in STYLES for p in PRECISIONS] + [("unrolled", p, True) for p in PRECISIONS]
FMA_FLAGS = ["-march=x86-64-v3", "-fno-math-errno"]


def vlabel(v) -> str:
    style, precision, fma = v
    return f"{style} {precision}" + (" fma" if fma else "")


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def paper_model() -> Model:
    return fit_model(simulate(load_sensor("paper"), grid_poses(PAPER_GRIDS["paper-sim"])), settings=FitSettings.exact())


def random_inputs(model: Model, n: int, seed: int = SEED) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return model.input_min + (model.input_max - model.input_min) * rng.random((n, model.n_inputs))


# --- builds (the bench program, callgrind, operation counts and sizes: host/cost.py) ---------

def build_bench(model: Model, style: str, precision: str, fma: bool, root: Path) -> Path:
    return cost.build_bench(model, style, precision, fma, root / f"{style}-{precision}{'-fma' if fma else ''}",
                            FMA_FLAGS if fma else None)


def arm_sizes(model: Model, style: str, precision: str, fma: bool, root: Path) -> dict:
    return cost.arm_sizes(model, style, precision, fma, root / f"arm-{style}-{precision}{'-fma' if fma else ''}")


def time_c(binaries: dict, inputs_file: Path) -> dict:
    """ns per estimate, TIME_REPEATS runs per binary, taken in turn so that a change of load hits all alike."""
    counts = {v: run([str(b), str(inputs_file), "calibrate", str(TIME_SECONDS)]).stdout.strip()
              for v, b in binaries.items()}
    out = {v: [] for v in binaries}
    for _ in range(TIME_REPEATS):
        for v, b in binaries.items():
            out[v].append(float(run([str(b), str(inputs_file), "time", counts[v]]).stdout))
    return out


# --- main ---------------------------------------------------------------------------------------

def median_spread(xs: list[float]) -> tuple[float, float, float]:
    return statistics.median(xs), min(xs), max(xs)


def main() -> None:
    parse_args(__doc__)  # no options: one it does not know is refused, not ignored
    t_start = time.perf_counter()
    need_tools("gcc", "valgrind", "objdump")
    flags = next((ln for ln in open("/proc/cpuinfo") if ln.startswith("flags")), "").split()
    have_fma = {"fma", "avx2"} <= set(flags)
    if not have_fma:
        log("this CPU has no FMA/AVX2: the fma builds are skipped")
    have_arm = all(shutil.which(t) for t in ("arm-none-eabi-gcc", "arm-none-eabi-size", "arm-none-eabi-nm"))

    log("fitting the paper model ...")
    model = paper_model()
    X = random_inputs(model, N_VECTORS)
    fc = floor_counts(model)

    results: dict = {}
    with tempfile.TemporaryDirectory(prefix="fitgen-eval-") as tmp:
        root = Path(tmp)
        inputs_file = root / "inputs.f64"
        np.ascontiguousarray(X, dtype=np.float64).tofile(inputs_file)
        binaries = {}
        for v in VARIANTS:
            if v[2] and not have_fma:
                continue
            log(f"C {vlabel(v)}: build, callgrind, Cortex-M4F sizes ...")
            binary = build_bench(model, *v, root)
            binaries[v] = binary
            results[v] = {"ir": instruction_counts(binary, inputs_file, binary.parent)}
            if have_arm:
                results[v]["arm"] = arm_sizes(model, *v, root)
        log(f"C timing: {TIME_REPEATS} rounds over the 4 builds ...")
        for v, ns in time_c(binaries, inputs_file).items():
            results[v]["ns"] = ns

    log("Python evaluator ...")
    for i in range(50):
        model.predict(X[i][None])
    single = []
    for i in range(PY_SINGLE_CALLS):
        row = X[i % N_VECTORS][None]
        t0 = time.perf_counter_ns()
        model.predict(row)
        single.append(time.perf_counter_ns() - t0)
    big = random_inputs(model, PY_ROWS, SEED + 1)
    model.predict(big[:1000])
    vector = []
    for _ in range(PY_VECTOR_REPEATS):
        t0 = time.perf_counter_ns()
        model.predict(big)
        vector.append((time.perf_counter_ns() - t0) / PY_ROWS)

    # --- tables ---
    cpu = ""
    try:
        cpu = next(ln.split(":", 1)[1].strip() for ln in open("/proc/cpuinfo") if ln.startswith("model name"))
    except (OSError, StopIteration):
        pass
    gcc_version = run(["gcc", "--version"]).stdout.splitlines()[0]
    n_terms = {eq.name: len(eq.terms) for eq in model.equations}
    print("# Cost of one estimate: generated C and Python evaluator\n")
    print(f"Model: paper-sim fit, {model.n_inputs} inputs, {len(model.equations)} outputs, "
          f"{fc['T']} terms ({', '.join(f'{k} {v}' for k, v in n_terms.items())}); model {model.sha256[:12]}.")
    print(f"Machine: {cpu or platform.processor()} ({platform.machine()}), {gcc_version}, "
          f"Python {platform.python_version()}, numpy {np.__version__}.")
    print(f"C flags: gcc -O2 {' '.join(WARNING_FLAGS)}; the fma builds add {' '.join(FMA_FLAGS)}; "
          f"inputs {N_VECTORS} vectors uniform in the input box.\n")

    variants = [v for v in VARIANTS if v in results]
    base = statistics.median(results["unrolled", "double", False]["ns"])
    print("## Time per estimate (all 5 outputs)\n")
    print(f"C: median of {TIME_REPEATS} runs of ~{TIME_SECONDS:g} s each, the {len(variants)} builds in turn (bench loop "
          f"included); Python: "
          f"median of {PY_SINGLE_CALLS} single calls, and of {PY_VECTOR_REPEATS} calls on {PY_ROWS:,} rows.\n")
    print("| evaluator | ns per estimate (median) | min - max | vs. C unrolled double |")
    print("| --- | --- | --- | --- |")
    for v in variants:
        med, lo, hi = median_spread(results[v]["ns"])
        print(f"| C {vlabel(v)} | {med:.1f} | {lo:.1f} - {hi:.1f} | {med / base:.2f}x |")
    for label, xs in (("Python predict(row[None]), 1 row per call", single),
                      (f"Python predict(X), {PY_ROWS:,} rows per call", vector)):
        med, lo, hi = median_spread(xs)
        print(f"| {label} | {med:,.1f} | {lo:,.1f} - {hi:,.1f} | {med / base:,.0f}x |")

    print("\n## Floor of floating-point operations\n")
    print("| quantity | count |")
    print("| --- | --- |")
    print(f"| terms T (of which v*d: {fc['vd']}, bare d: {fc['d']}) | {fc['T']} |")
    print(f"| distinct (element, power) pairs needing an operation, P (v^1 excepted) | {fc['P']} |")
    print(f"| same with v^1 counted | {fc['pairs']} |")
    print(f"| floor 2T + P | {fc['floor']} |")
    print(f"| floor with v^1 counted | {fc['floor_all']} |")

    print("\n## Floating-point operations per estimate, by kind\n")
    print("Written: counted from the model by the template's rules (inputs inside the domain). "
          "Executed: instructions counted by callgrind inside tm_estimate on x86-64, per estimate (a "
          "packed SSE instruction counts once; FP compare includes the isfinite test and the check gcc "
          "adds after each sqrt for errno; cbrt would be a libm call).\n")
    cols = [("unrolled, written", template_ops(model, "unrolled")),
            ("unrolled, written, x*1 folded", template_ops(model, "unrolled", fold_one=True)),
            ("table, written", template_ops(model, "table"))]
    exe = {v: results[v]["ir"]["mix"] for v in variants}
    print("| kind | " + " | ".join(c for c, _ in cols) + " | " +
          " | ".join(f"executed, {vlabel(v)}" for v in variants) + " |")
    print("| --- " * (1 + len(cols) + len(variants)) + "|")
    mapping = [("mul", "FP multiply"), ("add", "FP add/sub"), ("div", "FP divide"), ("sqrt", "FP sqrt"),
               ("cbrt", None), ("compare", "FP compare"), ("isfinite", None)]
    for kind, exe_kind in mapping:
        row = [str(c[kind]) for _, c in cols]
        row += [(f"{exe[v][exe_kind]:.0f}" if exe_kind else "-") for v in variants]
        print(f"| {kind} | " + " | ".join(row) + " |")
    arith = ("mul", "add", "div", "sqrt", "cbrt")
    row = [str(sum(c[k] for k in arith)) for _, c in cols]
    row += [f"{sum(exe[v][k] for k in ('FP multiply', 'FP add/sub', 'FP divide', 'FP sqrt')) + 2 * exe[v][FMA_KIND]:.0f}"
            for v in variants]
    print("| fused multiply-add | 0 | 0 | 0 | " + " | ".join(f"{exe[v][FMA_KIND]:.0f}" for v in variants) + " |")
    print("| arithmetic total (mul+add+div+sqrt+cbrt, an fma counted as 2) | " + " | ".join(row) + " |")

    print("\n## Instructions per estimate (callgrind, x86-64)\n")
    print(f"Whole loop: (Ir({N2:,}) - Ir({N1:,})) / {N2 - N1:,} from the totals: line (call, bench loop and "
          f"output sums included). In tm_estimate: the cost lines of tm_estimate and its callees only. "
          f"Repeat: Ir of a second run at N1 minus the first.\n")
    irs = {v: results[v]["ir"] for v in variants}
    print(table(["build", "instr/estimate, whole loop", "instr/estimate, in tm_estimate", "floor 2T+P",
                 "whole loop / floor", "tm_estimate / floor", "repeat"],
                [[vlabel(v), f"{ir['loop']:.1f}", f"{ir['fn']:.1f}", f"{fc['floor']}",
                  f"{ir['loop'] / fc['floor']:.2f}x", f"{ir['fn'] / fc['floor']:.2f}x", f"{ir['repeat']:+d}"]
                 for v, ir in irs.items()]))

    print("\nInstructions executed inside tm_estimate per estimate, by kind:\n")
    print("| kind | " + " | ".join(vlabel(v) for v in variants) + " |")
    print("| --- " * (1 + len(variants)) + "|")
    for kind in MIX_KINDS:
        if not any(results[v]["ir"]["mix"][kind] for v in variants):
            continue
        print(f"| {kind} | " + " | ".join(f"{results[v]['ir']['mix'][kind]:.1f}" for v in variants) + " |")
    print("| total | " + " | ".join(f"{sum(results[v]['ir']['mix'].values()):.1f}" for v in variants) + " |")

    print("\n## Target: unrolled within 1.5x of the floor in instructions\n")
    print(table(["build", "in tm_estimate / floor", "whole loop / floor", "within 1.5x"],
                [[vlabel(v), f"{ir['fn'] / fc['floor']:.2f}x", f"{ir['loop'] / fc['floor']:.2f}x",
                  "yes" if ir["fn"] / fc["floor"] <= 1.5 else "no"] for v, ir in irs.items()]))

    if have_arm:
        print("\n## Cortex-M4F sizes (bytes)\n")
        print(f"`{ARM_CC} -O2 -c` with the warning flags; tm_estimate (static) inlined into a one-line "
              "non-static wrapper. Flash = text + data, RAM = data + bss of the .o (text includes the "
              "constant tables); stack = the wrapper's frame from -fstack-usage. Undefined: library code "
              "the .o calls, not in its size; double arithmetic on the single-precision FPU is software "
              "(libgcc __aeabi_d*). Linked: flash a newlib program (nosys.specs, --gc-sections) grows by over "
              "an empty main, library code included.\n")
        print("| build | text | data | bss | flash (text+data) | RAM (data+bss) | stack | "
              "linked flash | undefined symbols |")
        print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
        for v in variants:
            a = results[v]["arm"]
            print(f"| {vlabel(v)} | {a['text']} | {a['data']} | {a['bss']} | {a['text'] + a['data']} | "
                  f"{a['data'] + a['bss']} | {a['stack']} | {a['linked']} | {', '.join(a['undefined']) or '-'} |")
    else:
        print("\n(arm-none-eabi tools not found: Cortex-M4F sizes skipped)")
    log(f"done in {time.perf_counter() - t_start:.0f} s")


if __name__ == "__main__":
    main()
