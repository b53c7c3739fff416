"""The MPU-9250 driver against the register-level fake chip (sim.world.imu.SimMpu9250 behind xfer2):
wrong chip, bus-error frames of all 0x00 / 0xFF, and the loop stopping the motors when frames go bad."""
from __future__ import annotations

import math

import pytest

from flightctl.sim.world.board import sim_board
from flightctl.drivers.mpu9250 import ImuError, Mpu9250
from flightctl.hal import ImuSample
from flightctl.loop import MAX_BAD_IMU_FRAMES, FlightLoop
from flightctl.params import load
from flightctl.sim.world.devices import SensorNoise, World
from flightctl.sim.world.imu import SimMpu9250
from flightctl.sim.flights.scenarios import SCENARIOS


@pytest.fixture
def world():
    return World(load(None).airframe, noise=SensorNoise.off())


def test_a_good_chip_reads_one_g_at_rest_in_si(world):
    imu = Mpu9250(SimMpu9250(world), sleep=lambda s: None)
    imu.start()
    s = ImuSample()
    assert imu.read(s)
    assert (s.ax, s.ay) == pytest.approx((0.0, 0.0), abs=0.01)
    assert s.az == pytest.approx(9.80665, abs=0.01)
    assert (s.gx, s.gy, s.gz) == pytest.approx((0.0, 0.0, 0.0), abs=1e-3)
    assert imu.has_mag and s.mag_fresh


@pytest.mark.parametrize("who", [0x70, 0x00, 0xFF])
def test_a_wrong_chip_is_refused_naming_the_value(world, who):
    imu = Mpu9250(SimMpu9250(world, who_am_i=who), sleep=lambda s: None)
    with pytest.raises(ImuError, match=f"0x{who:02X}"):
        imu.start()


@pytest.mark.parametrize("fault", ["zeros", "ones"])
def test_bus_error_frames_are_rejected_and_the_sample_left_alone(world, fault):
    spi = SimMpu9250(world)
    imu = Mpu9250(spi, sleep=lambda s: None)
    imu.start()
    s = ImuSample()
    assert imu.read(s)
    before = (s.ax, s.ay, s.az)
    spi.fault = fault
    assert imu.read(s) is False
    assert (s.ax, s.ay, s.az) == before
    spi.fault = None
    assert imu.read(s)


@pytest.mark.parametrize("fault", ["zeros", "ones"])
def test_motors_stop_when_imu_frames_go_bad_mid_flight(fault):
    params = load(None)
    hal, world = sim_board(params)
    writes = []
    real_write = hal.motors.write

    def recording_write(counts):
        writes.append(list(counts))
        real_write(counts)

    hal.motors.write = recording_write
    fault_at = 450 * 3                          # 1 s calibrating, then 2 s climbing
    bad_from = []

    def on_tick(i):
        if i == fault_at:
            hal.imu.spi.fault = fault
            bad_from.append(i)

    plan = SCENARIOS["hover"]().plan
    plan.restart()
    result = FlightLoop(hal, params, plan, calibrate_s=1.0, on_tick=on_tick).run()
    assert result.reason == "stopped: IMU frames bad"
    assert bad_from and result.iterations == fault_at + MAX_BAD_IMU_FRAMES
    assert max(max(c) for c in writes[:-1]) > 0        # it was flying
    assert writes[-1] == [0, 0, 0, 0]                  # the last command: zero thrust
    assert world.plant.u[:4] == (0.0, 0.0, 0.0, 0.0) or all(p == 0 for p in world.plant._next[:4])
    assert not math.isnan(world.plant.t)
