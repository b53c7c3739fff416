"""A fake GPIO chip behind libgpiod 2.x's Python API (`gpiod.Chip` and `gpiod.LineRequest`), for the Pi 5's
sonar lines (flightctl/drivers/gpio_cdev.py). No kernel GPIO simulator is usable here (no gpio-sim or
gpio-mockup module, no configfs, no /dev/gpiochip*), so the fake stands where the kernel's character
device does, at the API the driver calls; every value it hands back is the real binding's own type
(`gpiod.EdgeEvent`, `gpiod.LineInfo`, `gpiod.ChipInfo`, the `gpiod.line` enums), and it takes the real
`gpiod.LineSettings`. What it has not got raises AttributeError: nothing is answered by default.

The kernel side (`FakeGpioDevice`, one chip: the RP1's 54 lines, label "pinctrl-rp1"):
- a line is held by one request at a time: a second request, or one for a line another process holds
  (`hold`), fails with OSError EBUSY, and the line's info names the consumer, as the kernel's does;
- an input line with edge detection gets an event for each level change it sees, timestamped with the
  time of the change (CLOCK_MONOTONIC ns, as the kernel stamps it in its interrupt handler), queued in
  the request's buffer (`event_buffer_size`, default 16 per line; when full, the oldest is dropped, as
  gpiolib-cdev does); `wait_edge_events` sleeps until an event is queued or the timeout passes,
  `read_edge_events` blocks until one is;
- an HC-SR04 on (trigger, echo) (`attach_sonar`): when the trigger falls after at least 10 us high, the
  echo rises 450 us later and stays high distance * 5831 us; mode "none" gives no echo, "stuck" an echo
  that never falls, "far" the module's 38 ms out-of-range pulse. A trigger pulse under 10 us is ignored,
  as the module ignores it.
Edges scheduled in the future are applied by a thread at their time (a few tens of us late, with their
exact timestamp): what a reader sees is what a late-scheduled reader sees on a real kernel.

Not modelled: debounce, active-low, bias, the realtime and HTE event clocks, line names other than
"GPIOn", info events, and two requests' relative timing beyond one lock.
"""
from __future__ import annotations

import errno
import heapq
import os
import threading
import time
from dataclasses import dataclass, field
from datetime import timedelta

import gpiod
from gpiod.line import Bias, Clock, Direction, Drive, Edge, Value

from helpers.fakes import HCSR04_ECHO_DELAY_US, HCSR04_US_PER_M

ECHO_DELAY_NS = int(HCSR04_ECHO_DELAY_US * 1000)
NS_PER_M = int(HCSR04_US_PER_M * 1000)
FAR_NS = 38_000_000
MIN_TRIGGER_NS = 10_000
_RISING, _FALLING = gpiod.EdgeEvent.Type.RISING_EDGE.value, gpiod.EdgeEvent.Type.FALLING_EDGE.value


@dataclass
class Sonar:
    trigger: int
    echo: int
    distance_m: float = 1.0
    mode: str = "echo"      # "echo", "none", "stuck", "far"
    triggers: int = 0       # trigger pulses the module answered
    ignored: int = 0        # trigger pulses too short to answer
    widths_ns: list = field(default_factory=list)   # every trigger pulse's width, as the module saw it


@dataclass
class _Line:
    level: int = 0
    consumer: str | None = None     # who holds it
    request: "FakeLineRequest | None" = None
    settings: gpiod.LineSettings = field(default_factory=gpiod.LineSettings)
    rose_ns: int = 0                # when an output last went high


