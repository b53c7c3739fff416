"""`flightctl run --board pi` and `--board pi5` fly the simulator through their boards' fakes: the whole
onboard service (pre-arm checks, calibration, arming, the 450 Hz loop, landing, the log) with the real
drivers and client libraries, the pigpio board against the fake pigpiod, the Pi 5 board against the fake
sysfs PWM tree and the fake GPIO chip (tests/helpers/fakes/quad.py couples them to the simulated world). The two
logs agree within what the fakes' real-time timing adds: the sonar's echoes arrive in wall-clock time,
so an echo lands a loop earlier or later, and the altitude estimate follows it."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from helpers.fakes.quad import FakeQuad
from flightctl.logfile import read_flight_log
from flightctl.params import load
from flightctl.safety import CRASH_TOUCHDOWN_SPEED
from flightctl.service.run import main

PLAN = ('name = "hop"\nduration = 5.0\n[[move]]\nt = 0.0\nchannel = "alt"\nvalue = 0.5\nramp = 1.5\n'
        '[[move]]\nt = 3.0\nchannel = "alt"\nvalue = 0.0\nramp = 2.0\n')


@pytest.fixture(scope="module")
def flights(tmp_path_factory):
    params = load(None)
    out = {}
    for board in ("pi", "pi5"):
        d = tmp_path_factory.mktemp(board)
        (d / "hop.toml").write_text(PLAN)
        # the dead-man at 1 s: a busy machine may pause the simulated loop past the shipped 100 ms (the
        # dead-man's own tests keep 100 ms: test_safety_boards, test_pwm_deadman)
        (d / "board.toml").write_text("[esc]\ndeadman_ms = 1000\n")
        with FakeQuad(params, board, d, seed=3) as quad:
            rc = main(["--board", board, "--board-file", str(d / "board.toml"), "--plan", str(d / "hop.toml"),
                       "--log", str(d), "--calibrate", "1"], devices=quad.devices)
            outputs = quad.outputs()
            errors = list(getattr(quad.fake, "errors", []))
            exported = quad.fake.exported() if board == "pi5" else None
        log = next(d.glob("flight-*-hop.csv"))
        out[board] = dict(rc=rc, log=read_flight_log(log), summary=json.loads(next(d.glob("*-summary.json")).read_text()),
                          world=quad.world, outputs=outputs, errors=errors, exported=exported)
    return out


@pytest.mark.parametrize("board", ["pi", "pi5"])
def test_the_board_flies_the_plan_through_its_fakes_and_lands(flights, board):
    f = flights[board]
    assert f["rc"] == 0 and f["summary"]["reason"] == "plan complete", f["summary"]
    log, plant = f["log"], f["world"].plant
    assert log.meta["board"] == board
    assert 0.4 < np.nanmax(log["alt"]) < 1.2                      # it climbed towards 0.5 m
    assert plant.touchdowns and abs(plant.touchdowns[-1][1]) < CRASH_TOUCHDOWN_SPEED
    assert plant.x[2] < 0.05 and max(abs(plant.x[6]), abs(plant.x[7])) < math.radians(10)
    assert np.count_nonzero(~np.isnan(np.asarray(log["range"], float))) > 100     # the sonar answered at 45 Hz
    assert f["errors"] == []
    if board == "pi":                                             # after the flight: the stop pulse in pigpiod
        assert [on for on, _ in f["outputs"]] == [1000, 1000, 1000, 1000]
    else:                                                         # the channels released: no pulses
        assert f["exported"] == [] and [on for on, _ in f["outputs"]] == [None] * 4


def test_the_two_boards_fly_the_same_flight(flights):
    a, b = flights["pi"]["log"], flights["pi5"]["log"]
    assert abs(len(a) - len(b)) <= 2
    n = min(len(a), len(b))
    ea = [what.split(" at ")[0] for _, what in flights["pi"]["summary"]["events"]]
    eb = [what.split(" at ")[0] for _, what in flights["pi5"]["summary"]["events"]]
    assert ea == eb
    for (ta, _), (tb, _) in zip(flights["pi"]["summary"]["events"], flights["pi5"]["summary"]["events"]):
        assert abs(ta - tb) <= 0.05
    diff = lambda c: np.abs(np.asarray(a[c][:n], float) - np.asarray(b[c][:n], float))   # noqa: E731
    assert np.nanmax(diff("alt")) < 0.1
    for c in ("roll", "pitch"):
        assert np.nanmax(diff(c)) < math.radians(1.0), c
    for c in ("P1", "P2", "P3", "P4"):
        assert np.nanmean(diff(c)) < 1.0, c
    ra, rb = (np.count_nonzero(~np.isnan(np.asarray(x["range"], float))) for x in (a, b))
    assert abs(ra - rb) <= 0.1 * max(ra, rb)
