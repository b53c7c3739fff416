"""The candidate framework of diagnose: what a candidate is, and the two ways of fitting one.

The candidates themselves live beside their plant effects, one module per cause, in
`flightctl.sim.causes` (the registry); this module does not import them.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from flightctl.sim.identify.diagnose.dataset import OFFSET, DataSet
from flightctl.sim.identify.diagnose.scoring import (Score, Significance, block_stats, heldout, objective,
                                                     stats_objective)
from flightctl.sim.model import Effect

MIN_TIMING_PERIODS = 1.5  # lag or delay shorter than this many loop periods is not named


@dataclass
class Result:
    """What a candidate's `run` returns; the verdict adds the significance."""
    cause: str
    parameters: dict
    score: Score | None = None
    residual: np.ndarray | None = None     # fitted on all data, for the report
    explains: str = ""                     # the variable that explains the residual
    explanatory: np.ndarray | None = None
    folds: list = field(default_factory=list)
    significance: Significance | None = None

    @property
    def gain(self) -> float:
        return self.significance.gain

    @property
    def t_stat(self) -> float:
        return self.significance.t_stat


class Candidate:
    """The diagnose side of one cause: fit its parameters to a `DataSet` and score the fit on data
    it was not fitted on. The plug-in contract (copy a module of `flightctl.sim.causes` to add one):

    A subclass sets
      `effect`    the `Effect` subclass of the plant that it fits: its `cause` names the candidate
                  and its `required` names the parameters the fit reports (measured-data.md);
      `explains`  the variable that explains the residual, in words with its unit (report, figure);
    and implements, or inherits from `GridCandidate` or `AffineCandidate`,
      `run() -> Result`  the held-out `Score` (from `scoring.heldout`, whose fold function refits
                  on the training blocks only), the parameters fitted on all data (rounded for the
                  JSON report), and the full-data residual.
    It may override
      `why_not() -> str | None`  a reason the data cannot judge it (listed under `not_judged`,
                  not fitted): the excitation it needs is missing from the logs;
      `not_named(result) -> str | None`  asked only when its score is significant: a reason not
                  to name it all the same (written as a note), such as a size the data cannot
                  tell from nothing or a sign the physics excludes;
      `explanatory() -> (n,) array`  the explaining variable per sample, for the figure;
      `predict(parameters) -> (C, n)`  the filtered change of the prediction at given parameters
                  (the carried effect of a parameter file in the base model; `GridCandidate` and
                  `AffineCandidate` implement it from `delta` or `columns`);
      `why_not_carried() -> str | None`  a reason the logs cannot give that prediction (data it
                  needs are missing): the carried effect is then left out of the base, with a note.

    A prediction change is computed per file from the per-file arrays (`DataSet.predict_file` with
    the candidate's thrusts, scales or extra wrench, or its own columns of the channels) and then
    low-passed with `DataSet.delta_filtered` / `flat_filtered`, so that measurement and prediction
    go through the same filter. The base residual is `DataSet.r_base`; a candidate's residual is
    `r_base` minus its filtered change. `self.r_base` is the base residual this candidate is fitted
    on: `DataSet.r_base`, the base model with the parameter file's effects, except that the term of
    this candidate's own cause, when carried, is taken out: the fitted parameters replace the carried
    ones, and a fit at the carried value is the base model itself.
    """
    effect: type[Effect] = Effect
    explains = ""

    def __init__(self, ds: DataSet):
        self.ds = ds
        self.r_base = ds.base_without(self.cause)
        carried = ds.carried_parameters.get(self.cause)
        grid = getattr(self, "grid", None)
        if carried is not None and grid is not None and len(self.effect.required) == 1:
            # a fit over a grid of its one parameter: the carried value is a grid point, so that a
            # fold may keep the base model as it is
            self.grid = np.union1d(grid, [carried[next(iter(self.effect.required))]])

    @property
    def cause(self) -> str:
        return self.effect.cause

    def why_not(self) -> str | None:
        """A reason the data cannot judge this candidate, or None."""
        return None

    def not_named(self, result: Result) -> str | None:
        """A reason not to name this candidate although it is significant, or None."""
        return None

    def run(self) -> Result:
        raise NotImplementedError

    def explanatory(self) -> np.ndarray | None:
        return None

    def predict(self, parameters: dict) -> np.ndarray:
        """The filtered (C, n) change of the prediction at `parameters` (the effect's own names)."""
        raise NotImplementedError

    def why_not_carried(self) -> str | None:
        """A reason the logs cannot give this cause's prediction, or None."""
        return None


def too_short_to_time(result: Result, ds: DataSet) -> str | None:
    """`not_named` of a lag or delay: one shorter than MIN_TIMING_PERIODS loop periods."""
    v = next(iter(result.parameters.values()))
    if v < MIN_TIMING_PERIODS / ds.fs:
        return (f"{result.cause}: {v * 1e3:.1f} ms is within {MIN_TIMING_PERIODS:g} loop periods, the timing "
                f"uncertainty of a log (sensor filters, when in the period the sample is taken): not named")
    return None


