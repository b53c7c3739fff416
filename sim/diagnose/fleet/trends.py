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
l_0): the split point is searched, so its distribution is not chi-square. Its p-value is a parametric
bootstrap's from the no-change fit (Efron and Tibshirani, "An Introduction to the Bootstrap", 1993,
ch. 16.4): series drawn as y*_i ~ N(mu_0, s_i^2 + tau_0^2), each flight with its own standard error and
the spread between flights of the fitted no-change model, each searched over the split points the same
way. So the null keeps what each flight knows (a permutation of ten flights cannot give a p-value below
one over the orderings that move the split, about 1/60, whatever the flights' errors), and the p-value's
resolution is 1 / (DRAWS + 1), its add-one estimate (1 + #{LR* >= LR}) / (B + 1) (Phipson and Smyth,
"Permutation p-values should never be zero", Stat. Appl. Genet. Mol. Biol. 9, 2010); the draws stop early
once STOP of them reach the statistic, p = STOP / draws (Besag and Clifford, "Sequential Monte Carlo
p-values", Biometrika 78, 1991): a series far from any change costs a batch, not DRAWS.

A finding is tested as one (`calibrate` of several series): a vehicle's four motor shares average one, so
a motor that weakens moves all four; the finding's statistic is the largest of its series' LRs, its null
the largest of theirs drawn together. Over every finding of the fleet (not every series), Holm's
step-down correction (Holm, "A simple sequentially rejective multiple test procedure", Scand. J.
Statist. 6, 1979) holds the chance of naming anything on a fleet where nothing changed at ALPHA. The
onset's interval is the split points whose likelihood is within the chi-square(1) 95 % quantile of the
best (a likelihood-ratio confidence set for the change point: Siegmund, "Confidence sets in change-point
problems", Int. Statist. Rev. 56, 1988); the size is the step mu_2 - mu_1 (or the hinge's slope) at the
best split with its standard error.
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np
from scipy import stats

ALPHA = 0.05                 # the family-wise error rate over the fleet's findings
DRAWS = 1999                 # the bootstrap's series under no change (p-values from 1/2000)
STOP = 20                    # the draws stop once this many reach the statistic (Besag and Clifford)
BATCH = 100                  # series drawn at once
MIN_SIDE = 2                 # flights on each side of a step (the flights' own errors carry a short side)
MIN_FLIGHTS = 2 * MIN_SIDE + 1   # a series shorter than this is not tested
TAU_GRID = 24
LR_SET = float(stats.chi2.ppf(0.95, 1))   # the onset's 95 % likelihood set


@dataclass
class Change:
    """A series' fit at its best split: `lr`, `shape` ("step" or "hinge"), `onset` (the position in the
    series of the first flight changed: the new level's first, or the first after the hinge), `onset_set`
    (lo, hi), `size` and `size_se` (the step, or the hinge's slope per flight), `before` and `after` (the
    levels either side, fitted), `tau` (the spread between flights), `level` and `tau_null` (the
    no-change fit the bootstrap draws from); `p` and `p_adjusted` are its finding's (`calibrate`,
    `correct`), `draws` how many bootstrap series it took."""
    lr: float
    shape: str
    onset: int
    onset_set: tuple[int, int]
    size: float
    size_se: float
    before: float
    after: float
    tau: float
    n: int
    level: float
    tau_null: float
    p: float = 1.0
    p_adjusted: float = 1.0
    draws: int = 0


def _grid(y: np.ndarray, s2: np.ndarray) -> np.ndarray:
    scale = max(float(np.var(y)), float(np.median(s2)), 1e-30)
    g = scale * np.logspace(-4, 1, TAU_GRID - 1)
    return np.concatenate([[0.0], g]) if (s2 > 0).all() else g


def _weights(s2: np.ndarray, tau2: np.ndarray) -> np.ndarray:
    """(..., G, n) weights 1 / (s_i^2 + tau^2) of s2 (..., n)."""
    return 1.0 / (s2[..., None, :] + tau2[:, None])


def _null(Y: np.ndarray, w: np.ndarray) -> np.ndarray:
    """(B,) the no-change model's log-likelihood (less constants), profiled over the grid: Y (B, n), w
    (B, G, n) or (G, n)."""
    wy = w * Y[:, None, :]
    sse = (wy * Y[:, None, :]).sum(axis=-1) - wy.sum(axis=-1) ** 2 / w.sum(axis=-1)
    return (0.5 * (np.log(w).sum(axis=-1) - sse)).max(axis=1)


def _steps(Y: np.ndarray, w: np.ndarray) -> np.ndarray:
    """(B, K) the step model's profiled log-likelihood at each split k = MIN_SIDE .. n - MIN_SIDE."""
    n = Y.shape[1]
    logdet = np.log(w).sum(axis=-1)[..., None]                       # (B or 1, G, 1)
    cw = np.cumsum(w, axis=-1)
    cwy = np.cumsum(w * Y[:, None, :], axis=-1)                      # (B, G, n)
    cwyy = np.cumsum(w * Y[:, None, :] ** 2, axis=-1)
    k = np.arange(MIN_SIDE, n - MIN_SIDE + 1)
    left_w, left_y, left_yy = cw[..., k - 1], cwy[..., k - 1], cwyy[..., k - 1]
    right_w = cw[..., -1:] - left_w
    right_y, right_yy = cwy[..., -1:] - left_y, cwyy[..., -1:] - left_yy
    sse = (left_yy - left_y ** 2 / left_w) + (right_yy - right_y ** 2 / right_w)
    return (0.5 * (logdet - sse)).max(axis=1)


def _hinge_fit(Y: np.ndarray, w: np.ndarray, x: np.ndarray):
    """(B, G) sse, and the coefficients (a, b) and b's variance, of mu = a + b x by weighted least squares."""
    wy = w * Y[:, None, :]
    Sw, Swx, Swxx = w.sum(axis=-1), (w * x).sum(axis=-1), (w * x * x).sum(axis=-1)
    Swy, Swxy, Swyy = wy.sum(axis=-1), (wy * x).sum(axis=-1), (wy * Y[:, None, :]).sum(axis=-1)
    det = Sw * Swxx - Swx ** 2
    a = (Swxx * Swy - Swx * Swxy) / det
    b = (Sw * Swxy - Swx * Swy) / det
    sse = Swyy - a * Swy - b * Swxy
    return sse, a, b, Sw / det


def _hinges(Y: np.ndarray, w: np.ndarray) -> np.ndarray:
    """(B, K) the hinge model's profiled log-likelihood at each hinge k = 0 .. n - MIN_SIDE - 1, every k at
    once: the sums over the flights after k (x_i = i - k there, 0 before) from suffix sums of w, w i, w i^2,
    w y and w y i."""
    n = Y.shape[1]
    i = np.arange(n, dtype=float)
    wy = w * Y[:, None, :]

    def after(a):                            # sums over the flights from index j on, for every j
        return np.cumsum(a[..., ::-1], axis=-1)[..., ::-1]
    k = np.arange(0, n - MIN_SIDE, dtype=float)
    j = k.astype(int) + 1
    W, WI, WII = after(w)[..., j], after(w * i)[..., j], after(w * i * i)[..., j]
    WY, WYI = after(wy)[..., j], after(wy * i)[..., j]
    Sw, Swy = w.sum(axis=-1)[..., None], wy.sum(axis=-1)[..., None]
    Swyy = (wy * Y[:, None, :]).sum(axis=-1)[..., None]
    Swx, Swxx, Swxy = WI - k * W, WII - 2.0 * k * WI + k * k * W, WYI - k * WY
    det = Sw * Swxx - Swx ** 2
    a = (Swxx * Swy - Swx * Swxy) / det
    b = (Sw * Swxy - Swx * Swy) / det
    sse = Swyy - a * Swy - b * Swxy
    return (0.5 * (np.log(w).sum(axis=-1)[..., None] - sse)).max(axis=1)


def _search(Y, w, hinge: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    null = _null(Y, w)
    st = 2.0 * (_steps(Y, w) - null[:, None])
    hi = 2.0 * (_hinges(Y, w) - null[:, None]) if hinge else None
    best = st.max(axis=1) if hi is None else np.maximum(st.max(axis=1), hi.max(axis=1))
    return best, st, hi


def _seed(y: np.ndarray) -> int:
    return int.from_bytes(hashlib.sha256(np.ascontiguousarray(y, dtype=float).tobytes()).digest()[:8], "little")


class Fit:
    """One series fitted (`change`: its best split) and able to draw its null (`null`)."""

    def __init__(self, y, se, hinge: bool = False):
        self.y = np.asarray(y, dtype=float)
        self.s2 = np.nan_to_num(np.asarray(se, dtype=float), nan=0.0) ** 2
        self.hinge = hinge
        self.change = _fit(self.y, self.s2, hinge, self) if self.y.size >= MIN_FLIGHTS else None

    def null(self, rng: np.random.Generator, b: int) -> np.ndarray:
        """(b,) the statistic of b series drawn from the no-change fit (the module's docstring)."""
        c = self.change
        Y = c.level + np.sqrt(self.s2 + c.tau_null ** 2) * rng.standard_normal((b, self.y.size))
        return _search(Y, self.w, self.hinge)[0]


def _fit(y: np.ndarray, s2: np.ndarray, hinge: bool, into: Fit) -> Change:
    n = y.size
    tau2 = _grid(y, s2)
    w = into.w = _weights(s2, tau2)                                # (G, n)
    best, st, hi = _search(y[None, :], w, hinge)
    lr = float(best[0])
    ll = 0.5 * np.log(w).sum(axis=1)
    sw = w.sum(axis=1)
    m0 = (w * y).sum(axis=1) / sw
    g0 = int(np.argmax(ll - 0.5 * (w * (y - m0[:, None]) ** 2).sum(axis=1)))
    use_hinge = hi is not None and hi.max() > st.max()
    prof = (hi if use_hinge else st)[0]
    ks = np.arange(0, n - MIN_SIDE) if use_hinge else np.arange(MIN_SIDE, n - MIN_SIDE + 1)
    j = int(np.argmax(prof))
    k = int(ks[j])
    inside = ks[prof >= prof[j] - LR_SET]
    if use_hinge:
        x = np.maximum(0.0, np.arange(n) - k).astype(float)
        sse, a, b, var_b = _hinge_fit(y[None, :], w, x)
        g = int(np.argmax(ll - 0.5 * sse[0]))
        size, size_se = float(b[0, g]), float(np.sqrt(np.broadcast_to(var_b, b.shape)[0, g]))
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
    return Change(lr, "hinge" if use_hinge else "step", k + shift, (int(inside.min()) + shift, int(inside.max()) + shift),
                  size, size_se, before, after, float(np.sqrt(tau2[g])), n, float(m0[g0]), float(np.sqrt(tau2[g0])))


def calibrate(fits: list[Fit], draws: int = DRAWS) -> tuple[float, int]:
    """(p-value, draws) of a finding made of `fits` (each with a change): its statistic the largest of their
    LRs, its null the largest of theirs drawn together from their no-change fits, drawn in batches until
    STOP reach the statistic or `draws` are done (the module's docstring). The generator is seeded from
    the data: the same series give the same p-value."""
    fits = [f for f in fits if f.change is not None]
    lr = max(f.change.lr for f in fits)
    rng = np.random.default_rng(_seed(np.concatenate([f.y for f in fits])))
    exceed = done = 0
    while done < draws:
        b = min(BATCH, draws - done)
        top = np.max([f.null(rng, b) for f in fits], axis=0)
        exceed += int((top >= lr - 1e-9).sum())
        done += b
        if exceed >= STOP:
            return exceed / done, done
    return (1 + exceed) / (draws + 1), done


def test(y, se, hinge: bool = False, draws: int = DRAWS) -> Change | None:
    """The change test of one series, a finding of its own (the module's docstring); None when it has
    fewer than MIN_FLIGHTS values. `se` None or NaN: no standard error (tau then holds all the scatter)."""
    f = Fit(y, se, hinge)
    if f.change is not None:
        f.change.p, f.change.draws = calibrate([f], draws)
    return f.change


def correct(changes: list, alpha: float = ALPHA) -> list[bool]:
    """Holm's step-down over the tested findings (anything with a `p`; None: not tested): each one's
    adjusted p-value set, and whether it is named (adjusted p below alpha)."""
    idx = [i for i, c in enumerate(changes) if c is not None]
    order = sorted(idx, key=lambda i: changes[i].p)
    m = len(order)
    running = 0.0
    for rank, i in enumerate(order):
        running = max(running, min(1.0, (m - rank) * changes[i].p))
        changes[i].p_adjusted = running
    return [c is not None and c.p_adjusted < alpha for c in changes]
