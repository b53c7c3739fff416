"""Did a vehicle's series (one figure per flight with its standard error, in flight order) change, from
which flight, by how much, and how sure: a change-point test with its uncertainty, corrected over every
series of the fleet.

Each flight's value is y_i ~ N(mu_i, s_i^2 + tau^2): s_i its own standard error (the log's block
jackknife), tau the spread between flights that no flight's error holds (the pack's temperature, the
wind, the load: a series whose errors were all anyone trusted would call every wobble a change), fitted
by maximum likelihood, profiled on a grid (TAU_GRID values of tau^2 from 0 to 10 times the series'
variance, log-spaced). The models:

- no change: mu_i = mu;
- a step at flight k: mu_i = mu_1 before k, mu_2 from k on (each side at least MIN_SIDE flights);
- (`hinge` series: the battery's resistance, the vibration) a hinge at k: mu_i = a + b max(0, i - k), flat
  and then a linear rise or fall from k (k = 0: a trend over every flight).

The statistic is the largest likelihood ratio over the split points (and the two shapes), LR = 2 (l_1 -
l_0): the split point is searched, so its distribution is not chi-square; its p-value is from a
parametric bootstrap under the fitted no-change model (BOOTSTRAP replicates, each searched the same
way; Davison and Hinkley, Bootstrap Methods and their Application, 1997, ch. 4), with the add-one
estimate (1 + #{LR* >= LR}) / (B + 1). Over every series of the fleet, Holm's step-down correction (Holm,
"A simple sequentially rejective multiple test procedure", Scand. J. Statist. 6, 1979) holds the chance
of naming anything on a fleet where nothing changed at ALPHA. The onset's interval is the split points
whose likelihood is within the chi-square(1) 95 % quantile of the best (a likelihood-ratio confidence
set for the change point: Siegmund, "Confidence sets in change-point problems", Int. Statist. Rev. 56,
1988); the size is the step mu_2 - mu_1 (or the hinge's slope) at the best split with its standard error.
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np
from scipy import stats

ALPHA = 0.05                 # the family-wise error rate over the fleet's series
BOOTSTRAP = 1999             # replicates of the no-change null (p-values from 1/2000)
MIN_SIDE = 3                 # flights on each side of a step
MIN_FLIGHTS = 2 * MIN_SIDE + 2   # a series shorter than this is not tested
TAU_GRID = 24
LR_SET = float(stats.chi2.ppf(0.95, 1))   # the onset's 95 % likelihood set


@dataclass
class Change:
    """A series' test: `lr` and `p` (the bootstrap's), `shape` ("step" or "hinge"), `onset` (the position
    in the series of the first flight changed: the new level's first, or the first after the hinge),
    `onset_set` (lo, hi), `size`
    and `size_se` (the step, or the hinge's slope per flight), `before` and `after` (the levels either
    side, fitted), `tau` (the spread between flights), `p_adjusted` (Holm's, set by `correct`)."""
    lr: float
    p: float
    shape: str
    onset: int
    onset_set: tuple[int, int]
    size: float
    size_se: float
    before: float
    after: float
    tau: float
    n: int
    p_adjusted: float = 1.0


def _grid(y: np.ndarray, s2: np.ndarray) -> np.ndarray:
    scale = max(float(np.var(y)), float(np.median(s2)), 1e-30)
    g = scale * np.logspace(-4, 1, TAU_GRID - 1)
    return np.concatenate([[0.0], g]) if (s2 > 0).all() else g


def _weights(s2: np.ndarray, tau2: np.ndarray) -> np.ndarray:
    """(G, n) weights 1 / (s_i^2 + tau^2)."""
    return 1.0 / (s2[None, :] + tau2[:, None])


def _null(Y: np.ndarray, w: np.ndarray) -> np.ndarray:
    """(B,) the no-change model's log-likelihood (less constants), profiled over the grid: Y (B, n)."""
    logdet = np.log(w).sum(axis=1)                                  # (G,)
    Sw, Swy = w.sum(axis=1), Y @ w.T                                # (G,), (B, G)
    Swyy = (Y * Y) @ w.T
    sse = Swyy - Swy ** 2 / Sw
    return (0.5 * (logdet[None, :] - sse)).max(axis=1)


def _steps(Y: np.ndarray, w: np.ndarray) -> np.ndarray:
    """(B, K) the step model's profiled log-likelihood at each split k = MIN_SIDE .. n - MIN_SIDE."""
    n = Y.shape[1]
    logdet = np.log(w).sum(axis=1)
    cw = np.cumsum(w, axis=1)                                        # (G, n)
    cwy = np.cumsum(Y[:, None, :] * w[None], axis=2)                 # (B, G, n)
    cwyy = np.cumsum(Y[:, None, :] ** 2 * w[None], axis=2)
    k = np.arange(MIN_SIDE, n - MIN_SIDE + 1)
    left_w, left_y, left_yy = cw[:, k - 1], cwy[..., k - 1], cwyy[..., k - 1]
    right_w = cw[:, -1:] - left_w
    right_y, right_yy = cwy[..., -1:] - left_y, cwyy[..., -1:] - left_yy
    sse = (left_yy - left_y ** 2 / left_w) + (right_yy - right_y ** 2 / right_w)
    return (0.5 * (logdet[None, :, None] - sse)).max(axis=1)


def _hinge_fit(Y: np.ndarray, w: np.ndarray, x: np.ndarray):
    """(B, G) sse, and the coefficients (a, b) and their inverse-information matrices, of mu = a + b x."""
    Sw, Swx, Swxx = w.sum(axis=1), w @ x, w @ (x * x)
    Swy, Swxy, Swyy = Y @ w.T, (Y * x) @ w.T, (Y * Y) @ w.T
    det = Sw * Swxx - Swx ** 2
    a = (Swxx * Swy - Swx * Swxy) / det
    b = (Sw * Swxy - Swx * Swy) / det
    sse = Swyy - a * Swy - b * Swxy
    return sse, a, b, Sw / det


def _hinges(Y: np.ndarray, w: np.ndarray) -> np.ndarray:
    """(B, K) the hinge model's profiled log-likelihood at each hinge k = 0 .. n - MIN_SIDE - 1."""
    n = Y.shape[1]
    logdet = np.log(w).sum(axis=1)
    out = []
    for k in range(0, n - MIN_SIDE):
        x = np.maximum(0.0, np.arange(n) - k).astype(float)
        sse = _hinge_fit(Y, w, x)[0]
        out.append((0.5 * (logdet[None, :] - sse)).max(axis=1))
    return np.stack(out, axis=1)


def _search(Y, w, hinge: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    null = _null(Y, w)
    st = 2.0 * (_steps(Y, w) - null[:, None])
    hi = 2.0 * (_hinges(Y, w) - null[:, None]) if hinge else None
    best = st.max(axis=1) if hi is None else np.maximum(st.max(axis=1), hi.max(axis=1))
    return best, st, hi


def _seed(y: np.ndarray) -> int:
    return int.from_bytes(hashlib.sha256(np.ascontiguousarray(y, dtype=float).tobytes()).digest()[:8], "little")


def test(y, se, hinge: bool = False, bootstrap: int = BOOTSTRAP) -> Change | None:
    """The change test of one series (the module's docstring); None when it has fewer than MIN_FLIGHTS
    values. `se` None or NaN: no standard error (tau then holds all the scatter). The bootstrap's
    generator is seeded from the data: the same series gives the same p-value."""
    y = np.asarray(y, dtype=float)
    s2 = np.nan_to_num(np.asarray(se, dtype=float), nan=0.0) ** 2
    n = y.size
    if n < MIN_FLIGHTS:
        return None
    tau2 = _grid(y, s2)
    w = _weights(s2, tau2)
    best, st, hi = _search(y[None, :], w, hinge)
    lr = float(best[0])
    # the fitted no-change model: its mean and tau at the profile's best
    Sw, Swy, Swyy = w.sum(axis=1), w @ y, w @ (y * y)
    g0 = int(np.argmax(0.5 * (np.log(w).sum(axis=1) - (Swyy - Swy ** 2 / Sw))))
    mu0, sd0 = Swy[g0] / Sw[g0], np.sqrt(s2 + tau2[g0])
    rng = np.random.default_rng(_seed(y))
    exceed = 0
    for start in range(0, bootstrap, 200):
        Ystar = mu0 + sd0 * rng.standard_normal((min(200, bootstrap - start), n))
        exceed += int((_search(Ystar, w, hinge)[0] >= lr - 1e-9).sum())
    p = (1 + exceed) / (bootstrap + 1)
    use_hinge = hi is not None and hi.max() > st.max()
    prof = (hi if use_hinge else st)[0]
    ks = np.arange(0, n - MIN_SIDE) if use_hinge else np.arange(MIN_SIDE, n - MIN_SIDE + 1)
    j = int(np.argmax(prof))
    k = int(ks[j])
    inside = ks[prof >= prof[j] - LR_SET]
    ll = 0.5 * np.log(w).sum(axis=1)
    if use_hinge:
        x = np.maximum(0.0, np.arange(n) - k).astype(float)
        sse, a, b, var_b = _hinge_fit(y[None, :], w, x)
        g = int(np.argmax(ll - 0.5 * sse[0]))
        size, size_se = float(b[0, g]), float(np.sqrt(var_b[g]))
        before, after = float(a[0, g]), float(a[0, g] + b[0, g] * x[-1])
    else:
        wl, wr = w[:, :k], w[:, k:]
        ml = (wl * y[:k]).sum(axis=1) / wl.sum(axis=1)
        mr = (wr * y[k:]).sum(axis=1) / wr.sum(axis=1)
        sse = (wl * (y[:k] - ml[:, None]) ** 2).sum(axis=1) + (wr * (y[k:] - mr[:, None]) ** 2).sum(axis=1)
        g = int(np.argmax(ll - 0.5 * sse))
        before, after = float(ml[g]), float(mr[g])
        size, size_se = after - before, float(np.sqrt(1.0 / wl[g].sum() + 1.0 / wr[g].sum()))
    shift = 1 if use_hinge else 0        # a hinge at k leaves flight k flat: the first flight changed is k + 1
    return Change(lr, p, "hinge" if use_hinge else "step", k + shift, (int(inside.min()) + shift, int(inside.max()) + shift),
                  size, size_se, before, after, float(np.sqrt(tau2[g])), n)


def correct(changes: list[Change | None], alpha: float = ALPHA) -> list[bool]:
    """Holm's step-down over the tested series: each series' adjusted p-value set, and whether it is
    named (adjusted p below alpha)."""
    idx = [i for i, c in enumerate(changes) if c is not None]
    order = sorted(idx, key=lambda i: changes[i].p)
    m = len(order)
    running = 0.0
    for rank, i in enumerate(order):
        running = max(running, min(1.0, (m - rank) * changes[i].p))
        changes[i].p_adjusted = running
    return [c is not None and c.p_adjusted < alpha for c in changes]
