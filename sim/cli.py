"""`flightctl sim SCENARIO --log FLIGHT.csv`: fly the onboard control code against the simulated
quadcopter, write the contract flight log, a PNG of the responses, and print the step metrics.

`flightctl sim --plan PLAN.toml --log FLIGHT.csv` flies a plan file (what `flightctl run --plan`
takes) in simulated time, the same way.

`flightctl sim SCENARIO --fault NAME[:k=v,...]` (repeatable) injects a fault at the simulated devices
(what each fault does: docs/safety.md; their keys: docs/formats.md); `flightctl sim faults --json
M.json` flies every fault and writes the matrix.

Exit status: 0 the vehicle flew and landed upright, 1 it crashed or never flew, 2 bad input, 130
interrupted (Ctrl-C: the flight ends at once, its log is kept with a `# partial:` line)."""
from __future__ import annotations

import argparse
import json
import math
import sys
import threading
import time
from pathlib import Path

from flightctl.cli import EXIT_INTERRUPTED, ctrl_c_sets
from flightctl.control.estimator import ESTIMATORS
from flightctl.errors import InputError, Parser, seed
from flightctl.files import output_dir, output_file, write_atomic
from flightctl.logfile import FLIGHT_COLUMNS, MAG_COLUMNS, log_room
from flightctl.params import GAIN_SETS, shipped
from flightctl.sim import causes, engine
from flightctl.sim.world import faults
from flightctl.sim.world.board import SIM_CALIBRATE_S, TRUTH_COLUMNS
from flightctl.sim.flights.metrics import LEGEND, SETTLE_AFTER_S, SETTLED_DEG, hold_metrics, settled_errors, step_metrics
from flightctl.plans import load_plan
from flightctl.sim.flights.scenarios import SCENARIOS, scenario
from flightctl.sim.flights.run import gains_label


