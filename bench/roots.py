"""The cube root the generated C computes (tm_cbrtf / tm_cbrt, fitgen/roots.py) beside libm's: accuracy and cost.

Run:

    python bench/roots.py > /tmp/roots.md     # about 75 s on 2 cores; progress on stderr

Needs gcc, valgrind and mpmath; qemu-system-arm and arm-none-eabi-gcc for the Cortex-M4F part
(skipped without them). Results and their reading: docs/codegen.md ("Deterministic arithmetic")
and docs/eval-benchmark.md ("Cube roots: before and after").

1. Accuracy, in ulp of the correctly rounded cube root (|y - r| / ulp(r), r the exact root, ulp
   that of r's binade in the routine's precision), and the fraction of results equal to the
   correctly rounded root. Three routines: ours (fitgen.equations.roots.cbrt in numpy; the C tm_cbrtf /
   tm_cbrt from the generated header, compiled with gcc -O2 and fitgen.c.compiled.WARNING_FLAGS, is
   checked to give the same bits on every input), glibc's cbrtf / cbrt (called from the same C
   program), and numpy's np.cbrt.
   - float32, every float in [1, 8) (3 * 2^23 of them): the routine's error pattern repeats every
     factor 8 (the bit guess and every step scale exactly by 2 in the root for 8 in the argument),
     so this is every case of the normal range inside 2^-60..2^60, where no scaling is done.
     Reference: np.cbrt in float64 (its error, about 2^-52 relative, is below 2^-28 float ulp);
     where that lies within 2^-18 float ulp of a halfway point between two floats, the correct
     rounding is settled with mpmath at 120 bits.
   - float32, 2^22 random bit patterns over every positive finite float, subnormals included
     (seed 2026); same reference.
   - float64, 100,000 random bit patterns over every positive finite double, subnormals included,
     and 100,000 uniform in [1, 8) (seed 2026); reference mpmath.cbrt at 120 bits, rounded to 53
     bits by mpmath (round to nearest).
2. Instructions (callgrind, x86-64; deterministic, so one run each; host/cost.py's callgrind helpers):
   - per cube root: a loop over 4,096 inputs log-uniform in [1e-3, 1e3] (seed 2026) adding each
     root into a double, run for 1,000 and 11,000 roots; (Ir(11,000) - Ir(1,000)) / 10,000, and
     the same minus the loop with the identity in place of the root (net). Ours is inlined into
     the loop, as it is into tm_estimate; glibc's is a call through the PLT.
   - per estimate: fitgen.c.cost.C_BENCH and fitgen.c.cost.instruction_counts (as bench/eval.py: gcc -O2,
     WARNING_FLAGS, 1,000 and 11,000 estimates over 4,096 inputs uniform in the model's input box,
     seed 2026; "in tm_estimate" counts tm_estimate and its callees), for the header as generated
     (after) and for the same header text with its TM_CBRT define pointed back at libm's
     cbrtf / cbrt (before). Float and double, table and unrolled.
   The model: the two-rings preset fitted the paper's way, `fitgen simulate --sensor two-rings
   --grid paper-sim` then `fitgen fit --noise 0`: of the five presets' paper-way fits it has the
   most cube roots per estimate (4; two-radii 1, ring-vertical 2, paper and tilted-axes 0).
3. Cortex-M4F instructions per estimate: the reference firmware for QEMU's mps2-an386 (hil.firmware,
   arm-none-eabi-gcc -O2 with newlib-nano), BENCH under -icount shift=0 (hil.emulate.bench_instructions,
   as bench/refine_cost.py), the same model and the same before/after headers (before: newlib's
   cbrtf / cbrt); each BENCH pair run twice to show the count repeats. Double on the M4F is
   software (libgcc), so its figures are mostly that. Flash of the firmware image beside them.
"""

from __future__ import annotations

import platform
import shutil
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from benchutil import log, need_tools, parse_args, table

