"""NumPy's `Generator(PCG64(seed)).standard_normal()`, number for number, on a generator's state held in
four uint64 words (the batched simulator's chips, sim/sweeps/twin_loop.py `normals`), so that the compiled
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
(tests/sim/sweeps/test_batch.py checks these against them).
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
    """The (n, 4) uint64 words of `np.random.PCG64(s)` for each seed s: NumPy's seeding (`SeedSequence(s)`,
    its `generate_state(4, uint64)`, `pcg64_set_seed`), for seeds below 2^32 across the vehicles at once
    in numpy's uint32 and uint64 arithmetic (modular, as C's), others by NumPy itself."""
    s = np.asarray(seeds, dtype=object)
    if len(s) and all(isinstance(v, (int, np.integer)) and 0 <= v < 1 << 32 for v in s):
        return _seeded_words(np.asarray(s, dtype=np.uint32))
    out = np.empty((len(seeds), 4), dtype=np.uint64)
    for v, seed in enumerate(seeds):
        st = np.random.PCG64(seed).state["state"]
        a, b = st["state"], st["inc"]
        out[v] = (a >> 64, a & MASK64, b >> 64, b & MASK64)
    return out


# numpy/random/bit_generator.pyx (SeedSequence): its hash's constants, a pool of four 32-bit words
_INIT_A, _MULT_A, _INIT_B, _MULT_B = 0x43B0D7E5, 0x931E8875, 0x8B51F9DD, 0x58F38DED
_MIX_L, _MIX_R, _POOL = np.uint32(0xCA01F9DD), np.uint32(0x4973F715), 4
_U16 = np.uint32(16)


def _seeded_words(entropy: np.ndarray) -> np.ndarray:
    """`seeded` of one-word seeds (uint32), a vehicle per entry: SeedSequence's `mix_entropy` (hashmix, mix),
    `generate_state` (eight words, as four little-endian uint64), then `pcg_setseq_128_srandom_r`."""
    const = [_INIT_A]

    def hashmix(value):
        value = value ^ np.uint32(const[0])
        const[0] = const[0] * _MULT_A & 0xFFFFFFFF
        value = value * np.uint32(const[0])
        return value ^ (value >> _U16)

    def mix(x, y):
        r = _MIX_L * x - _MIX_R * y
        return r ^ (r >> _U16)
    zero = np.zeros_like(entropy)
    pool = [hashmix(entropy if i == 0 else zero) for i in range(_POOL)]
    for src in range(_POOL):
        for dst in range(_POOL):
            if src != dst:
                pool[dst] = mix(pool[dst], hashmix(pool[src]))
    h, words = _INIT_B, []
    for i in range(8):
        v = pool[i % _POOL] ^ np.uint32(h)
        h = h * _MULT_B & 0xFFFFFFFF
        v = v * np.uint32(h)
        words.append((v ^ (v >> _U16)).astype(np.uint64))
    val = [words[2 * j] | (words[2 * j + 1] << _S32) for j in range(4)]
    ihi = (val[2] << _S1) | (val[3] >> np.uint64(63))          # inc = initseq << 1 | 1
    ilo = (val[3] << _S1) | _ONE
    hi, lo = ihi.copy(), ilo.copy()                              # state 0, one step: inc
    lo2 = lo + val[1]                                            # + initstate
    hi = hi + val[0] + (lo2 < lo).astype(np.uint64)
    nhi = mulhi(lo2, _MUL_LO) + lo2 * _MUL_HI + hi * _MUL_LO     # one step
    nlo = lo2 * _MUL_LO
    lo = nlo + ilo
    hi = nhi + ihi + (lo < nlo).astype(np.uint64)
    return np.ascontiguousarray(np.stack([hi, lo, ihi, ilo], axis=1))


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
    """`random_standard_normal` (NumPy's ziggurat) on the generator g. KI, WI and FI, NumPy's tables, are bound
    where it is compiled (`compiled_normal`), hence the noqa."""
    while True:
        r = next64(g)
        idx = int(r & _FF)
        r = r >> _S8
        rabs = (r >> _S1) & _ABS
        x = float(rabs) * WI[idx]  # noqa: F821
        if r & _ONE:
            x = -x
        if rabs < KI[idx]:  # noqa: F821
            return x
        if idx == 0:
            while True:
                xx = -ZIGGURAT_NOR_INV_R * log1p(-next_double(g))
                yy = -log1p(-next_double(g))
                if yy + yy > xx * xx:
                    return -(ZIGGURAT_NOR_R + xx) if (rabs >> _S8) & _ONE else ZIGGURAT_NOR_R + xx
        elif (FI[idx - 1] - FI[idx]) * next_double(g) + FI[idx] < exp(-0.5 * x * x):  # noqa: F821
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
