"""MAVLink with pymavlink as the ground station on loopback UDP: the stream of `flightctl sim` (types,
rates, the frame change's signs, parameters), and the commands: land, kill (forced disarm), and arming
on `flightctl run --board sim` (refused without a plan, accepted with one). A lost link does not stop
a plan."""
from __future__ import annotations

import math
import os
import signal
import socket
import subprocess
import sys
import threading
import time

import pytest

from flightctl.cli import main as cli
from flightctl.logfile import read_flight_log
from helpers.without import run_without

os.environ.setdefault("MAVLINK20", "1")
mavutil = pytest.importorskip("pymavlink.mavutil")
from pymavlink.dialects.v20 import common as mav  # noqa: E402

# Real time on a shared machine: a test that measures wall-clock timing (frame rates, durations, pacing)
# is run again, up to twice, when the machine stalls it; what it asserts is unchanged.
pytestmark = pytest.mark.flaky(reruns=2)


FORCE = 21196


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Gcs:
    """A ground station: receives everything on a background thread; sends commands."""

    def __init__(self):
        self.port = free_port()
        self.conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{self.port}", dialect="common",
                                               source_system=255, source_component=190)
        self.msgs: list = []
        self.proc: subprocess.Popen | None = None    # the service sending to it, when in a process of its own
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    @property
    def url(self) -> str:
        return f"udpout:127.0.0.1:{self.port}"

    def _run(self):
        while not self._stop.is_set():
            m = self.conn.recv_match(blocking=True, timeout=0.05)
            if m is not None and m.get_type() != "BAD_DATA":
                with self._lock:
                    self.msgs.append(m)

    def of(self, kind: str) -> list:
        with self._lock:
            return [m for m in self.msgs if m.get_type() == kind]

    def texts(self) -> list[str]:
        return [m.text for m in self.of("STATUSTEXT")]

    def wait(self, cond, timeout: float = 20.0):
        """The first message that meets `cond`. From a service in its own process (`self.proc`) it is
        waited for as long as that process lives, however busy the machine; else for `timeout` s."""
        end = time.monotonic() + timeout
        while self.proc is not None or time.monotonic() < end:
            ended = self.proc is not None and self.proc.poll() is not None
            with self._lock:
                hit = next((m for m in self.msgs if cond(m)), None)
            if hit is not None:
                return hit
            if ended:
                raise AssertionError(f"the service ended (exit {self.proc.returncode}); texts: {self.texts()}")
            time.sleep(0.01)
        raise AssertionError(f"timed out; texts: {self.texts()}")

    def command(self, cmd: int, *params: float) -> None:
        p = list(params) + [0.0] * (7 - len(params))
        self.conn.mav.command_long_send(1, 1, cmd, 0, *p)

    def ack(self, cmd: int, after: int):
        return self.wait(lambda m: m.get_type() == "COMMAND_ACK" and m.command == cmd and id(m) not in after)

    def close(self):
        self._stop.set()
        self._thread.join()
        self.conn.close()


@pytest.fixture
def gcs():
    g = Gcs()
    yield g
    g.close()


PLAN = """name = "{name}"
duration = {duration}
[[move]]
t = 0.0
channel = "alt"
value = 1.0
ramp = 1.5
[[move]]
t = 2.5
channel = "roll"
value_deg = 6.0
[[move]]
t = 3.5
channel = "pitch"
value_deg = 6.0
[[move]]
t = 4.5
channel = "roll"
value = 0.0
[[move]]
t = 4.5
channel = "pitch"
value = 0.0
[[move]]
t = 5.0
channel = "alt"
value = 0.0
ramp = 3.0
"""


def sim_in_thread(tmp_path, gcs, name="mav", duration=9.0):
    plan = tmp_path / f"{name}.toml"
    plan.write_text(PLAN.format(name=name, duration=duration))
    log = tmp_path / f"{name}.csv"
    out = {}
    th = threading.Thread(target=lambda: out.setdefault("code", cli(
        ["sim", "--plan", str(plan), "--log", str(log), "--no-plot", "--quiet", "--params", "paper-as-flown", "--mavlink", gcs.url])))
    th.start()
    return th, log, out


