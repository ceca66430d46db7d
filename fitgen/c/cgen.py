"""C text helpers: literals that round-trip and identifiers checked against the C keywords.

Nothing from a model file reaches generated C except through these functions.
"""

from __future__ import annotations

import math
import re

import numpy as np

from fitgen.base.errors import InputError

C_KEYWORDS = frozenset("""
auto break case char const continue default do double else enum extern float for goto if inline int long
register restrict return short signed sizeof static struct switch typedef union unsigned void volatile while
_Bool _Complex _Imaginary _Alignas _Alignof _Atomic _Generic _Noreturn _Static_assert _Thread_local
bool true false NULL main
""".split())
_IDENT = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")
# macro names the C standard library reserves (C11 7.31, future library directions), as the upper-case prefix and
# '_' start every macro of a generated header: errno.h, locale.h, signal.h, fenv.h, inttypes.h, time.h, stdatomic.h
_RESERVED_MACROS = re.compile(r"^(E[0-9A-Z]|LC_[A-Z]|SIG[A-Z_]|FE_[A-Z]|(PRI|SCN)X|TIME_[A-Z]|ATOMIC_[A-Z])")


def identifier(name: str, what: str = "identifier", longest: int = 31) -> str:
    """``name`` if it is a safe C identifier: a letter first, then letters, digits, '_'; at most ``longest``
    characters; no keyword; no '__' (reserved to the implementation)."""
    if not isinstance(name, str) or not _IDENT.match(name) or "__" in name or len(name) > longest:
        raise InputError(f"{what} {name!r} is not a valid C identifier "
                         f"(a letter, then letters, digits or '_', at most {longest} characters, no '__')")
    if name in C_KEYWORDS or name.lower() in C_KEYWORDS:
        raise InputError(f"{what} {name!r} is a C keyword or a name C reserves")
    return name


# the first words of the header's two-word names whose second word is a name of its own: a prefix ending in one
# (tm_status) would define what the shorter prefix's header (tm) defines, e.g. TM_STATUS_NONFINITE; with a name
# both define, for the message (tests/test_refine.py derives the words from rendered headers)
CLASHING_TAILS = {"r": "r_term", "require": "REQUIRE_GENERATOR_VERSION_NUM", "status": "STATUS_NONFINITE"}


def prefix_identifier(prefix: str) -> str:
    """``prefix`` if it starts the generated identifiers safely: an :func:`identifier` of at most 16 characters
    that does not end in '_' (``<prefix>_model`` would hold '__', reserved in C and C++) and whose upper case does
    not start a macro name the C library reserves (``SIG_N_INPUTS``: signal.h's), nor end in a word
    (:data:`CLASHING_TAILS`) that would make its names another prefix's."""
    prefix = identifier(prefix, "prefix", 16)
    if prefix != prefix.lower():  # its macros and include guard are its upper case: Tm's would be tm's
        raise InputError(f"prefix {prefix!r}: give it in lower case ({prefix.lower()!r}); the header's macros and "
                         f"include guard take its upper case, so {prefix!r} and {prefix.lower()!r} would define the "
                         "same ones and the second header would compile to nothing")
    if prefix.endswith("_"):
        raise InputError(f"prefix {prefix!r} ends in '_': the names it starts would hold '__' (reserved)")
    tails = ["_".join(prefix.split("_")[i:]) for i in range(1, prefix.count("_") + 1)]
    if clash := next((t for t in tails if t in CLASHING_TAILS), None):
        other, name = prefix[:-len(clash) - 1], CLASHING_TAILS[clash]
        both = f"{other}_{name}" if name.islower() else f"{other.upper()}_{name}"
        raise InputError(f"prefix {prefix!r}: beside a header of prefix {other!r} in one program their names would "
                         f"clash ({both} is both headers'); choose another (e.g. "
                         f"{prefix.replace('_', '')!r})")
    if _RESERVED_MACROS.match(prefix.upper() + "_X"):
        raise InputError(f"prefix {prefix!r}: the header's macros ({prefix.upper()}_...) would start as "
                         "names the C library reserves (E and a digit or capital: errno.h; LC_, SIG, FE_, PRIX, "
                         "SCNX, TIME_, ATOMIC_); choose another")
    return prefix


def c_double(x: float) -> str:
    """A double literal that reads back to the same double (17 significant digits)."""
    x = float(x)
    if not math.isfinite(x):
        raise InputError(f"cannot write the non-finite number {x!r} as a C literal")
    text = repr(x)  # shortest round-trip repr
    if "e" not in text and "." not in text:
        text += ".0"
    return text


