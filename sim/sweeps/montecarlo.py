"""`flightctl sim SCENARIO --monte-carlo N [--params P] [--seed S] [--json MC.json] [--plot MC.png]`:
the flight over the parameter file's plausible ranges instead of at its nominal point.

Each of the N draws takes every ranged parameter of the file (`range.NAME = [lo, hi]`: of the airframe,
at the file's top, of its [filters] and [sensors], and of its `[[effect]]` tables;
flightctl/vehicles/paper-as-flown.toml: the airframe's constants of eq. 26-28 and its rotor inertia, the
D term's rate filter, the rotors' vibration and the gyro's broadband noise, the motor time constants,
the rotor drag, the inflow and hub damping, the delay chain) from its range (`draw`: a seeded generator,
uniform, or uniform in the logarithm where the schema says so; a motor time constant's top follows
the drawn rotor inertia), and flies the scenario with both gain sets on that same vehicle (a paired
comparison), through the full onboard path with sensor noise. A draw is the vehicle: its plant and its
controller take the drawn values (the controller uses eq. 26's h1 and h2, which the paper identified
on its bench, and its own rate filter). Per gain set it reports the share that flies (leaves the
ground, does not crash, lands upright), the share that settles (every bank within 1 degree and turn
within 3 degrees of its command from 3 s after the step to the next: `metrics.settles`), and what the
paper judged (sim/sweeps/judge.py: ringing, damping, the held error apart from the estimator's bias);
paired, draw by draw, the share where Table 6 beats Table 4 and the share where the paper's account
holds (Table 4 flies, Table 6 flies and beats it), and a figure of which ranges decide it
(`plot_deciding`). Flights run on the engine (sim/engine.py: Dask, one worker per core).

`--batch` flies the draws on the batched simulator instead (sim/sweeps/batch.py: the compiled per-vehicle
loop, thousands of vehicles a minute): draw k's vehicle with seed + k, as the full path flies it (the
same chip, noise, sonar, take-off, controller and landing: the same flight to rounding), judged the same way.
"""
from __future__ import annotations

import dataclasses
import json
import math
import os
from pathlib import Path

from flightctl.errors import InputError
from flightctl.params import GAIN_SETS
from flightctl.sim import engine

GAINS = ("table4", "table6")


AIRFRAME = "airframe"   # the "cause" of a ranged airframe value (`range.Jp = [lo, hi]` at the file's top)
TABLES = ("filters", "sensors")   # and of a ranged value of these tables (`range.NAME` inside them)


def ranged(params) -> list[tuple[str, str, float, float]]:
    """(cause, parameter, lo, hi) of every range the parameter file carries: its airframe's, its
    tables', then its effects'."""
    return [(AIRFRAME, name, lo, hi) for name, lo, hi in params.ranges] + list(params.table_ranges) + \
        [(e.cause, name, lo, hi) for e in params.effects for name, lo, hi in e.ranges]


def _logarithmic(params, cause: str, name: str) -> bool:
    """The schema draws this value uniformly in its logarithm (`log=True`, flightctl/params.py)."""
    if cause not in (AIRFRAME, *TABLES):
        return False
    obj = params.airframe if cause == AIRFRAME else getattr(params, cause)
    return next(f for f in dataclasses.fields(obj) if f.name == name).metadata.get("log", False)


def draw(params, n: int, seed: int = 0) -> dict:
    """n draws of every ranged parameter, (cause, parameter) -> (n,) array, each uniform in its range
    (in its logarithm where the schema says so), except where an effect's range follows a drawn
    airframe value (`Effect.range_scales`: the motor time constants' slowest plausible value is
    proportional to the rotor inertia Jp): its top is then hi * value / (the value's own top), never
    below its bottom. Seeded: the same draws every time."""
    import numpy as np

    from flightctl.sim import causes
    rng = np.random.default_rng(seed)
    spans = ranged(params)
    u = {(c, name): rng.uniform(0.0, 1.0, n) for c, name, _, _ in spans}
    out = {}
    for c, name, lo, hi in spans:
        if c in (AIRFRAME, *TABLES):
            if _logarithmic(params, c, name) and lo > 0.0:
                out[(c, name)] = lo * (hi / lo) ** u[(c, name)]
            else:
                out[(c, name)] = lo + u[(c, name)] * (hi - lo)
    tops = {name: hi for c, name, _, hi in spans if c == AIRFRAME}
    for c, name, lo, hi in spans:
        if c not in (AIRFRAME, *TABLES):
            scale = causes.CAUSES[c].effect.range_scales.get(name)
            if scale in tops:
                hi = np.maximum(lo, hi * out[(AIRFRAME, scale)] / tops[scale])
            out[(c, name)] = lo + u[(c, name)] * (hi - lo)
    return out