def parser() -> argparse.ArgumentParser:
    p = Parser(prog="flightctl sim", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scenario", nargs="?", choices=sorted(SCENARIOS), help="the named plan to fly")
    p.add_argument("--plan", metavar="PLAN.toml", help="fly this plan file instead (as `flightctl run --plan`)")
    p.add_argument("--log", help="the flight log to write (CSV; its columns: docs/formats.md); required but with --monte-carlo")
    p.add_argument("--effect", action="append", default=[], metavar="CAUSE:name=value,...",
                   help=f"add an extension to the simulated plant ({', '.join(causes.CAUSES)}); repeatable")
    p.add_argument("--fault", action="append", default=[], metavar="NAME[:at=S,k=v]",
                   help="inject a fault at the simulated devices (at: s after arming, the log's time, before the "
                        "plan's end; faults: " + ", ".join(faults.FAULTS + faults.LOADS) + "; their keys: docs/formats.md); repeatable")
    p.add_argument("--params", metavar="P.toml|NAME",
                   help=f"parameter file (TOML) or a shipped vehicle ({', '.join(shipped())}); default: the reference airframe")
    p.add_argument("--gains", choices=sorted(GAIN_SETS),
                   help="gain set by name: table6 (flight) or table4 (the paper's simulation); it replaces the "
                        "parameter file's [gains]; default: the file's [gains], else table6")
    p.add_argument("--truth", action="store_true",
                   help="perfect state feedback (the paper's simulation) instead of the full onboard path")
    p.add_argument("--estimator", choices=ESTIMATORS, default="flight",
                   help="onboard estimator structure (docs/estimator.md); default: flight")
    p.add_argument("--no-noise", action="store_true", help="switch sensor noise and bias off")
    p.add_argument("--seed", type=seed, default=0, help="seed of the sensor noise (a whole number from 0)")
    p.add_argument("--substeps", type=int, help=f"plant RK4 steps per loop period, 1 to {MAX_SUBSTEPS} (default 1)")
    p.add_argument("--plot", help="PNG of the responses (default: beside the log, .png)")
    p.add_argument("--no-plot", action="store_true", help="write no PNG")
    p.add_argument("--quiet", action="store_true",
                   help="nothing on stderr (the flight's announcement and progress); the results still print")
    p.add_argument("--mavlink", metavar="URL",
                   help="stream to a ground station and take its commands (pymavlink's connection string, "
                        "e.g. udpout:127.0.0.1:14550; needs pip install '.[mavlink]' in the flightctl checkout; README)")
    p.add_argument("--json", metavar="METRICS.json",
                   help="write the outcome and the metrics as JSON (SI units: s, m, rad)")
    p.add_argument("--monte-carlo", type=int, metavar="N",
                   help="fly N draws of the parameter file's plausible ranges with both gain sets, in parallel; "
                        "report the shares that fly, land and settle (--json, --plot: a map); with --fault, each draw flown "
                        "with it (the full path only: e.g. the loop's lateness, loop_late); sim/sweeps/montecarlo.py")
    p.add_argument("--batch", action="store_true",
                   help="with --monte-carlo: fly the draws on the batched simulator (sim/sweeps/batch.py: compiled, "
                        "each draw flown as the full onboard path flies it, take-off to landing)")
    engine.add_flag(p, "with --monte-carlo")
    return p


# One RK4 step a loop period (2.2 ms) already resolves the fastest term of the model (the motors' 20-40 ms);
# 100 steps of 22 us are far below every time constant, and the flight then runs slower than real time.
MAX_SUBSTEPS = 100


def speed(ratio: float) -> str:
    """Simulated time over wall time, to two significant figures below 10 (0.55x, 8.3x), whole above (71x)."""
    return f"{ratio:.2f}x" if ratio < 1 else f"{ratio:.1f}x" if ratio < 10 else f"{ratio:.0f}x"


def _finite(v: float) -> float | None:
    """JSON has no infinity or NaN: a step never settled, or a value not measured, is null."""
    return v if math.isfinite(v) else None


def run_json(args, params) -> dict:
    """What was flown, so that a metrics file says how to fly it again: the parameters (file or
    name, and a hash of their values), the gains, the path and estimator, the seed, effects and faults."""
    import dataclasses
    return {"params": {"file": args.params, "origin": params.origin or "reference airframe",
                       "sha256_16": params.digest()},
            "gains": {"set": gains_label(args, params), **dataclasses.asdict(params.gains)},
            "path": "perfect state feedback" if args.truth else "full onboard path",
            "estimator": None if args.truth else args.estimator, "seed": args.seed, "noise": not args.no_noise,
            "substeps": args.substeps or 1, "effects": args.effect, "faults": args.fault}


def metrics_json(flown, flight, wall_s: float) -> dict:
    """The outcome of a flight and its metrics (true responses), as `--json` writes them."""
    log = flight.log
    out = {"scenario": flown.name, "reason": flight.result.reason, "flown_s": float(log["t"][-1]),
           "wall_s": wall_s, "rows": len(log), "events": [{"t": t, "what": w} for t, w in flight.result.events],
           "touchdowns": [{"t": t, "speed": abs(vz)} for t, vz in flight.touchdowns],
           "outcome": flight.outcome, "crashed": flight.crashed, "flew": flight.flew,
           "log_dropped_rows": flight.log_dropped, "overruns": flight.result.overruns, "stalls": flight.result.stalls,
           "steps": []}
    if flown.name == "hover" and flight.flew:
        out["hold_last_10s"] = hold_metrics(log, until=flown.plan.duration)   # null: the hover was cut short
    for step in flown.steps:
        m = step_metrics(log, step, flight.t_arm, events=flight.result.events)
        out["steps"].append({"channel": step.channel, "t": step.t, "start": step.start, "end": step.end,
                             "window_s": step.window, "flown_s": m.flown_s, "flown": m.flown,
                             "rise_s": _finite(m.rise_s), "overshoot": _finite(m.overshoot),
                             "settling_s": _finite(m.settling_s), "steady_error": _finite(m.steady_error),
                             "coupling": {k: _finite(v) for k, v in m.coupling.items()}})
    return out


def main(argv: list[str]) -> int:
    from flightctl.sim.flights.run import fly

    if argv[:1] == ["faults"]:
        return faults_main(argv[1:])
    p = parser()
    args = p.parse_args(argv)
    if (args.scenario is None) == (args.plan is None):
        p.error("give exactly one of SCENARIO and --plan PLAN.toml")
    if args.monte_carlo is not None:
        engine.use(args.scheduler, args.quiet)
        return monte_carlo_main(args)
    if args.batch:
        p.error("--batch goes with --monte-carlo N")
    if args.log is None:
        p.error("the following arguments are required: --log")
    if args.substeps is not None and not 1 <= args.substeps <= MAX_SUBSTEPS:
        raise InputError(f"--substeps {args.substeps}: 1 to {MAX_SUBSTEPS} (one RK4 step a loop period already "
                         f"resolves the model's fastest term; {MAX_SUBSTEPS} runs slower than real time)")
    params = causes.load_vehicle(args.params, GAIN_SETS[args.gains] if args.gains else None)
    effects = tuple(causes.parse(e) for e in args.effect)
    injected = tuple(faults.parse(f) for f in args.fault)
    flown = SCENARIOS[args.scenario]() if args.scenario else scenario(load_plan(args.plan))
    for f in injected:
        if f.at >= flown.plan.duration:
            raise InputError(f"--fault {f.name}: at = {f.at:g} s, but {flown.name}'s plan ends "
                             f"{flown.plan.duration:g} s after arming: the fault would never be injected")
    log_path = output_file(args.log, "--log", ".csv")
    log_room(log_path, SIM_CALIBRATE_S + flown.plan.duration, params.airframe.loop_hz,
             len(FLIGHT_COLUMNS + MAG_COLUMNS + TRUTH_COLUMNS))
    if args.json:
        output_file(args.json, "--json", ".json")
    if args.plot and args.no_plot:
        raise InputError("--plot and --no-plot exclude each other")
    if not args.no_plot:
        output_file(args.plot or log_path.with_suffix(".png"), "--plot", ".png")
    link = None
    if args.mavlink:      # a URL it cannot open is one line before anything flies
        from flightctl.comms.mavlink import open_link
        link = open_link(args.mavlink, params)
    say = (lambda *a: None) if args.quiet else (lambda *a: print(*a, file=sys.stderr))
    path = "perfect state feedback" if args.truth else f"full onboard path, {args.estimator} estimator"
    say(f"flying {flown.name} ({flown.doc}); {gains_label(args, params)}, {path}"
        + (f"; plant with {', '.join(map(repr, effects))}" if effects else ""))
    for e in params.effects:
        if e.cause in {x.cause for x in effects}:
            say(f"  --effect {e.cause} replaces the one the parameter file carries "
                f"({', '.join(f'{k}={v:g}' for k, v in e.parameters)})")
    start = time.perf_counter()
    if link is not None:
        link.ready(flown.name)
    interrupt = threading.Event()
    try:
        with ctrl_c_sets(interrupt):
            flight = fly(flown, params, log_path, effects, noise=not args.no_noise, seed=args.seed,
                         truth=args.truth, substeps=args.substeps, estimator=args.estimator, telemetry=link,
                         faults=injected, interrupt=interrupt)
    finally:
        if link is not None:
            link.close()
    wall = time.perf_counter() - start
    log = flight.log
    duration = log["t"][-1] if len(log) else 0.0
    if interrupt.is_set():
        when = f"at t = {duration:.2f} s" if len(log) else "before arming"
        print(f"flightctl sim: interrupted {when}; the log {log_path} is kept, marked partial "
              "(no metrics, no figure)", file=sys.stderr)
        return EXIT_INTERRUPTED
    loop_reason = "" if flight.result.reason == "plan complete" else f" ({flight.result.reason})"
    print(f"{flown.name}: {flight.outcome}{loop_reason}; {duration:.1f} s flown in {wall:.1f} s "
          f"({speed(duration / wall)} real time), {len(log)} rows -> {log_path}")
    for t, what in flight.result.events:
        print(f"  t = {t:6.2f} s  {what}")
    for t, vz in flight.touchdowns:
        print(f"  touchdown at t = {t:6.2f} s, {abs(vz):.2f} m/s")
    if args.scenario == "hover" and flight.flew and not flight.crashed:
        h = hold_metrics(log, until=flown.plan.duration)
        print(f"  last 10 s: altitude within {100 * h['alt_error']:.1f} cm of 1.5 m, tilt within "
              f"{h['tilt'] * 57.2958:.2f} deg" if h else
              f"  the hover was cut short at t = {duration:.1f} s, before the plan's {flown.plan.duration:g} s")
    held = iter(settled_errors(log, flown.steps, flight.t_arm))
    for step in flown.steps:
        row = "  " + step_metrics(log, step, flight.t_arm, events=flight.result.events).row()
        if step.channel != "alt":
            err = next(held)[1]
            row += (f"; from {SETTLE_AFTER_S:g} s: within {err:.2f} deg" if math.isfinite(err)
                    else f"; from {SETTLE_AFTER_S:g} s: not flown that long")
        print(row)
    if flown.steps:
        print(LEGEND)
        print(f"  (from {SETTLE_AFTER_S:g} s: the largest true error from {SETTLE_AFTER_S:g} s after the step to the next "
              f"step; the paper's real flights settle within {SETTLED_DEG['roll']:g} deg for a bank and "
              f"{SETTLED_DEG['yaw']:g} deg for a turn, README)")
    if args.json:
        write_atomic(args.json, json.dumps({**metrics_json(flown, flight, wall), "run": run_json(args, params)},
                                           indent=1) + "\n")
        print(f"  metrics -> {args.json}")
    if not args.no_plot:
        png = Path(args.plot) if args.plot else log_path.with_suffix(".png")
        from flightctl.sim.plots import plot_flight
        plot_flight(log, png, f"flightctl sim {flown.name}: {gains_label(args, params)}, {path}")
        print(f"  plot -> {png}")
    return 1 if flight.crashed or not flight.flew else 0


def monte_carlo_main(args) -> int:
    """`--monte-carlo N`: sim/sweeps/montecarlo.py."""
    from flightctl.sim.sweeps import montecarlo
    from flightctl.sim.progress import Progress
    if args.scenario is None:
        raise InputError("--monte-carlo flies a named scenario (e.g. paper), not a plan file")
    most = 100000 if args.batch else 10000
    if not 1 <= args.monte_carlo <= most:
        raise InputError(f"--monte-carlo {args.monte_carlo}: between 1 and {most} draws")
    if args.fault and args.batch:
        raise InputError("--fault goes with the full onboard path: the batched simulator (--batch) has no "
                         "devices to inject it at")
    for f in args.fault:
        faults.parse(f)
    if args.json:
        output_file(args.json, "--json", ".json")
    if args.plot:
        output_file(args.plot, "--plot", ".png")
    bar = Progress(2 if args.batch else 2 * args.monte_carlo, "monte carlo ") if not args.quiet else None
    if args.batch:
        result = montecarlo.run_batch(args.params, args.scenario, args.monte_carlo, args.seed, progress=bar)
    else:
        result = montecarlo.run(args.params, args.scenario, args.monte_carlo, args.seed, progress=bar,
                                faults=tuple(args.fault))
    print(montecarlo.summary(result))
    if args.json:
        montecarlo.write_json(result, args.json)
        print(f"  metrics -> {args.json}")
    if args.plot:
        montecarlo.plot(result, args.plot)
        print(f"  plot -> {args.plot}")
    return 0


def faults_main(argv: list[str]) -> int:
    """`flightctl sim faults --json M.json [--doc docs/safety.md]`: the fault-injection matrix."""
    from flightctl.sim.flights import faultmatrix

    p = Parser(prog="flightctl sim faults", description=faultmatrix.__doc__)
    p.add_argument("--json", required=True, metavar="M.json", help="the matrix, one object per fault")
    p.add_argument("--logs", metavar="DIR", help="where the flights' logs go (default: beside --json)")
    p.add_argument("--doc", metavar="safety.md", help="also write the table into this Markdown file, "
                   "between its fault-matrix markers (docs/safety.md)")
    p.add_argument("--params", help=f"parameter file (TOML) or a shipped vehicle ({', '.join(shipped())}); "
                                    "default: the reference airframe")
    p.add_argument("--seed", type=seed, default=0, help="seed of the sensor noise (a whole number from 0)")
    args = p.parse_args(argv)
    out = output_file(args.json, "--json", ".json")
    logs = output_dir(args.logs, "--logs") if args.logs else output_dir(out.resolve().parent, "--json")
    if args.doc and not Path(args.doc).is_file():
        raise InputError(f"--doc {args.doc}: no such file")
    if args.doc:
        output_file(args.doc, "--doc", ".md")
    params = causes.load_vehicle(args.params, GAIN_SETS["table6"])
    faultmatrix.log_room(logs, params)
    logs.mkdir(parents=True, exist_ok=True)
    rows = faultmatrix.run_matrix(params, logs, seed=args.seed)
    write_atomic(out, json.dumps(rows, indent=1) + "\n")
    table = faultmatrix.markdown(rows)
    print(table, end="")
    if args.doc and not faultmatrix.write_doc(Path(args.doc), table):
        raise InputError(f"--doc {args.doc}: no fault-matrix markers ({faultmatrix.BEGIN})")
    return 0 if all(r["detected"] for r in rows) else 1
