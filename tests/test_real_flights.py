"""`flightctl diagnose` on real flights of another vehicle (issue 16; docs/real-flights.md): the
INDIflight 3-inch quadrotor of Blaha, Smeur and Remes (IROS 2024), whose motor time constant is
published (bench 20 ms; in flight 25.9-26.6 ms) and whose logs carry the rotors' own speeds.

- its rotor lag is named and sized against those figures and against the log's measured speeds;
- fitted on one flight, the model predicts another flight of the vehicle better than its base model;
- an effect hidden in the real log, drawn from a seeded generator and not told to the diagnosis, is
  found: the motor commands made to act later by 10-40 ms (the timing grows by that much, within
  5 ms), or one motor made to give a fraction of the thrust its command asks (the motor and its
  scale, in the identified rotor gains);
- the CSV that `flightctl log import` writes gives the same diagnosis as the foreign log.
"""
from __future__ import annotations

import json

import numpy as np
import pytest

from flightctl.cli import main
from real import INDIFLIGHT, need, rows_and_header, write

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
    for key in ("cause", "parameters", "rmse_base", "gain", "causes", "base_model"):
        assert again[key] == report[key], key


def test_a_delay_hidden_in_the_real_log_is_found(flight, tmp_path):
    csv, report, _ = flight
    rng = np.random.default_rng(16)
    delay = float(rng.uniform(0.010, 0.040))
    meta, names, rows = rows_and_header(csv.read_text())
    t = np.array([float(r[0]) for r in rows])
    shift = int(round(delay / float(np.median(np.diff(t)))))
    for j in (names.index(f"P{i}") for i in range(1, 5)):
        cells = [r[j] for r in rows]
        for r, v in zip(rows, cells[shift:] + cells[-1:] * shift):   # row k logs the command of row k + shift:
            r[j] = v                                                 # the motors act `delay` after the log says
    hidden = run([write(meta, names, rows, tmp_path / "delayed.csv")], tmp_path / "delayed.json")
    assert abs(timing(hidden) - timing(report) - shift * float(np.median(np.diff(t)))) <= 0.005, (
        delay, timing(report), timing(hidden))


def test_a_motor_scaled_in_the_real_log_is_found(flight, tmp_path):
    csv, report, _ = flight
    rng = np.random.default_rng(17)
    motor = int(rng.integers(1, 5))
    scale = float(rng.uniform(0.8, 0.95) if rng.random() < 0.5 else rng.uniform(1.05, 1.2))
    h2 = report["base_model"]["h2"]["value"]       # the vehicle's own curve, eq. 26 (unmodified log)
    meta, names, rows = rows_and_header(csv.read_text())
    j = names.index(f"P{motor}")
    for r in rows:   # the logged command now asks for 1/scale of the thrust the motor gave: it gives `scale` times it
        P = float(r[j])
        if P > 0:
            r[j] = f"{min(255.0, max(0.0, h2 + (P - h2) / np.sqrt(scale))):.6g}"
    hidden = run([write(meta, names, rows, tmp_path / "scaled.csv")], tmp_path / "scaled.json")
    before = np.array(report["base_model"]["rotor_gain"]["value"])
    after = np.array(hidden["base_model"]["rotor_gain"]["value"])
    ratio = after / before
    ratio = ratio / np.mean(np.delete(ratio, motor - 1))     # the gains are relative to the four's mean
    assert int(np.argmax(np.abs(ratio - 1.0))) == motor - 1, ratio
    assert ratio[motor - 1] == pytest.approx(scale, abs=0.03), (scale, ratio)
    assert np.allclose(np.delete(ratio, motor - 1), 1.0, atol=0.02), ratio


def _script():
    import importlib.util
    from pathlib import Path
    root = Path(__file__).resolve().parents[1]
    spec = importlib.util.spec_from_file_location("real_flights", root / "scripts" / "real_flights.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod, (root / "docs" / "real-flights.md").read_text()


def _doc_row(doc: str, name: str) -> str:
    return next(line for line in doc.splitlines() if line.startswith(f"| {name} |"))


@pytest.mark.parametrize("name", ["indiflight/LOG00258.BFL", "px4/roboto-test.ulg"])
def test_the_docs_table_is_what_the_script_computes_quick(tmp_path, name):
    """Two rows recomputed (a short log, and the refused one); every row under -m slow: the reports
    are a function of the logs and the code, run after run."""
    rf, doc = _script()
    status, report, _ = rf.diagnose(need(INDIFLIGHT.parent / name), tmp_path / "r.json")
    assert rf.row(name, status, report) == _doc_row(doc, name)


@pytest.mark.slow
@pytest.mark.timeout(900)   # nine real logs diagnosed in turn: 2 min on a fast day, over 4 on a slow one
def test_every_shipped_log_is_diagnosed_or_refused_as_the_docs_table_says(tmp_path):
    rf, doc = _script()
    for name in rf.LOGS:
        status, report, _ = rf.diagnose(need(INDIFLIGHT.parent / name), tmp_path / "r.json")
        assert status in (0, 2)
        assert rf.row(name, status, report) == _doc_row(doc, name), name
