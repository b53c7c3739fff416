"""The progress lines of the long work, on stderr: `Progress`, one counter line for the long commands
and scripts (`label[k/N] what  elapsed, time left`); `Stages`, one line per stage of a command whose
stages are few and uneven (`flightctl diagnose`).

On a terminal the line is rewritten in place; into a file or a pipe (CI, `2> log`) each finished
item is its own line, so that nothing is lost. Every line is flushed as it is written.

The time left is estimated from the work done since the first report, not from the first item
alone: the first item also pays the start-up (worker processes, the compiled plant, imports), and
with several workers items finish in bunches. Until the rate can be measured (a second report at
least a second after the first bunch) the line says "estimating". Work done inside a long item (the batched
simulator's vehicles) is reported as a fraction with `update`, at most every UPDATE_S.
No dependency (tqdm would do the same).
"""
from __future__ import annotations

import sys
import time
from typing import TextIO

UPDATE_S = 0.5          # a terminal's line is rewritten at most this often by `update`
UPDATE_FILE_S = 10.0    # ... and a file or a pipe gets a line at most this often by `update`
MEASURE_S = 1.0         # the shortest span a rate is measured over


class Progress:
    def __init__(self, total: float, label: str = "", out: TextIO | None = None, clock=time.perf_counter):
        self.total, self.label, self.done = total, label, 0.0
        self.finished = 0.0                                 # whole items, by `step`
        self.out = out if out is not None else sys.stderr
        self.clock = clock
        self.start = clock()
        self.tty = hasattr(self.out, "isatty") and self.out.isatty()
        self._first: tuple[float, float] | None = None     # (time, done) of the first report
        self._shown = -1e18                                 # when `update` last wrote

    def left(self, now: float) -> float | None:
        """Seconds left at the rate since the first report, or None while it cannot be measured."""
        if self._first is None:
            return None
        t1, d1 = self._first
        if now - t1 < MEASURE_S or self.done <= d1:
            return None
        return (now - t1) / (self.done - d1) * max(self.total - self.done, 0.0)

    def _line(self, what: str, now: float) -> str:
        left = self.left(now)
        done = f"{self.done:.0f}" if self.done == int(self.done) else f"{self.done:.1f}"
        return (f"{self.label}[{done}/{self.total:g}] {what}  {now - self.start:.0f} s elapsed, "
                + ("estimating the time left" if left is None else f"about {left:.0f} s left"))

    def _write(self, line: str, end: bool) -> None:
        if self.tty:
            self.out.write(f"\r\x1b[K{line}" + ("\n" if end else ""))
        else:
            self.out.write(line + "\n")
        self.out.flush()

    def _report(self, now: float) -> None:
        """The rate is measured from the last report of the first bunch (those within MEASURE_S of
        the first): items that finish together (several workers) are one report."""
        if self._first is None:
            self._bunch = now
        if now - self._bunch < MEASURE_S:
            self._first = (now, self.done)

    def step(self, what: str = "", n: float = 1) -> None:
        """`n` units of work finished (one item by default); `what` says which."""
        now = self.clock()
        self.finished += n
        self.done = self.finished
        line = self._line(what, now)
        self._report(now)
        self._shown = now
        self._write(line, self.done >= self.total)

    def update(self, fraction: float, what: str = "", items: float = 1) -> None:
        """The share (0..1) done of the `items` under way, from inside long work; written at most
        every UPDATE_S on a terminal, UPDATE_FILE_S elsewhere."""
        now = self.clock()
        self.done = self.finished + items * min(max(fraction, 0.0), 1.0)
        self._report(now)
        if now - self._shown >= (UPDATE_S if self.tty else UPDATE_FILE_S):
            self._shown = now
            self._write(self._line(what, now), False)


class Stages:
    """Progress lines on stderr, one per stage, each with the time elapsed (`prefix` before it). On a
    terminal they are live; otherwise (scripts, checks, `2> log`) they are held until the input is read
    and accepted (`release`), then live, so that bad input is the only line on stderr, as the CLI
    contract requires (docs/measured-data.md), and a long run still shows where it is."""

    def __init__(self, quiet: bool = False, prefix: str = "", out: TextIO | None = None):
        self.t0 = time.perf_counter()
        self.quiet, self.prefix = quiet, prefix
        self.out = out                                      # None: sys.stderr as it is at each line
        self.held: list[str] | None = None if (out or sys.stderr).isatty() else []

    def _say(self, line: str) -> None:
        print(*([self.prefix] if self.prefix else []), line, file=self.out or sys.stderr, flush=True)

    def __call__(self, *args) -> None:
        if self.quiet:
            return
        line = f"[{time.perf_counter() - self.t0:6.1f} s] " + " ".join(map(str, args))
        if self.held is None:
            self._say(line)
        else:
            self.held.append(line)

    def release(self) -> None:
        for line in self.held or ():
            self._say(line)
        self.held = None
