"""NumPy's `Generator(PCG64(seed)).standard_normal()`, number for number, on a generator's state held in
four uint64 words (the batched simulator's chips, sim/sweeps/flight.py `normals`), so that the compiled
loop draws its normals without numba's Generator objects: a typed list of them cost 12 us a vehicle to
make (each one unboxed through its ctypes interface), and each draw called NumPy's bit generator
through a function pointer.

- PCG64 (numpy/random/src/pcg64/pcg64.h, `pcg64_next64`, `pcg_setseq_128_step_r`,
  `pcg_output_xsl_rr_128_64`): the 128-bit state moves on as state * PCG_DEFAULT_MULTIPLIER_128 + inc
  (mod 2^128) before each output, and the output is the state's two halves xored, rotated right by
  its top six bits. `next_double` is (next64 >> 11) / 2^53 (numpy/random/_pcg64.pyx, `pcg64_double`).
- The normal: NumPy's ziggurat (numpy/random/src/distributions/distributions.c,
  `random_standard_normal`), with its tables (numba/np/random/_constants.py holds NumPy's
  ziggurat_constants.h: `ki_double`, `wi_double`, `fi_double`), as numba's
  numba/np/random/distributions.py writes it.

Words: (state's high, low, inc's high, low), from `np.random.PCG64(seed).state` (`seeded`), the
seeding NumPy's (SeedSequence). Compiled only: the plain batch keeps NumPy's generators
(tests/test_batch.py checks these against them).
"""
from __future__ import annotations

from math import exp, log1p

import numpy as np

MASK64 = (1 << 64) - 1
_M32 = np.uint64(0xFFFFFFFF)
_S32, _S11, _S58, _S8, _S1, _S6 = np.uint64(32), np.uint64(11), np.uint64(58), np.uint64(8), np.uint64(1), np.uint64(6)
_S64 = np.uint64(64)
_MUL_HI, _MUL_LO = np.uint64(2549297995355413924), np.uint64(4865540595714422341)   # PCG_DEFAULT_MULTIPLIER_128
_FF, _ONE, _ABS = np.uint64(0xFF), np.uint64(1), np.uint64(0x000FFFFFFFFFFFFF)
_TO_DOUBLE = 1.0 / 9007199254740992.0
ZIGGURAT_NOR_R = 3.6541528853610087963519472518
ZIGGURAT_NOR_INV_R = 0.27366123732975827203338247596


def seeded(seeds) -> np.ndarray:
    """The (n, 4) uint64 words of `np.random.PCG64(s)` for each seed s (NumPy's seeding)."""
    out = np.empty((len(seeds), 4), dtype=np.uint64)
    for v, s in enumerate(seeds):
        st = np.random.PCG64(s).state["state"]
        a, b = st["state"], st["inc"]
        out[v] = (a >> 64, a & MASK64, b >> 64, b & MASK64)
    return out


def mulhi(a, b):
    """The high 64 bits of the 128-bit product of two uint64 words."""
    a0, a1, b0, b1 = a & _M32, a >> _S32, b & _M32, b >> _S32
    p00, p01, p10, p11 = a0 * b0, a0 * b1, a1 * b0, a1 * b1
    mid = (p00 >> _S32) + (p01 & _M32) + (p10 & _M32)
    return p11 + (p01 >> _S32) + (p10 >> _S32) + (mid >> _S32)


def next64(g):
    """`pcg64_next64`: the state g (four words) one step on, its output."""
    hi, lo, ihi, ilo = g[0], g[1], g[2], g[3]
    nhi = mulhi(lo, _MUL_LO) + lo * _MUL_HI + hi * _MUL_LO       # state * multiplier, mod 2^128
    nlo = lo * _MUL_LO
    lo = nlo + ilo                                               # + inc, with the carry
    hi = nhi + ihi + (_ONE if lo < nlo else np.uint64(0))
    g[0], g[1] = hi, lo
    x = hi ^ lo
    rot = hi >> _S58
    return (x >> rot) | (x << ((_S64 - rot) & np.uint64(63)))


def next_double(g) -> float:
    return float(next64(g) >> _S11) * _TO_DOUBLE


def standard_normal(g) -> float:
    """`random_standard_normal` (NumPy's ziggurat) on the generator g."""
    while True:
        r = next64(g)
        idx = int(r & _FF)
        r = r >> _S8
        rabs = (r >> _S1) & _ABS
        x = float(rabs) * WI[idx]
        if r & _ONE:
            x = -x
        if rabs < KI[idx]:
            return x
        if idx == 0:
            while True:
                xx = -ZIGGURAT_NOR_INV_R * log1p(-next_double(g))
                yy = -log1p(-next_double(g))
                if yy + yy > xx * xx:
                    return -(ZIGGURAT_NOR_R + xx) if (rabs >> _S8) & _ONE else ZIGGURAT_NOR_R + xx
        elif (FI[idx - 1] - FI[idx]) * next_double(g) + FI[idx] < exp(-0.5 * x * x):
            return x


def tables():
    """(ki, wi, fi): NumPy's ziggurat tables for the normal, as numba carries them."""
    from numba.np.random._constants import fi_double, ki_double, wi_double
    return ki_double, wi_double, fi_double


def compiled_normal(cc):
    """`standard_normal` compiled (`cc`: sim/world/compiled.py `compiled_copy`), its tables bound."""
    ki, wi, fi = tables()
    step = cc(next64, mulhi=cc(mulhi))
    return cc(standard_normal, next64=step, next_double=cc(next_double, next64=step), KI=ki, WI=wi, FI=fi)
