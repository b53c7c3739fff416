"""flightctl.plans.plan: steps, raised-cosine ramps, landing plans; plan files and their limits; the named
plans of flightctl.plans; the steps the simulator measures; `flightctl sim --plan FILE`."""
import math

import numpy as np
import pytest

from flightctl.cli import main as cli
from flightctl.errors import InputError
from flightctl.logfile import MAG_COLUMNS, read_flight_log
from flightctl.plans.plan import MAX_PLAN_ALT_M, Move, Plan, check_plan, read_plan_file
from flightctl.plans import PLANS, load_plan
from flightctl.sim.world.board import TRUTH_COLUMNS
from flightctl.sim.flights.scenarios import SCENARIOS, measured_steps

ROLL, PITCH, YAW, ALT = range(4)


def test_no_moves_is_all_zero():
    plan = Plan([], 5.0)
    assert plan.at(0.0) == [0.0, 0.0, 0.0, 0.0]
    assert plan.at(4.0) == [0.0, 0.0, 0.0, 0.0]
    assert not plan.lands()


def test_step():
    plan = Plan([Move(1.0, "alt", 1.5)], 10.0)
    assert plan.at(0.0)[ALT] == 0.0
    assert plan.at(0.999)[ALT] == 0.0
    assert plan.at(1.0)[ALT] == 1.5          # a step takes effect at its time
    assert plan.at(7.0)[ALT] == 1.5
    assert plan.at(7.0)[ROLL] == 0.0


def test_raised_cosine_ramp():
    # from 0 to 2 m over 4 s starting at t = 1: v = 2 * (1 - cos(pi s)) / 2, s = (t - 1) / 4
    plan = Plan([Move(1.0, "alt", 2.0, ramp=4.0)], 10.0)
    assert plan.at(1.0)[ALT] == pytest.approx(0.0)
    assert plan.at(2.0)[ALT] == pytest.approx(1.0 - math.cos(math.pi / 4))          # 0.293
    assert plan.at(3.0)[ALT] == pytest.approx(1.0)                                  # half way: midpoint
    assert plan.at(4.0)[ALT] == pytest.approx(1.0 - math.cos(3 * math.pi / 4))      # 1.707
    assert plan.at(5.0)[ALT] == 2.0
    assert plan.at(6.0)[ALT] == 2.0


def test_ramp_from_the_current_value_and_symmetric():
    plan = Plan([Move(0.0, "alt", 1.0), Move(2.0, "alt", 3.0, ramp=1.0), Move(5.0, "alt", 0.0, ramp=2.0)],
                10.0)
    assert plan.at(1.0)[ALT] == 1.0
    assert plan.at(2.5)[ALT] == pytest.approx(2.0)        # midpoint of 1 -> 3
    assert plan.at(2.25)[ALT] == pytest.approx(1.0 + 2.0 * (1 - math.cos(math.pi / 4)) / 2)
    assert plan.at(3.0)[ALT] == 3.0
    assert plan.at(6.0)[ALT] == pytest.approx(1.5)        # midpoint of 3 -> 0
    assert plan.at(8.0)[ALT] == 0.0
    assert plan.lands()


def test_ramp_interrupted_starts_from_where_it_was():
    # a new move during a ramp starts from the value the ramp had reached
    plan = Plan([Move(0.0, "roll", 0.1, ramp=2.0), Move(1.0, "roll", -0.1, ramp=2.0)], 10.0)
    assert plan.at(0.5)[ROLL] == pytest.approx(0.1 * (1 - math.cos(math.pi / 4)) / 2)
    # at t = 1 the first ramp is at its midpoint 0.05; the second goes 0.05 -> -0.1 over 2 s
    assert plan.at(2.0)[ROLL] == pytest.approx((0.05 - 0.1) / 2)
    assert plan.at(3.0)[ROLL] == -0.1


