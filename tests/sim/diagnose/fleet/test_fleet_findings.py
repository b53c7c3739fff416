"""The fleet report sees what each log sees (issue 46): on small simulated fleets (sim/sweeps/fleet_flown.py:
three vehicles, ten or five flights each, ArduCopter DataFlash at the default rates), one motor of one
vehicle weakened to about 0.8 of its thrust from a flight in the middle on, which vehicle, motor and
flight drawn from a seeded generator and never told to the command (`flightctl diagnose --corpus DIR
--fleet REPORT`, its own process): ten flights name the vehicle, the motor and the onset flight by the
trend test; five flights name them from the logs' own findings at least. On drawn rows (sim/flights/
fleet_drawn.py, the noise drawn too), the test names a motor on no more fleets without a change than its
stated rate allows, and its p-value goes below what any permutation of ten flights can give. A report's
lines never contradict their own numbers (a rate it says a log lacks, which the log has)."""
from __future__ import annotations

import json
import re
import subprocess
import sys

import numpy as np
import pytest
from scipy import stats

pytest.importorskip("pymavlink")

from flightctl.sim.sweeps.fleet_flown import simulate_fleet  # noqa: E402
from flightctl.sim.sweeps.fleet_drawn import Noise, draw_fleet, judge  # noqa: E402
from flightctl.sim.diagnose.fleet.report import build  # noqa: E402
from flightctl.sim.diagnose.fleet.trends import ALPHA, test as change_test  # noqa: E402
from test_fleet_report import diagnose  # noqa: E402  (the command as a user runs it)

WEAK = (0.78, 0.82)          # "about 0.8"


def contradictions(md: str) -> list[str]:
    """The lines of a report that say a log needs a rate it has: 'needs ... X Hz or more' beside 'this
    log: Y Hz' or 'logged at Y Hz' with Y >= X."""
    bad = []
    for line in md.splitlines():
        need = re.search(r"(\d+(?:\.\d+)?) Hz or more", line)
        have = re.search(r"(?:this log: |logged at )(\d+(?:\.\d+)?) Hz", line)
        if need and have and float(have[1]) >= float(need[1]):
            bad.append(line)
    return bad


def fleet(tmp, seed: int, flights: int):
    truth = simulate_fleet(tmp / "logs", np.random.default_rng(seed), vehicles=3, flights=flights, seconds=22.0,
                           aging=False, weak_scale=WEAK)
    done = diagnose(tmp / "logs", tmp / "report")
    assert done.returncode == 0, done.stderr
    return truth, json.loads((tmp / "report" / "fleet.json").read_text()), (tmp / "report" / "fleet.md").read_text()


@pytest.fixture(scope="module")
def ten(tmp_path_factory):
    return fleet(tmp_path_factory.mktemp("ten"), 4601, 10)


@pytest.fixture(scope="module")
def five(tmp_path_factory):
    return fleet(tmp_path_factory.mktemp("five"), 4602, 5)


def _weak(truth):
    w = truth["weak"]
    v = truth["vehicles"][w["vehicle"]]
    return w, v["uid"], v["logs"]


def test_ten_flights_name_the_vehicle_the_motor_and_the_onset_flight(ten):
    truth, rep, md = ten
    w, uid, logs = _weak(truth)
    assert len(rep["changes"]) == 1, rep["changes"]
    c = rep["changes"][0]
    assert (c["vehicle"], c["what"], c["onset_flight"]) == (uid, f"motor {w['motor']}", w["onset"]), (w, c)
    assert c["onset_log"] == logs[w["onset"]] and c["p_adjusted"] < rep["alpha"]
    # the physical check reads the drawn scale back from the share's ratio
    assert float(re.search(r"about (\d\.\d+) of before", c["physical"]["check"])[1]) == pytest.approx(w["scale"], abs=0.03)
    assert "Nothing changed" not in md and f"| {uid} | motor {w['motor']}: " in md


