"""The cube root of the generated C (fitgen.equations.roots): accurate, and the same bits in C and Python on every machine.

Tests marked ``bitexact`` run twice: here, and in a subprocess with numpy's SIMD dispatch switched off
(NPY_DISABLE_CPU_FEATURES), so that nothing bit-exact rests on the CPU numpy finds.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import mpmath
import numpy as np
import pytest

from conftest import IN_CI, require_tool, run_cli
from fitgen.c.codegen import write_header
from fitgen.equations.model import Equation, Model
from fitgen.equations.roots import cbrt
from fitgen.equations.terms import parse_term

UINT = {np.float32: np.uint32, np.float64: np.uint64}


def _bit_patterns(dtype, n: int, seed: int) -> np.ndarray:
    """Random bit patterns of ``dtype`` (every sign, exponent and mantissa: subnormals, huge, specials)."""
    rng = np.random.default_rng(seed)
    bits = rng.integers(0, np.iinfo(np.int64).max, n, dtype=np.int64).astype(np.uint64)
    bits = bits.astype(UINT[dtype]) if dtype is np.float32 else bits * np.uint64(2) + (bits & np.uint64(1))
    fi = np.finfo(dtype)
    special = np.array([0.0, -0.0, fi.smallest_subnormal, fi.tiny, fi.max, -fi.max, np.inf, -np.inf, 1.0, 8.0,
                        27.0, 0.001, 2.0**-60, 2.0**60, 2.0**-600 if dtype is np.float64 else 0.5], dtype=dtype)
    return np.concatenate([special.view(UINT[dtype]), bits])


@pytest.mark.parametrize("dtype, max_ulp", [(np.float32, 1.0), (np.float64, 1.0)])
def test_cbrt_within_one_ulp_of_the_correctly_rounded_root(dtype, max_ulp):
    x = _bit_patterns(dtype, 3000, 1).view(dtype)
    x = np.abs(x[np.isfinite(x) & (x != 0)])
    y = cbrt(x)
    assert y.dtype == dtype
    mpmath.mp.prec = 200
    worst = 0.0
    for xi, yi in zip(x.tolist(), y.tolist()):
        exact = mpmath.cbrt(mpmath.mpf(xi))
        ulp = float(np.spacing(dtype(abs(yi))))
        worst = max(worst, float(abs(mpmath.mpf(yi) - exact)) / ulp)
    assert worst <= max_ulp, worst


def test_cbrt_specials_and_sign():
    for dt in (np.float32, np.float64):
        x = np.array([0.0, -0.0, np.inf, -np.inf, -27.0, 27.0, np.nan], dtype=dt)
        y = cbrt(x)
        assert y.dtype == dt
        np.testing.assert_array_equal(y[:6], np.array([0.0, -0.0, np.inf, -np.inf, -3.0, 3.0], dtype=dt))
        assert np.signbit(y[1]) and np.isnan(y[6])


def _root_model() -> Model:
    return Model(np.array([0.1, 0.1]), np.array([3.0, 3.0]),
                 (Equation("dx", 0.5, (parse_term("v1^1/3"), parse_term("v2^-2")), (1.5, -0.25)),))


def _cbrt_runner(folder: Path, precision: str, cc: list[str]) -> Path:
    """A program that reads bit patterns (hex) and prints the header's cube root of each, as bits."""
    write_header(_root_model(), folder, precision, "table", "tm")
    real, fn, w = ("float", "tm_cbrtf", "32") if precision == "float" else ("double", "tm_cbrt", "64")
    (folder / "roots.c").write_text(f"""#include <inttypes.h>
#include <stdio.h>
#include "tm_model.h"
int main(void)
{{
    uint{w}_t b;
    {real} x;
    (void)tm_estimate;
    while (scanf("%" SCNx{w}, &b) == 1) {{
        memcpy(&x, &b, sizeof x);
        x = {fn}(x);
        memcpy(&b, &x, sizeof b);
        printf("%" PRIx{w} "\\n", b);
    }}
    return 0;
}}
""")
    from fitgen.c.compiled import WARNING_FLAGS

    exe = folder / "roots"
    proc = subprocess.run(cc + WARNING_FLAGS + ["-O2", "-I", str(folder), str(folder / "roots.c"), "-o", str(exe),
                                                "-lm"], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    return exe


@pytest.mark.bitexact
@pytest.mark.parametrize("precision", ["float", "double"])
@pytest.mark.parametrize("target", ["gcc", "qemu-arm"])
def test_cbrt_c_equals_python_bit_for_bit(tmp_path, precision, target):
    """The header's tm_cbrtf / tm_cbrt against fitgen.equations.roots.cbrt on random bit patterns of the whole range."""
    if target == "gcc":
        cc, runner = [require_tool("gcc")], []
    else:
        cc, runner = [require_tool("arm-linux-gnueabihf-gcc"), "-static"], [require_tool("qemu-arm")]
    dtype = np.float32 if precision == "float" else np.float64
    exe = _cbrt_runner(tmp_path, precision, cc)
    bits = _bit_patterns(dtype, 50000, 2)
    proc = subprocess.run(runner + [str(exe)], input="\n".join(format(int(b), "x") for b in bits) + "\n",
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    c = np.array([int(t, 16) for t in proc.stdout.split()], dtype=UINT[dtype])
    py = cbrt(bits.view(dtype)).view(UINT[dtype])
    nan = np.isnan(bits.view(dtype))
    assert len(c) == len(bits)
    np.testing.assert_array_equal(c[~nan], py[~nan])
    assert np.all(np.isnan(c[nan].view(dtype)))


@pytest.fixture(scope="module")
def two_radii(tmp_path_factory):
    """two-radii fitted the paper's way (roots and negative powers), its held-out readings, and those scaled
    by 0.4 and 1.7 (clamped rows), as a CSV that `fitgen predict` reads."""
    from fitgen.physics.dataset import Dataset
    from fitgen.fitting.holdout import clean_readings
    from fitgen.equations.model import load_model

    folder = tmp_path_factory.mktemp("roots")
    for args in (("simulate", "--sensor", "two-radii", "--grid", "paper-sim", "-o", str(folder / "sim.csv")),
                 ("fit", str(folder / "sim.csv"), "--noise", "0", "--held-out", "500", "-o", str(folder / "m.json"))):
        proc = run_cli("fitgen", *args)
        assert proc.returncode == 0, proc.stderr
    model = load_model(folder / "m.json")
    kinds = {t.exponent for e in model.equations for t in e.terms}
    assert {"1/3", "1/2"} & kinds and {"-1", "-2", "-3", "-4"} & kinds, kinds
    clean, _ = clean_readings(model)
    v = np.vstack([clean, clean * 0.4, clean * 1.7])
    Dataset(v, np.zeros((len(v), 0)), ()).save(folder / "v.csv")
    return folder, model, v


def _predicted(folder: Path, precision: str) -> tuple[np.ndarray, np.ndarray]:
    out = folder / f"est-{precision}.csv"
    proc = run_cli("fitgen", "predict", str(folder / "m.json"), str(folder / "v.csv"), "-o", str(out),
                   "--precision", precision)
    assert proc.returncode == 0, proc.stderr
    table = np.loadtxt(out, delimiter=",", skiprows=1, ndmin=2)
    return table[:, :-1], table[:, -1].astype(int)


@pytest.mark.bitexact
@pytest.mark.parametrize("target", ["gcc", "qemu-arm"])
def test_float_header_equals_fitgen_predict(two_radii, target):
    """gcc's float header (x86-64, and armhf glibc under qemu-arm) equals `fitgen predict --precision float`."""
    from fitgen.c.compiled import CompiledModel

    folder, model, v = two_radii
    if target == "gcc":
        kw = {"cc": require_tool("gcc")}
    else:
        kw = {"cc": require_tool("arm-linux-gnueabihf-gcc") + " -static", "runner": require_tool("qemu-arm")}
    ref, ref_status = _predicted(folder, "float")
    assert np.any(ref_status > 0) and np.any(ref_status == 0)
    for style in ("table", "unrolled"):
        with CompiledModel(model, "float", style, **kw) as cm:
            out, status = cm.predict(v)
        np.testing.assert_array_equal(status, ref_status)
        np.testing.assert_array_equal(out, ref)


@pytest.mark.bitexact
def test_firmware_eval_equals_fitgen_predict(two_radii):
    """The reference firmware (newlib, Cortex-M4F in QEMU) answers EVAL with `fitgen predict --precision float`."""
    require_tool("qemu-system-arm")
    require_tool("arm-none-eabi-gcc")
    from hil.emulate import start_target
    from host.device import Device

    folder, model, v = two_radii
    ref, ref_status = _predicted(folder, "float")
    with start_target(model, "mps2", precision="float", style="table") as emu:
        with Device.open(emu.url, timeout=5) as dev:
            status, out = dev.eval(v)
    np.testing.assert_array_equal(status, ref_status)
    np.testing.assert_array_equal(out, ref)


def _simd_probe() -> dict:
    from numpy._core import _multiarray_umath as mu

    x = np.linspace(0.01, 3.0, 20000, dtype=np.float32)
    return {"features": {k: bool(v) for k, v in mu.__cpu_features__.items()},
            "dispatch": list(mu.__cpu_dispatch__),
            "numpy_cbrt": hashlib.sha256(np.cbrt(x).tobytes()).hexdigest(),
            "ours": hashlib.sha256(cbrt(x).tobytes()).hexdigest()}


PROBE = ("import json, sys; sys.path.insert(0, 'tests'); from test_roots import _simd_probe; "
         "print(json.dumps(_simd_probe()))")


def test_bit_identity_holds_without_numpy_simd():
    """The bitexact tests again in a subprocess with every SIMD target numpy dispatches to switched off. On a CPU
    where it dispatches to none (x86-64-v2: no AVX2), or in a suite run with them off, there is nothing to switch
    off and the subprocess runs them as the suite did."""
    here = _simd_probe()
    off = [t for t in here["dispatch"] if here["features"].get(t)]
    env = {**os.environ, "NPY_DISABLE_CPU_FEATURES": " ".join(off) or os.environ.get("NPY_DISABLE_CPU_FEATURES", "")}
    root = Path(__file__).resolve().parent.parent
    probe = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True, env=env, cwd=root)
    assert probe.returncode == 0, probe.stderr
    there = json.loads(probe.stdout)
    # the switch took effect: the targets are off in the subprocess, and where the CPU has AVX-512,
    # numpy's own float32 cbrt gives other bits (its AVX-512 path) while ours gives the same
    assert not any(there["features"][t] for t in off), there["features"]
    if here["features"].get("AVX512_SKX"):
        assert there["numpy_cbrt"] != here["numpy_cbrt"]
    assert there["ours"] == here["ours"]
    proc = subprocess.run([sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "-m", "bitexact",
                           "tests/test_roots.py", "tests/test_deployed.py"],
                          capture_output=True, text=True, env={**env, "CI": "true" if IN_CI else ""}, cwd=root,
                          timeout=1200)
    tail = proc.stdout.strip().splitlines()[-1:] or [proc.stderr[-300:]]
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-2000:]
    assert "passed" in tail[0] and "skipped" not in tail[0] and "deselected" in tail[0], tail[0]


