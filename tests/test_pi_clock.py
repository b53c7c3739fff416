"""The deadline-keeping wall clock (sleep to ~200 us before the deadline, then spin; overruns counted)
and the simulator paced by it. No SCHED_FIFO here: plain threads, short runs."""
from __future__ import annotations

import statistics
import time

import pytest

from flightctl.clock import SPIN_S, PacedClock, WallClock
from flightctl.hal import Clock


class FakeTime:
    """A monotonic clock that moves only when slept on or spun on (each read costs 1 us)."""

    def __init__(self):
        self.t = 100.0
        self.sleeps: list[float] = []

    def now(self) -> float:
        self.t += 1e-6
        return self.t

    def sleep(self, s: float) -> None:
        self.sleeps.append(s)
        self.t += s


def test_sleeps_to_200us_before_the_deadline_then_spins():
    ft = FakeTime()
    clock = WallClock(0.01, now=ft.now, sleep=ft.sleep)
    assert isinstance(clock, Clock)
    t1 = clock.wait_next()
    t2 = clock.wait_next()
    assert t2 - t1 == pytest.approx(0.01)
    assert all(s == pytest.approx(0.01 - SPIN_S, abs=1e-5) for s in ft.sleeps)
    assert clock.max_late_s < 5e-6 and clock.overruns == 0


def test_overruns_are_counted_and_whole_missed_periods_skipped():
    ft = FakeTime()
    clock = WallClock(0.01, now=ft.now, sleep=ft.sleep)
    t1 = clock.wait_next()
    ft.t += 0.013                 # the body ran 13 ms: the next deadline is 3 ms past
    t2 = clock.wait_next()
    assert clock.overruns == 1 and clock.skipped == 0
    assert t2 - t1 == pytest.approx(0.01)     # served at once, on the grid
    ft.t += 0.035                 # 35 ms: the deadlines at +10 and +20 ms are gone, +30 is just past
    t3 = clock.wait_next()
    assert clock.overruns == 2 and clock.skipped == 2
    assert (t3 - t2) == pytest.approx(0.03)   # the latest deadline served, on the grid: no catch-up burst
    t4 = clock.wait_next()
    assert t4 - t3 == pytest.approx(0.01) and clock.overruns == 2


def test_real_deadlines_at_450hz():
    clock = WallClock(1 / 450)
    clock.wait_next()
    lates, ticks = [], []
    for _ in range(225):          # half a second
        t = clock.wait_next()
        lates.append(time.perf_counter() - (clock._t0 + t))
        ticks.append(t)
    periods = [b - a for a, b in zip(ticks, ticks[1:])]
    assert all(p == pytest.approx(1 / 450) for p in periods) or clock.overruns > 0
    assert statistics.median(lates) < 0.5e-3   # shared CI machines: a loose bound on the typical error


def test_paced_clock_advances_the_lock_step_clock_once_per_wall_tick():
    class LockStep:
        period = 0.002

        def __init__(self):
            self.t = 0.0

        def now(self):
            return self.t

        def wait_next(self):
            self.t += self.period
            return self.t

    inner = LockStep()
    clock = PacedClock(inner)
    t0 = time.perf_counter()
    for _ in range(50):
        clock.wait_next()
    elapsed = time.perf_counter() - t0
    assert inner.t == pytest.approx(0.1)
    assert elapsed == pytest.approx(0.1, abs=0.03)    # real time
    assert clock.now() == inner.t
