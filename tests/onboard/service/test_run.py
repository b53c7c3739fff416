"""`flightctl run`: the service path on the simulator in real time, in a subprocess, with a local
socket standing for systemd's NOTIFY_SOCKET; SIGTERM mid-flight; the plan queue that a restart cannot
re-fly; pre-arm refusal; plan files; the ExecStopPost `--stop-motors` against the fake pigpiod."""
from __future__ import annotations

import json
import logging
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from helpers.fakes.pigpiod import running
from flightctl.cli import main as cli
from flightctl.drivers.esc import PigpioEsc
from flightctl.errors import InputError
from flightctl.logfile import MAG_COLUMNS, read_flight_log
from flightctl.plans import load_plan
from flightctl.service.run import TeardownLog, main
from flightctl.sim.world.board import TRUTH_COLUMNS
from helpers.without import PI_LIBRARIES, run_without

# Real time on a shared machine: a test that measures wall-clock timing (frame rates, durations, pacing)
# is run again, up to twice, when the machine stalls it; what it asserts is unchanged.
pytestmark = pytest.mark.flaky(reruns=2)




class Service:
    """`flightctl run ...` in a subprocess, its notify datagrams collected."""

    def __init__(self, tmp_path: Path, *args: str):
        self.sock_path = str(tmp_path / f"notify-{time.monotonic_ns()}.sock")
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        self.sock.bind(self.sock_path)
        self.messages: list[str] = []
        env = dict(os.environ, NOTIFY_SOCKET=self.sock_path)   # the installed package, never the source tree
        self.proc = subprocess.Popen([sys.executable, "-P", "-m", "flightctl.cli", "run", *args], cwd=tmp_path, env=env,
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)

    def wait_for(self, message: str, timeout: float) -> bool:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if any(message in m for m in self.messages):
                return True
            self.sock.settimeout(0.1)
            try:
                self.messages.append(self.sock.recv(4096).decode())
            except socket.timeout:
                if self.proc.poll() is not None and not self._drain():
                    return any(message in m for m in self.messages)
        return False

    def _drain(self) -> bool:
        self.sock.settimeout(0.01)
        try:
            self.messages.append(self.sock.recv(4096).decode())
            return True
        except socket.timeout:
            return False

    def stop(self, timeout: float = 15.0) -> tuple[int, str]:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
        try:
            _, err = self.proc.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            _, err = self.proc.communicate()
        while self._drain():
            pass
        self.sock.close()
        return self.proc.returncode, err


def test_sigterm_in_flight_writes_zero_thrust_and_exits_0(tmp_path):
    svc = Service(tmp_path, "--board", "sim", "--plan", "hover", "--log", "logs", "--calibrate", "0.5")
    try:
        assert svc.wait_for("READY=1", 30), svc.stop()[1]
        ready = time.monotonic()
        time.sleep(3.0)                          # 0.5 s calibrating, then 2.5 s of take-off in real time
    finally:
        wall = time.monotonic() - ready
        rc, err = svc.stop()
    assert rc == 0, err
    assert "SIGTERM" in err
    assert any("WATCHDOG=1" in m for m in svc.messages) and any("STOPPING=1" in m for m in svc.messages)
    logs = sorted((tmp_path / "logs").glob("flight-*-hover.csv"))
    assert len(logs) == 1
    log = read_flight_log(logs[0], extra=MAG_COLUMNS + TRUTH_COLUMNS)
    P = [log[c] for c in ("P1", "P2", "P3", "P4")]
    assert [p[-1] for p in P] == [0.0, 0.0, 0.0, 0.0]          # the last motor command: zero
    assert min(p[-2] for p in P) > 100                          # ... sent while flying
    assert log["true_z"][-1] > 0.05                             # in the air when SIGTERM came
    summary = json.loads(logs[0].with_name(logs[0].stem + "-summary.json").read_text())
    # Paced by the wall clock: never ahead of it; on a loaded machine the periods it could not keep are
    # skipped (the world waits), and counted: flown plus skipped periods span the wall time since READY.
    period = 1.0 / 450.0
    assert log["t"][-1] - log["t"][0] <= wall + 0.1
    paced = (summary["iterations"] + summary["skipped_periods"]) * period
    assert wall - 0.5 < paced <= wall + 0.1, (paced, wall, summary)
    assert summary["reason"] == "stopped: stop requested"


