"""The service inside its unit's sandbox (systemd/flightctl.service): which board `--board auto` picks when
/proc has only process directories (ProcSubset=pid), and the board's start-up and ExecStopPost there.

The sandbox is built as far as this machine allows: a private mount namespace (`unshare -m`, root
needed), a procfs mounted `subset=pid,hidepid=invisible` (ProcSubset=pid, ProtectProc=invisible) on
/proc, and a simulated Raspberry Pi 5 /sys bind-mounted over /sys: the device tree's model and the fake
PWM tree (tests/helpers/fakes/sysfs_pwm.py) at the paths the kernel uses. What is not reproduced: the unit's user
and groups (the child runs as root: the interpreter lives under /root), the device cgroup (DevicePolicy=),
the system-call filter and ProtectSystem=; `systemd-analyze verify` checks those settings
(tests/onboard/service/test_service_units.py)."""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from helpers.paths import TESTS
from helpers.fakes.sysfs_pwm import RP1_PWM0, FakePwmSysfs
from flightctl.boards import detect

PI5 = b"Raspberry Pi 5 Model B Rev 1.0\0"
PI4 = b"Raspberry Pi 4 Model B Rev 1.5\0"


def tree(tmp_path: Path, sysfs: bytes | None, proc: bytes | None) -> tuple[str, str]:
    paths = (tmp_path / "sys/firmware/devicetree/base/model", tmp_path / "proc/device-tree/model")
    for path, text in zip(paths, (sysfs, proc)):
        if text is not None:
            path.parent.mkdir(parents=True)
            path.write_bytes(text)
    return str(paths[0]), str(paths[1])


@pytest.mark.parametrize("sysfs, proc, board", [(PI5, None, "pi5"), (None, PI5, "pi5"), (PI4, PI5, "pi"),
                                                (PI5, PI4, "pi5"), (None, None, "pi")],
                         ids=["sandbox: no /proc/device-tree", "fallback to /proc", "sysfs first (4)",
                              "sysfs first (5)", "no device tree"])
def test_the_model_is_read_from_sysfs_first_and_from_proc_only_as_a_fallback(tmp_path, monkeypatch, sysfs, proc,
                                                                             board):
    monkeypatch.setattr(detect, "MODEL_PATHS", tree(tmp_path, sysfs, proc))
    assert detect.detected() == board


def test_the_shipped_paths_are_sysfs_then_proc():
    assert detect.MODEL_PATHS == ("/sys/firmware/devicetree/base/model", "/proc/device-tree/model")


# --- under the unit's restrictions -----------------------------------------------------------------
CHILD = r"""
import json, os, sys
sys.path.insert(0, {tests!r})
from helpers.fakes.gpiochip import FakeGpioDevice
from helpers.fakes.sysfs_pwm import FakePwmSysfs
from flightctl.boards import BoardOptions, BoardUnavailable, open_board, stop_motors
from flightctl.boards import detect
from flightctl.boards.pi5 import open_gpio_chip
from flightctl.params import load
from flightctl.sim.world.devices import SensorNoise, World
from flightctl.sim.world.imu import SimMpu9250
from flightctl.sim.world.power import SimIna219, SimSMBus
from helpers.paths import TESTS

out = {{"proc": [n for n in os.listdir("/proc") if not n.isdigit()],
       "proc_device_tree": os.path.exists("/proc/device-tree"), "model": detect.model(),
       "board": detect.detected()}}
try:
    open_gpio_chip("pinctrl-rp1", wait_s=0).close()
    out["gpio"] = "opened"
except BoardUnavailable as e:
    out["gpio"] = str(e)
params = load(None)
world = World(params.airframe, noise=SensorNoise.off())
world.battery.voltage, world.battery.current = 16.1, 0.4
fake = FakePwmSysfs.attach("/")            # the kernel's /sys/class/pwm, as the driver's default root finds it
gpio = FakeGpioDevice()
board = open_board("auto", params, BoardOptions(devices=dict(pwm_fs=fake, gpio_chip=gpio.chip(),
                                                             spi=SimMpu9250(world), smbus=SimSMBus(SimIna219(world)))))
out["opened"] = board.name
out["esc_pwm"] = board.meta["esc_pwm"]
out["on_times"] = fake.on_times_us()
board.hal.motors.arm()
board.hal.motors.write([34000] * 4)
board.hal.motors._exported.clear()         # the controller dies here: its channels stay exported, motors on
board.hal.motors._deadman = None
out["flying"] = fake.on_times_us()
out["stop_motors"] = stop_motors("auto", params, BoardOptions(devices=dict(pwm_fs=fake)))    # ExecStopPost
out["after"] = fake.on_times_us()
out["exported"] = fake.exported()
gpio.close()
print(json.dumps(out))
"""


