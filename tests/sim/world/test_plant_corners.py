"""The as-flown plant's corners (issue 37, item 3), each held by its physics, not by a number the code
printed: the gyro's broadband noise is vibration (no attitude random walk); eq. 26's thrust stops at
the ESC's full throttle; the rotor lines' yaw share is a rigid body's; the rotor drag on one pair is
momentum theory's; a vehicle that lands spinning is braked by its feet (and its IMU frames pass the
driver); tau_down follows the drawn tau; and each nominal value is the middle its range is drawn in."""
from __future__ import annotations

import dataclasses
import json
import math
import random
import struct

import numpy as np
import pytest

from flightctl.cli import main
from flightctl.drivers.mpu9250 import JUMP_GYRO
from flightctl.control import spin_design
from flightctl.params import Airframe, load
from flightctl.physics import thrust_from_command
from flightctl.sim import causes
from flightctl.sim.causes.rotor_drag import RotorDrag
from flightctl.sim.sweeps import montecarlo
from flightctl.sim.sweeps.batch import with_draws
from flightctl.sim.flights.run import fly
from flightctl.sim.flights.scenarios import SCENARIOS
from flightctl.sim.world import compiled, faults
from flightctl.sim.world.devices import SensorNoise
from flightctl.sim.world.imu import (_BURST, _C_A_LSB, _C_BBA, _C_BBQ, _C_G_LSB, _C_PERIOD, BROADBAND_HP_HZ,
                                    broadband_gains, chip_die, chip_frame, normals_per_read)
from flightctl.sim.world.model import PSI, R, VZ, Z, Model, angular_acceleration
from flightctl.sim.world.plant import FEET_MU, Plant
from helpers.script import load as load_script

RNG = np.random.default_rng(37)
DT = 1.0 / 450.0
G_LSB = 1000.0          # LSB per rad/s: fine enough that the register's rounding is far below the noise


def _chip(noise: SensorNoise, seed: int):
    """A chip with only `noise`, read in plain Python (`chip_frame`) at the loop's rate."""
    s, c = chip_die(noise, Airframe(), random.Random(seed))
    c[_C_G_LSB], c[_C_A_LSB], c[_C_PERIOD] = G_LSB, 100.0, 1e-3
    c[_C_BBA], c[_C_BBQ] = broadband_gains(DT)       # (the caller's `read_gains`, as SimMpu9250 finds them)
    return s, c


def _gyro(noise: SensorNoise, n: int, seed: int, thrusts, speeds) -> np.ndarray:
    """n reads of the chip's (p, q, r) in rad/s, the vehicle at rest with the rotors at `thrusts`."""
    s, c = _chip(noise, seed)
    k = normals_per_read(c)
    e = np.random.default_rng(seed).standard_normal(k * n).tolist()
    regs = bytearray(128)
    out = np.empty((n, 3))
    for j in range(n):
        chip_frame(regs, s, c, e, k * j, 0.0, 0.0, 9.8, 0.0, 0.0, 0.0, *thrusts, *speeds, 0.0, DT, 25.0, j > 0)
        out[j] = np.array(struct.unpack_from(">3h", regs, _BURST + 8)) / G_LSB
    return out


def test_the_gyros_broadband_noise_is_vibration_it_does_not_walk_the_attitude():
    p = load("paper-as-flown")
    lo, hi = next((lo, hi) for t, n, lo, hi in p.table_ranges if n == "gyro_broadband")
    sigma = float(np.exp(RNG.uniform(np.log(lo), np.log(hi))))           # drawn from the file's range
    a = p.airframe
    B = a.M * a.g / 4.0
    w = math.sqrt(B / a.c1)
    noise = dataclasses.replace(SensorNoise.off(), gyro_broadband=sigma, yaw_share=0.6, from_vehicle=False)
    n = 450 * 90
    rates = _gyro(noise, n, 5, (B, B, B, B), (w, w, w, w))
    p_rate = rates[:, 0]
    # the level per read is the file's at hover thrust
    assert float(np.std(p_rate)) == pytest.approx(sigma, rel=0.05)
    # integrated over the in-flight correction's 18 s, white noise would walk the angle by sigma sqrt(dt T);
    # vibration above the frame's modes leaves a bounded wobble, not a walk
    angle = np.cumsum(p_rate) * DT
    lag = int(round(p.filters.tau_tilt_air / DT))
    walked = float(np.std(angle[lag:] - angle[:-lag]))
    assert walked < 0.05 * sigma * DT * math.sqrt(lag)
    # its power sits above the corner: under 2 Hz a first-order high-pass keeps (2 / 20)^2 of it
    f = np.fft.rfftfreq(n, DT)
    psd = np.abs(np.fft.rfft(p_rate)) ** 2
    low, high = psd[(f > 0.2) & (f < 2.0)].mean(), psd[(f > 100.0) & (f < 200.0)].mean()
    assert low / high < 3.0 * (2.0 / BROADBAND_HP_HZ) ** 2