def test_a_queued_plan_is_flown_once_and_a_restart_does_not_re_arm(tmp_path):
    queue, logs = tmp_path / "plans", tmp_path / "logs"
    queue.mkdir()
    svc = Service(tmp_path, "--board", "sim", "--plan-queue", str(queue), "--log", str(logs), "--calibrate", "0.2")
    try:
        assert svc.wait_for("READY=1", 30), svc.stop()[1]
        (queue / "hop.toml").write_text('name = "hop"\nduration = 1.5\n'
                                        '[[move]]\nt = 0.0\nchannel = "alt"\nvalue = 0.3\nramp = 0.5\n'
                                        '[[move]]\nt = 0.7\nchannel = "alt"\nvalue = 0.0\nramp = 0.5\n')
        assert svc.wait_for("disarmed after hop", 45), svc.messages   # real time: calibrate, fly, land
    finally:
        rc, err = svc.stop()
    assert rc == 0, err
    assert list(queue.iterdir()) == []                            # claimed: gone from the queue
    assert len(list(logs.glob("plan-*-hop.toml"))) == 1          # ... kept beside its log
    assert len(list(logs.glob("flight-*-hop.csv"))) == 1
    # the service restarts (crash, watchdog, reboot): the queue is empty, it stays disarmed
    again = Service(tmp_path, "--board", "sim", "--plan-queue", str(queue), "--log", str(logs), "--calibrate", "0.2")
    try:
        assert again.wait_for("READY=1", 30)
        time.sleep(1.0)
    finally:
        rc, err = again.stop()
    assert rc == 0, err
    assert len(list(logs.glob("flight-*.csv"))) == 1             # no second flight


def test_prearm_refusal_exits_3_naming_the_reason(tmp_path):
    """The highest threshold run takes (a full 4S pack, 16.8 V) is above the simulated pack's 16.3 V."""
    svc = Service(tmp_path, "--board", "sim", "--plan", "hover", "--log", "logs", "--min-battery-v", "16.8")
    svc.proc.wait(timeout=30)
    rc, err = svc.stop()
    assert rc == 3
    assert "not flying: battery" in err and "below 16.80 V" in err
    assert not any("READY=1" in m for m in svc.messages)
    assert not (tmp_path / "logs").exists()


def test_plan_files_are_checked(tmp_path):
    good = tmp_path / "good.toml"
    good.write_text('duration = 10\n[[move]]\nt = 0\nchannel = "alt"\nvalue = 1.0\nramp = 2\n'
                    '[[move]]\nt = 3\nchannel = "roll"\nvalue_deg = 5\n[[move]]\nt = 6\nchannel = "alt"\nvalue = 0\n')
    plan = load_plan(str(good))
    assert plan.name == "good" and plan.duration == 10 and plan.lands()
    assert plan.moves[1].value == pytest.approx(0.0872665, rel=1e-5)       # degrees at the edge, rad inside
    assert load_plan("hover").name == "hover"
    for text, message in [('duration = 5\nspeed = 3\n', "unknown key 'speed'"),
                          ('[[move]]\nt = 0\nchannel = "alt"\nvalue = 1\n', "duration"),
                          ('duration = 5\n[[move]]\nt = 0\nchannel = "alt"\nvalue = 9\n', "outside"),
                          ('duration = 5\n[[move]]\nt = 0\nchannel = "roll"\nvalue_deg = 45\n', "beyond"),
                          ('duration = 5\n[[move]]\nt = 0\nchannel = "up"\nvalue = 1\n', "channel")]:
        bad = tmp_path / "bad.toml"
        bad.write_text(text)
        with pytest.raises(InputError, match=message):
            load_plan(str(bad))
    with pytest.raises(InputError, match="neither a plan file nor a named plan"):
        load_plan("no-such-plan")


