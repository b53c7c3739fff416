"""The candidate framework of diagnose: what a candidate is, and the two ways of fitting one.

The candidates themselves live beside their plant effects, one module per cause, in
`flightctl.sim.causes` (the registry); this module does not import them.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from flightctl.sim.diagnose.dataset import N_BLOCKS, Change, DataSet
from flightctl.sim.diagnose.scoring import (Score, Significance, fitted, heldout, heldout_linear,
                                                     linear_stats, solve)
from flightctl.sim.world.model import Effect

MIN_TIMING_PERIODS = 1.5  # lag or delay shorter than this many loop periods is not named
REFINE_XATOL = 3e-3       # a grid fit's refinement stops within this share of the neighbours' interval
COARSE_STRIDE = 4         # a grid fit computes every 4th point first, then walks to the best (GridCandidate.run)
# The physical range of a rotor's timing (lag or delay): docs/as-flown.md's motor time constants run from
# 20 ms (INDIflight's 3-inch rotors, bench) to 192 ms (the open-loop estimate with Table 2's rotor inertia;
# 170 ms measured for a 920 KV motor with a 9.4-inch propeller on an open-loop ESC); ESC and loop delays
# are a few ms to tens of ms. The search covers 0-300 ms; a fit at its end is no timing of a rotor.
MAX_TIMING_S = 0.3


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
    note: str | None = None                # why a significant-looking result is not named, if it is not
    not_physical: str | None = None        # why its size cannot be this vehicle's (`Candidate.physical`)

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
                  and its `required` names the parameters the fit reports (docs/measured-data.md);
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
      `physical(result) -> str | None`  why the fitted size cannot be this vehicle's, checked against
                  the log's own data or a published range (`physical_check` says which, with its
                  source): a significant candidate that fails it "fits, but is not physical" and is
                  not named;
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
    changes_thrust = False   # its `fold` changes the base model (the thrusts, their scales, the rotors'
                             # positions) rather than adding a term to it: folded first
    dynamic = False          # it needs the commands logged faster than the dynamics it times (dataset.DYNAMIC_MIN_HZ)
    physical_check = ""      # what size is physical, and its source (docs/diagnose.md, "Physical checks")
    needs_yaw = False        # it is told from the others by the yaw channel alone: not judged on a vehicle
                             # whose yaw effectiveness the log cannot identify (basemodel.yaw_identified)
    # the chain of causes (diagnose/verdict.py) reads these: `twin`, the cause that is the same physical
    # effect modelled another way (once one is in the chain the other is not tried); `times_actuation`, it
    # times the actuation (the gyro's timing of the report); `lookalikes`, the causes it is swapped with
    # once the others are in the model (`verdict._swap`), tried in this order
    twin: str | None = None
    times_actuation = False
    lookalikes: tuple[str, ...] = ()
    needs_accelerometer = False  # it predicts the accelerometer's channels alone: not judged on a log without one
                                 # (FileData.accel; its gain there would be exactly 0, not a verdict)

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

    def physical(self, result: Result) -> str | None:
        """Why the fitted size cannot be this vehicle's, or None (`physical_check`)."""
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

    def thrusts(self, parameters: dict) -> list[np.ndarray] | None:
        """A cause that changes the rotors' thrusts in time: the per-file drives (K, 4, n) at
        `parameters` (`DataSet.drive`: each component goes through the same change)."""
        return None

    def scales(self, parameters: dict) -> list | None:
        """A cause that scales each rotor's thrust and torque: the per-file scales ((4, n), (n,) or
        a number) at `parameters`."""
        return None

    def fold(self, parameters: dict) -> None:
        """Put this cause at `parameters` into the data set's base model (the chain of causes): the
        thrusts or scales it changes, else its change of the prediction as a carried term."""
        D, S = self.thrusts(parameters), self.scales(parameters)
        if S is not None:
            S = [s * t for s, t in zip(self.ds.S, S)]
        if D is not None or S is not None:
            self.ds.rebase(D, S)
        else:
            self.ds.carry(self.cause, parameters, self.predict(parameters))


