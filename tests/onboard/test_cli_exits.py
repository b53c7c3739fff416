"""What a new user meets when a command is interrupted, piped, or given what it cannot do: real
`flightctl` processes, their exit codes and their stderr (one line, never a traceback), and what
they leave on disk (nothing half-written; a flight cut short is kept and says so)."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from flightctl.cli import main
from flightctl.errors import InputError
from flightctl.files import write_atomic
from flightctl.logfile import MAG_COLUMNS, read_flight_log
from flightctl.sim.world.board import TRUTH_COLUMNS
from helpers.paths import ROOT

# Real processes on a shared machine: run again, up to twice, when the machine stalls one.
pytestmark = pytest.mark.flaky(reruns=2)

FLIGHTCTL = [sys.executable, "-P", "-m", "flightctl.cli"]   # the installed package, never the source tree


def start(args, cwd, **kw) -> subprocess.Popen:
    """`flightctl ARGS` in its own process group, as a shell runs a job (Ctrl-C reaches the group)."""
    return subprocess.Popen(FLIGHTCTL + args, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True, **kw)


def ctrl_c(proc: subprocess.Popen, after: float, ready=lambda: True) -> tuple[int, str, float]:
    """Ctrl-C on the process group `after` s from now, or later once `ready()`, however long the
    command takes to get there on a busy machine: (exit code, stderr, seconds it took to stop)."""
    time.sleep(after)
    while not ready() and proc.poll() is None:
        time.sleep(0.2)
    assert proc.poll() is None, "the command ended before Ctrl-C: " + proc.communicate()[1]
    os.killpg(proc.pid, signal.SIGINT)
    t0 = time.monotonic()
    _, err = proc.communicate()
    return proc.returncode, err, time.monotonic() - t0


def group_gone(pgid: int, within: float = 5.0) -> bool:
    end = time.monotonic() + within
    while True:
        try:
            os.killpg(pgid, 0)
        except ProcessLookupError:
            return True
        if time.monotonic() > end:
            return False
        time.sleep(0.1)


def one_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert "Traceback" not in err and "Error:" not in err.replace("error:", ""), err
    return lines[-1]


def test_ctrl_c_in_a_flight_ends_it_at_once_and_keeps_the_log_marked_partial(tmp_path):
    """100 substeps: the flight runs slower than real time, long enough to be interrupted."""
    proc = start(["sim", "paper", "--log", "p.csv", "--json", "p.json", "--substeps", "100"], tmp_path)

    def flying() -> bool:                 # a few seconds of rows in the log's temporary file
        return any(p.stat().st_size > 200000 for p in tmp_path.glob(".p.csv.*.part"))
    rc, err, took = ctrl_c(proc, 1.0, ready=flying)
    assert rc == 130 and took < 10.0
    assert one_line(err).startswith("flightctl sim: interrupted at t = ")
    log = read_flight_log(tmp_path / "p.csv", extra=MAG_COLUMNS + TRUTH_COLUMNS)
    assert log.meta["partial"].startswith("stopped: interrupted (Ctrl-C) at t = ")
    assert log["t"][-1] < 80.0                                   # the paper flight is 86 s: cut short
    assert not (tmp_path / "p.json").exists() and not (tmp_path / "p.png").exists()
    assert group_gone(proc.pid)                                  # the log's writer process ended too
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p.csv"]   # no temporary file left


def test_ctrl_c_in_the_monte_carlo_ends_every_worker_at_once(tmp_path):
    proc = start(["sim", "paper", "--params", "paper-as-flown", "--monte-carlo", "40", "--json", "mc.json"], tmp_path)
    rc, err, took = ctrl_c(proc, 8.0)
    assert rc == 130 and took < 5.0, err
    assert one_line(err) == "flightctl sim: interrupted"
    assert group_gone(proc.pid)                                   # workers and their log writers
    assert not (tmp_path / "mc.json").exists()


def test_output_into_a_reader_that_stops_early_is_dropped_quietly(tmp_path):
    """`flightctl sim hover ... | head -1`: the flight is done, its output has nowhere to go."""
    proc = subprocess.Popen(FLIGHTCTL + ["sim", "step_roll", "--log", "s.csv", "--json", "s.json"], cwd=tmp_path,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    first = proc.stdout.readline()
    proc.stdout.close()                                           # what head does after its line
    err = proc.stderr.read().decode()
    assert proc.wait() == 0, err
    assert first.startswith(b"step_roll: landed upright") and "Traceback" not in err and "BrokenPipe" not in err
    assert json.loads((tmp_path / "s.json").read_text())["outcome"] == "landed upright"   # the work was finished


def test_two_runs_writing_one_log_leave_one_whole_log(tmp_path):
    runs = [start(["sim", "hover", "--log", "same.csv", "--no-plot", "--seed", str(k)], tmp_path) for k in (1, 2)]
    outs = [p.communicate() for p in runs]
    assert [p.returncode for p in runs] == [0, 0], outs
    log = read_flight_log(tmp_path / "same.csv", extra=MAG_COLUMNS + TRUTH_COLUMNS)
    rows = [int(o[0].split(" rows -> ")[0].rsplit(" ", 1)[1]) for o in outs]
    assert len(log) in rows and "partial" not in log.meta
    assert sorted(p.name for p in tmp_path.iterdir()) == ["same.csv"]


def on_a_full_disk(room: int, code: str, cwd: Path) -> subprocess.CompletedProcess:
    """Python `code` in a process whose files cannot grow past `room` bytes (RLIMIT_FSIZE): a write
    stops part way, then fails, as on a full card."""
    head = ("import resource, signal, sys\n"
            "signal.signal(signal.SIGXFSZ, signal.SIG_IGN)\n"
            f"resource.setrlimit(resource.RLIMIT_FSIZE, ({room}, {room}))\n")
    return subprocess.run([sys.executable, "-P", "-c", head + code], cwd=cwd, capture_output=True, text=True)


def test_a_full_disk_leaves_whole_rows_marked_partial(tmp_path):
    """The file size limit (RLIMIT_FSIZE) stands for a full card: a write stops part way."""
    r = on_a_full_disk(400000, "from flightctl.cli import main\n"
                               "sys.exit(main(['sim', 'hover', '--log', 'f.csv', '--no-plot', '--quiet']))\n", tmp_path)
    assert "Traceback" not in r.stderr, r.stderr
    assert r.returncode in (0, 1) and "log write failed" in r.stdout
    log = read_flight_log(tmp_path / "f.csv", extra=MAG_COLUMNS + TRUTH_COLUMNS)   # every row whole
    assert "partial" in log.meta and "after" in log.meta["partial"]
    assert (tmp_path / "f.csv").stat().st_size <= 400000


def test_an_output_that_cannot_be_written_whole_leaves_nothing(tmp_path):
    r = on_a_full_disk(50, "from flightctl.errors import InputError\nfrom flightctl.files import write_atomic\n"
                           "try:\n    write_atomic('s.json', 'x' * 100)\nexcept InputError as e:\n    print(e)\n", tmp_path)
    assert "s.json: cannot write" in r.stdout, r.stderr
    assert list(tmp_path.iterdir()) == []                          # neither the file nor its temporary name
    write_atomic(tmp_path / "s.json", "whole\n")
    assert (tmp_path / "s.json").read_text() == "whole\n" and oct((tmp_path / "s.json").stat().st_mode)[-3:] != "600"


@pytest.mark.parametrize("argv", [
    ["sim", "hover", "--log", "{tmp}/f.csv", "--seed", "-1"],
    ["sim", "faults", "--json", "{tmp}/f.json", "--seed", "-1"],
    ["bench", "--board", "sim", "--out", "{tmp}/b.csv", "--seed", "-1"],
    ["tune", "--out", "{tmp}/t.toml", "--seed", "-1"],
    ["hil", "demo", "--seed", "-1"],
    ["run", "--board", "sim", "--plan", "hover", "--log", "{tmp}/logs", "--seed", "-1"],
])
def test_a_negative_seed_is_one_line(tmp_path, capsys, argv):
    assert main([a.format(tmp=tmp_path) for a in argv]) == 2
    assert "--seed -1: a whole number from 0" in one_line(capsys.readouterr().err)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("argv, says", [
    (["bench", "--board", "sim", "--out", "{tmp}/nodir/b.csv"], "--out"),
    (["bench", "--board", "sim", "--out", "{tmp}/b.csv", "--raw", "{tmp}/nodir/r.csv"], "--raw"),
    (["bench", "--board", "sim", "--out", "{tmp}/b.csv", "--plot", "{tmp}/b.jpg"], "--plot"),
    (["hil", "demo", "--json", "{tmp}/nodir/d.json"], "--json"),
    (["hil", "serve", "--link", "tcp:0", "--json", "{tmp}/nodir/d.json"], "--json"),
    (["tune", "--out", "{tmp}/nodir/t.toml"], "--out"),
    (["sim", "faults", "--json", "{tmp}/nodir/f.json"], "--json"),
    (["identify", "pendulum", "{tmp}/none.csv", "--json", "{tmp}/nodir/o.json"], "--json"),   # before the input is read
])
def test_outputs_are_checked_before_any_work(tmp_path, capsys, argv, says):
    """Before a motor turns or a flight starts: nothing spun, nothing written (and before the heavy
    libraries load: tests/onboard/test_cli_light.py)."""
    assert main([a.format(tmp=tmp_path) for a in argv]) == 2
    assert says in one_line(capsys.readouterr().err)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("fault, says", [
    ("motor_stop:motr=2", "unknown key 'motr' for motor_stop (known: at, motor)"),
    ("motor_stop:at=1,at=2", "at given twice"),
    ("motor_stop:motor=2,motor=3", "motor given twice"),
    ("battery_critical:motor=2", "unknown key 'motor' for battery_critical"),
    ("cpu_stall:at=30", "hover's plan ends 24 s after arming: the fault would never be injected"),
])
def test_a_fault_that_would_not_be_what_was_asked_is_refused(tmp_path, capsys, fault, says):
    assert main(["sim", "hover", "--log", str(tmp_path / "f.csv"), "--fault", fault]) == 2
    assert says in one_line(capsys.readouterr().err)
    assert list(tmp_path.iterdir()) == []


def test_substeps_beyond_the_range_and_a_csv_as_parameters_are_refused(tmp_path, capsys):
    assert main(["sim", "hover", "--log", str(tmp_path / "f.csv"), "--substeps", "100000"]) == 2
    assert "--substeps 100000: 1 to 100" in one_line(capsys.readouterr().err)
    empty = tmp_path / "p.csv"
    empty.write_text("")
    assert main(["sim", "hover", "--log", str(tmp_path / "f.csv"), "--params", str(empty)]) == 2
    assert "a parameter file is TOML and named .toml" in one_line(capsys.readouterr().err)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p.csv"]


@pytest.mark.parametrize("cell, says", [("1_0", "'1_0' is not a number (digits, a point and an exponent only)"),
                                        (" 5 ", "' 5 ' is not a number (spaces around a number)")])
@pytest.mark.parametrize("kind, rows", [
    ("pendulum", ["axis,pivot_distance,period", "x,0.30,1.12", "y,0.31,{cell}", "z,0.29,1.2"]),
    ("bench", ["motor,P,thrust,omega,voltage,current", "1,{cell},1.0,400,16,2", "1,160,2.0,500,16,4",
               "1,170,3.0,600,16,6"]),
])
def test_cells_python_would_read_as_numbers_are_refused(tmp_path, capsys, kind, rows, cell, says):
    f = tmp_path / f"{kind}.csv"
    f.write_text("\n".join(rows).format(cell=cell) + "\n")
    assert main(["identify", kind, str(f), "--json", str(tmp_path / "o.json")]) == 2
    assert one_line(capsys.readouterr().err).endswith(says)
    assert not (tmp_path / "o.json").exists()


def test_the_top_level_help_names_every_command_and_log_import(capsys):
    assert main(["--help"]) == 0
    out = capsys.readouterr().out
    assert "log import FOREIGN_LOG OUT.csv" in out


def test_help_points_to_pages_a_user_has(capsys):
    """The help of every command names only files of the checkout a user has (docs/...), never the
    project's contract (measured-data.md) or a source file."""
    from flightctl.cli import COMMANDS
    pages = {p.name for p in (ROOT / "docs").glob("*.md")}
    for name in COMMANDS:
        for argv in ([name, "--help"],) + (([name, "faults", "--help"],) if name == "sim" else ()):
            with pytest.raises(SystemExit):
                main(argv)
            text = capsys.readouterr().out
            assert "measured-data.md" not in text and "faults.py" not in text, name
            for page in {w.strip("(),.;:`'") for w in text.split() if w.startswith("docs/")}:
                assert page.removeprefix("docs/") in pages, (name, page)
