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

from flightctl.sim.diagnose.dataset import C, CHANNELS, N_BLOCKS, OFFSET, DataSet

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


def offsets(res, mask):
    """(C,): the mean of each offset channel over `mask`, 0 for the others."""
    m = np.zeros(C)
    m[OFFSET] = res[OFFSET][:, mask].mean(axis=1)
    return m


@dataclass
class LinearStats:
    """Per block b and channel c, sums over the block's samples of a residual e (C, n) and of free
    columns A (C, n, P) that a fit may subtract: e, A, e^2, A e and A A^T. Every fit of diagnose is
    a weighted least-squares fit of the free columns' coefficients from these, so that the folds of
    the held-out scoring cost sums over blocks, not passes over the data."""
    se: np.ndarray     # (B, C)
    sA: np.ndarray     # (B, C, P)
    ee: np.ndarray     # (B, C)
    Ae: np.ndarray     # (B, C, P)
    AA: np.ndarray     # (B, C, P, P)

    @property
    def P(self) -> int:
        return self.sA.shape[2]


def linear_stats(ds: DataSet, e: np.ndarray, A: np.ndarray | None = None) -> LinearStats:
    """The block sums of e (C, n) and A (C, n, P) (None: no free columns)."""
    if A is None:
        A = np.zeros((C, e.shape[1], 0))
    P = A.shape[2]
    st = LinearStats(np.zeros((N_BLOCKS, C)), np.zeros((N_BLOCKS, C, P)), np.zeros((N_BLOCKS, C)),
                     np.zeros((N_BLOCKS, C, P)), np.zeros((N_BLOCKS, C, P, P)))
    # most columns act in one channel or two: the products are taken per channel over its own columns
    active = [np.flatnonzero(A[c].any(axis=0)) for c in range(C)] if P else [np.arange(0)] * C
    for b, (i0, i1) in enumerate(ds.block_edges):
        eb = e[:, i0:i1]
        st.se[b] = eb.sum(axis=1)
        st.ee[b] = np.einsum("cn,cn->c", eb, eb)
        for c, cols in enumerate(active):
            if cols.size:
                Ab = A[c, i0:i1][:, cols]
                st.sA[b, c, cols] = Ab.sum(axis=0)
                st.Ae[b, c, cols] = eb[c] @ Ab
                st.AA[b, c, cols[:, None], cols[None, :]] = Ab.T @ Ab
    return st


def reparametrized(st: LinearStats, M: np.ndarray) -> LinearStats:
    """The statistics of the columns A M (P x Q): a fit of Q coefficients that set the P columns'
    linearly, without another pass over the data."""
    return LinearStats(st.se, st.sA @ M, st.ee, st.Ae @ M, np.einsum("pq,bcpr,rs->bcqs", M, st.AA, M))


def solve(st: LinearStats, keep, counts) -> tuple[float, np.ndarray, np.ndarray]:
    """The fit on the blocks `keep` (a boolean mask or indices): the coefficients theta (P,) of the
    free columns by least squares weighted per channel by the inverse of its residual variance
    (three reweighting passes: the maximum-likelihood fit of one variance per channel), the offset
    channels centred. Returns (sum_c log RSS_c, theta, offsets (C,))."""
    keep = np.asarray(keep)
    n = counts[keep].sum()
    cen = np.where(OFFSET, 1.0 / n, 0.0)
    se, ee = st.se[keep].sum(axis=0), st.ee[keep].sum(axis=0)
    ee = ee - cen * se * se
    theta = np.zeros(st.P)
    if st.P:
        sA = st.sA[keep].sum(axis=0)
        Ae = st.Ae[keep].sum(axis=0) - cen[:, None] * sA * se[:, None]
        AA = st.AA[keep].sum(axis=0) - cen[:, None, None] * sA[:, :, None] * sA[:, None, :]
        w = 1.0 / np.maximum(ee, 1e-300)
        for _ in range(3):
            M = np.einsum("c,cpq->pq", w, AA)
            h = np.einsum("c,cp->p", w, Ae)
            theta = np.linalg.lstsq(M + 1e-12 * np.trace(M) * np.eye(st.P), h, rcond=None)[0]
            rss = ee - 2.0 * Ae @ theta + np.einsum("p,cpq,q->c", theta, AA, theta)
            w = 1.0 / np.maximum(rss, 1e-300)
        ee = rss
        se = se - sA @ theta
    return float(np.log(np.maximum(ee, 1e-300)).sum()), theta, np.where(OFFSET, se / n, 0.0)


