"""The paper's vehicle as its own flights say it was: paper-as-flown's ranges conditioned on the
paper's evidence (sim/sweeps/evidence.py) by rejection ABC (approximate Bayesian computation) on the
batched simulator, and each model term's gain as evidence.

- `run`: n draws of a model's ranges (montecarlo.draw, seeded), each flown on the batched simulator
  (draw k with seed + k, chunk by chunk so that the records stay small) and judged by every
  observation; the draws that pass every informative one are the posterior sample (rejection ABC with
  a zero-one kernel: the tolerances are the observations').
- `marginals`: each range's 5/50/95 % quantiles before (the prior: all draws) and after (the passing
  draws), the posterior's with a bootstrap error.
- `held_out`: per observation, the share of the draws passing all the others that pass it (the
  posterior's prediction of the held-out fact) against the share of all draws that pass it (the
  prior's).
- `models`, `bayes_factor`: the share of a model's prior that passes the evidence is its marginal
  likelihood up to a constant (the zero-one kernel's), so the ratio of two models' shares is their
  Bayes factor; a term's is the model with it against the model without it (its [[effect]] table, the
  [sensors] table at the reference chip, the D path's EMA at 0), a candidate's the model with it
  against the model as it is. Its Monte Carlo error from the two binomial shares (delta method); a
  model that passes none gives a lower bound (the rule of three: its share below 3 / n at 95 %).
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from flightctl.params import TABLE6, Filters, Sensors
from flightctl.sim.sweeps import evidence, montecarlo

CHUNK = 250                 # draws flown together: their judged records stay a few hundred MB
QUANTILES = (0.05, 0.5, 0.95)
BOOTSTRAP = 200             # resamples of the passing draws for a quantile's error
TERMS = ("rotor_inflow", "motor_dynamics", "rotor_drag", "actuation_delay", "sensors", "tau_rate")
# candidates not in the model that the batched simulator carries: (name, estimator structure, what)
CANDIDATES = (("estimator paper", "paper", "sec. 4.4 read literally (`--estimator paper`): the EMA-filtered gyro "
                                           "integrated, the D term differentiating the fused angle"),)
# candidates the batched simulator cannot fly, and why (say so, do not guess their factor)
NOT_MEASURED = (
    ("loop lateness", "the late clock (sim/world/lateness.py, `--fault loop_late`) is the full path's: the batched "
                      "loop ticks on time, and the full path flies about 1/40 of its vehicle-steps a second"),
    ("an ESC's own response", "the `motor_lag` cause (sim/causes/motor_lag.py) is not compiled "
                              "(sim/world/compiled.py COMPILED_CAUSES), so the batch cannot fly it; motor_dynamics "
                              "already carries the rotor's first-order response"),
)


def without(params, term: str):
    """The model without one term: its [[effect]] table (and its ranges), the [sensors] table at the
    reference chip's defaults (Sensors()), or the D path's EMA at 0 (the gyro as the chip gives it)."""
    if term == "sensors":
        return dataclasses.replace(params, sensors=Sensors(),
                                   table_ranges=tuple(r for r in params.table_ranges if r[0] != "sensors"))
    if term == "tau_rate":
        return dataclasses.replace(params, filters=dataclasses.replace(params.filters, tau_rate=Filters().tau_rate),
                                   table_ranges=tuple(r for r in params.table_ranges if r[:2] != ("filters", "tau_rate")))
    if not any(e.cause == term for e in params.effects):
        raise ValueError(f"no term {term} in the model (its effects: {', '.join(e.cause for e in params.effects)})")
    return dataclasses.replace(params, effects=tuple(e for e in params.effects if e.cause != term))


def fly(params, n: int, seed: int, structure: str = "flight", workers: int = 1, progress=None) -> dict:
    """n draws of `params`' ranges flown and judged: {"draws": (cause, parameter) -> (n,) array,
    "verdicts": observation -> (n,) bool, "passes": (n,) bool}. `progress(fraction)`: after each chunk."""
    from flightctl.sim.flights.scenarios import SCENARIOS
    from flightctl.sim.sweeps.batch import simulate
    sc = SCENARIOS["paper"]()
    draws = montecarlo.draw(params, n, seed)
    verdicts = {i: np.zeros(n, dtype=bool) for i in evidence.IDS}
    hover_until = evidence.HOVER_RECORD_S[1] + 0.05
    for a in range(0, n, CHUNK):
        b = min(n, a + CHUNK)
        part = {k: v[a:b] for k, v in draws.items()}
        seeds = [seed + k for k in range(a, b)]
        rows = montecarlo.batch_rows(params, sc, part, seeds, workers=workers, structure=structure)
        hover = simulate(dataclasses.replace(params, gains=TABLE6), sc.plan, b - a, part, seeds=seeds,
                         record=evidence.HOVER_RECORD_S, until=hover_until, workers=workers, structure=structure,
                         wide=True)
        figs = evidence.figures(rows, evidence.hover_figures(hover.log, params.airframe.dt), params.airframe.loop_hz)
        for i, v in evidence.verdicts(figs).items():
            verdicts[i][a:b] = v
        if progress is not None:
            progress(b / n)
    return {"draws": draws, "verdicts": verdicts, "passes": evidence.passes(verdicts)}


def stored(result: dict) -> tuple[dict, dict[str, np.ndarray]]:
    """A stored run's prior draws and verdicts (docs/as-flown-posterior.json: "cause.parameter" -> values, the
    observation -> a string of 0/1) as `montecarlo.draw`'s arrays and `evidence.verdicts`' booleans."""
    draws = {tuple(k.split(".", 1)): np.array(v) for k, v in result["draws"].items()}
    verdicts = {i: np.array([c == "1" for c in s]) for i, s in result["verdicts"].items()}
    return draws, verdicts


def share(k: int, n: int) -> tuple[float, float]:
    """A binomial share and its Monte Carlo (standard) error."""
    p = k / n
    return p, math.sqrt(p * (1.0 - p) / n)


def bayes_factor(k_with: int, n_with: int, k_without: int, n_without: int) -> dict:
    """The Bayes factor of a model with a term against it without, from their passing counts: the ratio
    of the shares and its delta-method error; where the model without passes none, the lower bound
    share_with / (3 / n_without) (rule of three, 95 %)."""
    p1, _ = share(k_with, n_with)
    p0, _ = share(k_without, n_without)
    if k_with == 0 and k_without == 0:
        return {"factor": None, "error": None, "bound": None}
    if k_without == 0:
        return {"factor": None, "error": None, "bound": ">", "value": p1 / (3.0 / n_without)}
    if k_with == 0:
        return {"factor": None, "error": None, "bound": "<", "value": (3.0 / n_with) / p0}
    f = p1 / p0
    rel = math.sqrt((1.0 - p1) / (n_with * p1) + (1.0 - p0) / (n_without * p0))
    return {"factor": f, "error": f * rel, "bound": None}


def marginals(draws: dict, ok: np.ndarray, seed: int = 0) -> list[dict]:
    """Per range: the prior's and the posterior's QUANTILES, the posterior's with their bootstrap error."""
    rng = np.random.default_rng(seed)
    post_n = int(ok.sum())
    out = []
    for (cause, name), v in draws.items():
        prior = np.quantile(v, QUANTILES)
        row = {"range": f"{cause}.{name}", "prior": [float(x) for x in prior], "posterior": None, "error": None}
        if post_n >= 2:
            post = v[ok]
            boot = np.quantile(post[rng.integers(0, post_n, (BOOTSTRAP, post_n))], QUANTILES, axis=1)
            row["posterior"] = [float(x) for x in np.quantile(post, QUANTILES)]
            row["error"] = [float(x) for x in np.std(boot, axis=1)]
        out.append(row)
    return out


