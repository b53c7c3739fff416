"""`flightctl bench`: the four motors in turn on the simulated stand with the simulated instruments on a
pty (read through pyserial), one bench.csv that identify fits, the step profile's time constant, and
the safety stops: each leaves the motor at the stop pulse and keeps the rows so far."""
from __future__ import annotations

import json
import os
import random
import signal
import tomllib

import pytest

from flightctl.cli import main as cli
from flightctl.errors import InputError
from flightctl.logfile import BENCH_COLUMNS, read_table
from flightctl.params import load
from flightctl.hil import bench
from flightctl.hil.bench import RAW_COLUMNS, counts_for
from helpers.without import PI_LIBRARIES, run_without

FAST = ["--ramp", "400", "--settle", "0.3", "--hold", "0.3", "--no-plot"]


def test_sim_bench_through_the_pty_instruments_feeds_identify(tmp_path):
    """The issue's end-to-end chain: simulated motors, instruments on a pty through pyserial, bench.csv,
    `flightctl identify bench` recovers the simulated propeller within 3 %."""
    out = tmp_path / "bench.csv"
    assert cli(["bench", "--board", "sim", "--instruments", "pty", "--steps", "130,145,160,175,190",
                "--out", str(out), *FAST[:-1]]) == 0
    table = read_table(out, BENCH_COLUMNS)
    assert sorted(set(table["motor"])) == [1, 2, 3, 4] and len(table) == 20
    assert all(15.0 < v < 16.8 for v in table["voltage"])          # the onboard INA219 (simulated chip)
    raw = read_table(tmp_path / "bench-raw.csv", RAW_COLUMNS, text_columns=("phase",))
    assert len(raw) > 20 * 0.3 * 150 and (raw["t"][1:] >= raw["t"][:-1]).all()   # 200 lines/s, in time order
    assert {"ramp", "settle", "hold", "tare"} <= set(raw["phase"])
    assert (tmp_path / "bench.png").stat().st_size > 10_000
    report = tmp_path / "id.json"
    assert cli(["identify", "bench", str(out), "--json", str(report)]) == 0
    found, a = json.loads(report.read_text()), load(None).airframe
    for name in ("h1", "h2", "c1"):
        assert found[name]["value"] == pytest.approx(getattr(a, name), rel=0.03), name
    # the rows are the instruments' averages, not copies of the truth: eq. 26 within the noise
    for P, f in zip(table["P"], table["thrust"]):
        assert f == pytest.approx(a.h1 * (P - a.h2) ** 2, rel=0.02, abs=0.02)


def test_step_profile_refuses_a_motor_without_lag_instead_of_fitting_the_noise(tmp_path, capsys):
    """Issue 19: on the base model (no motor lag) the speed is at its new value at the first sample;
    the fit gave 123 ms from the noise. Now: no tau, a stop that says why, the rows kept, nothing written."""
    out, params = tmp_path / "step.csv", tmp_path / "fitted.toml"
    assert bench.main(["--board", "sim", "--profile", "step", "--motors", "1", "--step", "140,180",
                       "--record", "0.4", "--out", str(out), "--write-params", str(params), *FAST]) == 1
    err = capsys.readouterr().err
    assert "faster than this tachometer resolves" in err and "tau " not in err.split("stopped:")[0]
    assert not params.exists()
    assert list(read_table(out, BENCH_COLUMNS)["P"]) == [140, 180]


def test_step_profile_fits_the_motor_time_constant_and_writes_it(tmp_path):
    out, params = tmp_path / "step.csv", tmp_path / "fitted.toml"
    assert bench.main(["--board", "sim", "--params", "paper-as-flown", "--profile", "step", "--motors", "1,4",
                       "--step", "140,180", "--record", "0.4", "--out", str(out), "--write-params", str(params),
                       *FAST]) == 0
    true_tau = dict(load("paper-as-flown").effects[1].parameters)["tau"]
    written = load(params)
    dyn = [e for e in written.effects if e.cause == "motor_dynamics"]
    assert len(dyn) == 1 and dict(dyn[0].parameters)["tau"] == pytest.approx(true_tau, rel=0.1)
    assert "step profile" in dyn[0].source
    assert {e.cause for e in written.effects} == {e.cause for e in load("paper-as-flown").effects}
    assert "gains" not in tomllib.loads(params.read_text())       # a vehicle file leaves [gains] to --gains
    table = read_table(out, BENCH_COLUMNS)
    assert list(table["motor"]) == [1, 1, 4, 4] and list(table["P"]) == [140, 180, 140, 180]