class GridCandidate(Candidate):
    """One nonlinear parameter: predictions on a grid, folds choose the best grid point, the
    full-data fit is refined between the best point's neighbours by a bounded scalar search.
    Implement `delta(theta)`: the filtered (C, n) change of the prediction at parameter theta."""
    grid: np.ndarray = np.array([])
    round_to = 4

    @property
    def name(self) -> str:
        (name,) = self.effect.required
        return name

    def residual(self, theta) -> np.ndarray:
        return self.r_base - self.delta(theta)

    def predict(self, parameters):
        return self.delta(float(parameters[self.name]))

    def delta(self, theta) -> np.ndarray:
        raise NotImplementedError

    def _best(self, objs):
        from scipy import optimize   # here, not at the top: `flightctl sim` imports the causes for their effects
        j = int(np.argmin(objs))
        g = self.grid
        if 0 < j < len(g) - 1:
            lo, hi = g[j - 1], g[j + 1]
            try:
                res = optimize.minimize_scalar(lambda th: objective(self.residual(th), self._mask),
                                               bounds=(lo, hi), method="bounded",
                                               options={"xatol": (hi - lo) * 1e-3})
                return float(res.x)
            except ValueError:
                return float(g[j])
        return float(g[j])

    def run(self) -> Result:
        ds = self.ds
        deltas = [self.delta(th) for th in self.grid]
        stats = np.stack([block_stats(ds, self.r_base - d) for d in deltas])    # (J, 2, B, C)
        folds = []

        def fold(train):
            test_block = int(ds.block[~train][0])
            objs = [stats_objective(st, test_block, ds.block_counts) for st in stats]
            j = int(np.argmin(objs))
            folds.append(float(self.grid[j]))
            return self.r_base - deltas[j]

        score = heldout(ds, fold)
        self._mask = np.ones(ds.n, bool)
        objs = [objective(self.r_base - d, self._mask) for d in deltas]
        theta = self._best(objs)
        return Result(self.cause, {self.name: round(theta, self.round_to)}, score, self.residual(theta),
                      explains=self.explains, folds=folds)


class AffineCandidate(Candidate):
    """Prediction change D = G0 + sum_p theta_p G_p with filtered columns: weighted least squares,
    each channel weighted by the inverse of its residual variance (three reweighting passes), with
    the offset channels centred on the training data. Implement `columns()`, and `to_parameters`
    and `from_parameters` when the parameters are not the thetas themselves."""

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(self.effect.required)

    def columns(self):
        """(G0 (C, n) or None, [G_p (C, n)])"""
        raise NotImplementedError

    def to_parameters(self, theta) -> dict:
        return {n: float(v) for n, v in zip(self.names, theta)}

    def from_parameters(self, parameters: dict) -> list[float]:
        """The thetas of `columns` at the effect's parameters (the inverse of `to_parameters`)."""
        return [float(parameters[n]) for n in self.names]

    def predict(self, parameters):
        G0, Gs = self.columns()
        d = np.zeros_like(self.r_base) if G0 is None else G0.copy()
        for g, th in zip(Gs, self.from_parameters(parameters)):
            d += th * g
        return d

    def fit(self, G0, Gs, mask):
        r = self.r_base[:, mask] - (G0[:, mask] if G0 is not None else 0.0)
        A = np.stack([g[:, mask] for g in Gs], axis=-1)          # (C, n, P)
        r = r - np.where(OFFSET, r.mean(axis=1), 0.0)[:, None]
        A = A - np.where(OFFSET[:, None], A.mean(axis=1), 0.0)[:, None, :]
        w = 1.0 / np.maximum(np.einsum("cn,cn->c", r, r), 1e-300)
        theta = np.zeros(len(Gs))
        for _ in range(3):
            M = np.einsum("c,cnp,cnq->pq", w, A, A)
            h = np.einsum("c,cnp,cn->p", w, A, r)
            theta = np.linalg.lstsq(M, h, rcond=None)[0]
            e = r - A @ theta
            w = 1.0 / np.maximum(np.einsum("cn,cn->c", e, e), 1e-300)
        return theta

    def residual_at(self, G0, Gs, theta):
        res = self.r_base - (G0 if G0 is not None else 0.0)
        for g, th in zip(Gs, theta):
            res = res - th * g
        return res

    def run(self) -> Result:
        ds = self.ds
        G0, Gs = self.columns()
        folds = []

        def fold(train):
            th = self.fit(G0, Gs, train)
            folds.append(self.to_parameters(th))
            return self.residual_at(G0, Gs, th)

        score = heldout(ds, fold)
        theta = self.fit(G0, Gs, np.ones(ds.n, bool))
        return Result(self.cause, self.to_parameters(theta), score, self.residual_at(G0, Gs, theta),
                      explains=self.explains, folds=folds)
