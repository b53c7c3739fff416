"""The paper's own comparison, honestly: Table 4 (tuned in simulation with perfect state feedback)
and Table 6 (retuned on the vehicle), each flown (a) with perfect state feedback and (b) through the
full onboard path (SPI decode, EMA, complementary filter, 45 Hz ultrasonic), with both estimator
structures, on the paper's base model and on the as-flown model (`--params paper-as-flown`,
docs/as-flown.md). Prints a Markdown table of the step metrics (true responses) of figures 13-16.

    python scripts/paper_comparison.py [--out DIR]
"""
from __future__ import annotations

import argparse
import math
import tempfile
from pathlib import Path

from flightctl.params import GAIN_SETS, load
from flightctl.sim.metrics import step_metrics
from flightctl.sim.run import fly
from flightctl.sim.scenarios import SCENARIOS

PATHS = [("perfect state feedback", dict(truth=True)),
         ("full path, flight estimator", dict(estimator="flight")),
         ("full path, paper estimator", dict(estimator="paper"))]
STEPS = ["step_alt", "step_roll", "step_pitch", "step_yaw"]
MODELS = [("base", None), ("as-flown", "paper-as-flown")]


def fmt(v: float, k: float = 1.0, digits: int = 2) -> str:
    return "not settled" if math.isinf(v) else "-" if math.isnan(v) else f"{v * k:.{digits}f}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--out", help="keep the logs here (default: a temporary folder)")
    args = ap.parse_args()
    out = Path(args.out or tempfile.mkdtemp())
    out.mkdir(parents=True, exist_ok=True)
    print("| model | gains | path | step | rise (s) | overshoot (%) | settling (s) | steady error | worst coupling | outcome |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for model, gains in ((m, g) for m in MODELS for g in ("table4", "table6")):
        params = load(model[1], GAIN_SETS[gains])
        for label, kw in PATHS:
            for name in STEPS:
                sc = SCENARIOS[name]()
                flight = fly(sc, params, out / f"{model[0]}-{gains}-{name}-{label.split(',')[-1].strip().replace(' ', '_')}.csv",
                             **kw)
                m = step_metrics(flight.log, sc.steps[0], flight.t_arm)
                ang = sc.steps[0].channel != "alt"
                k, unit = (180 / math.pi, "deg") if ang else (1.0, "m")
                worst = max(m.coupling.items(), key=lambda kv: kv[1] * (180 / math.pi if kv[0] != "alt" else 100))
                wk, wu = (180 / math.pi, "deg") if worst[0] != "alt" else (100.0, "cm")
                outcome = flight.result.reason
                hard = [abs(vz) for _, vz in flight.touchdowns if abs(vz) > 1.0]
                if hard:
                    outcome = f"crashed: hit the floor at {max(hard):.1f} m/s"
                print(f"| {model[0]} | {gains} | {label} | {sc.steps[0].channel} {sc.steps[0].end * k:+g} {unit} | {fmt(m.rise_s)} | "
                      f"{fmt(m.overshoot, 100, 1)} | {fmt(m.settling_s)} | {fmt(m.steady_error, k, 3)} {unit} | "
                      f"{worst[0]} {fmt(worst[1], wk, 2)} {wu} | {outcome} |", flush=True)


if __name__ == "__main__":
    main()
