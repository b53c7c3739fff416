"""The landing the loop commands itself (flightctl/control/landing.py): the vertical estimate, the
touchdown the accelerometer confirms, and blind landings (the sonar lost) in the simulator from a
height and at a time drawn at random."""
from __future__ import annotations

import math
import random

import pytest

from flightctl.control.landing import LANDED_S, Landing, Vertical
from flightctl.params import load
from flightctl.physics import G
from flightctl.plans.plan import Move, Plan
from flightctl.safety import CRASH_TOUCHDOWN_SPEED
from flightctl.sim.world import faults
from flightctl.sim.flights.run import fly
from flightctl.sim.flights.scenarios import scenario

DT = 1.0 / 450


def test_the_vertical_estimate_learns_the_accelerometer_bias_and_holds_without_the_sonar():
    rng = random.Random(5)
    bias = rng.uniform(-0.3, 0.3)                  # m/s^2, unknown to the estimate
    w = 2 * math.pi / 5                            # a 5 s up-and-down of 0.5 m about 1.5 m
    vert = Vertical()
    vert.reset(0.0, 0.0, G)                        # the reset sees no bias
    vert.z = 1.5
    for i in range(int(23 / DT)):                  # 20 s with the sonar, then 3 s without
        t = i * DT
        z, a = 1.5 + 0.5 * math.sin(w * t), -0.5 * w * w * math.sin(w * t)
        vert.predict(0.0, 0.0, G + a + bias + rng.gauss(0.0, 0.5), 0.0, 0.0, DT)
        if t < 20.0 and i % 10 == 0:
            vert.correct(z + rng.gauss(0.0, 0.003), 10 * DT)
        if i == int(20 / DT):
            assert vert.b == pytest.approx(bias, abs=0.02)
    assert abs(vert.z - z) < 0.2                   # 3 s on the accelerometer alone (noise 0.5 m/s^2)


def _point_mass(z0: float, z_error: float, on_floor_from=None):
    """A vehicle moving only vertically under 4 (B + u_z) of thrust, with a floor that stops it over
    20 ms (as the simulator's plant), flown by `Landing` on a sonar-less `Vertical` whose altitude is
    off by `z_error`. Returns (landed time, touchdown speed, time on the floor before `landed`)."""
    M = 1.645
    landing, vert = Landing(M), Vertical()
    vert.reset(0.0, 0.0, G)
    vert.z, z, v = z0 + z_error, z0, 0.0
    landing.start(0.0, 0.3)
    t = 0.0
    touch = None
    stopping = 0.0
    while t < 30.0:
        uz = landing.step(vert, DT)
        thrust = 4.0 * (M * G / 4.0 + uz)
        a = thrust / M - G
        if z <= 0.0 and a <= 0.0:                  # on the floor
            f = G + stopping
            if touch is None:
                touch = (t, v)
                stopping = -v / 0.02
                f = G + stopping
            z = v = 0.0
        else:
            f = thrust / M
            v += a * DT
            z += v * DT
            if z < 0.0:
                z = 0.0
        if touch is not None and t - touch[0] > 0.02:
            stopping = 0.0
        vert.predict(0.0, 0.0, f, 0.0, 0.0, DT)
        t += DT
        if landing.landed:
            return t, abs(touch[1]) if touch else None, t - touch[0] if touch else None
    return None, abs(touch[1]) if touch else None, None


@pytest.mark.parametrize("z_error", [-0.4, 0.0, 0.4])
def test_the_touchdown_is_declared_only_on_the_floor(z_error):
    t_landed, speed, on_floor = _point_mass(1.0, z_error)
    assert t_landed is not None, "never declared landed"
    assert speed is not None and on_floor is not None and on_floor >= LANDED_S   # on the floor first
    assert speed < CRASH_TOUCHDOWN_SPEED


def _blind(alt: float, lost_at: float, seed: int, params):
    plan = Plan([Move(0.0, "alt", alt, 4.0), Move(lost_at + 6.0, "alt", 0.0, 3.0)], lost_at + 30.0, "blind",
                "climb, the sonar goes silent, land")
    fault = faults.parse(f"sonar_silent:at={lost_at}")   # after arming, as the log counts
    return fly(scenario(plan), params, "/dev/null", faults=[fault], seed=seed)


@pytest.mark.parametrize("case", range(2))
@pytest.mark.parametrize("model", [None, "paper-as-flown"])
def test_a_blind_landing_from_a_random_height_lands_upright(case, model):
    rng = random.Random(1000 + case)                   # the height and time are not told to the loop
    alt, lost_at, seed = rng.uniform(0.6, 3.0), rng.uniform(1.0, 10.0), rng.randrange(100)
    flight = _blind(alt, lost_at, seed, load(model))
    events = [what for _, what in flight.result.events]
    assert any(w.startswith("altitude lost") for w in events), events
    assert flight.outcome == "landed upright", (alt, lost_at, seed, flight.outcome, flight.touchdowns, events)
    assert flight.result.reason.startswith("landed: altitude lost"), flight.result.reason
    assert max(abs(v) for _, v in flight.touchdowns) < CRASH_TOUCHDOWN_SPEED
