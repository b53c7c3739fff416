"""The same safety on both Pi boards, each against its fakes (the pigpio board: the fake pigpiod through the
real pigpio client; the Pi 5 board: the fake sysfs PWM tree and GPIO chip): only the flight controller
commands the motors (another process changing the ESC output is seen disarmed and in flight), the
dead-man stops the motors when the loop stalls, and the kill path (a stop request in the air) leaves the
stop pulse on the ESCs. A channel or line another process holds at start-up is a refusal on the Pi 5
(tests/onboard/boards/test_pi5.py, tests/onboard/drivers/test_pwm_sysfs.py); on the Pi 3/4 pigpiod is flightctl's own and its
start takes the wave engine over (tests/onboard/drivers/test_esc.py)."""
from __future__ import annotations

import argparse
import threading
import time
from types import SimpleNamespace

import pigpio
import pytest

from helpers.fakes.quad import FakeQuad
from flightctl.boards import BoardOptions, open_board
from flightctl.control.controller import FlightController
from flightctl.drivers.pulses import OUTPUT_CHECK_S, EscError
from flightctl.hal import ArmingRefused
from flightctl.loop import FlightLoop
from flightctl.params import load
from flightctl.plans.plan import Move, Plan
from flightctl.service.run import Service

PARAMS = load(None)
BOARDS = ["pi", "pi5"]


class Rig:
    """A board opened on its fakes, the simulated world behind them, and what another process would do."""

    def __init__(self, board: str, tmp_path, deadman_ms: int | None = None):
        self.name = board
        self.quad = FakeQuad(PARAMS, board, tmp_path, seed=1).__enter__()
        board_file = None
        if deadman_ms is not None:         # the board file's keys replace the shipped file's (flightctl/boards)
            board_file = tmp_path / f"{board}-deadman.toml"
            board_file.write_text(f"[esc]\ndeadman_ms = {deadman_ms}\n")
        self.board = open_board(board, PARAMS, BoardOptions(devices=self.quad.devices,
                                                            board_file=None if board_file is None else str(board_file)))
        self.motors = self.board.hal.motors

    def close(self) -> None:
        self.board.close()
        self.quad.__exit__(None, None, None)

    def on_times(self) -> list:
        return [None if on is None else round(on) for on, _ in self.quad.outputs()]

    def intrude(self, on_us: int = 1900) -> None:
        """Another process drives the ESC outputs: a second pigpiod client's wave, or a write to the
        channels' duty_cycle files."""
        if self.name == "pi":
            pi = self.quad._ctx.connect()
            pins = sum(1 << p for p in self.motors.pins)
            pi.wave_add_new()
            pi.wave_add_generic([pigpio.pulse(pins, 0, on_us), pigpio.pulse(0, pins, 2227 - on_us)])
            pi.wave_send_repeat(pi.wave_create())
        else:
            for c in range(4):
                self.quad.fake.write(self.quad.fake.channel("1f00098000.pwm", c) / "duty_cycle", f"{on_us * 1000}")


@pytest.fixture(params=BOARDS)
def rig(request, tmp_path):
    r = Rig(request.param, tmp_path)
    yield r
    r.close()


class Notes:
    def __init__(self):
        self.lines: list[str] = []

    def status(self, text: str) -> None:
        self.lines.append(text)

    def tick(self, i: int = 0) -> None:
        pass


def test_another_process_on_the_escs_while_disarmed_is_seen_and_the_service_never_arms_again(rig):
    board = SimpleNamespace(hal=rig.board.hal, calibrate_s=0.0, min_battery_v=0.0, name=rig.name)
    svc = Service(argparse.Namespace(log=".", calibrate=None, min_battery_v=None), PARAMS, board, Notes(),
                  threading.Event())
    svc.watch_output()
    assert svc.tampered is None
    rig.intrude()
    time.sleep(0.01)
    assert rig.on_times() == [1900] * 4
    svc._next_output_check = 0.0
    svc.watch_output()
    assert svc.tampered and "another" in svc.tampered and "refusing to arm" in svc.notifier.lines[-1]
    time.sleep(0.01)
    assert rig.on_times() == [1000] * 4                                  # the stop pulse is back
    with pytest.raises(ArmingRefused, match="another"):
        svc.check()                                                      # even though it looks right again


def test_another_process_on_the_escs_in_flight_stops_the_loop_within_the_check_period(rig):
    m = rig.motors
    m.arm()
    m.write([24000] * 4)
    time.sleep(0.01)
    t0 = time.monotonic()
    rig.intrude()
    with pytest.raises(EscError, match="another"):
        while time.monotonic() - t0 < 1.0:
            m.write([24000] * 4)
            time.sleep(1 / 450)
    assert time.monotonic() - t0 < OUTPUT_CHECK_S + 0.05
    m.stop()
    time.sleep(0.01)
    assert rig.on_times() == [1000] * 4


def test_a_stalled_loop_has_the_motors_stopped_by_the_dead_man_within_a_quarter_second(rig):
    m = rig.motors
    m.arm()
    end = time.monotonic() + 0.3
    while time.monotonic() < end:
        m.write([34000] * 4)
        time.sleep(0.002)
    assert min(rig.on_times()) > 1800
    last = time.monotonic()                                              # the loop hangs here
    while time.monotonic() - last < 2.0 and rig.on_times() != [1000] * 4:
        time.sleep(0.002)
    assert time.monotonic() - last < 0.25


@pytest.fixture(params=BOARDS)
def rig_busy(request, tmp_path):
    """The rig with the dead-man at its longest (1 s): a test of another path on a busy machine, where the
    simulated loop may pause longer than the default 100 ms (the dead-man's own test is above)."""
    r = Rig(request.param, tmp_path, deadman_ms=1000)
    yield r
    r.close()


def test_a_stop_request_in_the_air_leaves_the_stop_pulse_on_the_escs(rig_busy):
    rig = rig_busy
    stop = threading.Event()
    world = rig.quad.world
    cut = {}

    def tick(i):
        if world.plant.x[2] > 0.3 and not stop.is_set():
            stop.set()
            cut["z"] = world.plant.x[2]

    plan = Plan([Move(0.0, "alt", 0.6, 1.0)], 6.0, "kill")
    loop = FlightLoop(rig.board.hal, PARAMS, plan, None, FlightController(PARAMS), calibrate_s=0.5, stop=stop,
                      on_tick=tick)
    result = loop.run()
    assert result.reason == "stopped: stop requested" and cut["z"] > 0.3       # cut in the air, on command
    time.sleep(0.01)
    assert rig.on_times() == [1000] * 4
