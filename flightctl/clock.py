"""Loop clocks: the deadline-keeping wall clock of the quadcopter, and the simulator paced by it.

`WallClock` keeps a fixed grid of deadlines `t1 + k * period` (t1 the first deadline), each computed
from the integer k, never summed, so that the grid does not drift by rounding. It sleeps until about
`spin_s` (200 us) before the deadline and then spins on the monotonic clock, which on Linux hits the deadline
with a p99 error near 0.1 ms where a plain `time.sleep` misses it by ~0.8 ms. A loop body that runs
past its deadline is an overrun: it is counted, the next deadline is served at once if it is still
within one period, and whole missed periods are skipped (never a burst of catch-up iterations).

`PacedClock` wraps a lock-step clock (the simulator's `SimClock`, whose `wait_next` advances the
world by one period) so that the wall clock paces it: the world is advanced, then the wall deadline
is awaited, so the world at time t is ready at wall time t. `flightctl run --board sim` flies on it.

Real-time settings (SCHED_FIFO, a pinned CPU) come from the systemd unit, never from the tests;
`freeze_gc()` is the one in-process measure, and it is harmless anywhere.
"""
from __future__ import annotations

import gc
import time
from typing import Callable

from flightctl.hal import Clock

SPIN_S = 200e-6   # sleep to this much before the deadline, then spin


class WallClock:
    """Deadlines on `time.perf_counter` (monotonic). `now()` is seconds since the clock was made."""

    def __init__(self, period: float, spin_s: float = SPIN_S, *,
                 now: Callable[[], float] = time.perf_counter, sleep: Callable[[float], None] = time.sleep):
        if period <= 0.0:
            raise ValueError("period must be positive")
        self.period = period
        self.spin_s = spin_s
        self._now, self._sleep = now, sleep
        self._t0 = now()
        self._t1: float | None = None   # the first deadline
        self._k = 0                     # index of the next deadline on the grid t1 + k * period
        self.ticks = 0                  # deadlines served (skipped ones not counted)
        self.overruns = 0           # deadlines the loop body ran past
        self.skipped = 0            # whole periods dropped after long overruns
        self.max_late_s = 0.0       # worst lateness at the return of wait_next (spin error or overrun)
        self.late_s = 0.0           # how late the loop reached the last deadline (0: in time; scripts/loop_lateness.py)

    def now(self) -> float:
        return self._now() - self._t0

    def wait_next(self) -> float:
        """Block until the next deadline; return the deadline (s since the clock was made)."""
        now, period = self._now, self.period
        t = now()
        if self._t1 is None:
            self._t1 = t + period
        deadline = self._t1 + self._k * period
        self.late_s = t - deadline if t > deadline else 0.0
        if t > deadline:
            self.overruns += 1
            behind = missed_periods(t - deadline, period)
            if behind:
                self.skipped += behind
                self._k += behind
                deadline = self._t1 + self._k * period
        else:
            remaining = deadline - t
            if remaining > self.spin_s:
                self._sleep(remaining - self.spin_s)
            while now() < deadline:
                pass
        late = now() - deadline
        if late > self.max_late_s:
            self.max_late_s = late
        self._k += 1
        self.ticks += 1
        return deadline - self._t0


def missed_periods(late: float, period: float) -> int:
    """The whole periods a loop that reaches its deadline `late` s after it has missed: `WallClock`
    skips them (and serves the last one passed at once), never catching up in a burst; the simulated
    board's late clock (sim/world/lateness.py) follows the same rule."""
    return int(late / period)


class PacedClock:
    """A lock-step clock (it advances a world in `wait_next`) paced by a `WallClock` in real time.
    Returns the lock-step clock's time, so logs carry simulated time; overruns are the wall clock's."""

    def __init__(self, inner: Clock, wall: WallClock | None = None):
        self.inner = inner
        self.period = inner.period
        self.wall = wall if wall is not None else WallClock(inner.period)

    @property
    def overruns(self) -> int:
        return self.wall.overruns

    def now(self) -> float:
        return self.inner.now()

    def wait_next(self) -> float:
        t = self.inner.wait_next()
        self.wall.wait_next()
        return t


def freeze_gc() -> None:
    """Move everything allocated so far out of the collector's sight (fewer, shorter pauses)."""
    gc.collect()
    gc.freeze()