class FakeGpioDevice:
    """The chip as the kernel has it; `chip()` is what `gpiod.Chip(path)` gives a process."""

    def __init__(self, name: str = "gpiochip0", label: str = "pinctrl-rp1", num_lines: int = 54,
                 now_ns=time.monotonic_ns):
        self.name, self.label, self.num_lines, self.now_ns = name, label, num_lines, now_ns
        self.lines = [_Line() for _ in range(num_lines)]
        self.lock = threading.Condition()
        self.sonar: Sonar | None = None
        self._due: list[tuple[int, int, int, int]] = []     # (t ns, seq, offset, level)
        self._seq = 0
        self.global_seqno = 0
        self._stop = False
        self._thread = threading.Thread(target=self._engine, daemon=True, name="fake-gpiochip")
        self._thread.start()

    def chip(self, path: str = "/dev/gpiochip0") -> "FakeChip":
        return FakeChip(self, path)

    def close(self) -> None:
        with self.lock:
            self._stop = True
            self.lock.notify_all()
        self._thread.join(2.0)

    # --- what other processes and the world do ----------------------------------------------------
    def hold(self, offset: int, consumer: str) -> None:
        """Another process requests the line (and keeps it)."""
        with self.lock:
            line = self.lines[offset]
            if line.consumer is not None:
                raise OSError(errno.EBUSY, os.strerror(errno.EBUSY))
            line.consumer = consumer

    def attach_sonar(self, trigger: int, echo: int, distance_m: float = 1.0, mode: str = "echo") -> Sonar:
        self.sonar = Sonar(trigger, echo, distance_m, mode)
        return self.sonar

    def drive(self, offset: int, level: int, at_ns: int | None = None) -> None:
        """An external signal on an input line: its level becomes `level` at `at_ns` (default now)."""
        with self.lock:
            self._schedule(self.now_ns() if at_ns is None else at_ns, offset, level)

    # --- the kernel's side -------------------------------------------------------------------------
    def _schedule(self, t_ns: int, offset: int, level: int) -> None:
        self._seq += 1
        heapq.heappush(self._due, (t_ns, self._seq, offset, level))
        self.lock.notify_all()

    def _engine(self) -> None:
        with self.lock:
            while not self._stop:
                now = self.now_ns()
                applied = False
                while self._due and self._due[0][0] <= now:
                    t, _, offset, level = heapq.heappop(self._due)
                    self._change(offset, level, t)
                    applied = True
                if applied:
                    self.lock.notify_all()
                wait = (self._due[0][0] - now) / 1e9 if self._due else 0.5
                self.lock.wait(max(wait, 0.0))

    def _change(self, offset: int, level: int, t_ns: int) -> None:
        line = self.lines[offset]
        if line.level == level:
            return
        line.level = level
        req, edge = line.request, line.settings.edge_detection
        if req is None or line.settings.direction != Direction.INPUT:
            return
        if edge == Edge.BOTH or (edge == Edge.RISING and level) or (edge == Edge.FALLING and not level):
            self.global_seqno += 1
            req._queue(gpiod.EdgeEvent(_RISING if level else _FALLING, t_ns, offset, self.global_seqno,
                                       req._next_line_seqno(offset)))

    def _output(self, offset: int, level: int) -> None:
        """A requested output line driven to `level` now (the sonar's trigger)."""
        now = self.now_ns()
        line = self.lines[offset]
        if level and not line.level:
            line.rose_ns = now
        falling = line.level and not level
        line.level = level
        s = self.sonar
        if s is None or offset != s.trigger or not falling:
            return
        s.widths_ns.append(now - line.rose_ns)
        if now - line.rose_ns < MIN_TRIGGER_NS:
            s.ignored += 1
            return
        s.triggers += 1
        rise = now + ECHO_DELAY_NS
        if s.mode == "echo":
            self._schedule(rise, s.echo, 1)
            self._schedule(rise + int(s.distance_m * NS_PER_M), s.echo, 0)
        elif s.mode == "far":
            self._schedule(rise, s.echo, 1)
            self._schedule(rise + FAR_NS, s.echo, 0)
        elif s.mode == "stuck":
            self._schedule(rise, s.echo, 1)


def _seconds(timeout) -> float | None:
    if timeout is None:
        return None
    return timeout.total_seconds() if isinstance(timeout, timedelta) else float(timeout)


