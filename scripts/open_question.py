"""The paper's open question (docs/diagnose.md): which extension, at which size, makes the simulation
gains of Table 4 unflyable and the flight gains of Table 6 flyable?

Flies the `step_roll` scenario (figure 14: hover at 1.5 m, a +5 degree roll step) with Table 4 and
Table 6, through perfect state feedback (the paper's own simulation) and through the full onboard
path (simulated sensors, drivers, the "flight" estimator), with an actuation delay or a motor lag of
increasing size hidden in the plant, and records the largest true roll or pitch angle over three
noise seeds (60 degrees = crash). Writes the figure and the numbers beside it (.json).

    python scripts/open_question.py [--out docs/open-question.png] [--quick]
    python scripts/open_question.py --params paper-as-flown --out docs/open-question-as-flown.png --seeds 1
    python scripts/open_question.py --from NUMBERS.json --table     the numbers of a run (the .json beside
                                                            its figure) as Markdown tables (docs/diagnose.md's blocks)

On a model that already carries `motor_dynamics` (the as-flown file), the motor-lag sweep replaces its
time constant instead of adding a second lag.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path

import numpy as np

from flightctl.params import TABLE4, EffectSpec, load
from flightctl.sim import causes
from flightctl.sim.docs import table as markdown_table
from flightctl.sim.progress import Progress
from flightctl.sim.flights.run import fly
from flightctl.sim.flights.scenarios import SCENARIOS

CRASH_DEG = 60.0
SIZES_MS = {"actuation_delay": [0, 1, 2, 3, 4, 5, 6, 7.5, 10, 15, 20, 30, 35, 40, 45, 50],
            "motor_lag": [0, 2, 4, 6, 8, 10, 15, 20, 30, 40, 50, 60, 70, 80, 100]}
SEEDS = (0, 1, 2)   # sensor-noise seeds; a case counts by its worst flight
PARAM = {"actuation_delay": "delay", "motor_lag": "tau"}
CASES = [("Table 4", "truth"), ("Table 6", "truth"), ("Table 4", "flight"), ("Table 6", "flight"),
         ("Table 4", "paper"), ("Table 6", "paper")]


def one(gains: str, path: str, cause: str, ms: float, log: Path, seed: int = 0, model: str | None = None) -> float:
    params = load(model, TABLE4 if gains == "Table 4" else None)
    eff = (causes.make(cause, **{PARAM[cause]: ms / 1e3}),) if ms > 0 else ()
    if cause == "motor_lag" and any(e.cause == "motor_dynamics" for e in params.effects):
        tau = max(ms, 1.0) / 1e3     # the model's own rotor lag, at the size swept
        params = dataclasses.replace(params, effects=tuple(
            EffectSpec(e.cause, (("tau", tau),), e.source) if e.cause == "motor_dynamics" else e
            for e in params.effects))
        eff = ()
    kw = {"truth": True} if path == "truth" else {"estimator": path}
    try:
        f = fly(SCENARIOS["step_roll"](), params, log, effects=eff, noise=True, seed=seed, **kw)
    except (ValueError, OverflowError):      # the state diverged to NaN/inf: a crash
        return CRASH_DEG
    roll = np.degrees(np.abs(np.concatenate([f.log["true_roll"], f.log["true_pitch"]])))
    worst = float(np.nanmax(roll)) if roll.size else CRASH_DEG
    return CRASH_DEG if f.crashed else min(worst, CRASH_DEG)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0].replace("\n", " "))
    ap.add_argument("--out", default="docs/open-question.png", help="the figure (PNG); its numbers go beside it as .json")
    ap.add_argument("--quick", action="store_true", help="three sizes per effect (a smoke run)")
    ap.add_argument("--replot", action="store_true", help="redraw the figure from the .json beside it")
    ap.add_argument("--table", action="store_true", help="print the .json beside the figure as Markdown tables")
    ap.add_argument("--params", help="parameter file or shipped name (default: the paper's base model)")
    ap.add_argument("--seeds", type=int, default=len(SEEDS), help="noise seeds per case (default 3)")
    ap.add_argument("--from", dest="source", metavar="NUMBERS.json",
                    help="the numbers --table prints and --replot draws (default: the .json beside --out)")
    args = ap.parse_args(argv)
    source = Path(args.source) if args.source else Path(args.out).with_suffix(".json")
    if args.table:
        print(table(json.loads(source.read_text())))
        return 0
    if args.replot:
        plot(json.loads(source.read_text()), args.out)
        return 0
    log = Path(args.out).with_suffix(".tmp.csv")
    results = {}
    sweeps = {cause: sizes[::5] if args.quick else sizes for cause, sizes in SIZES_MS.items()}
    progress = Progress(sum(map(len, sweeps.values())) * len(CASES))
    for cause, sizes in sweeps.items():
        for gains, path in CASES:
            row = []
            for ms in sizes:
                row.append(max(one(gains, path, cause, ms, log, seed, args.params)
                               for seed in SEEDS[:args.seeds]))
                progress.step(f"{cause} {gains} {path} {ms:.1f} ms: max tilt {row[-1]:.1f} deg")
            results[f"{cause}|{gains}|{path}"] = dict(zip(map(str, sizes), row))
    log.unlink(missing_ok=True)
    Path(args.out).with_suffix(".json").write_text(json.dumps(results, indent=1) + "\n")
    plot(results, args.out)
    return 0


def table(results: dict) -> str:
    """The largest roll or pitch angle of each case, per effect size: one Markdown table per effect."""
    out = []
    for cause in SIZES_MS:
        rows = [results[f"{cause}|{gains}|{path}"] for gains, path in CASES]
        out += markdown_table([f"{cause} {PARAM[cause]} [ms]", *(f"{g}, {p}" for g, p in CASES)],
                              [[str(size), *("crash" if r[size] >= CRASH_DEG else f"{r[size]:.1f}" for r in rows)]
                               for size in rows[0]])
        out.append("")
    out.append(f"The largest true roll or pitch angle in degrees over the step (`crash`: {CRASH_DEG:g} or more); "
               "truth: perfect state feedback; flight, paper: the full onboard path with that estimator.")
    return "\n".join(out)


def plot(results: dict, out: str) -> None:
    from flightctl.sim.plots import figure, figure_legend, save
    fig, axes = figure(1, 2, size=(9, 4.2), sharey="row")
    axes = axes[0]
    style = {"truth": "-", "flight": "--", "paper": ":"}
    label = {"truth": "perfect state feedback", "flight": "full path, flight estimator",
             "paper": "full path, paper estimator"}
    color = {"Table 4": "tab:red", "Table 6": "tab:blue"}
    for ax, cause in zip(axes, SIZES_MS):
        for gains, path in CASES:
            r = results[f"{cause}|{gains}|{path}"]
            ax.plot([float(s) for s in r], list(r.values()), style[path], marker="o", ms=3, color=color[gains],
                    label=f"{gains}, {label[path]}")
        ax.axhline(CRASH_DEG, color="k", lw=0.5)
        ax.set_xlabel(f"{cause} {PARAM[cause]} [ms] (linear to 10, then logarithmic)", fontsize=8)
        ax.set_yscale("log")
        ax.set_xscale("symlog", linthresh=10.0, linscale=1.5)
        ticks = [0, 2, 4, 6, 8, 10, 20, 50, 100]
        ax.set_xticks([x for x in ticks if x <= max(SIZES_MS[cause])])
        ax.set_xticklabels([str(x) for x in ticks if x <= max(SIZES_MS[cause])])
        ax.set_xlim(0, max(SIZES_MS[cause]) * 1.05)
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("largest roll/pitch in a 5 deg roll step [deg]\n(60 = crash)", fontsize=8)
    figure_legend(fig, axes[0], ncol=3)
    fig.suptitle("Which hidden effect makes Table 4 unflyable and Table 6 flyable? (step_roll, figure 14)",
                 fontsize=9)
    save(fig, out, dpi=80)
    print(f"wrote {out}", file=sys.stderr)


if __name__ == "__main__":
    sys.exit(main())
