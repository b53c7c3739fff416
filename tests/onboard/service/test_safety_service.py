"""Issue 10, defect 1: only the flight controller commands the motors. Another pigpiod client (the
reviewer's unprivileged user on pigpiod's port) changes the ESC pins through the fake pigpiod, which
speaks the real protocol to two real `pigpio` clients: the driver's read-back notices it while
disarmed and in flight, arming is refused, and `stop()` always puts the stop wave back."""
from __future__ import annotations

import time

import pigpio
import pytest

from helpers.fakes.pigpiod import running
from flightctl.drivers.esc import EscError, OUTPUT_CHECK_S, PigpioEsc
from flightctl.hal import ArmingRefused

PINS = (17, 27, 22, 25)
PERIOD_US = 2227


def intrude(pi, on_us: int = 1900) -> int:
    """What the reviewer did: a repeating 1900 us wave on the four ESC pins, from a second client."""
    pi.wave_add_new()
    pi.wave_add_generic([pigpio.pulse(sum(1 << p for p in PINS), 0, on_us),
                         pigpio.pulse(0, sum(1 << p for p in PINS), PERIOD_US - on_us)])
    wid = pi.wave_create()
    pi.wave_send_repeat(wid)
    return wid


def test_stop_always_writes_the_stop_wave_even_when_it_believes_it_is_there():
    ctx = running()
    with ctx as (fake, pi):
        esc = PigpioEsc(pi, PINS, deadman_ms=0)
        esc.start()
        intruder = ctx.connect()
        intrude(intruder)
        assert fake.live_wave().on_times() == {p: 1900 for p in PINS}
        esc.stop()                                       # SIGTERM: the service's last stop()
        time.sleep(0.01)
        assert fake.live_wave_id() == esc._stop_wid
        assert fake.live_wave().on_times() == {p: 1000 for p in PINS}


def test_a_foreign_wave_while_disarmed_is_seen_and_arming_is_refused():
    ctx = running()
    with ctx as (fake, pi):
        esc = PigpioEsc(pi, PINS)
        esc.start()
        assert esc.output_problems(measure=True) == []
        intruder = ctx.connect()
        intrude(intruder)
        problems = esc.output_problems(measure=True)
        assert any("another" in p for p in problems), problems
        assert any("1900 us" in p for p in problems), problems     # the real output, measured
        with pytest.raises(ArmingRefused, match="another pigpiod client"):
            esc.arm()
        assert not esc.armed and not fake.script_running()


def test_a_pin_switched_to_input_by_another_client_is_seen():
    ctx = running()
    with ctx as (fake, pi):
        esc = PigpioEsc(pi, PINS)
        esc.start()
        ctx.connect().set_mode(PINS[2], pigpio.INPUT)
        assert any(f"GPIO {PINS[2]}" in p and "input" in p for p in esc.output_problems())


def test_a_foreign_wave_in_flight_stops_the_loop_within_the_check_period():
    ctx = running()
    with ctx as (fake, pi):
        esc = PigpioEsc(pi, PINS, deadman_ms=0)
        esc.arm()
        counts = [24000] * 4
        esc.write(counts)
        time.sleep(0.01)
        intruder = ctx.connect()
        t0 = time.monotonic()
        intrude(intruder)
        with pytest.raises(EscError, match="another pigpiod client"):
            while time.monotonic() - t0 < 1.0:
                esc.write(counts)                        # an unchanged command: nothing else would look
                time.sleep(1 / 450)
        assert time.monotonic() - t0 < OUTPUT_CHECK_S + 0.05
        esc.stop()
        time.sleep(0.01)
        assert fake.live_wave().on_times() == {p: 1000 for p in PINS}



class Notes:
    def __init__(self):
        self.lines: list[str] = []

    def status(self, text: str) -> None:
        self.lines.append(text)

    def tick(self) -> None:
        pass


def test_the_disarmed_service_notices_a_foreign_wave_puts_the_stop_pulse_back_and_never_arms_again():
    import argparse
    import threading
    from types import SimpleNamespace

    from flightctl.service.run import Service
    ctx = running()
    with ctx as (fake, pi):
        esc = PigpioEsc(pi, PINS)
        esc.start()
        board = SimpleNamespace(hal=SimpleNamespace(motors=esc), calibrate_s=0.0, min_battery_v=0.0, name="pi")
        args = argparse.Namespace(log=".", calibrate=None, min_battery_v=None)
        notes = Notes()
        svc = Service(args, None, board, notes, threading.Event())
        svc.watch_output()
        assert svc.tampered is None
        intrude(ctx.connect())
        svc._next_output_check = 0.0
        svc.watch_output()
        assert svc.tampered and "another pigpiod client" in svc.tampered
        assert notes.lines and "refusing to arm" in notes.lines[-1]
        time.sleep(0.01)
        assert fake.live_wave().on_times() == {p: 1000 for p in PINS}     # the stop pulse is back
        with pytest.raises(ArmingRefused, match="another pigpiod client"):
            svc.check()                                  # even though the output looks right again
