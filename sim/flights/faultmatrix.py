"""`flightctl sim faults --json M.json`: fly every fault `flightctl sim --fault` takes (docs/safety.md) in a
short hover and report, per fault, whether the onboard loop named it (`detected`, `detect_ms` from the
injection to the loop's first event naming it), what it did (`action`: hold, land or stop, from its
events), the outcome on the true state (flightctl/safety.py's crash definition, through
`flightctl.sim.flights.run.judge`) and whether the log reads back whole (`log_intact`).
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from flightctl.errors import InputError
from flightctl.logfile import FLIGHT_COLUMNS, MAG_COLUMNS, read_flight_log
from flightctl.logfile import log_room as flight_log_room
from flightctl.params import Params
from flightctl.plans.plan import Move, Plan
from flightctl.sim.progress import Progress
from flightctl.sim.world import faults
from flightctl.sim.world.board import SIM_CALIBRATE_S, TRUTH_COLUMNS
from flightctl.sim.flights.run import fly
from flightctl.sim.flights.scenarios import scenario

FAULT_AFTER_S = 6.0   # s after arming: in a steady hover at 1 m
HOLD_S = 4.0          # s of hover after the fault

# The loop's event that names each fault (flightctl/loop.py, the drivers' reasons)
NAMED_BY = {"imu_frozen": "IMU frame refused (frozen", "imu_garbage": "IMU frame refused",
            "imu_intermittent": "IMU frame refused", "gyro_saturation": "IMU saturated",
            "accel_zero": "IMU frame refused (accelerometer reads zero",
            "sonar_silent": "altitude lost", "sonar_stuck": "altitude lost",
            "battery_critical": "battery low", "motor_stop": " of its ", "motor_partial": " of its ",
            "cpu_stall": "loop stalled", "log_full": "log write failed"}
OPTIONS = {"cpu_stall": "ms=50", "battery_critical": "cell=3.3", "motor_partial": "share=0.3"}   # the matrix's figures


def hover_plan(fault_after: float = FAULT_AFTER_S, hold: float = HOLD_S) -> Plan:
    """Take off to 1 m (2 s ramp), hold; the fault comes at `fault_after`; land `hold` s later."""
    land = fault_after + hold
    return Plan([Move(0.0, "alt", 1.0, 2.0), Move(land, "alt", 0.0, 3.0)], land + 4.0, "faults",
                f"hover at 1 m, a fault at {fault_after:g} s, land at {land:g} s")


def action(events, t_named: float) -> str:
    """The loop's answer from the event naming the fault on: stop (motors cut), land, or hold."""
    for t, what in events:
        if t < t_named:
            continue
        if what.startswith("stopped:"):
            return "stop"
        if what.endswith(": landing") or what.endswith(": descending"):
            return "land"
        if what.startswith("landed"):
            break
    return "hold"


def log_intact(path: Path, written: int) -> bool:
    """The CSV reads back with the contract reader, with every row the writer wrote and no empty
    required cell."""
    try:
        table = read_flight_log(path, min_rows=1)
    except InputError:
        return False
    cols = ("t", "P1", "P2", "P3", "P4", "gyro_x", "gyro_y", "gyro_z", "acc_x", "acc_y", "acc_z")
    return len(table) == written and all(bool((table[c] == table[c]).all()) for c in cols)


def fly_fault(spec: str, params: Params, log_dir: Path, fault_after: float = FAULT_AFTER_S,
              hold: float = HOLD_S, seed: int = 0) -> dict:
    """One row of the matrix: `spec` is NAME[:k=v] without `at` (set to `fault_after` after arming)."""
    name = spec.partition(":")[0]
    fault = faults.parse(f"{spec}{',' if ':' in spec else ':'}at={fault_after}")   # after arming
    log = log_dir / f"fault-{name}.csv"
    flight = fly(scenario(hover_plan(fault_after, hold)), params, log, faults=[fault], seed=seed)
    res = flight.result
    t_fault = fault_after                                                     # log time of injection
    t_named = next((t for t, what in res.events if NAMED_BY[name] in what and t >= t_fault - 1e-9), None)
    outcome = "crashed" if flight.crashed else flight.outcome
    L = flight.log
    on = np.flatnonzero((L["P1"] > 0) | (L["P2"] > 0) | (L["P3"] > 0) | (L["P4"] > 0))
    cut = min(int(on[-1]) + 1, len(L) - 1) if on.size else 0
    return {"fault": spec, "detected": t_named is not None,
            "detect_ms": round(1000 * (t_named - t_fault), 1) if t_named is not None else None,
            "action": action(res.events, t_named) if t_named is not None else "none",
            "outcome": outcome, "why": flight.outcome, "loop": res.reason,
            "log_intact": log_intact(log, len(flight.log) - flight.log_dropped),
            "log_dropped_rows": flight.log_dropped,
            "cut_alt": round(float(L["true_z"][cut]), 3)}   # true altitude (m) when the motors stopped


def log_room(log_dir: Path, params: Params, names=faults.FAULTS) -> None:
    """Refuse a matrix whose flights' logs would not fit on `log_dir`'s disk, before the first flight."""
    seconds = len(list(names)) * (SIM_CALIBRATE_S + hover_plan().duration)
    flight_log_room(log_dir, seconds, params.airframe.loop_hz, len(FLIGHT_COLUMNS + MAG_COLUMNS + TRUTH_COLUMNS),
                    "--logs")


def run_matrix(params: Params, log_dir: Path, names=faults.FAULTS, progress: bool = True, **kw) -> list[dict]:
    """Fly every fault; one progress line per fault on stderr (`progress=False` for tests)."""
    names = list(names)
    bar = Progress(len(names), "faults ") if progress else None
    rows = []
    for n in names:
        rows.append(fly_fault(f"{n}:{OPTIONS[n]}" if n in OPTIONS else n, params, log_dir, **kw))
        if bar:
            bar.step(n)
    return rows


def markdown(rows: list[dict]) -> str:
    lines = ["| fault | detected | detect (ms) | action | outcome | log intact |", "|---|---|---|---|---|---|"]
    for r in rows:
        ms = "-" if r["detect_ms"] is None or not math.isfinite(r["detect_ms"]) else f"{r['detect_ms']:.0f}"
        out = r["why"] if r["outcome"] == "crashed" else r["outcome"]
        lines.append(f"| {r['fault']} | {'yes' if r['detected'] else 'NO'} | {ms} | {r['action']} | {out} | "
                     f"{'yes' if r['log_intact'] else 'no'} |")
    return "\n".join(lines) + "\n"


BEGIN, END = "<!-- fault matrix: begin (written by `flightctl sim faults`) -->", "<!-- fault matrix: end -->"


def write_doc(doc: Path, table: str) -> bool:
    """Replace the table between BEGIN and END in `doc`; False when the markers are absent."""
    from flightctl.sim.docs import write_block
    return write_block(doc, BEGIN, END, table)
