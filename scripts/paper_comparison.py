"""The paper's own comparison, honestly: Table 4 (tuned in simulation with perfect state feedback)
and Table 6 (retuned on the vehicle), each flown (a) with perfect state feedback and (b) through the
full onboard path (SPI decode, filters, 45 Hz ultrasonic), with both estimator structures, on the
paper's base model and on the as-flown model (`--params paper-as-flown`, docs/as-flown.md). Prints
the Markdown table of the README (step metrics of the true responses, figures 13-16);
tests/project/test_readme_table.py checks that the README holds what this prints.

    python scripts/paper_comparison.py [--out DIR]
"""
from __future__ import annotations

import argparse
import math
import tempfile
from pathlib import Path

from flightctl.params import GAIN_SETS, load
from flightctl.sim.flights.metrics import step_metrics
from flightctl.sim.progress import Progress
from flightctl.sim.flights.run import fly
from flightctl.sim.flights.scenarios import SCENARIOS

MODELS = {"base": None, "as-flown": "paper-as-flown"}
GAINS = ("table4", "table6")
PATHS = {"perfect state feedback": dict(truth=True),
         "full path, flight estimator": dict(estimator="flight"),
         "full path, paper estimator": dict(estimator="paper")}
STEPS = ("step_alt", "step_roll", "step_pitch", "step_yaw")
HEADER = ("| model | gains | path | step | rise (s) | overshoot (%) | settling (s) | steady error | "
          "worst coupling | outcome |\n|---|---|---|---|---|---|---|---|---|---|")
CASES = [(m, g, p, s) for m in MODELS for g in GAINS for p in PATHS for s in STEPS]


def fmt(v: float, k: float = 1.0, digits: int = 2) -> str:
    return "not settled" if math.isinf(v) else "-" if math.isnan(v) else f"{v * k:.{digits}f}"


def row(model: str, gains: str, path: str, step: str, out: Path) -> str:
    """One row of the table: fly `step` and measure its first step's true response."""
    sc = SCENARIOS[step]()
    flight = fly(sc, load(MODELS[model], GAIN_SETS[gains]),
                 out / f"{model}-{gains}-{step}-{path.split(',')[-1].strip().replace(' ', '_')}.csv", **PATHS[path])
    s = sc.steps[0]
    m = step_metrics(flight.log, s, flight.t_arm)
    k, unit = (180 / math.pi, "deg") if s.channel != "alt" else (1.0, "m")
    worst = max(m.coupling.items(), key=lambda kv: kv[1] * (180 / math.pi if kv[0] != "alt" else 100))
    wk, wu = (180 / math.pi, "deg") if worst[0] != "alt" else (100.0, "cm")
    outcome = flight.outcome            # the one definition of a crash (flightctl/safety.py)
    if m.flown_s <= 0.0:                # the flight ended before the step: nothing to measure
        return (f"| {model} | {gains} | {path} | {s.channel} {s.end * k:+g} {unit} | not flown | - | - | - | - | "
                f"{outcome} |")
    return (f"| {model} | {gains} | {path} | {s.channel} {s.end * k:+g} {unit} | {fmt(m.rise_s)} | "
            f"{fmt(m.overshoot, 100, 1)} | {fmt(m.settling_s)} | {fmt(m.steady_error, k, 3)} {unit} | "
            f"{worst[0]} {fmt(worst[1], wk, 2)} {wu} | {outcome} |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", help="keep the logs here (default: a temporary folder)")
    args = ap.parse_args()
    out = Path(args.out or tempfile.mkdtemp())
    out.mkdir(parents=True, exist_ok=True)
    print(HEADER)
    progress = Progress(len(CASES))
    for case in CASES:
        print(row(*case, out), flush=True)
        progress.step(" ".join(case))


if __name__ == "__main__":
    main()
