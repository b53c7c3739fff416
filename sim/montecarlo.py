"""`flightctl sim SCENARIO --monte-carlo N [--params P] [--seed S] [--json MC.json] [--plot MC.png]`:
the flight over the parameter file's plausible ranges instead of at its nominal point.

Each of the N draws takes every ranged parameter of the file's `[[effect]]` tables (`range.NAME =
[lo, hi]`, flightctl/vehicles/paper-as-flown.toml: the motor time constant, the rotor drag, the
inflow damping) uniformly from its range (a seeded generator), and flies the scenario with both gain
sets on that same plant (a paired comparison), through the full onboard path with sensor noise. Per
gain set it reports the share that flies (leaves the ground and does not crash), lands upright, and
settles (every bank within 1 degree and turn within 3 degrees of its command from 3 s after the step
to the next: `flightctl.sim.metrics.settles`, the tests' reading of the paper's facts), the paired count
where one table settles and the other does not, and a map of the outcomes over the first two ranged
parameters. The paper's facts (both tables fly; Table 6, retuned on the vehicle, settles) become
probabilities over the plausible model. Flights run in parallel processes, one per core.
"""
from __future__ import annotations

import json
import os
import random
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from flightctl.errors import InputError
from flightctl.params import GAIN_SETS

GAINS = ("table4", "table6")


def ranged(params) -> list[tuple[str, str, float, float]]:
    """(cause, parameter, lo, hi) of every range the parameter file carries, in its order."""
    return [(e.cause, name, lo, hi) for e in params.effects for name, lo, hi in e.ranges]


def _fly(job: tuple) -> dict:
    """One flight (in a worker process): job = (params spec, scenario, gain set, draw, seed)."""
    from flightctl.sim import causes
    from flightctl.sim.metrics import settles
    from flightctl.sim.run import fly
    from flightctl.sim.scenarios import SCENARIOS
    spec, scenario, gains, draw, seed = job
    params = causes.load_vehicle(spec, GAIN_SETS[gains])
    effects = []
    for e in params.effects:
        values = {**dict(e.parameters), **{n: v for (c, n), v in draw.items() if c == e.cause}}
        effects.append(causes.make(e.cause, **values))
    sc = SCENARIOS[scenario]()
    flight = fly(sc, params, os.devnull, tuple(effects), seed=seed)
    settled = flight.flew and not flight.crashed and settles(flight.log, sc.steps, flight.t_arm)
    return {"gains": gains, "flies": bool(flight.flew and not flight.crashed),
            "lands": flight.outcome == "landed upright", "settles": bool(settled), "outcome": flight.outcome}


def run(spec: str | None, scenario: str, n: int, seed: int = 0, progress=None, jobs: int | None = None) -> dict:
    from flightctl.sim import causes
    params = causes.load_vehicle(spec)
    spans = ranged(params)
    if not spans:
        raise InputError(f"--monte-carlo: {spec or 'the reference airframe'} carries no ranges "
                         "(range.NAME = [lo, hi] in its [[effect]] tables; --params paper-as-flown has them)")
    rng = random.Random(seed)
    draws = [{(c, name): rng.uniform(lo, hi) for c, name, lo, hi in spans} for _ in range(n)]
    jobs_list = [(spec, scenario, g, d, seed + k) for k, d in enumerate(draws) for g in GAINS]
    results = []
    with ProcessPoolExecutor(max_workers=jobs or os.cpu_count() or 1) as pool:
        for job, r in zip(jobs_list, pool.map(_fly, jobs_list)):
            results.append(r)
            if progress is not None:
                progress(f"{job[2]}: " + ", ".join(f"{c}.{n} {v:.4g}" for (c, n), v in job[3].items())
                         + f": {r['outcome']}{', settles' if r['settles'] else ''}")
    rows = [{"draw": {f"{c}.{name}": v for (c, name), v in d.items()},
             **{g: results[2 * k + j] for j, g in enumerate(GAINS)}} for k, d in enumerate(draws)]
    share = {g: {what: sum(r[g][what] for r in rows) / n for what in ("flies", "lands", "settles")} for g in GAINS}
    paired = {"table6 settles, table4 not": sum(r["table6"]["settles"] and not r["table4"]["settles"] for r in rows),
              "table4 settles, table6 not": sum(r["table4"]["settles"] and not r["table6"]["settles"] for r in rows)}
    return {"scenario": scenario, "params": spec or "reference airframe", "n": n, "seed": seed,
            "ranges": [{"cause": c, "parameter": name, "lo": lo, "hi": hi} for c, name, lo, hi in spans],
            "share": share, "paired": paired, "draws": rows}


def summary(result: dict) -> str:
    lines = [f"{result['scenario']} over {result['n']} draws of {result['params']}'s ranges "
             + ", ".join(f"{r['cause']}.{r['parameter']} [{r['lo']:.4g}, {r['hi']:.4g}]" for r in result["ranges"])]
    for g, s in result["share"].items():
        lines.append(f"  {g}: flies {100 * s['flies']:.0f} %, lands upright {100 * s['lands']:.0f} %, "
                     f"settles {100 * s['settles']:.0f} %")
    lines.append("  paired: " + "; ".join(f"{k}: {v}" for k, v in result["paired"].items()))
    return "\n".join(lines)


def plot(result: dict, path: str | Path) -> None:
    """The outcome of each draw over the first two ranged parameters, one panel per gain set."""
    from flightctl.sim.plots import figure, legend, save
    keys = sorted(result["draws"][0]["draw"], key=lambda k: not k.endswith(".tau")) if result["draws"] else []
    fig, ax = figure(1, len(GAINS), size=(12.0, 5.0))
    for j, g in enumerate(GAINS):
        a = ax[0, j]
        for label, colour, pick in (("settles", "tab:green", lambda r: r["settles"]),
                                    ("lands, rings", "tab:orange", lambda r: r["lands"] and not r["settles"]),
                                    ("crashes", "tab:red", lambda r: not r["lands"])):
            pts = [r["draw"] for r in result["draws"] if pick(r[g])]
            if pts and keys:
                x = [p[keys[0]] for p in pts]
                y = [p[keys[1]] if len(keys) > 1 else 0.0 for p in pts]
                a.plot(x, y, "o", color=colour, ms=5, label=f"{label} ({len(pts)})")
        a.set_xlabel(keys[0] if keys else "")
        a.set_ylabel(keys[1] if len(keys) > 1 else "")
        s = result["share"][g]
        a.set_title(f"{g}: flies {100 * s['flies']:.0f} %, settles {100 * s['settles']:.0f} %")
        a.grid(alpha=0.3)
        legend(a)
    fig.suptitle(f"flightctl sim {result['scenario']} --monte-carlo {result['n']} --params {result['params']}")
    save(fig, path)


def write_json(result: dict, path: str | Path) -> None:
    Path(path).write_text(json.dumps(result, indent=1) + "\n")
