"""The real drivers (MPU-9250 over SPI, HC-SR04 on pigpio, INA219 over I2C) against the simulated
devices of sim.devices and sim.power and against tiny hand-made fakes. Expected values come from the datasheet scales and
the formulas, worked out here."""
import math
import struct

import numpy as np
import pigpio
import pytest

from flightctl.boards import BoardOptions, open_board
from flightctl.drivers.hcsr04 import HcSr04
from flightctl.drivers.ina219 import Ina219
from flightctl.drivers.mpu9250 import ImuError, Mpu9250
from flightctl.hal import ImuSample
from flightctl.params import Airframe, load
from flightctl.sim.world.devices import SensorNoise, SimGpio, World
from flightctl.sim.world.imu import SimMpu9250
from flightctl.sim.causes import make
from helpers.hand import R_hand

G = 9.80665
M = 1.645
H1, H2 = 1.49e-3, 120.0
EARTH = np.array([20e-6, 0.0, -40e-6])
ACCEL_LSB_PER_G = {0: 16384.0, 1: 8192.0, 2: 4096.0, 3: 2048.0}      # +-2, 4, 8, 16 g
GYRO_LSB_PER_DPS = {0: 131.0, 1: 65.5, 2: 32.8, 3: 16.4}             # +-250 ... 2000 deg/s
MAG_T_PER_LSB = 0.15e-6
US_PER_M = 5831.0
ECHO, TRIG = 24, 23


def no_sleep(_):
    pass


def quiet_world(effects=()):
    return World(Airframe(), effects, noise=SensorNoise.off())


def started_imu(world, accel_fs=2, gyro_fs=1, **chip_kw):
    chip = SimMpu9250(world, **chip_kw)
    drv = Mpu9250(chip, accel_fs, gyro_fs, sleep=no_sleep)
    drv.start()
    return chip, drv


# --- MPU-9250 against the simulated chip -----------------------------------------------------------

@pytest.mark.parametrize("fs", [0, 1, 2, 3])
def test_imu_round_trip_every_full_scale(fs):
    """Airborne, moving at (1.2, -0.8, 0) m/s level with rotor drag k = 0.5 and all four P = 180:
    specific force (-0.5*1.2 s/M, +0.5*0.8 s/M, 4 h1 60^2 / M) = (-0.421, 0.280, 13.04) m/s^2 (1.33 g),
    s = sqrt(f / B) each rotor's induced velocity over the hover's (momentum theory's ram drag, the
    rotors above hover thrust here), rates (1, -2, 3) rad/s (172 deg/s): within every range. Decoded
    within one LSB."""
    world = quiet_world((make("rotor_drag", k=0.5),))
    chip, drv = started_imu(world, accel_fs=fs, gyro_fs=fs)
    plant = world.plant
    plant.on_ground = False
    plant.x[2] = 3.0
    plant.x[3], plant.x[4] = 1.2, -0.8
    plant.x[9:12] = [1.0, -2.0, 3.0]
    plant.u = (180.0, 180.0, 180.0, 180.0, 16.0)
    s = ImuSample()
    assert drv.read(s)
    share = math.sqrt(H1 * 60.0 ** 2 / (M * G / 4.0))
    f_true = (-0.5 * 1.2 * share / M, 0.5 * 0.8 * share / M, 4 * H1 * 60.0 ** 2 / M)
    a_lsb = G / ACCEL_LSB_PER_G[fs]
    g_lsb = math.radians(1.0) / GYRO_LSB_PER_DPS[fs]
    for got, want in zip((s.ax, s.ay, s.az), f_true):
        assert abs(got - want) <= a_lsb
    for got, want in zip((s.gx, s.gy, s.gz), (1.0, -2.0, 3.0)):
        assert abs(got - want) <= g_lsb
    assert s.az == pytest.approx(13.04, abs=0.01)


