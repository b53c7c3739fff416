"""The service against what goes wrong around it: a log directory it cannot write, a notify socket it
cannot reach, pigpiod gone, a dead accelerometer, a plan name that cannot name a file, a package
folder and a home it cannot write (numba's cache). Each is one line and a defined exit code, decided
before READY=1 where it can be."""
from __future__ import annotations

import logging
import os
import shutil
import subprocess
import sys
import time

import pytest

from helpers.fakes.pigpiod import running
from flightctl.cli import main as cli
from flightctl.drivers.esc import EscError
from flightctl.params import load
from flightctl.service.run import EXIT_ERROR, EXIT_REFUSED, device_error, main, prearm
from flightctl.service.queue import PlanQueue
from flightctl.sim.world.devices import SensorNoise, World
from flightctl.sim.world.imu import SimMpu9250
from flightctl.sim.world.power import SimIna219, SimSMBus
from test_run import Service

pytestmark = pytest.mark.flaky(reruns=2)


def test_a_log_directory_that_cannot_be_written_is_refused_before_ready(tmp_path):
    """A file where the log directory should be (as a read-only card would: nothing can be made there)."""
    (tmp_path / "logs").write_text("not a directory\n")
    svc = Service(tmp_path, "--board", "sim", "--plan", "hover", "--log", "logs/flights", "--calibrate", "0.2")
    svc.proc.wait(timeout=60)
    rc, err = svc.stop()
    assert rc == EXIT_REFUSED, err
    assert "not flying: --log logs/flights:" in err and "is not a directory" in err and "Traceback" not in err
    assert not any("READY=1" in m for m in svc.messages)


def test_an_unusable_notify_socket_is_refused_before_anything_opens(tmp_path, caplog):
    """Under systemd ($NOTIFY_SOCKET set) the watchdog pings would fail in flight: refuse to start."""
    os.environ["NOTIFY_SOCKET"] = str(tmp_path / "gone.sock")
    try:
        assert main(["--board", "sim", "--plan", "hover", "--log", str(tmp_path / "logs")]) == EXIT_REFUSED
    finally:
        del os.environ["NOTIFY_SOCKET"]
    assert [r.getMessage() for r in caplog.records if r.levelno >= logging.ERROR] == [
        f"not flying: NOTIFY_SOCKET={tmp_path / 'gone.sock'} cannot be reached: under systemd, the watchdog pings "
        "would fail in flight"]
    assert not (tmp_path / "logs").exists()


def _chips():
    params = load(None)
    world = World(params.airframe, noise=SensorNoise.off())
    world.battery.voltage, world.battery.current = 16.1, 0.4
    return params, world


def test_pigpiod_gone_is_one_line_and_exit_1(tmp_path, caplog, monkeypatch):
    """The real pigpio client on a fake pigpiod that vanishes once the board is open: the pre-arm
    checks' first ESC command finds no daemon."""
    import flightctl.service.run as service
    from flightctl.boards.pi import open_pi_board
    params, world = _chips()
    ctx = running()
    fake, pi = ctx.__enter__()
    try:
        def opener(name):
            def open_board(p, options):
                board = open_pi_board(p, None, pi=pi, spi=SimMpu9250(world), smbus=SimSMBus(SimIna219(world)))
                fake.stop()                                   # pigpiod gone
                return board
            return open_board
        monkeypatch.setattr(service, "opener", opener)
        rc = main(["--board", "pi", "--plan", "hover", "--log", str(tmp_path), "--calibrate", "0.2"])
    finally:
        pi.stop()
    errors = [r for r in caplog.records if r.levelno >= logging.ERROR]
    assert rc == EXIT_ERROR
    assert errors[0].getMessage().startswith("stopping on a device error, the motors stopped: ")
    assert all(r.exc_info is None for r in caplog.records)          # no traceback in the journal
    assert "pigpiod" in errors[0].getMessage()


def test_device_errors_are_told_from_bugs():
    assert device_error(EscError("the pigpiod dead-man stopped the motors: no command reached it for 100 ms"))
    assert device_error(ConnectionResetError(104, "Connection reset by peer"))
    assert not device_error(ZeroDivisionError("float division by zero"))
    assert not device_error(KeyError("x"))


def test_a_dead_accelerometer_is_refused_before_arming_and_named_in_flight(tmp_path, capsys):
    params, world = _chips()
    chip = SimMpu9250(world)
    inner = chip.xfer2

    def dead(data):                        # the accelerometer's six bytes read 0, the rest lives
        rx = inner(data)
        return [rx[0]] + [0] * 6 + list(rx[7:]) if len(rx) > 14 else rx
    chip.xfer2 = dead
    from types import SimpleNamespace

    from flightctl.drivers.mpu9250 import Mpu9250
    from flightctl.sim.world.devices import SimMotors
    imu = Mpu9250(chip)
    imu.start()
    hal = SimpleNamespace(imu=imu, power=SimpleNamespace(read=lambda: (16.0, 0.5)), motors=SimMotors(world))
    hal.motors.arm = lambda: None
    reasons = prearm(hal, params, 10.0)
    assert reasons == ["IMU: the accelerometer reads 0.00 g at rest: accelerometer faulty"]
    log = tmp_path / "f.csv"
    assert cli(["sim", "hover", "--log", str(log), "--fault", "accel_zero:at=4", "--no-plot"]) == 1
    out = capsys.readouterr().out
    assert "IMU frame refused (accelerometer reads zero)" in out and "motors stopped" in out


def test_a_queued_plan_whose_name_holds_a_nul_is_refused_naming_it(tmp_path):
    queue, logs = tmp_path / "queue", tmp_path / "logs"
    queue.mkdir()
    plan = queue / "p.toml"
    plan.write_text('name = "a\\u0000b"\nduration = 5\n[[move]]\nt = 0\nchannel = "alt"\nvalue = 1\n')
    t = time.time()
    os.utime(plan, (t - 1, t - 1))
    q = PlanQueue(queue, logs, started=t - 10)
    assert q.take() is None
    (name, reason), = q.refused
    assert "holds a NUL character" in reason and "slash" not in reason.split("holds", 1)[1].split(":")[0]


@pytest.mark.skipif(not shutil.which("unshare") or os.geteuid() != 0, reason="needs unshare and root")
def test_a_service_user_without_a_writable_package_or_home_still_flies(tmp_path):
    """The package folder and HOME mounted read-only (a service user): numba's cache goes to the
    temporary folder, said once; the flight flies (it used to crash: "cannot cache function")."""
    import flightctl
    package = os.path.dirname(os.path.dirname(flightctl.__file__))
    home = tmp_path / "home"
    home.mkdir()
    script = (f"mount --bind -o ro {package} {package} && mount --bind -o ro {home} {home} && "
              f"cd {tmp_path} && HOME={home} XDG_CACHE_HOME={home} {sys.executable} -P -m flightctl.cli "
              f"sim hover --log {tmp_path}/f.csv --no-plot --quiet")
    r = subprocess.run(["unshare", "-m", "sh", "-c", script], capture_output=True, text=True, timeout=300)
    if "mount" in r.stderr and r.returncode != 0 and "flightctl" not in r.stderr:
        pytest.skip(f"no mount namespace here: {r.stderr.strip()}")
    assert r.returncode == 0, r.stderr
    assert "Traceback" not in r.stderr
    notes = [line for line in r.stderr.splitlines() if "compiled simulator's cache" in line]
    assert len(notes) <= 1 and (not notes or "cannot be written" in notes[0])