def one_draw(draws: dict, k: int) -> dict:
    """Draw k of `draw`'s arrays: (cause, parameter) -> a float."""
    return {key: float(v[k]) for key, v in draws.items()}


def drawn_airframe(airframe, draws: dict):
    """The airframe with its drawn values: one draw's floats (`one_draw`), or all (arrays, the batch)."""
    values = {name: v for (c, name), v in draws.items() if c == AIRFRAME}
    return dataclasses.replace(airframe, **values) if values else airframe


def drawn_params(params, drawn: dict, effects: bool = True):
    """The vehicle of one draw (floats): the parameter file with its airframe, its tables and (unless
    not `effects`: the batch draws them as arrays, `batch.with_draws`) its effects' parameters at their
    drawn values."""
    from flightctl.params import EffectSpec
    tables = {t: dataclasses.replace(getattr(params, t), **{n: v for (c, n), v in drawn.items() if c == t})
              for t in TABLES}
    if effects:
        tables["effects"] = tuple(EffectSpec(e.cause, tuple((k, drawn.get((e.cause, k), v)) for k, v in e.parameters),
                                             e.source, e.ranges) for e in params.effects)
    return dataclasses.replace(params, airframe=drawn_airframe(params.airframe, drawn), **tables)


def _fly(job: tuple) -> dict:
    """One flight (in a worker process): job = (params spec, scenario, gain set, draw, seed)."""
    from flightctl.sim import causes
    from flightctl.sim.flights.metrics import settles
    from flightctl.sim.flights.run import fly
    from flightctl.sim.flights.scenarios import SCENARIOS
    from flightctl.sim.sweeps import judge
    from flightctl.sim.world import faults
    spec, scenario, gains, drawn, seed, injected = job
    params = drawn_params(causes.load_vehicle(spec, GAIN_SETS[gains]), drawn)
    sc = SCENARIOS[scenario]()
    flight = fly(sc, params, os.devnull, seed=seed, faults=[faults.parse(f) for f in injected])
    flies = bool(flight.flew and not flight.crashed and flight.outcome == "landed upright")
    settled = flies and settles(flight.log, sc.steps, flight.t_arm)
    figures = judge.summary(judge.step_figures(flight.log, sc.steps, flight.t_arm)) if flies else {"score": None}
    return {"gains": gains, "flies": flies, "lands": flight.outcome == "landed upright", "settles": bool(settled),
            "outcome": flight.outcome, **figures}


def run(spec: str | None, scenario: str, n: int, seed: int = 0, progress=None, jobs: int | None = None,
        faults: tuple[str, ...] = ()) -> dict:
    """The module docstring's Monte Carlo; `progress`: a sim/progress.py Progress, one step a flight;
    `faults`: `--fault` texts flown on every draw (sim/world/faults.py; the loop's lateness)."""
    from flightctl.sim import causes
    params = causes.load_vehicle(spec)
    spans = ranged(params)
    if not spans:
        raise InputError(f"--monte-carlo: {spec or 'the reference airframe'} carries no ranges "
                         "(range.NAME = [lo, hi] in its [[effect]] tables; --params paper-as-flown has them)")
    drawn = draw(params, n, seed)
    draws = [one_draw(drawn, i) for i in range(n)]
    jobs_list = [(spec, scenario, g, d, seed + k, tuple(faults)) for k, d in enumerate(draws) for g in GAINS]

    def done(k: int, r: dict) -> None:          # as each flight finishes (sim/engine.py)
        job = jobs_list[k]
        progress.step(f"{job[2]}: " + ", ".join(f"{c}.{n} {v:.4g}" for (c, n), v in job[3].items())
                 + f": {r['outcome']}{', settles' if r['settles'] else ''}"
                 + (f", score {r['score']:.2f}" if r.get("score") is not None else ""))
    results = engine.run(_fly, jobs_list, jobs, done if progress is not None else None)
    rows = [{"draw": {f"{c}.{name}": v for (c, name), v in d.items()},
             **{g: results[2 * k + j] for j, g in enumerate(GAINS)}} for k, d in enumerate(draws)]
    return _result(spec, scenario, n, seed, spans, rows, **({"faults": list(faults)} if faults else {}))


