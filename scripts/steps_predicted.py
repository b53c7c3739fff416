"""The predicted steps beside the measured ones (docs/steps.md, "Predicted and measured"): each shipped log
with a measured rate step (Betaflight's, PX4's), the base model identified on its first half predicting its
second half's steps (`predict.held_out`); PID-Analyzer's CS110 pair (tests/data/pid-analyzer), each tune's
log predicted by the model of the other with its own gains (`predict.cross`); and two `flightctl sim excite`
flights of the paper's vehicle (seeds 0 and 1), the first's model flying the second's attitude PIDs (eq. 24),
where the truth is known, and a simulated flight of steps in both halves predicted as a log is (held out).
One row per prediction and axis.

    python scripts/steps_predicted.py
"""
from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FLIGHTS = ROOT / ".." / "shared" / "data" / "real" / "flights"
CS110 = ROOT / "tests" / "data" / "pid-analyzer"
HELD_OUT = ((FLIGHTS / "betaflight" / "LOG00037.BFL", 1), (FLIGHTS / "betaflight" / "btfl_002.bbl", 1),
            (CS110 / "example_smooth_tune.BBL", 1), (CS110 / "better_tune.BBL", 1),
            (FLIGHTS / "px4" / "quadrotor_local.ulg", 1))
PLAN = ROOT / "tests" / "data" / "plans" / "steps-both-halves.toml"
CROSS = (("example_smooth_tune.BBL", "better_tune.BBL"), ("better_tune.BBL", "example_smooth_tune.BBL"))
AXIS = {"x": "roll", "y": "pitch", "z": "yaw"}


def _pair(e: dict, k: str, scale: float) -> str:
    f = lambda x: "-" if x is None else f"{scale * x:.0f}"
    lo, hi = e[k]["spread"]
    return f"{f(e[k]['predicted'])} ({f(e[k]['measured'])}, {f(lo)}-{f(hi)})"


def rows(name_id: str, name_ck: str, out: dict) -> list[list[str]]:
    L = []
    for a in "xyz":
        e = out[a]
        if "why" in e:
            L.append([name_id, name_ck, AXIS[a], "", "", "", "", e["why"].split("; fly next time")[0]])
            continue
        L.append([name_id, name_ck, AXIS[a], _pair(e, "delay_s", 1e3), _pair(e, "rise_s", 1e3),
                  _pair(e, "overshoot", 100), f"{e['step_error']:.2f}",
                  "agrees" if e["agrees"] else (e["points_to"] or "the curves' shape").split(": ", 1)[-1]
                  .replace(" (the gain from the commands to the angular acceleration, k_axis and h2)", "")
                  .split(" (")[0]])
    return L


def _sim(a, predict, controller) -> list[list[str]]:
    """The two simulated excite flights: identified on seed 0, its attitude steps predicted on seed 1; then a flight
    of steps in both halves (tests/data/plans/steps-both-halves.toml), its second half by its first's model."""
    import contextlib
    import io
    import tempfile

    from flightctl.cli import main as cli
    from flightctl.logfile import read_flight_log
    with tempfile.TemporaryDirectory() as d:
        logs = [Path(d) / f"excite{s}.csv" for s in (0, 1)]
        for seed, log in enumerate(logs):
            with contextlib.redirect_stdout(io.StringIO()):      # the flights' own summaries are not the table's
                code = cli(["sim", "excite", "--seed", str(seed), "--log", str(log), "--no-plot", "--quiet"])
            if code not in (0, 1):
                raise SystemExit(f"flightctl sim excite --seed {seed} failed")
        both = Path(d) / "both.csv"
        with contextlib.redirect_stdout(io.StringIO()):
            code = cli(["sim", "--plan", str(PLAN), "--log", str(both), "--no-plot", "--quiet"])
        if code != 0:
            raise SystemExit(f"flightctl sim --plan {PLAN.name} failed")
        A, B, C = (read_flight_log(p, min_rows=10) for p in logs + [both])
        pred, _ = predict.cross(A, B, controller.of_table(B), a)
        held, _ = predict.held_out(C, controller.of_table(C), a)
    cut = held["x"]["identified_on"].rsplit(" ", 2)[-2]
    return (rows("flightctl sim excite, seed 0", "seed 1 (attitude loop, Table 6's gains)", pred)
            + rows(f"flightctl sim {PLAN.stem} to {cut} s", f"its rest, from {cut} s (attitude loop)", held))


def main(argv: list[str]) -> int:
    from flightctl import params as paramfile
    from flightctl.sim.docs import table
    from flightctl.sim.diagnose import predict
    from flightctl.sim.logs import controller, read_foreign
    a = paramfile.load(None).airframe
    out = []
    tables = {}
    for path, index in HELD_OUT:
        tab = read_foreign(str(path))[index - 1]
        tables[path.name] = tab
        pred, _ = predict.held_out(tab, controller.of_table(tab), a)
        cut = pred["x"]["identified_on"].rsplit(" ", 2)[-2]
        out += rows(f"{path.name} to {cut} s", f"its rest, from {cut} s", pred)
    for ident, check in CROSS:
        pred, _ = predict.cross(tables[ident], tables[check], controller.of_table(tables[check]), a)
        out += rows(ident, f"{check} (its own gains)", pred)
    out += _sim(a, predict, controller)
    header = ["identified on", "checked on", "axis", "delay ms predicted (measured, spread)",
              "rise 10-90 % ms predicted (measured, spread)", "overshoot % predicted (measured, spread)",
              "step error", "agrees, or what it points to"]
    print("\n".join(table(header, out)))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
