"""Fly a scenario: the onboard loop against the simulated board (sim/board.py), lock-step,
writing the contract flight log plus the simulator's true state in `true_*` columns (which diagnose
never reads)."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from flightctl import __version__
from flightctl.boards import BoardOptions
from flightctl.control.controller import FlightController
from flightctl.logfile import MAG_COLUMNS, FlightLogWriter, Table
from flightctl.loop import FlightLoop, FlightResult
from flightctl.params import Params, dumps
from flightctl.sim.board import SIM_CALIBRATE_S, open_board
from flightctl.sim.devices import SensorNoise, TruthEstimator, TruthRangefinder
from flightctl.sim.scenarios import Scenario


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
    board = open_board(params, BoardOptions(seed=seed, effects=tuple(effects), substeps=substeps,
                                            noise=SensorNoise() if noise else SensorNoise.off()))
    hal, world = board.hal, board.world
    truth_est = None
    if truth:
        truth_est = TruthEstimator(world)
        hal.rangefinder = TruthRangefinder(world)
    meta = {"software": f"flightctl {__version__}", "board": board.name, "scenario": scenario.name,
            "path": "perfect state feedback" if truth else f"full onboard path ({estimator} estimator)",
            "calibrate_s": calibrate_s, **board.meta, "params": dumps(params)}
    log = FlightLogWriter(log_path, meta, extra=MAG_COLUMNS + board.extra_columns, keep=True)
    scenario.plan.restart()
    loop = FlightLoop(hal, params, scenario.plan, log, FlightController(params, truth_est, estimator),
                      calibrate_s=calibrate_s, extra_row=board.extra_row)
    result = loop.run()
    board.close()
    return Flight(scenario, log.table(), result, world.plant.touchdowns, 0.0)
