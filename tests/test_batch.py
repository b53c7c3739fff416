"""The batched simulator (sim/sweeps/batch.py) against the single one: the vectorised controller gives the
onboard controller's PWM counts step for step, the vector model the scalar model's derivatives, the
batched plant the single plant's states."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from flightctl.control.controller import FlightController
from flightctl.hal import ImuSample
from flightctl.params import Filters, Gains, Params, load
from flightctl.sim import causes
from flightctl.sim.sweeps.batch import BatchController, BatchPlant, fly
from flightctl.sim.world.model import N_RIGID, PHI, Z, Model, P
from flightctl.sim.world.plant import Plant


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


@pytest.mark.parametrize("structure", ["flight", "paper"])
def test_batch_controller_gives_the_onboard_counts(structure):
    """Same IMU samples, echoes and setpoints: the same PWM counts within one count of rounding, at
    every step, for vehicles with their own gains, on the ground and in flight."""
    rng = np.random.default_rng(17)
    n, steps = 6, 1500
    params = _random_params(rng, n)
    onboard = [FlightController(p, structure=structure) for p in params]
    batch = BatchController(params, structure=structure)
    dt = params[0].airframe.dt
    s = ImuSample()
    gyro = np.zeros((3, n))
    tilt = np.zeros((2, n))
    sp = np.zeros((4, n))
    worst = 0
    same = 0
    for k in range(steps):
        t = k * dt
        if k == 300:   # lift-off: the in-flight correction from here on
            batch.in_flight[:] = True
            for c in onboard:
                c.est.in_flight = True
        gyro += rng.normal(0.0, 0.05, gyro.shape)
        gyro *= 0.995
        tilt += gyro[:2] * dt
        acc = np.array([-9.8 * np.sin(tilt[1]), 9.8 * np.sin(tilt[0]), 9.8 * np.cos(tilt[0]) * np.cos(tilt[1])])
        acc += rng.normal(0.0, 0.3, acc.shape)
        if k % 150 == 0:
            sp = np.array([rng.uniform(-0.2, 0.2, n), rng.uniform(-0.2, 0.2, n), rng.uniform(-3.0, 3.0, n),
                           rng.uniform(0.5, 2.0, n)])
        if k % 10 == 0:
            d = rng.uniform(0.2, 2.5, n)   # (a lost echo in the air: the batch holds the altitude, onboard
            #                                 the vertical estimate stands in; sim/sweeps/batch.py)
            batch.on_range(d, t)
            for i, c in enumerate(onboard):
                c.on_range(float(d[i]), t)
        counts = batch.step(gyro[0], gyro[1], gyro[2], acc[0], acc[1], acc[2], dt, sp[0], sp[1], sp[2], sp[3])
        for i, c in enumerate(onboard):
            s.gx, s.gy, s.gz = gyro[:, i].tolist()
            s.ax, s.ay, s.az = acc[:, i].tolist()
            expected = c.step(s, dt, *sp[:, i].tolist())
            diff = max(abs(int(counts[j, i]) - expected[j]) for j in range(4))
            worst = max(worst, diff)
            same += diff == 0
            assert c.est.roll == pytest.approx(batch.roll[i], abs=1e-9)
            assert c.est.yaw == pytest.approx(batch.yaw[i], abs=1e-9)
    assert worst <= 1
    assert same >= 0.99 * n * steps
    assert len(set(map(tuple, counts.T))) > 1      # the vehicles did differ


def _states(rng, n, model: Model):
    x = np.zeros((model.n, n))
    x[:N_RIGID] = rng.normal(0.0, 0.3, (N_RIGID, n))
    x[Z] = rng.uniform(0.1, 2.0, n)
    x[N_RIGID:] = rng.uniform(300.0, 700.0, (model.n - N_RIGID, n))   # rotor speeds or thrusts
    if model.n > N_RIGID and model.effects[0].cause == "motor_lag":
        x[N_RIGID:] = rng.uniform(1.0, 7.0, (4, n))
    return x


@pytest.mark.parametrize("cause", [c for c in causes.CAUSES if c != "actuation_delay"])
def test_vector_model_is_the_scalar_model(cause):
    """`Model(vector=True)` evaluates the same f and specific force as the scalar model, column by
    column, for the base model with each effect (the hooks run unchanged on arrays)."""
    rng = np.random.default_rng(3)
    spec = causes.CAUSES[cause].parameters
    values = {k: (2.0 if k == "motor" else p.lo + 0.3 * (p.hi - p.lo)) for k, p in spec.items()}
    if cause == "battery_sag":
        values = {"v_nominal": 14.8}
    a = Params().airframe
    n = 5
    vec = Model(a, (causes.make(cause, **values),), vector=True)
    x = _states(rng, n, vec)
    u = tuple(rng.uniform(150.0, 230.0, n) for _ in range(4)) + (rng.uniform(13.0, 16.0, n),)
    xd = np.array(vec.f(0.0, x, u))
    sf = np.array(np.broadcast_arrays(*vec.specific_force(0.0, x, u)))   # 0.0 where no effect adds a force
    for i in range(n):
        one = Model(a, (causes.make(cause, **values),))
        ui = [float(v[i]) for v in u]
        assert one.f(0.0, x[:, i].tolist(), ui) == pytest.approx(xd[:, i].tolist(), rel=1e-12, abs=1e-12)
        assert one.specific_force(0.0, x[:, i].tolist(), ui) == pytest.approx(sf[:, i].tolist(), rel=1e-12, abs=1e-12)


def test_batch_plant_is_the_single_plant_with_a_parameter_per_vehicle():
    """The batched plant with one motor time constant, one actuation delay and one rotor inertia per
    vehicle (arrays in the effects' parameters and in the airframe) follows the single plant flown
    with each value, command for command."""
    from flightctl.sim.sweeps.batch import with_draws
    from flightctl.sim.sweeps.montecarlo import drawn_airframe
    params = load("paper-as-flown")
    a = params.airframe
    taus = np.array([0.02, 0.035, 0.08, 0.15])
    delays = np.array([0.0, 0.0011, 0.0044, 0.0071])      # none, a fraction, whole periods and a fraction
    jps = np.array([0.8e-4, 1.0e-4, 2.0e-4, 2.67e-4])
    n = taus.size
    draws = {("motor_dynamics", "tau"): taus, ("actuation_delay", "delay"): delays, ("airframe", "Jp"): jps}
    batch = BatchPlant(drawn_airframe(a, draws), with_draws(params, draws), n, substeps=2)
    batch.hover(3.0)
    singles = []
    for i, (tau, delay) in enumerate(zip(taus, delays)):
        tau_down = dict(next(e for e in params.effects if e.cause == "motor_dynamics").parameters)["tau_down"]
        drawn = (causes.make("motor_dynamics", tau=float(tau), tau_down=tau_down),
                 causes.make("actuation_delay", delay=float(delay)))
        plant = Plant(Model(drawn_airframe(a, draws, i), causes.combined(params, drawn)), a.dt, 2, a.battery_nominal_v)
        hover = tuple(float(v[i]) for v in batch.u)
        plant._queue.extend([hover] * len(plant._queue))   # hovering: the hover input held before
        plant.x = batch.x[:, i].tolist()
        plant.on_ground = False
        singles.append(plant)
    rng = np.random.default_rng(5)
    for k in range(400):
        if k % 20 == 0:
            counts = np.round(rng.uniform(26300, 27700, (4, n))).astype(int)
        batch.advance(counts)
        for i, plant in enumerate(singles):
            plant.command(*(counts[:, i] * 255.0 / 40000.0).tolist(), a.battery_nominal_v)
            plant.advance(a.dt)
    for i, plant in enumerate(singles):
        assert plant.x == pytest.approx(batch.x[:, i].tolist(), rel=1e-9, abs=1e-9)
    assert np.ptp(batch.x[PHI]) > 1e-3   # the time constants made a difference


def test_batch_flight_freezes_a_vehicle_that_tips_over():
    """A vehicle without roll and pitch gains, started rolling at 5 rad/s, tips past 60 degrees and is
    counted as crashed and frozen; one with gains recovers and holds its setpoint."""
    p = load("paper-as-flown")
    zero = dataclasses.replace(p, gains=dataclasses.replace(p.gains, kp_phi=0.0, kd_phi=0.0, ki_phi=0.0,
                                                            kp_theta=0.0, kd_theta=0.0, ki_theta=0.0))
    plant = BatchPlant(p.airframe, causes.combined(p, ()), 2)
    plant.hover(1.0)
    plant.x[P] = 5.0   # the rotors' inflow damps a roll rate in Jxx / (2 k l^2) = 0.36 s: 5 rad/s tips past 60 deg
    flight = fly(plant, BatchController([p, zero]), lambda t: (0.0, 0.0, 0.0, 1.0), 4.0)
    assert flight.crashed.tolist() == [False, True]
    assert 0.1 < flight.crash_t[1] < 1.0
    # its plant frozen at its last state before 60 deg (the record's rows after N_RIGID: the estimates)
    assert (flight.states[-1][:N_RIGID, 1] == flight.states[-2][:N_RIGID, 1]).all()
    assert math.radians(50) < abs(flight.states[-1][PHI][1]) <= math.radians(60)
    assert abs(flight.states[-1][PHI][0]) < 0.01 and abs(flight.states[-1][Z][0] - 1.0) < 0.1


def test_one_substep_keeps_the_closed_loop_of_two():
    """The batch's default, one RK4 step per loop period, against two: a stepped flight of the
    as-flown model differs by under 1 mm and 0.01 degree (the fastest pole, 1/tau = 50 1/s, is
    0.11 of RK4's stability bound at that step)."""
    p = load("paper-as-flown")
    out = []
    for sub in (1, 2):
        plant = BatchPlant(p.airframe, causes.combined(p, ()), 1, substeps=sub)
        plant.hover(1.0)
        out.append(fly(plant, BatchController(p, 1), lambda t: (0.1 * (t > 0.5), -0.1 * (t > 1.5), 0.3, 1.0 + 0.3 * (t > 1.0)),
                       4.0).states)
    one, two = out
    assert np.max(np.abs(one[:, Z] - two[:, Z])) < 1e-3
    assert np.max(np.abs(one[:, PHI:PHI + 3] - two[:, PHI:PHI + 3])) < math.radians(0.01)
    assert np.max(np.abs(two[:, PHI])) > 0.05   # it did move
