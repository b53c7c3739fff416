"""`flightctl sim --json`: the outcome and the step metrics of a flight, machine-readable, SI units."""
from __future__ import annotations

import json
import math

import pytest

from flightctl.cli import main as cli
from flightctl.logfile import read_flight_log
from flightctl.sim.flights.metrics import step_metrics
from flightctl.sim.flights.scenarios import Step

PLAN = """name = "json-roll"
duration = 7.0
[[move]]
t = 0.0
channel = "alt"
value = 1.0
ramp = 2.0
[[move]]
t = 4.0
channel = "roll"
value_deg = 5.0
"""


def test_json_metrics_of_a_roll_step(tmp_path, capsys):
    plan, log, out = tmp_path / "p.toml", tmp_path / "f.csv", tmp_path / "m.json"
    plan.write_text(PLAN)
    assert cli(["sim", "--plan", str(plan), "--log", str(log), "--no-plot", "--quiet", "--json", str(out)]) == 0
    m = json.loads(out.read_text())
    assert m["scenario"] == "json-roll" and m["crashed"] is False
    assert m["reason"] and not m["reason"].startswith("stopped")     # the plan was flown to its end
    assert m["flown_s"] > 6.9 and m["rows"] > 3000
    assert [e["what"] for e in m["events"]][0] == "armed"
    (step,) = m["steps"]
    assert step["channel"] == "roll" and step["end"] == math.radians(5.0)
    # the same numbers as the metrics of the written log, in SI units (rad, s)
    ref = step_metrics(read_flight_log(log, extra=("true_roll", "true_pitch", "true_yaw", "true_z")),
                       Step("roll", 4.0, 0.0, math.radians(5.0), 3.0), 0.0)
    assert step["rise_s"] == pytest.approx(ref.rise_s, abs=0.005) and 0 < step["rise_s"] < 1.0   # the CSV has 6 digits
    assert step["coupling"]["alt"] == pytest.approx(ref.coupling["alt"], rel=1e-3)
    assert abs(step["steady_error"]) < math.radians(1.0)


def test_json_into_a_missing_directory_is_one_line(tmp_path, capsys):
    code = cli(["sim", "hover", "--log", str(tmp_path / "f.csv"), "--json", str(tmp_path / "no" / "m.json")])
    assert code == 2
    assert capsys.readouterr().err.count("\n") == 1 and not (tmp_path / "f.csv").exists()
