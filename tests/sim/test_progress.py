"""The counter line of the long commands: one line per unit of work into a file or pipe, rewritten in
place on a terminal, with the count, the total and an honest time left (from the work done since
the first report, never from the first item, which pays the start-up)."""
from __future__ import annotations

import io
import re

from flightctl.sim.progress import UPDATE_FILE_S, Progress


class Tty(io.StringIO):
    def isatty(self):
        return True


class Clock:
    def __init__(self):
        self.t = 0.0

    def __call__(self):
        return self.t


def test_a_pipe_gets_one_line_per_step():
    out, clock = io.StringIO(), Clock()
    p = Progress(3, out=out, clock=clock)
    for what in ("a", "b", "c"):
        clock.t += 2.0
        p.step(what)
    lines = out.getvalue().splitlines()
    assert [re.match(r"\[(\d)/3\] (\w)  \d+ s elapsed, ", line).groups() for line in lines] == \
        [("1", "a"), ("2", "b"), ("3", "c")]
    assert lines[0].endswith("estimating the time left")       # one item: no rate yet
    assert lines[1].endswith("about 2 s left") and lines[-1].endswith("about 0 s left")


def test_the_estimate_leaves_out_the_start_up_of_the_first_item():
    """The first item takes 10 s (workers starting, compiling), each later one 1 s: after the third,
    7 items are left at 1 s each, not at the 4 s average of the three."""
    out, clock = io.StringIO(), Clock()
    p = Progress(10, out=out, clock=clock)
    for dt in (10.0, 1.0, 1.0):
        clock.t += dt
        p.step()
    assert out.getvalue().splitlines()[-1].endswith("12 s elapsed, about 7 s left")


def test_items_finishing_together_do_not_make_a_rate():
    """Two workers finish their items within a few ms of each other: no estimate from that instant."""
    out, clock = io.StringIO(), Clock()
    p = Progress(8, out=out, clock=clock)
    clock.t = 5.0
    p.step()
    clock.t = 5.01
    p.step()
    assert out.getvalue().splitlines()[-1].endswith("estimating the time left")
    clock.t = 8.0
    p.step()
    p.step()
    assert out.getvalue().splitlines()[-1].endswith("about 6 s left")   # 2 items in 3 s after the first two


def test_a_terminal_gets_one_line_rewritten():
    out = Tty()
    p = Progress(2, label="sweep ", out=out)
    p.step("x")
    assert "\n" not in out.getvalue() and out.getvalue().startswith("\r")
    p.step("y")
    assert out.getvalue().count("\n") == 1 and "sweep [2/2] y" in out.getvalue()


def test_work_inside_an_item_is_reported_and_rate_limited_into_a_file():
    """The batched simulator reports fractions of its items: a file gets at most one line every
    UPDATE_FILE_S of them, each with the count so far and an estimate from the work done."""
    out, clock = io.StringIO(), Clock()
    p = Progress(2, label="batch ", out=out, clock=clock)
    for k in range(1, 41):                       # 40 s, a report every second, 0.025 of the work each
        clock.t = float(k)
        p.update(k * 0.025, "table4")
    lines = out.getvalue().splitlines()
    assert len(lines) == 40 // UPDATE_FILE_S      # at 1, 11, 21 and 31 s
    assert lines[-1].startswith("batch [0.8/2] table4  31 s elapsed")
    left = float(re.search(r"about (\d+) s left", lines[-1]).group(1))
    assert left == (2 - 31 * 0.025) / 0.025      # 0.025 a second


def test_stages_are_held_off_a_terminal_until_released_then_live():
    """`Stages` (flightctl diagnose's lines): into a file nothing is written before `release`, then
    the held lines in order with the prefix, then each line as it comes; `quiet` writes nothing."""
    from flightctl.sim.progress import Stages
    out = io.StringIO()
    s = Stages(prefix="diagnose:", out=out)
    s("reading", "a.bin")
    s("fitting")
    assert out.getvalue() == ""
    s.release()
    s("done")
    lines = out.getvalue().splitlines()
    assert [line.split("] ", 1)[1] for line in lines] == ["reading a.bin", "fitting", "done"]
    assert all(line.startswith("diagnose: [") and " s] " in line for line in lines)
    quiet = io.StringIO()
    q = Stages(quiet=True, out=quiet)
    q("x")
    q.release()
    assert quiet.getvalue() == ""
