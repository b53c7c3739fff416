"""Fly a scenario: the onboard loop against the simulated quadcopter, writing the contract flight log
(plus the simulator's true state in `true_*` columns, which diagnose never reads)."""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from flightctl import __version__
from flightctl.boards import sim_board
from flightctl.control.controller import FlightController
from flightctl.logfile import MAG_COLUMNS, FlightLogWriter, Table
from flightctl.loop import FlightLoop, FlightResult
from flightctl.params import Params, dumps
from flightctl.sim.devices import SensorNoise, TruthEstimator, TruthRangefinder
from flightctl.sim.scenarios import Scenario

TRUTH_COLUMNS = ("true_x", "true_y", "true_z", "true_roll", "true_pitch", "true_yaw")
SIM_CALIBRATE_S = 2.0   # the paper sat still for 60 s; the simulated gyro bias is constant


@dataclass
class Flight:
    scenario: Scenario
    log: Table
    result: FlightResult
    touchdowns: list[tuple[float, float]]
    t_arm: float   # log time of arming (the log starts there)


def fly(scenario: Scenario, params: Params, log_path: str | Path, effects=(), noise: bool = True,
        seed: int = 0, truth: bool = False, substeps: int = 2, calibrate_s: float = SIM_CALIBRATE_S,
        estimator: str = "flight") -> Flight:
    """`truth=True` is perfect state feedback: the controller sees the true attitude and altitude at
    every loop (the paper's own simulation); otherwise the full onboard path."""
    hal, world = sim_board(params, effects, SensorNoise() if noise else SensorNoise.off(), seed, substeps)
    truth_est = None
    if truth:
        truth_est = TruthEstimator(world)
        hal.rangefinder = TruthRangefinder(world)
    x = world.plant

    def true_state():
        s = x.x
        return s[0], s[1], s[2], s[6], s[7], (s[8] + math.pi) % (2 * math.pi) - math.pi

    meta = {"software": f"flightctl {__version__}", "board": "sim", "scenario": scenario.name,
            "path": "perfect state feedback" if truth else f"full onboard path ({estimator} estimator)",
            "calibrate_s": calibrate_s, "params": dumps(params)}
    log = FlightLogWriter(log_path, meta, extra=MAG_COLUMNS + TRUTH_COLUMNS, keep=True)
    scenario.plan.restart()
    loop = FlightLoop(hal, params, scenario.plan, log, FlightController(params, truth_est, estimator),
                      calibrate_s=calibrate_s, extra_row=true_state)
    result = loop.run()
    return Flight(scenario, log.table(), result, x.touchdowns, 0.0)