def test_ten_flights_carry_up_what_each_log_names_beside_the_trend(ten):
    truth, rep, md = ten
    w, uid, _ = _weak(truth)
    per = [p for p in rep["per_log"] if p["cause"] == "motor_weak"]
    assert [(p["vehicle"], p["motor"]) for p in per] == [(uid, w["motor"])], per
    p = per[0]
    assert p["first_flight"] == w["onset"] and set(p["flights"]) <= set(range(w["onset"], 10)), (w, p)
    assert len(p["flights"]) >= (10 - w["onset"]) - 1
    assert p["trend"].startswith(f"the trend test names motor {w['motor']} from flight {w['onset'] + 1}")


def test_five_flights_name_it_from_the_logs_own_findings_at_least(five):
    truth, rep, md = five
    w, uid, logs = _weak(truth)
    per = [p for p in rep["per_log"] if p["cause"] == "motor_weak"]
    assert [(p["vehicle"], p["motor"], p["first_flight"]) for p in per] == [(uid, w["motor"], w["onset"])], (w, per)
    assert per[0]["first_log"] == logs[w["onset"]]
    assert "Nothing changed" not in md
    assert f"| {uid} | motor {w['motor']} weak |" in md
    # what the trend test says beside it, it says of the same vehicle and motor, or nothing
    assert all((c["vehicle"], c["what"]) == (uid, f"motor {w['motor']}") for c in rep["changes"]), rep["changes"]


def test_no_line_of_the_report_contradicts_its_own_numbers(ten, five):
    for _, rep, md in (ten, five):
        assert contradictions(md) == []
        for v in rep["vehicles"]:
            if v["timing"]:                 # these logs are at 25 Hz: the reason given is the rate they lack
                assert "25.0 Hz" in v["timing"] and "48 Hz or more" in v["timing"]


def test_a_project_log_at_450_hz_is_not_told_it_needs_48_hz(tmp_path):
    """The issue's line: this project's own flight log (the 450 Hz loop's CSV) reaches the dynamic tier,
    which runs on this project's airframe and identifies no timing: the report says that, not a rate."""
    folder = tmp_path / "logs"
    folder.mkdir()
    fly = subprocess.run([sys.executable, "-P", "-m", "flightctl.cli", "sim", "hover", "--log", str(folder / "hover.csv"),
                          "--no-plot", "--quiet"], capture_output=True, text=True)
    assert fly.returncode == 0, fly.stderr
    done = diagnose(folder, tmp_path / "report")
    assert done.returncode == 0, done.stderr
    rep = json.loads((tmp_path / "report" / "fleet.json").read_text())
    md = (tmp_path / "report" / "fleet.md").read_text()
    (v,) = rep["vehicles"]
    assert v["flights"][0]["status"] == "diagnosed"
    assert contradictions(md) == [] and "Hz or more" not in v["timing"], v["timing"]
    assert "this project's airframe" in v["timing"]


def test_fleets_without_a_change_are_flagged_at_the_stated_rate_at_most():
    """Null rows: fleets of three healthy vehicles' drawn rows, the noise (the shares' errors, the spread
    between flights) and the fleet's length drawn: the share of fleets with a motor named stays within
    what a 5 % family-wise rate gives (a binomial's 99 % upper bound)."""
    rng = np.random.default_rng(4603)
    fleets, flagged = 60, 0
    for _ in range(fleets):
        noise = Noise(float(np.log(rng.uniform(5e-4, 2e-2))), float(rng.uniform(0.1, 0.4)), float(rng.uniform(0.0, 1e-2)))
        rows, truth = draw_fleet(rng, 3, int(rng.choice([5, 10, 20])), 0.0, noise)
        flagged += judge(build(rows), truth)["false"] > 0
    assert flagged <= stats.binom.ppf(0.99, fleets, ALPHA), flagged


