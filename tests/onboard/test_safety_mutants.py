"""Issue 10, defect 8: tests that kill the mutants which survived the suite - the crash-tilt cutoff
raised to 180 degrees, a shipped dead-man of 10 s (board file and defaults changed together), and the
service reporting zero overruns. Each asserts the behaviour, not the constant."""
from __future__ import annotations

import argparse
import json
import math
import threading
import time

from helpers.fakes.pigpiod import running
from flightctl.logfile import MAG_COLUMNS, FlightLogWriter
from flightctl.loop import FlightLoop
from flightctl.params import load
from flightctl.boards.pi import open_pi_board
from flightctl.plans.plan import Move, Plan
from flightctl.service.sdnotify import Notifier
from flightctl.service.run import Service
from flightctl.sim.world.board import SIM_CALIBRATE_S, TRUTH_COLUMNS, open_board, sim_board, truth_row
from flightctl.boards import BoardOptions
from flightctl.sim.world.devices import SensorNoise, World
from flightctl.sim.world.imu import SimMpu9250
from flightctl.sim.world.power import SimIna219, SimSMBus

PARAMS = load(None)


def test_a_vehicle_going_over_is_cut_as_it_passes_60_degrees(tmp_path):
    # a roll command of 80 degrees (past what check_plan allows) throws the vehicle over
    hal, world = sim_board(PARAMS)
    log = FlightLogWriter(tmp_path / "f.csv", {}, extra=MAG_COLUMNS + TRUTH_COLUMNS, keep=True)
    plan = Plan([Move(0.0, "alt", 1.0, 2.0), Move(3.0, "roll", math.radians(80))], 8.0, "over")
    result = FlightLoop(hal, PARAMS, plan, log, calibrate_s=SIM_CALIBRATE_S, extra_row=truth_row(world)).run()
    assert result.reason == "stopped: crash (tilt past 60 degrees)"
    table = log.table()
    worst = max(abs(table["roll"]).max(), abs(table["pitch"]).max())
    assert math.radians(50) < worst < math.radians(66)        # cut within a loop or two of 60 (the last row logged is before it)
    assert table["t"][-1] < 3.0 + 1.0                          # right after the step, not at the plan's end


def test_the_shipped_pi_board_stops_the_motors_within_a_quarter_second_of_the_last_command():
    params = load(None)
    world = World(params.airframe, noise=SensorNoise.off())
    world.battery.voltage, world.battery.current = 16.1, 0.4
    with running() as (fake, pi):
        board = open_pi_board(params, None, pi=pi, spi=SimMpu9250(world), smbus=SimSMBus(SimIna219(world)))
        motors = board.hal.motors
        pins = motors.pins
        motors.arm()
        end = time.monotonic() + 0.3
        while time.monotonic() < end:
            motors.write([34000] * 4)
            time.sleep(0.002)
        assert fake.live_wave().on_times()[pins[0]] > 1000
        last = time.monotonic()                     # the controller hangs
        while time.monotonic() - last < 2.0 and fake.live_wave().on_times() != {p: 1000 for p in pins}:
            time.sleep(0.002)
        stopped_after = time.monotonic() - last
        board.close()
    assert stopped_after < 0.25, f"the shipped dead-man let the motors run {stopped_after:.2f} s"


class StallingNotifier(Notifier):
    """No systemd; one tick stalls the loop's thread for 60 ms (a CPU stall)."""

    def __init__(self, at: int):
        super().__init__(None)
        self.at = at

    def tick(self, i: int = 0):
        if i == self.at:
            time.sleep(0.06)
        return super().tick(i)


def test_the_service_reports_the_overruns_of_its_flight(tmp_path):
    args = argparse.Namespace(log=str(tmp_path), calibrate=0.2, min_battery_v=None, plan="hop", plan_queue=None)
    board = open_board(PARAMS, BoardOptions(realtime=True, noise=SensorNoise.off()))
    plan = Plan([Move(0.0, "alt", 0.3, 0.3), Move(0.5, "alt", 0.0, 0.3)], 1.0, "hop")
    try:
        result = Service(args, PARAMS, board, StallingNotifier(at=200), threading.Event()).fly(plan)
    finally:
        board.close()
    assert result.overruns >= 1 and result.overruns == board.hal.clock.overruns
    summary = json.loads(next(tmp_path.glob("flight-*-summary.json")).read_text())
    assert summary["overruns"] == result.overruns