def _has_fma() -> bool:
    try:
        flags = open("/proc/cpuinfo").read().split()
    except OSError:
        return False
    return "fma" in flags and "avx2" in flags


@pytest.mark.bitexact
@pytest.mark.parametrize("cc", ["gcc -std=gnu99 -ffp-contract=fast", "clang -std=gnu99"])
def test_the_header_turns_contraction_off_itself(two_radii, cc):
    """In GNU mode on a core with an FMA, GCC fuses a * b + c unless told not to, even with -ffp-contract=fast on
    the command line; clang fuses within statements by default: the header's pragmas keep the bits Python's."""
    from fitgen.c.compiled import CompiledModel

    folder, model, v = two_radii
    tool, *flags = cc.split()
    require_tool(tool)
    flags += ["-march=x86-64-v3"] if _has_fma() else []  # where the CPU can run fused multiply-adds
    for precision in ("float", "double"):
        ref, _ = _predicted(folder, precision)
        # as cflags, after the project's -std=c99, which would otherwise replace gnu99
        with CompiledModel(model, precision, "unrolled", cc=tool, cflags=flags) as cm:
            out, _ = cm.predict(v)
        np.testing.assert_array_equal(out, ref)


@pytest.mark.bitexact
@pytest.mark.parametrize("cc", ["gcc", "clang", "clang-arm"])
def test_the_header_keeps_its_bits_and_its_guard_under_fast_math(two_radii, cc):
    """A firmware built with -Ofast: without the header's pragmas the sums are reordered, clang approximates
    the square root, and isfinite() folds to 1, so that a NaN reading came out as an estimate with status 0 (gcc)
    or 255 (clang). With them the header answers Python's bits, and -1 with zeros for a non-finite reading.
    clang for ARM (armhf Linux under qemu-arm) refused the header's file-scope float_control ("not supported on
    this target"), with or without -Ofast: a warning, so -Werror stopped the build."""
    from fitgen.c.compiled import CompiledModel

    folder, model, v = two_radii
    if cc == "clang-arm":
        require_tool("clang")
        kw, modes = {"cc": "clang --target=arm-linux-gnueabihf -static", "runner": require_tool("qemu-arm")}, \
            ([], ["-Ofast"])
    else:
        require_tool(cc)
        kw, modes = {"cc": cc}, (["-Ofast"] + (["-march=x86-64-v3"] if _has_fma() else []),)
    bad = np.tile(v[:1], (3, 1))
    bad[0, 0], bad[1, 3], bad[2, 7] = np.nan, np.inf, -np.inf
    for precision in ("float", "double"):
        ref, ref_status = _predicted(folder, precision)
        for style, flags in ((style, flags) for style in ("table", "unrolled") for flags in modes):
            with CompiledModel(model, precision, style, cflags=flags, **kw) as cm:
                out, status = cm.predict(np.vstack([v, bad]))
            np.testing.assert_array_equal(out[:len(v)], ref, err_msg=f"{precision} {style} {flags}")
            np.testing.assert_array_equal(status[:len(v)], ref_status)
            assert np.all(status[len(v):] == -1) and np.all(out[len(v):] == 0), (precision, style, status[len(v):])


