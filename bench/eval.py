"""Cost of one estimate: the generated C (both styles, both precisions) beside the Python evaluator.

Run: ``python bench/eval.py > /tmp/eval.md`` (markdown on stdout, progress on stderr; about
25 s on 2 cores). Needs gcc and valgrind; arm-none-eabi-gcc/size/nm for the Cortex-M4F
sizes (that part is skipped when they are missing). Tables and their reading:
docs/eval-benchmark.md.

The model is the paper model: fit_model on the paper-sim grid (1,875 poses, no noise) of the
``paper`` sensor; 5 outputs, 8 inputs. Inputs are 4,096 vectors uniform in the model's
input box (seed 2026), the same for every measurement.

1. ns per estimate of the generated C: the header written by fitgen.codegen.write_header,
   included by a bench program (C_BENCH below) built with gcc -O2 and host.compiled's
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
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

import numpy as np

from fitgen.codegen import PRECISIONS, STYLES, write_header
from fitgen.fit import fit_model
from fitgen.model import Model
from fitgen.sensor import load_sensor
from fitgen.simulate import PAPER_GRIDS, grid_poses, simulate
from host.compiled import WARNING_FLAGS, compile_checked

N_VECTORS = 4096
SEED = 2026
TIME_SECONDS = 0.2
TIME_REPEATS = 11
PY_SINGLE_CALLS = 2000
PY_ROWS = 100_000
PY_VECTOR_REPEATS = 5
N1, N2 = 1_000, 11_000
# (style, precision, fma): the four plain builds, then the unrolled style with fused multiply-adds,
# built for a core that has them (x86-64-v3) and without errno checks after sqrt (safe: see the header)
VARIANTS = [(s, p, False) for s in STYLES for p in PRECISIONS] + [("unrolled", p, True) for p in PRECISIONS]
FMA_FLAGS = ["-march=x86-64-v3", "-fno-math-errno"]


def vlabel(v) -> str:
    style, precision, fma = v
    return f"{style} {precision}" + (" fma" if fma else "")
ARM_CC = "arm-none-eabi-gcc -mcpu=cortex-m4 -mthumb -mfloat-abi=hard -mfpu=fpv4-sp-d16"

C_BENCH = r"""
#define _POSIX_C_SOURCE 199309L
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#define TM_API static __attribute__((noinline, noclone))
#include "tm_model.h"

#define NVEC 4096
static tm_real inputs[NVEC][TM_N_INPUTS];
static volatile double sink;

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* n estimates over the vectors in turn; status and outputs summed so that none is dead */
static double run(long n)
{
    tm_real out[TM_N_OUTPUTS];
    double acc = 0.0;
    long i;
    int j, k = 0;
    for (i = 0; i < n; ++i) {
        acc += (double)tm_estimate(inputs[k], out);
        for (j = 0; j < TM_N_OUTPUTS; ++j) {
            acc += (double)out[j];
        }
        if (++k == NVEC) {
            k = 0;
        }
    }
    return acc;
}

static double timed(long n)
{
    double t0 = now_s();
    sink = run(n);
    return now_s() - t0;
}

/* usage: bench INPUTS calibrate SECONDS  (prints how many estimates take about SECONDS)
 *        bench INPUTS time N              (prints ns per estimate over N estimates)
 *        bench INPUTS count N             (runs N estimates, prints their sum) */
