"""The plan queue (flightctl/service/queue.py, issue 10 defects 2 and 5): every plan is validated before it
is claimed, a bad or stale one is moved aside with a one-line reason and the service keeps running,
nothing can hang it, and what cannot be done is said in the journal."""
from __future__ import annotations

import logging
import os
import time
from pathlib import Path

import pytest

from flightctl.service.queue import PlanQueue

GOOD = 'name = "hop"\nduration = 1.5\n[[move]]\nt = 0.0\nchannel = "alt"\nvalue = 0.3\nramp = 0.5\n'
BAD = {
    "latin1.toml": b'name = "caf\xe9"\nduration = 1\n',
    "utf16.toml": GOOD.encode("utf-16"),
    "deep.toml": b"a = " + b"[" * 20000 + b"]" * 20000 + b"\n",
    "move.toml": b"duration = 1\nmove = 5\n",
    "slash.toml": b'name = "a/b"\nduration = 1\n',
    "nul.toml": b'name = "a\\u0000b"\nduration = 1\n',
    "long.toml": ('name = "%s"\nduration = 1\n' % ("x" * 300)).encode(),
    "spaces.toml": b'name = "my plan"\nduration = 1\n',
}


class Clock:
    def __init__(self, t: float):
        self.t = t

    def __call__(self) -> float:
        return self.t


def put(queue: Path, name: str, data: bytes | str, mtime: float) -> Path:
    p = queue / name
    p.write_bytes(data.encode() if isinstance(data, str) else data)
    os.utime(p, (mtime, mtime))
    return p


@pytest.fixture
def q(tmp_path):
    clock = Clock(time.time())
    queue = PlanQueue(tmp_path / "plans", tmp_path / "logs", started=clock.t - 10, clock=clock, max_age_s=60)
    queue.open()
    return queue, clock


def test_bad_plans_are_moved_aside_with_a_one_line_reason_and_a_good_one_still_flies(q, caplog):
    queue, clock = q
    for name, data in BAD.items():
        put(queue.queue, name, data, clock.t - 2)
    os.mkfifo(queue.queue / "pipe.toml")               # a named pipe: never opened, so never a hang
    os.utime(queue.queue / "pipe.toml", (clock.t - 2, clock.t - 2))
    put(queue.queue, "good.toml", GOOD, clock.t - 1)
    with caplog.at_level(logging.INFO, "flightctl.run"):
        t0 = time.monotonic()
        plan, claimed = queue.take()
        assert time.monotonic() - t0 < 5
    assert plan.name == "hop" and claimed.parent == queue.log_dir and claimed.read_text() == GOOD
    assert sorted(n for n in os.listdir(queue.queue) if n != "refused") == []
    aside = queue.queue / "refused"
    reasons = {p.name: p.read_text() for p in aside.glob("*.reason")}
    assert len(reasons) == len(BAD) + 1
    for name in list(BAD) + ["pipe.toml"]:
        (text,) = [r for f, r in reasons.items() if f.endswith(f"-{name}.reason")]
        assert text.count("\n") == 1 and name in text, text          # one line naming the file
    assert "regular file" in next(r for f, r in reasons.items() if "pipe" in f)
    assert "300 characters" in next(r for f, r in reasons.items() if "long" in f)
    refused = [r for r in caplog.records if "plan refused" in r.getMessage()]
    assert len(refused) == len(BAD) + 1 and all("\n" not in r.getMessage() for r in refused)
    assert not any(r.exc_info for r in caplog.records)               # no traceback anywhere
    assert queue.take() is None


def test_a_plan_queued_before_the_service_started_never_flies(tmp_path, caplog):
    now = time.time()
    queue = PlanQueue(tmp_path / "plans", tmp_path / "logs", started=now - 5, clock=Clock(now))
    queue.open()
    put(queue.queue, "yesterday.toml", GOOD, now - 86400)     # queued a day earlier, the service down
    with caplog.at_level(logging.INFO, "flightctl.run"):
        assert queue.take() is None
    assert not queue.log_dir.exists() or not list(queue.log_dir.iterdir())
    (reason,) = (queue.queue / "refused").glob("*.reason")
    assert "before this service started" in reason.read_text()
    assert any("stale" in r.getMessage() for r in caplog.records if r.levelno >= logging.ERROR)