def test_channels_independent_and_moves_sorted():
    plan = Plan([Move(2.0, "yaw", 0.5), Move(1.0, "pitch", -0.1), Move(0.0, "roll", 0.05)], 5.0)
    assert plan.at(0.5) == [0.05, 0.0, 0.0, 0.0]
    assert plan.at(1.5) == [0.05, -0.1, 0.0, 0.0]
    assert plan.at(2.5) == [0.05, -0.1, 0.5, 0.0]


def test_time_jump_over_several_moves():
    plan = Plan([Move(1.0, "alt", 1.0), Move(2.0, "alt", 2.0, ramp=2.0), Move(3.0, "alt", 0.5)], 10.0)
    assert plan.at(3.5)[ALT] == 0.5


def test_restart():
    plan = Plan([Move(1.0, "alt", 1.0)], 5.0)
    assert plan.at(2.0)[ALT] == 1.0
    plan.restart()
    assert plan.at(0.5)[ALT] == 0.0
    assert plan.at(1.5)[ALT] == 1.0


def test_lands():
    assert Plan([Move(0.0, "alt", 1.0), Move(5.0, "alt", 0.0, ramp=2.0)], 10.0).lands()
    assert not Plan([Move(0.0, "alt", 1.0)], 10.0).lands()
    assert not Plan([Move(0.0, "alt", 1.0), Move(5.0, "roll", 0.0)], 10.0).lands()
    # the last altitude move counts, not the last move
    assert Plan([Move(0.0, "alt", 1.0), Move(4.0, "alt", 0.0), Move(5.0, "yaw", 1.0)], 10.0).lands()


def test_unknown_channel():
    with pytest.raises(ValueError, match="throttle"):
        Plan([Move(0.0, "throttle", 1.0)], 5.0)