FUSED_AT_O3 = Path(__file__).resolve().parent / "data" / "model_gcc_fuses_at_O3.json"  # the paper, no roots


def _fused(header_dir: Path, flags: list[str], tmp: Path) -> int:
    """Fused multiply-add instructions gcc puts into tm_estimate's object with ``flags``."""
    src = tmp / "call.c"
    src.write_text('#include "tm_model.h"\nint call(const tm_real *i, tm_real *o);\n'
                   "int call(const tm_real *i, tm_real *o) { return tm_estimate(i, o); }\n")
    obj = tmp / "call.o"
    proc = subprocess.run(["gcc", "-std=c99", *flags, "-I", str(header_dir), "-c", str(src), "-o", str(obj)],
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    dump = subprocess.run([require_tool("objdump"), "-d", str(obj)], capture_output=True, text=True).stdout
    return sum(bool(re.search(r"\svfn?m", line)) for line in dump.splitlines())


@pytest.mark.bitexact
def test_gcc_at_O3_does_not_fuse_what_its_vectoriser_pairs(tmp_path):
    """GCC 12's basic-block vectoriser at -O3 (and -Ofast) on a core with an FMA paired an add with a subtract in
    this model's double unrolled header and fused them with a product (vfmsubadd), fp-contract=off or not: 43 of
    2,500 held-out outputs differed from Model.predict. The header turns that vectoriser off; `tactile-host verify
    --cc "gcc -O3 ..."` builds at -O3 (it built at -O2 whatever --cc said) and finds the bits Python's."""
    from fitgen.c.cgen import GCC_FP
    from fitgen.equations.model import load_model

    require_tool("gcc")
    model = load_model(FUSED_AT_O3)
    header = write_header(model, tmp_path / "h", precision="double", style="unrolled")
    flags = ["-O3", "-march=x86-64-v3"]  # compiled only: any x86-64 can build for an FMA
    assert _fused(header.parent, flags, tmp_path) == 0
    if subprocess.run(["gcc", "-dumpversion"], capture_output=True, text=True).stdout.strip().split(".")[0] == "12":
        # the version the docs name: without the vectoriser off, the fused instruction is there
        old = GCC_FP.replace(', "no-tree-slp-vectorize"', "")
        assert old != GCC_FP
        header.write_text(header.read_text().replace(GCC_FP, old))
        assert _fused(header.parent, flags, tmp_path) > 0
    if _has_fma():  # where the build can run: verify at the user's -O3 and -Ofast
        for cc in ("gcc -O3 -march=x86-64-v3", "gcc -Ofast -march=x86-64-v3"):
            proc = run_cli("tactile-host", "verify", str(FUSED_AT_O3), "--precision", "double", "--style",
                           "unrolled", "--cc", cc, "--vectors", "500")
            assert proc.returncode == 0, (cc, proc.stdout[-1500:], proc.stderr[-500:])


def test_the_users_compiler_flags_come_after_the_projects(monkeypatch, tmp_path):
    """--cc "gcc -O3 -std=gnu99": the build checked is the one the user asked for, not the project's -O2 c99."""
    from fitgen.c import compiled

    seen = []
    # a compiler that writes its output, as compile_checked requires of one that exits 0
    monkeypatch.setattr(compiled, "run_tool", lambda cmd, *a, **k: seen.append(cmd) or
                        Path(cmd[cmd.index("-o") + 1]).touch() or subprocess.CompletedProcess(cmd, 0, "", ""))
    compiled.compile_checked("gcc -O3 -std=gnu99", [tmp_path / "a.c"], tmp_path / "a", tmp_path)
    cmd = seen[0]
    assert cmd[0] == "gcc"
    assert cmd.index("-O3") > cmd.index("-O2") and cmd.index("-std=gnu99") > cmd.index("-std=c99"), cmd


@pytest.mark.parametrize("cc", ["clang", "gcc"])
def test_a_nan_reading_is_refused_behind_a_function_under_finite_math(two_radii, tmp_path, cc):
    """clang under -Ofast, -ffast-math or -ffinite-math-only took the range test's comparisons as ordered: a NaN
    reading passed it, and tm_estimate answered NaN with status 0, once the header sat behind an ordinary function
    (the vector runner inlines it, where the layout happened to hold). The reading's bits are tested first there."""
    from fitgen.c.compiled import WARNING_FLAGS as WARNING

    require_tool(cc)
    _, model, v = two_radii
    for precision in ("float", "double"):
        for style in ("table", "unrolled"):
            h = write_header(model, tmp_path / f"h-{precision}-{style}", precision=precision, style=style)
            lib, main = tmp_path / "lib.c", tmp_path / "main.c"
            lib.write_text('#include "tm_model.h"\nint run(const tm_real *in, tm_real *out);\n'
                           "int run(const tm_real *in, tm_real *out) { return tm_estimate(in, out); }\n")
            real = precision
            row = ", ".join(repr(float(x)) for x in v[0])
            main.write_text(f"#include <math.h>\n#include <stdio.h>\nint run(const {real} *in, {real} *out);\n"
                            f"int main(void) {{\n    {real} in[{model.n_inputs}] = {{ {row} }}, out[5];\n"
                            "    int k, st;\n    for (k = 0; k < 3; ++k) {\n"
                            "        in[k] = k == 0 ? NAN : k == 1 ? INFINITY : -INFINITY;\n"
                            "        st = run(in, out);\n"
                            "        printf(\"%d %g %g\\n\", st, (double)out[0], (double)out[4]);\n"
                            f"        in[k] = ({real}){float(v[0][0])!r};\n    }}\n    return 0;\n}}\n")
            for flags in (["-Ofast"], ["-O2", "-ffast-math"], ["-O2", "-ffinite-math-only"]):
                exe = tmp_path / "t"
                for src, obj, extra in ((lib, tmp_path / "lib.o", WARNING + flags + ["-I", str(h.parent)]),
                                        (main, tmp_path / "main.o", ["-O0"])):
                    proc = subprocess.run([cc, *extra, "-c", str(src), "-o", str(obj)], capture_output=True,
                                          text=True)
                    assert proc.returncode == 0, proc.stderr
                subprocess.run([cc, str(tmp_path / "lib.o"), str(tmp_path / "main.o"), "-o", str(exe), "-lm"],
                               check=True)
                lines = subprocess.run([str(exe)], capture_output=True, text=True).stdout.split()
                assert lines == ["-1", "0", "0"] * 3, (precision, style, flags, lines)