def test_a_plan_older_than_the_maximum_age_is_refused(q):
    queue, clock = q
    queue.started = clock.t - 3600
    put(queue.queue, "late.toml", GOOD, clock.t - 61)
    assert queue.take() is None
    (reason,) = (queue.queue / "refused").glob("*.reason")
    assert "61 s ago" in reason.read_text() and "60 s" in reason.read_text()


def test_a_plan_stuck_behind_an_unwritable_log_directory_says_so_and_never_flies_late(tmp_path, caplog):
    clock = Clock(time.time())
    blocker = tmp_path / "ro"
    blocker.write_text("")               # the log directory cannot be created (root ignores modes)
    queue = PlanQueue(tmp_path / "plans", blocker / "logs", started=clock.t - 1, clock=clock, max_age_s=60)
    queue.open()
    put(queue.queue, "hop.toml", GOOD, clock.t - 1)
    with caplog.at_level(logging.INFO, "flightctl.run"):
        for _ in range(5):                               # polled twice a second: said once
            assert queue.take() is None
            clock.t += 0.5
    waiting = [r.getMessage() for r in caplog.records if "waits" in r.getMessage()]
    assert len(waiting) == 1 and "log directory" in waiting[0] and "not writable" in waiting[0]
    assert (queue.queue / "hop.toml").exists()          # still queued, not claimed
    blocker.unlink()                                     # the directory comes back ...
    clock.t += 60                                        # ... after the plan went stale
    assert queue.take() is None
    assert not list(queue.log_dir.glob("plan-*"))
    (reason,) = (queue.queue / "refused").glob("*.reason")
    assert "stale" in reason.read_text()


def test_a_queue_where_plans_cannot_be_moved_aside_says_so_once(q, caplog):
    queue, clock = q
    (queue.queue / "refused").write_text("")             # moving aside fails
    put(queue.queue, "bad.toml", b"duration = 1\nmove = 5\n", clock.t - 1)
    with caplog.at_level(logging.INFO, "flightctl.run"):
        assert queue.take() is None
        assert queue.take() is None
    said = [r.getMessage() for r in caplog.records if "cannot be moved aside" in r.getMessage()]
    assert len(said) == 1 and "bad.toml" in said[0]


def test_a_queue_that_cannot_exist_is_said_in_the_journal(tmp_path, caplog):
    (tmp_path / "file").write_text("")
    queue = PlanQueue(tmp_path / "file" / "plans", tmp_path / "logs")
    with caplog.at_level(logging.INFO, "flightctl.run"):
        queue.open()
        assert queue.take() is None
    assert any("plan queue" in r.getMessage() and r.levelno == logging.ERROR for r in caplog.records)


def test_a_plan_still_being_written_is_left_alone(q):
    queue, clock = q
    put(queue.queue, "hop.toml", GOOD, clock.t - 0.1)
    assert queue.take() is None and (queue.queue / "hop.toml").exists()
    clock.t += 1
    assert queue.take()[0].name == "hop"


def test_the_service_stays_up_disarmed_through_stale_and_bad_plans(tmp_path):
    from test_run import Service
    queue, logs = tmp_path / "plans", tmp_path / "logs"
    queue.mkdir()
    put(queue, "yesterday.toml", GOOD, time.time() - 86400)      # queued while the service was down
    svc = Service(tmp_path, "--board", "sim", "--plan-queue", str(queue), "--log", str(logs), "--calibrate", "0.2")
    try:
        assert svc.wait_for("READY=1", 30), svc.stop()[1]
        assert svc.wait_for("plan yesterday.toml refused", 5), svc.messages
        for k, name in enumerate(("deep.toml", "move.toml", "long.toml")):   # three bad plans in a row
            put(queue, name, BAD[name], time.time() - 1)
            assert svc.wait_for(f"plan {name} refused", 5), svc.messages
        assert svc.proc.poll() is None                                  # still running, disarmed
    finally:
        rc, err = svc.stop()
    assert rc == 0, err
    assert "Traceback" not in err and "before this service started" in err
    assert not logs.exists() or not list(logs.glob("flight-*"))
    assert len(list((queue / "refused").glob("*.reason"))) == 4