from fitgen.c.codegen import write_header
from fitgen.equations.model import Model, load_model
from fitgen.equations.roots import cbrt as ours_cbrt
from fitgen.c import cost
from fitgen.c.compiled import WARNING_FLAGS, compile_checked

SENSOR = "two-rings"
SEED = 2026
F32_RANDOM = 1 << 22
F64_RANDOM = 100_000
NEAR_HALF = 2.0**-18  # float ulp: below this distance to a halfway point, mpmath decides
MP_PREC = 120
CHUNK = 1 << 22
ROOT_N1, ROOT_N2 = 1_000, 11_000

LIBM = {"float": "cbrtf", "double": "cbrt"}
OURS = {"float": "tm_cbrtf", "double": "tm_cbrt"}

# One program per precision, including that precision's generated header for its tm_cbrtf / tm_cbrt:
#   roots IN count N             N roots of the NVEC float64 inputs in IN, in turn (callgrind; FUNC picks the root)
#   roots eval IN OURS LIBM      raw tm_real inputs -> raw outputs of ours and of libm's
#   roots range LO HI OURS LIBM  (float) every float whose bits are in [LO, HI)
C_ROOTS = r"""
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <math.h>
#define TM_API static __attribute__((unused))
#include "tm_model.h"

#if TM_PRECISION_FLOAT
#define OURS tm_cbrtf
#define LIBM cbrtf
#else
#define OURS tm_cbrt
#define LIBM cbrt
#endif
#define IDENT(x) (x)
#ifndef FUNC
#define FUNC OURS
#endif

#define NVEC 4096
static tm_real xs[NVEC];
""" + cost.C_READ_RAW + r"""

static double run(long n)
{
    double acc = 0.0;
    long i;
    int k = 0;
    for (i = 0; i < n; ++i) {
        acc += (double)FUNC(xs[k]);
        if (++k == NVEC) {
            k = 0;
        }
    }
    return acc;
}

static void write_all(const char *path, const tm_real *y, long n)
{
    FILE *f = fopen(path, "wb");
    if (f == NULL || fwrite(y, sizeof *y, (size_t)n, f) != (size_t)n) {
        fprintf(stderr, "cannot write %s\n", path);
        exit(2);
    }
    fclose(f);
}

static void eval(const tm_real *x, long n, const char *ours_path, const char *libm_path)
{
    tm_real *y = calloc((size_t)n, sizeof *y);
    long i;
    if (y == NULL) {
        exit(2);
    }
    for (i = 0; i < n; ++i) {
        y[i] = OURS(x[i]);
    }
    write_all(ours_path, y, n);
    for (i = 0; i < n; ++i) {
        y[i] = LIBM(x[i]);
    }
    write_all(libm_path, y, n);
    free(y);
}

int main(int argc, char **argv)
{
    FILE *f;
    long n, i;
    tm_real *x;
    if (argc >= 4 && strcmp(argv[2], "count") == 0) {
        static double raw[NVEC];
        if (read_raw(argv[1], raw, NVEC) != 0) {
            return 2;
        }
        for (i = 0; i < NVEC; ++i) {
            xs[i] = (tm_real)raw[i];
        }
        printf("%.17g\n", run(atol(argv[3])));
        return 0;
    }
    if (argc == 5 && strcmp(argv[1], "eval") == 0) {
        f = fopen(argv[2], "rb");
        if (f == NULL || fseek(f, 0, SEEK_END) != 0) {
            return 2;
        }
        n = ftell(f) / (long)sizeof(tm_real);
        rewind(f);
        x = malloc((size_t)n * sizeof *x);
        if (x == NULL || fread(x, sizeof *x, (size_t)n, f) != (size_t)n) {
            return 2;
        }
        fclose(f);
        eval(x, n, argv[3], argv[4]);
        free(x);
        return 0;
    }
#if TM_PRECISION_FLOAT
    if (argc == 6 && strcmp(argv[1], "range") == 0) {
        unsigned long lo = strtoul(argv[2], NULL, 0), hi = strtoul(argv[3], NULL, 0);
        uint32_t b;
        n = (long)(hi - lo);
        x = malloc((size_t)n * sizeof *x);
        if (x == NULL) {
            return 2;
        }
        for (i = 0; i < n; ++i) {
            b = (uint32_t)(lo + (unsigned long)i);
            memcpy(&x[i], &b, sizeof b);
        }
        eval(x, n, argv[4], argv[5]);
        free(x);
        return 0;
    }
#endif
    fprintf(stderr, "usage: %s INPUTS count N | eval IN OURS LIBM | range LO HI OURS LIBM\n", argv[0]);
    return 2;
}
"""


