"""A mistake in a command's arguments or output paths is found before the heavy libraries load (issue
39: `flightctl bench --out nodir/b.csv` answered after 59 s on a busy machine, nearly all of it importing
scipy.optimize). Each command runs in a fresh interpreter and reports which of them it imported; no
clock is read: what is judged is that they were not imported at all."""
from __future__ import annotations

import json
import subprocess
import sys

import pytest

HEAVY = ("scipy", "matplotlib", "control", "numba", "pymavlink", "pyulog", "orangebox")
PROBE = f"""
import json, sys
from flightctl.cli import main
rc = main(sys.argv[1:])
print(json.dumps([rc, sorted(m for m in {HEAVY!r} if m in sys.modules)]))
"""

BAD = [
    ["bench", "--out", "nodir/b.csv"],
    ["bench", "--board", "sim", "--out", "nodir/b.csv"],
    ["identify", "bench", "bench.csv", "--json", "nodir/fit.json"],
    ["identify", "rcbenchmark", "run.csv", "--out", "nodir/bench.csv"],
    ["identify", "real-data", "--data", "nodir", "--out", "nodir"],
    ["analyze", "--json", "nodir/a.json"],
    ["analyze", "--plot", "nodir/loops"],
    ["sim", "hover", "--log", "nodir/h.csv"],
    ["sim", "paper", "--params", "paper-as-flown", "--log", "h.csv", "--json", "nodir/m.json"],
    ["sim", "paper", "--monte-carlo", "4", "--batch", "--json", "nodir/mc.json"],
    ["sim", "faults", "--json", "nodir/f.json"],
    ["sim", "hover", "--log", "h.csv", "--effect", "motor_lag:tau=abc"],
    ["tune", "--out", "nodir/g.toml"],
    ["hil", "demo", "--json", "nodir/d.json"],
    ["hil", "serve", "--link", "tcp:0", "--json", "nodir/s.json"],
    ["hil", "serve", "--link", "serial:/dev/no-such-port,921600"],
    ["sim", "paper", "--monte-carlo", "abc"],
    ["params", "show", "no-such-vehicle"],
    ["log", "export", "flight.csv", "nodir/f.ulg"],
]


@pytest.mark.parametrize("argv", BAD, ids=" ".join)
def test_a_bad_argument_is_refused_before_the_heavy_imports(tmp_path, argv):
    # no timeout: the child is waited for, however busy the machine (it ends by itself)
    r = subprocess.run([sys.executable, "-c", PROBE, *argv], cwd=tmp_path, capture_output=True, text=True)
    rc, imported = json.loads(r.stdout.strip().splitlines()[-1])
    assert rc == 2, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert imported == [], f"imported before refusing: {imported}"
    assert list(tmp_path.iterdir()) == []                     # nothing written
