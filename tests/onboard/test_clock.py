"""The deadline-keeping wall clock (sleep to ~200 us before the deadline, then spin; overruns counted)
and the simulator paced by it. No SCHED_FIFO here: plain threads, short runs."""
from __future__ import annotations

import random

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


class BusyTime(FakeTime):
    """FakeTime on a busy machine: a sleep overshoots by a random (seeded) 0 to 3 ms, now and then by
    up to 20 ms (the process not scheduled), and `work` is a loop body of random length."""

    def __init__(self, seed: int):
        super().__init__()
        self.rng = random.Random(seed)

    def sleep(self, s: float) -> None:
        over = self.rng.uniform(0.0, 3e-3) if self.rng.random() < 0.3 else 0.0
        super().sleep(s + over + (self.rng.uniform(0.0, 20e-3) if self.rng.random() < 0.02 else 0.0))

    def work(self) -> None:
        self.t += self.rng.uniform(0.2e-3, 1.5e-3) if self.rng.random() < 0.95 else self.rng.uniform(2e-3, 12e-3)


@pytest.mark.parametrize("seed", range(5))
def test_deadlines_at_450hz_on_a_busy_machine(seed):
    """The schedule's logic under a machine that oversleeps and stalls (a fake clock: what the wall
    clock of a shared machine would give is luck, not the code): every tick is on the grid and never
    early, a late body is an overrun served at once, whole periods missed are skipped, never caught up."""
    ft = BusyTime(seed)
    period = 1 / 450
    clock = WallClock(period, now=ft.now, sleep=ft.sleep)
    clock.wait_next()
    t1 = clock._t1
    ticks, overruns, skipped = [], 0, 0
    for _ in range(450):
        ft.work()
        start = ft.t - clock._t0
        expected = t1 - clock._t0 + clock._k * period       # the next deadline, before the body's lateness
        t = clock.wait_next()
        assert ft.t - clock._t0 >= t - 1e-9                 # never returns before its deadline
        assert abs((t - (t1 - clock._t0)) / period - round((t - (t1 - clock._t0)) / period)) < 1e-6   # on the grid
        if start > expected:                                # the body ran past the deadline
            overruns += 1
            skipped += int((start - expected) / period)
        ticks.append(t)
    assert clock.overruns == overruns > 0 and clock.skipped == skipped
    periods = [b - a for a, b in zip(ticks, ticks[1:])]
    assert min(periods) == pytest.approx(period)            # no catch-up burst: never closer than a period
    assert clock.ticks == 451


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
    ft = FakeTime()
    clock = PacedClock(inner, WallClock(inner.period, now=ft.now, sleep=ft.sleep))
    t0 = ft.t
    for _ in range(50):
        clock.wait_next()
    assert inner.t == pytest.approx(0.1)
    assert ft.t - t0 == pytest.approx(0.1, abs=inner.period)    # paced: 50 periods of the (fake) wall clock
    assert clock.now() == inner.t and clock.overruns == 0
