"""Issue 36: on a Raspberry Pi 5 the motors stop whatever kills the controller. The controller runs in a
process of its own against the fake sysfs PWM tree (tests/helpers/fakes/sysfs_pwm.py), armed and commanding
flight duty; it is killed by a signal, or killed together with its dead-man (what `systemctl kill -s
KILL flightctl` does to the whole unit), and the stop pulse is read back from the fake kernel: written by
the dead-man (pwm_deadman.py; the unit's KillMode=process leaves it alive for that), or by the unit's
ExecStopPost, `flightctl run --board auto --stop-motors`, which finds the Pi 5 through sysfs."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from helpers.paths import TESTS
from helpers.fakes.sysfs_pwm import RP1_PWM0, FakePwmSysfs
from flightctl.boards import detect
from flightctl.drivers.pulses import EscError
from flightctl.drivers.pwm_sysfs import SysfsPwmEsc
from flightctl.service.run import main

STOP_NS, FLIGHT = 1_000_000, 34000

CONTROLLER = """
import sys, time
sys.path.insert(0, {tests!r})
from helpers.fakes.sysfs_pwm import FakePwmSysfs
from flightctl.drivers.pwm_sysfs import SysfsPwmEsc
from helpers.paths import TESTS
fake = FakePwmSysfs.attach({base!r})
esc = SysfsPwmEsc("1f00098000.pwm", (0, 1, 2, 3), root=str(fake.root), fs=fake, deadman_ms=100)
esc.start()
esc.arm()
esc.write([{flight}] * 4)
print(esc._deadman.pid, flush=True)
while True:
    esc.write([{flight}] * 4)
    time.sleep(0.002)
"""


def duty(fake: FakePwmSysfs, c: int) -> int:
    """What the channel's duty_cycle file reads (the dead-man writes it directly, as on the Pi)."""
    return int((fake.channel(RP1_PWM0, c) / "duty_cycle").read_text() or 0)


def wait_for(predicate, timeout: float) -> None:
    end = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > end:
            raise AssertionError(f"not within {timeout} s")
        time.sleep(0.002)


def flying(tmp_path: Path) -> tuple[FakePwmSysfs, subprocess.Popen, int]:
    """The controller, armed at flight duty, in a session of its own (its dead-man in it too)."""
    fake = FakePwmSysfs(tmp_path)
    proc = subprocess.Popen([sys.executable, "-c", CONTROLLER.format(tests=str(TESTS), base=str(tmp_path),
                                                                     flight=FLIGHT)],
                            stdout=subprocess.PIPE, text=True, cwd=TESTS, start_new_session=True)
    deadman = int(proc.stdout.readline())
    assert all(duty(fake, c) > 1_800_000 for c in range(4))
    return fake, proc, deadman


def gone(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    return False


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGABRT, signal.SIGSEGV, signal.SIGTERM, signal.SIGINT],
                         ids=lambda s: signal.Signals(s).name)
def test_the_dead_man_outlives_a_controller_killed_by_any_signal_and_writes_the_stop_pulse(tmp_path, sig):
    """SIGKILL (OOM, kill -9), SIGABRT (the watchdog), SIGSEGV (a crash), SIGTERM and SIGINT without the
    service's handlers: no `finally` runs, the pipe closes, the dead-man writes the stop pulse and exits."""
    fake, proc, deadman = flying(tmp_path)
    try:
        proc.send_signal(sig)
        proc.wait(10)
        wait_for(lambda: all(duty(fake, c) == STOP_NS for c in range(4)), 5.0)
        wait_for(lambda: gone(deadman), 5.0)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == -sig
    assert fake.exported() == [0, 1, 2, 3]              # still exported: ExecStopPost releases them


def test_the_whole_unit_killed_at_once_is_stopped_by_execstoppost(tmp_path, monkeypatch):
    """`systemctl kill -s KILL flightctl`: the controller and its dead-man die together; the unit's
    ExecStopPost, exactly as the unit runs it (--board auto), puts the stop pulse on, disables and
    releases the channels."""
    fake, proc, deadman = flying(tmp_path)
    try:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(10)
        wait_for(lambda: gone(deadman), 5.0)
    finally:
        if proc.poll() is None:
            proc.kill()
    model = tmp_path / "firmware-model"
    model.write_bytes(b"Raspberry Pi 5 Model B Rev 1.0\0")
    monkeypatch.setattr(detect, "MODEL_PATHS", (str(model), str(tmp_path / "no-proc-device-tree")))
    after = FakePwmSysfs.attach(tmp_path)               # the ExecStopPost process's view of the kernel
    assert main(["--board", "auto", "--stop-motors"], devices=dict(pwm_root=str(after.root), pwm_fs=after)) == 0
    for c in range(4):
        mine = [(p.rsplit("/", 1)[1], v) for p, v, err in after.stores if p.startswith(f"pwmchip2/pwm{c}/") and not err]
        assert mine == [("duty_cycle", str(STOP_NS)), ("enable", "0")]
        assert after.retained(RP1_PWM0, c)["duty_cycle"] == STOP_NS
    assert after.exported() == [] and after.on_times_us() == {c: None for c in range(4)}


def test_after_the_dead_man_fired_the_next_write_stops_before_any_flight_duty(tmp_path):
    """A stalled loop: the dead-man fires after deadman_ms and closes its pipe; the loop, resuming, sends
    its heartbeat first and raises, the stop pulse untouched (issue 36: the duty writes came first)."""
    fake = FakePwmSysfs(tmp_path)
    esc = SysfsPwmEsc(RP1_PWM0, (0, 1, 2, 3), root=str(fake.root), fs=fake, deadman_ms=50)
    esc.start()
    try:
        esc.arm()
        esc.write([FLIGHT] * 4)
        assert duty(fake, 0) > 1_800_000
        deadman = esc._deadman
        deadman.wait(5)                                   # the stall: it fires and exits
        assert all(duty(fake, c) == STOP_NS for c in range(4))
        n = esc.writes
        with pytest.raises(EscError, match="the ESC dead-man stopped the motors"):
            esc.write([FLIGHT + 1000] * 4)                # a new command: it would be written if it could
        assert esc.writes == n and all(duty(fake, c) == STOP_NS for c in range(4))
    finally:
        esc.close()
    assert fake.exported() == []