def _result(spec, scenario, n, seed, spans, rows, **extra) -> dict:
    """The report of a Monte Carlo: the shares per gain set, and paired, draw by draw, the verdicts."""
    from flightctl.sim.sweeps import judge
    for r in rows:
        r.update(judge.verdict(r["table4"], r["table6"]))
    share = {g: {what: sum(r[g][what] for r in rows) / n for what in ("flies", "lands", "settles")} for g in GAINS}
    paired = {"table6 settles, table4 not": sum(r["table6"]["settles"] and not r["table4"]["settles"] for r in rows),
              "table4 settles, table6 not": sum(r["table4"]["settles"] and not r["table6"]["settles"] for r in rows),
              "table6 beats table4": sum(r["table6 beats table4"] for r in rows) / n,
              "paper's account": sum(r["paper's account"] for r in rows) / n}
    return {"scenario": scenario, "params": spec or "reference airframe", "n": n, "seed": seed, **extra,
            "ranges": [{"cause": c, "parameter": name, "lo": lo, "hi": hi} for c, name, lo, hi in spans],
            "share": share, "paired": paired, "draws": rows}


def _batch_window(sc) -> tuple[float, float, list]:
    """(start, end, attitude steps) of a scenario's judged span: from 1 s after its take-off ramp to the
    end of its last attitude step's window."""
    steps = [st for st in sc.steps if st.channel != "alt"]
    if not steps:
        raise InputError(f"--batch: the scenario {sc.name} has no attitude steps to judge")
    start = max((m.t + m.ramp for m in sc.plan.moves if m.channel == "alt" and m.t == 0.0), default=0.0) + 1.0
    steps = [st for st in steps if st.t >= start]
    return start, max(st.t + st.window for st in steps) + 0.05, steps


def run_batch(spec: str | None, scenario: str, n: int, seed: int = 0, progress=None, workers: int | None = None) -> dict:
    """The draws flown on the batched simulator (sim/sweeps/batch.py): draw k with seed + k, the vehicle
    `run` flies, both gain sets, judged as `_fly` judges (flies, lands, settles, the paper's figures). `progress`: a
    sim/progress.py Progress, one step a gain set, the vehicles in between."""
    from flightctl.sim import causes
    from flightctl.sim.flights.scenarios import SCENARIOS
    params = causes.load_vehicle(spec)
    spans = ranged(params)
    if not spans:
        raise InputError(f"--monte-carlo: {spec or 'the reference airframe'} carries no ranges")
    draws = draw(params, n, seed)
    rows = batch_rows(params, SCENARIOS[scenario](), draws, [seed + k for k in range(n)], progress, workers)
    return _result(spec, scenario, n, seed, spans, rows,
                   simulator="batched simulator (sim/sweeps/batch.py): each draw's vehicle flown as the full onboard "
                             "path flies it, from power-on to its landing, compiled")


