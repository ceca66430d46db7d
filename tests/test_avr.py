"""The header on the ATmega328P (Arduino Uno): codegen --target, avr-gcc builds, estimates in simavr against Python."""

import dataclasses
import shlex
import subprocess

import numpy as np
import pytest

from fitgen.c.codegen import render_header
from fitgen.equations.terms import FAMILIES
from fitgen.fitting.fit import FitSettings, fit_model
from fitgen.physics.sensor import load_sensor
from fitgen.physics.simulate import PAPER_GRIDS, grid_poses, simulate

from conftest import assert_one_line_error, require_tool, run_cli

STRICT = ["-Wall", "-Wextra", "-Werror", "-pedantic", "-Wdouble-promotion", "-Wfloat-conversion", "-O2"]
USE = ("#include \"tm_model.h\"\nint use(const tm_input *i, tm_output *o);\n"
       "int use(const tm_input *i, tm_output *o) { return tm_estimate(i, o); }\n")


@pytest.fixture(scope="module")
def small_model():
    """A no-roots model of the paper sensor in volts (as the ADCs read it), 6 terms per output at most."""
    ds = simulate(load_sensor("paper").with_transfer("gmr"), grid_poses(PAPER_GRIDS["paper-sim"]))
    return fit_model(ds, settings=FitSettings.exact(exponents=FAMILIES["no-roots"], max_terms=6))


@pytest.fixture(scope="module")
def model_file(small_model, tmp_path_factory):
    return str(small_model.save(tmp_path_factory.mktemp("avr") / "model.json"))


def test_uno_refuses_a_double_header(model_file, tmp_path):
    proc = run_cli("fitgen", "codegen", model_file, "-o", str(tmp_path / "x"), "--precision", "double", "--target", "uno")
    assert_one_line_error(proc, contains="target uno")
    assert "double is 32 bits" in proc.stderr
    assert not (tmp_path / "x" / "tm_model.h").exists()
    # no --precision: double where the target runs it, else what it runs (this exact model: the target's first);
    # no --style: on the Uno unrolled, as arduino-build (a table evaluation's arrays on the stack overrun its RAM)
    for target, said in (("uno", "(float, unrolled"), ("microbit", "(fixed point"), ("mps2", "(double, table")):
        proc = run_cli("fitgen", "codegen", model_file, "-o", str(tmp_path / target), "--target", target)
        assert proc.returncode == 0 and said in proc.stderr, proc.stderr
    assert "typedef float tm_real;" in (tmp_path / "uno" / "tm_model.h").read_text()
    # the table's other rows: the Cortex-M0 runs fixed point only, the Pi no fixed point, the M4F all three
    assert_one_line_error(run_cli("fitgen", "codegen", model_file, "-o", str(tmp_path / "y"), "--precision", "float",
                                  "--target", "microbit"), contains="target microbit")
    assert_one_line_error(run_cli("fitgen", "codegen", model_file, "-o", str(tmp_path / "y"), "--precision", "fixed",
                                  "--target", "pi"), contains="target pi")
    # a model fixed point cannot run, on the target that runs nothing else: said as the target's, in one line
    # (it said "fixed point has no harmonic terms" to a user who never asked for fixed point)
    import dataclasses

    from fitgen.equations.model import Equation, load_model
    from fitgen.equations.terms import Term

    m = load_model(model_file)
    rooted = dataclasses.replace(m, equations=tuple(
        Equation(e.name, e.intercept, (*e.terms, Term(1, "1/2")), (*e.coefficients, 1e-9)) if e.name == "dz" else e
        for e in m.equations))
    path = rooted.save(tmp_path / "rooted.json")
    for cmd in (["codegen", str(path), "-o", str(tmp_path / "r")],
                ["predict", str(path), str(path), "-o", str(tmp_path / "r.csv")]):
        assert_one_line_error(run_cli("fitgen", *cmd, "--target", "microbit"), 2,
                              "runs fixed point only, and fixed point takes integer powers only, but output dz has "
                              "the root")
    for precision, target in (("float", "uno"), ("fixed", "uno"), ("double", "mps2"), ("double", "pi")):
        proc = run_cli("fitgen", "codegen", model_file, "-o", str(tmp_path / precision), "--precision", precision,
                       "--target", target)
        assert proc.returncode == 0, proc.stderr
    # the header does not depend on the target, given its style: one header builds everywhere
    plain = run_cli("fitgen", "codegen", model_file, "-o", str(tmp_path / "plain"), "--precision", "float",
                    "--style", "unrolled")
    assert plain.returncode == 0
    assert (tmp_path / "plain" / "tm_model.h").read_bytes() == (tmp_path / "float" / "tm_model.h").read_bytes()