# --- plan files, the named plans, the steps the simulator measures -------------------------------------
def write(tmp_path, text: str, name: str = "p.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_every_named_plan_is_fresh_described_and_within_the_plan_file_limits():
    assert set(PLANS) >= {"hover", "paper", "step_alt", "step_roll", "step_pitch", "step_yaw", "excite", "hover_low"}
    for name, make in PLANS.items():
        plan = make()
        assert plan.name == name and plan.doc
        assert check_plan(plan) is plan
        assert make() is not plan                    # a Plan keeps setpoint state: one per flight
    assert PLANS["paper"]().lands() and not PLANS["hover"]().lands()


def test_the_limits_refuse_a_plan_naming_the_move():
    too_high = Plan([Move(0.0, "alt", 1.0), Move(5.0, "alt", MAX_PLAN_ALT_M + 0.5)], 10.0, "high")
    with pytest.raises(InputError, match="plan high: move 2: altitude 3.5 m outside"):
        check_plan(too_high)
    with pytest.raises(InputError, match="roll 31 deg beyond"):
        check_plan(Plan([Move(0.0, "roll", math.radians(31))], 10.0))
    with pytest.raises(InputError, match="duration"):
        check_plan(Plan([], 0.0))


def test_a_plan_file_error_names_the_move_in_the_files_order(tmp_path):
    path = write(tmp_path, 'duration = 9\n[[move]]\nt = 5\nchannel = "alt"\nvalue = 1\n'
                           '[[move]]\nt = 1\nchannel = "pitch"\nvalue_deg = -40\n')
    with pytest.raises(InputError, match=r"p.toml: move 2: pitch -40 deg beyond"):
        read_plan_file(path)


@pytest.mark.parametrize("text, message", [
    ('name = "../x"\nduration = 5\n', "name '../x' holds a slash"),
    ('duration = 5\nmove = 3\n', "expected \\[\\[move\\]\\] tables"),
    ('duration = 5\n[[move]]\nt = 0\nchannel = "alt"\nvalue_deg = 1\n', "alt is in metres"),
    ('duration = 5\n[[move]]\nt = 0\nchannel = "yaw"\nvalue = 1\nvalue_deg = 1\n', "exactly one of value"),
    ('duration = 5\n[[move]]\nt = -1\nchannel = "yaw"\nvalue = 1\n', "must not be negative"),
    ('duration = 5\n[[move]]\nt = "soon"\nchannel = "yaw"\nvalue = 1\n', "t: expected a number"),
])
def test_bad_plan_files_are_one_line_naming_the_problem(tmp_path, text, message):
    with pytest.raises(InputError, match=message):
        read_plan_file(write(tmp_path, text))


def test_load_plan_takes_a_file_or_a_name(tmp_path):
    path = write(tmp_path, 'duration = 6\n[[move]]\nt = 0\nchannel = "yaw"\nvalue_deg = 90\n', "turn.toml")
    plan = load_plan(str(path))
    assert plan.name == "turn" and plan.moves[0].value == pytest.approx(math.pi / 2)
    assert load_plan("excite").name == "excite"
    with pytest.raises(InputError, match="named: hover, paper"):
        load_plan("hovr")


def test_the_simulator_measures_every_step_until_the_next_move():
    steps = measured_steps(PLANS["paper"]())
    roll = [(s.t, round(math.degrees(s.start)), round(math.degrees(s.end)), s.window) for s in steps
            if s.channel == "roll"]
    assert roll == [(8, 0, 5, 3), (11, 5, 0, 4), (15, 0, -5, 5), (20, -5, 0, 4)]    # the paper's schedule
    assert [s.channel for s in steps].count("yaw") == 4 and all(s.channel != "alt" for s in steps)  # ramps
    # a step to the ground is a landing (the loop disarms on touchdown), not a response
    assert [(s.channel, s.t, s.end, s.window) for s in measured_steps(PLANS["step_alt"]())] == [("alt", 0.0, 2.0, 12.0)]
    # the last step is measured to the end of the plan
    assert [(s.t, s.window) for s in measured_steps(PLANS["step_roll"]())] == [(10.0, 8.0)]
    assert set(SCENARIOS) == set(PLANS) and SCENARIOS["excite"]().plan.name == "excite"


def test_flightctl_sim_flies_a_plan_file_in_simulated_time(tmp_path, capsys):
    path = write(tmp_path, 'name = "nudge"\nduration = 5\n[[move]]\nt = 0\nchannel = "alt"\nvalue = 0.8\nramp = 1.5\n'
                           '[[move]]\nt = 3\nchannel = "pitch"\nvalue_deg = 3\n')
    log = tmp_path / "nudge.csv"
    assert cli(["sim", "--plan", str(path), "--log", str(log), "--quiet"]) == 0
    out = capsys.readouterr().out
    table = read_flight_log(log, extra=MAG_COLUMNS + TRUTH_COLUMNS)
    assert table.meta["scenario"] == "nudge"
    in_plan = table["t"] <= 5.0
    assert np.count_nonzero(in_plan) == pytest.approx(5 * 450, abs=2)   # the plan, in simulated time
    assert table["true_z"][in_plan][-1] > 0.5                     # it flew the plan ...
    assert table["true_z"][-1] < 0.05 and "landed" in out         # ... and, ending in the air, landed
    assert "pitch   +0.0 ->   +3.0 deg" in out                      # its step, measured
    assert log.with_suffix(".png").stat().st_size > 0


def test_flightctl_sim_takes_exactly_one_of_a_scenario_and_a_plan_file(tmp_path, capsys):
    path = write(tmp_path, 'duration = 5\n')
    assert cli(["sim", "hover", "--plan", str(path), "--log", str(tmp_path / "x.csv")]) == 2
    assert capsys.readouterr().err == "flightctl sim: error: give exactly one of SCENARIO and --plan PLAN.toml\n"
    assert cli(["sim", "--log", str(tmp_path / "x.csv")]) == 2
    assert not (tmp_path / "x.csv").exists()
