"""The fleet report finds what changed across flights, hidden in a simulated fleet (sim/sweeps/fleet_flown.py:
four vehicles, forty 30 s flights each, flown by the batched simulator and written as ArduCopter DataFlash
at ArduPilot's default rates, in one folder under numbered names that say nothing of the vehicle or the
order). The generator draws, from a seeded generator, which vehicle's motor weakens (which motor, to what
share of its thrust, from which flight) and which vehicle's battery ages (from which flight, to what
resistance); the command is run as a user runs it (`flightctl diagnose --corpus DIR --fleet REPORT`, its
own process) and is never told what was drawn.

Tolerances: the weak motor's onset flight exactly or one flight off, inside the report's onset set; the
aging battery's onset within three flights (a resistance that rises gradually is first seen above the
flights' scatter a few flights after it starts); nothing named on the two healthy vehicles (the
family-wise error rate over the fleet's series is trends.ALPHA)."""
from __future__ import annotations

import json

import numpy as np
import pytest

pytest.importorskip("pymavlink")

from flightctl.sim.sweeps.fleet_flown import simulate_fleet  # noqa: E402
from test_fleet_report import diagnose  # noqa: E402  (the command as a user runs it)

SEED = 3801
ONSET_TOL = {"motor": 1, "battery": 3}


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("fleet")
    truth = simulate_fleet(tmp / "logs", np.random.default_rng(SEED))
    done = diagnose(tmp / "logs", tmp / "report")
    assert done.returncode == 0, done.stderr
    return truth, json.loads((tmp / "report" / "fleet.json").read_text()), tmp


def test_the_logs_are_grouped_by_their_board_and_put_in_flight_order_by_their_gps_time(fleet):
    truth, rep, _ = fleet
    assert len(rep["vehicles"]) == len(truth["vehicles"])
    by = {v["vehicle"]: v for v in rep["vehicles"]}
    for v in truth["vehicles"]:
        got = by[v["uid"]]
        assert [f["log"] for f in got["flights"]] == v["logs"]
        assert got["order"].startswith("the logs' start times (GPS time")
        assert all(f["status"] == "diagnosed" for f in got["flights"])


def test_the_weak_motor_is_named_on_its_vehicle_from_the_flight_it_began(fleet):
    truth, rep, _ = fleet
    w = truth["weak"]
    uid = truth["vehicles"][w["vehicle"]]["uid"]
    motors = [c for c in rep["changes"] if c["what"].startswith("motor")]
    assert len(motors) == 1, (w, motors)
    c = motors[0]
    assert (c["vehicle"], c["what"]) == (uid, f"motor {w['motor']}"), (w, c)
    assert abs(c["onset_flight"] - w["onset"]) <= ONSET_TOL["motor"], (w, c)
    assert c["onset_set_flights"][0] <= w["onset"] <= c["onset_set_flights"][1], (w, c)
    assert c["onset_log"] == truth["vehicles"][w["vehicle"]]["logs"][c["onset_flight"]]
    assert c["after"] > c["before"]             # the weak motor is commanded more for its share of the thrust
    assert c["p_adjusted"] < rep["alpha"]


def test_the_aging_battery_is_named_on_its_vehicle_with_its_onset_and_its_rise(fleet):
    truth, rep, _ = fleet
    b = truth["battery"]
    v = truth["vehicles"][b["vehicle"]]
    packs = [c for c in rep["changes"] if c["what"] == "battery"]
    assert len(packs) == 1, (b, packs)
    c = packs[0]
    assert c["vehicle"] == v["uid"]
    assert abs(c["onset_flight"] - b["onset"]) <= ONSET_TOL["battery"], (b, c)
    assert c["after"] > c["before"]
    # the rise the report sizes against the drawn one (the pack's own resistance over its last and first flights)
    drawn = np.mean(v["ohm"][-5:]) - np.mean(v["ohm"][:b["onset"]])
    assert c["after"] - c["before"] == pytest.approx(drawn, rel=0.35), (drawn, c)


def test_nothing_is_named_on_the_healthy_vehicles(fleet):
    truth, rep, _ = fleet
    touched = {truth["vehicles"][truth[k]["vehicle"]]["uid"] for k in ("weak", "battery")}
    assert {c["vehicle"] for c in rep["changes"]} == touched, rep["changes"]
    assert len(rep["changes"]) == 2, rep["changes"]


def test_a_run_started_again_rebuilds_the_same_report_from_the_results_table(fleet):
    _, rep, tmp = fleet
    again = diagnose(tmp / "logs", tmp / "report")
    assert again.returncode == 0, again.stderr
    assert json.loads((tmp / "report" / "fleet.json").read_text()) == rep
    assert {p.name for p in (tmp / "report").glob("vehicle-*.png")} == {f"vehicle-{k}.png" for k in range(1, 5)}
