"""The batched simulator (sim/sweeps/batch.py, twin_loop.py, twin_controller.py) against the single one: its copy
of the onboard controller gives the onboard controller's PWM counts count for count, and a vehicle it
flies is the vehicle `flightctl sim` flies with the same draw and seed, to the bit, take-off to
landing; its Monte Carlo judges each draw as the full path's does."""
from __future__ import annotations

import dataclasses
import math
import os
import random
import types

import numpy as np
import pytest

from flightctl.control.controller import FlightController
from flightctl.hal import ImuSample
from flightctl.params import Filters, Gains, Params, load
from flightctl.sim.flights.run import fly
from flightctl.sim.flights.scenarios import SCENARIOS
from flightctl.sim.sweeps import montecarlo
from flightctl.sim.sweeps import twin_controller
from flightctl.sim.sweeps.batch import WIDE, simulate, uniforms
from flightctl.sim.sweeps.montecarlo import draw, drawn_params
from flightctl.sim.world import compiled


def _random_params(rng, n: int) -> list[Params]:
    """n parameter sets with gains drawn within a factor of Table 6 and Table 4, a random in-flight
    tilt correction and a random EMA on the D term's rates (each off for some)."""
    out = []
    for _ in range(n):
        base = dataclasses.asdict(Gains() if rng.random() < 0.5 else load("paper-as-flown").gains)
        gains = Gains(**{k: v * rng.uniform(0.5, 2.0) + (rng.uniform(0, 0.01) if k.startswith("ki") else 0.0)
                         for k, v in base.items()})
        filters = Filters(tau_tilt_air=0.0 if rng.random() < 0.3 else rng.uniform(2.0, 20.0),
                          tau_rate=0.0 if rng.random() < 0.3 else rng.uniform(0.002, 0.3))
        out.append(dataclasses.replace(Params(), gains=gains, filters=filters))
    return out


def _copy():
    """The controller's functions as the batch runs them: compiled where numba is, else plain."""
    if compiled.enabled():
        return types.SimpleNamespace(**twin_controller.compiled_functions(compiled.compiled_copy))
    return types.SimpleNamespace(step=twin_controller.step, on_range=twin_controller.on_range, set_reference=twin_controller.set_reference,
                                 arm=twin_controller.arm, landing_start=twin_controller.landing_start)


@pytest.mark.parametrize("structure", ["flight", "paper"])
def test_the_batch_controller_gives_the_onboard_counts(structure):
    """Same IMU samples (with the magnetometer), echoes (some lost) and setpoints: the same PWM counts
    and estimates at every step, for vehicles with their own gains and filters, on the floor, in
    flight, and landing (the loop's own landing: the vertical estimate and the touchdown test)."""
    rng = np.random.default_rng(17)
    fn = _copy()
    n, steps = 4, 1500
    params = _random_params(rng, n)
    dt = params[0].airframe.dt
    s = ImuSample()
    same = 0
    for p in params:
        c = FlightController(p, structure=structure)
        e = np.zeros(twin_controller.N_E)
        e[twin_controller.ALT_T] = -1.0
        k = np.array(twin_controller.constants(p, structure))
        counts = np.zeros(4, dtype=np.int64)
        bias = (float(rng.normal(0, 0.02)), float(rng.normal(0, 0.02)), float(rng.uniform(-3, 3)))
        c.est.set_reference(bias[:2], bias[2], True)
        fn.set_reference(e, *bias, True)
        gyro, tilt = np.zeros(3), np.zeros(2)
        for i in range(steps):
            t = i * dt
            if i == 300:                     # lift-off: the in-flight correction from here on
                c.est.in_flight = True
                e[twin_controller.IN_FLIGHT] = 1.0
                s.ax, s.ay, s.az = 0.1, -0.2, 9.7
                c.arm(s)
                fn.arm(e, s.az)
            if i == 1100:                    # the loop's own landing
                c.land(0.3)
                fn.landing_start(e, 0.3)
            gyro = 0.995 * gyro + rng.normal(0.0, 0.05, 3)
            tilt += gyro[:2] * dt
            acc = np.array([-9.8 * math.sin(tilt[1]), 9.8 * math.sin(tilt[0]), 9.8 * math.cos(tilt[0]) * math.cos(tilt[1])])
            acc += rng.normal(0.0, 0.3, 3)
            mag = np.array([2e-5, 0.0, -4e-5]) + rng.normal(0.0, 3e-7, 3)
            s.gx, s.gy, s.gz = gyro.tolist()
            s.ax, s.ay, s.az = acc.tolist()
            s.mx, s.my, s.mz = mag.tolist()
            s.mag_fresh = True
            if i % 10 == 0:
                d = float(rng.uniform(0.2, 2.5)) if rng.random() < 0.8 else math.nan
                c.on_range(d, t)
                fn.on_range(e, k, d, t)
            sp = (float(rng.uniform(-0.2, 0.2)), float(rng.uniform(-0.2, 0.2)), 0.5, 1.0) if i % 150 < 75 else \
                (0.0, 0.0, -0.5, 1.5)
            expected = c.step(s, dt, *sp)
            fn.step(e, k, *gyro, *acc, *mag, True, dt, *sp, counts)
            assert counts.tolist() == expected, (i, counts, expected)
            assert (e[twin_controller.ROLL], e[twin_controller.PITCH], e[twin_controller.YAW]) == (c.est.roll, c.est.pitch, c.est.yaw)
            assert (e[twin_controller.UZ], e[twin_controller.VZ]) == (c.uz, c.vert.z)
            same += 1
        assert c.landing.integral != 0.0 and c.est.yaw != 0.0     # the landing and the magnetometer did act
    assert same == n * steps


