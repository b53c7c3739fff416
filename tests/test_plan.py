"""flightctl.plan: steps, raised-cosine ramps, landing plans."""
import math

import pytest

from flightctl.plan import Move, Plan

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
