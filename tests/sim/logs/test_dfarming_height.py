"""The logged height as a source of the arming (sim/logs/dfarming.py, issue 45 item 1): a climb and a
return to the start height is a flight, whatever the other sources left out. A log written here as
ArduCopter 4.x DataFlash (sim/logs/dfwrite.py) with no ARM message (ArduCopter before 4.0 has none), an EV
that is no arming event (25, SET_HOME) and no motor outputs (LOG_BITMASK without RCOUT) was refused as
"never armed", a false reason: it is refused for its unlogged outputs. A barometer drifting the same
height without coming back is no flight; outputs at their disarmed pulse under a flight are said to
disagree with it."""
from __future__ import annotations

import math

import numpy as np
import pytest

from flightctl.errors import InputError
from flightctl.sim.logs import read_foreign
from flightctl.sim.logs.dfwrite import DataFlash

pytest.importorskip("pymavlink")
G = 9.80665


def _log(path, height, rcou: bool, rng):
    """60 s: IMU at 25 Hz (at rest on the ground, then hovering), BARO at 5 Hz reading `height(t)` (m) plus
    a barometer's 0.1 m noise, EV 25 at 1 s; RCOU (5 Hz) at MOT_PWM_MIN throughout when `rcou`."""
    f = DataFlash(without=() if rcou else ("RCOU",))
    f.add("MSG", 1000, "ArduCopter V4.5.7 (1a2b3c4d)")
    for k, v in {"FRAME_CLASS": 1, "FRAME_TYPE": 1, "MOT_PWM_MIN": 1100, "MOT_PWM_MAX": 1900,
                 **{f"SERVO{m}_FUNCTION": 32 + m for m in range(1, 5)}}.items():
        f.add("PARM", 1000, k, float(v))
    f.add("EV", 1_000_000, 25)
    for k in range(60 * 25):
        t = k / 25.0
        us = int(round((2.0 + t) * 1e6))
        f.add("IMU", us, 0, *rng.normal(0.0, 0.01, 3), *(rng.normal(0.0, 0.3, 3) + (0.0, 0.0, -G)))
        if k % 5 == 2:        # 5 Hz, between the IMU's rows
            f.add("BARO", us + 100, 0, float(height(t) + rng.normal(0.0, 0.1)))
            if rcou:
                f.add("RCOU", us + 200, *([1100] * 4 + [0] * 10))
    path.write_bytes(f.bytes())
    return path


def _climb(top):
    """On the ground 10 s, up to `top` m by 20 s, there until 40 s, down by 50 s, on the ground again."""
    return lambda t: top * float(np.clip((t - 10.0) / 10.0, 0, 1) - np.clip((t - 40.0) / 10.0, 0, 1))


def test_a_climb_and_return_in_the_height_says_armed_where_nothing_else_was_logged(tmp_path):
    rng = np.random.default_rng(4501)
    top = float(rng.uniform(4.0, 20.0))
    with pytest.raises(InputError) as e:
        read_foreign(str(_log(tmp_path / "climb.bin", _climb(top), False, rng)))
    assert "never armed" not in str(e.value) and "motor commands were not logged" in str(e.value), str(e.value)


def test_a_drifting_barometer_is_no_flight(tmp_path):
    """The same height reached by a slow drift with no return (a pressure change on the ground)."""
    rng = np.random.default_rng(4502)
    drift = float(rng.uniform(4.0, 20.0))
    with pytest.raises(InputError, match="never armed"):
        read_foreign(str(_log(tmp_path / "drift.bin", lambda t: drift * t / 60.0, False, rng)))


def test_outputs_at_their_disarmed_pulse_under_a_flight_are_said_to_disagree(tmp_path):
    rng = np.random.default_rng(4503)
    top = float(rng.uniform(4.0, 20.0))
    try:
        (table,) = read_foreign(str(_log(tmp_path / "flat.bin", _climb(top), True, rng)))
        notes = table.meta.get("import_notes", "")
    except InputError as e:                       # (the idle outputs may refuse it later: the note is the point)
        notes = str(e)
    assert "never armed" not in notes
    assert "the arming's sources disagree: the motor outputs at their disarmed pulse throughout, but BARO Alt" in notes, notes
    rise = float(notes.split("BARO Alt ")[1].split(" m")[0])
    assert rise == pytest.approx(top, abs=0.5), (top, notes)
