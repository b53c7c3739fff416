"""The ESC driver through the real pigpio client against a fake pigpiod on loopback: the 449 Hz wave,
its on-times, the period-preserving switch, the frequency read-back that refuses to arm, and the
pigpiod-side dead-man that stops the motors when the controller dies."""
from __future__ import annotations

import time

import pigpio
import pytest

from helpers.fakes.pigpiod import running
from flightctl.drivers.esc import EscError, PigpioEsc, deadman_script, stop_motors, wave_pulses
from flightctl.hal import PWM_RANGE, ArmingRefused

# Real time on a shared machine: a test that measures wall-clock timing (frame rates, durations, pacing)
# is run again, up to twice, when the machine stalls it; what it asserts is unchanged.
pytestmark = pytest.mark.flaky(reruns=2)


PINS = (17, 27, 22, 25)
PERIOD_US = 2227           # round(1e6 / 449)


def wait_for(predicate, timeout=1.0, step=0.002):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if predicate():
            return True
        time.sleep(step)
    return predicate()


def expected_on_us(count: int) -> float:
    return count / PWM_RANGE * PERIOD_US


def test_wave_pulses_raise_all_pins_together_and_drop_each_after_its_on_time():
    pulses = wave_pulses(PINS, [1200, 1000, 1200, 1500], PERIOD_US)
    assert [(p.gpio_on, p.gpio_off, p.delay) for p in pulses] == [
        (sum(1 << p for p in PINS), 0, 1000),
        (0, 1 << 27, 200),
        (0, 1 << 17 | 1 << 22, 300),
        (0, 1 << 25, PERIOD_US - 1500),
    ]
    assert sum(p.delay for p in pulses) == PERIOD_US
    with pytest.raises(ValueError):
        wave_pulses(PINS, [0, 1000, 1000, 1000], PERIOD_US)


def test_start_puts_the_stop_pulse_at_449_hz_on_all_four_pins():
    with running() as (fake, pi):
        esc = PigpioEsc(pi, PINS)
        esc.start()
        wave = fake.live_wave()
        assert wave.length == PERIOD_US and esc.built_period_us == PERIOD_US
        assert 1e6 / wave.length == pytest.approx(449.0, abs=0.05)
        assert wave.on_times() == {p: 1000 for p in PINS}
        assert fake.errors == []


def test_written_counts_become_on_times_within_1us_of_a_2227us_period():
    commands = [[20000, 25000, 30000, 28000], [30900, 30870, 30812, 30999], [40000, 0, 19000, 21000]]
    with running() as (fake, pi):
        esc = PigpioEsc(pi, PINS, deadman_ms=0)
        esc.start()
        for counts in commands:
            esc.write(counts)
            assert wait_for(lambda: fake.live_wave_id() == esc._current)
            wave = fake.live_wave()
            assert wave.length == PERIOD_US
            on = wave.on_times()
            for pin, c in zip(PINS, counts):
                want = min(max(expected_on_us(c), esc.stop_us), esc.max_us)   # clamped to [1000, 2100] us
                assert abs(on[pin] - want) <= 1.0, (pin, c, on[pin], want)
        # and measured on the pins through the real callback thread (edge ticks across the 32-bit wrap)
        esc.write([22000, 26000, 31000, 35000])
        assert wait_for(lambda: fake.live_wave_id() == esc._current)
        measured = esc.measure(0.1)
        for pin, c in zip(PINS, [22000, 26000, 31000, 35000]):
            freq, high, n = measured[pin]
            assert freq == pytest.approx(449.03, abs=0.05) and n >= 40
            assert abs(high - expected_on_us(c)) <= 1.0
        assert fake.errors == []