@pytest.mark.parametrize("fs", [0, 1, 2, 3])
def test_imu_on_the_floor_reads_plus_g(fs):
    world = quiet_world()
    _, drv = started_imu(world, accel_fs=fs, gyro_fs=fs)
    s = ImuSample()
    assert drv.read(s)
    assert abs(s.ax) <= G / ACCEL_LSB_PER_G[fs] and abs(s.ay) <= G / ACCEL_LSB_PER_G[fs]
    assert abs(s.az - G) <= G / ACCEL_LSB_PER_G[fs]


def test_imu_saturates_at_int16_limits():
    world = quiet_world()
    _, drv = started_imu(world, accel_fs=0, gyro_fs=0)
    plant = world.plant
    plant.on_ground = False
    plant.x[2] = 3.0
    plant.x[9:12] = [10.0, -10.0, 0.5]                   # 573 deg/s against a 250 deg/s range
    plant.u = (255.0, 255.0, 255.0, 255.0, 16.0)         # 4 h1 135^2 / M = 66 m/s^2 = 6.7 g > 2 g
    s = ImuSample()
    assert drv.read(s)
    assert s.az == pytest.approx(32767 / 16384 * G)
    assert s.gx == pytest.approx(math.radians(32767 / 131))
    assert s.gy == pytest.approx(math.radians(-32768 / 131))
    assert abs(s.gz - 0.5) <= math.radians(1 / 131)
    # the 16 g range holds it
    _, drv16 = started_imu(world, accel_fs=3, gyro_fs=3)
    assert drv16.read(s)
    assert abs(s.az - 4 * H1 * 135.0 ** 2 / M) <= G / 2048
    assert abs(s.gx - 10.0) <= math.radians(1 / 16.4)


def test_imu_magnetometer_axes_through_the_sim():
    world = quiet_world()
    _, drv = started_imu(world)
    assert drv.has_mag
    att = (0.2, -0.1, 0.8)
    world.plant.x[6:9] = list(att)
    s = ImuSample()
    assert drv.read(s)
    assert s.mag_fresh
    want = R_hand(*att).T @ EARTH
    for got, w in zip((s.mx, s.my, s.mz), want):
        assert abs(got - w) <= MAG_T_PER_LSB


def test_imu_without_magnetometer():
    world = quiet_world()
    _, drv = started_imu(world, has_mag=False)
    assert not drv.has_mag
    s = ImuSample()
    assert drv.read(s)
    assert not s.mag_fresh


def test_imu_wrong_who_am_i_names_the_value():
    world = quiet_world()
    chip = SimMpu9250(world, who_am_i=0x70)
    drv = Mpu9250(chip, sleep=no_sleep)
    with pytest.raises(ImuError, match="0x70"):
        drv.start()


@pytest.mark.parametrize("fault", ["zeros", "ones"])
def test_imu_bus_error_frames_refused(fault):
    world = quiet_world()
    chip, drv = started_imu(world)
    s = ImuSample()
    s.ax, s.gz = 1.25, -0.5
    chip.fault = fault
    assert drv.read(s) is False
    assert (s.ax, s.gz) == (1.25, -0.5)        # the sample is left untouched
    chip.fault = None
    assert drv.read(s) is True


def test_imu_full_scale_selection_checked():
    with pytest.raises(ValueError):
        Mpu9250(SimMpu9250(quiet_world()), accel_fs=4, sleep=no_sleep)
    with pytest.raises(ValueError):
        Mpu9250(SimMpu9250(quiet_world()), gyro_fs=-1, sleep=no_sleep)


# --- MPU-9250 against a hand-encoded burst ---------------------------------------------------------

class FakeSpi:
    def __init__(self, frame):
        self.frame = list(frame)
        self.max_speed_hz = 0
        self.sent = []

    def xfer2(self, data):
        self.sent.append(list(data))
        return self.frame[:len(data)]


