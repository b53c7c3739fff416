"""The independent regression of the angular acceleration on the commanded torque (axischeck.py) on real
logs: it sees the roll and pitch the base model identifies, and it reverses with a motor order that
reverses an axis (a hidden change the regression is not told of)."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from flightctl import params as paramfile
from flightctl.sim.diagnose.axischeck import regression
from flightctl.sim.diagnose.data import load_file
from flightctl.sim.logs import read_foreign
from helpers.real import FLIGHTS, need


@pytest.fixture(scope="module")
def gecko():
    path = need(FLIGHTS / "betaflight" / "btfl_002.bbl")
    return load_file(read_foreign(str(path))[0], paramfile.load(None).airframe)


def test_the_regression_sees_both_axes_of_an_acrobatic_flight(gecko):
    for axis in (0, 1):
        r = regression([gecko], axis)
        assert r["t"] > 2.0 and r["signs"] == 8 and 0 < r["r2"] < 1, (axis, r)


def test_a_motor_order_that_mirrors_an_axis_reverses_its_regression(gecko):
    rng = np.random.default_rng(42)
    axis = int(rng.integers(2))          # which axis the swap mirrors, drawn, not told
    # Betaflight's quad X: 1 rear right, 2 front right, 3 rear left, 4 front left; swapping 1<->3 and 2<->4
    # mirrors left and right (roll), 1<->2 and 3<->4 front and rear (pitch)
    order = (2, 3, 0, 1) if axis == 0 else (1, 0, 3, 2)
    swapped = dataclasses.replace(gecko, P=gecko.P[list(order)])
    before, after = regression([gecko], axis), regression([swapped], axis)
    assert before["t"] > 2.0 and after["t"] < -2.0 and after["signs"] == 0, (before, after)
    other = regression([swapped], 1 - axis)
    assert other["t"] > 2.0, other
