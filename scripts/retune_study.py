"""The paper's retuning reproduced in simulation (issue 43 part 2; docs/tune.md, "The paper's retuning, in
simulation"): hidden vehicles drawn from paper-as-flown's ranges (sim/sweeps/montecarlo.py `draw`), a share of them
with an effect drawn at random (a motor lag, an actuation delay, a weak motor; `HIDDEN`, its size from a seeded
generator, never told to the code under test), each flies the paper flight with Table 4; its log goes through
`tune --from-log` (sim/sweeps/fromlog.py); the gains from the log, where it gives any, fly the same hidden vehicle;
Table 6 flies it too. Each flight judged as the Monte Carlo judges (sim/sweeps/judge.py): flies (left the ground,
no crash, landed upright), holds (flies, and every attitude step rings and holds within its band), its score.

    python scripts/retune_study.py [--vehicles 100] [--seed 43] [--hidden-share 0.5]

STATE: the prediction for flightctl's own logs (its attitude loop, eq. 24 on the angles, through its mixer) is
issue 42's other branch (h42p); until it is merged `predict.loop_parts` refuses a flightctl log before any fit,
and every log's "gains from the log" is that refusal, counted in the table's last column.
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

HIDDEN = ("motor_lag", "actuation_delay", "motor_weak")


def hidden(rng: np.random.Generator) -> str:
    """One effect and its size (the ranges of tests/test_diagnose_cases.py's `draw`)."""
    cause = str(rng.choice(HIDDEN))
    if cause == "motor_lag":
        return f"motor_lag:tau={rng.uniform(0.02, 0.1):.4f}"
    if cause == "actuation_delay":
        return f"actuation_delay:delay={rng.uniform(0.01, 0.05):.4f}"
    return f"motor_weak:motor={int(rng.integers(1, 5))},scale={rng.uniform(0.8, 0.95):.3f}"


def judged(flight, sc) -> dict:
    from flightctl.sim.sweeps import judge
    flies = bool(flight.flew and not flight.crashed and flight.outcome == "landed upright")
    if not flies:
        return {"flies": False, "holds": False, "score": None}
    figures = judge.step_figures(flight.log, sc.steps, flight.t_arm)
    return {"flies": True, "holds": bool(judge.holds(figures, True)), "score": judge.summary(figures)["score"]}


def study(n: int, seed: int, share: float, progress=print) -> dict:
    from flightctl import params as paramfile
    from flightctl.logfile import read_flight_log
    from flightctl.params import TABLE4, TABLE6
    from flightctl.sim import causes
    from flightctl.sim.flights.run import fly
    from flightctl.sim.flights.scenarios import SCENARIOS
    from flightctl.sim.sweeps import fromlog
    from flightctl.sim.sweeps.montecarlo import draw, drawn_params, one_draw
    import dataclasses
    base = causes.load_vehicle("paper-as-flown")
    draws = draw(base, n, seed)
    rng = np.random.default_rng(seed)
    a = paramfile.load(None).airframe
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(n):
            effect = hidden(rng) if rng.random() < share else None
            effects = [causes.parse(effect)] if effect else []
            params = drawn_params(base, one_draw(draws, k))
            row = {"vehicle": k, "hidden": effect}
            log = Path(tmp) / "table4.csv"
            for name, g in (("table4", TABLE4), ("table6", TABLE6)):
                sc = SCENARIOS["paper"]()
                flight = fly(sc, dataclasses.replace(params, gains=g), log if name == "table4" else os.devnull,
                             effects=effects, seed=seed + k)
                row[name] = judged(flight, sc)
            rep = fromlog.from_log(read_flight_log(log), a, fromlog.Targets(), draws=16, seed=seed + k)
            new = fromlog.recommended(rep)
            if new:       # flightctl's attitude gains, eq. 24: kp_phi etc.
                name_of = {"x": "phi", "y": "theta", "z": "psi"}
                g = dataclasses.replace(TABLE4, **{f"{kk}_{name_of[ax]}": v for ax, gg in new.items() for kk, v in gg.items()})
                sc = SCENARIOS["paper"]()
                row["from_log"] = judged(fly(sc, dataclasses.replace(params, gains=g), os.devnull, effects=effects,
                                             seed=seed + k), sc)
            else:
                row["from_log"] = {"refused": rep.get("refused")}
            rows.append(row)
            progress(f"vehicle {k + 1}/{n}{' (' + effect + ')' if effect else ''}: Table 4 "
                     f"{'holds' if row['table4']['holds'] else 'flies' if row['table4']['flies'] else 'crashes'}, "
                     f"Table 6 {'holds' if row['table6']['holds'] else 'flies' if row['table6']['flies'] else 'crashes'}, "
                     f"from the log: {'refused' if 'refused' in row['from_log'] else row['from_log']}")
    return {"vehicles": n, "seed": seed, "hidden_share": share, "rows": rows}


def markdown(res: dict) -> str:
    rows = res["rows"]
    n = len(rows)
    L = [f"`python scripts/retune_study.py --vehicles {res['vehicles']} --seed {res['seed']} --hidden-share "
         f"{res['hidden_share']:g}`: {n} hidden vehicles of paper-as-flown's ranges, "
         f"{sum(r['hidden'] is not None for r in rows)} with a hidden effect.", "",
         "| gains | flies | holds | median score where it holds | refused (no gains from the log) |", "|---|---|---|---|---|"]
    for name, key in (("Table 4", "table4"), ("Table 6", "table6"), ("gains from the log", "from_log")):
        got = [r[key] for r in rows if "refused" not in r[key]]
        refused = n - len(got)
        scores = [g["score"] for g in got if g["holds"] and g["score"] is not None]
        L.append(f"| {name} | {sum(g['flies'] for g in got)} of {len(got)} | {sum(g['holds'] for g in got)} of {len(got)} | "
                 f"{np.median(scores):.2f} |" if scores else
                 f"| {name} | {sum(g['flies'] for g in got)} of {len(got)} | {sum(g['holds'] for g in got)} of {len(got)} | - |")
        L[-1] += f" {refused} |"
    reasons = sorted({r["from_log"]["refused"] for r in rows if "refused" in r["from_log"]})
    if reasons:
        L += ["", "Refused: " + "; ".join(reasons)]
    return "\n".join(L)


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--vehicles", type=int, default=100)
    ap.add_argument("--seed", type=int, default=43)
    ap.add_argument("--hidden-share", type=float, default=0.5)
    args = ap.parse_args(argv)
    res = study(args.vehicles, args.seed, args.hidden_share, lambda m: print(m, file=sys.stderr))
    print(markdown(res))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