def burst(head, mag=(0, 0, 0), st2=0x10):
    return [0] + list(struct.pack(">7h", *head)) + list(struct.pack("<3hB", *mag, st2))


def test_imu_decode_is_big_endian():
    # accel x as raw bytes 0x01 0x02: big-endian 258 (little-endian would be 513)
    frame = [0, 0x01, 0x02] + list(struct.pack(">6h", -2, 16384, 0, 131, -131, 258)) + [0] * 7
    spi = FakeSpi(frame)
    drv = Mpu9250(spi, accel_fs=0, gyro_fs=0, sleep=no_sleep)
    s = ImuSample()
    assert drv.read(s)
    assert spi.sent[-1] == [0x80 | 0x3B] + [0] * 21          # one burst read from ACCEL_XOUT_H
    assert s.ax == pytest.approx(258 * G / 16384)
    assert s.ay == pytest.approx(-2 * G / 16384)
    assert s.az == pytest.approx(G)                           # 16384 LSB = 1 g at +-2 g
    assert s.gx == pytest.approx(math.radians(1.0))           # 131 LSB = 1 deg/s at +-250 deg/s
    assert s.gy == pytest.approx(-math.radians(1.0))
    assert s.gz == pytest.approx(math.radians(258 / 131))


@pytest.mark.parametrize("fs", [0, 1, 2, 3])
def test_imu_scales_by_hand(fs):
    drv = Mpu9250(FakeSpi(burst((1000, -1000, 2000, 0, 1000, -1000, 2000))), accel_fs=fs, gyro_fs=fs,
                  sleep=no_sleep)
    s = ImuSample()
    assert drv.read(s)
    a = G / ACCEL_LSB_PER_G[fs]
    w = math.pi / 180 / GYRO_LSB_PER_DPS[fs]
    assert (s.ax, s.ay, s.az) == pytest.approx((1000 * a, -1000 * a, 2000 * a))
    assert (s.gx, s.gy, s.gz) == pytest.approx((1000 * w, -1000 * w, 2000 * w))


def test_imu_magnetometer_axes_by_hand():
    # AK8963 (x, y, z) = (100, -200, 300) LSB -> body (x_mpu = y_ak, y_mpu = x_ak, z_mpu = -z_ak)
    drv = Mpu9250(FakeSpi(burst((0, 0, 16384, 0, 0, 0, 0), (100, -200, 300))), sleep=no_sleep)
    drv.has_mag = True
    s = ImuSample()
    assert drv.read(s)
    assert s.mag_fresh
    assert (s.mx, s.my, s.mz) == pytest.approx((-200 * 0.15e-6, 100 * 0.15e-6, -300 * 0.15e-6))


def test_imu_magnetometer_overflow_bit():
    drv = Mpu9250(FakeSpi(burst((0, 0, 16384, 0, 0, 0, 0), (100, -200, 300), st2=0x10 | 0x08)),
                  sleep=no_sleep)
    drv.has_mag = True
    s = ImuSample()
    assert drv.read(s)
    assert s.mag_fresh is False


@pytest.mark.parametrize("byte", [0x00, 0xFF])
def test_imu_all_same_byte_frame_refused(byte):
    drv = Mpu9250(FakeSpi([0] + [byte] * 21), sleep=no_sleep)
    drv.has_mag = True
    assert drv.read(ImuSample()) is False


# --- HC-SR04 against the simulated GPIO ------------------------------------------------------------

def sonar_world(distance, tick0=0):
    world = quiet_world()
    gpio = SimGpio(world, tick0=tick0)
    world.gpio = gpio
    world.plant.x[2] = distance     # on the floor the plant holds its state: a fixed range
    hc = HcSr04(gpio, TRIG, ECHO)
    hc.start()
    return world, gpio, hc


def wait_result(world, hc, periods=30):
    for _ in range(periods):
        world.advance(world.dt)
        r = hc.poll()
        if r is not None:
            return r, world.t
    return None, world.t


