"""Issue 10, defects 3 and 7: the motors are cut in the air only for a crash or a kill command, and
the simulator's verdicts agree with each other.

Every flight here is the onboard loop (flightctl/loop.py) against the simulated quadcopter; the faults
come in at the lowest boundary there is: a real file that refuses to be written (/dev/full: ENOSPC), a
stream that blocks like a stalled SD card, the real AF_UNIX notify socket going away, a plan object
whose setpoint goes bad in flight.
"""
from __future__ import annotations

import math
import os
import socket
import threading

import numpy as np
import pytest

from flightctl.logfile import MAG_COLUMNS, FlightLogWriter, read_flight_log
from flightctl.loop import TOUCHDOWN_S, FlightLoop
from flightctl.params import load
from flightctl.plans.plan import Move, Plan
from flightctl.safety import CRASH_TILT, CRASH_TOUCHDOWN_SPEED, crash_reason, first_tilt_past
from flightctl.service.sdnotify import Notifier
from flightctl.sim.world.board import SIM_CALIBRATE_S, TRUTH_COLUMNS, sim_board, truth_row
from flightctl.sim.cli import main as sim_main
from flightctl.sim.flights.run import fly
from flightctl.sim.flights.scenarios import scenario

PARAMS = load(None)


def soft_landing(touchdowns, log):
    """Landed upright and slowly, motors stopped, at the end of the flight."""
    assert touchdowns, "the vehicle never came down: the flight ended in the air"
    assert abs(touchdowns[-1][1]) < CRASH_TOUCHDOWN_SPEED, touchdowns
    assert log["true_z"][-1] < 0.05
    assert max(abs(log["true_roll"][-1]), abs(log["true_pitch"][-1])) < math.radians(10)
    assert all(log[p][-1] == 0.0 for p in ("P1", "P2", "P3", "P4"))


def fly_plan(tmp_path, plan, log_path=None, **kw):
    return fly(scenario(plan), PARAMS, log_path or tmp_path / "f.csv", **kw)


# --- defect 3: no cut in the air for an ordinary event --------------------------------------------
def test_a_plan_that_ends_in_the_air_lands_instead_of_cutting(tmp_path):
    flight = fly_plan(tmp_path, Plan([Move(0.0, "alt", 1.0, 2.0)], 5.0, "ends_high"))
    soft_landing(flight.touchdowns, flight.log)
    assert any("plan ended in the air" in what for _, what in flight.result.events)
    assert flight.result.reason.startswith("landed")


def test_a_landing_move_after_duration_is_flown_as_a_controlled_landing(tmp_path):
    flight = fly_plan(tmp_path, Plan([Move(0.0, "alt", 1.0, 2.0), Move(6.0, "alt", 0.0, 2.0)], 5.0, "late"))
    soft_landing(flight.touchdowns, flight.log)
    assert any("plan ended in the air" in what for _, what in flight.result.events)


def test_a_plan_that_ends_while_its_touchdown_is_being_confirmed_lands_as_with_time_to_spare(tmp_path):
    """The plan's own touchdown is confirmed TOUCHDOWN_S after the sonar first puts the vehicle on
    the floor with the setpoint at 0. A plan that ends inside that half second (excite, 0.5 s after
    its ramp) must not be taken for one that ended in the air: that started the loop's own landing
    on the floor, on an altitude estimate without an echo, and lifted the vehicle off again."""
    moves = [Move(0.0, "alt", 0.5, 2.0), Move(5.0, "alt", 0.0, 2.0)]
    spare = fly_plan(tmp_path, Plan(moves, 30.0, "spare"))
    t_landed = next(t for t, w in spare.result.events if w == "landed: motors stopped") - spare.t_arm
    tight = fly_plan(tmp_path, Plan(moves, t_landed - 0.5 * TOUCHDOWN_S, "tight"))
    assert not [w for _, w in tight.result.events if "ended in the air" in w], tight.result.events
    assert next(t for t, w in tight.result.events if w == "landed: motors stopped") - tight.t_arm == pytest.approx(t_landed)
    soft_landing(tight.touchdowns, tight.log)


def test_a_full_disk_drops_log_rows_and_lands(tmp_path):
    # /dev/full: every write reaches the kernel and fails with ENOSPC, as on a full SD card
    plan = Plan([Move(0.0, "alt", 1.0, 2.0), Move(6.0, "alt", 0.0, 3.0)], 12.0, "full")
    flight = fly_plan(tmp_path, plan, log_path="/dev/full")
    soft_landing(flight.touchdowns, flight.log)      # the kept rows: the simulator's record
    events = " | ".join(what for _, what in flight.result.events)
    assert "log write failed" in events and "No space left" in events and "landing" in events
    assert flight.log_dropped > 0