def sandboxed(base: Path, script: str) -> subprocess.CompletedProcess:
    """`script` in a private mount namespace: the simulated /sys over /sys, procfs with subset=pid."""
    shell = (f"mount --make-rprivate / && mount --bind {base / 'sys'} /sys && "
             "mount -t proc -o subset=pid,hidepid=invisible proc /proc && "
             f'exec "$0" -c "$1"')
    return subprocess.run(["unshare", "-m", "sh", "-c", shell, sys.executable, script], capture_output=True,
                          text=True, timeout=120, cwd=TESTS)


def can_sandbox() -> str | None:
    """Why the sandbox cannot be built here (None: it can)."""
    if os.geteuid() != 0:
        return "not root: mount namespaces and mounts need CAP_SYS_ADMIN"
    if shutil.which("unshare") is None:
        return "no unshare (util-linux)"
    r = subprocess.run(["unshare", "-m", "sh", "-c", "mount --make-rprivate / && "
                        "mount -t proc -o subset=pid proc /proc && ls /proc"], capture_output=True, text=True)
    if r.returncode != 0:
        return f"the kernel refuses a procfs with subset=pid in a new mount namespace: {r.stderr.strip()}"
    return None


@pytest.mark.skipif(can_sandbox() is not None, reason=str(can_sandbox()))
def test_inside_the_units_sandbox_auto_is_the_pi5_board_and_execstoppost_stops_the_motors(tmp_path):
    fake = FakePwmSysfs(tmp_path)              # a 6.6 kernel's numbering: the RP1's PWM0 at pwmchip2
    fake.retain(RP1_PWM0, 1, period=20_000_000, duty_cycle=2_500_000, enable=1)   # a servo test left it so
    model = tmp_path / "sys/firmware/devicetree/base/model"
    model.parent.mkdir(parents=True)
    model.write_bytes(PI5)
    r = sandboxed(tmp_path, CHILD.format(tests=str(TESTS)))
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout.strip().splitlines()[-1])
    # ProcSubset=pid: /proc has the processes and nothing else, so no /proc/device-tree
    assert not out["proc_device_tree"] and set(out["proc"]) <= {"self", "thread-self"}, out["proc"]
    assert out["model"] == "Raspberry Pi 5 Model B Rev 1.0" and out["board"] == "pi5"
    # the GPIO chip lookup runs on this machine's /dev: it has no GPIO chip, and says so in one line
    gpiochips = sorted(p.name for p in Path("/dev").glob("gpiochip*"))
    if not gpiochips:
        assert out["gpio"] == "no GPIO chip 'pinctrl-rp1' (there: none)"
    assert out["opened"] == "pi5" and out["esc_pwm"] == "1f00098000.pwm channels [0, 1, 2, 3]"
    assert out["on_times"] == {str(c): 1000.0 for c in range(4)}        # from the servo's state too
    assert min(out["flying"].values()) > 1800
    assert out["stop_motors"].startswith("stop pulse (1000 us), then disabled and unexported: pwm0, pwm1, pwm2, pwm3")
    assert out["after"] == {str(c): None for c in range(4)} and out["exported"] == []
    assert fake.retained(RP1_PWM0, 0)["duty_cycle"] == 1_000_000          # the stop pulse, kept for the next user


@pytest.mark.skipif(can_sandbox() is not None, reason=str(can_sandbox()))
def test_the_units_execstoppost_command_finds_the_pi5_in_the_sandbox_and_stops_what_a_dead_controller_left(tmp_path):
    """The unit's own ExecStopPost command line, in the sandbox, on the kernel's files (written with the
    `os` module as on the Pi, so the fake's rules do not apply: it checks the path the command takes, not
    the kernel's answers). Before issue 36 it picked the pigpio board there and exited 1."""
    fake = FakePwmSysfs(tmp_path)
    chip = fake.dirs[RP1_PWM0]
    for c in range(4):                                   # a dead controller's channels, motors running
        fake.write(chip / "export", str(c))
        for what, value in (("period", "2227171"), ("duty_cycle", "1800000"), ("enable", "1")):
            fake.write(chip / f"pwm{c}" / what, value)
    model = tmp_path / "sys/firmware/devicetree/base/model"
    model.parent.mkdir(parents=True)
    model.write_bytes(PI5)
    script = ("import sys; from flightctl.cli import main; "
              "sys.exit(main(['run', '--board', 'auto', '--stop-motors']))")
    r = sandboxed(tmp_path, script)
    assert r.returncode == 0, r.stderr
    assert "stop-motors: stop pulse (1000 us), then disabled and unexported: pwm0, pwm1, pwm2, pwm3 of " \
           "1f00098000.pwm" in r.stderr
    for c in range(4):
        assert (chip / f"pwm{c}" / "duty_cycle").read_text() == "1000000\n"
        assert (chip / f"pwm{c}" / "enable").read_text() == "0\n"
