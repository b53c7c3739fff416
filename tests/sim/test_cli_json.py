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


def test_the_json_and_the_log_say_what_was_flown_and_where_each_value_comes_from(tmp_path, capsys):
    """A parameter file with its own [gains], flown with `--gains table4`: the flag wins; the metrics
    record the parameters (file, a hash of their values), the gains, the estimator and the seed; the
    log's header gives each value its own source (Table 4's 17.1 is not labelled Table 6, the file's
    rotor inertia not Table 2)."""
    from flightctl.params import TABLE4, load
    plan, params, log, out = (tmp_path / n for n in ("p.toml", "mine.toml", "f.csv", "m.json"))
    plan.write_text(PLAN)
    params.write_text("Jp = 0.0001  # kg m^2; weighed and measured on the bench\n[gains]\nkp_phi = 5.0\n")
    assert cli(["sim", "--plan", str(plan), "--params", str(params), "--gains", "table4", "--seed", "7",
                "--log", str(log), "--json", str(out), "--no-plot"]) == 0
    assert "table4, full onboard path" in capsys.readouterr().err
    run = json.loads(out.read_text())["run"]
    assert run["params"] == {"file": str(params), "origin": f"file {params}",
                             "sha256_16": load(params, TABLE4).digest()}
    assert run["gains"]["set"] == "table4" and run["gains"]["kp_phi"] == TABLE4.kp_phi      # not the file's 5.0
    assert (run["estimator"], run["seed"], run["path"]) == ("flight", 7, "full onboard path")
    header = read_flight_log(log, extra=("true_z",)).meta["params"].splitlines()
    line = {h.split(" = ")[0]: h for h in header if " = " in h}
    assert line["kp_phi"] == (f"kp_phi = 17.1  # N/rad; paper, Table 4 (--gains table4, replacing the [gains] "
                              f"of file {params})")
    assert line["Jp"] == f"Jp = 0.0001  # kg m^2; file {params}: weighed and measured on the bench"
    assert line["M"].endswith("# kg; paper, Table 2")                    # not in the file: the schema's


def test_without_gains_the_files_own_fly_and_the_json_says_so(tmp_path, capsys):
    plan, params, out = tmp_path / "p.toml", tmp_path / "mine.toml", tmp_path / "m.json"
    plan.write_text(PLAN)
    params.write_text("[gains]\nkp_phi = 5.0\n")
    assert cli(["sim", "--plan", str(plan), "--params", str(params), "--log", str(tmp_path / "f.csv"),
                "--json", str(out), "--no-plot", "--quiet"]) == 0
    gains = json.loads(out.read_text())["run"]["gains"]
    assert gains["set"] == f"the [gains] of file {params}" and gains["kp_phi"] == 5.0
