"""How often the fleet report finds a weakened motor, by fleet size and change size, and how often it names
one on a healthy vehicle (issue 46, item 1; docs/fleet.md, "How often it finds a change").

    python scripts/fleet_detection.py [--trials 30] [--seed 46] [--doc docs/fleet.md]

1. Calibrate the rows' draw on flown and diagnosed flights: three vehicles of six 22 s flights each
   (sim/sweeps/fleet_flown.py, ArduCopter DataFlash at the default rates), one motor of one vehicle at
   CAL_SCALE of its thrust from a drawn flight on, `flightctl diagnose --corpus` run on them as a user runs
   it; from its results table, the motor shares' standard errors (their log's mean and spread), the spread
   between flights of the healthy vehicles (the no-change fit's tau, trends.py, the median over their
   shares) and the weak motor's scale read back from its share's ratio (report.share_scale).
2. Draw fleets of three vehicles of 5, 10, 20 and 40 flights' rows (sim/sweeps/fleet_drawn.py: the shares
   with their standard errors, drawn as the calibration found them; flying them all would take hours),
   one vehicle's motor losing 5, 10 or 20 % of its thrust from a drawn flight on, or none (the null rows),
   `trials` fleets a cell, and build the fleet report of each (report.build: the grouping, the test, Holm's
   correction and the physical check). A change is found when its vehicle and motor are named with the
   onset within a flight; a false finding is a motor named on a healthy vehicle. The rows hold the shares
   only: the family is each vehicle's motor finding (a real report also tests the battery and the vibration,
   which makes Holm's correction stricter). Done at the calibrated noise and at NOISIER times it (the
   standard errors and the spread: a shorter, windier flight's).
"""
from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

BEGIN, END = "<!-- fleet-detection: begin -->", "<!-- fleet-detection: end -->"
FLIGHTS = (5, 10, 20, 40)
SIZES = (0.05, 0.10, 0.20)
VEHICLES = 3
CAL_SCALE = 0.85
NOISIER = 10.0


def calibrate(seed: int) -> dict:
    """The rows' noise (sim/sweeps/fleet_drawn.py's Noise) from flown and diagnosed flights, and the weak motor read back."""
    from flightctl.sim.sweeps.fleet_flown import simulate_fleet
    from flightctl.sim.sweeps.fleet_drawn import Noise
    from flightctl.sim.diagnose.fleet.report import build, share_scale
    from flightctl.sim.diagnose.fleet.trends import Fit
    with tempfile.TemporaryDirectory() as tmp:
        truth = simulate_fleet(Path(tmp) / "logs", np.random.default_rng(seed), vehicles=3, flights=6, seconds=22.0,
                               aging=False, weak_scale=(CAL_SCALE, CAL_SCALE))
        done = subprocess.run([sys.executable, "-P", "-m", "flightctl.cli", "diagnose", "--corpus", f"{tmp}/logs",
                               "--json", f"{tmp}/all.json", "--results", f"{tmp}/rows.jsonl", "--quiet", "--jobs", "2"],
                              capture_output=True, text=True)
        if done.returncode != 0:
            raise SystemExit(f"fleet_detection: diagnose --corpus failed: {done.stderr.strip()}")
        rows = [json.loads(line) for line in Path(f"{tmp}/rows.jsonl").read_text().splitlines()]
    rep = build(rows)
    weak = truth["weak"]
    uid = truth["vehicles"][weak["vehicle"]]["uid"]
    log_se, taus = [], []
    for v in rep["vehicles"]:
        for i in range(1, 5):
            s = v["series"][f"share_{i}"]
            log_se += [math.log(e) for e in s["stderr"]]
            if v["vehicle"] != uid:
                taus.append(Fit(s["value"], s["stderr"]).change.tau_null)
    v = next(v for v in rep["vehicles"] if v["vehicle"] == uid)
    y = v["series"][f"share_{weak['motor']}"]["value"]
    k = weak["onset"]
    return {"noise": Noise(float(np.mean(log_se)), float(np.std(log_se)), float(np.median(taus))),
            "scale": weak["scale"], "read": share_scale(float(np.mean(y[k:]) / np.mean(y[:k]))),
            "flights": len(rows)}


