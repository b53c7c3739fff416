"""The Pi 5's sonar: the one HC-SR04 driver (flightctl/drivers/hcsr04.py) on the GPIO character device
(flightctl/drivers/gpio_cdev.py, libgpiod 2.x's API) against the fake GPIO chip (tests/helpers/fakes/gpiochip.py):
echoes timed by the kernel's timestamps, no echo, a stuck echo, the module's out-of-range pulse, the
trigger pulse the module needs, and a line another process holds."""
from __future__ import annotations

import math
import random
import time

import gpiod
import pytest

from helpers.fakes.gpiochip import MIN_TRIGGER_NS, FakeGpioDevice
from flightctl.drivers.gpio_cdev import CdevGpio, GpioBusy
from flightctl.drivers.hcsr04 import US_PER_M, WATCHDOG_MS, HcSr04
from test_hcsr04_pigpio import measure      # the same measurement as on the pigpio board

TRIGGER, ECHO = 23, 24


@pytest.fixture
def device():
    d = FakeGpioDevice()
    yield d
    d.close()


def sonar_on(device, **kw):
    lines = CdevGpio(device.chip(), TRIGGER, ECHO, **kw)
    lines.start()
    sonar = HcSr04(lines, TRIGGER, ECHO)
    sonar.start()
    return lines, sonar


def test_echoes_are_timed_by_the_kernel_timestamps(device):
    rng = random.Random(5)
    module = device.attach_sonar(TRIGGER, ECHO)
    lines, sonar = sonar_on(device)
    for _ in range(12):
        module.distance_m = rng.uniform(0.05, 3.9)
        r = measure(sonar)
        # the width is two timestamps in whole microseconds: within 1 us, 0.17 mm
        assert r == pytest.approx(module.distance_m, abs=1.0 / US_PER_M), module.distance_m
    assert module.triggers == 12 and module.ignored == 0         # every trigger pulse was long enough
    assert lines.edges == 24 and lines.error is None
    lines.close()


def test_a_late_reader_still_measures_the_true_width(device):
    """The reader thread is held off for 5 ms (a busy CPU) while the echo comes and goes: the width is
    the difference of the kernel's timestamps, not of the times the events were read."""
    device.attach_sonar(TRIGGER, ECHO, 0.3)
    lines, sonar = sonar_on(device)
    with device.lock:                                  # nothing is delivered while the lock is held
        sonar.trigger()
        time.sleep(0.005)                              # the whole 2.2 ms echo passes meanwhile
    r = None
    while r is None:                                   # the reader thread, however late it runs
        r = sonar.poll()
        time.sleep(0.001)
    assert r == pytest.approx(0.3, abs=1.0 / US_PER_M)
    lines.close()


@pytest.mark.parametrize("mode", ["none", "stuck", "far"])
def test_a_failed_measurement_is_nan_within_the_watchdog(device, mode):
    module = device.attach_sonar(TRIGGER, ECHO, 1.0, mode=mode)
    lines, sonar = sonar_on(device)
    t0 = time.monotonic()
    r = measure(sonar, timeout=60.0)                   # waited for, however busy the machine
    took = time.monotonic() - t0
    assert r is not None and math.isnan(r)
    assert WATCHDOG_MS / 1000 - 0.005 < took           # the watchdog's 30 ms, not before
    time.sleep(0.03)              # "far": the module's 38 ms pulse ends now; it must not read as a range
    assert sonar.poll() is None and sonar.failures == 1
    if mode != "stuck":
        module.mode = "echo"
        assert measure(sonar) == pytest.approx(1.0, abs=1e-3)   # and the next measurement works again
    lines.close()


def test_a_trigger_shorter_than_10_us_gets_no_echo_so_the_driver_sends_10(device):
    module = device.attach_sonar(TRIGGER, ECHO, 1.0)
    lines, _ = sonar_on(device)
    # A 3 us pulse is busy-waited between two line writes, as on the Pi: a busy machine may preempt the
    # thread between them and stretch it past 10 us. Each pulse is judged by the width the module saw,
    # until one came out short (on a quiet machine the first).
    for k in range(1, 51):
        lines.gpio_trigger(TRIGGER, 3, 1)
        while module.triggers + module.ignored < k:   # the fake kernel's thread, however late it runs
            time.sleep(0.001)
        short = [w < MIN_TRIGGER_NS for w in module.widths_ns]
        assert (module.triggers, module.ignored) == (short.count(False), short.count(True))
        if short[-1]:
            break
    assert short[-1], module.widths_ns
    before = module.triggers
    lines.gpio_trigger(TRIGGER, 10, 1)
    while module.triggers + module.ignored < k + 1:
        time.sleep(0.001)
    assert module.triggers == before + 1 and module.widths_ns[-1] >= MIN_TRIGGER_NS
    lines.close()


@pytest.mark.parametrize("line", [TRIGGER, ECHO])
def test_a_line_held_by_another_process_is_a_refusal_naming_it(device, line):
    device.hold(line, "gpio-keys")
    with pytest.raises(GpioBusy, match=rf"GPIO {line} is held by 'gpio-keys'"):
        CdevGpio(device.chip(), TRIGGER, ECHO).start()
    other = TRIGGER if line == ECHO else ECHO
    assert not device.chip().get_line_info(other).used          # the other line was not kept


def test_the_lines_are_requested_as_the_kernel_shows_them_and_released_at_close(device):
    lines, sonar = sonar_on(device)
    chip = device.chip()
    trig, echo = chip.get_line_info(TRIGGER), chip.get_line_info(ECHO)
    assert trig.used and trig.consumer == "flightctl" and trig.direction == gpiod.line.Direction.OUTPUT
    assert echo.used and echo.direction == gpiod.line.Direction.INPUT
    assert echo.edge_detection == gpiod.line.Edge.BOTH
    with pytest.raises(OSError):                                  # ours now: another request is EBUSY
        chip.request_lines({ECHO: gpiod.LineSettings()}, consumer="other")
    sonar.stop()
    lines.close()
    assert not chip.get_line_info(TRIGGER).used and not chip.get_line_info(ECHO).used