def test_teardown_row_records_the_stop_command(tmp_path):
    path = tmp_path / "f.csv"
    log = TeardownLog(path, {"k": "v"}, MAG_COLUMNS, period=0.01)
    row = (0.5, 170.0, 171.0, 170.0, 171.0, 0.1, 0.2, 0.3, 0.0, 0.0, 9.8, "1.0000", 16.0,
           0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0)
    log.append(row)
    log.close()
    table = read_flight_log(path, min_rows=2)
    assert list(table["t"]) == [0.5, 0.51]
    assert [table[c][-1] for c in ("P1", "P2", "P3", "P4")] == [0, 0, 0, 0]
    assert table["gyro_z"][-1] == pytest.approx(0.3)


def test_stop_motors_puts_the_stop_pulse_on_whatever_a_dead_controller_left(tmp_path):
    with running() as (fake, pi):
        dead = PigpioEsc(pi, (17, 27, 22, 25), deadman_ms=10_000)
        dead.arm()
        dead.write([38000] * 4)
        board = tmp_path / "board.toml"
        board.write_text(f'[pigpio]\nhost = "127.0.0.1"\nport = {fake.port}\n')
        assert main(["--board", "pi", "--board-file", str(board), "--stop-motors"]) == 0
        assert fake.live_wave().on_times() == {17: 1000, 27: 1000, 22: 1000, 25: 1000}
        assert fake.scripts == {}


def board_without_pigpiod(tmp_path) -> Path:
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()                                   # nothing listens there
    board = tmp_path / "board.toml"
    board.write_text(f"[pigpio]\nport = {port}\n")
    return board


def test_stop_motors_without_pigpiod_fails_loudly(tmp_path):
    board = board_without_pigpiod(tmp_path)
    assert main(["--board", "pi", "--board-file", str(board), "--stop-motors"]) == 1


def test_stop_motors_on_the_simulator_has_nothing_to_do(caplog):
    caplog.set_level(logging.INFO, logger="flightctl.run")
    assert main(["--board", "sim", "--stop-motors"]) == 0
    assert "nothing to do on the sim board" in caplog.text


def test_the_pi_board_without_pigpiod_exits_3_with_one_line(tmp_path, caplog):
    board = board_without_pigpiod(tmp_path)
    assert main(["--board", "pi", "--board-file", str(board), "--plan", "hover", "--log", str(tmp_path)]) == 3
    errors = [r.getMessage() for r in caplog.records if r.levelname == "ERROR"]
    assert len(errors) == 1 and errors[0].startswith("not flying: cannot reach pigpiod")
    assert not list(tmp_path.glob("flight-*"))


def test_an_unknown_board_or_a_bad_board_file_is_one_line(tmp_path, capsys):
    assert cli(["run", "--board", "hil9", "--plan", "hover"]) == 2
    assert capsys.readouterr().err.strip().splitlines() == [
        "flightctl run: error: unknown board 'hil9' (known: pi, pi5, auto, sim, hil)"]
    board = tmp_path / "board.toml"
    board.write_text("[esc]\ndeadman_ms = 5000\n")
    assert cli(["run", "--board", "pi", "--board-file", str(board), "--plan", "hover", "--log", str(tmp_path)]) == 2
    assert capsys.readouterr().err.strip().splitlines() == [
        f"flightctl run: error: {board}: esc.deadman_ms: 5000 ms is out of range [20, 1000]"]


def test_the_pi_board_on_a_machine_without_the_pi_libraries_is_one_line(tmp_path):
    r = run_without(PI_LIBRARIES, ["run", "--board", "pi", "--plan", "hover", "--log", "logs"], tmp_path)
    assert r.returncode == 3, r.stderr
    assert r.stderr.strip().splitlines() == [
        "flightctl run: not flying: the pi board needs the Python module 'pigpio', which is not installed "
        "(install the Pi libraries with pip install '.[pi]' in the flightctl checkout)"]
