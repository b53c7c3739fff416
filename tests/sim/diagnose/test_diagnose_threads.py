"""`flightctl diagnose` starts no BLAS thread beyond its own: its fits are small matrices, and on a busy
machine OpenBLAS's pool spun for a quarter to two fifths of the user time (docs/diagnose.md, "Speed").
Checked in a child process, as a user runs the command: the threads the process holds once the
diagnosis is written (Linux's /proc/self/task), beside a control process that loads numpy with the
environment as it is, whose OpenBLAS starts its pool, so that the count is shown to see BLAS threads
where there are any."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from helpers.real import FLIGHTS, need

CHILD = """
import json, os, sys
from flightctl.cli import main
rc = main(["diagnose", sys.argv[1], "--json", sys.argv[2], "--quiet"])
print(json.dumps({"rc": rc, "threads": len(os.listdir("/proc/self/task")),
                  "env": {k: os.environ.get(k) for k in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")}}))
"""


# the control: numpy loaded as any program loads it, with the environment as it is (no thread setting)
CONTROL = """
import os, numpy
numpy.ones((64, 64)) @ numpy.ones((64, 64))
print(len(os.listdir("/proc/self/task")))
"""
UNSET = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def _child(code: str, *args) -> str:
    env = {k: v for k, v in os.environ.items() if k not in UNSET}
    done = subprocess.run([sys.executable, "-P", "-c", code, *map(str, args)], capture_output=True, text=True, env=env,
                          timeout=1800)
    assert done.returncode == 0, done.stderr[-2000:]
    return done.stdout.strip().splitlines()[-1]


@pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="counts threads in Linux's /proc")
def test_diagnose_runs_one_blas_thread(tmp_path):
    log = need(FLIGHTS / "betaflight" / "LOG00037.BFL")
    got = json.loads(_child(CHILD, log, tmp_path / "r.json"))
    assert got["rc"] == 0 and json.loads((tmp_path / "r.json").read_text())["cause"]
    assert got["env"] == {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    assert got["threads"] == 1, f"{got['threads']} threads after the diagnosis: BLAS threads were started"
    if (os.cpu_count() or 1) > 1:
        assert int(_child(CONTROL)) > 1, "the control started no BLAS thread: the count cannot see them"
