"""`flightctl sim SCENARIO --monte-carlo N` (issue 17; sim/sweeps/montecarlo.py): the flight over the parameter
file's plausible ranges. Short flights (step_roll, 18 s) keep it quick; the paper flight is the same code."""
from __future__ import annotations

import json

from flightctl.cli import main
from flightctl.params import VEHICLES


def _narrow(tmp_path):
    """The as-flown file with each range shrunk to within 15 % of its value (tau 30-40 ms), where the
    paper's facts hold (docs/as-flown.md, tests/sim/flights/test_as_flown.py); a range around 0 stays 0."""
    text = (VEHICLES / "paper-as-flown.toml").read_text()
    lines = []
    values = {}
    for line in text.splitlines():
        key = line.split(" = ")[0]
        if line.startswith("[[effect]]"):
            values = {}
        elif " = " in line and not key.startswith(("range.", "cause", "source", "#")):
            values[key] = line.split(" = ")[1].split("#")[0].strip()
        if line.startswith("range."):
            value = float(values[key.removeprefix("range.")])
            line = f"{key} = [{0.85 * value!r}, {1.15 * value!r}]"
        lines.append(line)
    path = tmp_path / "narrow.toml"
    path.write_text("\n".join(lines) + "\n")
    return path


def test_draws_stay_in_their_ranges_and_the_shares_count_them(tmp_path):
    out = tmp_path / "mc.json"
    rc = main(["sim", "step_roll", "--params", str(_narrow(tmp_path)), "--monte-carlo", "3", "--seed", "5",
               "--json", str(out), "--plot", str(tmp_path / "mc.png"), "--quiet"])
    r = json.loads(out.read_text())
    assert rc == 0 and r["n"] == 3 and len(r["draws"]) == 3
    spans = {f"{s['cause']}.{s['parameter']}": (s["lo"], s["hi"]) for s in r["ranges"]}
    assert set(spans) == {"airframe.Jp", "airframe.h1", "airframe.h2", "airframe.c1", "airframe.g1", "airframe.g2",
                          "filters.tau_rate", "sensors.accel_vibration", "sensors.gyro_vibration", "sensors.harmonic2",
                          "sensors.harmonic3", "sensors.gyro_broadband", "rotor_inflow.k", "rotor_inflow.hub",
                          "motor_dynamics.tau", "rotor_drag.k", "rotor_drag.yaw",
                          "actuation_delay.delay"}
    for d in r["draws"]:
        for key, v in d["draw"].items():
            assert spans[key][0] <= v <= spans[key][1]
        for key in ("motor_dynamics.tau",):   # its top follows the drawn Jp (tau_down takes its value)
            lo, hi = spans[key]
            assert d["draw"][key] <= max(lo, hi * d["draw"]["airframe.Jp"] / spans["airframe.Jp"][1]) + 1e-12
    assert len({d["draw"]["motor_dynamics.tau"] for d in r["draws"]}) == 3     # drawn, not the nominal
    for g in ("table4", "table6"):
        for what in ("flies", "lands", "settles"):
            assert r["share"][g][what] == sum(d[g][what] for d in r["draws"]) / 3
    assert r["share"]["table6"]["lands"] == 1.0 and r["share"]["table6"]["settles"] == 1.0   # tau 30-40 ms
    assert (tmp_path / "mc.png").stat().st_size > 0


def test_a_file_without_ranges_is_one_line(tmp_path, capsys):
    assert main(["sim", "step_roll", "--monte-carlo", "2"]) == 2
    assert "carries no ranges" in capsys.readouterr().err


def test_batched_monte_carlo_flies_the_narrow_ranges_and_fails_the_slow_motors(tmp_path):
    """`--batch` (sim/sweeps/batch.py, each vehicle's simulated chip and sonar): within 15 % of the as-flown
    values every draw flies with Table 6, as on the full onboard path above (the 1-degree band of
    "settles" is the estimator's with the vehicle's gyro noise, docs/as-flown.md: a share, not a claim);
    with the motors' time constant moved to 150-192 ms (the slow end of its range), Table 4's bank
    loops ring or crash in most draws."""
    narrow = _narrow(tmp_path)
    out = tmp_path / "mc.json"
    rc = main(["sim", "step_roll", "--params", str(narrow), "--monte-carlo", "8", "--batch", "--json", str(out),
               "--plot", str(tmp_path / "mc.png"), "--quiet"])
    r = json.loads(out.read_text())
    assert rc == 0 and r["n"] == 8 and "batched simulator" in r["simulator"]
    assert r["share"]["table6"]["flies"] == 1.0
    for g in ("table4", "table6"):
        assert r["share"][g]["settles"] == sum(d[g]["settles"] for d in r["draws"]) / 8
    slow = tmp_path / "slow.toml"
    slow.write_text("\n".join(   # both ways: the rotors speed up and slow down in 150-192 ms
        line.split(" = ")[0] + " = [0.15, 0.192]" if line.startswith(("range.tau =", "range.tau_down ="))
        else line.split(" = ")[0] + " = 0.17" if line.startswith(("tau =", "tau_down =")) else line
        for line in narrow.read_text().splitlines()) + "\n")
    rc = main(["sim", "step_roll", "--params", str(slow), "--monte-carlo", "8", "--batch", "--json", str(out), "--quiet"])
    r = json.loads(out.read_text())
    assert r["share"]["table4"]["settles"] <= 0.25
    assert all(0.15 <= d["draw"]["motor_dynamics.tau"] <= 0.192 for d in r["draws"])


def test_batch_needs_monte_carlo(capsys):
    assert main(["sim", "step_roll", "--log", "x.csv", "--batch"]) == 2
    assert capsys.readouterr().err == "flightctl sim: error: --batch goes with --monte-carlo N\n"   # one line
