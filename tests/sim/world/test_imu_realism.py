"""What a real MPU-9250 does, in the simulated chip, read back through the real driver (SPI burst decode):
a zero-rate offset that wanders, a die that warms after power-on and offsets that follow it, white noise
set by the DLPF the driver configures, and the rotors' vibration at their speed, filtered and aliased like
the chip's output. Expected values are worked out here from the datasheet figures and eq. 26-27; each
statistical tolerance is a few standard errors of its estimate (seeded)."""
import math
from dataclasses import replace

import numpy as np
import pytest

from flightctl.drivers import mpu9250_regs as reg
from flightctl.drivers.mpu9250 import Mpu9250
from flightctl.hal import ImuSample
from flightctl.params import Airframe
from flightctl.sim.world.devices import SensorNoise, World
from flightctl.sim.world.imu import SimMpu9250

OFF = SensorNoise.off()
A = Airframe()
HOVER_N = A.M * A.g / 4
LSB_RAD_S = math.radians(1 / 16.4)   # gyro at +-2000 deg/s and accelerometer at +-8 g, the driver's defaults
ACCEL_LSB = A.g / 4096
# 3-dB bandwidths (Hz) of the DLPF by DLPF_CFG / A_DLPF_CFG, from the register map's tables
GYRO_BW = {1: 184.0, 3: 41.0}
ACCEL_BW = {1: 218.1, 3: 44.8}


def imu(noise, world=None, seed=0, dlpf=1):
    world = world or World(A, noise=noise, seed=seed)
    n = world.noise
    ideal = n.gyro_density == 0.0 and n.accel_density == 0.0   # its frames repeat: no frozen check
    drv = Mpu9250(SimMpu9250(world), dlpf=dlpf, sleep=lambda s: None, frozen_frames=0 if ideal else 4)
    drv.start()
    return world, drv


def record(world, drivers, seconds, every=1):
    """Advance the world loop period by loop period; read every driver each `every` periods.
    Returns times (n,), accel and gyro (drivers, n, 3) and the decoded temperature (drivers, n)."""
    s = ImuSample()
    steps = int(round(seconds / world.dt))
    t, acc, gyr, temp = [], [], [], []
    for k in range(steps + 1):
        if k % every == 0:
            t.append(world.t)
            row_a, row_g, row_t = [], [], []
            for d in drivers:
                assert d.read(s)
                row_a.append((s.ax, s.ay, s.az))
                row_g.append((s.gx, s.gy, s.gz))
                row_t.append(d.temperature)
            acc.append(row_a), gyr.append(row_g), temp.append(row_t)
        world.advance(world.dt)
    swap = lambda v: np.swapaxes(np.array(v), 0, 1)  # noqa: E731
    return np.array(t), swap(acc), swap(gyr), np.array(temp).T


def spin(world, *P):
    """Hold the four ESC commands (eq. 26 values); the thrusts below the weight keep it on the floor."""
    world.plant.command(*P, world.battery.voltage)
    world.advance(world.dt)
    return [A.h1 * (p - A.h2) ** 2 for p in P]   # eq. 26


def test_gyro_offset_wanders_as_a_random_walk_of_the_configured_intensity():
    """Var(b(t) - b(0)) = K^2 t for a random walk. 200 chips on one world, each read at its own irregular
    intervals (the walk integrates each sample's own dt), three axes: 600 increments per lag, so the
    variance is known to sqrt(2/600) = 6 %; 20 % is over three standard errors."""
    K = 2e-3
    world = World(A, noise=replace(OFF, gyro_bias_walk=K), seed=7)
    rng = np.random.default_rng(7)
    drivers = [imu(None, world)[1] for _ in range(200)]
    reads = {d: set(rng.integers(1, 40, 500).cumsum()) for d in drivers}   # 1 to 39 loop periods apart
    lags = (5.0, 10.0, 20.0)
    at = {lag: int(round(lag / world.dt)) for lag in lags}
    s = ImuSample()
    start, seen = {}, {lag: [] for lag in lags}
    for k in range(at[20.0] + 1):
        for d in drivers:
            if k == 0 or k in at.values() or k in reads[d]:
                d.read(s)
                if k == 0:
                    start[d] = (s.gx, s.gy, s.gz)
                for lag in lags:
                    if k == at[lag]:
                        seen[lag] += [g - g0 for g, g0 in zip((s.gx, s.gy, s.gz), start[d])]
        world.advance(world.dt)
    for lag in lags:
        assert np.var(seen[lag]) / (K * K * lag) == pytest.approx(1.0, abs=0.2), lag
        assert abs(np.mean(seen[lag])) < 4 * K * math.sqrt(lag / 600)   # no drift of its own