def test_eq_26s_thrust_stops_rising_at_the_escs_full_throttle():
    p = load("paper-as-flown")
    a = p.airframe
    # an RC ESC's input is 1.0-2.0 ms: 2.0 ms of the 449 Hz frame is full throttle
    full = 255.0 * 2.0e-3 * a.esc_pwm_hz
    assert spin_design.esc_full_throttle(p) == pytest.approx(full, abs=0.01)
    ceiling = thrust_from_command(spin_design.esc_full_throttle(p), a.h1, a.h2)
    # the whole plant (the file's effects; compiled where numba is), commanded past full throttle: each
    # rotor's speed settles where eq. 27 gives the ceiling, not eq. 26 at the command
    for P, f_expected in ((255.0, ceiling), (full - 12.0, thrust_from_command(full - 12.0, a.h1, a.h2))):
        plant = Plant(Model(a, causes.combined(p, ())), DT)
        for _ in range(int(1.5 / DT)):
            plant.command(P, P, P, P, 16.0)
            plant.advance(DT)
        assert plant.forces().f == pytest.approx([f_expected] * 4, rel=1e-3), P
    assert thrust_from_command(255.0, a.h1, a.h2) > 1.4 * ceiling       # what eq. 26 alone gave (27.2 N)


def test_the_rotor_lines_yaw_share_is_a_rigid_bodys():
    p = load("paper-as-flown")
    a = p.airframe
    h = load_script("as_flown").HUB_HEIGHT
    # a rotor's imbalance force turning at the hover speed, at the hub (l, 0, h): eq. 7 rocks the frame
    w = math.sqrt(a.M * a.g / 4.0 / a.c1)
    F = 3e-6 * w * w
    dt, rate = 2e-6, [0.0, 0.0, 0.0]
    seen = []
    for k in range(int(4 * 2 * math.pi / w / dt)):
        fx, fy = F * math.cos(w * k * dt), F * math.sin(w * k * dt)
        torque = (-h * fy, h * fx, a.l * fy)                             # r x F
        d = angular_acceleration(*rate, *torque, 0.0, 0.0, a.Jxx, a.Jyy, a.Jzz, a.Jp)
        rate = [r + dt * dr for r, dr in zip(rate, d)]
        seen.append(rate)
    seen = np.array(seen)
    swing = seen.max(axis=0) - seen.min(axis=0)
    assert swing[2] / swing[0] == pytest.approx(p.sensors.yaw_lines, rel=0.03)
    # and the chip's lines carry that share: one rotor running, its lines alone
    noise = dataclasses.replace(SensorNoise.off(), gyro_vibration=0.02, yaw_lines=p.sensors.yaw_lines,
                                from_vehicle=False)
    B = a.M * a.g / 4.0
    rates = _gyro(noise, 4000, 3, (B, 0.0, 0.0, 0.0), (w, 0.0, 0.0, 0.0))
    assert float(np.std(rates[:, 2]) / np.std(rates[:, 0])) == pytest.approx(p.sensors.yaw_lines, rel=0.1)


def test_on_one_pair_the_rotor_drag_is_momentum_theorys():
    a = Airframe()
    B = a.M * a.g / 4.0
    rho, area = 1.225, math.pi * a.rotor_radius ** 2
    v_i = lambda f: math.sqrt(f / (2.0 * rho * area))                    # noqa: E731  momentum theory
    k = float(RNG.uniform(0.5, 1.7))
    e = RotorDrag(k=k)
    e.attach(a, 12)
    x = [0.0] * 12
    for f in ([B] * 4, [2 * B, 0.0, 2 * B, 0.0], list(RNG.uniform(0.3, 1.8, 4) * B)):
        force, torque = [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]
        e.wrench(0.0, x, f, (1.0, 0.0, 0.0), force, torque)
        # the ram drag rho A v_i V of each rotor, k at hover for four
        assert -force[0] == pytest.approx(k * sum(v_i(fi) for fi in f) / (4.0 * v_i(B)), rel=1e-12)
    force, torque = [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]
    e.wrench(0.0, x, [2 * B, 0.0, 2 * B, 0.0], (1.0, 0.0, 0.0), force, torque)
    assert -force[0] / k == pytest.approx(math.sqrt(2.0) / 2.0, rel=1e-12)