def test_switching_waves_never_cuts_a_period_nor_queues_more_than_one_wave():
    with running() as (fake, pi):
        esc = PigpioEsc(pi, PINS, deadman_ms=0)
        esc.start()
        t_end = time.monotonic() + 0.4
        k = 0
        while time.monotonic() < t_end:       # far faster than the wave: every write a new command
            esc.write([20000 + (k % 50) * 100, 22000, 24000 + (k % 7) * 10, 26000])
            k += 1
            with fake.lock:
                assert len(fake._queue) <= 1   # pigpio would chain every wave sent early: lag would grow
        assert k > 100 and esc.deferred > 0
        assert fake.errors == []               # no wave deleted while on the pins or queued
        assert len(fake.waves) <= 4            # replaced waves are reclaimed
        starts = [t for t, _, _ in fake.history]
        for t in starts[1:]:                   # every switch at a cycle boundary of the first wave
            cycles = (t - starts[0]) / PERIOD_US
            assert abs(cycles - round(cycles)) < 1e-6
        final = [33000, 34000, 35000, 36000]   # the loop keeps writing: the last command gets through
        for _ in range(4):
            esc.write(final)
            time.sleep(PERIOD_US * 1e-6)
        assert wait_for(lambda: fake.live_wave_id() == esc._current)
        assert fake.live_wave().on_times() == {p: round(expected_on_us(c)) for p, c in zip(PINS, final)}


def test_a_450hz_loop_on_a_449hz_wave_keeps_the_lag_under_two_periods():
    with running() as (fake, pi):
        esc = PigpioEsc(pi, PINS, deadman_ms=0)
        esc.start()
        t0 = time.monotonic()
        for k in range(450):                   # one second at the loop rate, a new command each time
            while time.monotonic() < t0 + k / 450.0:
                pass
            esc.write([20000 + (k % 100) * 50, 21000, 22000, 23000])
            with fake.lock:
                assert len(fake._queue) <= 1
        assert fake.errors == []


def test_an_unchanged_command_sends_no_new_wave():
    with running() as (fake, pi):
        esc = PigpioEsc(pi, PINS, deadman_ms=0)
        esc.start()
        esc.write([30000, 30000, 30000, 30000])
        created = fake.count("WVCRE")
        for _ in range(20):
            esc.write([30000, 30000, 30000, 30000])
            esc.write([30001, 30000, 30000, 30000])   # the same on-time at 1 us resolution
        assert fake.count("WVCRE") == created


def test_arming_measures_449_hz_and_starts_the_deadman():
    with running() as (fake, pi):
        esc = PigpioEsc(pi, PINS)
        esc.arm()
        assert esc.armed and fake.script_running()
        for pin in PINS:
            freq, high, n = esc.measured[pin]
            assert freq == pytest.approx(449.03, abs=0.05) and abs(high - 1000) <= 1 and n >= 50
        esc.stop()
        assert not fake.script_running() and fake.scripts == {}
        assert fake.live_wave().on_times() == {p: 1000 for p in PINS}


@pytest.mark.parametrize("scale, shown", [(449.0 / 400.0, "400.0 Hz"), (2.0, "224.5 Hz")])
def test_arming_is_refused_when_the_output_frequency_is_wrong(scale, shown):
    # 400 Hz: what set_PWM_frequency(449) silently gives; 224.5 Hz: waves at half speed (pigpio #331)
    with running(wave_clock_scale=scale) as (fake, pi):
        esc = PigpioEsc(pi, PINS)
        with pytest.raises(ArmingRefused) as e:
            esc.arm()
        assert shown in str(e.value) and "449 Hz" in str(e.value) and "GPIO 17" in str(e.value)
        assert not esc.armed and not fake.script_running()
        assert fake.live_wave().on_times() == {p: 1000 for p in PINS}


def test_dma_pwm_cannot_make_449_hz():
    """The fact behind the wave: pigpio's DMA PWM answers the closest fixed frequency."""
    with running() as (fake, pi):
        assert pi.set_PWM_frequency(17, 449) == 400
        assert pi.get_PWM_frequency(17) == 400


