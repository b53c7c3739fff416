"""What a new user reads first: `--version`, the top-level help (its exit codes, the foreign logs
`log import` reads), an error naming the subcommand it came from, a bad `--mavlink` URL refused before
anything flies, and the real-time factor of `flightctl sim` with its figures (issue 39)."""
from __future__ import annotations

import re

import pytest

from flightctl import __version__, cli
from flightctl.sim.cli import speed


def test_version_names_the_package_python_and_the_simulator(capsys):
    assert cli.main(["--version"]) == 0
    out = capsys.readouterr().out.strip()
    assert out.startswith(f"flightctl {__version__} (Python ")
    assert re.search(r"the (compiled|plain-Python) simulator", out), out


def test_top_level_help_gives_the_exit_codes_and_every_foreign_log(capsys):
    assert cli.main(["--help"]) == 0
    out = capsys.readouterr().out
    codes = out.split("exit codes:", 1)[1]
    assert [int(m) for m in re.findall(r"^\s+(\d+)\s", codes, re.M)] == [0, 1, 2, 3, cli.EXIT_INTERRUPTED]
    log = next(line for line in out.splitlines() if line.strip().startswith("log "))
    assert all(name in log for name in ("PX4", "ArduPilot", "Betaflight", "INAV")), log


@pytest.mark.parametrize("argv, name", [
    (["hil", "demo", "--seconds", "-1"], "flightctl hil demo"),
    (["params", "show", "no-such-vehicle"], "flightctl params show"),
    (["params", "diff", "no-such-a", "no-such-b"], "flightctl params diff"),
    (["identify", "bench", "no-such.csv", "--json", "out.json"], "flightctl identify bench"),
    (["hil", "frobnicate"], "flightctl hil"),                 # not a subcommand: the command's own name
])
def test_an_error_carries_its_own_commands_name(tmp_path, monkeypatch, capsys, argv, name):
    monkeypatch.chdir(tmp_path)
    assert cli.main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"{name}: error: "), err


def test_a_bad_mavlink_url_is_one_line_before_anything_flies(tmp_path, capsys):
    pytest.importorskip("pymavlink")
    assert cli.main(["sim", "hover", "--log", str(tmp_path / "h.csv"), "--mavlink", "bogus:xyz"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("flightctl sim: error: --mavlink bogus:xyz: cannot open"), err
    assert "udpout:HOST:PORT" in err[0]
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("ratio, shown", [(8.0 / 24.5, "0.33x"), (0.55, "0.55x"), (1.0, "1.0x"), (8.26, "8.3x"),
                                          (70.8, "71x")])
def test_the_real_time_factor_keeps_two_figures_below_ten(ratio, shown):
    assert speed(ratio) == shown


@pytest.mark.parametrize("argv", [["sim", "paper", "--monte-carlo", "abc"], ["sim", "faults", "--frob"],
                                  ["analyze", "--alt", "abc"], ["tune", "--robust", "abc", "--out", "g.toml"],
                                  ["bench", "--frob"], ["identify", "bench"], ["params", "frob"],
                                  ["hil", "demo", "--seconds", "abc"]])
def test_argparse_errors_are_one_line_not_a_usage_block(tmp_path, monkeypatch, capsys, argv):
    monkeypatch.chdir(tmp_path)
    assert cli.main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"flightctl {argv[0]}"), err