def test_bench_keeps_the_other_motors_stopped_and_ramps(monkeypatch, tmp_path):
    writes = []
    real_open = bench.open_bench

    def recording_open(args, params):
        rig = real_open(args, params)
        real_write = rig.board.hal.motors.write
        rig.board.hal.motors.write = lambda c: (writes.append(list(c)), real_write(c))
        return rig

    monkeypatch.setattr(bench, "open_bench", recording_open)
    assert bench.main(["--board", "sim", "--motor", "2", "--steps", "180", "--ramp", "100", "--settle", "0.1",
                       "--hold", "0.1", "--no-plot", "--out", str(tmp_path / "b.csv")]) == 0
    assert all(c[0] == c[2] == c[3] == 0 for c in writes)
    motor2 = [c[1] for c in writes]
    steps = [b - a for a, b in zip(motor2, motor2[1:])]
    max_step = 100 / 450 / 255 * 40000 + 1                                   # 100 P/s at 450 Hz, in counts
    assert max(abs(s) for s in steps) <= max_step
    assert max(motor2) == round(180 / 255 * 40000) and motor2[-1] == 0        # ramped down at the end


def test_steps_above_the_maximum_or_a_bad_motor_are_refused(tmp_path, capsys):
    assert cli(["bench", "--board", "sim", "--motor", "1", "--steps", "150,230", "--out", str(tmp_path / "b.csv")]) == 2
    assert "exceeds --max 200" in capsys.readouterr().err
    assert cli(["bench", "--board", "sim", "--motor", "5", "--steps", "150"]) == 2
    assert cli(["bench", "--board", "sim", "--instruments", "morse:/dev/x", "--out", str(tmp_path / "b.csv")]) == 2
    assert cli(["bench", "--board", "sim", "--instruments", "serial:/dev/null", "--out", str(tmp_path / "b.csv")]) == 2
    assert not (tmp_path / "b.csv").exists()
    with pytest.raises(InputError):
        bench.parse_steps("150,abc", 200)


def _run_with(monkeypatch, tmp_path, argv, on_write):
    """bench.main on the simulated stand; `on_write(counts, rig)` sees every motor write (and may
    return the counts the ESCs get instead: a faulty ESC)."""
    state = {}
    real_open = bench.open_bench

    def hooked_open(args, params):
        rig = real_open(args, params)
        motors = state["motors"] = rig.board.hal.motors
        real_write = motors.write

        def write(c):
            real_write(on_write(c, rig) or c)         # what on_write returns goes out instead
        motors.write = write
        return rig

    monkeypatch.setattr(bench, "open_bench", hooked_open)
    out = tmp_path / "b.csv"
    status = bench.main(["--board", "sim", "--motors", "1", "--steps", "130,145,160,175,190", *FAST, "--out", str(out),
                         *argv])
    motors = state["motors"]
    assert motors.counts == [0, 0, 0, 0] and not motors.armed                # the stop pulse, whatever happened
    return status, read_table(out, BENCH_COLUMNS, min_rows=0)


@pytest.mark.parametrize("fault, argv, expected, rows", [
    ("silent", [], "went silent", [130, 145]),
    (None, ["--max-rpm", "5000"], "beyond the propeller's limit", [130, 145, 160]),   # 553 rad/s at P = 175
    ("slipping", [], "thrust fell", [130, 145, 160]),
])
def test_a_fault_or_an_implausible_reading_stops_the_spinning_motor(monkeypatch, tmp_path, capsys, fault, argv,
                                                                    expected, rows):
    seen = []

    def on_write(c, rig):
        seen.append(c[0])
        if c[0] >= counts_for(158):                     # during the third step
            if fault == "slipping":
                rig.sim.thrust_gain = 0.3                 # the load cell slips in its mount
            elif fault:
                rig.sim.fault = fault

    status, table = _run_with(monkeypatch, tmp_path, argv, on_write)
    assert status == 1
    assert max(seen) >= counts_for(158)                 # it was spinning when it stopped
    err = capsys.readouterr().err
    assert expected in err and "motor 1 at the stop pulse" in err
    assert list(table["P"]) == rows


@pytest.mark.parametrize("how", ["ctrl-c", "sigterm"])
def test_ctrl_c_or_sigterm_stops_the_motor_and_keeps_the_rows_so_far(monkeypatch, tmp_path, how):
    def on_write(c, rig):
        if c[0] >= counts_for(140):
            if how == "ctrl-c":
                raise KeyboardInterrupt
            os.kill(os.getpid(), signal.SIGTERM)

    previous = signal.getsignal(signal.SIGTERM)
    status, table = _run_with(monkeypatch, tmp_path, [], on_write)
    assert status == 130 and list(table["P"]) == [130]
    assert signal.getsignal(signal.SIGTERM) == previous