class FakeChip:
    """`gpiod.Chip`: the calls the driver makes on it."""

    def __init__(self, device: FakeGpioDevice, path: str):
        self.device, self._path, self._open = device, path, True

    def __enter__(self) -> "FakeChip":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _check_closed(self) -> None:
        if not self._open:
            raise gpiod.ChipClosedError()

    def close(self) -> None:
        self._open = False

    @property
    def path(self) -> str:
        return self._path

    def get_info(self) -> gpiod.ChipInfo:
        self._check_closed()
        d = self.device
        return gpiod.ChipInfo(d.name, d.label, d.num_lines)

    def get_line_info(self, line: int) -> gpiod.LineInfo:
        self._check_closed()
        d = self.device
        with d.lock:
            ln = d.lines[line]
            s = ln.settings
            return gpiod.LineInfo(line, f"GPIO{line}", ln.consumer is not None, ln.consumer or "",
                                  (s.direction if s.direction != Direction.AS_IS else Direction.INPUT).value,
                                  False, Bias.UNKNOWN.value, Drive.PUSH_PULL.value, s.edge_detection.value,
                                  Clock.MONOTONIC.value, False, 0)

    def request_lines(self, config: dict, consumer: str | None = None, event_buffer_size: int | None = None,
                      output_values: dict | None = None) -> "FakeLineRequest":
        self._check_closed()
        d = self.device
        wanted: dict[int, gpiod.LineSettings] = {}
        for key, settings in config.items():
            for offset in (key if isinstance(key, (tuple, list, set, frozenset)) else (key,)):
                if not isinstance(offset, int):
                    raise NotImplementedError(f"the fake chip takes line offsets, not {offset!r}")
                if not 0 <= offset < d.num_lines:
                    raise ValueError(f"line offset {offset} out of range")
                if settings is not None and not isinstance(settings, gpiod.LineSettings):
                    raise TypeError(f"settings must be gpiod.LineSettings, got {type(settings).__name__}")
                if offset in wanted:
                    raise ValueError(f"line must be configured exactly once - offset {offset} repeats")
                wanted[offset] = settings or gpiod.LineSettings()
        with d.lock:
            if any(d.lines[o].consumer is not None for o in wanted):
                raise OSError(errno.EBUSY, os.strerror(errno.EBUSY))
            req = FakeLineRequest(d, self._path, sorted(wanted), event_buffer_size or 16 * len(wanted))
            for o, s in wanted.items():
                ln = d.lines[o]
                ln.consumer, ln.request, ln.settings = consumer or "?", req, s
                if s.direction == Direction.OUTPUT:
                    value = (output_values or {}).get(o, s.output_value)
                    d._output(o, 1 if value == Value.ACTIVE else 0)
            return req


class FakeLineRequest:
    """`gpiod.LineRequest`: the calls the driver makes on it."""

    def __init__(self, device: FakeGpioDevice, chip_name: str, offsets: list[int], capacity: int):
        self.device, self.chip_name, self.offsets, self.capacity = device, chip_name, offsets, capacity
        self._events: list[gpiod.EdgeEvent] = []
        self._line_seqno = {o: 0 for o in offsets}
        self._released = False
        self.dropped = 0        # events lost to a full buffer

    def __bool__(self) -> bool:
        return not self._released

    def __enter__(self) -> "FakeLineRequest":
        return self

    def __exit__(self, *exc) -> None:
        self.release()

    def _check_released(self) -> None:
        if self._released:
            raise gpiod.RequestReleasedError()

    def _next_line_seqno(self, offset: int) -> int:
        self._line_seqno[offset] += 1
        return self._line_seqno[offset]

    def _queue(self, event) -> None:
        if len(self._events) >= self.capacity:
            self._events.pop(0)
            self.dropped += 1
        self._events.append(event)

    def release(self) -> None:
        d = self.device
        with d.lock:
            if self._released:
                return
            self._released = True
            for o in self.offsets:
                ln = d.lines[o]
                if ln.request is self:
                    ln.consumer, ln.request, ln.settings = None, None, gpiod.LineSettings()
            d.lock.notify_all()

    def get_value(self, line: int) -> Value:
        return self.get_values([line])[0]

    def get_values(self, lines=None) -> list[Value]:
        self._check_released()
        with self.device.lock:
            return [Value.ACTIVE if self.device.lines[o].level else Value.INACTIVE for o in (lines or self.offsets)]

    def set_value(self, line: int, value: Value) -> None:
        self.set_values({line: value})

    def set_values(self, values: dict) -> None:
        self._check_released()
        d = self.device
        with d.lock:
            for o, v in values.items():
                if o not in self.offsets:
                    raise ValueError(f"line {o} is not in this request")
                if d.lines[o].settings.direction != Direction.OUTPUT:
                    raise OSError(errno.EPERM, os.strerror(errno.EPERM))
                d._output(o, 1 if v == Value.ACTIVE else 0)

    def wait_edge_events(self, timeout=None) -> bool:
        self._check_released()
        d = self.device
        with d.lock:
            return bool(d.lock.wait_for(lambda: self._events or self._released, _seconds(timeout))) and not self._released

    def read_edge_events(self, max_events: int | None = None) -> list:
        self._check_released()
        d = self.device
        with d.lock:
            d.lock.wait_for(lambda: self._events or self._released)
            self._check_released()
            n = max_events or 64
            out, self._events = self._events[:n], self._events[n:]
            return out