@pytest.mark.parametrize("d", [0.05, 0.5, 1.0, 2.0, 3.9])
def test_sonar_distance_from_echo_width(d):
    world, gpio, hc = sonar_world(d)
    hc.trigger()
    r, t = wait_result(world, hc)
    # width d * 5831 us, measured on integer microsecond ticks: within 1 us = 1/5831 m
    assert abs(r - d) <= 1.0 / US_PER_M + 1e-12
    assert hc.failures == 0
    assert t >= (10 + 450 + d * US_PER_M) * 1e-6   # not before the echo has ended


def test_sonar_tick_wrap():
    tick0 = 2 ** 32 - 1000       # the echo rises at tick 2^32 - 540 and falls at tick 5291
    world, gpio, hc = sonar_world(1.0, tick0=tick0)
    ticks = []
    gpio.callback(ECHO, pigpio.EITHER_EDGE, lambda g, level, tick: ticks.append((level, tick)))
    hc.trigger()
    r, _ = wait_result(world, hc)
    (l1, rise), (l0, fall) = ticks[:2]
    assert (l1, l0) == (1, 0)
    assert rise > 2 ** 32 - 1000 and fall < 10000      # it really straddles the wrap
    assert abs(r - 1.0) <= 1.0 / US_PER_M + 1e-12


@pytest.mark.parametrize("d", [4.2, 0.01])
def test_sonar_out_of_range_is_nan(d):
    world, gpio, hc = sonar_world(d)
    hc.trigger()
    r, _ = wait_result(world, hc)
    assert r is not None and math.isnan(r)
    assert hc.failures == 1


def test_sonar_no_echo_watchdog_nan():
    # beyond 4.5 m the module holds the echo high 38 ms: the 30 ms watchdog ends the wait
    world, gpio, hc = sonar_world(5.0)
    hc.trigger()
    r, t = wait_result(world, hc, periods=40)
    assert r is not None and math.isnan(r)
    assert 0.030 <= t <= 0.030 + 460e-6 + world.dt + 1e-9
    assert hc.failures == 1
    # the late falling edge at 38 ms is not taken for a measurement
    r, _ = wait_result(world, hc, periods=10)
    assert r is None


def test_sonar_stuck_echo_watchdog_nan_and_triggers_skipped():
    world, gpio, hc = sonar_world(1.0)
    calls = []
    real = gpio.gpio_trigger
    gpio.gpio_trigger = lambda *a: (calls.append(world.t), real(*a))[1]
    gpio.stick_echo_high()
    hc.trigger()
    hc.trigger()                    # still waiting: not sent again
    assert len(calls) == 1
    r, t = wait_result(world, hc, periods=40)
    assert math.isnan(r)
    assert t == pytest.approx(0.030, abs=world.dt + 1e-9)
    for k in range(2, 4):           # every new wait ends the same way
        hc.trigger()
        r, _ = wait_result(world, hc, periods=40)
        assert math.isnan(r)
        assert hc.failures == k
    assert len(calls) == 3


def test_sonar_trigger_skipped_while_echo_under_way():
    world, gpio, hc = sonar_world(2.0)       # 11.7 ms echo
    calls = []
    real = gpio.gpio_trigger
    gpio.gpio_trigger = lambda *a: (calls.append(world.t), real(*a))[1]
    hc.trigger()
    world.advance(world.dt)
    hc.trigger()                             # the echo is high: skipped
    assert len(calls) == 1
    r, _ = wait_result(world, hc)
    assert abs(r - 2.0) <= 1 / US_PER_M + 1e-12
    hc.trigger()
    assert len(calls) == 2
    r, _ = wait_result(world, hc)
    assert abs(r - 2.0) <= 1 / US_PER_M + 1e-12
    assert hc.failures == 0


