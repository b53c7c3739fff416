"""`flightctl diagnose` on real flights of another vehicle (issue 16; docs/real-flights.md): the
INDIflight 3-inch quadrotor of Blaha, Smeur and Remes (IROS 2024), whose motor time constant is
published (bench 20 ms; in flight 25.9-26.6 ms) and whose logs carry the rotors' own speeds.

- its rotor lag is named and sized against those figures and against the log's measured speeds;
- fitted on one flight, the model predicts another flight of the vehicle better than its base model;
- (effects hidden in real logs, and logs scrambled on purpose: tests/sim/diagnose/test_diagnose_real_hidden.py);
- the CSV that `flightctl log import` writes gives the same diagnosis as the foreign log.
"""
from __future__ import annotations

import json
import re

import pytest

from flightctl.cli import main
from helpers.real import FLIGHTS, INDIFLIGHT, need
from helpers.paths import DATA, ROOT

ARDUPILOT = DATA / "ardupilot"     # this project's test logs (tests/data)

BENCH_TAU = 0.020                    # s, the paper's Table I: the motor's time constant on the bench
FLIGHT_TAU = (0.0259, 0.0266)        # s, its onboard fit in flight, motors 1-3
TIMING = ("motor_lag", "actuation_delay", "motor_dynamics")


def run(args: list[str], out) -> dict:
    assert main(["diagnose", *map(str, args), "--json", str(out), "--quiet"]) == 0
    return json.loads(out.read_text())


def timing(report: dict) -> float:
    """The size (s) of the chain's cause that times the actuation."""
    entry = next(c for c in report["causes"] if c["cause"] in TIMING)
    return float(next(iter(entry["parameters"].values())))


@pytest.fixture(scope="module")
def flight(tmp_path_factory):
    """LOG00230 imported with `flightctl log import`, its diagnosis (of the foreign log itself, with
    LOG00231, another flight of the vehicle, to validate on) and the CSV's text."""
    tmp = tmp_path_factory.mktemp("indiflight")
    log = need(INDIFLIGHT / "LOG00230.BFL")
    csv = tmp / "LOG00230.csv"
    assert main(["log", "import", str(log), str(csv), "--quiet"]) == 0
    report = run([log, "--validate", need(INDIFLIGHT / "LOG00231.BFL")], tmp / "LOG00230.json")
    return csv, report, tmp


def test_the_rotor_lag_is_named_and_sized_against_the_published_and_the_measured_rotor_speeds(flight):
    _, report, _ = flight
    assert report["base_model"]["identified"]
    t = timing(report)
    assert 0.75 * BENCH_TAU <= t <= 1.35 * FLIGHT_TAU[1], t
    check = report["rotor_speed_check"]          # the log's omega, commanded -> measured
    assert 0.75 * BENCH_TAU <= check["tau"] <= 1.2 * FLIGHT_TAU[1], check
    assert abs(t - (check["tau"] + check["delay"])) <= 0.006, (t, check)


def test_fitted_on_one_flight_it_predicts_another_better_than_the_base_model(flight):
    _, report, _ = flight
    v = report["validation"]
    assert v["causes"] == [c["cause"] for c in report["causes"]]
    assert v["rmse_extended"] < v["rmse_base"] and v["gain"] > 0.02, v


def test_the_imported_csv_gives_the_same_diagnosis_as_the_foreign_log(flight):
    csv, report, tmp = flight
    again = run([csv], tmp / "csv.json")
    for key in ("cause", "parameters", "rmse_base", "gain", "causes", "base_model", "tier", "static"):
        assert again[key] == report[key], key


def _doc_table() -> list[str]:
    """The rows of docs/real-flights.md's corpus table."""
    from flightctl.sim.diagnose.corpus import TABLE_BEGIN, TABLE_END
    doc = (ROOT / "docs" / "real-flights.md").read_text()
    return doc.split(TABLE_BEGIN, 1)[1].split(TABLE_END, 1)[0].strip().splitlines()


def _corpus(folders, tmp_path) -> list[str]:
    out = tmp_path / "table.md"
    assert main(["diagnose", "--corpus", *map(str, folders), "--table", str(out), "--quiet"]) == 0
    from flightctl.sim.diagnose.corpus import TABLE_BEGIN, TABLE_END
    return out.read_text().split(TABLE_BEGIN, 1)[1].split(TABLE_END, 1)[0].strip().splitlines()


