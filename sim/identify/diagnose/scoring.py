"""Held-out scoring of a diagnose model (docs/diagnose.md, "Score" and "Significance").

A model's residual is scored by blocked cross-validation: each of the `N_BLOCKS` contiguous blocks
is predicted by the model fitted on the others. The objective of every fit and the metric of every
score is the Gaussian log-likelihood with one noise variance per channel, sum_c log RSS_c; the
accelerometer channels carry one constant offset each (their bias), fitted on the training data.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from flightctl.sim.identify.diagnose.dataset import C, CHANNELS, N_BLOCKS, OFFSET, DataSet

MIN_GAIN = 0.01          # effect-size floor on the held-out gain (docs/diagnose.md)
T_CRIT = 3.0             # Diebold-Mariano t on the held-out loss differential (docs/diagnose.md)
DM_WINDOW_S = 1.0        # s: windows of the loss differential for that test (at most; at least
DM_MIN_WINDOWS = 30      # this many windows, each no shorter than 0.1 s)
# One channel judged on its own (docs/diagnose.md, "Significance"): the same effect-size floor as
# MIN_GAIN when the whole effect sits in one channel (1 - (1 - MIN_GAIN)^6), T_CRIT's one-sided
# level (0.135 %) shared by the six channels (Bonferroni: 3.5), and windows of 0.25 s, six times
# the correlation time of the low-passed residual, so that an effect confined to a few seconds of
# flight (the yaw steps) spreads over enough windows to be tested.
MIN_CHANNEL_GAIN = 1.0 - (1.0 - MIN_GAIN) ** C
T_CHANNEL = 3.5
DM_CHANNEL_WINDOW_S = 0.25


def _rss(res, mask, offsets=None):
    """Per-channel residual sum of squares over `mask`; offset channels centred by `offsets`."""
    r = res[:, mask]
    if offsets is not None:
        r = r - offsets[:, None]
    return np.einsum("cn,cn->c", r, r)


def offsets(res, mask):
    """(C,): the mean of each offset channel over `mask`, 0 for the others."""
    m = np.zeros(C)
    m[OFFSET] = res[OFFSET][:, mask].mean(axis=1)
    return m


def objective(res, mask):
    """Gaussian log-likelihood with one variance per channel (up to constants): sum_c log RSS_c."""
    return float(np.log(_rss(res, mask, offsets(res, mask)) + 1e-300).sum())


def block_stats(ds: DataSet, res):
    """(2, B, C): per block and channel, the sum and the sum of squares of a residual."""
    out = np.zeros((2, N_BLOCKS, C))
    for b, (i0, i1) in enumerate(ds.block_edges):
        r = res[:, i0:i1]
        out[0, b] = r.sum(axis=1)
        out[1, b] = np.einsum("cn,cn->c", r, r)
    return out


def stats_objective(st, test_block, counts):
    """`objective` on all blocks but one, from `block_stats` and the samples per block."""
    keep = np.arange(N_BLOCKS) != test_block
    n = counts[keep].sum()
    s1, s2 = st[0, keep].sum(axis=0), st[1, keep].sum(axis=0)
    rss = s2 - np.where(OFFSET, s1 * s1 / n, 0.0)
    return float(np.log(np.maximum(rss, 1e-300)).sum())


@dataclass
class Score:
    rss: np.ndarray          # (N_BLOCKS, C) held-out residual sums of squares
    count: np.ndarray        # (N_BLOCKS,) samples per block
    residual: np.ndarray     # (C, n) held-out residual (each block predicted by the fit on the others)

    def rmse(self):
        return np.sqrt(self.rss.sum(axis=0) / self.count.sum())


def heldout(ds: DataSet, residual_for_fold) -> Score:
    """`residual_for_fold(train_mask) -> (C, n) residual` of the model fitted on train_mask."""
    rss = np.zeros((N_BLOCKS, C))
    count = np.zeros(N_BLOCKS)
    out = np.empty((C, ds.n))
    for b in range(N_BLOCKS):
        test = ds.block == b
        res = residual_for_fold(~test)
        out[:, test] = res[:, test] - offsets(res, ~test)[:, None]
        rss[b] = np.einsum("cn,cn->c", out[:, test], out[:, test])
        count[b] = test.sum()
    return Score(rss, count, out)


def geomean(x):
    return float(np.exp(np.mean(np.log(x))))


@dataclass
class Significance:
    gain: float                # 1 - rmse_extended / rmse_base, both geometric means over the channels
    block_gain: np.ndarray     # (N_BLOCKS,) the same per block
    t_stat: float              # the Diebold-Mariano t of the loss differential
    channel_gain: np.ndarray   # (C,) 1 - rmse_extended / rmse_base of each channel
    channel_t: np.ndarray      # (C,) the same test on each channel alone, windows of DM_CHANNEL_WINDOW_S

    def named_by(self) -> str | None:
        """Why the candidate is significant: "all channels" (the geometric mean), or the first
        channel whose own gain is, or None. A candidate that predicts worse overall is not."""
        if self.gain >= MIN_GAIN and self.t_stat >= T_CRIT:
            return "all channels"
        if self.gain > 0:
            for c, g, t in zip(CHANNELS, self.channel_gain, self.channel_t):
                if g >= MIN_CHANNEL_GAIN and t >= T_CHANNEL:
                    return c
        return None


def _windows(base: Score, score: Score, fs: float, window_s: float):
    """((C, m) per-channel loss differentials log(RSS_base / RSS_ext) over m windows of `window_s`
    (shorter if that gives fewer than DM_MIN_WINDOWS, never under 0.1 s), m), or None if m < 2."""
    n = base.residual.shape[1]
    win = min(window_s, max(0.1, n / fs / DM_MIN_WINDOWS))
    per = max(2, int(round(win * fs)))
    m = n // per
    if m < 2:
        return None
    eb = (base.residual[:, :m * per] ** 2).reshape(C, m, per).sum(axis=2)
    ee = (score.residual[:, :m * per] ** 2).reshape(C, m, per).sum(axis=2)
    return np.log((eb + 1e-300) / (ee + 1e-300)), m


def _t(w: np.ndarray, m: int) -> float:
    se = w.std(ddof=1) / math.sqrt(m)
    return float(w.mean() / se) if se > 0 else (math.inf if w.mean() > 0 else 0.0)


def significance(score: Score, base: Score, fs: float) -> Significance:
    """Per-block held-out gains, and a Diebold-Mariano-type test of equal predictive accuracy on
    the held-out residuals. The held-out data are cut into windows of DM_WINDOW_S (much longer than
    the correlation time of the low-passed residual, so that windows are close to independent); in
    each window the loss differential is the metric's own, mean_c log(RSS_base,c / RSS_ext,c) (a
    log ratio, so that a few violent windows, a touchdown or a crash, cannot swamp the others). t is
    its mean over the windows in standard errors; when the candidate predicts no better than the
    base model, t is about N(0, 1) or below, and T_CRIT = 3 is a one-sided 0.1 % level. Each
    channel is also tested alone, on windows of DM_CHANNEL_WINDOW_S. `fs`: samples per second."""
    ratio = score.rss / base.rss                       # (B, C)
    block_gain = 1.0 - np.exp(0.5 * np.log(ratio).mean(axis=1))
    gain = 1.0 - geomean(score.rmse()) / geomean(base.rmse())
    channel_gain = 1.0 - score.rmse() / base.rmse()
    out = Significance(gain, block_gain, 0.0, channel_gain, np.zeros(C))
    windows = _windows(base, score, fs, DM_WINDOW_S)
    if windows is not None:
        w, m = windows
        out.t_stat = _t(w.mean(axis=0), m)
    windows = _windows(base, score, fs, DM_CHANNEL_WINDOW_S)
    if windows is not None:
        w, m = windows
        out.channel_t = np.array([_t(w[c], m) for c in range(C)])
    return out
