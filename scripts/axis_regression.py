"""An independent check of the base model's roll and pitch effectiveness (issue 42, part 1): per log, the
angular acceleration (the gyro's difference, a zero-phase 2nd-order Butterworth at 12 Hz forward and back)
regressed on the commanded torque through the log's layout (sum_i y_i P_i^2 for roll, -sum_i x_i P_i^2 for
pitch: eq. 26 with h2 = 0, eq. 25's structure), the commands DELAY_S late, low-passed alike, with an
intercept per block; over the airborne rows diagnose uses (`data.load_file`), cut into 8 contiguous blocks.
The regression is `flightctl.sim.diagnose.axischeck.regression` (its docstring: the method).
Printed per axis: the slope's sign in each block, its R^2, and the block-jackknife t of the slope (the
slope over the delete-one-block jackknife's standard error), beside the tool's t (the base model's
effectiveness over its jackknife error, `basemodel.identify`), or the tool's refusal.

    python scripts/axis_regression.py [LOG[#index] ...]     (default: the shared real flights and tests/data)
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
FLIGHTS = ROOT / ".." / "shared" / "data" / "real" / "flights"
DEFAULT = [FLIGHTS / "betaflight" / "LOG00037.BFL", FLIGHTS / "betaflight" / "btfl_002.bbl",
           FLIGHTS / "betaflight" / "btfl_all.bbl", *sorted((FLIGHTS / "indiflight").glob("*.BFL")),
           ROOT / "tests" / "data" / "pid-analyzer" / "better_tune.BBL",
           ROOT / "tests" / "data" / "pid-analyzer" / "example_smooth_tune.BBL",
           ROOT / "tests" / "data" / "ardupilot" / "log171.bin"]


def _tool(tab, a) -> tuple[dict | None, str]:
    """The tool's (t per axis, or None) and its refusal ('' when it identified)."""
    from flightctl.errors import InputError
    from flightctl.sim.diagnose.basemodel import identify
    from flightctl.sim.diagnose.rotorspeed import rotor_speed_lag
    from flightctl.sim.diagnose.verdict import _files
    try:
        files = _files([tab], a, [], lambda *_: None)
        v, _ = identify(files, 12.0, lambda *_: None, rotor_speed_lag(files))
    except InputError as e:
        return None, str(e).split(": ", 1)[-1]
    rep = v.identification
    return {n: rep[k]["value"] / rep[k]["stderr"] for n, k in (("roll", "k_p"), ("pitch", "k_q"))}, ""


def main(argv: list[str]) -> int:
    from flightctl import params as paramfile
    from flightctl.errors import InputError
    from flightctl.sim.diagnose.axischeck import regression
    from flightctl.sim.diagnose.data import load_file
    from flightctl.sim.diagnose.dataset import N_BLOCKS
    from flightctl.sim.logs import read_foreign
    a = paramfile.load(None).airframe
    paths = [Path(p) for p in argv] or DEFAULT
    print("| log | axis | blocks with the layout's sign | R^2 | regression t | tool's t | tool's refusal |")
    print("|---|---|---|---|---|---|---|")
    for path in paths:
        name, _, index = str(path).partition("#")
        try:
            tables = read_foreign(name, int(index) if index else None)
        except InputError:
            continue
        for tab in tables:
            try:
                fd = load_file(tab, a)
            except InputError:
                continue
            if fd.airborne.sum() / (1.0 / float(np.median(np.diff(fd.t)))) < 1.0:
                continue
            tool, why = _tool(tab, a)
            for axis, label in enumerate(("roll", "pitch")):
                r = regression([fd], axis)
                t = "" if tool is None else f"{tool[label]:.1f}"
                print(f"| {Path(tab.path).name} | {label} | {r['signs']} of {N_BLOCKS} | {r['r2']:.2f} | "
                      f"{r['t']:.1f} | {t} | {why[:160]} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