def _compile(cc, folder, suffix, flags):
    src = folder / f"use.{suffix}"
    src.write_text(USE)
    obj = folder / f"use_{suffix}.o"
    proc = subprocess.run([cc, *flags, *STRICT, "-I", str(folder), "-c", str(src), "-o", str(obj)],
                          capture_output=True, text=True)
    return proc, obj


def test_double_header_fails_on_avr_with_its_reason(small_model, tmp_path):
    require_tool("avr-gcc")
    require_tool("gcc")
    (tmp_path / "tm_model.h").write_text(render_header(small_model, "double"))
    proc, _ = _compile("avr-gcc", tmp_path, "c", ["-mmcu=atmega328p", "-std=c99"])
    assert proc.returncode != 0
    first = next(ln for ln in proc.stderr.splitlines() if "error" in ln)
    assert "#error" in first and "double-precision header" in first and "DBL_MANT_DIG != 53" in first, first
    # the same header builds where double has 53 bits: the check is not always on
    proc, _ = _compile("gcc", tmp_path, "c", ["-std=c99"])
    assert proc.returncode == 0, proc.stderr


@pytest.mark.parametrize("precision,style", [("float", "table"), ("float", "unrolled"), ("fixed", "table")])
def test_header_builds_warning_free_for_atmega328p_tables_in_flash(small_model, tmp_path, precision, style):
    require_tool("avr-gcc")
    require_tool("avr-g++")
    require_tool("avr-size")
    (tmp_path / "tm_model.h").write_text(render_header(small_model, precision, style, target="uno"))
    for cc, suffix, std in (("avr-gcc", "c", "-std=c99"), ("avr-g++", "cpp", "-std=gnu++11")):
        proc, obj = _compile(cc, tmp_path, suffix, ["-mmcu=atmega328p", std])
        assert proc.returncode == 0, proc.stderr
        assert proc.stderr == ""
        # avr-gcc puts const data in RAM (.data) unless it is PROGMEM: nothing of the header's is there
        text, data, bss = (int(x) for x in subprocess.run(["avr-size", str(obj)], capture_output=True, text=True,
                                                          check=True).stdout.splitlines()[1].split()[:3])
        assert data == 0 and bss == 0 and text > 0


def test_a_fixed_header_with_an_output_of_no_terms_builds_for_the_atmega328p(small_model, tmp_path):
    """An output that is its intercept alone (a cap of 2 can leave thx none) has no term table, and the AVR path
    called tm_avr_dot on it: 'tm_dot_thx' undeclared; an output 0 everywhere was Q100, past any 1 << frac."""
    require_tool("avr-gcc")
    eqs = tuple(dataclasses.replace(e, intercept=0.0, terms=(), coefficients=()) if e.name == "thx" else e
                for e in small_model.equations)
    header = render_header(dataclasses.replace(small_model, equations=eqs), "fixed")
    (tmp_path / "tm_model.h").write_text(header)
    proc, _ = _compile("avr-gcc", tmp_path, "c", ["-mmcu=atmega328p", "-std=c99"])
    assert proc.returncode == 0 and proc.stderr == "", proc.stderr
    assert "thx [deg]: 0 terms, Q31," in header


def test_estimates_in_simavr_equal_python(small_model):
    """float (both styles) bit for bit with Model.predict(precision='float'); fixed point with the plan's integers;
    inside and outside the domain (the status bits too); cycles counted for every estimate."""
    for tool in ("avr-gcc", "avr-size", "gcc", "pkg-config"):
        require_tool(tool)
    from fitgen.c.avr import fits_uno, run_on_avr
    from fitgen.equations.inputscale import plan_at

    rng = np.random.default_rng(5)
    lo, hi = small_model.input_min, small_model.input_max
    span = hi - lo
    x = lo + rng.uniform(-0.1, 1.1, (24, small_model.n_inputs)) * span  # a tenth beyond each end: clamped too
    ref, ref_status = small_model.predict(x.astype(np.float32).astype(float), with_status=True, precision="float")
    assert np.any(ref_status > 0) and np.any(ref_status == 0)
    for style in ("table", "unrolled"):
        run = run_on_avr(small_model, x, "float", style)
        np.testing.assert_array_equal(run.status, ref_status)
        np.testing.assert_array_equal(run.outputs, ref)
        assert len(run.cycles) == len(x) and np.all(run.cycles > 1000) and fits_uno(run)
    for mul_bits in (16, 32):
        fm = plan_at(small_model, None, None, mul_bits)[0]
        codes = np.round(np.clip(x, 0, None) / fm.input_lsb)
        run = run_on_avr(small_model, codes, "fixed", mul_bits=mul_bits)
        want, want_status = fm.predict_codes(codes)
        np.testing.assert_array_equal(run.status, want_status)
        np.testing.assert_array_equal(run.outputs, want)
        assert np.all(run.cycles > 1000) and fits_uno(run)


