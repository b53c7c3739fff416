"""The loop clock counts whole periods: the same plan flown at 2 and at 20 plant substeps per loop sees
the same clock, so its setpoints change on the same rows and its sonar echoes arrive on the same loops
(within one: the echo's width follows the altitude, which the finer integration changes a little).
A clock summing substep lengths drifts by rounding and moved setpoint changes by a loop or two."""
from __future__ import annotations

import math

import numpy as np
import pytest

from flightctl.params import load
from flightctl.plans.plan import Move, Plan
from flightctl.sim.flights.run import fly
from flightctl.sim.flights.scenarios import scenario

SP = ("roll_sp", "pitch_sp", "yaw_sp", "alt_sp")


def six_seconds() -> Plan:
    """A take-off ramp and steps at whole seconds, where a drifting clock decides by its last bit."""
    return Plan([Move(0.0, "alt", 1.0, 2.0), Move(3.0, "roll", math.radians(4)), Move(4.0, "roll", 0.0),
                 Move(4.0, "pitch", math.radians(-4)), Move(5.0, "pitch", 0.0), Move(5.0, "yaw", 0.3)],
                6.0, "six_seconds", "a take-off ramp, then roll, pitch and yaw steps")


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    out = {}
    for n in (2, 20):
        path = tmp_path_factory.mktemp("substeps") / f"flight_{n}.csv"
        flight = fly(scenario(six_seconds()), load(None), path, seed=4, substeps=n)
        assert flight.result.reason.startswith("landed: plan ended in the air")   # not stopped on the way
        out[n] = flight.log
    return out


def changes(log, column: str) -> np.ndarray:
    return np.flatnonzero(np.diff(log[column]) != 0.0) + 1


def test_setpoints_change_on_the_same_rows_at_2_and_20_substeps(logs):
    coarse, fine = logs[2], logs[20]
    assert len(coarse) == len(fine)
    np.testing.assert_array_equal(coarse["t"], fine["t"])
    for column in ("roll_sp", "pitch_sp", "yaw_sp"):
        rows = changes(coarse, column)
        np.testing.assert_array_equal(rows, changes(fine, column), err_msg=column)
        assert len(rows) == {"roll_sp": 2, "pitch_sp": 2, "yaw_sp": 1}[column]
    # each step on the first loop at or after its time since arming, a whole number of periods
    dt = load(None).airframe.dt
    for t_move, column in ((3.0, "roll_sp"), (4.0, "pitch_sp"), (5.0, "yaw_sp")):
        row = changes(coarse, column)[0]
        assert coarse["t"][row] >= t_move > coarse["t"][row - 1]
        assert coarse["t"][row] == pytest.approx(t_move, abs=dt)
    for column in SP:   # the ramp too: the same setpoint at the same time, to the last bit
        np.testing.assert_array_equal(coarse[column], fine[column], err_msg=column)


def test_echoes_arrive_on_the_same_loops_within_one(logs):
    coarse, fine = (np.flatnonzero(~np.isnan(logs[n]["range"])) for n in (2, 20))
    assert len(coarse) > 200                       # about 45 Hz over 6 s
    assert abs(len(coarse) - len(fine)) <= 1
    gaps = np.abs(coarse[:, None] - fine[None, :]).min(axis=1)
    assert gaps.max() <= 1
    assert np.mean(gaps == 0) > 0.9
