"""sim/sweeps/pcg64.py: NumPy's PCG64 and ziggurat normal on four uint64 words, number for number."""
from __future__ import annotations

import numpy as np
import pytest

from flightctl.sim.sweeps import pcg64
from flightctl.sim.world import compiled


@pytest.mark.skipif(not compiled.enabled(), reason="compiled only (numba)")
def test_the_words_give_numpys_normals_and_state():
    """Seeds drawn at random (small, large, 2^63 and up): 30,000 normals each equal to
    `default_rng(seed).standard_normal`, the ziggurat's tail and wedges included, and the words then
    NumPy's PCG64 state after as many draws."""
    import numba
    normal = pcg64.compiled_normal(compiled.compiled_copy)

    @numba.njit
    def draw(G, k, out):
        for v in range(G.shape[0]):
            for j in range(k):
                out[v, j] = normal(G[v])

    rng = np.random.default_rng(48)
    seeds = [int(s) for s in rng.integers(0, 1 << 20, 4)] + [int(rng.integers(1 << 62, 1 << 63)) * 3, 0]
    G = pcg64.seeded(seeds)
    out = np.empty((len(seeds), 30000))
    draw(G, out.shape[1], out)
    for v, s in enumerate(seeds):
        bits = np.random.PCG64(s)
        ref = np.random.Generator(bits).standard_normal(out.shape[1])
        assert np.array_equal(out[v], ref), s
        st = bits.state["state"]
        assert (int(G[v, 0]) << 64 | int(G[v, 1])) == st["state"]
        assert (int(G[v, 2]) << 64 | int(G[v, 3])) == st["inc"]
    assert np.abs(out).max() > pcg64.ZIGGURAT_NOR_R       # the tail's branch was taken


def test_the_seeding_is_numpys_for_every_kind_of_seed():
    """`seeded` (one-word seeds at once in numpy's modular arithmetic, others by NumPy) gives
    `np.random.PCG64(seed)`'s state and increment for 3,000 seeds drawn below 2^32, its ends, and a
    mixed list with seeds of several words."""
    rng = np.random.default_rng(4848)
    small = [0, 1, (1 << 32) - 1] + [int(s) for s in rng.integers(0, 1 << 32, 3000)]
    mixed = small[:5] + [1 << 32, int(rng.integers(1 << 40, 1 << 62)), 12345678901234567890]
    for seeds in (small, mixed, small[:1]):
        G = pcg64.seeded(seeds)
        assert G.dtype == np.uint64 and G.shape == (len(seeds), 4)
        for v, s in enumerate(seeds):
            st = np.random.PCG64(s).state["state"]
            assert (int(G[v, 0]) << 64 | int(G[v, 1]), int(G[v, 2]) << 64 | int(G[v, 3])) == (st["state"], st["inc"]), s
