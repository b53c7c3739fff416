"""What a new user meets (issue 19), through the command line as a user runs it: every case here
was a traceback or a silently wrong figure. Each is now one line and the right exit code, with what
was computed kept."""
from __future__ import annotations

import json

import pytest

from flightctl.cli import main
from flightctl.params import load
from flightctl.sim import causes


def _err(capsys) -> str:
    lines = capsys.readouterr().err.strip().splitlines()
    assert lines and "Traceback" not in "\n".join(lines)
    return lines[-1]


@pytest.mark.parametrize("fault", ["sonar_silent", "sonar_stuck", "battery_critical", "log_full", "motor_stop"])
def test_a_hover_cut_short_by_a_fault_still_writes_its_metrics_and_figure(tmp_path, capsys, fault):
    """hold_metrics raised on a zero-size window: the hover's last 10 s were never flown."""
    log, out, png = tmp_path / "f.csv", tmp_path / "m.json", tmp_path / "f.png"
    rc = main(["sim", "hover", "--log", str(log), "--fault", f"{fault}:at=3", "--json", str(out),
               "--plot", str(png), "--quiet"])
    report = json.loads(out.read_text())
    assert rc == (1 if report["crashed"] or not report["flew"] else 0)
    assert png.stat().st_size > 0
    if report["flown_s"] < 24.0 and report["flew"]:              # the plan's hover ends at 24 s
        assert report["hold_last_10s"] is None
        assert report["crashed"] or "cut short" in capsys.readouterr().out


@pytest.mark.parametrize("flag", ["--log", "--json", "--plot"])
def test_sim_outputs_that_cannot_be_written_are_refused_before_flying(tmp_path, capsys, flag):
    args = {"--log": str(tmp_path / "f.csv"), "--json": None, "--plot": None}
    args[flag] = str(tmp_path) if flag != "--plot" else str(tmp_path / "missing" / "p.png")
    argv = ["sim", "hover"] + [x for k, v in args.items() if v for x in (k, v)]
    assert main(argv) == 2
    assert flag in _err(capsys)
    assert not (tmp_path / "f.csv").exists()


def test_analyze_json_into_a_directory_is_one_line(tmp_path, capsys):
    assert main(["analyze", "--json", str(tmp_path)]) == 2
    assert "is a directory" in _err(capsys)


def test_a_plant_that_diverges_stops_with_its_reason_and_keeps_the_log(tmp_path, capsys):
    """Jzz = 1e-6 kg m^2 is inside the schema; the yaw axis then diverges (math domain error)."""
    params = tmp_path / "p.toml"
    params.write_text("Jzz = 1e-6\n")
    log = tmp_path / "f.csv"
    assert main(["sim", "hover", "--params", str(params), "--log", str(log), "--no-plot", "--quiet"]) == 1
    out = capsys.readouterr()
    assert "diverged" in out.out and "Traceback" not in out.err
    assert log.stat().st_size > 0


def test_an_unknown_effect_in_a_parameter_file_names_the_file(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text('[[effect]]\ncause = "nope"\nk = 1\n')
    for argv in (["sim", "hover", "--params", str(bad), "--log", str(tmp_path / "f.csv")],
                 ["params", "show", str(bad)], ["analyze", "--params", str(bad)]):
        assert main(argv) == 2
        line = _err(capsys)
        assert str(bad) in line and "[[effect]] 1" in line and "nope" in line
    assert not (tmp_path / "f.csv").exists()


def test_params_show_of_an_unknown_name_lists_the_shipped_vehicles(capsys):
    assert main(["params", "show", "M"]) == 2
    assert "paper-as-flown" in _err(capsys)


def test_an_effect_of_a_carried_cause_replaces_it(tmp_path, capsys):
    """Issue 17: `--effect motor_dynamics:tau=...` on paper-as-flown added a second motor_dynamics;
    both added reaction torque. Now one, the given one, and the command says so."""
    params = load("paper-as-flown")
    carried = {e.cause for e in params.effects}
    assert "motor_dynamics" in carried
    given = causes.parse("motor_dynamics:tau=0.045")
    plant = causes.combined(params, (given,))
    assert [e for e in plant if e.cause == "motor_dynamics"] == [given]
    assert {e.cause for e in plant} == carried
    log = tmp_path / "f.csv"
    main(["sim", "step_yaw", "--params", "paper-as-flown", "--effect", "motor_dynamics:tau=0.045",
          "--log", str(log), "--no-plot"])
    assert "--effect motor_dynamics replaces the one the parameter file carries" in capsys.readouterr().err