def _headline(lines: list[str]) -> tuple[int, int]:
    """(flights diagnosed, airborne flights) from the table's headline."""
    m = re.match(r"\*\*(\d+) of (\d+) airborne multirotor flights get a diagnosis", lines[0])
    assert m, lines[0]
    return int(m[1]), int(m[2])


def test_the_docs_table_is_what_the_corpus_command_computes_quick(tmp_path):
    """Three rows recomputed (a short flight, a refused one, and a log of no flight) from two folders
    that hold them where the shipped folders do, and the headline's count of them; every row under -m
    slow: the rows are a function of the logs and the code."""
    names = ["flights/indiflight/LOG00258.BFL", "flights/px4/roboto-test.ulg", "data/ardupilot/backend_log_80k.bin"]
    sources = [INDIFLIGHT.parent / "indiflight/LOG00258.BFL", INDIFLIGHT.parent / "px4/roboto-test.ulg",
               ARDUPILOT / "backend_log_80k.bin"]
    for name, source in zip(names, sources):
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).symlink_to(need(source).resolve())
    lines = _corpus([tmp_path / "flights", tmp_path / "data"], tmp_path)
    doc = _doc_table()
    rows = [line for line in lines if line.startswith("|")]
    assert rows[:2] == [line for line in doc if line.startswith("|")][:2]      # the columns
    assert {r.split(" | ")[0] for r in rows[2:]} == {f"| {n}" for n in names}
    for row in rows[2:]:
        assert row in doc, (row, [r for r in doc if r.startswith(row.split(" | ")[0])])
    diagnosed = sum("| refused |" not in r for r in rows[2:])
    flights = sum(not any(w in r for w in ("| never armed", "| header only", "| too short to judge",
                                           "may never have left the ground", "not a multirotor")) for r in rows[2:])
    assert _headline(lines) == (diagnosed, flights)


@pytest.mark.slow
@pytest.mark.timeout(1800)   # every shipped log, two at a time: 5-10 min on this machine when shared
def test_every_shipped_log_is_diagnosed_or_refused_as_the_docs_table_says(tmp_path):
    assert _corpus([need(INDIFLIGHT.parent), ARDUPILOT.parent], tmp_path) == _doc_table()


# What a refusal of an airborne multirotor flight may say (issue 45, "Done when"): its motors or its attitude
# (or gyro) not logged, or logged under the static tier's 5 Hz
NOT_LOGGED = ("were not logged", "was not logged", "were logged at")


def test_every_airborne_multirotor_flight_of_the_shipped_corpus_with_its_motors_and_attitude_gets_a_tier():
    """Issue 45's "Done when", on the docs table the slow test above recomputes from the shipped logs: every row
    the corpus counts as an airborne multirotor flight (`corpus.flew`: not refused as holding no flight, nor as
    another vehicle) gets the static tier at least (a dynamic row has the static tier too), unless its refusal
    says its motors or its attitude were not logged (or too slowly); and the headline counts those rows."""
    from flightctl.sim.diagnose.corpus import NO_FLIGHT
    from flightctl.sim.logs.frames import NOT_MULTIROTOR
    lines = _doc_table()
    rows = [r.split(" | ") for r in lines if r.startswith("| flights/") or r.startswith("| data/")]
    flights = [r for r in rows if r[4] != "refused" or not any(w in r[-1] for w in NO_FLIGHT + (NOT_MULTIROTOR,))]
    assert flights and len(rows) > len(flights)
    for r in flights:
        if r[4] == "refused":
            assert any(w in r[-1] for w in NOT_LOGGED), (r[0], r[-1])
        else:
            assert r[4] in ("static", "dynamic (static too)") and r[5], (r[0], r[4], r[5])
    # diagnosed: a tier with a finding of the vehicle, not a static cell of the battery's figures alone
    battery = [r for r in flights if r[4] == "static" and all(p.startswith(("battery ", "R ")) for p in r[5].split("; "))]
    assert _headline(lines) == (sum(r[4] != "refused" for r in flights) - len(battery), len(flights)), battery
    assert all("btfl_all.bbl #12" in r[0] for r in battery) and f"{len(battery)} gets the battery's figures alone" in lines[0]


