"""What one estimate costs: instructions counted by callgrind, operations by kind, flash on Cortex-M.

The measuring pieces bench/eval.py and ``fitgen tradeoff`` share:

- :data:`C_BENCH`: a bench program that includes ``tm_model.h`` (tm_estimate kept out of
  line, as a call on a device is), reads :data:`NVEC` input vectors (raw float64, row-major;
  cast to ``tm_input``, so a fixed-point header gets them as the integer codes the file holds)
  and runs N estimates over them in turn (``count N``), or times them.
- :func:`instruction_counts`: callgrind (x86-64) at N1 and N2 estimates; (Ir(N2) - Ir(N1)) /
  (N2 - N1) per estimate, for the whole loop and inside tm_estimate and its callees, which
  removes start-up and input reading. Deterministic: the same binary gives the same counts.
- :func:`template_ops`: floating-point operations per estimate as the templates write them.
- :func:`arm_sizes`: text/data/bss of the estimator compiled for a Cortex-M core, and the flash it
  adds to a linked newlib program (library code included) over an empty main.

Needs gcc and valgrind (and objdump for the instruction mix); arm-none-eabi-gcc/size/nm for sizes.
"""

from __future__ import annotations

import re
import shlex
import subprocess
from collections import Counter
from pathlib import Path

import numpy as np

from fitgen.base.children import run_captured
from fitgen.c.codegen import write_header
from fitgen.equations.model import Model
from fitgen.equations.terms import monomial_factors
from fitgen.c.compiled import compile_checked

NVEC = 4096
N1, N2 = 1_000, 11_000
# Cortex-M cores: the M4F has a single-precision FPU (double is software, libgcc __aeabi_d*);
# the M0 has none (the fixed-point target)
ARM_CORES = {
    "cortex-m4f": "arm-none-eabi-gcc -mcpu=cortex-m4 -mthumb -mfloat-abi=hard -mfpu=fpv4-sp-d16",
    "cortex-m0": "arm-none-eabi-gcc -mcpu=cortex-m0 -mthumb -mfloat-abi=soft",
}
ARM_CC = ARM_CORES["cortex-m4f"]

# the input file of the bench programs (this one and bench/roots.py's): ``count`` raw float64 numbers
C_READ_RAW = r"""
static int read_raw(const char *path, double *raw, size_t count)
{
    FILE *f = fopen(path, "rb");
    if (f == NULL || fread(raw, sizeof *raw, count, f) != count) {
        fprintf(stderr, "cannot read %s\n", path);
        return 2;
    }
    fclose(f);
    return 0;
}
"""

C_BENCH = r"""
#define _POSIX_C_SOURCE 199309L
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#define TM_API static __attribute__((noinline, noclone))
#include "tm_model.h"

#define NVEC 4096
static tm_input inputs[NVEC][TM_N_INPUTS];
static volatile double sink;
""" + C_READ_RAW + r"""

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* n estimates over the vectors in turn; status and outputs summed so that none is dead */
static double run(long n)
{
    tm_output out[TM_N_OUTPUTS];
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
    int i, j;
    long n;
    double t;
    if (argc < 4) {
        fprintf(stderr, "usage: %s INPUTS calibrate SECONDS | INPUTS time N | INPUTS count N\n", argv[0]);
        return 2;
    }
    if (read_raw(argv[1], &raw[0][0], (size_t)NVEC * TM_N_INPUTS) != 0) {
        return 2;
    }
    for (i = 0; i < NVEC; ++i) {
        for (j = 0; j < TM_N_INPUTS; ++j) {
            inputs[i][j] = (tm_input)raw[i][j];
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
int tm_bench_call(const tm_input *in, tm_output *out);
int tm_bench_call(const tm_input *in, tm_output *out)
{
    return tm_estimate(in, out);
}
"""
C_ARM_MAIN = """
#include "tm_model.h"
int tm_bench_call(const tm_input *in, tm_output *out);
int main(void);
int main(void)
{
    static tm_input in[TM_N_INPUTS];
    static tm_output out[TM_N_OUTPUTS];
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


def run(cmd: list[str], **kw) -> subprocess.CompletedProcess:
    """Run a tool; a failure is a RuntimeError with its first lines of stderr."""
    proc = run_captured(cmd, **kw)
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed ({proc.returncode}): {proc.stderr.strip()[:400]}")
    return proc


# --- operation counts -------------------------------------------------------------------------

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
    in the unrolled style. Clamp: isfinite and 2 compares per input. Harmonic terms: the ring's
    sum (N - 1 adds) and its reciprocal (1 division), per harmonic used one multiply and add per
    nonzero weight and one multiply by 1/sum, per monomial one multiply per factor after the first.
    """
    ops = Counter()
    monomials = {t.harm for eq in model.equations for t in eq.terms if t.harm}
    if monomials:
        used = {f for text in monomials for f in monomial_factors(text)}
        ops["add"] += model.n_inputs - 1
        ops["div"] += 1
        for sym, w in model.harmonics.weights:
            if sym in used:
                n_w = sum(1 for x in w if x != 0.0)
                ops["mul"] += n_w + 1
                ops["add"] += n_w - 1
        ops["mul"] += sum(len(monomial_factors(text)) - 1 for text in monomials)
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
    if model.refine is not None:
        ops.update(refine_ops(model.refine))  # update, not +=: a Counter sum drops the zero counts
    return ops


