"""The paper's real-flight facts (section 4.4.5, figures 17-20) as SIL tests on the as-flown model
(`--params paper-as-flown`): the full onboard path with the vehicle's sensors (the gyro's broadband
noise and the rotors' vibration lines, a wandering and warming gyro bias), its rate path and delay
chain, at the file's nominal values and at the fast end of the motor time constant's range
(docs/as-flown.md; the shares over every range are the Monte Carlo's).

Tolerances, and why:
- the paper's account, judged as the paper judged it (sim/sweeps/judge.py): at the fast end of the
  motors Table 4 (tuned in simulation) flies and lands, Table 6 (retuned on the vehicle) flies, lands,
  holds every bank and turn within the pilot's bound (the size of sec. 3.3's tuning steps) and rings
  less; not a band on the true error, which both tables share with the estimator's bias. At the
  file's nominal Table 4 does not hold (its banks limit-cycle or it crashes, docs/as-flown.md) and
  Table 6 does: the whole account holds in a minority of the Monte Carlo's draws, which the README
  counts.
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
from flightctl.sim.sweeps import judge

TAUS = (0.02, None)   # s: the fast end of the motor time constants' range, and the file's nominal (its middle)


def as_flown(gains: str, tau: float | None = None):
    p = load("paper-as-flown", GAIN_SETS[gains])
    if tau is None:
        return p
    effects = tuple(EffectSpec(e.cause, (("tau", tau),) + tuple(kv for kv in e.parameters if kv[0] != "tau"), e.source)
                    if e.cause == "motor_dynamics" else e for e in p.effects)
    assert effects != p.effects
    return dataclasses.replace(p, effects=effects)


def settled_errors(flight) -> list[tuple[str, float]]:
    """Per step: the largest true error (deg) from 3 s after the step to the next step."""
    return metrics.settled_errors(flight.log, flight.scenario.steps, flight.t_arm)


def _judged(tmp_path, tau) -> dict:
    sc = SCENARIOS["paper"]()
    judged = {}
    for gains in ("table4", "table6"):
        flight = fly(sc, as_flown(gains, tau), tmp_path / f"{gains}.csv", seed=3)
        lands = flight.result.reason == "plan complete" and any("landed" in what for _, what in flight.result.events)
        if lands:
            assert flight.touchdowns and max(abs(vz) for _, vz in flight.touchdowns) < 1.0
            figures = judge.step_figures(flight.log, sc.steps, flight.t_arm)
            assert len(figures) == 12
        judged[gains] = {"flies": lands and flight.outcome == "landed upright",
                         **(judge.summary(figures) if lands else {"score": None})}
    return judged


def test_at_the_fast_end_of_the_motors_both_tables_land_and_table6_holds_and_rings_less(tmp_path):
    """Sec. 4.4.5: the simulation's gains flew the vehicle, the retuned ones improved it."""
    judged = _judged(tmp_path, TAUS[0])
    verdict = judge.verdict(judged["table4"], judged["table6"])
    assert judged["table4"]["flies"] and judge.bounded(judged["table6"]), judged
    assert verdict["table6 beats table4"] and verdict["paper's account, landing only"], judged


def test_at_the_files_nominal_table6_holds_where_table4_does_not(tmp_path):
    """At the nominal point (its rate path at the log-middle of its range, 11.3 dt, since issue 37),
    Table 4's high gains do not hold the banks: the paper's account does not hold there even by
    landing alone, while Table 6 holds within the bound and so beats it (the Monte Carlo gives the
    shares over the ranges)."""
    judged = _judged(tmp_path, TAUS[1])
    verdict = judge.verdict(judged["table4"], judged["table6"])
    assert judged["table6"]["flies"] and judge.bounded(judged["table6"]), judged["table6"]
    assert not judge.bounded(judged["table4"]) and verdict["table6 beats table4"], judged


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