def test_sim_streams_a_quadrotor_with_our_signs_in_ned(tmp_path, gcs, capsys):
    th, log_path, out = sim_in_thread(tmp_path, gcs)
    gcs.wait(lambda m: m.get_type() == "HEARTBEAT")
    gcs.conn.mav.param_request_list_send(1, 1)
    th.join(60)
    time.sleep(0.3)
    assert out["code"] == 0
    log = read_flight_log(log_path)

    beats = gcs.of("HEARTBEAT")
    assert beats and all(b.type == mav.MAV_TYPE_QUADROTOR for b in beats)
    assert any(b.base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED for b in beats)      # it flew armed
    assert gcs.of("SYS_STATUS") and gcs.of("BATTERY_STATUS")
    assert any(14.0 < b.voltages[0] / 1000 < 17.0 for b in gcs.of("BATTERY_STATUS"))

    att = gcs.of("ATTITUDE")
    ms = [a.time_boot_ms for a in att]
    span = (ms[-1] - ms[0]) / 1000
    assert len(att) / span >= 49.0                                   # 50 Hz in the vehicle's time
    deg = math.degrees
    # a positive roll shows as a positive roll; our positive pitch (nose down) as a negative pitch
    roll, pitch = [a.roll for a in att], [a.pitch for a in att]
    assert deg(max(roll)) > 4.0 and deg(max(log["pitch"])) > 4.0       # the +6 degree steps
    assert deg(max(roll)) == pytest.approx(deg(log["roll"].max()), abs=0.3)
    assert deg(min(roll)) == pytest.approx(deg(log["roll"].min()), abs=0.3)
    assert deg(min(pitch)) == pytest.approx(-deg(log["pitch"].max()), abs=0.3)
    assert deg(max(pitch)) == pytest.approx(-deg(log["pitch"].min()), abs=0.3)
    pos = gcs.of("LOCAL_POSITION_NED")
    assert min(p.z for p in pos) == pytest.approx(-log["alt"].max(), abs=0.02)   # z down
    sonar = [d for d in gcs.of("DISTANCE_SENSOR")]
    assert sonar and all(d.orientation == mav.MAV_SENSOR_ROTATION_PITCH_270 for d in sonar)
    assert max(d.current_distance for d in sonar) == pytest.approx(100 * log["range"][log["range"] == log["range"]].max(), abs=2)
    servo = sorted(s.servo1_raw for s in gcs.of("SERVO_OUTPUT_RAW") if s.servo1_raw > 0)   # 0: motors stopped
    assert len(servo) > 100 and 1100 < servo[len(servo) // 2] < 2000     # ESC pulses in microseconds
    texts = gcs.texts()
    assert "armed" in texts and any(t.startswith("landed") for t in texts)

    params = {p.param_id: p for p in gcs.of("PARAM_VALUE")}
    assert len(params) == params["kp_phi"].param_count == 36   # the airframe, the gains, the filters
    assert params["kp_phi"].param_value == pytest.approx(4.48)
    assert params["M"].param_value == pytest.approx(1.645)
    assert "batt_nominal_v" in params                                   # 17 characters: the alias


def test_land_and_kill_from_the_ground_station(tmp_path, gcs, capsys):
    th, log_path, out = sim_in_thread(tmp_path, gcs, "land", 30.0)
    gcs.wait(lambda m: m.get_type() == "LOCAL_POSITION_NED" and m.z < -0.9)
    gcs.command(mav.MAV_CMD_NAV_LAND)
    assert gcs.ack(mav.MAV_CMD_NAV_LAND, ()).result == mav.MAV_RESULT_ACCEPTED
    th.join(60)
    assert out["code"] == 0                                           # landed upright
    gcs.wait(lambda m: m.get_type() == "STATUSTEXT" and m.text.startswith("landed"))
    assert any(t.startswith("land commanded by the ground station") for t in gcs.texts())
    assert read_flight_log(log_path)["t"][-1] < 20.0                   # long before the plan's 30 s

    gcs2 = Gcs()
    try:
        th, log_path, out = sim_in_thread(tmp_path, gcs2, "kill", duration=30.0)
        gcs2.wait(lambda m: m.get_type() == "LOCAL_POSITION_NED" and m.z < -0.5)
        gcs2.command(mav.MAV_CMD_COMPONENT_ARM_DISARM, 0.0, 0.0)           # a plain disarm in the air: refused
        assert gcs2.ack(mav.MAV_CMD_COMPONENT_ARM_DISARM, ()).result == mav.MAV_RESULT_DENIED
        first = {id(m) for m in gcs2.of("COMMAND_ACK")}
        gcs2.command(mav.MAV_CMD_COMPONENT_ARM_DISARM, 0.0, FORCE)         # forced: the kill switch
        assert gcs2.ack(mav.MAV_CMD_COMPONENT_ARM_DISARM, first).result == mav.MAV_RESULT_ACCEPTED
        th.join(60)
        gcs2.wait(lambda m: m.get_type() == "STATUSTEXT" and m.text.startswith("stopped: killed by the ground"))
        log = read_flight_log(log_path)
        assert log["t"][-1] < 20.0 and out["code"] == 1                # cut in the air: it fell (a crash)
    finally:
        gcs2.close()


def test_losing_the_link_does_not_stop_the_plan(tmp_path, capsys):
    """Nobody listens at the ground station's address: the same flight, row for row, as without a link."""
    plan = tmp_path / "p.toml"
    plan.write_text(PLAN.format(name="lost", duration=9.0))
    logs = []
    for k, extra in enumerate(([], ["--mavlink", f"udpout:127.0.0.1:{free_port()}"])):
        logs.append(tmp_path / f"{k}.csv")
        assert cli(["sim", "--plan", str(plan), "--log", str(logs[-1]), "--no-plot", "--quiet",
                    "--params", "paper-as-flown", *extra]) == 0
    a, b = (read_flight_log(p) for p in logs)
    assert a["t"][-1] >= 8.0 and a["alt"].max() > 0.9
    for c in a.columns:
        assert ((a[c] == b[c]) | (a[c] != a[c])).all(), c


def run_service(tmp_path, gcs, *extra):
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    env.pop("NOTIFY_SOCKET", None)
    gcs.proc = subprocess.Popen([sys.executable, "-P", "-m", "flightctl.cli", "run", "--board", "sim", "--log",
                                 str(tmp_path), "--calibrate", "0.5", "--mavlink", gcs.url, *extra],
                                env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    return gcs.proc


def test_run_arms_only_with_a_plan_loaded(tmp_path, gcs):
    proc = run_service(tmp_path, gcs)                                 # no plan: it waits, disarmed
    try:
        gcs.wait(lambda m: m.get_type() == "HEARTBEAT")
        gcs.command(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1.0)
        assert gcs.ack(mav.MAV_CMD_COMPONENT_ARM_DISARM, ()).result == mav.MAV_RESULT_DENIED
        assert "arming refused: no plan loaded" in gcs.texts()
        assert not any(b.base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED for b in gcs.of("HEARTBEAT"))
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.communicate()
    assert proc.returncode == 0


def test_run_waits_for_the_pilot_to_arm(tmp_path, gcs):
    plan = tmp_path / "short.toml"
    plan.write_text('name = "short"\nduration = 3.5\n[[move]]\nt = 0.0\nchannel = "alt"\nvalue = 0.4\nramp = 0.8\n'
                    '[[move]]\nt = 1.2\nchannel = "alt"\nvalue = 0.0\nramp = 1.2\n')
    proc = run_service(tmp_path, gcs, "--plan", str(plan))
    try:
        gcs.wait(lambda m: m.get_type() == "STATUSTEXT" and m.text.startswith("ready: plan short"))
        time.sleep(0.8)                                               # calibrated, and still waiting
        assert "armed" not in gcs.texts() and proc.poll() is None
        gcs.command(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1.0)
        assert gcs.ack(mav.MAV_CMD_COMPONENT_ARM_DISARM, ()).result == mav.MAV_RESULT_ACCEPTED
        gcs.wait(lambda m: m.get_type() == "HEARTBEAT" and m.base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED)
        output, _ = proc.communicate()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 0, output
    texts = gcs.texts()
    assert "armed" in texts and any(t.startswith("landed") for t in texts)
    (csv,) = tmp_path.glob("flight-*short.csv")
    assert read_flight_log(csv)["alt"].max() > 0.3


@pytest.mark.parametrize("command", [["sim", "hover", "--log", "f.csv"],
                                     ["run", "--board", "sim", "--plan", "hover", "--log", "."]])
def test_without_pymavlink_mavlink_is_one_line_saying_how_to_get_it(tmp_path, command):
    r = run_without(("pymavlink",), command + ["--mavlink", "udpout:127.0.0.1:9"], cwd=tmp_path)
    assert r.returncode == 2, r.stderr
    (line,) = r.stderr.strip().splitlines()[-1:]
    assert "pip install '.[mavlink]' in the flightctl checkout" in line and "Traceback" not in r.stderr
    assert not list(tmp_path.glob("*.csv"))                          # nothing flown
