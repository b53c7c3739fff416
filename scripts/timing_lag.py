"""Does a flight prefer a first-order motor lag and a short delay to the long pure delay the base model is
identified at (issue 42; basemodel.py `_timing`, `timing_objective`)? Per log: the best pure delay on the 0-60 ms
part of the identification's grid, and the best (lag, delay) pair on a grid of lags 5-40 ms and delays 0-35 ms,
with the objective's difference (sum over the channels of log RSS: 0.01 is a 1 % smaller residual on one
channel). Default logs: those of the docs block steps-predicted.

    python scripts/timing_lag.py [LOG ...]
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
FLIGHTS = ROOT / ".." / "shared" / "data" / "real" / "flights"
DEFAULT = (FLIGHTS / "betaflight" / "LOG00037.BFL", FLIGHTS / "betaflight" / "btfl_002.bbl",
           ROOT / "tests" / "data" / "pid-analyzer" / "example_smooth_tune.BBL",
           ROOT / "tests" / "data" / "pid-analyzer" / "better_tune.BBL")
DELAYS = np.arange(0.0, 0.0601, 0.005)
LAGS = (0.005, 0.01, 0.015, 0.02, 0.03, 0.04)
SHORT = np.arange(0.0, 0.0351, 0.0025)


def main(argv: list[str]) -> int:
    from flightctl import params as paramfile
    from flightctl.sim.diagnose.basemodel import identification_set, timing_objective, yaw_drag_column
    from flightctl.sim.diagnose.dataset import LOWPASS_HZ
    from flightctl.sim.diagnose.verdict import _files
    from flightctl.sim.logs import read_foreign
    a = paramfile.load(None).airframe
    print("| log | best pure delay (ms) | best lag + delay (ms) | objective: pure minus lag + delay |")
    print("|---|---|---|---|")
    for path in [Path(p) for p in argv] or DEFAULT:
        files = _files(read_foreign(str(path))[:1], a, [], lambda *_: None)
        ds = identification_set(files, LOWPASS_HZ)
        drag = yaw_drag_column(ds)
        pure, d = min((timing_objective(ds, drag, float(d)), float(d)) for d in DELAYS)
        both, lag, d2 = min((timing_objective(ds, drag, float(s), lag), lag, float(s)) for lag in LAGS for s in SHORT)
        print(f"| {path.name} | {1e3 * d:.1f} | {1e3 * lag:.0f} + {1e3 * d2:.1f} | {pure - both:+.4f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