# --- the model and the headers ------------------------------------------------------------------

def fit_two_rings(folder: Path) -> Model:
    """The preset fitted the paper's way, through the command line exactly as a user would."""
    fitgen = [sys.executable, "-c", "import sys; from fitgen.app.cli import main; main(sys.argv[1:])"]
    cost.run(fitgen + ["simulate", "--sensor", SENSOR, "--grid", "paper-sim", "-o", str(folder / "s.csv")])
    cost.run(fitgen + ["fit", str(folder / "s.csv"), "--noise", "0", "-o", str(folder / "m.json")])
    return load_model(folder / "m.json")


def point_at_libm(header: Path, precision: str) -> None:
    """The 'before' header: the same text, TM_CBRT back on libm's cbrtf / cbrt."""
    text = header.read_text()
    old = f"#define TM_CBRT {OURS[precision]}\n"
    if text.count(old) != 1:
        raise RuntimeError(f"{header}: no single line {old.strip()!r}")
    header.write_text(text.replace(old, f"#define TM_CBRT {LIBM[precision]}\n"))


def build_estimate_bench(model: Model, style: str, precision: str, before: bool, folder: Path) -> Path:
    """fitgen.c.cost.build_bench, with the header patched in between for the 'before' build."""
    folder.mkdir(parents=True, exist_ok=True)
    header = write_header(model, folder, precision, style)
    if before:
        point_at_libm(header, precision)
    (folder / "bench.c").write_text(cost.C_BENCH)
    compile_checked("gcc", [folder / "bench.c"], folder / "bench", folder)
    return folder / "bench"


def build_roots(model: Model, precision: str, func: str, folder: Path) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    write_header(model, folder, precision, "unrolled")
    (folder / "roots.c").write_text(C_ROOTS)
    compile_checked("gcc", [folder / "roots.c"], folder / "roots", folder, [f"-DFUNC={func}"])
    return folder / "roots"


# --- accuracy -------------------------------------------------------------------------------------

class Tally:
    """max and mean ulp error and the count of correctly rounded results, accumulated over chunks."""

    def __init__(self):
        self.max = 0.0
        self.sum = 0.0
        self.n = 0
        self.correct = 0

    def add(self, err: np.ndarray, correct: np.ndarray) -> None:
        if err.size:
            self.max = max(self.max, float(err.max()))
        self.sum += float(err.sum())
        self.n += err.size
        self.correct += int(correct.sum())

    def row(self) -> list[str]:
        return [f"{self.max:.3f}", f"{self.sum / self.n:.3f}", f"{100.0 * self.correct / self.n:.2f} %"]


def mp_round(x, prec: int) -> float:
    """The exact cube root of float x, rounded to nearest at ``prec`` bits (float() of an mpf truncates)."""
    import mpmath

    with mpmath.workprec(MP_PREC):
        r = mpmath.cbrt(mpmath.mpf(float(x)))
    with mpmath.workprec(prec):
        return float(+r)