def batch_rows(params, sc, draws: dict, seeds: list[int], progress=None, workers: int | None = None,
               structure: str = "flight") -> list[dict]:
    """The Monte Carlo's rows of `draws` ((cause, parameter) -> (n,) arrays) of `params` flown on the
    batched simulator with both gain sets (vehicle k with seeds[k]; `structure` the estimator's), each
    gain set's flights judged as `_fly` judges them (flies, lands, settles, judge.summary's figures)."""
    import numpy as np

    from flightctl.sim.flights.metrics import settles
    from flightctl.sim.sweeps import judge
    from flightctl.sim.sweeps.batch import simulate
    n = len(seeds)
    steps = [st for st in sc.steps if st.channel != "alt"]
    record = (min(st.t for st in steps) - 0.05, max(st.t + st.window for st in steps) + 0.05) if steps else None
    out = {}
    for g in GAINS:
        frac = (lambda f, g=g: progress.update(f, f"{g}: {n} vehicles")) if progress is not None else None
        flight = simulate(dataclasses.replace(params, gains=GAIN_SETS[g]), sc.plan, n, draws, seeds=seeds,
                          record=record, workers=workers or os.cpu_count() or 1, progress=frac, structure=structure)
        flies = flight.flies
        settled = settles(flight.log, sc.steps, 0.0) & flies if steps else flies
        figures = judge.step_figures(flight.log, sc.steps, 0.0) if steps else []
        out[g] = (flight, flies, settled, figures)
        if progress is not None:
            progress.step(f"{g}: {n} vehicles, {flight.vehicle_steps / 1e6:.1f} M vehicle-steps")
    rows = []
    for k in range(n):
        row = {"draw": {f"{c}.{name}": float(v[k]) for (c, name), v in draws.items()}}
        for g in GAINS:
            flight, flies, settled, figures = out[g]
            mine = [{key: (v[k] if isinstance(v, np.ndarray) and v.ndim else v) for key, v in f.items()} for f in figures]
            row[g] = {"gains": g, "flies": bool(flies[k]), "lands": flight.outcome[k] == "landed upright",
                      "settles": bool(settled[k]), "outcome": flight.outcome[k],
                      **(judge.summary(mine) if flies[k] and mine else {"score": None})}
        rows.append(row)
    return rows


def summary(result: dict) -> str:
    lines = [f"{result['scenario']} over {result['n']} draws of {result['params']}'s ranges "
             + ", ".join(f"{r['cause']}.{r['parameter']} [{r['lo']:.4g}, {r['hi']:.4g}]" for r in result["ranges"])]
    if "simulator" in result:
        lines.append(f"  on the {result['simulator']}")
    for g, s in result["share"].items():
        lands = f"lands upright {100 * s['lands']:.0f} %, " if "lands" in s else ""
        lines.append(f"  {g}: flies {100 * s['flies']:.0f} %, {lands}settles {100 * s['settles']:.0f} %")
    p = result["paired"]
    account = p["paper's account"]
    lines.append(f"  paired: table6 settles, table4 not: {p['table6 settles, table4 not']}; "
                 f"table4 settles, table6 not: {p['table4 settles, table6 not']}")
    lines.append(f"  paired, as the paper judged (ringing, sim/sweeps/judge.py): table6 beats table4 in "
                 f"{100 * p['table6 beats table4']:.0f} %; the paper's account (both hold within "
                 f"sec. 3.3's bound, table6 better) holds in {100 * account:.0f} %")
    return "\n".join(lines)


def plot(result: dict, path: str | Path) -> None:
    """The outcome of each draw over the first two ranged parameters, one panel per gain set."""
    from flightctl.sim.plots import figure, legend, save
    # the motor time constant against the delay where both are drawn, else against the next ranged term
    keys = sorted(result["draws"][0]["draw"], key=lambda k: (not k.endswith(".tau"), not k.endswith(".delay"))) \
        if result["draws"] else []
    fig, ax = figure(1, len(GAINS), size=(12.0, 5.0))
    for j, g in enumerate(GAINS):
        a = ax[0, j]
        for label, colour, pick in (("settles", "tab:green", lambda r: r["settles"]),
                                    ("flies, rings", "tab:orange", lambda r: r["flies"] and not r["settles"]),
                                    ("crashes", "tab:red", lambda r: not r["flies"])):
            pts = [r["draw"] for r in result["draws"] if pick(r[g])]
            if pts and keys:
                x = [p[keys[0]] for p in pts]
                y = [p[keys[1]] if len(keys) > 1 else 0.0 for p in pts]
                a.plot(x, y, "o", color=colour, ms=5 if len(result["draws"]) <= 200 else 2, label=f"{label} ({len(pts)})")
        a.set_xlabel(keys[0] if keys else "")
        a.set_ylabel(keys[1] if len(keys) > 1 else "")
        s = result["share"][g]
        a.set_title(f"{g}: flies {100 * s['flies']:.0f} %, settles {100 * s['settles']:.0f} %")
        a.grid(alpha=0.3)
        legend(a)
    fig.suptitle(f"flightctl sim {result['scenario']} --monte-carlo {result['n']} --params {result['params']}"
                 + (" --batch" if "simulator" in result else ""))
    save(fig, path)