def test_deadman_stops_the_motors_when_the_controller_stops_writing():
    with running() as (fake, pi):
        esc = PigpioEsc(pi, PINS, deadman_ms=100)
        esc.arm()
        t_end = time.monotonic() + 0.35         # longer than the dead-man: the writes keep it fed
        while time.monotonic() < t_end:
            esc.write([34000, 34000, 34000, 34000])
            time.sleep(0.002)
        assert fake.live_wave().on_times()[17] == round(expected_on_us(34000))
        assert fake.script_running()
        t_last = time.monotonic()               # the controller hangs: no more writes
        assert wait_for(lambda: fake.live_wave_id() is not None
                        and fake.live_wave().on_times() == {p: 1000 for p in PINS}, timeout=1.0)
        stopped_after = time.monotonic() - t_last
        assert 0.08 <= stopped_after <= 0.3
        assert not fake.script_running()
        assert fake.errors == []


def test_deadman_stops_the_motors_when_the_controller_process_dies():
    with running() as (fake, pi):
        esc = PigpioEsc(pi, PINS)
        esc.arm()
        esc.write([36000, 35000, 36000, 35000])
        assert wait_for(lambda: fake.live_wave().on_times()[27] == round(expected_on_us(35000)))
        pi.stop()                               # the client is gone: pigpiod alone keeps the wave...
        assert wait_for(lambda: fake.live_wave().on_times() == {p: 1000 for p in PINS}, timeout=1.0)
        assert fake.errors == []


def test_after_the_deadman_fired_the_controller_does_not_resume_flight():
    with running() as (fake, pi):
        esc = PigpioEsc(pi, PINS)
        esc.arm()
        t0 = time.monotonic()
        for k in range(45):                     # armed, a new command every loop: no false alarm
            while time.monotonic() < t0 + k / 450.0:
                pass
            esc.write([30000 + 40 * k] * 4)
        time.sleep(0.3)                         # the loop stalls: the dead-man stops the motors
        assert fake.live_wave().on_times() == {p: 1000 for p in PINS}
        with pytest.raises(EscError, match="dead-man stopped the motors"):
            esc.write([31000] * 4)
        assert fake.live_wave().on_times() == {p: 1000 for p in PINS}
        esc.stop()


def test_start_and_stop_motors_clear_what_a_dead_controller_left_behind():
    with running() as (fake, pi):
        dead = PigpioEsc(pi, PINS, deadman_ms=10_000)   # a controller that died armed, long dead-man
        dead.arm()
        dead.write([38000, 38000, 38000, 38000])
        assert wait_for(lambda: fake.live_wave_id() == dead._current)
        assert fake.script_running()
        stop_motors(pi, PINS)                    # what ExecStopPost runs
        assert fake.scripts == {}                # the stale dead-man is gone: it cannot halt the next flight
        assert fake.live_wave().on_times() == {p: 1000 for p in PINS}
        fresh = PigpioEsc(pi, PINS)
        fresh.arm()
        fresh.write([30000, 30000, 30000, 30000])
        assert wait_for(lambda: fake.live_wave_id() == fresh._current)
        fresh.stop()


def test_deadman_script_text_uses_pigpio_script_commands():
    text = deadman_script(PINS, 3)
    assert text == "tag 0 mils 10 dcr p0 jp 0 wvhlt w 17 0 w 27 0 w 22 0 w 25 0 wvtxr 3 halt"
    with running() as (fake, pi):
        sid = pi.store_script(text.encode())
        assert sid >= 0
        with pytest.raises(pigpio.error):
            pi.store_script(b"tag 0 frobnicate 3")


def test_bad_construction_is_refused():
    with pytest.raises(ValueError):
        PigpioEsc(None, (17, 17, 22, 25))
    with pytest.raises(ValueError):
        PigpioEsc(None, PINS, stop_us=1000, max_us=2300)   # longer than the 2227 us period