def held_out(verdicts: dict[str, np.ndarray]) -> list[dict]:
    """Per informative observation: the prior's share that passes it, and among the draws that pass
    every other one (the posterior conditioned on all but it) the share that passes it."""
    out = []
    for i in evidence.INFORMATIVE:
        given = evidence.passes(verdicts, leave_out=i)
        k_prior, n = int(verdicts[i].sum()), len(verdicts[i])
        n_given = int(given.sum())
        k_given = int((verdicts[i] & given).sum())
        out.append({"observation": i, "prior": [k_prior, n], "posterior": [k_given, n_given]})
    return out


def nearest_median(draws: dict, ok: np.ndarray) -> int:
    """The passing draw nearest the posterior's median: each value's rank among the passing draws (0 to
    1, scale-free), the draw whose ranks lie closest to one half (least squares)."""
    idx = np.nonzero(ok)[0]
    if idx.size == 0:
        raise ValueError("no draw passes the evidence")
    d = np.zeros(idx.size)
    for v in draws.values():
        post = v[idx]
        rank = (np.argsort(np.argsort(post)) + 0.5) / idx.size
        d += (rank - 0.5) ** 2
    return int(idx[int(np.argmin(d))])


def counts(result: dict) -> dict:
    """JSON-ready counts of one model's run: its n and seed, passing draws, and per observation."""
    v, n = result["verdicts"], len(result["passes"])
    return {"n": n, "passed": int(result["passes"].sum()), "observations": {i: int(x.sum()) for i, x in v.items()}}