# --- fixed point for the 16-bit multiply, and the header's AVR assembly ---------------------------------


def _sample_codes(fm, n, seed):
    """At most ``n`` rows of fitgen.c.verify.make_code_vectors: the extremes (min/max codes, one past them, the
    int32 ends: clamped), corners, edges and random codes, in a seeded sample."""
    from fitgen.c.verify import make_code_vectors

    codes, kinds = make_code_vectors(fm, n_random=60, seed=seed)
    rng = np.random.default_rng(seed)
    pick = [i for i, k in enumerate(kinds) if k not in ("corner", "random", "edge", "outside")]  # the extremes
    for kind, count in (("edge", 64), ("corner", 30), ("outside", 16), ("random", 60)):
        rows = [i for i, k in enumerate(kinds) if k == kind]
        pick += [int(i) for i in rng.choice(rows, min(len(rows), count), replace=False)]
    rows = codes[pick[:n]]
    assert np.any(rows == np.iinfo(np.int32).min) and np.any(rows == np.iinfo(np.int32).max)
    return rows


@pytest.fixture(scope="module")
def bench_model():
    """The model bench/avr_cost.py measures: the paper sensor in volts fitted as `fitgen fit --family no-roots`."""
    ds = simulate(load_sensor("paper").with_transfer("gmr"), grid_poses(PAPER_GRIDS["paper-sim"]))
    return fit_model(ds, settings=FitSettings.family("no-roots"))


def test_uno_plan_in_simavr_bit_for_bit(small_model, bench_model):
    """The uno plan's header on the ATmega328P (its assembly, and its portable C built for AVR) and the 32-bit
    plan's (assembly) answer the numpy model's integers exactly, extremes and clamping included: 16x16->32
    outputs, power chains in 16 bits, byte-aligned and unaligned 32x32->64 sums, reciprocals."""
    for tool in ("avr-gcc", "avr-size", "gcc", "pkg-config"):
        require_tool(tool)
    from fitgen.c.avr import run_on_avr
    from fitgen.equations.fixedpoint import build_fixed
    from fitgen.equations.inputscale import default_input_scale
    from test_fixedpoint import every_kind_model, narrow_chain_model

    lsb, off, _ = default_input_scale(bench_model)
    cases = [(small_model, lsb, off), (bench_model, lsb, off), (every_kind_model(), 1.7e-4, -0.123456789),
             (narrow_chain_model(), 1e-4, 0.0)]
    for n, (model, lsb, off) in enumerate(cases):
        for mul_bits, portable in ((16, False), (16, True), (32, False)):
            fm = build_fixed(model, lsb, off, mul_bits)
            codes = _sample_codes(fm, 150, n)
            run = run_on_avr(model, codes, "fixed", input_lsb=lsb, input_offset=off, mul_bits=mul_bits,
                             portable=portable)
            want, want_status = fm.predict_codes(codes)
            np.testing.assert_array_equal(run.status, want_status)
            np.testing.assert_array_equal(run.outputs, want)
            assert np.any(want_status > 0) and np.any(want_status == 0)
    # as the Arduino IDE builds it (-Os -flto: whole-program optimisation around the naked assembly), and at -O0
    fm = build_fixed(bench_model, *cases[1][1:], 16)
    codes = _sample_codes(fm, 80, 9)
    want, want_status = fm.predict_codes(codes)
    for opt in (("-Os", "-flto"), ("-O0",)):
        run = run_on_avr(bench_model, codes, "fixed", mul_bits=16, opt=opt)
        np.testing.assert_array_equal(run.status, want_status)
        np.testing.assert_array_equal(run.outputs, want)


def test_fixed_on_the_uno_takes_fewer_cycles_than_float(bench_model):
    """The issue's acceptance on the bench's model: fixed point (the uno plan) under float, table and unrolled,
    with flash to spare; the assembly is what makes 32x32->64 products cheap (the portable C is slower)."""
    for tool in ("avr-gcc", "avr-size", "gcc", "pkg-config"):
        require_tool(tool)
    from fitgen.c.avr import fits_uno, run_on_avr
    from fitgen.equations.inputscale import plan_at

    rng = np.random.default_rng(9)
    lo, hi = bench_model.input_min, bench_model.input_max
    x = lo + rng.uniform(0, 1, (12, bench_model.n_inputs)) * (hi - lo)
    fm = plan_at(bench_model, mul_bits=16)[0]
    fixed = run_on_avr(bench_model, fm.codes_of(x), "fixed")
    portable = run_on_avr(bench_model, fm.codes_of(x), "fixed", portable=True)
    floats = [run_on_avr(bench_model, x, "float", style) for style in ("table", "unrolled")]
    assert fits_uno(fixed) and fixed.ram == 0
    assert np.max(fixed.cycles) < min(np.min(f.cycles) for f in floats)
    assert np.max(fixed.cycles) < np.min(portable.cycles)


