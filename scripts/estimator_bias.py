"""The estimator's bias in a held bank on `paper-as-flown` (issue 37; docs/as-flown.md), taken apart: the
paper flight with Table 6 through the full onboard path, one term of the sensors switched on at a time,
its four held banks' bias (the true angle less the estimate over each bank's last second,
sim/sweeps/judge.py) against the truth the vehicle's own estimate claims (its held error); then which of
the Monte Carlo's ranges its stored bias follows (docs/as-flown-mc.json, no flight).

    python scripts/estimator_bias.py [--seeds 4] [--doc docs/as-flown.md]

tests/sim/flights/test_estimator_bias.py holds the two causes it finds on short flights.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import statistics
from pathlib import Path

import numpy as np

from flightctl.params import GAIN_SETS, EffectSpec, load
from flightctl.sim.docs import marked, publish
from flightctl.sim.flights.run import fly
from flightctl.sim.flights.scenarios import SCENARIOS
from flightctl.sim.sweeps import judge, montecarlo

ROOT = Path(__file__).resolve().parents[1]
BEGIN, END = marked("estimator bias")
BANKS = ((0, 1.0), (2, -1.0), (4, 1.0), (6, -1.0))   # (step index, sign): the +-5 degree banks of roll, pitch
QUIET = {"accel_vibration": 0.0, "gyro_broadband": 0.0, "gyro_vibration": 0.0}


def _variants(p):
    """(label, parameters, noise, seeded): the file's vehicle with one sensor term at a time."""
    r = dataclasses.replace
    sensors = lambda **kw: r(p, sensors=r(p.sensors, **{**QUIET, **kw}))   # noqa: E731
    k_lo = next(lo for c, n, lo, hi in montecarlo.ranged(p) if (c, n) == ("rotor_drag", "k"))
    weak = r(p, effects=tuple(EffectSpec(e.cause, tuple((n, k_lo if n == "k" else v) for n, v in e.parameters),
                                         e.source, e.ranges) if e.cause == "rotor_drag" else e for e in p.effects))
    bb_hi = next(hi for c, n, lo, hi in montecarlo.ranged(p) if n == "gyro_broadband")
    av_hi = next(hi for c, n, lo, hi in montecarlo.ranged(p) if n == "accel_vibration")
    s = p.sensors
    return [
        (f"no sensor noise: the drag-lagged tilt alone, k = {_k(p):.2f} N s/m", p, False, False),
        (f"no sensor noise, k = {k_lo:.2f} (the range's weak end)", weak, False, False),
        ("+ the chip (its noise, offsets, warm-up; the calibration)", sensors(), True, True),
        (f"+ the gyro's broadband noise, {s.gyro_broadband:.3f} rad/s (nominal)", sensors(gyro_broadband=s.gyro_broadband),
         True, True),
        (f"+ the gyro's broadband noise, {bb_hi:.2f} rad/s (top)", sensors(gyro_broadband=bb_hi), True, True),
        (f"+ the accelerometer's rotor lines, {s.accel_vibration:.2f} m/s^2 (nominal)",
         sensors(accel_vibration=s.accel_vibration), True, True),
        (f"+ the accelerometer's rotor lines, {av_hi:.1f} m/s^2 (top)", sensors(accel_vibration=av_hi), True, True),
        ("the file's nominal vehicle, every term", p, True, True),
        ("the same without the in-flight correction (tau_tilt_air = 0)",
         r(p, filters=r(p.filters, tau_tilt_air=0.0)), True, True)]


def _k(p) -> float:
    return next(dict(e.parameters)["k"] for e in p.effects if e.cause == "rotor_drag")


def _banks(params, noise: bool, seed: int) -> tuple[list[float], list[float]]:
    sc = SCENARIOS["paper"]()
    flight = fly(sc, params, os.devnull, seed=seed, noise=noise)
    if flight.outcome != "landed upright":
        raise SystemExit(f"estimator_bias: seed {seed}: {flight.outcome}")
    figs = judge.step_figures(flight.log, sc.steps, flight.t_arm)
    return [float(figs[i]["bias"]) * sign for i, sign in BANKS], [float(f["held"]) for f in figs[:8]]


def measure(seeds: int) -> list[tuple[str, float, float, float, float]]:
    """Per variant: (label, the banks' bias in their direction, mean; its part beyond the noise-free
    drag-lagged one, rms; the worst |bias| of the 8 bank steps, median over seeds; the worst held
    error by its own estimate)."""
    p = load("paper-as-flown", GAIN_SETS["table6"])
    rows, clean = [], None
    for label, params, noise, seeded in _variants(p):
        banks, held = zip(*(_banks(params, noise, s) for s in (range(1, seeds + 1) if seeded else (1,))))
        if clean is None:
            clean = banks[0]
        ref = clean if params.filters.tau_tilt_air > 0.0 else [0.0] * len(clean)   # no correction: no drag part
        extra = [b - c for bs in banks for b, c in zip(bs, ref)] if seeded else [0.0]
        worst = statistics.median(max(abs(x) for x in bs) for bs in banks)
        rows.append((label, float(np.mean(banks)), math.sqrt(sum(e * e for e in extra) / len(extra)),
                     worst, max(abs(h) for hs in held for h in hs)))
    return rows


def following(path: Path = ROOT / "docs" / "as-flown-mc.json") -> list[tuple[str, float]]:
    """Spearman's rank correlation of each draw's worst bank bias (Table 6, where it flew) with each range."""
    from scipy.stats import spearmanr
    rows = [r for r in json.loads(path.read_text())["draws"] if r["table6"]["flies"]]
    bias = [max(r["table6"]["roll"]["bias_deg"], r["table6"]["pitch"]["bias_deg"]) for r in rows]
    out = [(key, float(spearmanr([r["draw"][key] for r in rows], bias)[0])) for key in rows[0]["draw"]]
    return sorted(out, key=lambda kv: -abs(kv[1]))


def render(rows, seeds: int, corr) -> str:
    lines = [f"`python scripts/estimator_bias.py --seeds {seeds}`: the paper flight with Table 6 through the full "
             f"onboard path, seeds 1-{seeds} (one flight where nothing is random); bias: the true angle less the "
             f"estimate over each held bank's last second, taken in the bank's direction; held error: the estimate "
             f"less the command there (what the paper's figures show).", "",
             "| sensors | bias in the bank's direction, mean (deg) | beyond the drag-lagged part, rms (deg) | "
             "worst of the 8 bank steps, median (deg) | worst held error by its own estimate (deg) |",
             "|---|---|---|---|---|"]
    for label, mean, extra, worst, held in rows:
        lines.append(f"| {label} | {mean:.2f} | {extra:.2f} | {worst:.2f} | {held:.2f} |")
    lines += ["", "The Monte Carlo's stored bias (Table 6's worst bank, docs/as-flown-mc.json) follows, by Spearman's "
              "rank correlation over its draws: " + ", ".join(f"`{k}` {v:+.2f}" for k, v in corr[:4]) + "."]
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--doc", help="write the block into this copy of docs/as-flown.md")
    args = ap.parse_args()
    if args.seeds < 1:
        ap.error("--seeds: at least 1")
    publish(render(measure(args.seeds), args.seeds, following()), args.doc, BEGIN, END)


if __name__ == "__main__":
    main()