def test_a_step_that_does_not_settle_in_time_stops(monkeypatch, tmp_path, capsys):
    """An ESC whose output creeps (its speed never steady): the holds go on until --step-timeout, no
    longer. The creep's rate is drawn, the bench is not told it."""
    rate = random.Random(49).uniform(15.0, 25.0)       # P/s of creep: halves of a hold differ beyond 1 %
    start = {}

    def creep(c, rig):
        t = rig.board.hal.clock.now()
        start.setdefault("t", t)
        return [c[0] + counts_for(rate * (t - start["t"])), *c[1:]] if c[0] else None   # stopped: stopped
    status, table = _run_with(monkeypatch, tmp_path, ["--step-timeout", "1.5"], creep)
    assert status == 1 and len(table) == 0
    assert "did not settle within --step-timeout 1.5 s" in capsys.readouterr().err
    raw = read_table(tmp_path / "b-raw.csv", ("t",), text_columns=("phase",), min_rows=1)
    assert raw["t"][-1] - start["t"] <= 1.5


def test_the_step_timeout_covers_the_ramp_of_a_late_loop(monkeypatch, tmp_path, capsys):
    """A loaded board's late loop periods (each a drawn number of periods long) stretch the ramp:
    the step timeout stops the motor in its ramp, not only after the settle and a hold."""
    rng = random.Random(7)

    def late(c, rig):
        clock = rig.board.hal.clock
        if not hasattr(clock, "late"):
            on_time = clock.wait_next

            def wait_next():
                for _ in range(rng.randint(1, 3)):          # 1 to 3 periods for each one the bench asks for
                    t = on_time()
                return t
            clock.late = clock.wait_next = wait_next
    status, table = _run_with(monkeypatch, tmp_path, ["--steps", "190", "--ramp", "50", "--settle", "0.2",
                                                      "--hold", "0.2", "--step-timeout", "4.5"], late)
    assert status == 1 and len(table) == 0                # 3.8 s of ramp on time, about 7.6 s late
    assert "the step took longer than --step-timeout 4.5 s (in its ramp)" in capsys.readouterr().err


@pytest.mark.parametrize("flag, value, says", [
    ("--settle", "1e300", "--settle 1e+300: from 0 to 60 s"),
    ("--hold", "1e300", "--hold 1e+300: above 0 to 60 s"),
    ("--hold", "nan", "--hold nan: above 0 to 60 s"),
    ("--record", "inf", "--record inf: above 0 to 10 s"),
    ("--step-timeout", "-1", "--step-timeout -1: above 0 to 300 s"),
    ("--silent", "nan", "--silent nan: above 0 to 10 s"),
    ("--ramp", "0.001", "--ramp 0.001: from 1 to 500 P/s"),
    ("--max", "nan", "--max nan: above 0 to 255"),
    ("--max-rpm", "nan", "--max-rpm nan: a speed above 0 is needed"),
    ("--max-rpm", "1e9", "--max-rpm 1e+09: above the propeller's own limit"),
    ("--settle", "40", "--step-timeout 30: shorter than one step (190 / --ramp 50 + --settle 40 + --hold 2"),
])
def test_every_time_and_rate_is_bounded_before_a_motor_turns(tmp_path, capsys, flag, value, says):
    out = tmp_path / "b.csv"
    assert cli(["bench", "--board", "sim", "--motors", "1", "--steps", "130,190", "--out", str(out), flag, value]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and says in err, err
    assert list(tmp_path.iterdir()) == []


def test_an_unknown_board_or_a_pi_board_that_is_not_there_is_one_line(tmp_path, capsys):
    assert cli(["bench", "--board", "bench9", "--motor", "1", "--steps", "150"]) == 2
    assert capsys.readouterr().err.strip() == "flightctl bench: error: unknown board 'bench9' (known: pi, pi5, auto, sim, hil)"
    board = tmp_path / "board.toml"
    board.write_text("[pigpio]\nport = 1\n")              # nothing listens on port 1
    out = tmp_path / "b.csv"
    assert cli(["bench", "--board", "pi", "--board-file", str(board), "--motor", "1", "--steps", "150",
                "--out", str(out)]) == 3
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("flightctl bench: cannot open the pi board: cannot reach pigpiod")
    assert not out.exists()


def test_the_pi_bench_on_a_machine_without_the_pi_libraries_is_one_line(tmp_path):
    r = run_without(PI_LIBRARIES, ["bench", "--board", "pi", "--motor", "1", "--steps", "150"], tmp_path)
    assert r.returncode == 3
    assert r.stderr.strip().splitlines() == [
        "flightctl bench: cannot open the pi board: the pi board needs the Python module 'pigpio', which is not "
        "installed (install the Pi libraries with pip install '.[pi]' in the flightctl checkout)"]
    assert not (tmp_path / "bench.csv").exists()
