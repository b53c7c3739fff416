"""The HC-SR04 driver on a real `pigpio.pi` (its callback thread, 12-byte notification reports, the
watchdog) against the fake pigpiod: echoes, the 32-bit tick wrap, no echo, a stuck echo, out of range."""
from __future__ import annotations

import math
import time

import pytest

from helpers.fakes.pigpiod import running
from flightctl.drivers.hcsr04 import WATCHDOG_MS, HcSr04

TRIG, ECHO = 23, 24


def measure(sonar: HcSr04, timeout: float = 0.5):
    """Trigger once and wait for the result (None if nothing came)."""
    sonar.trigger()
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        r = sonar.poll()
        if r is not None:
            return r
        time.sleep(0.002)
    return None


@pytest.fixture
def sonar_on_fake():
    with running() as (fake, pi):
        fake.attach_sonar(TRIG, ECHO, distance_m=1.0)
        sonar = HcSr04(pi, TRIG, ECHO)
        sonar.start()
        yield fake, sonar
        sonar.stop()


def test_echo_width_gives_the_distance_across_the_tick_wrap():
    with running(tick0=(1 << 32) - 100_000) as (fake, pi):   # the 32-bit tick wraps within an echo
        fake.attach_sonar(TRIG, ECHO)
        sonar = HcSr04(pi, TRIG, ECHO)
        sonar.start()
        distances = (0.25, 1.0, 2.5, 3.9, 0.5)
        wrapped = False
        for k in range(60):                                   # until the echoes have crossed the wrap
            d = distances[k % len(distances)]
            fake.sonar.distance_m = d
            if not wrapped:      # the wrap put mid-echo again: a busy machine may let it pass between two echoes
                fake.tick0 = ((1 << 32) - int(fake.now_us()) - int(d / 343.0 * 1e6)) & 0xFFFFFFFF
            before = fake.tick(fake.now_us())
            r = measure(sonar)
            assert r == pytest.approx(d, abs=0.001), (d, r)
            wrapped = wrapped or fake.tick(fake.now_us()) < before
            if wrapped and k >= len(distances):
                break
        assert wrapped
        assert sonar.failures == 0
        sonar.stop()


def test_no_echo_reports_nan_from_the_watchdog(sonar_on_fake):
    fake, sonar = sonar_on_fake
    fake.sonar.mode = "none"
    t0 = time.monotonic()
    r = measure(sonar)
    assert r is not None and math.isnan(r)
    assert time.monotonic() - t0 >= 0.8 * WATCHDOG_MS / 1000
    assert sonar.failures == 1
    fake.sonar.mode = "echo"                   # and it recovers
    assert measure(sonar) == pytest.approx(1.0, abs=0.001)
    assert sonar.failures == 0


def test_stuck_echo_keeps_reporting_nan(sonar_on_fake):
    fake, sonar = sonar_on_fake
    fake.sonar.mode = "stuck"
    for k in range(3):
        r = measure(sonar)
        assert r is not None and math.isnan(r), k
    assert sonar.failures == 3


def test_echo_beyond_4m_is_rejected(sonar_on_fake):
    fake, sonar = sonar_on_fake
    fake.sonar.distance_m = 4.5                # a 26 ms echo: shorter than the watchdog, out of range
    r = measure(sonar)
    assert r is not None and math.isnan(r)
