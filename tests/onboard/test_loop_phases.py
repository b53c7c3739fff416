"""The loop's phases (flightctl/loop.py PHASES, docs/architecture.md "The loop's phases"): a flight meets
them in order, each leaves for the phases the docs name, and the motors and the log follow the phase:
stopped and no row on the ground, written in the air, stopped and rows after the touchdown."""
from __future__ import annotations

from flightctl.logfile import MAG_COLUMNS, FlightLogWriter
from flightctl.loop import DONE, FLYING, GROUND, LANDING, PHASES, TWO_ROTORS, FlightLoop
from flightctl.params import load
from flightctl.plans.plan import Move, Plan
from flightctl.sim.world.board import SIM_CALIBRATE_S, sim_board
from flightctl.sim.world.faults import parse


def _fly(params, plan, fault=None, tmp_path=None):
    """The flight's phase at each tick (read at the next tick's watchdog ping: the phase the tick
    left), the motors' non-zero writes per phase, the loop, its result and its log."""
    hal, world = sim_board(params, seed=11)
    if fault is not None:
        parse(fault).apply(hal, world)
    seen: list[str] = []
    writes = {p: 0 for p in PHASES}
    write = hal.motors.write

    def counted(counts):                      # (a stop writes zeros: not counted)
        if any(counts):
            writes[loop.phase] += 1
        write(counts)

    hal.motors.write = counted
    log = FlightLogWriter(tmp_path / "f.csv", {}, extra=MAG_COLUMNS, keep=True) if tmp_path is not None else None
    loop = FlightLoop(hal, params, plan, log, calibrate_s=SIM_CALIBRATE_S,
                      on_tick=lambda i: seen.append(loop.phase) if i > 1 else None)
    result = loop.run()
    seen.append(loop.phase)
    return seen, writes, loop, result, log


def _order(seen):
    out = [seen[0]]
    for p in seen[1:]:
        if p != out[-1]:
            out.append(p)
    return out


def test_the_plans_own_landing_goes_ground_flying_done_and_the_log_starts_at_arming(tmp_path):
    plan = Plan([Move(0.0, "alt", 1.0, 2.0), Move(6.0, "alt", 0.0, 3.0)], 12.0, "up and down")
    seen, writes, loop, result, log = _fly(load(None), plan, tmp_path=tmp_path)
    assert _order(seen) == [GROUND, FLYING, DONE], result.events
    assert result.reason == "plan complete"
    assert writes[GROUND] == writes[DONE] == 0 and writes[FLYING] > 0
    ground = seen.count(GROUND)
    assert ground == round(SIM_CALIBRATE_S * 450) - 1           # the ticks before the arming tick
    # a row from the arming tick on, DONE's too, but for the tick at the plan's end, which ends the loop
    assert len(log.table()["t"]) == len(seen) - ground - 1
    assert seen.count(DONE) > 1                               # the rows on the floor to the plan's end


def test_a_plan_ending_in_the_air_is_landed_by_the_loop_and_ends_at_the_touchdown():
    plan = Plan([Move(0.0, "alt", 1.0, 2.0)], 5.0, "no landing")
    seen, writes, loop, result, _ = _fly(load(None), plan)
    assert _order(seen) == [GROUND, FLYING, LANDING, DONE], result.events
    assert seen.count(DONE) == 1                              # the loop's own landing ends the loop at once
    assert writes[LANDING] > 0 and writes[DONE] == 0
    assert result.reason.startswith("landed: plan ended in the air at ")


def test_a_lost_motor_flies_down_on_two_rotors_and_the_controller_gives_the_attitude():
    params = load("paper-as-flown")
    plan = Plan([Move(0.0, "alt", 1.0, 2.0)], 12.0, "hover")
    seen, writes, loop, result, _ = _fly(params, plan, "motor_stop:at=4,motor=2")
    assert _order(seen) == [GROUND, FLYING, TWO_ROTORS, DONE], result.events
    assert result.reason == "landed: motor 2 lost"
    assert writes[TWO_ROTORS] > 0
    ctl = loop.ctl
    assert ctl.spin is loop.spin and ctl.spin.pair == (0, 2)   # motors 1 and 3 fly it
    assert ctl.est.in_flight is False                          # `touchdown`: the ground filter again