def test_a_flight_answered_on_its_battery_alone_is_not_counted_as_diagnosed():
    """btfl_all.bbl #12 (3.7 s in the air: too little hover for the shares, no vibration, no motor at full command)
    gets the static tier with its battery's voltage only: a flight without a diagnosis of its vehicle in the
    headline, said apart; a flight whose static tier finds its hover (mechanical_fail.log) is diagnosed."""
    from flightctl.sim.diagnose.corpus import Row, headline, run_one
    row = run_one(Row("btfl_all.bbl #12", str(need(FLIGHTS / "betaflight" / "btfl_all.bbl")), 12))
    st = row.report["static"]
    assert row.status == "diagnosed" and row.tier() == "static" and "battery" in st, row.reason
    assert not any(k in st for k in ("hover", "vibration")) and st["motor_at_full"]["spans"] == [], st
    other = run_one(Row("mechanical_fail.log", str(ARDUPILOT / "mechanical_fail.log"), None))
    assert other.tier() == "static" and "hover" in other.report["static"] and other.diagnosed()
    assert not row.diagnosed()
    line = headline([row, other])
    assert line.startswith("**1 of 2 airborne multirotor flights get a diagnosis (50 %)**: 0 the dynamic tier, 1 the "
                           "static tier only, 1 gets the battery's figures alone"), line
    row.stored(None)                     # as the corpus keeps a finished row (the results table): the count holds
    assert not row.diagnosed() and headline([row, other]) == line


def _refusal(capsys, log, tmp_path, *index) -> str:
    capsys.readouterr()
    out = tmp_path / "r.json"
    assert main(["diagnose", str(log), *index, "--json", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and not out.exists(), err
    return err


def test_a_px4_hover_with_motors_logged_at_10_hz_is_judged_for_static_effects(tmp_path):
    """quadrotor_local.ulg takes off on a ramp that sits on its legs for about ten seconds: with those
    rows taken as flight no effectiveness could be told from zero and the log was refused as contradicting
    its layout. Its 10 Hz motor outputs are enough for the static effects, and only those are judged."""
    report = run([need(FLIGHTS / "px4" / "quadrotor_local.ulg")], tmp_path / "q.json")
    base = report["base_model"]
    for name in ("k_p", "k_q", "k_z"):
        assert base[name]["value"] > 2 * base[name]["stderr"], (name, base[name])
    not_judged = {n["cause"]: n["why"] for n in report["not_judged"]}
    assert all("10.0 Hz" in not_judged[c] for c in TIMING), not_judged
    assert report["data"]["airborne_s"] < 80          # the ramp on the ground and the touchdown left out


def _static_only(log, tmp_path, *index) -> str:
    """The report of a log the dynamic tier refuses and the static tier answers: its `tier_why`."""
    out = tmp_path / "r.json"
    assert main(["diagnose", str(log), *index, "--json", str(out), "--quiet"]) == 0
    report = json.loads(out.read_text())
    assert report["tier"] == "static" and report["cause"] == "none" and report["static"], report["tier_why"]
    return report["tier_why"]


def test_px4_sensors_logged_at_9_hz_get_the_static_tier_and_are_told_why_not_the_dynamic(tmp_path):
    why = _static_only(need(FLIGHTS / "px4" / "esc_status_log.ulg"), tmp_path)
    assert "gyro and accelerometer were logged at 9.6 Hz" in why and "SDLOG_PROFILE" in why, why
    assert "contradict" not in why


def test_a_log_that_hardly_moves_an_axis_gets_the_static_tier_and_is_told_it_does_not_show_it(tmp_path):
    """btfl_all.bbl #12: the Gecko of btfl_002 (which is judged), 3.7 s in the air, hardly a pitch."""
    why = _static_only(need(FLIGHTS / "betaflight" / "btfl_all.bbl"), tmp_path, "--index", "12")
    assert "does not identify the vehicle's pitch effectiveness" in why and "s in the air" in why, why
    assert "contradict" not in why
    # the refusal says what an independent regression finds, and it agrees: no pitch in this flight
    found = re.search(r"regression of the angular acceleration .* finds pitch t = (-?[\d.]+), the layout's sign in "
                      r"(\d) of 8 blocks", why)
    assert found, why
    assert float(found[1]) < 2.0 and int(found[2]) < 8, why


def test_a_take_off_that_never_left_the_ground_is_not_called_an_unlogged_motor(tmp_path, capsys):
    """INAV's log 3: motor 3 held at its minimum by the controller for half a second on the ground."""
    err = _refusal(capsys, need(FLIGHTS / "inav" / "blackbox_log_2026-02-21_145057.TXT"), tmp_path, "--index", "3")
    assert "too short to judge" in err and "not logged" not in err, err
