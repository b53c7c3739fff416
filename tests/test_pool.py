"""The sweeps' worker processes (sim/pool.py) never outlive their parent: one killed outright (as
pytest-xdist ends a worker that does not stop on Ctrl-C) takes them with it, mid-job."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest

PARENT = """
import multiprocessing, sys, time
from flightctl.sim.pool import run_all
said = []
def polled():
    if not said:
        said.append(1)
        print(" ".join(str(p.pid) for p in multiprocessing.active_children()), flush=True)
run_all(time.sleep, [3600, 3600], 2, poll_s=0.05, polled=polled)
"""


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/status") as f:
            return "\\tZ" not in next(line for line in f if line.startswith("State:"))  # a zombie has ended
    except FileNotFoundError:
        return False


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the parent-death signal is Linux's")
def test_workers_end_with_a_parent_killed_outright():
    parent = subprocess.Popen([sys.executable, "-c", PARENT], stdout=subprocess.PIPE, text=True)
    workers = [int(p) for p in parent.stdout.readline().split()]
    assert len(workers) == 2 and all(_alive(p) for p in workers)
    os.kill(parent.pid, signal.SIGKILL)
    parent.wait()
    while any(_alive(p) for p in workers):   # no deadline: an orphan would run its hour (pytest-timeout ends it)
        time.sleep(0.05)
