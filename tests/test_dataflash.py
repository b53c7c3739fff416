"""ArduPilot's DataFlash log through `flightctl.sim.logs.dataflash` (docs/log-import.md): a real
ArduCopter log (tests/data/ardupilot, GPL-3.0-or-later) read with what its parameters say, edited to
be what it is not (a hexacopter, a plane) and refused by name; and this project's simulated flights
written as ArduCopter logs (tests/dataflash.py, read back through pymavlink) with the motor outputs,
the frame and the ESC telemetry drawn at random: every sample comes back where the log put it."""
from __future__ import annotations

import math
import struct
from pathlib import Path

import numpy as np
import pytest

from flightctl.cli import main
from flightctl.logfile import read_flight_log
from flightctl.sim.logs import each_log, read_foreign
from dataflash import DataFlash

pytest.importorskip("pymavlink")
REAL = Path(__file__).parent / "data" / "ardupilot" / "backend_log_80k.bin"
# ArduPilot's quad frames (ArduPilot's motor-order diagrams): per motor 1-4, (x forward, y left) in arm
# lengths and the spin (+1 counter-clockwise)
S = math.sqrt(0.5)
FRAMES = {0: [(0, -1, 1), (0, 1, 1), (1, 0, -1), (-1, 0, -1)],                    # PLUS: right, left, front, back
          1: [(S, -S, 1), (-S, S, 1), (S, S, -1), (-S, -S, -1)],                  # X: FR, RL, FL, RR
          12: [(-S, -S, -1), (S, -S, 1), (-S, S, 1), (S, S, -1)],                 # BF_X: RR, FR, RL, FL
          13: [(S, -S, 1), (S, S, -1), (-S, S, 1), (-S, -S, -1)],                 # DJI_X: FR, FL, RL, RR
          14: [(S, -S, 1), (-S, -S, -1), (-S, S, 1), (S, S, -1)]}                 # CW_X: FR, RR, RL, FL


def rotors(table):
    return [tuple(float(v) for v in r.split()) for r in table.meta["rotors"].split(";")]


def test_a_real_arducopter_log_is_read_as_its_parameters_say():
    (e,) = each_log(str(REAL))
    t = e.table
    assert t.meta["firmware"].startswith("ArduCopter V4.6.2")
    assert np.allclose(rotors(t), FRAMES[1], atol=1e-4)                       # QUAD/X
    assert "SERVO1, SERVO2, SERVO3, SERVO4" in t.meta["motor_outputs"] and t.meta["command_range"] == "1120 1920"
    assert np.all(np.vstack([t[f"P{i}"] for i in range(1, 5)]) == 0)           # on the ground, at MOT_PWM_MIN
    assert t["acc_z"].mean() == pytest.approx(9.76, abs=0.05)                  # FRD's -g is our +g
    assert np.nanmean(t["battery_v"]) == pytest.approx(16.44, abs=0.05)
    assert (t.meta["battery_cells"], t.meta["battery_cells_source"].split()[0]) == ("4", "MOT_BAT_VOLT_MAX")
    assert float(t.meta["rate_hz"]) == pytest.approx(25, abs=1.5)
    assert "24.6 Hz: too slow" in t.meta["import_notes"] and "IMU_FAST" in t.meta["import_notes"]


def _patched(tmp_path, name: str, value: float) -> Path:
    data = REAL.read_bytes()
    key = name.encode().ljust(16, b"\0")
    k = data.find(key)
    assert k > 0, name
    out = tmp_path / "edited.bin"
    out.write_bytes(data[:k + 16] + struct.pack("<f", value) + data[k + 20:])
    return out


def test_a_real_log_edited_into_another_vehicle_is_refused_by_name(tmp_path, capsys):
    for name, value, words in (("FRAME_CLASS", 2.0, "FRAME_CLASS = 2: a hexacopter"),
                               ("FRAME_CLASS", 3.0, "FRAME_CLASS = 3: an octocopter"),
                               ("FRAME_TYPE", 4.0, "FRAME_TYPE = 4"),
                               ("SERVO5_FUNCTION", 37.0, "more than four motors")):
        path = _patched(tmp_path, name, value)
        assert main(["log", "import", str(path), str(tmp_path / "o.csv")]) == 2
        err = capsys.readouterr().err
        assert words in err and len(err.strip().splitlines()) == 1, err
    plane = tmp_path / "plane.bin"
    plane.write_bytes(REAL.read_bytes().replace(b"ArduCopter V4.6.2", b"ArduPlane V4.6.2\0"))
    assert main(["log", "import", str(plane), str(tmp_path / "o.csv")]) == 2
    assert "a fixed wing, not a quadrotor" in capsys.readouterr().err


