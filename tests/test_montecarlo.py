"""`flightctl sim SCENARIO --monte-carlo N` (issue 17; sim/montecarlo.py): the flight over the parameter
file's plausible ranges. Short flights (step_roll, 18 s) keep it quick; the paper flight is the same code."""
from __future__ import annotations

import json

from flightctl.cli import main
from flightctl.params import VEHICLES


def _narrow(tmp_path):
    """The as-flown file with each range shrunk to within 15 % of its value (tau 30-40 ms), where the
    paper's facts hold (docs/as-flown.md, tests/test_as_flown.py)."""
    text = (VEHICLES / "paper-as-flown.toml").read_text()
    lines = []
    value = None
    for line in text.splitlines():
        if line.split(" = ")[0] in ("k", "tau"):
            value = float(line.split(" = ")[1])
        if line.startswith("range."):
            name = line.split(" = ")[0]
            line = f"{name} = [{0.85 * value!r}, {1.15 * value!r}]"
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
    assert set(spans) == {"rotor_inflow.k", "motor_dynamics.tau", "rotor_drag.k"}
    for d in r["draws"]:
        for key, v in d["draw"].items():
            assert spans[key][0] <= v <= spans[key][1]
    assert len({d["draw"]["motor_dynamics.tau"] for d in r["draws"]}) == 3     # drawn, not the nominal
    for g in ("table4", "table6"):
        for what in ("flies", "lands", "settles"):
            assert r["share"][g][what] == sum(d[g][what] for d in r["draws"]) / 3
    assert r["share"]["table6"]["lands"] == 1.0 and r["share"]["table6"]["settles"] == 1.0   # tau 30-40 ms
    assert (tmp_path / "mc.png").stat().st_size > 0


def test_a_file_without_ranges_is_one_line(tmp_path, capsys):
    assert main(["sim", "step_roll", "--monte-carlo", "2"]) == 2
    assert "carries no ranges" in capsys.readouterr().err