def fitted(e: np.ndarray, A: np.ndarray | None, theta: np.ndarray) -> np.ndarray:
    """e - A theta: the residual with the free columns subtracted (offsets not removed)."""
    if A is None or not theta.size:
        return e
    return e - A @ theta


@dataclass
class Score:
    rss: np.ndarray          # (N_BLOCKS, C) held-out residual sums of squares
    count: np.ndarray        # (N_BLOCKS,) samples per block
    residual: np.ndarray     # (C, n) held-out residual (each block predicted by the fit on the others)

    def rmse(self):
        return np.sqrt(self.rss.sum(axis=0) / self.count.sum())


def heldout(ds: DataSet, fold) -> Score:
    """`fold(test_block) -> ((C, n_test) residual on the test block, offsets (C,))` of the model
    fitted on the other blocks; the held-out residual is that residual less those offsets."""
    rss = np.zeros((N_BLOCKS, C))
    out = np.empty((C, ds.n))
    for b, (i0, i1) in enumerate(ds.block_edges):
        res, off = fold(b)
        out[:, i0:i1] = res - off[:, None]
        rss[b] = np.einsum("cn,cn->c", out[:, i0:i1], out[:, i0:i1])
    return Score(rss, ds.block_counts.copy(), out)


def heldout_linear(ds: DataSet, e: np.ndarray, A: np.ndarray | None, st: LinearStats | None = None,
                   record=None) -> Score:
    """The held-out Score of a linear model: each block predicted with the coefficients fitted on
    the others. `record(theta)` sees each fold's coefficients."""
    st = linear_stats(ds, e, A) if st is None else st
    blocks = np.arange(N_BLOCKS)

    def fold(b):
        _, theta, off = solve(st, blocks != b, ds.block_counts)
        if record is not None:
            record(theta)
        i0, i1 = ds.block_edges[b]
        return fitted(e[:, i0:i1], None if A is None else A[:, i0:i1], theta), off

    return heldout(ds, fold)


def geomean(x):
    """The geometric mean of the channels' RMSE; a channel whose RMSE is exactly zero is one the log does
    not measure (no accelerometer: `DataSet._sense`), left out."""
    x = np.asarray(x, float)
    return float(np.exp(np.mean(np.log(x[x > 0])))) if (x > 0).any() else 0.0


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
    measured = base.rss.sum(axis=0) > 0               # (C,): the channels the log measures (geomean)
    ratio = score.rss[:, measured] / base.rss[:, measured]     # (B, C measured)
    block_gain = 1.0 - np.exp(0.5 * np.log(ratio).mean(axis=1))
    gain = 1.0 - geomean(score.rmse()) / geomean(base.rmse())
    channel_gain = np.where(measured, 1.0 - score.rmse() / np.where(measured, base.rmse(), 1.0), 0.0)
    out = Significance(gain, block_gain, 0.0, channel_gain, np.zeros(C))
    windows = _windows(base, score, fs, DM_WINDOW_S)
    if windows is not None:
        w, m = windows
        out.t_stat = _t(w[measured].mean(axis=0), m)
    windows = _windows(base, score, fs, DM_CHANNEL_WINDOW_S)
    if windows is not None:
        w, m = windows
        out.channel_t = np.array([_t(w[c], m) for c in range(C)])
    return out