def test_drawn_changes_are_found_and_the_healthy_vehicles_left_alone():
    rng = np.random.default_rng(4604)
    got = []
    for _ in range(12):
        noise = Noise(float(np.log(rng.uniform(1e-3, 5e-3))), 0.3, float(rng.uniform(0.0, 2e-3)))
        rows, truth = draw_fleet(rng, 3, 10, float(rng.uniform(0.1, 0.2)), noise)
        got.append(judge(build(rows), truth))
    assert sum(g["found"] for g in got) >= 11, got
    assert sum(g["false"] for g in got) <= 1, got


def test_the_bootstraps_p_value_goes_below_what_ten_flights_orderings_can_give():
    """Ten flights, a step of many standard errors at a drawn flight: the p-value is the bootstrap's
    resolution, below 1/60 (a permutation test's floor here); the same series without the step is not."""
    rng = np.random.default_rng(4605)
    se = rng.uniform(0.005, 0.015, 10)
    y = 1.0 + rng.normal(0.0, se)
    onset = int(rng.integers(3, 8))
    stepped = y.copy()
    stepped[onset:] += rng.uniform(0.1, 0.2)
    c = change_test(stepped, se)
    assert c.p < 1 / 60 and c.onset == onset, c
    assert change_test(y, se).p > 0.01


def test_a_real_craft_over_several_logs_is_one_vehicle_in_the_order_of_its_start_times(tmp_path):
    """INAV's "NAZGUL 10" (../shared/data/real/flights/inav: three logs in one file, each with its craft name
    and its RTC's start): one vehicle by its craft name, in its logs' start order; none of the three flew long
    enough to judge, and the report says so rather than that nothing changed."""
    from helpers.real import FLIGHTS, need
    src = need(FLIGHTS / "inav" / "blackbox_log_2026-02-21_145057.TXT")
    (tmp_path / "logs").mkdir()
    (tmp_path / "logs" / "nazgul.TXT").symlink_to(src)
    done = diagnose(tmp_path / "logs", tmp_path / "report")
    assert done.returncode == 0, done.stderr
    rep = json.loads((tmp_path / "report" / "fleet.json").read_text())
    md = (tmp_path / "report" / "fleet.md").read_text()
    (v,) = rep["vehicles"]
    assert v["vehicle"] == "NAZGUL 10" and "Craft name" in v["identity"]
    assert [f["log"] for f in v["flights"]] == [f"nazgul.TXT #{k}" for k in (1, 2, 3)]
    starts = [f["start_utc"] for f in v["flights"]]
    assert v["order"].startswith("the logs' start times") and starts == sorted(starts)
    assert all(f["status"] == "refused" for f in v["flights"])
    assert rep["changes"] == [] and rep["per_log"] == [] and "Nothing changed" not in md
    assert "3 logs, 0 diagnosed (not: too short to judge, 3)" in md and contradictions(md) == []


def test_a_header_only_log_goes_with_its_files_other_logs():
    """A file of many blackbox logs is one flight controller's flash: a log refused before its header was
    read (header only, as in betaflight/btfl_all.bbl) is the vehicle its file's other logs name, not its
    folder's; a log alone in its file without an identity stays its folder's."""
    from flightctl.sim.diagnose.fleet.grouping import group
    named = {"vehicle_id": "AIKO AIKONF7 / Gecko", "vehicle_id_source": "the blackbox header's Craft name"}
    rows = [{"log": "bf/all.bbl #1", "path": "/d/bf/all.bbl", "index": 1, "status": "diagnosed", "meta": named},
            {"log": "bf/all.bbl #2", "path": "/d/bf/all.bbl", "index": 2, "status": "refused", "meta": {},
             "reason": "header only: armed and disarmed at once, no frames"},
            {"log": "bf/other.bbl", "path": "/d/bf/other.bbl", "index": None, "status": "refused", "meta": {}}]
    vs = {v.name: [r["log"] for r in v.flights] for v in group(rows)}
    assert vs == {"AIKO AIKONF7 / Gecko": ["bf/all.bbl #1", "bf/all.bbl #2"], "bf": ["bf/other.bbl"]}
