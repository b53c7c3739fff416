"""The counter line of the long scripts: one line per unit of work into a file or pipe, rewritten in
place on a terminal, with the count, the total and the time left."""
from __future__ import annotations

import io
import re

from flightctl.sim.progress import Progress


class Tty(io.StringIO):
    def isatty(self):
        return True


def test_a_pipe_gets_one_line_per_step():
    out = io.StringIO()
    p = Progress(3, out=out)
    for what in ("a", "b", "c"):
        p.step(what)
    lines = out.getvalue().splitlines()
    assert [re.match(r"\[(\d)/3\] (\w)  \d+ s elapsed, about \d+ s left$", l).groups() for l in lines] == \
        [("1", "a"), ("2", "b"), ("3", "c")]
    assert lines[-1].endswith("about 0 s left")


def test_a_terminal_gets_one_line_rewritten():
    out = Tty()
    p = Progress(2, label="sweep ", out=out)
    p.step("x")
    assert "\n" not in out.getvalue() and out.getvalue().startswith("\r")
    p.step("y")
    assert out.getvalue().count("\n") == 1 and "sweep [2/2] y" in out.getvalue()