@pytest.fixture(scope="module")
def flight(tmp_path_factory):
    d = tmp_path_factory.mktemp("df")
    assert main(["sim", "step_roll", "--log", str(d / "f.csv"), "--no-plot", "--quiet", "--seed", "3"]) == 0
    return read_flight_log(d / "f.csv"), d


def write(flight, rng, frame_type: int, armed: bool = True, firmware: str = "ArduCopter V4.5.7 (1a2b3c4d)"):
    """The flight as an ArduCopter log; the motors on channels drawn from `rng`. Returns the path,
    the channels (1-based) of motors 1-4, the PWM range."""
    log, d = flight
    chans = [int(c) + 1 for c in rng.choice(8, 4, replace=False)]
    lo, hi = 1100.0, 1900.0
    f = DataFlash()
    f.add("MSG", 1000, firmware)
    params = {"FRAME_CLASS": 1, "FRAME_TYPE": frame_type, "MOT_PWM_MIN": lo, "MOT_PWM_MAX": hi, "MOT_BAT_VOLT_MAX": 12.6}
    params.update({f"SERVO{c}_FUNCTION": 33 + m for m, c in enumerate(chans)})
    for k, v in params.items():
        f.add("PARM", 1000, k, float(v))
    f.add("ARM", 2000, 1 if armed else 0)
    t0 = 10.0
    for k in range(len(log)):
        us = int(round((t0 + log["t"][k]) * 1e6))
        g = [log["gyro_x"][k], -log["gyro_y"][k], -log["gyro_z"][k]]
        f.add("IMU", us, 0, *g, log["acc_x"][k], -log["acc_y"][k], -log["acc_z"][k])
        pwm = [0] * 14
        for m, c in enumerate(chans):
            pwm[c - 1] = int(round(lo + log[f"P{m + 1}"][k] / 255.0 * (hi - lo)))
        f.add("RCOU", us - 5, *pwm)                  # (the command before the gyro sample of its row)
        f.add("RATE", us, *(math.degrees(v) for v in g))
        for m, c in enumerate(chans):
            f.add("ESC", us, c - 1, 40.0 * log[f"P{m + 1}"][k])      # rpm: a stand-in the test knows
        if k % 10 == 0:
            f.add("BAT", us, 0, 11.9, 7.5)
            f.add("ATT", us, 0.0, math.degrees(log["roll"][k]), 0.0, -math.degrees(log["pitch"][k]), 0.0,
                  -math.degrees(log["yaw"][k]) % 360.0)
    path = d / f"f{frame_type}.bin"
    path.write_bytes(f.bytes())
    return path, chans, (lo, hi)


@pytest.mark.parametrize("frame_type", sorted(FRAMES))
def test_a_simulated_flight_written_as_arducopter_comes_back(flight, frame_type):
    rng = np.random.default_rng(100 + frame_type)
    path, chans, (lo, hi) = write(flight, rng, frame_type)
    log, _ = flight
    (t,) = read_foreign(str(path))
    assert len(t) == len(log)
    assert np.allclose(rotors(t), FRAMES[frame_type], atol=1e-4)
    assert t.meta["motor_outputs"].startswith("RCOU " + ", ".join(f"SERVO{c}" for c in chans))
    for m in range(1, 5):                        # within the microsecond of the pulse: 255 / 800 P
        assert np.allclose(t[f"P{m}"], log[f"P{m}"], atol=0.5 * 255 / (hi - lo) + 1e-6), m
        # the ESC of the motor's own output channel: 40 rpm per P unit, as written
        assert np.allclose(t[f"omega{m}"], 40.0 * log[f"P{m}"] * 2 * math.pi / 60, rtol=1e-5, atol=1e-3), m
    for a in "xyz":
        assert np.allclose(t[f"gyro_{a}"], log[f"gyro_{a}"], rtol=1e-5, atol=1e-6)
        assert np.allclose(t[f"setpoint_{a}"], log[f"gyro_{a}"], rtol=1e-4, atol=1e-5)
    assert np.allclose(t["acc_z"], log["acc_z"], rtol=1e-5)
    assert np.nanmax(np.abs(t["roll"] - log["roll"])) < 0.05       # ATT at a tenth of the rows, held
    assert t.meta["battery_cells"] == "3"


def test_a_log_that_never_armed_is_refused(flight, capsys):
    path, _, _ = write(flight, np.random.default_rng(7), 1, armed=False)
    assert main(["log", "import", str(path), str(path.with_suffix(".csv"))]) == 2
    assert "never armed" in capsys.readouterr().err
    assert not path.with_suffix(".csv").exists()
