"""`flightctl sim SCENARIO --monte-carlo N [--params P] [--seed S] [--json MC.json] [--plot MC.png]`:
the flight over the parameter file's plausible ranges instead of at its nominal point.

Each of the N draws takes every ranged parameter of the file (`range.NAME = [lo, hi]`: of the airframe,
at the file's top, and of its `[[effect]]` tables; flightctl/vehicles/paper-as-flown.toml: the rotor
inertia, the motor time constants, the rotor drag, the inflow and hub damping, the ESC delay)
uniformly from its range (`draw`: a seeded generator; a motor time constant's top follows the drawn
rotor inertia), and flies the scenario with both gain
sets on that same plant (a paired comparison), through the full onboard path with sensor noise. Per
gain set it reports the share that flies (leaves the ground and does not crash), lands upright, and
settles (every bank within 1 degree and turn within 3 degrees of its command from 3 s after the step
to the next: `flightctl.sim.flights.metrics.settles`, the tests' reading of the paper's facts), the paired count
where one table settles and the other does not, and a map of the outcomes over the first two ranged
parameters. The paper's facts (both tables fly; Table 6, retuned on the vehicle, settles) become
probabilities over the plausible model. Flights run in parallel processes, one per core.

`--batch` flies the draws on the batched simulator instead (sim/sweeps/batch.py: thousands of vehicles at
once, the vectorised copy of the controller, ideal sensors, no floor): from a hover after the
take-off to the end of the scenario's last attitude step, the same settle criterion; it answers
whether the control law holds over the ranges, without the estimator's and the sensors' share, and
reports no landing.
"""
from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path

from flightctl.errors import InputError
from flightctl.params import GAIN_SETS
from flightctl.sim.pool import run_all

GAINS = ("table4", "table6")


AIRFRAME = "airframe"   # the "cause" of a ranged airframe value (`range.Jp = [lo, hi]` at the file's top)


def ranged(params) -> list[tuple[str, str, float, float]]:
    """(cause, parameter, lo, hi) of every range the parameter file carries, its airframe's first."""
    return [(AIRFRAME, name, lo, hi) for name, lo, hi in params.ranges] + \
        [(e.cause, name, lo, hi) for e in params.effects for name, lo, hi in e.ranges]


def draw(params, n: int, seed: int = 0) -> dict:
    """n draws of every ranged parameter, (cause, parameter) -> (n,) array, each uniform in its range,
    except where an effect's range follows a drawn airframe value (`Effect.range_scales`: the motor
    time constants' slowest plausible value is proportional to the rotor inertia Jp): its top is then
    hi * value / (the value's own top), never below its bottom. Seeded: the same draws every time."""
    import numpy as np

    from flightctl.sim import causes
    rng = np.random.default_rng(seed)
    spans = ranged(params)
    u = {(c, name): rng.uniform(0.0, 1.0, n) for c, name, _, _ in spans}
    out = {(c, name): lo + u[(c, name)] * (hi - lo) for c, name, lo, hi in spans if c == AIRFRAME}
    tops = {name: hi for c, name, _, hi in spans if c == AIRFRAME}
    for c, name, lo, hi in spans:
        if c != AIRFRAME:
            scale = causes.CAUSES[c].effect.range_scales.get(name)
            if scale in tops:
                hi = np.maximum(lo, hi * out[(AIRFRAME, scale)] / tops[scale])
            out[(c, name)] = lo + u[(c, name)] * (hi - lo)
    return out


def drawn_airframe(airframe, draws: dict, k=None):
    """The airframe with its drawn values: draw k of each (a float), or all (arrays, the batch)."""
    values = {name: (v if k is None else float(v[k])) for (c, name), v in draws.items() if c == AIRFRAME}
    return dataclasses.replace(airframe, **values) if values else airframe


def _fly(job: tuple) -> dict:
    """One flight (in a worker process): job = (params spec, scenario, gain set, draw, seed)."""
    from flightctl.sim import causes
    from flightctl.sim.flights.metrics import settles
    from flightctl.sim.flights.run import fly
    from flightctl.sim.flights.scenarios import SCENARIOS
    spec, scenario, gains, drawn, seed = job
    params = causes.load_vehicle(spec, GAIN_SETS[gains])
    effects = []
    for e in params.effects:
        values = {**dict(e.parameters), **{n: v for (c, n), v in drawn.items() if c == e.cause}}
        effects.append(causes.make(e.cause, **values))
    sc = SCENARIOS[scenario]()
    # the plant flies the drawn airframe; the controller knows the file's nominal one
    flight = fly(sc, params, os.devnull, tuple(effects), seed=seed, plant_airframe=drawn_airframe(params.airframe, drawn))
    settled = flight.flew and not flight.crashed and settles(flight.log, sc.steps, flight.t_arm)
    return {"gains": gains, "flies": bool(flight.flew and not flight.crashed),
            "lands": flight.outcome == "landed upright", "settles": bool(settled), "outcome": flight.outcome}


