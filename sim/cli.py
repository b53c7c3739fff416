"""`flightctl sim SCENARIO --log FLIGHT.csv`: fly the onboard control code against the simulated
quadcopter, write the contract flight log, a PNG of the responses, and print the step metrics.

`flightctl sim --plan PLAN.toml --log FLIGHT.csv` flies a plan file (what `flightctl run --plan`
takes) in simulated time, the same way."""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from flightctl.control.estimator import ESTIMATORS
from flightctl.errors import InputError
from flightctl.params import GAIN_SETS, load
from flightctl.sim import causes
from flightctl.sim.metrics import hold_metrics, step_metrics
from flightctl.plans import load_plan
from flightctl.sim.scenarios import SCENARIOS, scenario


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="flightctl sim", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scenario", nargs="?", choices=sorted(SCENARIOS), help="the named plan to fly")
    p.add_argument("--plan", metavar="PLAN.toml", help="fly this plan file instead (as `flightctl run --plan`)")
    p.add_argument("--log", required=True, help="the flight log to write (CSV, measured-data.md)")
    p.add_argument("--effect", action="append", default=[], metavar="CAUSE:name=value,...",
                   help=f"add an extension to the simulated plant ({', '.join(causes.CAUSES)}); repeatable")
    p.add_argument("--params", help="parameter file (TOML); default: the reference airframe")
    p.add_argument("--gains", choices=sorted(GAIN_SETS), default="table6",
                   help="gain set: table6 (flight, default) or table4 (the paper's simulation)")
    p.add_argument("--truth", action="store_true",
                   help="perfect state feedback (the paper's simulation) instead of the full onboard path")
    p.add_argument("--estimator", choices=ESTIMATORS, default="flight",
                   help="onboard estimator structure (docs/estimator.md); default: flight")
    p.add_argument("--no-noise", action="store_true", help="switch sensor noise and bias off")
    p.add_argument("--seed", type=int, default=0, help="seed of the sensor noise")
    p.add_argument("--substeps", type=int, default=2, help="plant integration steps per loop period")
    p.add_argument("--plot", help="PNG of the responses (default: beside the log, .png)")
    p.add_argument("--no-plot", action="store_true")
    p.add_argument("--quiet", action="store_true")
    return p


def main(argv: list[str]) -> int:
    from flightctl.sim.run import fly

    p = parser()
    args = p.parse_args(argv)
    if (args.scenario is None) == (args.plan is None):
        p.error("give exactly one of SCENARIO and --plan PLAN.toml")
    if args.substeps < 1:
        raise InputError("--substeps: at least 1")
    params = load(args.params, GAIN_SETS[args.gains])
    effects = tuple(causes.parse(e) for e in args.effect)
    flown = SCENARIOS[args.scenario]() if args.scenario else scenario(load_plan(args.plan))
    log_path = Path(args.log)
    if not log_path.parent.is_dir():
        raise InputError(f"--log {log_path}: the directory does not exist")
    say = (lambda *a: None) if args.quiet else (lambda *a: print(*a, file=sys.stderr))
    path = "perfect state feedback" if args.truth else f"full onboard path, {args.estimator} estimator"
    say(f"flying {flown.name} ({flown.doc}); {args.gains}, {path}"
        + (f"; plant with {', '.join(map(repr, effects))}" if effects else ""))
    start = time.perf_counter()
    flight = fly(flown, params, log_path, effects, noise=not args.no_noise, seed=args.seed,
                 truth=args.truth, substeps=args.substeps, estimator=args.estimator)
    wall = time.perf_counter() - start
    log = flight.log
    duration = log["t"][-1]
    print(f"{flown.name}: {flight.result.reason}; {duration:.1f} s flown in {wall:.1f} s "
          f"({duration / wall:.0f}x real time), {len(log)} rows -> {log_path}")
    for t, what in flight.result.events:
        print(f"  t = {t:6.2f} s  {what}")
    for t, vz in flight.touchdowns:
        print(f"  touchdown at t = {t:6.2f} s, {abs(vz):.2f} m/s")
    if args.scenario == "hover":
        h = hold_metrics(log)
        print(f"  last 10 s: altitude within {100 * h['alt_error']:.1f} cm of 1.5 m, "
              f"tilt within {h['tilt'] * 57.2958:.2f} deg")
    for step in flown.steps:
        print("  " + step_metrics(log, step, flight.t_arm).row())
    if not args.no_plot:
        png = Path(args.plot) if args.plot else log_path.with_suffix(".png")
        from flightctl.sim.plots import plot_flight
        plot_flight(log, png, f"flightctl sim {flown.name}: {args.gains}, {path}")
        print(f"  plot -> {png}")
    return 0