def too_short_to_time(result: Result, ds: DataSet) -> str | None:
    """`not_named` of a lag or delay: one shorter than MIN_TIMING_PERIODS loop periods."""
    v = next(iter(result.parameters.values()))
    if v < MIN_TIMING_PERIODS / ds.fs:
        return (f"{result.cause}: {v * 1e3:.1f} ms is within {MIN_TIMING_PERIODS:g} loop periods, the timing "
                f"uncertainty of a log (sensor filters, when in the period the sample is taken): not named")
    return None


TIMING_CHECK = (f"a lag or delay of 0-{1e3 * MAX_TIMING_S:.0f} ms: motor time constants of 20-192 ms "
                "(docs/as-flown.md: INDIflight's bench, the open-loop estimate with Table 2's rotor inertia, a "
                "measured 9.4-inch rotor) and ESC delays of a few ms")


def timing_not_physical(result: Result, why: str = "no rotor's lag or delay is that long (the commands and the "
                                                     "motion the log shows do not match in time)") -> str | None:
    """`physical` of a lag or delay: one at or beyond MAX_TIMING_S (the end of the search), and `why` not."""
    v = next(iter(result.parameters.values()))
    if v >= MAX_TIMING_S * 0.995:
        return f"{v * 1e3:.0f} ms is at the end of the 0-{1e3 * MAX_TIMING_S:.0f} ms search: {why}"
    return None


def columns_of(change: Change, own=()) -> np.ndarray | None:
    """(C, n, P) free columns of a fit: the candidate's own (each (C, n)), then the change's (the
    identified vehicle's effectiveness at the candidate's thrusts); None when there are none."""
    cols = list(own) + list(change.free)
    return np.stack(cols, axis=-1) if cols else None


