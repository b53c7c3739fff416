"""GPIO lines through the kernel's GPIO character device (libgpiod 2.x's Python binding `gpiod`), with the
calls the HC-SR04 driver makes (`hal.Gpio`, pigpio's names), so that one sonar driver (drivers/hcsr04.py)
times the echo on both Pi boards: pigpio's callbacks on a Pi 3/4, the kernel's edge events on a Pi 5.

    lines = CdevGpio(gpiod.Chip("/dev/gpiochip0"), trigger=23, echo=24)
    lines.start()                        # requests both lines; a line held by another process is refused
    sonar = HcSr04(lines, 23, 24)        # its callback and watchdog are served by the thread below

The echo line is requested with edge detection on both edges: the kernel timestamps each edge in its
interrupt handler (CLOCK_MONOTONIC, ns) and queues it; a reader thread sleeps in `wait_edge_events` (no
polling: the kernel wakes it), reads the events and hands each to the callback as pigpio would,
`func(gpio, level, tick)` with the tick the microseconds of the kernel timestamp, wrapped to 32 bits.
The width of an echo is thus the difference of two kernel timestamps, whatever the thread's latency.
pigpio's watchdog (`set_watchdog`) is the wait's timeout: no edge for the watchdog period reports
LEVEL_TIMEOUT, repeated every period without an edge, as pigpio does. The trigger is its own request
(output, low): `gpio_trigger` drives it high for `pulse_len` us (a spin on the monotonic clock; the
HC-SR04 needs 10 us) and low again; the module answers after the falling edge.

A line another process holds is a refusal (`GpioBusy`): the kernel answers the request with EBUSY and
the line's info names its consumer, which the message repeats.
"""
from __future__ import annotations

import errno
import threading
import time
from datetime import timedelta

from flightctl.hal import GPIO_INPUT, GPIO_OUTPUT, LEVEL_TIMEOUT

CONSUMER = "flightctl"
IDLE_WAIT_S = 0.1           # the reader thread's longest sleep without a watchdog (to notice close())


class GpioBusy(Exception):
    """A GPIO line is held by another consumer."""


class _Callback:
    def __init__(self, owner: "CdevGpio", pin: int, func):
        self.owner, self.pin, self.func = owner, pin, func

    def cancel(self) -> None:
        if self in self.owner._callbacks:
            self.owner._callbacks.remove(self)


class CdevGpio:
    """`hal.Gpio` for one trigger output and one echo input of a `gpiod.Chip`."""

    def __init__(self, chip, trigger: int, echo: int, consumer: str = CONSUMER, now_ns=time.monotonic_ns):
        self.chip, self.trigger_pin, self.echo_pin, self.consumer = chip, trigger, echo, consumer
        self._now_ns = now_ns
        self._out = self._in = None
        self._callbacks: list[_Callback] = []
        self._watchdog_ns = 0
        self._last_ns = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.edges = 0          # edge events read so far
        self.error: BaseException | None = None   # what ended the reader thread early

    def start(self) -> None:
        import gpiod
        from gpiod.line import Direction, Edge, Value

        self._out = self._request(gpiod, self.trigger_pin, gpiod.LineSettings(
            direction=Direction.OUTPUT, output_value=Value.INACTIVE))
        self._active, self._inactive = Value.ACTIVE, Value.INACTIVE
        try:
            self._in = self._request(gpiod, self.echo_pin, gpiod.LineSettings(
                direction=Direction.INPUT, edge_detection=Edge.BOTH))
        except BaseException:
            self._out.release()
            self._out = None
            raise
        self._rising = gpiod.EdgeEvent.Type.RISING_EDGE
        self._last_ns = self._now_ns()
        self._thread = threading.Thread(target=self._serve, daemon=True, name="gpio-cdev-edges")
        self._thread.start()

    def _request(self, gpiod, offset: int, settings):
        try:
            return self.chip.request_lines(config={offset: settings}, consumer=self.consumer)
        except OSError as e:
            if e.errno != errno.EBUSY:
                raise
            info = self.chip.get_line_info(offset)
            who = f"{info.consumer!r}" if info.consumer else "another process"
            raise GpioBusy(f"GPIO {offset} is held by {who}: the sonar cannot use it (the kernel answered "
                           "EBUSY); stop that process or wire the sonar to free pins") from None

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(2.0)
        for req in (self._out, self._in):
            if req is not None:
                try:
                    req.release()
                except Exception:
                    pass
        self._out = self._in = None

    # --- the pigpio calls of the HC-SR04 driver ------------------------------------------------
    def set_mode(self, gpio: int, mode: int) -> int:
        """The directions are fixed by the requests: only the ones they have are accepted."""
        if (gpio, mode) not in ((self.trigger_pin, GPIO_OUTPUT), (self.echo_pin, GPIO_INPUT)):
            raise ValueError(f"GPIO {gpio}: mode {mode} is not what this board requested for it")
        return 0

    def gpio_trigger(self, user_gpio: int, pulse_len: int = 10, level: int = 1) -> int:
        if user_gpio != self.trigger_pin:
            raise ValueError(f"GPIO {user_gpio} is not the trigger line (GPIO {self.trigger_pin})")
        on, off = (self._active, self._inactive) if level else (self._inactive, self._active)
        out, now = self._out, self._now_ns
        out.set_value(user_gpio, on)
        end = now() + pulse_len * 1000
        while now() < end:
            pass
        out.set_value(user_gpio, off)
        return 0

    def callback(self, user_gpio: int, edge: int, func) -> _Callback:
        if user_gpio != self.echo_pin:
            raise ValueError(f"GPIO {user_gpio} has no edge detection (only the echo, GPIO {self.echo_pin})")
        cb = _Callback(self, user_gpio, func)
        self._callbacks.append(cb)
        return cb

    def set_watchdog(self, user_gpio: int, wdog_timeout: int) -> int:
        self._watchdog_ns = int(wdog_timeout) * 1_000_000
        self._last_ns = self._now_ns()
        return 0

    def get_current_tick(self) -> int:
        return (self._now_ns() // 1000) & 0xFFFFFFFF

    # --- the reader thread ---------------------------------------------------------------------
    def _serve(self) -> None:
        try:
            while not self._stop.is_set():
                wd = self._watchdog_ns
                wait = IDLE_WAIT_S if not wd else max(0.0, (self._last_ns + wd - self._now_ns()) / 1e9)
                if self._in.wait_edge_events(timedelta(seconds=wait)):
                    for ev in self._in.read_edge_events():
                        self.edges += 1
                        self._last_ns = ev.timestamp_ns
                        self._fire(1 if ev.event_type == self._rising else 0, ev.timestamp_ns)
                elif wd and self._now_ns() >= self._last_ns + wd:
                    self._last_ns += wd
                    self._fire(LEVEL_TIMEOUT, self._last_ns)
        except BaseException as e:          # a released request, a bug: the sonar then times out, visibly
            if not self._stop.is_set():
                self.error = e

    def _fire(self, level: int, t_ns: int) -> None:
        tick = (t_ns // 1000) & 0xFFFFFFFF
        for cb in list(self._callbacks):
            cb.func(self.echo_pin, level, tick)