def _asm_program(mul, div, dots) -> str:
    """An AVR program that runs the header's assembly (fitgen.c.avrasm) on given operands and prints the results."""
    from fitgen.c import avrasm

    def lit(v):
        return f"(-{-v - 1}LL-1)" if v < 0 else f"{v}LL"

    tables = []
    for k, (_, terms) in enumerate(dots):
        data = [b for off, c, s in terms for b in (off & 255, off >> 8, *((c >> (8 * i)) & 255 for i in range(4)), s & 255)]
        tables.append(f"static const uint8_t tab{k}[] PROGMEM = {{ {', '.join(map(str, data + [255, 255]))} }};")
    return f"""#include <avr/io.h>
#include <avr/pgmspace.h>
#include <avr/sleep.h>
#include <avr/interrupt.h>
#include <stdint.h>
#include <string.h>
#define U __attribute__((unused))
static void __attribute__((naked, noinline)) dot(int64_t *acc U, const int32_t *v U, const uint8_t *t U)
{{
    __asm__ __volatile__(
{avrasm.c_literal(avrasm.dot())});
}}
static void __attribute__((naked, noinline)) mulsh(int32_t a U, int32_t b U, int8_t s U, int32_t *out U)
{{
    __asm__ __volatile__(
{avrasm.c_literal(avrasm.mulsh())});
}}
static void __attribute__((naked, noinline)) divr(int32_t d U, uint32_t hi U, uint32_t add U, int32_t *out U)
{{
    __asm__ __volatile__(
{avrasm.c_literal(avrasm.divr())});
}}
static void put(char c) {{ uint16_t n; for (n = 0; n < 10000u && !(UCSR0A & (1 << UDRE0)); ++n) {{}} UDR0 = (uint8_t)c; }}
static void hex(uint32_t v) {{ uint8_t d = 8; while (d > 0u) {{ uint8_t x = (uint8_t)((v >> (4u * (d - 1u))) & 0xFu);
    put((char)(x < 10u ? '0' + x : 'a' + (x - 10))); --d; }} put(' '); }}
typedef struct {{ int32_t a, b; int8_t s; }} mv;
static const mv muls[] PROGMEM = {{ {', '.join(f'{{(int32_t){lit(a)}, (int32_t){lit(b)}, {s}}}' for a, b, s in mul)} }};
typedef struct {{ int32_t d; uint32_t hi, add; }} dv;
static const dv divs[] PROGMEM = {{ {', '.join(f'{{(int32_t){lit(d)}, {hi}UL, {add}UL}}' for d, hi, add in div)} }};
static const int64_t acc0[] PROGMEM = {{ {', '.join(lit(a) for a, _ in dots)} }};
{chr(10).join(tables)}
static const uint8_t *const tabs[] = {{ {', '.join(f'tab{k}' for k in range(len(dots)))} }};
int main(void)
{{
    int32_t v[{DOT_VALUES}];
    uint16_t i;
    UBRR0 = 0; UCSR0A = (uint8_t)(1 << U2X0); UCSR0B = (uint8_t)(1 << TXEN0); UCSR0C = (uint8_t)(3 << UCSZ00);
    for (i = 0; i < {DOT_VALUES}; ++i) v[i] = (int32_t)((uint32_t)i * 2654435761UL) >> (i % 31u);
    for (i = 0; i < {len(mul)}; ++i) {{ mv m; int32_t r; memcpy_P(&m, &muls[i], sizeof m); mulsh(m.a, m.b, m.s, &r);
        hex((uint32_t)r); }}
    for (i = 0; i < {len(div)}; ++i) {{ dv d; int32_t r; memcpy_P(&d, &divs[i], sizeof d); divr(d.d, d.hi, d.add, &r);
        hex((uint32_t)r); }}
    for (i = 0; i < {len(dots)}; ++i) {{ int64_t acc; uint32_t w[2]; memcpy_P(&acc, &acc0[i], 8); dot(&acc, v, tabs[i]);
        memcpy(w, &acc, 8); hex(w[1]); hex(w[0]); }}
    put('\\n'); put('.'); put('\\n');
    for (i = 0; i < 10000u && !(UCSR0A & (1 << TXC0)); ++i) {{}}
    cli(); sleep_enable(); sleep_cpu();
    return 0;
}}
"""