def refine_ops(r) -> Counter:
    """Floating-point operations of a refinement's steps (fitgen.equations.refine) as model.h.j2 writes them,
    every step taken: per step the scaled pose and its powers, each monomial once (4 multiplies),
    the prior's share, per forward term one multiply-add for the value and, per component it holds,
    the power times the derivative's monomial and a multiply-add; per element the transform, the
    residual and the normal equations' updates; then a 5x5 Cholesky solve and the clamp."""
    ops = Counter()
    n = len(r.forward)
    ops["add"] += 5 + 5 + 25  # u, dp, g
    ops["mul"] += 5 + 5 * r.degree + 4 * len(r.monomials) + 25
    for eq in r.forward:
        for e in eq.exponents:
            held = sum(1 for a in e if a)
            ops["mul"] += 1 + 2 * held
            ops["add"] += 1 + held
    if r.transform == "cbrt":
        ops["mul"] += 3 * n
        ops["div"] += 2 * n
        ops["compare"] += n
    ops["add"] += n * (1 + 5 + 15)
    ops["mul"] += n * (1 + 10 + 5 + 5 + 15)
    for j in range(5):
        ops["mul"] += j + (4 - j) * j + 2 * j
        ops["add"] += j + (4 - j) * j + 2 * j
        ops["div"] += (4 - j) + 2
        ops["sqrt"] += 1
        ops["compare"] += 1
    ops["add"] += 5
    ops["compare"] += 10
    ops["isfinite"] += 5
    for k in ops:
        ops[k] *= r.steps
    return ops


# --- callgrind ----------------------------------------------------------------------------------

def callgrind(binary: Path, inputs_file: Path, n: int, out: Path, dump_instr: bool = True) -> Path:
    """Run the bench program for ``n`` estimates under callgrind; the output file's path."""
    run(["valgrind", "--tool=callgrind", f"--dump-instr={'yes' if dump_instr else 'no'}", "--dump-line=no",
         f"--callgrind-out-file={out}", str(binary), str(inputs_file), "count", str(n)])
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


# --- builds and measurements ------------------------------------------------------------------

def write_inputs(inputs: np.ndarray, path: Path) -> Path:
    """The bench program's input file: exactly NVEC rows (repeated or cut), float64, row-major."""
    X = np.atleast_2d(np.asarray(inputs, dtype=np.float64))
    X = X[np.arange(NVEC) % len(X)]
    np.ascontiguousarray(X).tofile(path)
    return path