@pytest.mark.parametrize("dlpf", [1, 3])
def test_white_noise_follows_the_density_and_the_dlpf_the_driver_sets(dlpf):
    """sigma = density * sqrt(pi/2 * B) for a first-order DLPF of 3-dB bandwidth B: 0.01 deg/s/rtHz and
    300 ug/rtHz (datasheet 3.1, 3.2). 900 reads x 3 axes: the standard deviation to 1.4 %; 6 % allowed
    (sigma is 5 to 45 LSB, so quantisation adds LSB^2/12 to the variance, under 0.3 %)."""
    world, drv = imu(replace(OFF, gyro_density=math.radians(0.01), accel_density=300e-6 * A.g), dlpf=dlpf)
    _, acc, gyr, _ = record(world, [drv], 2.0)
    gyro_sigma = math.radians(0.01) * math.sqrt(math.pi / 2 * GYRO_BW[dlpf])
    accel_sigma = 300e-6 * A.g * math.sqrt(math.pi / 2 * ACCEL_BW[dlpf])
    assert np.std(gyr[0] - gyr[0].mean(axis=0)) == pytest.approx(gyro_sigma, rel=0.06)
    assert np.std(acc[0] - acc[0].mean(axis=0)) == pytest.approx(accel_sigma, rel=0.06)


def test_die_temperature_read_through_the_driver_warms_as_specified():
    """T = 25 + rise (1 - exp(-t / tau)) degC after power-on, within the register's 1/333.87 degC."""
    rise, tau = 5.0, 2.0
    world, drv = imu(replace(OFF, warmup_rise=rise, warmup_tau=tau))
    t, _, _, temp = record(world, [drv], 3 * tau, every=9)
    expected = 25.0 + rise * (1 - np.exp(-t / tau))
    assert np.max(np.abs(temp[0] - expected)) <= 0.5 / reg.TEMP_LSB_PER_C + 1e-9
    assert np.all(np.diff(temp[0]) >= 0) and temp[0][-1] - temp[0][0] > 0.9 * rise


def test_offsets_follow_the_die_temperature_through_their_coefficients():
    """Each axis's offset moves by c (T - T0), c drawn per axis with the configured spread: the gyro and
    accelerometer readings are linear in the temperature the driver decodes, and the slopes of 40 chips
    (120 per sensor) have the configured spread, known to sqrt(1/240) = 6.5 %; 25 % allowed."""
    gc, ac = math.radians(0.5), 0.05   # large, so that a 5 degC rise moves many LSB
    world = World(A, noise=replace(OFF, warmup_rise=5.0, warmup_tau=1.0, gyro_temp_coeff=gc,
                                   accel_temp_coeff=ac), seed=3)
    drivers = [imu(None, world)[1] for _ in range(40)]
    _, acc, gyr, temp = record(world, drivers, 4.0, every=20)
    slopes_g, slopes_a = [], []
    for i in range(len(drivers)):
        x = temp[i] - temp[i][0]
        for data, slopes, lsb in ((gyr[i], slopes_g, LSB_RAD_S), (acc[i], slopes_a, ACCEL_LSB)):
            for axis in range(3):
                y = data[:, axis] - data[0, axis]
                c = np.dot(x, y) / np.dot(x, x)
                assert np.max(np.abs(y - c * x)) <= 1.5 * lsb + abs(c) / reg.TEMP_LSB_PER_C
                slopes.append(c)
    assert np.std(slopes_g) == pytest.approx(gc, rel=0.25)
    assert np.std(slopes_a) == pytest.approx(ac, rel=0.25)