class StalledCard:
    """A file whose flush (the write system call under Python's buffer) blocks until released: an SD
    card stalling for seconds."""

    def __init__(self, path):
        self.f = open(path, "w")
        self.name = str(path)
        self.release = threading.Event()

    def write(self, s):
        return self.f.write(s)

    def flush(self):
        self.release.wait()
        self.f.flush()

    def close(self):
        self.f.close()


def test_a_writer_that_cannot_keep_up_drops_rows_says_so_and_never_blocks_the_loop(tmp_path):
    card = StalledCard(tmp_path / "f.csv")
    log = FlightLogWriter(card, {"k": "v"}, chunk=45, background=True, queue_chunks=4)
    row = (0.0, 1.0, 1.0, 1.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 9.8, "", 16.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    loop = threading.Thread(target=lambda: [log.append((i / 450.0,) + row[1:]) for i in range(45 * 20)])
    loop.start()
    loop.join(10.0)
    assert not loop.is_alive(), "the loop waited for the stalled card"
    assert not card.release.is_set()
    assert log.dropped > 0 and "could not keep up" in log.error
    card.release.set()
    log.close()
    card.close()
    table = read_flight_log(tmp_path / "f.csv")
    assert len(table) == 45 * 20 - log.dropped      # what was not dropped is there, in order
    assert "dropped_rows" in table.meta and int(table.meta["dropped_rows"].split()[0]) == log.dropped


def test_a_lost_notify_socket_lands(tmp_path):
    path = str(tmp_path / "notify.sock")
    listener = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    listener.bind(path)
    hal, world = sim_board(PARAMS)
    notifier = Notifier(path, ping_s=0.25, clock=lambda: world.t)
    lost_at = int((SIM_CALIBRATE_S + 4.0) * 450)        # in the air, 2 s after take-off

    def tick(i):
        if i == lost_at:
            listener.close()
            os.unlink(path)                            # systemd's socket is gone
        return notifier.tick(i)

    log = FlightLogWriter(tmp_path / "f.csv", {}, extra=MAG_COLUMNS + TRUTH_COLUMNS, keep=True)
    plan = Plan([Move(0.0, "alt", 1.0, 2.0), Move(20.0, "alt", 0.0, 3.0)], 25.0, "notify")
    loop = FlightLoop(hal, PARAMS, plan, log, calibrate_s=SIM_CALIBRATE_S, on_tick=tick,
                      extra_row=truth_row(world))
    result = loop.run()
    assert notifier.errors > 0
    events = " | ".join(what for _, what in result.events)
    assert "watchdog ping failed" in events and "landing" in events
    soft_landing(world.plant.touchdowns, log.table())
    assert world.plant.touchdowns[-1][0] < SIM_CALIBRATE_S + 20.0    # it did not wait for the plan's landing


class FailingPlan(Plan):
    """A plan whose setpoints go bad (NaN, then an exception) in flight."""

    def at(self, t):
        sp = super().at(t)
        if t > 3.0:
            sp[1] = math.nan
        if t > 3.5:
            raise ValueError("plan broke")
        return sp


def test_a_plan_that_goes_bad_in_flight_lands(tmp_path):
    plan = FailingPlan([Move(0.0, "alt", 1.0, 2.0), Move(9.0, "alt", 0.0, 2.0)], 12.0, "bad")
    flight = fly_plan(tmp_path, plan)
    soft_landing(flight.touchdowns, flight.log)
    events = " | ".join(what for _, what in flight.result.events)
    assert "plan failed" in events and "landing" in events
    assert np.isfinite(flight.log["pitch_sp"]).all()


def test_crash_and_kill_still_cut_at_once(tmp_path):
    stop = threading.Event()
    hal, world = sim_board(PARAMS)
    ticks = int((SIM_CALIBRATE_S + 3.0) * 450)
    loop = FlightLoop(hal, PARAMS, Plan([Move(0.0, "alt", 1.0, 2.0)], 10.0, "kill"), None,
                      calibrate_s=SIM_CALIBRATE_S, stop=stop, on_tick=lambda i: stop.set() if i == ticks else None)
    result = loop.run()
    assert result.reason == "stopped: stop requested"
    assert world.plant.x[2] > 0.5 and not world.plant.touchdowns      # cut in the air, on command


# --- defect 7: one verdict ------------------------------------------------------------------------
def test_one_definition_of_a_crash():
    assert CRASH_TILT == pytest.approx(math.radians(60))
    assert crash_reason(0.0, CRASH_TOUCHDOWN_SPEED * 0.9) is None
    assert "m/s" in crash_reason(0.0, CRASH_TOUCHDOWN_SPEED * 1.1)
    assert "tilted" in crash_reason(CRASH_TILT * 1.01, 0.0)
    assert crash_reason(math.nan, 0.0) is not None


def test_a_logs_first_tilt_past_the_limit_is_found_where_it_was_drawn():
    """`first_tilt_past`, the one reading of a log's crash (the plots' crash times, diagnose's rows before
    it): the first row past the limit on either axis, a NaN row never one, a level log none."""
    rng = np.random.default_rng(17)
    for _ in range(20):
        n = int(rng.integers(50, 500))
        roll, pitch = rng.uniform(-0.9, 0.9, n) * CRASH_TILT, rng.uniform(-0.9, 0.9, n) * CRASH_TILT
        assert first_tilt_past(roll, pitch) is None
        k = int(rng.integers(1, n))
        roll[rng.integers(0, k)] = np.nan
        axis = roll if rng.random() < 0.5 else pitch
        axis[k] = float(rng.choice([-1.0, 1.0]) * rng.uniform(1.001, 2.0) * CRASH_TILT)
        axis[rng.integers(k, n):] = 3.0
        assert first_tilt_past(roll, pitch) == k
        with np.errstate(invalid="ignore"):
            assert first_tilt_past(roll, pitch, 2.0 * CRASH_TILT) == int(np.flatnonzero(np.abs(axis) > 2 * CRASH_TILT)[0])


def test_a_hard_touchdown_is_a_crash_and_exits_non_zero(tmp_path, capsys):
    """Figure 13 flown as two true steps, 0 -> 2 m -> 0: the step to the floor is a fall (the shipped
    `step_alt` lands on a ramp instead)."""
    plan = tmp_path / "steps.toml"
    plan.write_text('name = "steps"\nduration = 20.0\n[[move]]\nt = 0.0\nchannel = "alt"\nvalue = 2.0\n'
                    '[[move]]\nt = 12.0\nchannel = "alt"\nvalue = 0.0\n')
    rc = sim_main(["--plan", str(plan), "--log", str(tmp_path / "s.csv"), "--no-plot"])
    out = capsys.readouterr().out
    assert rc == 1
    assert "crashed: hit the floor at 5." in out and "plan complete" not in out


@pytest.mark.parametrize("params", ["M = 50.0\n",
                                    "[gains]\n" + "".join(f"{k}_{a} = 0.0\n" for a in ("z", "phi", "theta", "psi")
                                                         for k in ("kp", "ki", "kd"))],
                         ids=["heavy", "zero gains"])
def test_a_vehicle_that_never_flew_says_so(tmp_path, capsys, params):
    (tmp_path / "p.toml").write_text(params)
    rc = sim_main(["hover", "--params", str(tmp_path / "p.toml"), "--log", str(tmp_path / "h.csv"), "--no-plot"])
    out = capsys.readouterr().out
    assert rc == 1
    assert "never left the ground" in out and "within" not in out and "plan complete" not in out
    assert "no touchdown detected" not in out          # nothing to land: the motors stop on the floor
    assert read_flight_log(tmp_path / "h.csv")["t"][-1] <= 24.0 + 1e-6   # within the plan's 24 s


def test_console_times_are_log_times(tmp_path, capsys):
    assert sim_main(["hover_low", "--log", str(tmp_path / "l.csv"), "--no-plot"]) == 0
    out = capsys.readouterr().out
    log = read_flight_log(tmp_path / "l.csv", extra=TRUTH_COLUMNS)
    armed = next(line for line in out.splitlines() if "armed" in line)
    assert float(armed.split("=")[1].split("s")[0]) == pytest.approx(log["t"][0], abs=1 / 450)
    touchdown = next(line for line in out.splitlines() if "touchdown at" in line)
    t_touch = float(touchdown.split("=")[1].split("s")[0])
    first_down = log["t"][np.flatnonzero((log["true_z"] <= 0.0) & (log["t"] > 5.0))[0]]
    assert t_touch == pytest.approx(first_down, abs=0.02)
    assert "landed upright" in out