DOT_VALUES = 40


def test_avr_assembly_equals_python(tmp_path):
    """The three routines against Python's integers on random and extreme operands over their whole ranges:
    products of +-(2^31 - 1), 0 and -1; every shift -62..62 (dot) and 0..62 (mulsh); divisors 1 to 2^31 - 1."""
    for tool in ("avr-gcc", "gcc", "pkg-config"):
        require_tool(tool)
    from fitgen.c.avr import build_runner
    from fitgen.c.compiled import WARNING_FLAGS
    from fitgen.equations.fixedmodel import rshr

    rng = np.random.default_rng(10)
    edge = [2**31 - 1, -(2**31 - 1), 0, 1, -1, 2**30, -(2**30)]

    def r32():
        return int(rng.choice(edge)) if rng.random() < 0.2 else int(rng.integers(-2**31 + 1, 2**31)) >> int(rng.integers(0, 31))

    mul = []
    for s in list(range(63)) * 3:
        a, b = r32(), r32()
        while abs(rshr(a * b, s)) > 2**31 - 1:
            a >>= 1
        mul.append((a, b, s))
    div = []
    for d in [1, 2, 3, 2**31 - 1] + [max(1, r32() & (2**31 - 1)) for _ in range(120)]:
        n = 0
        while n < 62 and (2**(n + 1) + d // 2) // d <= 2**31 - 1:
            n += 1
        n = int(rng.choice([n, int(rng.integers(0, n + 1))]))
        div.append((d, n))
    vals = [(np.int64(i) * 2654435761 % 2**32).astype(np.uint32).view(np.int32) >> (i % 31) for i in range(DOT_VALUES)]
    dots = []
    for _ in range(40):
        acc = acc0 = int(rng.integers(-2**61, 2**61)) >> int(rng.integers(0, 62))
        terms = []
        for s in rng.integers(-62, 63, int(rng.integers(0, 12))):
            k, c = int(rng.integers(0, DOT_VALUES)), r32()
            p = c * int(vals[k])
            s = int(s)
            while s < 0 and abs(p) << -s > 2**62:
                s += 1
            if abs(acc + rshr(p, s)) <= 2**62:
                acc += rshr(p, s)
                terms.append((4 * k, c, s))
        dots.append((acc0, terms, acc))
    src = tmp_path / "asm.c"
    src.write_text(_asm_program(mul, [(d, 2**(n - 32) if n >= 32 else 0, 0 if n >= 32 else 2**n) for d, n in div],
                                [(a, t) for a, t, _ in dots]))
    elf = tmp_path / "asm.elf"
    subprocess.run(["avr-gcc", "-mmcu=atmega328p", *WARNING_FLAGS, "-O2", str(src), "-o", str(elf)], check=True,
                   capture_output=True)
    proc = subprocess.run([str(build_runner(tmp_path)), str(elf), "500000000"], capture_output=True, text=True,
                          timeout=600)
    assert proc.returncode == 0, proc.stderr
    got = [int(w, 16) for ln in proc.stdout.splitlines() if not ln.startswith("Loaded") and ln != "." for w in ln.split()]
    want = ([rshr(a * b, s) % 2**32 for a, b, s in mul] + [(2**n + d // 2) // d for d, n in div]
            + [w for _, _, acc in dots for w in ((acc % 2**64) >> 32, acc % 2**32)])
    assert got == want


def test_a_link_past_the_flash_says_by_how_much_not_collect2s_line():
    """tradeoff --core uno read "building the AVR program failed: collect2: error: ld returned 1 exit status" for a
    model past the ATmega328P's flash: the linker's own line says why."""
    from fitgen.base.errors import InputError
    from fitgen.c.avr import _run

    said = ("/usr/bin/avr-ld: bench.elf section `.text' will not fit in region `text'\n"
            "/usr/bin/avr-ld: region `text' overflowed by 4321 bytes\n"
            "collect2: error: ld returned 1 exit status")
    with pytest.raises(InputError, match="^linking failed: over the ATmega328P's flash by 4,321 B$"):
        _run(["sh", "-c", f"printf '%s\\n' {shlex.quote(said)} >&2; exit 1"], "linking")
    with pytest.raises(InputError, match="^linking failed: collect2: error: ld returned 1 exit status$"):
        _run(["sh", "-c", "echo 'collect2: error: ld returned 1 exit status' >&2; exit 1"], "linking")
