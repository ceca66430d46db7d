"""The cube root the generated C computes: IEEE basic operations in a fixed order, bit for bit.

libm's cbrt differs between libraries (glibc, newlib, avr-libc) and numpy's between CPUs (its
AVX-512 path), so neither the C nor the Python evaluation may call one. Both run this routine
instead (the C text is ``tm_cbrtf`` / ``tm_cbrt`` in firmware_templates/model.h.j2):

1. |x| outside 2^-60..2^60 (float; double 2^-600..2^600) scaled by 2^(-+3s), s = 20 (double 200),
   so that no intermediate (y^3, y (y^3 + 2a)) overflows or turns subnormal; every reading a
   sensor gives is inside;
2. a first guess from the bits: float ``i / 3 + 0x2A5137A0`` (Kahan); double the same on the
   upper 32 bits with 715094163 (fdlibm), the lower word 0; within 3.2 % of the root;
3. float: one Halley step, y (y^3 + 2a) / (2y^3 + a), then one Newton step,
   y - (y^2 y - a) / (3 y^2); double: two Halley steps, then the Newton step;
4. the result scaled by 2^-s, the sign restored; 0, infinities and NaN are returned as given.

Every step is an addition, a multiplication or a division, each correctly rounded by IEEE 754
on every core (and by numpy's SIMD kernels), so the same operations in the same order give the
same bits. Measured accuracy (bench/roots.py, docs/codegen.md): within 0.97 ulp of the
correctly rounded root in float and 0.93 ulp in double.
"""

from __future__ import annotations

import numpy as np

# (dtype, unsigned view, bits of the upper word kept for the guess, guess constant, Halley steps,
#  below this a is scaled up, above it down, by 2^(3s); s)
_PLANS = {
    np.dtype(np.float32): (np.uint32, 0, 0x2A5137A0, 1, 2.0**-60, 2.0**60, 20),
    np.dtype(np.float64): (np.uint64, 32, 715094163, 2, 2.0**-600, 2.0**600, 200),
}


def cbrt(x: np.ndarray) -> np.ndarray:
    """The cube root of each element, in x's precision (float32 or float64), as the generated C rounds it."""
    x = np.asarray(x)
    if x.dtype not in _PLANS:
        x = x.astype(np.float64)
    dt = x.dtype.type
    uint, shift, magic, halley, small, large, s = _PLANS[x.dtype]
    x = np.atleast_1d(x)
    bits = x.view(uint)
    sign = bits & uint(1 << (8 * x.itemsize - 1))
    a = (bits ^ sign).view(x.dtype)
    special = ~np.isfinite(a) | (a == 0)
    a = np.where(special, dt(1.0), a)
    up, down = a < dt(small), a > dt(large)
    with np.errstate(over="ignore", under="ignore"):  # np.where computes the scaling of every row
        a = np.where(up, a * dt(2.0 ** (3 * s)), a)
        a = np.where(down, a * dt(2.0 ** (-3 * s)), a)
    ab = a.view(uint)
    if shift:
        hi = (ab >> uint(shift)).astype(np.uint32)
        y = ((hi // np.uint32(3) + np.uint32(magic)).astype(uint) << uint(shift)).view(x.dtype)
    else:
        y = (ab // uint(3) + uint(magic)).view(x.dtype)
    for _ in range(halley):
        t = y * y * y
        y = y * (t + a + a) / (t + t + a)
    y2 = y * y
    y = y - (y2 * y - a) / (dt(3.0) * y2)
    y = np.where(up, y * dt(2.0 ** -s), np.where(down, y * dt(2.0 ** s), y))  # exact: y is normal
    y = (y.view(uint) | sign).view(x.dtype)
    return np.where(special, x, y)
