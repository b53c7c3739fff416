"""`gyro_lag`'s plant side: the simulated MPU-9250 behind the real driver reports its rates through the
undeclared first-order lag, noise included, and the accelerometer does not pass through it."""
from __future__ import annotations

import math

import numpy as np
import pytest

from flightctl.drivers.mpu9250 import Mpu9250
from flightctl.hal import ImuSample
from flightctl.params import Params
from flightctl.sim import causes
from flightctl.sim.causes.gyro_lag import pt1_gain
from flightctl.sim.world.devices import SensorNoise, World
from flightctl.sim.world.imu import SimMpu9250
from flightctl.sim.world.model import P, R

LSB = math.radians(1.0 / 16.4)   # rad/s: the driver's gyro scale (+-2000 deg/s)


def reads(effects, noise, n, rates=(0.4, 0.0, -0.3), seed=3):
    """n reads through the driver, one per loop period, of a vehicle on the floor that starts to turn
    at `rates` after the first read: (gyro (n, 3), accelerometer (n, 3))."""
    a = Params().airframe
    world = World(a, tuple(effects), noise, seed=seed)
    imu = Mpu9250(SimMpu9250(world), sleep=lambda s: None, frozen_frames=0)
    imu.start()
    s, gyro, acc = ImuSample(), [], []
    for k in range(n):
        world.advance(a.dt)
        if k == 1:      # a step of the body rates (on the floor the rigid body's state is held as set)
            world.plant.x[P:R + 1] = list(rates)
        assert imu.read(s), imu.why
        gyro.append((s.gx, s.gy, s.gz))
        acc.append((s.ax, s.ay, s.az))
    return np.array(gyro), np.array(acc), a.dt


def test_the_chip_reports_its_rates_through_the_lag():
    tau = 0.02
    plain, acc0, dt = reads((), SensorNoise.off(), 60)
    lagged, acc1, _ = reads((causes.make("gyro_lag", tau=tau),), SensorNoise.off(), 60)
    # the lag of the chip's output, read by read: y_k = y_(k-1) + k (x_k - y_(k-1))
    k = pt1_gain(dt, tau)
    want = plain.copy()
    for i in range(1, len(want)):
        want[i] = want[i - 1] + k * (plain[i] - want[i - 1])
    assert np.abs(lagged - want).max() <= 2 * LSB
    # it lags: one time constant after the step the rate has covered 1 - 1/e of it, not all
    i = 2 + int(round(tau / dt))
    assert lagged[i, 0] == pytest.approx(plain[i, 0] * (1 - math.exp(-1)), abs=0.06 * plain[i, 0])
    assert np.array_equal(acc0, acc1)      # the accelerometer does not pass through it


def test_it_smooths_the_gyro_noise_too():
    """White noise through the lag keeps k / (2 - k) of its variance: the chip's output is filtered,
    not only the rigid body's rates."""
    tau = 0.005
    n = 3000
    plain, _, dt = reads((), SensorNoise().steady(), n, rates=(0.0, 0.0, 0.0))
    lagged, _, _ = reads((causes.make("gyro_lag", tau=tau),), SensorNoise().steady(), n, rates=(0.0, 0.0, 0.0))
    k = pt1_gain(dt, tau)
    ratio = np.std(lagged[100:], axis=0) / np.std(plain[100:], axis=0)
    assert ratio == pytest.approx(np.full(3, math.sqrt(k / (2 - k))), rel=0.12)


def test_parse_builds_it_and_refuses_a_lag_out_of_range():
    from flightctl.errors import InputError
    e = causes.parse("gyro_lag:tau=0.03")
    assert e.uses_gyro and e.parameters == {"tau": 0.03}
    with pytest.raises(InputError, match="out of range"):
        causes.parse("gyro_lag:tau=-0.01")


def _noise(tmp_path, name, *args, params=()):
    """The gyro noise diagnose reports for a quick flight of the hidden-effect tests (`flightctl sim
    --plan`, then `flightctl diagnose`), with `args` added to the simulation's command line and `params`
    to both."""
    import json

    from flightctl.cli import main
    from helpers.diagnose_cases import quick_plan
    log, out = tmp_path / f"{name}.csv", tmp_path / f"{name}.json"
    assert main(["sim", "--plan", str(quick_plan(tmp_path)), "--log", str(log), "--seed", "7", "--no-plot",
                 "--quiet", *args, *params]) in (0, 1)
    assert main(["diagnose", str(log), "--json", str(out), "--quiet", *params]) == 0
    report = json.loads(out.read_text())
    return report["data"]["gyro_noise"], report["causes"]


def test_diagnose_reports_the_gyro_noise_beside_the_causes_not_as_one(tmp_path):
    """The level diagnose reports (the gyro above 60 Hz, as white noise per read) is the simulated chip's
    own where it is all there is, rises with the as-flown vehicle's `[sensors]` (frame broadband noise
    and rotor lines) and falls where a lag smooths the gyro; more noise names no cause."""
    from flightctl.drivers import mpu9250_regs as reg
    from flightctl.drivers.mpu9250 import DLPF
    chip = SensorNoise().gyro_density * math.sqrt(0.5 * math.pi * reg.GYRO_DLPF[DLPF][0])   # rad/s per read
    plain, named = _noise(tmp_path, "plain")
    assert named == []
    for axis in "pqr":
        assert plain["white_per_read"][axis] == pytest.approx(chip, rel=0.15)
    noisy, named = _noise(tmp_path, "as_flown", params=("--params", "paper-as-flown"))
    from flightctl.params import load
    broadband = load("paper-as-flown").sensors.gyro_broadband    # rad/s per read at hover thrust, roll and pitch
    assert min(noisy["white_per_read"][a] for a in "pq") == pytest.approx(broadband, rel=0.5)
    assert "gyro_lag" not in [c["cause"] for c in named]
    lagged, named = _noise(tmp_path, "lagged", "--effect", "gyro_lag:tau=0.01")
    assert [c["cause"] for c in named] == ["gyro_lag"]
    assert max(lagged["rms"].values()) < 0.5 * min(plain["rms"].values())