class FakeGpio:
    def __init__(self):
        self.funcs = {}
        self.triggers = 0
        self.tick = 1_000_000

    def set_mode(self, gpio, mode):
        return 0

    def callback(self, pin, edge, func):
        self.funcs[pin] = func

        class Cb:
            def cancel(self_inner):
                pass
        return Cb()

    def set_watchdog(self, pin, ms):
        return 0

    def gpio_trigger(self, pin, pulse_len=10, level=1):
        self.triggers += 1
        return 0

    def get_current_tick(self):
        return self.tick


def test_sonar_idle_watchdog_report_just_after_a_trigger_is_not_a_failure():
    """pigpio repeats the watchdog report every 30 ms while the echo line is quiet. One that lands
    between a trigger and the echo's rising edge (0.46 ms later) is the idle line's, not a missing
    echo: the measurement that follows must not be reported as failed."""
    gpio = FakeGpio()
    hc = HcSr04(gpio, TRIG, ECHO)
    hc.start()
    edge = gpio.funcs[ECHO]
    t0 = gpio.tick
    hc.trigger()
    edge(ECHO, pigpio.TIMEOUT, t0 + 100)          # the idle line's periodic report
    assert hc.poll() is None
    edge(ECHO, 1, t0 + 460)
    edge(ECHO, 0, t0 + 460 + 5831)
    assert hc.poll() == pytest.approx(1.0)
    assert hc.failures == 0


def test_sonar_by_hand_edges():
    gpio = FakeGpio()
    hc = HcSr04(gpio, TRIG, ECHO)
    hc.start()
    edge = gpio.funcs[ECHO]
    hc.trigger()
    edge(ECHO, 1, 2 ** 32 - 3000)
    edge(ECHO, 0, 2 ** 32 - 3000 + 11662 - 2 ** 32)      # 11662 us across the wrap: 2.0 m
    assert hc.poll() == pytest.approx(11662 / 5831)
    assert hc.poll() is None
    hc.trigger()
    edge(ECHO, pigpio.TIMEOUT, 5000)                      # nothing came back
    r = hc.poll()
    assert math.isnan(r) and hc.failures == 1


# --- INA219 on the simulated board -----------------------------------------------------------------

def test_the_sim_board_reads_its_battery_through_the_ina219_driver():
    board = open_board("sim", load(None), BoardOptions(noise=SensorNoise.off()))
    power, battery = board.hal.power, board.world.battery
    assert isinstance(power, Ina219)
    battery.voltage, battery.current = 15.3, 21.0
    v, i = power.read()
    assert v == pytest.approx(15.3, abs=0.002 + 0.5e-5)   # bus to half its 4 mV LSB, shunt to half 10 uV
    assert i == pytest.approx(21.0, abs=0.0025 + 1e-9)    # half of 10 uV / 2 mOhm
    board.close()


def test_the_simulated_power_monitor_is_as_noisy_as_configured():
    """battery_sigma = 0.01 V on the bus voltage (2.5 LSB) and as many LSBs on the shunt: 25 uV, 12.5 mA
    on 2 mOhm; each with the rounding to its LSB, 4 mV / sqrt(12) and 5 mA / sqrt(12), beside it."""
    board = open_board("sim", load(None), BoardOptions(seed=1))
    assert board.world.noise.battery_sigma == 0.01
    battery = board.world.battery
    battery.voltage, battery.current = 15.3, 10.0
    v, i = np.array([board.hal.power.read() for _ in range(400)]).T
    assert v.std() == pytest.approx(math.hypot(0.01, 0.004 / math.sqrt(12)), rel=0.15)
    assert i.std() == pytest.approx(math.hypot(0.0125, 0.005 / math.sqrt(12)), rel=0.15)
    assert v.mean() == pytest.approx(15.3, abs=4 * 0.01 / math.sqrt(400) + 0.002)
    assert i.mean() == pytest.approx(10.0, abs=4 * 0.0125 / math.sqrt(400) + 0.0025)
