"""The significance rules of diagnose on residuals built by hand: an effect that lives in one channel
and in a few seconds of the flight is named by that channel, even when the test over all channels
misses it (the outside check: linear yaw drag sized exactly, mean gain 0.061, t = 2.8); noise,
a tiny systematic gain and a candidate worse overall are not."""
from __future__ import annotations

import numpy as np

from flightctl.sim.diagnose.dataset import CHANNELS, N_BLOCKS
from flightctl.sim.diagnose.scoring import (MIN_CHANNEL_GAIN, MIN_GAIN, T_CHANNEL, T_CRIT, Score,
                                                     significance)

FS = 450.0
N = int(80 * FS)          # an 80 s flight, like the paper's
R_DOT = CHANNELS.index("r_dot")


def score_of(residual: np.ndarray) -> Score:
    """The held-out Score of a (C, n) residual, blocks as in DataSet."""
    edges = np.linspace(0, residual.shape[1], N_BLOCKS + 1).round().astype(int)
    rss = np.array([np.einsum("cn,cn->c", residual[:, a:b], residual[:, a:b])
                    for a, b in zip(edges[:-1], edges[1:])])
    return Score(rss, np.diff(edges).astype(float), residual)


def base_and_bursts(rng, n_bursts: int, size: float):
    """White measurement noise in every channel, plus a model error in r_dot during n_bursts yaw
    manoeuvres of 1 s each (what a missing yaw drag leaves in the residual)."""
    base = rng.standard_normal((len(CHANNELS), N))
    error = np.zeros(N)
    for k in range(n_bursts):
        i0 = int((5 + k * 70 / n_bursts) * FS)
        error[i0:i0 + int(FS)] = size * np.sin(np.linspace(0, 3 * np.pi, int(FS)))
    base[R_DOT] += error
    return base, error


def test_one_channel_effect_in_a_few_seconds_is_named_by_its_channel():
    rng = np.random.default_rng(1)
    base, error = base_and_bursts(rng, n_bursts=5, size=4.0)
    fitted = base.copy()
    fitted[R_DOT] -= error                    # the candidate explains the error exactly
    s = significance(score_of(fitted), score_of(base), FS)
    assert s.gain >= MIN_GAIN                 # a real effect: the mean gain is well above the floor ...
    assert s.t_stat < T_CRIT                  # ... but concentrated, so the test over all channels misses it
    assert s.channel_gain[R_DOT] >= MIN_CHANNEL_GAIN and s.channel_t[R_DOT] >= T_CHANNEL
    assert s.named_by() == "r_dot"
    others = np.arange(len(CHANNELS)) != R_DOT
    np.testing.assert_array_equal(s.channel_gain[others], 0.0)


def test_the_same_effect_spread_over_the_flight_is_named_by_all_channels():
    rng = np.random.default_rng(2)
    base, error = base_and_bursts(rng, n_bursts=60, size=1.0)
    fitted = base.copy()
    fitted[R_DOT] -= error
    s = significance(score_of(fitted), score_of(base), FS)
    assert s.t_stat >= T_CRIT and s.named_by() == "all channels"


def test_noise_is_not_named():
    for seed in range(20):
        rng = np.random.default_rng(100 + seed)
        base = rng.standard_normal((len(CHANNELS), N))
        # a candidate fitted on other blocks that only moves the noise around a little
        fitted = base + 0.05 * rng.standard_normal(base.shape)
        assert significance(score_of(fitted), score_of(base), FS).named_by() is None


def test_a_tiny_systematic_gain_is_not_named_however_sure():
    rng = np.random.default_rng(3)
    base = rng.standard_normal((len(CHANNELS), N))
    fitted = base.copy()
    fitted[R_DOT] *= 0.98                      # 2 % better everywhere: t is huge, the effect is not
    s = significance(score_of(fitted), score_of(base), FS)
    assert s.channel_t[R_DOT] > 10 * T_CHANNEL
    assert s.channel_gain[R_DOT] < MIN_CHANNEL_GAIN and s.named_by() is None


def test_a_candidate_worse_overall_is_not_named_by_one_good_channel():
    rng = np.random.default_rng(4)
    base, error = base_and_bursts(rng, n_bursts=5, size=4.0)
    fitted = base.copy()
    fitted[R_DOT] -= error
    fitted[CHANNELS.index("acc_z")] *= 1.5     # but it spoils another channel more than it helps
    s = significance(score_of(fitted), score_of(base), FS)
    assert s.channel_gain[R_DOT] >= MIN_CHANNEL_GAIN and s.channel_t[R_DOT] >= T_CHANNEL
    assert s.gain < 0 and s.named_by() is None