def c_float(x: float) -> str:
    """A float literal (``f`` suffix) for the float nearest ``x``, reading back to that float."""
    x = float(x)
    if not math.isfinite(x) or abs(x) > float(np.finfo(np.float32).max):
        raise InputError(f"the number {x!r} does not fit in a float")
    f = np.float32(x)
    text = np.format_float_scientific(f, unique=True, trim="0") if f != 0 else "0.0"
    text = text.replace("e+", "e")
    if "." not in text and "e" not in text:
        text += ".0"
    if text.endswith("."):
        text += "0"
    text = text.replace(".e", ".0e")
    return text + "f"


def c_real(x: float, precision: str) -> str:
    return c_float(x) if precision == "float" else c_double(x)


_NOT_PLAIN = re.compile(r"[^A-Za-z0-9 _.,:;/+\-=()\[\]']")  # an apostrophe needs no escape between double quotes


def c_string(text: str, lossy: bool = False) -> str:
    """A C string literal for plain ASCII text (letters, digits, a few symbols) only; ``lossy``: any other
    character shown as '_', not refused (a file's name, say; not '?', which C99's trigraphs may read)."""
    if lossy:
        text = _NOT_PLAIN.sub("_", text)
    if _NOT_PLAIN.search(text):
        raise InputError(f"refusing to place {text!r} in a C string")
    return f'"{text}"'


# a header's floating point as written under any flags (docs/codegen.md): no contraction into fused multiply-adds
# and none of -ffast-math. GCC takes it for the whole file; clang, whose file-scope float_control is refused off x86,
# at the start of each function body, where the scope macro stands. GCC 12's basic-block vectoriser at -O3 pairs an
# add with a subtract and fuses them with a product (vfmsubadd) whatever fp-contract says, so it is off wherever the
# target may have a fused multiply-add; x86 without one cannot fuse, and keeps it (its code, and the instruction
# counts the docs quote, unchanged)
GCC_FP = "\n".join(['#if defined(__FMA__) || !(defined(__x86_64__) || defined(__i386__))',
                     '#pragma GCC optimize("fp-contract=off", "no-fast-math", "no-tree-slp-vectorize")', "#else",
                     '#pragma GCC optimize("fp-contract=off", "no-fast-math")', "#endif"])
CLANG_FP = ("clang fp contract(off)", "clang fp reassociate(off)", "clang fp exceptions(strict)")


FINITE_ONLY = "(defined(__FINITE_MATH_ONLY__) && __FINITE_MATH_ONLY__)"  # -ffinite-math-only, -ffast-math, -Ofast


def nonfinite_test(name: str, macro: str, real: str, otherwise: str) -> str:
    """C lines defining ``macro(v)``: under -ffinite-math-only a test of ``v``'s exponent bits (``name``, a static
    inline function of a ``real``), else ``otherwise`` (the macro's text then, of v). A compiler told there are no
    NaNs may take every comparison as ordered: clang let a NaN reading through a range test and gave estimates
    of NaN with status 0; isfinite() may fold to 1."""
    bits, mask = ("uint32_t", "0x7f800000u") if real == "float" else ("uint64_t", "UINT64_C(0x7ff0000000000000)")
    return "\n".join([f"#if {FINITE_ONLY}", f"static inline int {name}({real} v)", "{", f"    {bits} b;",
                      "    memcpy(&b, &v, sizeof b);", f"    return (b & {mask}) == {mask};", "}",
                      f"#define {macro}(v) {name}(v)", "#else", f"#define {macro}(v) {otherwise}", "#endif"])


def fp_guard(scope: str) -> tuple[str, str]:
    """The lines before and after a header's code that keep its floating point as written, ``scope`` the macro each
    of its function bodies starts with: clang's contract(off), and under -ffast-math reassociate(off) and strict
    exceptions (no rsqrt for sqrt, no reciprocal, a real isfinite()); GCC's push, GCC_FP and pop."""
    before = ["#if defined(__clang__)", f"#if defined(__FAST_MATH__) || {FINITE_ONLY}",
              f"#define {scope} " + " ".join(f'_Pragma("{p}")' for p in CLANG_FP), "#else",
              f'#define {scope} _Pragma("{CLANG_FP[0]}")', "#endif", "#else", f"#define {scope}",
              "#if defined(__GNUC__)", "#pragma GCC push_options", GCC_FP, "#endif", "#endif"]
    after = ["#if !defined(__clang__) && defined(__GNUC__)", "#pragma GCC pop_options", "#endif"]
    return "\n".join(before), "\n".join(after)
