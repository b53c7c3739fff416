"""The scripts that set this code beside a commit's (scripts/revision.py, `--against REV` of
scripts/batch_profile.py and scripts/diagnose_speed.py): the commit's package as git holds it, bad input
one line and exit 2 with nothing written, and the reports' comparison finding what differs."""
from __future__ import annotations

import math
import shutil
import subprocess
import sys

import numpy as np
import pytest

from helpers.script import ROOT, load

needs_git = pytest.mark.skipif(shutil.which("git") is None or not (ROOT / ".git").exists(), reason="no git checkout")


def _run(*args: str):
    return subprocess.run([sys.executable, *args], capture_output=True, text=True, cwd=ROOT)


@needs_git
def test_a_commits_package_is_what_git_holds(tmp_path):
    revision = load("revision")
    rev = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "HEAD~1"], capture_output=True, text=True).stdout.strip()
    folder = revision.package(rev, str(tmp_path))
    for path, inside in (("sim/diagnose/dataset.py", "flightctl/sim/diagnose/dataset.py"),
                         ("flightctl/params.py", "flightctl/params.py"), ("hil/__init__.py", "flightctl/hil/__init__.py")):
        held = subprocess.run(["git", "-C", str(ROOT), "show", f"{rev}:{path}"], capture_output=True).stdout
        assert (tmp_path / inside).read_bytes() == held
    assert folder == str(tmp_path)
    assert revision.day(rev)[:2] == "20"


@needs_git
@pytest.mark.parametrize("args", [("scripts/batch_profile.py", "--against", "no-such-commit"),
                                  ("scripts/diagnose_speed.py", "--against", "no-such-commit"),
                                  ("scripts/diagnose_speed.py",),
                                  ("scripts/diagnose_speed.py", "--against", "HEAD", "--rounds", "0"),
                                  ("scripts/diagnose_speed.py", "--against", "HEAD", "no-such-log.bbl")])
def test_bad_input_is_one_line_and_exit_2(tmp_path, args):
    out = tmp_path / "r.json"
    r = _run(*args, *(("--json", str(out)) if "batch_profile" in args[0] else ()))
    assert r.returncode == 2, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr, r.stderr
    assert not out.exists() and r.stdout == ""


def test_the_reports_differences_are_found_where_they_are():
    differences = load("diagnose_speed").differences
    rng = np.random.default_rng(42)
    report = {"cause": "rotor_drag", "parameters": {"k": float(rng.uniform(0, 1))}, "runtime_s": 3.0,
              "rounds": [{"score": [float(x) for x in rng.standard_normal(int(rng.integers(3, 8)))],
                          "missing": math.nan} for _ in range(int(rng.integers(2, 5)))]}
    same = {**report, "runtime_s": float(rng.uniform(4, 9)), "rounds": [dict(r) for r in report["rounds"]]}
    assert differences(report, same) == []                      # the run time aside, NaN equal to NaN
    i = int(rng.integers(len(report["rounds"])))
    j = int(rng.integers(len(report["rounds"][i]["score"])))
    moved = {**same, "rounds": [dict(r, score=list(r["score"])) for r in same["rounds"]]}
    moved["rounds"][i]["score"][j] += float(rng.uniform(1e-12, 1e-9)) * (1 + abs(moved["rounds"][i]["score"][j]))
    assert differences(report, moved) == [f"/rounds[{i}]/score[{j}]"]
    fewer = {k: v for k, v in report.items() if k != "cause"}
    assert differences(report, fewer) == ["/cause"]