def run(spec: str | None, scenario: str, n: int, seed: int = 0, progress=None, jobs: int | None = None) -> dict:
    """The module docstring's Monte Carlo; `progress`: a sim/progress.py Progress, one step a flight."""
    from flightctl.sim import causes
    params = causes.load_vehicle(spec)
    spans = ranged(params)
    if not spans:
        raise InputError(f"--monte-carlo: {spec or 'the reference airframe'} carries no ranges "
                         "(range.NAME = [lo, hi] in its [[effect]] tables; --params paper-as-flown has them)")
    drawn = draw(params, n, seed)
    draws = [{k: float(v[i]) for k, v in drawn.items()} for i in range(n)]
    jobs_list = [(spec, scenario, g, d, seed + k) for k, d in enumerate(draws) for g in GAINS]

    def done(k: int, r: dict) -> None:          # as each flight finishes (sim/pool.py)
        job = jobs_list[k]
        progress.step(f"{job[2]}: " + ", ".join(f"{c}.{n} {v:.4g}" for (c, n), v in job[3].items())
                 + f": {r['outcome']}{', settles' if r['settles'] else ''}")
    results = run_all(_fly, jobs_list, jobs or os.cpu_count() or 1, done if progress is not None else None)
    rows = [{"draw": {f"{c}.{name}": v for (c, name), v in d.items()},
             **{g: results[2 * k + j] for j, g in enumerate(GAINS)}} for k, d in enumerate(draws)]
    share = {g: {what: sum(r[g][what] for r in rows) / n for what in ("flies", "lands", "settles")} for g in GAINS}
    paired = {"table6 settles, table4 not": sum(r["table6"]["settles"] and not r["table4"]["settles"] for r in rows),
              "table4 settles, table6 not": sum(r["table4"]["settles"] and not r["table6"]["settles"] for r in rows)}
    return {"scenario": scenario, "params": spec or "reference airframe", "n": n, "seed": seed,
            "ranges": [{"cause": c, "parameter": name, "lo": lo, "hi": hi} for c, name, lo, hi in spans],
            "share": share, "paired": paired, "draws": rows}


def _batch_window(sc) -> tuple[float, float, list]:
    """(start, end, attitude steps) of a scenario for the batched flight: from 1 s after its take-off
    ramp to the end of its last attitude step's window."""
    steps = [st for st in sc.steps if st.channel != "alt"]
    if not steps:
        raise InputError(f"--batch: the scenario {sc.name} has no attitude steps to judge")
    start = max((m.t + m.ramp for m in sc.plan.moves if m.channel == "alt" and m.t == 0.0), default=0.0) + 1.0
    steps = [st for st in steps if st.t >= start]
    return start, max(st.t + st.window for st in steps) + 0.05, steps


def run_batch(spec: str | None, scenario: str, n: int, seed: int = 0, progress=None, workers: int | None = None) -> dict:
    """The draws flown on the batched simulator (module docstring), both gain sets on the same draws;
    `progress`: a sim/progress.py Progress, one step a gain set, the vehicle-steps in between."""
    import numpy as np

    from flightctl.sim import causes
    from flightctl.sim.sweeps.batch import simulate
    from flightctl.sim.flights.metrics import settles
    from flightctl.sim.world.model import PHI, PSI, THETA
    from flightctl.sim.flights.scenarios import SCENARIOS
    params = causes.load_vehicle(spec)
    spans = ranged(params)
    if not spans:
        raise InputError(f"--monte-carlo: {spec or 'the reference airframe'} carries no ranges")
    sc = SCENARIOS[scenario]()
    start, end, steps = _batch_window(sc)
    draws = draw(params, n, seed)
    out = {}
    for g in GAINS:
        frac = (lambda f, g=g: progress.update(f, f"{g}: {n} vehicles")) if progress is not None else None
        flight = simulate(causes.load_vehicle(spec, GAIN_SETS[g]), sc.plan, start, end, n, draws,
                          workers=workers or os.cpu_count() or 1, record_every=9, progress=frac)
        st = flight.states
        log = {"t": flight.t, "true_roll": st[:, PHI], "true_pitch": st[:, THETA],
               "true_yaw": (st[:, PSI] + np.pi) % (2 * np.pi) - np.pi}
        flies = ~flight.crashed
        out[g] = (flies, settles(log, steps, 0.0) & flies, flight.crash_t)
        if progress is not None:
            progress.step(f"{g}: {n} vehicles, {flight.vehicle_steps / 1e6:.1f} M vehicle-steps")
    rows = [{"draw": {f"{c}.{name}": float(v[k]) for (c, name), v in draws.items()},
             **{g: {"gains": g, "flies": bool(out[g][0][k]), "settles": bool(out[g][1][k]),
                    "outcome": "in the air" if out[g][0][k] else f"crashed at {out[g][2][k]:.2f} s"} for g in GAINS}}
            for k in range(n)]
    share = {g: {what: sum(r[g][what] for r in rows) / n for what in ("flies", "settles")} for g in GAINS}
    paired = {"table6 settles, table4 not": sum(r["table6"]["settles"] and not r["table4"]["settles"] for r in rows),
              "table4 settles, table6 not": sum(r["table4"]["settles"] and not r["table6"]["settles"] for r in rows)}
    return {"scenario": scenario, "params": spec or "reference airframe", "n": n, "seed": seed,
            "simulator": f"batched simulator (sim/sweeps/batch.py): ideal sensors, from {start:g} s to {end:g} s after arming",
            "ranges": [{"cause": c, "parameter": name, "lo": lo, "hi": hi} for c, name, lo, hi in spans],
            "share": share, "paired": paired, "draws": rows}


def summary(result: dict) -> str:
    lines = [f"{result['scenario']} over {result['n']} draws of {result['params']}'s ranges "
             + ", ".join(f"{r['cause']}.{r['parameter']} [{r['lo']:.4g}, {r['hi']:.4g}]" for r in result["ranges"])]
    if "simulator" in result:
        lines.append(f"  on the {result['simulator']}")
    for g, s in result["share"].items():
        lands = f"lands upright {100 * s['lands']:.0f} %, " if "lands" in s else ""
        lines.append(f"  {g}: flies {100 * s['flies']:.0f} %, {lands}settles {100 * s['settles']:.0f} %")
    lines.append("  paired: " + "; ".join(f"{k}: {v}" for k, v in result["paired"].items()))
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
    from flightctl.errors import write_atomic
    write_atomic(path, json.dumps(result, indent=1) + "\n")
