"""HC-SR04 ultrasonic rangefinder on pigpio: a 10 us trigger pulse, the echo width measured from
either-edge callbacks with microsecond ticks (`tick_diff`, wrap-safe), a watchdog for the
no-echo and stuck-high cases, and out-of-range readings rejected.

`gpio` is a `pigpio.pi` on the quadcopter and `sim.devices.SimGpio` in simulation: the same edge
handling runs in both.
"""
from __future__ import annotations

import math


from flightctl.hal import EITHER_EDGE, GPIO_INPUT, GPIO_OUTPUT, LEVEL_TIMEOUT, Gpio, tick_diff

US_PER_M = 5831.0           # echo width per metre: there and back at 343 m/s
MIN_RANGE_M, MAX_RANGE_M = 0.02, 4.0
WATCHDOG_MS = 30            # longer than the 23 ms echo of the 4 m range


class HcSr04:
    def __init__(self, gpio: Gpio, trigger_pin: int, echo_pin: int):
        self.gpio, self.trigger_pin, self.echo_pin = gpio, trigger_pin, echo_pin
        self._rise = None       # tick of the rising echo edge
        self._waiting = False   # a trigger was sent and its echo has not ended
        self._result = None     # distance (m), NaN for a failed measurement, None for nothing new
        self._t_trigger = 0     # tick of the last trigger
        self.failures = 0       # consecutive failed measurements
        self._cb = None

    def start(self) -> None:
        self.gpio.set_mode(self.trigger_pin, GPIO_OUTPUT)
        self.gpio.set_mode(self.echo_pin, GPIO_INPUT)
        self._cb = self.gpio.callback(self.echo_pin, EITHER_EDGE, self._edge)
        self.gpio.set_watchdog(self.echo_pin, WATCHDOG_MS)

    def stop(self) -> None:
        if self._cb is not None:
            self._cb.cancel()
            self._cb = None
        self.gpio.set_watchdog(self.echo_pin, 0)

    def trigger(self) -> None:
        """Start a measurement unless the last one is still under way (its echo still high)."""
        if self._waiting:
            return
        self._waiting = True
        self._t_trigger = self.gpio.get_current_tick()
        self.gpio.gpio_trigger(self.trigger_pin, 10, 1)

    def _edge(self, gpio: int, level: int, tick: int) -> None:
        if level == 1:
            self._rise = tick
        elif level == 0 and self._rise is not None:
            width_us = tick_diff(self._rise, tick)
            self._rise = None
            self._waiting = False
            distance = width_us / US_PER_M
            self._finish(distance if MIN_RANGE_M <= distance <= MAX_RANGE_M else math.nan)
        elif level == LEVEL_TIMEOUT and self._waiting and (
                self._rise is not None or tick_diff(self._t_trigger, tick) >= 1000 * WATCHDOG_MS):
            # no edge for WATCHDOG_MS since the trigger: no echo came back, or the echo line is stuck
            # high (pigpio repeats the report on a quiet line, so one may land just after a trigger)
            self._rise = None
            self._waiting = False
            self._finish(math.nan)

    def _finish(self, distance: float) -> None:
        self.failures = self.failures + 1 if distance != distance else 0
        self._result = distance

    def poll(self) -> float | None:
        result, self._result = self._result, None
        return result
