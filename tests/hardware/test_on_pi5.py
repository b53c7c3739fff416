"""The first-flight checklist on the quadcopter's Raspberry Pi 5 (docs/pi.md, "First flight checklist"):
`python -m pytest -m hardware tests/hardware/test_on_pi5.py -v -s` on the Pi, the flightctl service stopped,
PROPELLERS OFF. Every step prints what it measured and, when it fails, what to do. Deselected by default
(pyproject: -m 'not hardware'); skips itself off a Pi 5 or without /dev/spidev0.0. Set FLIGHTCTL_BOARD_FILE
for another wiring than the shipped flightctl/boards/pi5.toml, FLIGHTCTL_LOOP_S for a shorter loop check
than a minute, and FLIGHTCTL_LOOPBACK_PIN=N with a jumper from motor 1's pin (GPIO 12, header
pin 32) to GPIO N to have the real output measured (kernel edge timestamps on GPIO N).

No test here spins a motor: the ESC outputs carry the stop pulse or 1030 us, below eq. 26's dead zone
(h2 = 120, 1048 us). What they check is what the fakes cannot: the RP1's PWM chip and the overlay, the
kernel accepting the writes as the fake does, the dead-man process on the Pi, the real chips answering,
and the loop's timing with the sysfs writes.
"""
from __future__ import annotations

import os
import statistics
import time
from pathlib import Path

import pytest

from checks import battery, imu_at_rest, loop_io, sonar_answers, step

from flightctl.boards.detect import MODEL_PATHS, is_pi5, model

BOARD_FILE = os.environ.get("FLIGHTCTL_BOARD_FILE")
LOOPBACK = os.environ.get("FLIGHTCTL_LOOPBACK_PIN")
BELOW_DEAD_ZONE = round(1030 / 2227.171 * 40000)       # 1030 us: under h2, the motors do not turn

pytestmark = [
    pytest.mark.hardware,
    pytest.mark.skipif(not is_pi5(), reason="not a Raspberry Pi 5"),
    pytest.mark.skipif(not Path("/dev/spidev0.0").exists(), reason="no /dev/spidev0.0 (not on the quadcopter)"),
]


@pytest.fixture(scope="module")
def config():
    from flightctl.boards.pi5 import load_board

    return load_board(BOARD_FILE)


@pytest.fixture
def esc(config):
    from flightctl.drivers.pwm_sysfs import SysfsPwmEsc

    e = SysfsPwmEsc(config.pwm.chip, config.pwm.channels, 449.0, config.esc.stop_us, config.esc.max_us,
                    config.esc.deadman_ms, pins=config.pwm.pins)
    e.start()
    yield e
    e.close()


def test_the_board_is_found_where_the_service_looks(config):
    step("board detection", f"{MODEL_PATHS[0]}: {model((MODEL_PATHS[0],))!r}", is_pi5(model((MODEL_PATHS[0],))),
         "the service's sandbox hides /proc/device-tree: the model must be readable from sysfs; update the "
         "kernel (sudo apt full-upgrade)")


def test_the_esc_channels_take_the_period_and_the_stop_pulse(esc):
    back = {}
    for c in esc.channels:
        d = Path(esc.dir, f"pwm{c}")
        back[c] = {k: (d / k).read_text().strip() for k in ("period", "duty_cycle", "enable", "polarity")}
    shown = "; ".join(f"channel {c}: period {v['period']} ns, pulse {int(v['duty_cycle']) / 1000:g} us, "
                      f"enable {v['enable']}, {v['polarity']}" for c, v in back.items())
    ok = esc.output_problems() == [] and esc.check_frequency() == pytest.approx(449.0, abs=0.01)
    step("ESC pulses read back", shown, ok,
         "another process drives a channel (ls /sys/class/pwm/*/pwm*; flightctl run --board pi5 --stop-motors "
         "releases what a dead controller left), or the board file's chip and channels are wrong")


def test_the_overlay_muxes_the_esc_pins_to_pwm0(config):
    import shutil
    import subprocess

    if shutil.which("pinctrl") is None:
        pytest.skip("no pinctrl")
    for pin, channel in zip(config.pwm.pins, config.pwm.channels):
        out = subprocess.run(["pinctrl", "get", str(pin)], capture_output=True, text=True).stdout
        step(f"GPIO {pin} muxed to PWM0 channel {channel}", out.strip(), f"PWM0_CHAN{channel}" in out,
             "dtoverlay=flightctl-pwm-pi5 missing from /boot/firmware/config.txt or not applied: rerun "
             "scripts/install-pi.sh and reboot")