def build_bench(model: Model, style: str, precision: str, fma: bool, folder: Path,
                extra: list[str] | None = None, **header) -> Path:
    """The bench program for the model's header (written into ``folder``), built with gcc -O2.

    ``header``: further keywords of fitgen.c.codegen.write_header (input_lsb, input_offset for fixed point).
    """
    folder.mkdir(parents=True, exist_ok=True)
    write_header(model, folder, precision, style, fma=fma, **header)
    src = folder / "bench.c"
    src.write_text(C_BENCH)
    binary = folder / "bench"
    compile_checked("gcc", [src], binary, folder, extra)
    return binary


def instruction_counts(binary: Path, inputs_file: Path, work: Path, n1: int = N1, n2: int = N2,
                       mix: bool = True, repeat: bool = True) -> dict:
    """Instructions per estimate from callgrind runs at ``n1`` and ``n2`` estimates.

    ``loop``: whole bench loop; ``fn``: inside tm_estimate and what it calls; with ``mix`` also the
    executed instructions by kind and mnemonic (objdump); with ``repeat`` a second run at n1, whose
    total minus the first (``repeat``) shows that the counts repeat exactly.
    """
    a = parse_callgrind(callgrind(binary, inputs_file, n1, work / "cg-n1.out", mix))
    b = parse_callgrind(callgrind(binary, inputs_file, n2, work / "cg-n2.out", mix))
    n = n2 - n1
    out = {"loop": (b[0] - a[0]) / n, "fn": (b[1] - a[1]) / n, "n1_total": a[0]}
    if repeat:
        again = parse_callgrind(callgrind(binary, inputs_file, n1, work / "cg-n1b.out", mix))
        out["repeat"] = again[0] - a[0]
    if mix:
        dis = disassembly(binary)
        kinds: Counter = Counter()
        mnem: Counter = Counter()
        for addr in set(a[2]) | set(b[2]):
            count = (b[2][addr] - a[2][addr]) / n
            op, args = dis.get(addr, ("?", ""))
            kinds[kind_of(op, args)] += count
            mnem[op] += count
        out["mix"], out["mnemonics"] = kinds, mnem
    return out


def _size(path: Path) -> tuple[int, int, int]:
    text, data, bss = (int(x) for x in run(["arm-none-eabi-size", str(path)]).stdout.splitlines()[1].split()[:3])
    return text, data, bss


def arm_sizes(model: Model, style: str, precision: str, fma: bool, folder: Path, cc: str = ARM_CC,
              **header) -> dict:
    """Sizes in bytes of the estimator built for a Cortex-M core (``cc``: compiler and core flags).

    ``cc -O2 -c`` (warning flags, -fstack-usage) of a file whose non-static function calls the static
    tm_estimate (inlined there): text, data, bss of the .o, its stack frame, the symbols it leaves
    undefined (library code), and ``linked``: the flash it adds to a newlib program (nosys.specs,
    --gc-sections) over an empty main, library code included. ``header``: as for :func:`build_bench`.
    """
    d = Path(folder)
    d.mkdir(parents=True, exist_ok=True)
    write_header(model, d, precision, style, fma=fma, **header)
    (d / "call.c").write_text(C_ARM)
    obj = d / "call.o"
    compile_checked(cc, [d / "call.c"], obj, d, ["-fstack-usage"], link=False)
    text, data, bss = _size(obj)
    su = (d / "call.su").read_text().split()
    undefined = [ln.split()[-1] for ln in run(["arm-none-eabi-nm", "-u", str(obj)]).stdout.splitlines() if ln.strip()]
    (d / "main.c").write_text(C_ARM_MAIN)
    (d / "empty.c").write_text(C_ARM_EMPTY)
    link = shlex.split(cc) + ["-O2", "-specs=nosys.specs", "-Wl,--gc-sections", "-I", str(d)]
    run(link + [str(d / "main.c"), str(obj), "-o", str(d / "full.elf"), "-lm"])
    run(link + [str(d / "empty.c"), "-o", str(d / "empty.elf")])
    sizes = [sum(_size(d / elf)[:2]) for elf in ("full.elf", "empty.elf")]
    return {"text": text, "data": data, "bss": bss, "stack": int(su[1]), "undefined": undefined,
            "linked": sizes[0] - sizes[1]}
