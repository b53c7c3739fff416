"""The paper's real-flight facts (section 4.4.5, figures 17-20) as SIL tests on the as-flown model
(`--params paper-as-flown`): the full onboard path with sensor noise, a wandering and warming gyro bias
and rotor vibration on, across the motor time constants such a vehicle has (docs/as-flown.md).

Tolerances, and why:
- banks within 1 deg, turns within 3 deg of the command from 3 s after the step: the issue's reading of
  "settle around the command values" and "quick stabilization"; the bound holds until the next step.
- touchdown below 1 m/s: a fall from the 1.5 m hover lands at 5.4 m/s.
- the 5-minute hover: 2 deg of true tilt is about 0.34 m/s^2 of unintended horizontal acceleration, what a
  pilot notices as a drift; 10 cm of altitude is 2.5 % of the HC-SR04's range and many times its
  millimetre resolution, so it bounds the altitude loop, not the sensor.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from flightctl.params import GAIN_SETS, EffectSpec, load
from flightctl.plans.plan import Move, Plan
from flightctl.sim.flights import metrics
from flightctl.sim.flights.run import fly
from flightctl.sim.flights.scenarios import SCENARIOS, Scenario

TAUS = (0.02, 0.04)   # s: the motor time constants over which the claims hold (docs/as-flown.md: from
#                        about 45 ms Table 6's pitch, its weakest loop (kd 0.13), no longer settles within 1 deg)


def as_flown(gains: str, tau: float | None = None):
    p = load("paper-as-flown", GAIN_SETS[gains])
    if tau is None:
        return p
    effects = tuple(EffectSpec(e.cause, (("tau", tau),), e.source) if e.cause == "motor_dynamics" else e
                    for e in p.effects)
    assert effects != p.effects or tau == 0.035
    return dataclasses.replace(p, effects=effects)


def settled_errors(flight) -> list[tuple[str, float]]:
    """Per step: the largest true error (deg) from 3 s after the step to the next step."""
    return metrics.settled_errors(flight.log, flight.scenario.steps, flight.t_arm)


@pytest.mark.parametrize("tau", TAUS)
@pytest.mark.parametrize("gains", ["table6", "table4"])
def test_the_paper_flight_flies_and_lands_on_the_as_flown_model(tmp_path, gains, tau):
    flight = fly(SCENARIOS["paper"](), as_flown(gains, tau), tmp_path / "f.csv", seed=3)
    assert flight.result.reason == "plan complete"
    assert any("landed" in what for _, what in flight.result.events)
    assert flight.touchdowns and max(abs(vz) for _, vz in flight.touchdowns) < 1.0
    if gains == "table6":    # the paper's flight gains: figures 18-20
        errors = settled_errors(flight)
        assert len(errors) == 12
        for channel, err in errors:
            assert err < metrics.SETTLED_DEG[channel], (channel, err, errors)


def test_the_as_flown_model_damps_what_the_base_model_lets_ring(tmp_path):
    """Table 6 through the full path: the base model's yaw turns ring for many seconds (issue 9's
    contradiction); the as-flown model's settle. Same seed, same plan."""
    base = settled_errors(fly(SCENARIOS["paper"](), load(None, GAIN_SETS["table6"]), tmp_path / "b.csv", seed=3))
    flown = settled_errors(fly(SCENARIOS["paper"](), as_flown("table6"), tmp_path / "a.csv", seed=3))
    worst = lambda errs, ch: max(e for c, e in errs if c == ch)
    assert worst(base, "yaw") > 3.0 > worst(flown, "yaw")


def test_a_five_minute_hover_with_a_wandering_gyro_bias_stays_level(tmp_path):
    plan = Plan([Move(0.0, "alt", 1.5, 4.0), Move(306.0, "alt", 0.0, 4.0)], 312.0, "hover-5min")
    flight = fly(Scenario("hover-5min", plan, (), "a 5-minute hover"), as_flown("table6"), tmp_path / "h.csv",
                 seed=5)
    log = flight.log
    t = log["t"] - flight.t_arm
    hold = (t >= 6.0) & (t <= 306.0)
    tilt = np.degrees(np.maximum(np.abs(log["true_roll"][hold]), np.abs(log["true_pitch"][hold])))
    assert flight.result.reason == "plan complete"
    assert tilt.max() < 2.0, tilt.max()
    assert np.max(np.abs(log["true_z"][hold] - 1.5)) < 0.10