def test_the_batchs_uniforms_are_the_mersenne_twisters_random_calls():
    """`uniforms(r, k)` (the sonar's and power monitor's numbers, drawn at once) is k calls of
    `r.random()`, number for number, and leaves r where they leave it, from states met mid-stream."""
    rng = np.random.default_rng(3)
    for seed in rng.integers(0, 2 ** 40, 20):
        a, b = random.Random(int(seed)), random.Random(int(seed))
        for _ in range(int(rng.integers(0, 700))):   # somewhere within the generator's 624-word block
            a.random()
            b.random()
        for k in (1, 2, 311, 624, 1000):
            expected = [b.random() for _ in range(k)]
            np.testing.assert_array_equal(uniforms(a, k), expected)
            assert a.getstate() == b.getstate()


@pytest.mark.skipif(not compiled.enabled(), reason="the batch's speed needs numba (the default install)")
def test_a_batch_vehicle_flies_the_full_paths_flight():
    """Two draws of paper-as-flown's ranges, each with its seed: the batch's record of the true and
    estimated attitude is the full onboard path's log, to the bit, and its outcome is the same; its wide
    record (sim/sweeps/fleet_flown.py's logs) is the log's commands, IMU sample and altitude estimate."""
    params = load("paper-as-flown")
    sc = SCENARIOS["step_roll"]()
    draws = draw(params, 2, seed=8)
    seeds = [11, 12]
    batch = simulate(params, sc.plan, 2, draws, seeds=seeds, record=(0.0, sc.plan.duration - 1.0), wide=True)
    for v, seed in enumerate(seeds):
        vehicle = drawn_params(params, {key: float(val[v]) for key, val in draws.items()})
        full = fly(sc, vehicle, os.devnull, seed=seed)
        assert batch.outcome[v] == full.outcome
        rows = min(len(batch.log["t"]), len(full.log))   # (a crash ends the full path's log early)
        np.testing.assert_array_equal(batch.log["t"][:rows], full.log["t"][:rows])
        for column in ("true_roll", "true_pitch", "true_yaw", "roll", "pitch", "yaw") + WIDE:
            np.testing.assert_array_equal(batch.log[column][:rows, v], full.log[column][:rows], err_msg=column)
        assert np.isnan(batch.log["true_roll"][rows:, v]).all()
        assert rows > 4000                                # it flew past the step (at 10 s)


@pytest.mark.skipif(not compiled.enabled(), reason="the batch's speed needs numba (the default install)")
def test_the_batched_monte_carlo_judges_each_draw_as_the_full_path():
    """`--batch` against the full path on the same three draws of step_roll: per draw and gain set, the
    same outcome, the same settle verdict and the same score (the paper's figures)."""
    batch = montecarlo.run_batch("paper-as-flown", "step_roll", 3, seed=5, workers=1)
    full = montecarlo.run("paper-as-flown", "step_roll", 3, seed=5)
    for b, f in zip(batch["draws"], full["draws"]):
        for g in montecarlo.GAINS:
            assert (b[g]["outcome"], b[g]["settles"], b[g].get("score")) == (f[g]["outcome"], f[g]["settles"], f[g].get("score"))
    assert batch["share"] == full["share"] and batch["paired"] == full["paired"]


@pytest.mark.slow
@pytest.mark.timeout(3600)   # 80 paper flights through the full path: minutes on two cores
def test_forty_paired_draws_give_the_full_paths_shares():
    """The paper flight on 40 draws of every range of paper-as-flown, both gain sets, by the full onboard
    path and by the batch: each share (flies, lands, settles, and the paired verdicts) within 3 points."""
    batch = montecarlo.run_batch("paper-as-flown", "paper", 40, seed=2)
    full = montecarlo.run("paper-as-flown", "paper", 40, seed=2)
    for g in montecarlo.GAINS:
        for what in ("flies", "lands", "settles"):
            assert abs(batch["share"][g][what] - full["share"][g][what]) <= 0.03, (g, what)
    for what in montecarlo.VERDICTS:
        assert abs(batch["paired"][what] - full["paired"][what]) <= 0.03, what
    assert 0.0 < full["share"]["table6"]["flies"] < 1.0 or 0.0 < full["share"]["table4"]["flies"] < 1.0   # draws differ