@pytest.mark.parametrize("dlpf", [1, 3])
def test_vibration_at_each_rotor_speed_with_an_amplitude_in_proportion_to_its_thrust(dlpf):
    """Four rotors at four speeds on the floor (P = 150..180, 12.8 N < the weight): the decoded specific
    force holds a sinusoid at each rotor's speed w = sqrt(f / c1) (eq. 27) on every axis, of amplitude
    vibration * f / f_hover through the DLPF's first-order gain 1 / sqrt(1 + (F / B)^2). Fitted by least
    squares at the four known frequencies over 4 s. What the fit leaves: the chip holds its last 1 kHz
    sample, so the read times jitter by up to 1 ms (an amplitude loss under 1.5 % at 96 Hz): 4 % allowed."""
    vib = 1.0
    world, drv = imu(replace(OFF, vibration=vib), seed=5, dlpf=dlpf)
    f = spin(world, 150, 160, 170, 180)
    t, acc, _, _ = record(world, [drv], 4.0)
    w = [math.sqrt(fi / A.c1) for fi in f]
    X = np.column_stack([np.ones_like(t)] + [g(wi * t) for wi in w for g in (np.cos, np.sin)])
    for axis in range(3):
        coef, *_ = np.linalg.lstsq(X, acc[0][:, axis], rcond=None)
        assert coef[0] == pytest.approx((0.0, 0.0, A.g)[axis], abs=0.01)   # on the floor: (0, 0, g)
        for i, (fi, wi) in enumerate(zip(f, w)):
            gain = 1 / math.sqrt(1 + (wi / (2 * math.pi * ACCEL_BW[dlpf])) ** 2)
            amplitude = math.hypot(coef[1 + 2 * i], coef[2 + 2 * i])
            assert amplitude == pytest.approx(vib * fi / HOVER_N * gain, rel=0.04), (axis, i)


@pytest.mark.parametrize("smplrt_div", [0, 9])
def test_vibration_aliases_through_the_output_sample_rate(smplrt_div):
    """One rotor at P = 175: f = 4.51 N, 88.1 Hz. At the driver's 1 kHz output rate the 450 Hz reads see
    88.1 Hz; with SMPLRT_DIV = 9 (100 Hz, written over SPI) the chip's samples alias it to 11.9 Hz."""
    world, drv = imu(replace(OFF, vibration=1.0), seed=2)
    drv.write(reg.SMPLRT_DIV, smplrt_div)
    f = spin(world, 175, 0, 0, 0)[0]
    t, acc, _, _ = record(world, [drv], 10.0)
    x = acc[0][:, 0] - acc[0][:, 0].mean()
    spectrum = np.abs(np.fft.rfft(x * np.hanning(len(x))))
    freqs = np.fft.rfftfreq(len(x), world.dt)
    rotor_hz = math.sqrt(f / A.c1) / (2 * math.pi)
    rate = 1000.0 / (1 + smplrt_div)
    seen = abs(rotor_hz - rate * round(rotor_hz / rate))   # the alias of the rotor in the chip's samples
    assert freqs[np.argmax(spectrum)] == pytest.approx(seen, abs=2 * (freqs[1] - freqs[0]))
    assert (seen < 50) == (smplrt_div == 9)


def test_all_of_it_vanishes_with_noise_off_and_only_the_wandering_with_steady():
    """SensorNoise.off(): spinning rotors, time passing, and every read is the truth (one LSB), the
    temperature constant. steady(): white noise and a fixed offset, but neither warm-up nor walk nor
    vibration: the mean gyro of the first and the last second agree within their noise."""
    world, drv = imu(OFF)
    spin(world, 170, 170, 170, 170)
    _, acc, gyr, temp = record(world, [drv], 5.0)
    assert np.all(np.abs(acc[0] - (0.0, 0.0, A.g)) <= ACCEL_LSB) and np.all(gyr[0] == 0.0)
    assert np.ptp(temp[0]) == 0.0 and temp[0][0] == pytest.approx(SimMpu9250.AMBIENT_C, abs=1 / 333.87)

    steady = replace(SensorNoise(), gyro_bias_walk=1e-3).steady()   # even a large walk is dropped
    world, drv = imu(steady, seed=4)
    spin(world, 170, 170, 170, 170)
    _, acc, gyr, temp = record(world, [drv], 20.0)
    assert np.ptp(temp[0]) == 0.0
    first, last = gyr[0][:450].mean(axis=0), gyr[0][-450:].mean(axis=0)
    sigma = math.radians(0.01) * math.sqrt(math.pi / 2 * GYRO_BW[1]) / math.sqrt(450)
    assert np.all(np.abs(first - last) < 5 * sigma * math.sqrt(2))
    assert np.std(acc[0][:, 0]) == pytest.approx(300e-6 * A.g * math.sqrt(math.pi / 2 * ACCEL_BW[1]), rel=0.06)
