"""Fly a scenario: the onboard loop against the simulated board (sim/world/board.py), lock-step,
writing the contract flight log plus the simulator's true state in `true_*` columns (which diagnose
never reads), and judge the outcome on the true state with the one definition of a crash
(flightctl/safety.py)."""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from flightctl import __version__
from flightctl.boards import BoardOptions
from flightctl.control.controller import FlightController
from flightctl.logfile import MAG_COLUMNS, FlightLogWriter, Table
from flightctl.loop import FlightLoop, FlightResult
from flightctl.params import Params, dumps
from flightctl.safety import LEFT_GROUND_ALT, crash_reason
from flightctl.sim.world.board import SIM_CALIBRATE_S, open_board
from flightctl.sim.world.devices import SensorNoise, TruthEstimator, TruthRangefinder
from flightctl.sim.world.plant import Diverged
from flightctl.sim.flights.scenarios import Scenario


@dataclass
class Flight:
    scenario: Scenario
    log: Table
    result: FlightResult
    touchdowns: list[tuple[float, float]]   # (log time, vertical speed at contact)
    t_arm: float   # log time of arming (the log starts there)
    log_dropped: int = 0                    # rows the log writer could not write
    outcome: str = ""                       # "landed upright", "crashed: ...", "never left the ground", ...
    crashed: bool = False
    flew: bool = True


ON_GROUND = 0.05   # m, true altitude
# s of plan: forking the log's writer costs about 20 ms (a large process: its page tables), which a
# flight this long wins back by formatting its rows off the loop's core (about 10 % of the loop's time)
LOG_CHILD_S = 10.0


def judge(result: FlightResult, log: Table, touchdowns, g: float) -> tuple[str, bool, bool]:
    """(outcome, crashed, flew) on the true state: a crash by flightctl.safety (largest true tilt,
    fastest touchdown), a vehicle cut in the air (it falls: a crash), one that never rose
    LEFT_GROUND_ALT, or one that landed upright."""
    if not len(log):
        return "never armed: " + result.reason, False, False
    z = log["true_z"]
    tilt = float(np.max(np.maximum(np.abs(log["true_roll"]), np.abs(log["true_pitch"]))))
    speed = max((abs(vz) for _, vz in touchdowns), default=0.0)
    stopped = result.reason.removeprefix("stopped: crash").strip(" ()") if result.reason.startswith("stopped: crash") \
        else None
    return judge_figures(float(z[-1]), float(np.nanmax(z)), tilt, speed, stopped, g)


def judge_figures(z_end: float, z_max: float, tilt: float, speed: float, stopped: str | None,
                  g: float) -> tuple[str, bool, bool]:
    """`judge` on a flight's figures: its last and highest true altitude, its largest true tilt, its
    fastest touchdown, and why the loop stopped for a crash of its own (None: it did not); the
    batched simulator (sim/sweeps/batch.py) judges its vehicles with it too."""
    if not math.isfinite(z_end) or z_end > ON_GROUND:             # the motors stopped above the floor
        speed = max(speed, math.sqrt(2 * g * max(z_end, 0.0)) if math.isfinite(z_end) else math.inf)
    why = crash_reason(tilt if math.isfinite(tilt) else math.nan, speed)
    if why is None:
        why = stopped
    if why is not None:
        return f"crashed: {why}", True, bool(z_max >= LEFT_GROUND_ALT)
    if not z_max >= LEFT_GROUND_ALT:
        return f"never left the ground (highest {z_max:.2f} m)", False, False
    return "landed upright", False, True


def unstable_axis(params: Params) -> str:
    """The axis whose derivative term moves its rate most in one loop period (eq. 24 and 25: a torque
    2 l u_phi, 2 l u_theta, 4 g1 u_psi per unit output): above 2 the sampled loop cannot be stable,
    whatever the integrator, as on the real vehicle."""
    a, g = params.airframe, params.gains
    loops = {"roll": (2 * a.l * g.kd_phi / a.Jxx, "Jxx", a.Jxx), "pitch": (2 * a.l * g.kd_theta / a.Jyy, "Jyy", a.Jyy),
             "yaw": (4 * a.g1 * g.kd_psi / a.Jzz, "Jzz", a.Jzz)}
    axis, (k, name, value) = max(loops.items(), key=lambda kv: kv[1][0])
    return (f"the {axis} loop's D term moves its rate by {k * a.dt:.2g} of itself per loop period with "
            f"{name} = {value:g} kg m^2: {'above 2, unstable at ' + format(a.loop_hz, 'g') + ' Hz' if k * a.dt > 2 else 'stable'}")