int main(int argc, char **argv)
{
    static double raw[NVEC][TM_N_INPUTS];
    FILE *f;
    int i, j;
    long n;
    double t;
    if (argc < 4) {
        fprintf(stderr, "usage: %s INPUTS calibrate SECONDS | INPUTS time N | INPUTS count N\n", argv[0]);
        return 2;
    }
    f = fopen(argv[1], "rb");
    if (f == NULL || fread(raw, sizeof raw, 1, f) != 1) {
        fprintf(stderr, "cannot read %s\n", argv[1]);
        return 2;
    }
    fclose(f);
    for (i = 0; i < NVEC; ++i) {
        for (j = 0; j < TM_N_INPUTS; ++j) {
            inputs[i][j] = (tm_real)raw[i][j];
        }
    }
    if (strcmp(argv[2], "count") == 0) {
        printf("%.17g\n", run(atol(argv[3])));
        return 0;
    }
    if (strcmp(argv[2], "calibrate") == 0) {
        n = NVEC;
        timed(n);
        while ((t = timed(n)) < 0.05) {
            n *= 2;
        }
        printf("%ld\n", (long)((double)n * atof(argv[3]) / t) + 1);
        return 0;
    }
    if (strcmp(argv[2], "time") == 0) {
        n = atol(argv[3]);
        timed(NVEC);
        printf("%.4f\n", 1e9 * timed(n) / (double)n);
        return 0;
    }
    fprintf(stderr, "unknown mode %s\n", argv[2]);
    return 2;
}
"""

C_ARM = """
#include "tm_model.h"
int tm_bench_call(const tm_real *in, tm_real *out);
int tm_bench_call(const tm_real *in, tm_real *out)
{
    return tm_estimate(in, out);
}
"""
C_ARM_MAIN = """
#include "tm_model.h"
int tm_bench_call(const tm_real *in, tm_real *out);
int main(void);
int main(void)
{
    static tm_real in[TM_N_INPUTS], out[TM_N_OUTPUTS];
    return tm_bench_call(in, out);
}
"""
C_ARM_EMPTY = """
int main(void);
int main(void)
{
    return 0;
}
"""


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def run(cmd: list[str], **kw) -> subprocess.CompletedProcess:
    proc = subprocess.run(cmd, capture_output=True, text=True, **kw)
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed ({proc.returncode}): {proc.stderr.strip()[:400]}")
    return proc


def paper_model() -> Model:
    return fit_model(simulate(load_sensor("paper"), grid_poses(PAPER_GRIDS["paper-sim"])))


def random_inputs(model: Model, n: int, seed: int = SEED) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return model.input_min + (model.input_max - model.input_min) * rng.random((n, model.n_inputs))


# --- 3. operation counts -------------------------------------------------------------------

def needs(model: Model) -> list[set[str]]:
    out = [set() for _ in range(model.n_inputs)]
    for eq in model.equations:
        for t in eq.terms:
            if t.element:
                out[t.element - 1].add(t.exponent)
    return out


def floor_counts(model: Model) -> dict:
    terms = [t for eq in model.equations for t in eq.terms]
    pairs = {(k, e) for k, need in enumerate(needs(model)) for e in need}
    costly = {(k, e) for k, e in pairs if e != "1"}
    return {"T": len(terms), "vd": sum(1 for t in terms if t.element and t.mult),
            "d": sum(1 for t in terms if t.mult and not t.element), "pairs": len(pairs), "P": len(costly),
            "floor": 2 * len(terms) + len(costly), "floor_all": 2 * len(terms) + len(pairs)}


def template_ops(model: Model, style: str, fold_one: bool = False) -> Counter:
    """Floating-point operations per estimate as model.h.j2 writes them (inputs inside the domain).

    unrolled: v2 = v*v once per input that needs any of ^2..^4, ^-2..^-4; v3 = v2*v and
    v4 = v2*v2 once each (the ^3/^-3 and ^4/^-4 expressions are the same, gcc shares them);
    1/v^k one division each; ^1/2 sqrt, ^1/3 cbrt, ^1/4 two sqrt. table: v2 = v*v for every
    input; each of ^3, ^-3 (^4, ^-4) computes its own v2*v (v2*v2). Per term: coefficient *
    (base * d) and one add; ``fold_one`` drops the base * 1 (or 1 * d) multiply gcc folds away
    in the unrolled style. Clamp: isfinite and 2 compares per input.
    """
    ops = Counter()
    for need in needs(model):
        if not need:
            if style == "table":
                ops["mul"] += 1
            continue
        if style == "table" or need & {"2", "3", "4", "-2", "-3", "-4"}:
            ops["mul"] += 1
        for group in (("3", "-3"), ("4", "-4")):
            n = sum(e in need for e in group)
            ops["mul"] += n if style == "table" else min(n, 1)
        ops["div"] += sum(e in need for e in ("-1", "-2", "-3", "-4"))
        ops["sqrt"] += ("1/2" in need) + 2 * ("1/4" in need)
        ops["cbrt"] += "1/3" in need
    for eq in model.equations:
        for t in eq.terms:
            ops["add"] += 1
            ops["mul"] += 1
            if not fold_one or (t.element and t.mult):
                ops["mul"] += 1
    ops["compare"] += 2 * model.n_inputs
    ops["isfinite"] += model.n_inputs
    return ops


# --- builds ---------------------------------------------------------------------------------

def build_bench(model: Model, style: str, precision: str, fma: bool, root: Path) -> Path:
    d = root / f"{style}-{precision}{'-fma' if fma else ''}"
    d.mkdir()
    write_header(model, d, precision, style, fma=fma)
    src = d / "bench.c"
    src.write_text(C_BENCH)
    binary = d / "bench"
    compile_checked("gcc", [src], binary, d, FMA_FLAGS if fma else None)
    return binary


def time_c(binaries: dict, inputs_file: Path) -> dict:
    """ns per estimate, TIME_REPEATS runs per binary, taken in turn so that a change of load hits all alike."""
    counts = {v: run([str(b), str(inputs_file), "calibrate", str(TIME_SECONDS)]).stdout.strip()
              for v, b in binaries.items()}
    out = {v: [] for v in binaries}
    for _ in range(TIME_REPEATS):
        for v, b in binaries.items():
            out[v].append(float(run([str(b), str(inputs_file), "time", counts[v]]).stdout))
    return out


# --- 4. callgrind ------------------------------------------------------------------------------

def callgrind(binary: Path, inputs_file: Path, n: int, out: Path) -> Path:
    run(["valgrind", "--tool=callgrind", "--dump-instr=yes", "--dump-line=no", f"--callgrind-out-file={out}",
         str(binary), str(inputs_file), "count", str(n)])
    return out


def parse_callgrind(path: Path, fn_prefix: str = "tm_estimate") -> tuple[int, int, Counter]:
    """(total Ir, Ir inside the function and its callees, self Ir per instruction address).

    The file is written with --dump-instr=yes --dump-line=no: cost lines are "ADDR IR", ADDR
    absolute (0x...), relative to the previous one (+n/-n, decimal) or "*"; the cost line after
    a calls= line is the inclusive cost of that call.
    """
    names: dict[str, str] = {}
    total = None
    current = ""
    addr = 0
    after_call = False
    inclusive = 0
    per_addr: Counter = Counter()
    for line in path.read_text().splitlines():
        if not line:
            continue
        c = line[0]
        if c.isdigit() or c in "+-*":
            parts = line.split()
            pos = parts[0]
            if pos.startswith("0x"):
                addr = int(pos, 16)
            elif pos[0] in "+-":
                addr += int(pos)
            ir = int(parts[1]) if len(parts) > 1 else 0
            if current.startswith(fn_prefix):
                inclusive += ir
                if not after_call:
                    per_addr[addr] += ir
            after_call = False
            continue
        if line.startswith(("fn=", "cfn=", "cfi=", "cfl=")):
            key, _, rest = line.partition("=")
            m = re.match(r"\((\d+)\)(?: (.*))?", rest)
            name = rest
            if m:
                if m.group(2) is not None:
                    names[m.group(1)] = m.group(2)
                name = names.get(m.group(1), "?")
            if key == "fn":
                current = name
        elif line.startswith("calls="):
            after_call = True
        elif line.startswith(("totals:", "summary:")):
            total = int(line.split()[1])
    if total is None:
        raise RuntimeError(f"{path}: no totals: or summary: line")
    return total, inclusive, per_addr


def disassembly(binary: Path, symbol_prefix: str = "tm_estimate") -> dict[int, tuple[str, str]]:
    """address -> (mnemonic, operands) of the instructions of the function."""
    text = run(["objdump", "-d", "--no-show-raw-insn", str(binary)]).stdout
    out = {}
    inside = False
    for line in text.splitlines():
        m = re.match(r"^[0-9a-f]+ <([^>]+)>:", line)
        if m:
            inside = m.group(1).startswith(symbol_prefix)
            continue
        m = re.match(r"^\s+([0-9a-f]+):\s+(\S+)\s*(.*)$", line)
        if inside and m:
            out[int(m.group(1), 16)] = (m.group(2), m.group(3))
    return out


FMA_KIND = "FP fused multiply-add"
MIX_KINDS = ("FP multiply", "FP add/sub", "FP fused multiply-add", "FP divide", "FP sqrt", "FP compare",
             "FP/SIMD move, load, store, logic",
             "integer ALU, address, load, store", "branch", "call, ret, push, pop")


def kind_of(mnemonic: str, operands: str) -> str:
    if re.fullmatch(r"v?f(n)?m(add|sub)\d*[sp][sd]", mnemonic):
        return "FP fused multiply-add"
    m = re.fullmatch(r"v?(mul|add|sub|div|sqrt)[sp][sd]", mnemonic)
    if m:
        return {"mul": "FP multiply", "add": "FP add/sub", "sub": "FP add/sub", "div": "FP divide",
                "sqrt": "FP sqrt"}[m.group(1)]
    if re.fullmatch(r"v?u?comis[sd]", mnemonic):
        return "FP compare"
    if mnemonic.startswith(("call", "ret", "push", "pop", "leave")):
        return "call, ret, push, pop"
    if mnemonic.startswith("j"):
        return "branch"
    if "%xmm" in operands or re.fullmatch(r"v?(p\w+|\w+p[sd]|cvt\w+)", mnemonic):
        return "FP/SIMD move, load, store, logic"
    return "integer ALU, address, load, store"


def instruction_counts(binary: Path, inputs_file: Path, work: Path) -> dict:
    a = parse_callgrind(callgrind(binary, inputs_file, N1, work / "cg-n1.out"))
    b = parse_callgrind(callgrind(binary, inputs_file, N2, work / "cg-n2.out"))
    again = parse_callgrind(callgrind(binary, inputs_file, N1, work / "cg-n1b.out"))
    n = N2 - N1
    dis = disassembly(binary)
    mix: Counter = Counter()
    mnem: Counter = Counter()
    for addr in set(a[2]) | set(b[2]):
        count = (b[2][addr] - a[2][addr]) / n
        op, args = dis.get(addr, ("?", ""))
        mix[kind_of(op, args)] += count
        mnem[op] += count
    return {"loop": (b[0] - a[0]) / n, "fn": (b[1] - a[1]) / n, "repeat": again[0] - a[0],
            "n1_total": a[0], "mix": mix, "mnemonics": mnem}


# --- 6. Cortex-M4F sizes ------------------------------------------------------------------------

def arm_sizes(model: Model, style: str, precision: str, fma: bool, root: Path) -> dict:
    d = root / f"arm-{style}-{precision}{'-fma' if fma else ''}"
    d.mkdir()
    write_header(model, d, precision, style, fma=fma)
    (d / "call.c").write_text(C_ARM)
    obj = d / "call.o"
    compile_checked(ARM_CC, [d / "call.c"], obj, d, ["-fstack-usage"], link=False)
    text, data, bss = (int(x) for x in run(["arm-none-eabi-size", str(obj)]).stdout.splitlines()[1].split()[:3])
    su = (d / "call.su").read_text().split()
    undefined = [ln.split()[-1] for ln in run(["arm-none-eabi-nm", "-u", str(obj)]).stdout.splitlines() if ln.strip()]
    # flash the function adds to a linked program (library code included) over an empty main
    (d / "main.c").write_text(C_ARM_MAIN)
    (d / "empty.c").write_text(C_ARM_EMPTY)
    link = ARM_CC.split() + ["-O2", "-specs=nosys.specs", "-Wl,--gc-sections", "-I", str(d)]
    run(link + [str(d / "main.c"), str(obj), "-o", str(d / "full.elf"), "-lm"])
    run(link + [str(d / "empty.c"), "-o", str(d / "empty.elf")])
    sizes = []
    for elf in ("full.elf", "empty.elf"):
        t, dt, _ = (int(x) for x in run(["arm-none-eabi-size", str(d / elf)]).stdout.splitlines()[1].split()[:3])
        sizes.append(t + dt)
    return {"text": text, "data": data, "bss": bss, "stack": int(su[1]), "undefined": undefined,
            "linked": sizes[0] - sizes[1]}


# --- main ---------------------------------------------------------------------------------------

def median_spread(xs: list[float]) -> tuple[float, float, float]:
    return statistics.median(xs), min(xs), max(xs)


def main() -> None:
    t_start = time.perf_counter()
    for tool in ("gcc", "valgrind", "objdump"):
        if shutil.which(tool) is None:
            sys.exit(f"{tool} not found")
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
    print(f"| fused multiply-add | 0 | 0 | 0 | " + " | ".join(f"{exe[v][FMA_KIND]:.0f}" for v in variants) + " |")
    print("| arithmetic total (mul+add+div+sqrt+cbrt, an fma counted as 2) | " + " | ".join(row) + " |")

    print(f"\n## Instructions per estimate (callgrind, x86-64)\n")
    print(f"Whole loop: (Ir({N2:,}) - Ir({N1:,})) / {N2 - N1:,} from the totals: line (call, bench loop and "
          f"output sums included). In tm_estimate: the cost lines of tm_estimate and its callees only. "
          f"Repeat: Ir of a second run at N1 minus the first.\n")
    print("| build | instr/estimate, whole loop | instr/estimate, in tm_estimate | floor 2T+P | "
          "whole loop / floor | tm_estimate / floor | repeat |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for v in variants:
        ir = results[v]["ir"]
        print(f"| {vlabel(v)} | {ir['loop']:.1f} | {ir['fn']:.1f} | {fc['floor']} | "
              f"{ir['loop'] / fc['floor']:.2f}x | {ir['fn'] / fc['floor']:.2f}x | {ir['repeat']:+d} |")

    print("\nInstructions executed inside tm_estimate per estimate, by kind:\n")
    print("| kind | " + " | ".join(vlabel(v) for v in variants) + " |")
    print("| --- " * (1 + len(variants)) + "|")
    for kind in MIX_KINDS:
        if not any(results[v]["ir"]["mix"][kind] for v in variants):
            continue
        print(f"| {kind} | " + " | ".join(f"{results[v]['ir']['mix'][kind]:.1f}" for v in variants) + " |")
    print("| total | " + " | ".join(f"{sum(results[v]['ir']['mix'].values()):.1f}" for v in variants) + " |")

    print("\n## Target: unrolled within 1.5x of the floor in instructions\n")
    print("| build | in tm_estimate / floor | whole loop / floor | within 1.5x |")
    print("| --- | --- | --- | --- |")
    for v in variants:
        ir = results[v]["ir"]
        r = ir["fn"] / fc["floor"]
        print(f"| {vlabel(v)} | {r:.2f}x | {ir['loop'] / fc['floor']:.2f}x | {'yes' if r <= 1.5 else 'no'} |")

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
