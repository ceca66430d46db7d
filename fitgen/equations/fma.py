"""Fused multiply-add in numpy: round(a * b + c) once, as C99's ``fma`` does.

numpy has no fma; this is the emulation of Boldo and Melquiond ("Emulation of FMA
and correctly rounded sums: proved algorithms using rounding to odd", IEEE Trans.
Computers 57(4), 2008, algorithm 5.4): an exact product (Dekker), an exact sum, one
addition rounded to odd, and a final rounding to nearest. It is correctly rounded
for binary64 while |a|, |b| < 2^995 and a * b is zero or above 2^-969 in magnitude
(no overflow in the split, no underflow in the product's error term); the generated
C's domain guard and coefficient limits keep a model's terms well inside that.
"""

from __future__ import annotations

import numpy as np

_SPLITTER = 134217729.0  # 2^27 + 1: splits a double into two 26-bit halves


def _split(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    t = _SPLITTER * a
    hi = t - (t - a)
    return hi, a - hi


def two_product(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """p, e with p = fl(a * b) and p + e = a * b exactly."""
    p = a * b
    ah, al = _split(a)
    bh, bl = _split(b)
    e = ((ah * bh - p) + ah * bl + al * bh) + al * bl
    return p, e


def two_sum(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """s, e with s = fl(a + b) and s + e = a + b exactly (Knuth)."""
    s = a + b
    bb = s - a
    e = (a - (s - bb)) + (b - bb)
    return s, e


def add_round_to_odd(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a + b rounded to odd: exact when representable, else the neighbour whose last bit is 1."""
    s, e = two_sum(a, b)
    # consecutive doubles of one sign are consecutive integers in their bit patterns,
    # so of s and its neighbour toward the exact value exactly one is odd
    even = (np.ascontiguousarray(s).view(np.int64) & 1) == 0
    step = np.nextafter(s, np.where(e > 0, np.inf, -np.inf))
    return np.where((e != 0) & even, step, s)


def fma(a, b, c) -> np.ndarray:
    """Elementwise a * b + c with a single rounding (binary64)."""
    a, b, c = np.broadcast_arrays(*(np.asarray(x, dtype=np.float64) for x in (a, b, c)))
    with np.errstate(over="ignore", invalid="ignore"):
        uh, ul = two_product(a, b)
        th, tl = two_sum(c, uh)
        v = add_round_to_odd(tl, ul)
        out = th + v
        # exact zeros, infinities and NaN follow the plain expression (the emulation would lose the sign of 0)
        plain = a * b + c
    special = ~np.isfinite(uh) | ~np.isfinite(c) | (uh == 0)
    return np.where(special, plain, out)
