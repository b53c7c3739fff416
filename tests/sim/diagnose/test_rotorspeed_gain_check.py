"""What a pattern of the rotors' thrusts in hover is (sim/diagnose/rotorspeed.py,
`rotor_gain_check`): a yaw trim (the pair of one spin pushing harder, a pattern of the spins) is told
from a centre of mass off the middle (a pattern of the positions) and from a weak motor, with and without
the log's rotor speeds. The pattern, its size and the layout are drawn from a seeded generator."""
from __future__ import annotations

import math
import random

import numpy as np
import pytest

from flightctl.sim.diagnose.data import Layout
from flightctl.sim.diagnose.rotorspeed import rotor_gain_check, trim_pattern

RNG = random.Random(171)
SD = [0.01] * 4


def _layout(rng):
    """The paper's + or an X, turned by a drawn angle, with its spins (two of each, alternating)."""
    turn = rng.choice((0.0, math.pi / 4)) + rng.uniform(-0.1, 0.1)
    a = [turn + k * math.pi / 2 for k in range(4)]
    first = rng.choice((1.0, -1.0))
    return Layout(tuple(math.cos(v) for v in a), tuple(math.sin(v) for v in a),
                  (first, -first, first, -first), unit="arm")


def _unit(g):
    g = np.asarray(g, float)
    return g / g.mean()


@pytest.mark.parametrize("seed", range(4))
def test_a_yaw_trim_is_named_as_the_spins_pattern_with_its_size(seed):
    rng = random.Random(RNG.random() + seed)
    layout, split = _layout(rng), rng.choice((1, -1)) * rng.uniform(0.08, 0.4)
    g = _unit(1.0 + 0.5 * split * np.array(layout.spin))
    check = rotor_gain_check(g, SD, layout, None)
    assert check["verdict"] == "not told apart" and "a pattern of the spins" in check["why"]
    assert "centre of mass at" not in check["why"]
    assert check["yaw_trim"]["ccw_minus_cw"] == pytest.approx(split, rel=0.05)
    assert check["yaw_trim"]["share"] > 0.99
    # the rotors turn on one curve (their speeds give the same thrust for the command): a yaw trim
    speeds = {"speed_gain": [1.0, 1.0, 1.0, 1.0]}
    assert rotor_gain_check(g, SD, layout, speeds)["verdict"] == "yaw trim"


@pytest.mark.parametrize("seed", range(4))
def test_a_centre_of_mass_is_still_a_centre_of_mass(seed):
    rng = random.Random(RNG.random() + 10 + seed)
    layout = _layout(rng)
    d = np.array([rng.uniform(-0.1, 0.1), rng.uniform(-0.1, 0.1)])
    d *= 0.08 / max(np.abs(trim_pattern(layout) @ d).max(), 1e-9)   # a pattern of 8 % at its largest
    g = _unit(1.0 + trim_pattern(layout) @ d)
    check = rotor_gain_check(g, SD, layout, {"speed_gain": [1.0, 1.0, 1.0, 1.0]})
    assert check["verdict"] == "centre of mass", check
    assert check["yaw_trim"]["share"] < 0.01


def test_a_weak_motor_whose_speed_shows_it_is_not_a_yaw_trim():
    layout = _layout(random.Random(3))
    g = _unit([0.8, 1.0, 1.0, 1.0])
    speeds = {"speed_gain": list(np.sqrt(g))}       # its speed gives its thrust (eq. 27)
    check = rotor_gain_check(g, SD, layout, speeds)
    assert check["verdict"] == "weak motor" and "motor 1" in check["why"]