def measure(trials: int, seed: int) -> dict:
    from flightctl.sim.sweeps.fleet_drawn import Noise, draw_fleet, judge
    from flightctl.sim.diagnose.fleet.report import build
    cal = calibrate(seed)
    n0 = cal["noise"]
    levels = {"as flown": n0, f"{NOISIER:g} x": Noise(n0.se_log_mean + math.log(NOISIER), n0.se_log_sd, NOISIER * n0.tau)}
    rng = np.random.default_rng(seed)
    out = {}
    for name, noise in levels.items():
        for n in FLIGHTS:
            for size in (0.0,) + SIZES:
                got = [judge(build(rows), truth) for rows, truth in
                       (draw_fleet(rng, VEHICLES, n, size, noise) for _ in range(trials))]
                out[name, n, size] = {"found": sum(g["found"] for g in got), "false": sum(g["false"] for g in got),
                                      "healthy": sum(g["healthy"] for g in got),
                                      "fleets_false": sum(g["false"] > 0 for g in got), "trials": trials}
    return {"cal": cal, "levels": levels, "cells": out, "trials": trials}


def markdown(m: dict) -> str:
    from flightctl.sim.docs import table
    from flightctl.sim.diagnose.fleet.trends import ALPHA
    cal, n0 = m["cal"], m["cal"]["noise"]
    pct = lambda k, n: f"{100 * k / n:.3g} % ({k}/{n})"
    lines = [f"Calibrated on {cal['flights']} flown and diagnosed 22 s flights (sim/sweeps/fleet_flown.py, ArduCopter DataFlash "
             f"at the default rates): a share's standard error {100 * math.exp(n0.se_log_mean):.3g} % (log spread "
             f"{n0.se_log_sd:.2f}), the spread between a healthy vehicle's flights {100 * n0.tau:.2g} %, a motor drawn "
             f"at {cal['scale']:g} of its thrust read back from its share as {cal['read']:.3f}. Each cell: "
             f"{m['trials']} fleets of {VEHICLES} vehicles' drawn rows (sim/sweeps/fleet_drawn.py), the fleet report "
             f"built on each; found: the vehicle and motor named, the onset within a flight; false: a motor named on "
             f"a healthy vehicle (the stated rate: {100 * ALPHA:g} % of fleets with no change).", ""]
    rows = []
    for name in m["levels"]:
        for n in FLIGHTS:
            c = m["cells"]
            null = c[name, n, 0.0]
            false = sum(c[name, n, s]["false"] for s in (0.0,) + SIZES)
            healthy = sum(c[name, n, s]["healthy"] for s in (0.0,) + SIZES)
            rows.append([name, str(n)] + [pct(c[name, n, s]["found"], c[name, n, s]["trials"]) for s in SIZES]
                        + [pct(null["fleets_false"], null["trials"]), pct(false, healthy)])
    header = ["noise", "flights a vehicle"] + [f"found: {100 * s:.0f} % weaker" for s in SIZES] + [
        "null rows: fleets with a false finding", "healthy vehicles named (every row)"]
    return "\n".join(lines + table(header, rows))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=30, help="fleets drawn a cell (default 30)")
    ap.add_argument("--seed", type=int, default=46)
    ap.add_argument("--doc", help="write the block into this Markdown file (between its markers)")
    a = ap.parse_args(argv)
    if a.trials < 1:
        ap.error("--trials: at least 1")
    text = markdown(measure(a.trials, a.seed))
    from flightctl.sim.docs import publish
    publish(text, a.doc, BEGIN, END)
    return 0


if __name__ == "__main__":
    sys.exit(main())
