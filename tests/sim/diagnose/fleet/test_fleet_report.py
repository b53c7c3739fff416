"""The fleet report (`flightctl diagnose --corpus DIR --fleet REPORT`, sim/diagnose/fleet/) on real logs:
three of indiflight's blackbox logs (../shared/data/real/flights/indiflight, one board model, MATEK H743,
no craft name), under names whose order is not their flights': a board's name alone is no vehicle (issue
45), so they are the vehicle of their folder, the report saying the board, in the order of their `Log
start datetime`; with a `--vehicles` map, the vehicles the map
says, the report rebuilt from the results table without reading a log again. Bad `--fleet` and
`--vehicles` input is one line on stderr, exit 2, nothing written. And the change test itself on series
drawn at random (a step of a drawn size at a drawn flight, and none)."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from flightctl.cli import main
from flightctl.sim.diagnose.fleet.trends import correct, test as change_test
from helpers.real import INDIFLIGHT, need
from helpers.paths import DATA

# the three shortest of the six logs, renamed so that the names' order is the reverse of the flights'
RENAMED = {"LOG00257.BFL": "c.BFL", "LOG00258.BFL": "b.BFL", "LOG00259.BFL": "a.BFL"}


def diagnose(folder: Path, report: Path, *extra: str) -> subprocess.CompletedProcess:
    """`flightctl diagnose --corpus FOLDER --fleet REPORT` in its own process, as a user runs it (-P: the
    installed package, tests/sim/diagnose/test_corpus.py)."""
    return subprocess.run([sys.executable, "-P", "-m", "flightctl.cli", "diagnose", "--corpus", str(folder), "--fleet",
                           str(report), "--quiet", "--jobs", "2", *extra], capture_output=True, text=True,
                          env={**os.environ, "OPENBLAS_NUM_THREADS": "1"})


@pytest.fixture(scope="module")
def indiflight(tmp_path_factory):
    pytest.importorskip("distributed")
    src = need(INDIFLIGHT)
    tmp = tmp_path_factory.mktemp("fleet_real")
    (tmp / "logs").mkdir()
    for name, new in RENAMED.items():
        (tmp / "logs" / new).symlink_to(src / name)
    done = diagnose(tmp / "logs", tmp / "report")
    assert done.returncode == 0, done.stderr
    return tmp, json.loads((tmp / "report" / "fleet.json").read_text())


def test_real_logs_that_name_only_their_board_are_their_folders_vehicle_in_the_order_of_their_start_times(indiflight):
    _, rep = indiflight
    assert [v["vehicle"] for v in rep["vehicles"]] == ["(the corpus' folder)"]
    v = rep["vehicles"][0]
    assert v["identity"].startswith("the log's folder") and "MTKS MATEKH743" in v["identity"]
    assert v["order"].startswith("the logs' start times")
    assert [f["log"] for f in v["flights"]] == ["c.BFL", "b.BFL", "a.BFL"]
    starts = [f["start_utc"] for f in v["flights"]]
    assert starts == sorted(starts) and len(set(starts)) == 3
    # each flight's figures are in the report: the static tier's shares and the dynamic tier's timing
    assert v["series"]["share_1"]["flight"] == [0, 1, 2] and v["series"]["timing_s"]["flight"] == [0, 1, 2]
    assert all(s["test"] is None for s in v["series"].values())      # three flights: too few to test
    assert rep["changes"] == []
    assert v["timing"] is None                                        # the dynamic tier gave a timing: followed


def test_a_vehicles_map_regroups_the_logs_from_the_results_table(indiflight):
    tmp, _ = indiflight
    mapping = tmp / "map.csv"
    mapping.write_text("log,vehicle\nc.BFL,frame-A\nb.BFL,frame-A\na.BFL,frame-B\n")
    reports = tmp / "report" / "results.reports"
    before = {p: p.stat().st_mtime_ns for p in reports.iterdir()}
    again = diagnose(tmp / "logs", tmp / "report", "--vehicles", str(mapping))
    assert again.returncode == 0, again.stderr
    rep = json.loads((tmp / "report" / "fleet.json").read_text())
    assert [(v["vehicle"], [f["log"] for f in v["flights"]]) for v in rep["vehicles"]] == [
        ("frame-A", ["c.BFL", "b.BFL"]), ("frame-B", ["a.BFL"])]
    assert all(v["identity"] == "--vehicles" for v in rep["vehicles"])
    assert {p: p.stat().st_mtime_ns for p in reports.iterdir()} == before      # no log diagnosed again


@pytest.fixture
def one_log(tmp_path) -> Path:
    folder = tmp_path / "logs"
    folder.mkdir()
    (folder / "f.bin").symlink_to(DATA / "ardupilot" / "backend_log_80k.bin")
    return folder


@pytest.mark.parametrize("case", ["fleet is a file", "vehicles without fleet", "bad header", "a row of one cell",
                                  "unknown log", "no map", "fleet without corpus"])
def test_bad_fleet_input_is_one_line_exit_2_and_nothing_written(one_log, tmp_path, capsys, case):
    report, mapping = tmp_path / "report", tmp_path / "map.csv"
    args = ["diagnose", "--corpus", str(one_log), "--fleet", str(report), "--quiet"]
    text = {"bad header": "file,vehicle\nf.bin,A\n", "a row of one cell": "log,vehicle\nf.bin\n",
            "unknown log": "log,vehicle\nf.bin,A\ng.bin,B\n"}.get(case)
    if text is not None:
        mapping.write_text(text)
    if case == "fleet is a file":
        report.write_text("not a folder")
    if case == "vehicles without fleet":
        args = ["diagnose", "--corpus", str(one_log), "--json", str(tmp_path / "out.json"), "--vehicles", str(mapping)]
    if case == "fleet without corpus":
        args = ["diagnose", str(one_log / "f.bin"), "--json", str(tmp_path / "out.json"), "--fleet", str(report)]
    if case not in ("fleet is a file", "vehicles without fleet", "fleet without corpus"):
        args += ["--vehicles", str(mapping)]
    before = sorted(p.name for p in tmp_path.rglob("*"))
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    word = {"fleet is a file": "--fleet", "vehicles without fleet": "--vehicles", "bad header": "row 1",
            "a row of one cell": "row 2", "unknown log": "g.bin", "no map": "--vehicles",
            "fleet without corpus": "--corpus"}[case]
    assert word in err[0], err
    assert sorted(p.name for p in tmp_path.rglob("*")) == before


def test_the_change_test_finds_a_drawn_step_and_names_nothing_on_series_without_one():
    rng = np.random.default_rng(3802)
    n = 40
    changes, truth = [], []
    for k in range(6):
        se = rng.uniform(0.5, 1.5, n)
        y = 10.0 + rng.normal(0.0, se) + rng.normal(0.0, 0.3, n)      # the flights' errors and a spread between them
        onset = int(rng.integers(8, 32)) if k == 0 else None
        if onset is not None:
            y[onset:] += rng.uniform(2.5, 4.0)
        changes.append(change_test(y, se))
        truth.append(onset)
    named = correct(changes)
    assert named == [True] + [False] * 5, [(c.p, c.p_adjusted) for c in changes]
    c = changes[0]
    assert abs(c.onset - truth[0]) <= 1 and c.onset_set[0] <= truth[0] <= c.onset_set[1], (truth[0], c)
    assert c.size > 2.0 * c.size_se


@pytest.mark.parametrize("fmt", ["dataflash", "ulog"])
def test_the_simulated_fleet_writes_the_vehicle_and_the_start_as_its_autopilot_does(tmp_path, fmt):
    """sim/sweeps/fleet_flown.py's logs read back (sim/logs/identity.py) with the board the generator drew and
    each flight's start time, as the readers take them from a real log of that autopilot."""
    import datetime as dt
    pytest.importorskip("pymavlink" if fmt == "dataflash" else "pyulog")
    from flightctl.sim.sweeps.fleet_flown import simulate_fleet
    from flightctl.sim.diagnose.cli import read_logs
    truth = simulate_fleet(tmp_path, np.random.default_rng(3803), vehicles=1, flights=2, seconds=22.0, weak=False,
                           aging=False, fmt=fmt)
    v = truth["vehicles"][0]
    for name, start in zip(v["logs"], v["start_utc"]):
        meta = read_logs([str(tmp_path / name)], None, lambda *a: None)[0].meta
        assert meta["vehicle_id"] == v["uid"]
        read = dt.datetime.fromisoformat(meta["start_utc"].replace("Z", "+00:00"))
        # the log's time zero: ArduPilot's boot (seconds before arming), PX4's first row (the arming here)
        assert dt.timedelta(0) <= dt.datetime.fromisoformat(start) - read < dt.timedelta(seconds=30), (start, read)