def fly(scenario: Scenario, params: Params, log_path: str | Path, effects=(), noise: bool = True,
        seed: int = 0, truth: bool = False, substeps: int | None = None, calibrate_s: float = SIM_CALIBRATE_S,
        estimator: str = "flight", telemetry=None, faults=(), plant_airframe=None, interrupt=None) -> Flight:
    """`truth=True` is perfect state feedback: the controller sees the true attitude and altitude at
    every loop (the paper's own simulation); otherwise the full onboard path. `telemetry`: a ground
    station link (flightctl/comms/mavlink.py) the loop streams to and takes commands from. `faults`:
    `flightctl.sim.world.faults.Fault`s, applied to the board's devices and the log; their `at` counts
    from arming, as the log's time does. `plant_airframe`: the simulated vehicle's airframe where
    it is not the one the controller is given (a Monte Carlo draw). `interrupt`: a threading.Event set
    by Ctrl-C (flightctl/cli.py): the loop ends at its next period, the log closed with a `# partial:`
    line."""
    # With a ground station the simulated world runs in real time, as SITL does: the station's
    # clock (heartbeats, commands) and the flight's then agree.
    board = open_board(params, BoardOptions(seed=seed, effects=tuple(effects), substeps=substeps,
                                            noise=SensorNoise() if noise else SensorNoise.off(),
                                            realtime=telemetry is not None, airframe=plant_airframe))
    hal, world = board.hal, board.world
    truth_est = None
    if truth:
        truth_est = TruthEstimator(world)
        hal.rangefinder = TruthRangefinder(world)
    meta = {"software": f"flightctl {__version__}", "board": board.name, "scenario": scenario.name,
            "path": "perfect state feedback" if truth else f"full onboard path ({estimator} estimator)",
            "calibrate_s": calibrate_s, **board.meta, "params": dumps(params)}
    if faults:
        meta["faults"] = ", ".join(f"{f.name} at {f.at:g} s after arming" for f in faults)
    # the log formatted in a child process, off the loop's core (logfile.py), for a plan of LOG_CHILD_S
    # or more, unless the flight runs in real time (a ground station) or a fault must reach the file's
    # writes (log_full)
    log = FlightLogWriter(log_path, meta, extra=MAG_COLUMNS + board.extra_columns, keep=True,
                          process=(scenario.plan.duration >= LOG_CHILD_S and telemetry is None
                                   and not any(f.name == "log_full" for f in faults)))
    armed_at = hal.clock.now() + calibrate_s      # the simulated time the loop arms at (FlightLoop.run)
    for fault in faults:
        replace(fault, at=fault.at + armed_at).apply(hal, world, log)
    scenario.plan.restart()
    loop = FlightLoop(hal, params, scenario.plan, log, FlightController(params, truth_est, estimator),
                      calibrate_s=calibrate_s, extra_row=board.extra_row, telemetry=telemetry, stop=interrupt)
    loop.stop_reason = "interrupted (Ctrl-C)"
    diverged = None
    try:
        result = loop.run()
    except Diverged as e:          # the loop has stopped the motors and closed the log
        result, diverged = loop.result, e
    board.close()
    t_arm = result.t_arm if result.t_arm is not None else calibrate_s
    if diverged is not None:
        result.reason = (f"stopped: the simulation diverged (the plant's state is not finite at t = "
                         f"{diverged.t - t_arm:.2f} s; {unstable_axis(params)})")
    touchdowns = [(t - t_arm, vz) for t, vz in world.plant.touchdowns]
    table = log.table()
    outcome, crashed, flew = judge(result, table, touchdowns, params.airframe.g)
    return Flight(scenario, table, result, touchdowns, 0.0, log.dropped, outcome, crashed, flew)


def gains_label(args, params) -> str:
    """The gain set flown, as the announcement and the JSON name it."""
    if args.gains:
        return args.gains
    file_gains = any(name.startswith(("kp_", "ki_", "kd_")) for name, _ in params.sources)
    return f"the [gains] of {params.origin}" if file_gains else "table6"
