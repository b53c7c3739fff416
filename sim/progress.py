"""One counter line on stderr for the long scripts: `[k/N] what  elapsed, time left`.

On a terminal the line is rewritten in place; into a file or a pipe (CI, `2> log`) each update is
its own line, so that nothing is lost. No dependency (tqdm would do the same).
"""
from __future__ import annotations

import sys
import time
from typing import TextIO


class Progress:
    def __init__(self, total: int, label: str = "", out: TextIO | None = None):
        self.total, self.label, self.done = total, label, 0
        self.out = out if out is not None else sys.stderr
        self.start = time.perf_counter()
        self.tty = hasattr(self.out, "isatty") and self.out.isatty()

    def step(self, what: str = "") -> None:
        """One unit of work finished; `what` says which."""
        self.done += 1
        elapsed = time.perf_counter() - self.start
        left = elapsed / self.done * (self.total - self.done)
        line = (f"{self.label}[{self.done}/{self.total}] {what}  {elapsed:.0f} s elapsed, "
                f"about {left:.0f} s left")
        if self.tty:
            end = "\n" if self.done >= self.total else ""
            self.out.write(f"\r\x1b[K{line}{end}")
        else:
            self.out.write(line + "\n")
        self.out.flush()
