"""The first-flight checklist on the quadcopter's Raspberry Pi 3/4 (docs/pi.md, "First flight checklist"):
`python -m pytest -m hardware tests/hardware/test_on_pi.py -v -s` on the Pi, pigpiod running, the flightctl
service stopped, PROPELLERS OFF. Every step prints what it measured and, when it fails, what to do.
Deselected by default (pyproject: -m 'not hardware'); skips itself without /dev/spidev0.0 or a reachable
pigpiod. Set FLIGHTCTL_BOARD_FILE to use another wiring than the shipped flightctl/boards/pi.toml, and
FLIGHTCTL_LOOP_S for a shorter loop check than a minute.

No test here spins a motor: the ESC outputs carry the stop pulse or pulses below eq. 26's dead zone
(h2 = 120, 1048 us). What they check is what the fakes cannot: the real 449 Hz on the pins, pigpiod
accepting the dead-man script, the real chips answering, the loop's timing on the Pi's CPU.
"""
from __future__ import annotations

import os
import socket
import time
from pathlib import Path

import pytest

from checks import battery, imu_at_rest, loop_io, sonar_answers, step

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
    lines = out.strip().splitlines()
    step("pigpiod's port", "; ".join(" ".join(line.split()[2:4]) for line in lines) or "nothing listens on 8888",
         bool(lines) and all(("127.0.0.1:8888" in line or "[::1]:8888" in line) for line in lines),
         "pigpiod must run with -l (systemd/pigpiod.service.d/flightctl.conf): rerun scripts/install-pi.sh "
         "and systemctl restart pigpiod")


def test_esc_outputs_run_at_449hz_with_the_stop_pulse(esc):
    measured = esc.measure(0.5)
    step("ESC pulses measured on the pins", "; ".join(f"GPIO {pin}: {freq:.2f} Hz, {high:.0f} us ({n} edges)"
                                                      for pin, (freq, high, n) in measured.items()),
         all(abs(freq - 449.0) < 0.5 and abs(high - esc.stop_us) < 12 and n > 200 for freq, high, n in measured.values()),
         "a pin without edges: check [esc] pins in the board file; at 224.5 Hz: pigpio's wave clock runs at half "
         "speed (pigpio issue #331), do not fly")


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
    high = esc.measure(0.1)[esc.pins[0]][1]
    step("1030 us commanded", f"GPIO {esc.pins[0]}: {high:.0f} us", abs(high - 1030) < 12,
         "the wave did not change: pigpiod refused it; journalctl -u pigpiod")
    time.sleep(0.3)                                       # no writes: the dead-man fires
    status, _ = pi.script_status(esc._sid)
    after = esc.measure(0.2)
    step("dead-man after a 0.3 s stall", f"script status {status} (halted: {pigpio.PI_SCRIPT_HALTED}); "
         + ", ".join(f"GPIO {pin}: {h:.0f} us" for pin, (_, h, _) in after.items()),
         status == pigpio.PI_SCRIPT_HALTED and all(abs(h - esc.stop_us) < 12 for _, h, _ in after.values()),
         "pigpiod did not run the dead-man script: do not fly; check pigpiod's version (79) and its log")


def test_imu_is_an_mpu9250_and_reads_one_g_and_small_rates_at_rest(config):
    imu_at_rest(config)


def test_power_monitor_reads_a_battery(config):
    battery(config)


def test_sonar_answers(pi, config):
    from flightctl.drivers.hcsr04 import HcSr04

    sonar = HcSr04(pi, config.sonar.trigger_pin, config.sonar.echo_pin)
    sonar.start()
    try:
        sonar_answers(sonar)
    finally:
        sonar.stop()


def test_the_loop_keeps_450hz_with_imu_and_esc_io(esc, config):
    """The inner loop's I/O at 450 Hz for a minute: IMU burst read + ESC write per tick (no control math)."""
    below = [round(1030 / 2227 * 40000) + k % 3 for k in range(4)]
    loop_io(config, esc.write, lambda k: [c + k % 2 for c in below],       # a new command every tick: the worst case
            "ESC write (a new wave)")
    print(f"{esc.deferred} commands deferred")