class GridCandidate(Candidate):
    """One nonlinear parameter: predictions on a grid, folds choose the best grid point, the
    full-data fit is refined between the best point's neighbours by a bounded scalar search.
    Implement `delta(theta) -> Change` (`DataSet.delta_filtered` of the per-file predictions) or a
    filtered (C, n) change of the prediction at parameter theta."""
    grid: np.ndarray = np.array([])
    round_to = 4
    cached = False    # its change of the prediction depends on the base model alone, not on the carried terms

    @property
    def name(self) -> str:
        (name,) = self.effect.required
        return name

    def change(self, theta) -> Change:
        d = self.delta(theta)
        return d if isinstance(d, Change) else Change(d, self.ds.base_free)

    def _kept_change(self, theta, keep: bool) -> Change:
        """`change(theta)` from the data set's store of its model (`DataSet.changes`), or computed,
        and stored when `keep` (the grid's points): a candidate whose change depends on the base
        model alone (`cached`) finds it there in every later round whose model only carries more
        terms, and in the backfit's fits on top of carried causes (docs/diagnose.md, "Speed")."""
        key = (self.cause, float(theta))
        kept = self.ds.changes.get(key)
        if kept is not None:
            delta, live, rows = kept
            free = np.zeros(live.shape + delta.shape[-1:])
            free[live] = rows
            return Change(delta, free)
        ch = self.change(theta)
        if keep:
            live = np.any(ch.free != 0.0, axis=-1)       # most free columns act in one channel or two
            self.ds.changes[key] = (ch.delta, live, ch.free[live])
        return ch

    def design(self, theta, keep: bool = False):
        """(e, A): the residual before the free columns, and the free columns, at theta."""
        ch = self._kept_change(theta, keep) if self.cached else self.change(theta)
        return self.r_base - ch.delta, columns_of(ch)

    def objective(self, theta, keep=None) -> float:
        e, A = self.design(theta)
        keep = np.ones(N_BLOCKS, bool) if keep is None else keep
        return solve(linear_stats(self.ds, e, A), keep, self.ds.block_counts)[0]

    def predict(self, parameters):
        return self.change(float(parameters[self.name])).delta

    def delta(self, theta):
        raise NotImplementedError

    def _best(self, j: int) -> float:
        """The full-data fit refined between grid point j (its best) and its neighbours."""
        from scipy import optimize   # here, not at the top: `flightctl sim` imports the causes for their effects
        g = self.grid
        if 0 < j < len(g) - 1:
            lo, hi = g[j - 1], g[j + 1]
            try:
                res = optimize.minimize_scalar(self.objective, bounds=(lo, hi), method="bounded",
                                               options={"xatol": (hi - lo) * REFINE_XATOL})
                return float(res.x)
            except ValueError:
                return float(g[j])
        return float(g[j])

    def run(self) -> Result:
        """Each fold's grid point (the best on its training blocks) and the full data's, found coarse
        to fine: every COARSE_STRIDE-th point first, then from the best of those a walk to the nearest
        grid point that neither neighbour beats (docs/diagnose.md, "Speed"). Over an objective with
        one minimum along the grid that is the grid's best point, found with a third to a half of
        the designs (each a pass over the log at its full rate); the grid's other points are not
        computed."""
        ds = self.ds
        stats: dict[int, object] = {}     # grid index -> the block sums of its design
        blocks = np.arange(N_BLOCKS)
        masks = [blocks != b for b in blocks] + [np.ones(N_BLOCKS, bool)]     # the folds, then all data
        fits: dict[tuple[int, int], tuple] = {}

        def fit(m, j):
            if j not in stats:
                stats[j] = linear_stats(ds, *self.design(self.grid[j], keep=True))
            if (m, j) not in fits:
                fits[m, j] = solve(stats[j], masks[m], ds.block_counts)
            return fits[m, j]

        last = len(self.grid) - 1
        for j in sorted(set(range(0, last + 1, COARSE_STRIDE)) | {last}):
            fit(len(masks) - 1, j)
        best = []
        for m in range(len(masks)):
            key = lambda j: (fit(m, j)[0], j)      # ties: the lower point, as np.argmin
            j = min(list(stats), key=key)
            while True:
                k = min([i for i in (j - 1, j, j + 1) if 0 <= i <= last], key=key)
                if k == j:
                    break
                j = k
            best.append(j)
        chosen = [(best[b], fits[b, best[b]]) for b in blocks]     # each fold's grid point and fit
        folds = [float(self.grid[j]) for j, _ in chosen]
        pieces = {}                       # each grid point's design computed once, for every fold that chose it
        for j in sorted({j for j, _ in chosen}):
            e, A = self.design(self.grid[j])
            for b, (jb, fit_b) in enumerate(chosen):
                if jb == j:
                    i0, i1 = ds.block_edges[b]
                    pieces[b] = fitted(e[:, i0:i1], None if A is None else A[:, i0:i1], fit_b[1]), fit_b[2]
        score = heldout(ds, pieces.__getitem__)
        allb = np.ones(N_BLOCKS, bool)
        theta = self._best(best[-1])
        e, A = self.design(theta)
        coef = solve(linear_stats(ds, e, A), allb, ds.block_counts)[1]
        return Result(self.cause, {self.name: round(theta, self.round_to)}, score, fitted(e, A, coef),
                      explains=self.explains, folds=folds)


class AffineCandidate(Candidate):
    """Prediction change D = G0 + sum_p theta_p G_p with filtered columns: weighted least squares,
    each channel weighted by the inverse of its residual variance (three reweighting passes), with
    the offset channels centred on the training data, beside the base model's free columns.
    Implement `columns()`, and `to_parameters` and `from_parameters` when the parameters are not
    the thetas themselves."""

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

    def linear_run(self, G0, Gs) -> tuple[Score, np.ndarray, np.ndarray, list]:
        """(held-out score, full-data thetas of Gs, full-data residual, per-fold thetas) of the fit
        of the columns Gs (with the base model's free columns) to r_base - G0."""
        ds = self.ds
        e = self.r_base if G0 is None else self.r_base - G0
        A = columns_of(Change(None, ds.base_free), Gs)
        st = linear_stats(ds, e, A)
        folds = []
        score = heldout_linear(ds, e, A, st, record=lambda th: folds.append(th[:len(Gs)]))
        theta = solve(st, np.ones(N_BLOCKS, bool), ds.block_counts)[1]
        return score, theta[:len(Gs)], fitted(e, A, theta), folds

    def run(self) -> Result:
        G0, Gs = self.columns()
        score, theta, residual, folds = self.linear_run(G0, Gs)
        return Result(self.cause, self.to_parameters(theta), score, residual, explains=self.explains,
                      folds=[self.to_parameters(th) for th in folds])