def test_a_vehicle_that_lands_spinning_is_braked_by_its_feet():
    a = load("paper-as-flown").airframe
    plant = Plant(Model(a), DT)
    r0 = float(RNG.uniform(15.0, 30.0)) * (1 if RNG.random() < 0.5 else -1)
    plant.x[Z], plant.x[VZ], plant.x[R] = 0.01, -0.5, r0
    plant.on_ground = False
    rates, grounded, psi = [r0], [False], [plant.x[PSI]]
    for _ in range(int(2.0 / DT)):
        plant.advance(DT)
        rates.append(plant.x[R])
        grounded.append(plant.on_ground)
        psi.append(plant.x[PSI])
    assert plant.touchdowns and plant.on_ground
    assert max(abs(b - a) for a, b in zip(rates, rates[1:])) < JUMP_GYRO      # no frame the driver must refuse
    # from the period it touched down in, the spin falls at the feet's Coulomb friction at the arm over Jzz
    k = grounded.index(True)
    brake = FEET_MU * a.M * a.g * a.l / a.Jzz
    r_td, psi_td = rates[k - 1], psi[k - 1]          # as it touched down (eq. 6's air drag slowed it before)
    stopped = (rates.index(0.0) - (k - 1)) * DT
    assert stopped == pytest.approx(abs(r_td) / brake, abs=2 * DT)
    assert psi[-1] - psi_td == pytest.approx(r_td * abs(r_td) / (2 * brake), rel=0.02)


def test_a_two_rotor_landing_passes_every_imu_frame(tmp_path):
    out = tmp_path / "m.json"
    rc = main(["sim", "hover", "--params", "paper-as-flown", "--fault", "motor_stop:motor=2,at=6.3",
               "--log", str(tmp_path / "f.csv"), "--json", str(out), "--no-plot", "--quiet"])
    report = json.loads(out.read_text())
    assert rc == 0 and report["outcome"] == "landed upright"
    assert any("flying on motors" in e["what"] for e in report["events"])
    assert not [e for e in report["events"] if e["what"].startswith("IMU frame refused")]


def test_tau_down_follows_the_drawn_tau():
    p = load("paper-as-flown")
    draws = montecarlo.draw(p, 16, seed=int(RNG.integers(1000)))
    assert ("motor_dynamics", "tau_down") not in draws
    model = Model(montecarlo.drawn_airframe(p.airframe, draws), with_draws(p, draws))
    laid = compiled.layout_rows(model, 16)
    assert laid[1][:, compiled._DOWN].tolist() == draws[("motor_dynamics", "tau")].tolist()


@pytest.mark.parametrize("table,name", [("filters", "tau_rate"), ("sensors", "gyro_broadband"),
                                        ("sensors", "gyro_vibration"), ("sensors", "harmonic2"),
                                        ("sensors", "harmonic3")])
def test_each_nominal_is_the_middle_of_the_range_as_it_is_drawn(table, name):
    p = load("paper-as-flown")
    lo, hi = next((lo, hi) for t, n, lo, hi in p.table_ranges if (t, n) == (table, name))
    drawn = montecarlo.draw(p, 4000, seed=int(RNG.integers(1000)))[(table, name)]
    nominal = getattr(getattr(p, table), name)
    # the draws' median is the middle of the range as drawn (uniform, or in the logarithm); the nominal too
    assert float(np.median(drawn)) == pytest.approx(nominal, rel=0.06, abs=0.02 * (hi - lo))
    log = montecarlo._logarithmic(p, table, name)
    middle = math.sqrt(lo * hi) if log else 0.5 * (lo + hi)
    assert nominal == pytest.approx(middle, rel=5e-3)          # (the file keeps three or four figures)


def test_at_the_top_of_g1_and_g2_the_two_rotor_spin_stays_within_the_gyros_full_scale(tmp_path):
    """The spin a pair settles at is eq. 6's drag against the pair's eq. 28: with g1 and g2 at the top of
    their ranges it comes near the gyro's 2000 deg/s. With the sensors' noise and lines at the top of
    theirs too, no gyro word reaches full scale and the two-rotor landing holds."""
    told = load("paper-as-flown")
    tops = {n: hi for n, lo, hi in told.ranges if n in ("g1", "g2")}
    noise = {name: hi for table, name, lo, hi in told.table_ranges if table == "sensors"}
    flown = dataclasses.replace(told, sensors=dataclasses.replace(told.sensors, **noise))
    plant = dataclasses.replace(told.airframe, **tops)
    d = spin_design.design_inputs(dataclasses.replace(told, airframe=plant))
    full_scale = math.radians(2000.0)
    assert spin_design.equilibrium_spin(d) > 0.9 * full_scale          # the corner the review found
    flight = fly(SCENARIOS["hover"](), flown, tmp_path / "f.csv", faults=[faults.parse("motor_stop:motor=2,at=8")],
                 plant_airframe=plant, seed=int(RNG.integers(1, 100)))
    assert flight.outcome == "landed upright" and flight.result.reason.startswith("landed: motor 2 lost")
    assert not [w for _, w in flight.result.events if w.startswith("IMU saturated")]