def write_json(result: dict, path: str | Path) -> None:
    from flightctl.files import write_atomic
    write_atomic(path, json.dumps(result, indent=1) + "\n")


VERDICTS = ("paper's account", "table6 beats table4")


def _position(result: dict, key: str, v: float) -> float:
    """Where v lies in its range, 0 to 1 (in its logarithm where the range spans a decade or more and
    starts above 0: drawn so, or its top follows a drawn value)."""
    r = next(r for r in result["ranges"] if f"{r['cause']}.{r['parameter']}" == key)
    lo, hi = r["lo"], r["hi"]
    if lo > 0.0 and hi / lo >= 10.0:
        return math.log(v / lo) / math.log(hi / lo)
    return (v - lo) / (hi - lo) if hi > lo else 0.5


def deciding(result: dict, what: str = "paper's account") -> list[tuple[str, float, float, int, int]]:
    """Which ranges decide `what` (a paired verdict): per ranged parameter, the share of the draws in
    the lower and in the upper half of its range where it holds, and the two counts; largest
    difference first."""
    rows = result["draws"]
    out = []
    for key in rows[0]["draw"] if rows else ():
        low = [r[what] for r in rows if _position(result, key, r["draw"][key]) < 0.5]
        high = [r[what] for r in rows if _position(result, key, r["draw"][key]) >= 0.5]
        share = lambda xs: sum(xs) / len(xs) if xs else math.nan   # noqa: E731
        out.append((key, share(low), share(high), len(low), len(high)))
    return sorted(out, key=lambda row: -abs(row[2] - row[1]) if row[1] == row[1] and row[2] == row[2] else 0.0)


def plot_deciding(result: dict, path: str | Path, bins: int = 4) -> None:
    """Which ranges decide the paper's account: per ranged parameter, the share where it holds in the
    lower and upper half of the range (left); for the four that move it most, the share in `bins`
    bins of the range (right), beside the share where Table 6 beats Table 4."""
    from flightctl.sim.plots import figure, legend, save
    order = deciding(result)
    fig, ax = figure(1, 2, size=(13.0, 0.32 * len(order) + 2.5))
    a = ax[0, 0]
    y = list(range(len(order)))[::-1]
    a.barh([v + 0.2 for v in y], [100 * r[1] for r in order], height=0.4, color="tab:blue", label="lower half of its range")
    a.barh([v - 0.2 for v in y], [100 * r[2] for r in order], height=0.4, color="tab:orange", label="upper half")
    a.set_yticks(y)
    a.set_yticklabels([r[0] for r in order], fontsize=8)
    a.axvline(100 * result["paired"]["paper's account"], color="k", lw=0.8, ls="--", label="all draws")
    a.set_xlabel("draws where the paper's account holds (%)")
    a.grid(alpha=0.3, axis="x")
    legend(a)
    b = ax[0, 1]
    rows = result["draws"]
    for key, colour in zip([r[0] for r in order[:4]], ("tab:red", "tab:green", "tab:purple", "tab:brown")):
        pos = [min(int(_position(result, key, r["draw"][key]) * bins), bins - 1) for r in rows]
        for what, style in zip(VERDICTS, ("-o", ":s")):
            shares = [100 * sum(r[what] for r, p in zip(rows, pos) if p == k) / max(1, pos.count(k)) for k in range(bins)]
            b.plot([(k + 0.5) / bins for k in range(bins)], shares, style, color=colour,
                   label=f"{key}: {what}" if what == VERDICTS[0] else f"{key}: table6 beats table4")
    b.set_xlabel("position in the parameter's range (0 = bottom, 1 = top; in its logarithm where it spans a decade)")
    b.set_ylabel("share of the draws (%)")
    b.set_ylim(-5, 105)
    b.grid(alpha=0.3)
    legend(b)
    fig.suptitle(f"Which ranges decide the paper's account: flightctl sim {result['scenario']} --monte-carlo "
                 f"{result['n']} --params {result['params']}" + (" --batch" if "simulator" in result else ""))
    save(fig, path)
