"""On the quadcopter itself: `python -m pytest -m hardware tests/hardware -v` on the Pi, pigpiod running,
PROPELLERS OFF. Deselected by default (pyproject: -m 'not hardware'); skips itself without
/dev/spidev0.0 or a reachable pigpiod. Set FLIGHTCTL_BOARD_FILE to use another wiring than the
shipped flightctl/boards/pi.toml.

No test here spins a motor: the ESC outputs carry the stop pulse or pulses below eq. 26's dead zone
(h2 = 120, 1048 us). What they check is what the fakes cannot: the real 449 Hz on the pins, pigpiod
accepting the dead-man script, the real chips answering, the loop's timing on the Pi's CPU.
"""
from __future__ import annotations

import math
import os
import socket
import time
from pathlib import Path

import pytest

from checks import loop_io, sonar_answers

BOARD_FILE = os.environ.get("FLIGHTCTL_BOARD_FILE")


def _pigpiod_reachable(host: str = "127.0.0.1", port: int = 8888) -> bool:
    try:
        with socket.create_connection((host, port), timeout=0.5):
            return True
    except OSError:
        return False


pytestmark = [
    pytest.mark.hardware,
    pytest.mark.skipif(not Path("/dev/spidev0.0").exists(), reason="no /dev/spidev0.0 (not on the quadcopter)"),
    pytest.mark.skipif(not _pigpiod_reachable(), reason="pigpiod not reachable on 127.0.0.1:8888"),
]


@pytest.fixture(scope="module")
def config():
    from flightctl.boards.pi import load_board

    return load_board(BOARD_FILE)


@pytest.fixture
def pi(config):
    from flightctl.boards.pi import connect_pigpio

    p = connect_pigpio(config)
    yield p
    p.stop()


@pytest.fixture
def esc(pi, config):
    from flightctl.drivers.esc import PigpioEsc

    e = PigpioEsc(pi, config.esc.pins, 449.0, config.esc.stop_us, config.esc.max_us, config.esc.deadman_ms,
                  config.esc.tolerance_hz)
    e.start()
    yield e
    e.stop()


def test_pigpiod_is_bound_to_localhost_only():
    import subprocess

    out = subprocess.run(["ss", "-ltnH", "sport = :8888"], capture_output=True, text=True).stdout
    assert out.strip(), "nothing listens on port 8888"
    assert all(("127.0.0.1:8888" in line or "[::1]:8888" in line) for line in out.strip().splitlines()), out


def test_esc_outputs_run_at_449hz_with_the_stop_pulse(esc):
    measured = esc.measure(0.5)
    for pin, (freq, high, n) in measured.items():
        assert abs(freq - 449.0) < 0.5, (pin, freq)
        assert abs(high - esc.stop_us) < 12, (pin, high)
        assert n > 200


def test_arming_check_and_the_deadman_script_are_accepted_by_pigpiod(esc, pi):
    import pigpio

    esc.arm()
    assert esc.armed and esc._sid is not None
    status, _ = pi.script_status(esc._sid)
    assert status in (pigpio.PI_SCRIPT_RUNNING, pigpio.PI_SCRIPT_WAITING)
    below_dead_zone = round(1030 / 2227 * 40000)          # 1030 us: under h2, the motors do not turn
    t_end = time.monotonic() + 0.3
    while time.monotonic() < t_end:
        esc.write([below_dead_zone] * 4)
        time.sleep(1 / 450)
    assert abs(esc.measure(0.1)[esc.pins[0]][1] - 1030) < 12
    time.sleep(0.3)                                       # no writes: the dead-man fires
    status, _ = pi.script_status(esc._sid)
    assert status == pigpio.PI_SCRIPT_HALTED
    for pin, (freq, high, n) in esc.measure(0.2).items():
        assert abs(high - esc.stop_us) < 12, (pin, high)


def test_imu_is_an_mpu9250_and_reads_one_g_at_rest(config):
    from flightctl.boards.boardfile import open_spi
    from flightctl.drivers.mpu9250 import Mpu9250
    from flightctl.hal import ImuSample

    spi = open_spi(config.imu)
    try:
        imu = Mpu9250(spi)
        imu.start()
        s = ImuSample()
        good = sum(imu.read(s) for _ in range(100))
        assert good == 100
        assert math.sqrt(s.ax ** 2 + s.ay ** 2 + s.az ** 2) == pytest.approx(9.81, abs=0.8)
    finally:
        spi.close()


def test_power_monitor_reads_a_battery(config):
    import smbus2

    from flightctl.drivers.ina219 import Ina219

    bus = smbus2.SMBus(config.power.i2c_bus)
    try:
        ina = Ina219(bus, config.power.address, config.power.shunt_ohm, config.power.max_current_a)
        ina.start()
        v, i = ina.read()
        assert 5.0 < v < 26.0 and abs(i) < config.power.max_current_a
    finally:
        bus.close()


def test_sonar_answers(pi, config):
    from flightctl.drivers.hcsr04 import HcSr04

    sonar = HcSr04(pi, config.sonar.trigger_pin, config.sonar.echo_pin)
    sonar.start()
    try:
        sonar_answers(sonar)
    finally:
        sonar.stop()


def test_the_loop_keeps_450hz_with_imu_and_esc_io(esc, config):
    """The inner loop's I/O at 450 Hz for 3 s: IMU burst read + ESC write per tick (no control math)."""
    below = [round(1030 / 2227 * 40000) + k % 3 for k in range(4)]
    loop_io(config, esc.write, lambda k: [c + k % 2 for c in below],       # a new command every tick: the worst case
            "ESC write (a new wave)")
    print(f"{esc.deferred} commands deferred")