@pytest.mark.skipif(LOOPBACK is None, reason="FLIGHTCTL_LOOPBACK_PIN not set (no jumper from GPIO 12)")
def test_the_real_output_runs_at_449hz_with_the_commanded_on_time(esc):
    import gpiod
    from gpiod.line import Edge

    from flightctl.boards.pi5 import open_gpio_chip

    chip = open_gpio_chip("pinctrl-rp1")
    req = chip.request_lines({int(LOOPBACK): gpiod.LineSettings(edge_detection=Edge.BOTH)}, consumer="flightctl-test")
    try:
        for on_us, count in ((1000, 0), (1030, BELOW_DEAD_ZONE)):
            esc.write([count] * 4)
            time.sleep(0.05)
            req.read_edge_events() if req.wait_edge_events(0) else None
            events, end = [], time.monotonic() + 0.5
            while time.monotonic() < end:
                if req.wait_edge_events(0.05):
                    events += req.read_edge_events()
            rises = [e.timestamp_ns for e in events if e.event_type == e.Type.RISING_EDGE]
            highs = [b.timestamp_ns - a.timestamp_ns for a, b in zip(events, events[1:])
                     if a.event_type == a.Type.RISING_EDGE and b.event_type == b.Type.FALLING_EDGE]
            freq = 1e9 * (len(rises) - 1) / (rises[-1] - rises[0])
            high = statistics.median(highs) / 1e3
            step(f"pulse on the pin, {on_us} us commanded", f"{freq:.3f} Hz, high {high:.2f} us",
                 abs(freq - 449.0) < 0.5 and abs(high - on_us) < 5,
                 "check the jumper from GPIO 12 to the loopback pin; a wrong width or rate with the right "
                 "sysfs values means the pin is driven by something else (pinctrl get 12)")
    finally:
        req.release()
        chip.close()


def test_the_dead_man_process_stops_the_escs_when_the_loop_stalls(esc):
    esc.arm()
    end = time.monotonic() + 0.3
    while time.monotonic() < end:
        esc.write([BELOW_DEAD_ZONE] * 4)
        time.sleep(1 / 450)
    assert esc.output_problems() == []
    time.sleep(0.3)                                        # no writes: the dead-man fires
    duty = [Path(esc.dir, f"pwm{c}", "duty_cycle").read_text().strip() for c in esc.channels]
    step("dead-man after a 0.3 s stall", f"duty cycles {duty} ns", duty == [str(esc.stop_us * 1000)] * 4,
         "the dead-man process did not fire: do not fly; journalctl for its errors, and check that the "
         "flightctl user can write the duty_cycle files (the udev rule)")
    with pytest.raises(Exception, match="dead-man"):
        esc.write([BELOW_DEAD_ZONE] * 4)


def test_the_imu_reads_one_g_and_small_rates_at_rest(config):
    imu_at_rest(config)


def test_the_power_monitor_reads_the_battery(config):
    battery(config)


def test_the_sonar_answers_through_the_gpio_character_device(config):
    from flightctl.boards.pi5 import open_gpio_chip
    from flightctl.drivers.gpio_cdev import CdevGpio
    from flightctl.drivers.hcsr04 import HcSr04

    chip = open_gpio_chip(config.gpio.chip)
    lines = CdevGpio(chip, config.sonar.trigger_pin, config.sonar.echo_pin)
    lines.start()
    sonar = HcSr04(lines, config.sonar.trigger_pin, config.sonar.echo_pin)
    sonar.start()
    try:
        sonar_answers(sonar)
    finally:
        sonar.stop()
        lines.close()
        chip.close()


def test_the_loop_keeps_450hz_with_imu_reads_and_pwm_writes(esc, config):
    """The inner loop's I/O at 450 Hz for a minute: an IMU burst read and four duty-cycle writes per tick."""
    loop_io(config, esc.write, lambda k: [BELOW_DEAD_ZONE + (k + i) % 3 for i in range(4)],   # all change: the worst case
            "ESC write (4 duty cycles)")