def float32_reference(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """(root in float64, ulp of the float32 root, correctly rounded float32 root, cases settled by mpmath)."""
    r = np.cbrt(x.astype(np.float64))
    _, e = np.frexp(r)
    ulp = np.ldexp(1.0, e - 24)
    q = r / ulp
    near = np.abs(q - np.floor(q) - 0.5) < NEAR_HALF
    rounded = r.astype(np.float32)
    for i in np.flatnonzero(near):
        rounded[i] = np.float32(mp_round(x[i], 24))
    return r, ulp, rounded, int(near.sum())


def accuracy_float32(x_chunks, libm_all: np.ndarray, ours_c_all: np.ndarray) -> dict:
    """Tallies of ours, glibc's and numpy's over the chunks of float32 inputs; C-vs-Python differences."""
    tallies = {k: Tally() for k in ("ours", "libm", "numpy")}
    settled = 0
    c_differs = 0
    numpy_is_libm = 0
    start = 0
    for x in x_chunks:
        stop = start + x.size
        r, ulp, rounded, near = float32_reference(x)
        settled += near
        ys = {"ours": ours_cbrt(x), "libm": libm_all[start:stop], "numpy": np.cbrt(x)}
        c_differs += int(np.count_nonzero(ys["ours"].view(np.uint32) != ours_c_all[start:stop].view(np.uint32)))
        numpy_is_libm += int(np.count_nonzero(ys["numpy"].view(np.uint32) == ys["libm"].view(np.uint32)))
        for k, y in ys.items():
            tallies[k].add(np.abs(y.astype(np.float64) - r) / ulp, y == rounded)
        start = stop
    return {"tallies": tallies, "settled": settled, "c_differs": c_differs, "n": start,
            "numpy_is_libm": numpy_is_libm}


def accuracy_float64(x: np.ndarray, ys: dict) -> dict:
    import mpmath

    tallies = {k: Tally() for k in ys}
    errs = {k: np.empty(x.size) for k in ys}
    good = {k: np.empty(x.size, dtype=bool) for k in ys}
    with mpmath.workprec(MP_PREC):
        for i, xi in enumerate(x):
            r = mpmath.cbrt(mpmath.mpf(float(xi)))
            _, e = mpmath.frexp(r)
            with mpmath.workprec(53):
                rounded = float(+r)
            for k, y in ys.items():
                yi = float(y[i])
                errs[k][i] = abs(float(mpmath.ldexp(mpmath.mpf(yi) - r, 53 - e)))
                good[k][i] = yi == rounded
    for k in ys:
        tallies[k].add(errs[k], good[k])
    return tallies


def random_bits(rng: np.random.Generator, n: int, dtype) -> np.ndarray:
    """n positive finite numbers of ``dtype`` with uniformly random bit patterns (subnormals included)."""
    uint, top = (np.uint32, 0x7F800000) if dtype == np.float32 else (np.uint64, 0x7FF0000000000000)
    return rng.integers(1, top, size=n, dtype=uint).view(dtype)


def c_eval(binary: Path, x: np.ndarray, work: Path) -> tuple[np.ndarray, np.ndarray]:
    (work / "in.bin").write_bytes(np.ascontiguousarray(x).tobytes())
    cost.run([str(binary), "eval", str(work / "in.bin"), str(work / "ours.bin"), str(work / "libm.bin")])
    return (np.fromfile(work / "ours.bin", dtype=x.dtype), np.fromfile(work / "libm.bin", dtype=x.dtype))


# --- instructions ---------------------------------------------------------------------------------

def ir_total(binary: Path, inputs: Path, n: int, out: Path) -> int:
    return cost.parse_callgrind(cost.callgrind(binary, inputs, n, out, dump_instr=False))[0]


def per_root(binary: Path, inputs: Path, work: Path) -> float:
    work.mkdir(parents=True, exist_ok=True)
    a = ir_total(binary, inputs, ROOT_N1, work / "r1.out")
    b = ir_total(binary, inputs, ROOT_N2, work / "r2.out")
    return (b - a) / (ROOT_N2 - ROOT_N1)


def m4f_counts(model: Model, precision: str, style: str, before: bool, folder: Path) -> dict:
    from hil.emulate import MACHINES, Emulator, bench_instructions
    from hil.firmware import build_firmware, firmware_size, render_firmware
    from host.device import Device

    render_firmware(model, folder, precision=precision, style=style, port="mps2")
    if before:
        point_at_libm(folder / "tm_model.h", precision)
    image = build_firmware(folder, "mps2")
    with Emulator(image, machine=MACHINES["mps2"]) as emu:
        with Device.open(emu.url, timeout=10) as dev:
            first = bench_instructions(dev)["instructions"]
            again = bench_instructions(dev)["instructions"]
    return {"ins": first, "repeat": again - first, "flash": firmware_size(image)["flash"]}


def before_after(counts: dict, key: str, fmt: str, roots_per_estimate: int, more) -> list[list[str]]:
    """Table rows per build (style, precision): ``counts[...][key]`` before and after in format ``fmt``,
    the difference, per cube root, then the cells ``more(before, after)``."""
    rows = []
    for s in ("table", "unrolled"):
        for p in ("float", "double"):
            b, a = counts[s, p, True], counts[s, p, False]
            d = a[key] - b[key]
            rows.append([f"{s} {p}", format(b[key], fmt), format(a[key], fmt), format(d, "+" + fmt),
                         format(d / roots_per_estimate, "+" + fmt)] + more(b, a))
    return rows


def cpu_name() -> str:
    try:
        return next(ln.split(":", 1)[1].strip() for ln in open("/proc/cpuinfo") if ln.startswith("model name"))
    except (OSError, StopIteration):
        return platform.processor() or "CPU unknown"


# --- main -----------------------------------------------------------------------------------------

def main() -> None:
    parse_args(__doc__)  # no options: one it does not know is refused, not ignored
    need_tools("gcc", "valgrind")
    have_m4f = all(shutil.which(t) for t in ("qemu-system-arm", "arm-none-eabi-gcc"))
    rng = np.random.default_rng(SEED)
    with tempfile.TemporaryDirectory(prefix="fitgen-roots-") as tmp, ThreadPoolExecutor(2) as pool:
        root = Path(tmp)
        log(f"fitting {SENSOR} the paper's way ...")
        model = fit_two_rings(root)
        n_cbrt = sum(1 for eq in model.equations for t in eq.terms if t.exponent == "1/3")
        roots_per_estimate = sum("1/3" in need for need in cost.needs(model))
        n_terms = sum(len(eq.terms) for eq in model.equations)

        # builds: the roots programs (ours, libm, identity per precision) and the 8 estimate benches
        log("building ...")
        progs = {(p, f): build_roots(model, p, func, root / f"roots-{p}-{f}")
                 for p in ("float", "double") for f, func in
                 (("ours", OURS[p]), ("libm", LIBM[p]), ("identity", "IDENT"))}
        variants = [(s, p, b) for s in ("table", "unrolled") for p in ("float", "double") for b in (True, False)]
        benches = {v: build_estimate_bench(model, *v, root / f"est-{v[0]}-{v[1]}-{'before' if v[2] else 'after'}")
                   for v in variants}

        # instructions on x86-64, two callgrind jobs at a time
        log("callgrind: per cube root and per estimate ...")
        root_inputs = root / "roots.f64"
        np.exp(rng.uniform(np.log(1e-3), np.log(1e3), cost.NVEC)).tofile(root_inputs)
        est_inputs = cost.write_inputs(model.input_min + (model.input_max - model.input_min)
                                       * np.random.default_rng(SEED).random((cost.NVEC, model.n_inputs)),
                                       root / "inputs.f64")
        root_jobs = {k: pool.submit(per_root, b, root_inputs, b.parent / "cg") for k, b in progs.items()}
        est_jobs = {v: pool.submit(cost.instruction_counts, b, est_inputs, b.parent, mix=False)
                    for v, b in benches.items()}

        # accuracy (in this thread while callgrind runs)
        log("accuracy: float32, every float in [1, 8) ...")
        lo, hi = 0x3F800000, 0x41000000
        cost.run([str(progs["float", "ours"]), "range", hex(lo), hex(hi), str(root / "f_ours.bin"),
                  str(root / "f_libm.bin")])
        ours_c = np.fromfile(root / "f_ours.bin", dtype=np.float32)
        libm = np.fromfile(root / "f_libm.bin", dtype=np.float32)
        chunks = (np.arange(a, min(a + CHUNK, hi), dtype=np.uint32).view(np.float32) for a in range(lo, hi, CHUNK))
        acc = {"f32 [1, 8)": accuracy_float32(chunks, libm, ours_c)}
        del ours_c, libm
        log("accuracy: float32, random bit patterns ...")
        x = random_bits(rng, F32_RANDOM, np.float32)
        ours_c, libm = c_eval(progs["float", "ours"], x, root)
        acc["f32 random"] = accuracy_float32(iter([x]), libm, ours_c)
        f64 = {}
        for label, x in (("random bit patterns", random_bits(rng, F64_RANDOM, np.float64)),
                         ("uniform in [1, 8)", rng.uniform(1.0, 8.0, F64_RANDOM))):
            log(f"accuracy: float64, {label} (mpmath) ...")
            ours_c, libm = c_eval(progs["double", "ours"], x, root)
            ys = {"ours": ours_cbrt(x), "libm": libm, "numpy": np.cbrt(x)}
            f64[label] = {"tallies": accuracy_float64(x, ys), "n": x.size,
                          "c_differs": int(np.count_nonzero(ys["ours"].view(np.uint64) != ours_c.view(np.uint64))),
                          "numpy_is_libm": int(np.count_nonzero(ys["numpy"].view(np.uint64) == libm.view(np.uint64))),
                          "subnormal": int(np.count_nonzero(x < np.finfo(np.float64).tiny))}

        log("waiting for callgrind ...")
        per = {k: j.result() for k, j in root_jobs.items()}
        est = {v: j.result() for v, j in est_jobs.items()}

        m4f = {}
        if have_m4f:
            log("Cortex-M4F (QEMU mps2-an386, icount): 8 firmware builds ...")
            jobs = {v: pool.submit(m4f_counts, model, v[1], v[0], v[2],
                                   root / f"fw-{v[0]}-{v[1]}-{'before' if v[2] else 'after'}") for v in variants}
            m4f = {v: j.result() for v, j in jobs.items()}
        else:
            log("qemu-system-arm or arm-none-eabi-gcc missing: Cortex-M4F part skipped")

    # --- tables ---
    gcc_version = cost.run(["gcc", "--version"]).stdout.splitlines()[0]
    glibc = " ".join(platform.libc_ver())
    arm_gcc = cost.run(["arm-none-eabi-gcc", "--version"]).stdout.splitlines()[0] if m4f else ""
    try:
        from numpy._core._multiarray_umath import __cpu_features__ as cpu

        avx512 = "AVX512F" if cpu.get("AVX512F") else "no AVX-512"
    except ImportError:
        avx512 = "CPU features unknown"
    print("# The cube root of the generated C: accuracy and cost (bench/roots.py)\n")
    print(f"Ours: fitgen.equations.roots.cbrt (numpy) and the C tm_cbrtf / tm_cbrt of the generated header. "
          f"libm: {glibc}. numpy {np.__version__} ({avx512} on this CPU). {gcc_version}; "
          f"{platform.machine()}, {cpu_name()}.\n")

    print("## Accuracy (ulp of the correctly rounded root)\n")
    names = {"ours": "ours", "libm": "glibc {}", "numpy": "numpy np.cbrt"}
    rows = []
    for label, key, prec in (("float32, every float in [1, 8)", "f32 [1, 8)", "float"),
                             ("float32, random bit patterns", "f32 random", "float")):
        a = acc[key]
        for k, t in a["tallies"].items():
            rows.append([label, f"{a['n']:,}", names[k].format(LIBM[prec])] + t.row())
    for label, a in f64.items():
        for k, t in a["tallies"].items():
            rows.append([f"float64, {label}", f"{a['n']:,}", names[k].format("cbrt")] + t.row())
    print(table(["inputs", "n", "routine", "max ulp", "mean ulp", "correctly rounded"], rows))
    print()
    for label, key in (("float32 [1, 8)", "f32 [1, 8)"), ("float32 random", "f32 random")):
        a = acc[key]
        print(f"- {label}: C tm_cbrtf differs from fitgen.equations.roots.cbrt on {a['c_differs']} of {a['n']:,} inputs; "
              f"np.cbrt gives glibc's bits on {a['numpy_is_libm']:,}; {a['settled']} near-halfway cases "
              f"settled by mpmath.")
    for label, a in f64.items():
        print(f"- float64 {label}: C tm_cbrt differs from fitgen.equations.roots.cbrt on {a['c_differs']} of {a['n']:,}; "
              f"np.cbrt gives glibc's bits on {a['numpy_is_libm']:,}; {a['subnormal']} subnormal inputs.")

    print("\n## Instructions per cube root (callgrind, x86-64)\n")
    print(f"Loop over {cost.NVEC:,} inputs log-uniform in [1e-3, 1e3], each root added into a double; "
          f"(Ir({ROOT_N2:,}) - Ir({ROOT_N1:,})) / {ROOT_N2 - ROOT_N1:,}. Net: minus the same loop with the "
          f"identity. Ours inlined, glibc's called through the PLT.\n")
    rows = []
    for p in ("float", "double"):
        base = per[p, "identity"]
        for f in ("ours", "libm"):
            name = f"ours ({OURS[p]})" if f == "ours" else f"glibc {LIBM[p]}"
            rows.append([p, name, f"{per[p, f]:.1f}", f"{per[p, f] - base:.1f}"])
    print(table(["precision", "routine", "instructions per root, loop included", "net"], rows))

    print("\n## Instructions per estimate (callgrind, x86-64)\n")
    print(f"Model: {SENSOR} fitted the paper's way (paper-sim grid, `fitgen fit --noise 0`), {model.n_inputs} inputs, "
          f"{len(model.equations)} outputs, {n_terms} terms, {n_cbrt} cube-root terms, {roots_per_estimate} cube "
          f"roots per estimate; model {model.sha256[:12]}. C_BENCH, gcc -O2 {' '.join(WARNING_FLAGS)}, "
          f"{cost.NVEC:,} inputs uniform in the input box; (Ir({cost.N2:,}) - Ir({cost.N1:,})) / "
          f"{cost.N2 - cost.N1:,}. Before: the same header with TM_CBRT on libm's cbrtf / cbrt. "
          f"Repeat: a second run at {cost.N1:,} estimates minus the first, before / after.\n")
    rows = before_after(est, "fn", ".1f", roots_per_estimate,
                        lambda b, a: [f"{b['loop']:.1f}", f"{a['loop']:.1f}", f"{b['repeat']:+d} / {a['repeat']:+d}"])
    print(table(["build", "in tm_estimate, before (libm)", "after (ours)", "difference", "per cube root",
                 "whole loop, before", "whole loop, after", "repeat"], rows))

    if m4f:
        print("\n## Instructions per estimate on the Cortex-M4F (QEMU mps2-an386, icount)\n")
        print(f"Reference firmware, {arm_gcc}, -O2, newlib-nano; BENCH at 200 and 2,200 estimates under "
              "-icount shift=0 (a 40-instruction tick, so 0.02 instructions of resolution). Before: newlib's "
              "cbrtf / cbrt. Repeat: a second BENCH pair minus the first, before / after. Flash: the image.\n")
        rows = before_after(m4f, "ins", ",.1f", roots_per_estimate, lambda b, a: [
            f"{b['repeat']:+.2f} / {a['repeat']:+.2f}", f"{b['flash']:,}", f"{a['flash']:,}"])
        print(table(["build", "before (newlib)", "after (ours)", "difference", "per cube root", "repeat",
                     "flash before", "flash after"], rows))
    log("done")


if __name__ == "__main__":
    main()
