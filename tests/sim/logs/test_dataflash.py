"""ArduPilot's DataFlash log through `flightctl.sim.logs.dataflash` (docs/log-import.md): a real
ArduCopter log (tests/data/ardupilot, GPL-3.0-or-later) read with what its parameters say, edited to
be what it is not (a hexacopter, a plane) and refused by name; a real ArduCopter 3.3 flight that ends
in a crash (log171.bin, CC BY-SA 3.0) read with its own field names, judged by diagnose without the
crash, and a delay drawn at random and shifted into it found; and this project's simulated flights
written as ArduCopter logs (sim/logs/dfwrite.py, read back through pymavlink) with the motor outputs,
the frame and the ESC telemetry drawn at random: every sample comes back where the log put it."""
from __future__ import annotations

import json
import math
import struct
from pathlib import Path

import numpy as np
import pytest

from flightctl.cli import main
from flightctl.logfile import read_flight_log
from flightctl.params import Airframe
from flightctl.sim.diagnose.data import load_file
from flightctl.sim.logs import each_log, read_foreign
from flightctl.sim.logs.dfwrite import DataFlash, text_log
from helpers.real import delay_fit, delayed, rows_and_header, write as write_csv
from helpers.paths import DATA

pytest.importorskip("pymavlink")
REAL = DATA / "ardupilot" / "backend_log_80k.bin"
# ArduPilot's quad frames (ArduPilot's motor-order diagrams): per motor 1-4, (x forward, y left) in arm
# lengths and the spin (+1 counter-clockwise)
S = math.sqrt(0.5)
FRAMES = {0: [(0, -1, 1), (0, 1, 1), (1, 0, -1), (-1, 0, -1)],                    # PLUS: right, left, front, back
          1: [(S, -S, 1), (-S, S, 1), (S, S, -1), (-S, -S, -1)],                  # X: FR, RL, FL, RR
          12: [(-S, -S, -1), (S, -S, 1), (-S, S, 1), (S, S, -1)],                 # BF_X: RR, FR, RL, FL
          13: [(S, -S, 1), (S, S, -1), (-S, S, 1), (-S, -S, -1)],                 # DJI_X: FR, FL, RL, RR
          14: [(S, -S, 1), (-S, -S, -1), (-S, S, 1), (S, S, -1)]}                 # CW_X: FR, RR, RL, FL
FRAMES[3] = [(x, y, -s) for x, y, s in FRAMES[1]]                                  # H: X with the spins reversed
FRAMES[2] = FRAMES[1]       # V: X's positions, its yaw factors +-0.7981 and +-1 (AP_MotorsMatrix): X's spins


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
    # a hexa or octo frame over a quad's four outputs: the outputs do not hold the frame's motors
    for name, value, words in (("FRAME_CLASS", 2.0, "SERVOn_FUNCTION assigns motors [1, 2, 3, 4]: the frame's motors 1-6"),
                               ("FRAME_CLASS", 3.0, "SERVOn_FUNCTION assigns motors [1, 2, 3, 4]: the frame's motors 1-8"),
                               ("FRAME_CLASS", 6.0, "FRAME_CLASS = 6: a helicopter"),
                               ("FRAME_CLASS", 7.0, "FRAME_CLASS = 7: a tricopter"),
                               ("FRAME_TYPE", 4.0, "FRAME_TYPE = 4: FRAME_CLASS 1, FRAME_TYPE 4 (V-tail)"),
                               ("SERVO5_FUNCTION", 37.0, "more than the frame's 4 motors")):
        path = _patched(tmp_path, name, value)
        assert main(["log", "import", str(path), str(tmp_path / "o.csv")]) == 2
        err = capsys.readouterr().err
        assert words in err and len(err.strip().splitlines()) == 1, err
    plane = tmp_path / "plane.bin"
    plane.write_bytes(REAL.read_bytes().replace(b"ArduCopter V4.6.2", b"ArduPlane V4.6.2\0"))
    assert main(["log", "import", str(plane), str(tmp_path / "o.csv")]) == 2
    assert "a fixed wing, not a multirotor" in capsys.readouterr().err


@pytest.fixture(scope="module")
def flight(tmp_path_factory):
    d = tmp_path_factory.mktemp("df")
    assert main(["sim", "step_roll", "--log", str(d / "f.csv"), "--no-plot", "--quiet", "--seed", "3"]) == 0
    return read_flight_log(d / "f.csv"), d


def write(flight, rng, frame_type: int, armed: bool = True, firmware: str = "ArduCopter V4.5.7 (1a2b3c4d)",
          pid: bool = False):
    """The flight as an ArduCopter log; the motors on channels drawn from `rng`. Returns the path,
    the channels (1-based) of motors 1-4, the PWM range. `pid`: RATE at a tenth of the rows (its default
    10 Hz) and PIDR/PIDP/PIDY on every row (LOG_BITMASK's PID bit), their Tar the gyro plus a drawn offset
    (rad/s, FRD), and ATT's DesRoll/DesPitch/DesYaw the attitude plus another."""
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
            # disarmed, ArduCopter holds its motor outputs at their lowest pulse (output_min)
            pwm[c - 1] = int(round(lo + (log[f"P{m + 1}"][k] if armed else 0.0) / 255.0 * (hi - lo)))
        f.add("RCOU", us - 5, *pwm)                  # (the command before the gyro sample of its row)
        if not pid or k % 10 == 0:
            f.add("RATE", us, *(math.degrees(v) for v in g))
        if pid:
            for name, v, off in zip(("PIDR", "PIDP", "PIDY"), g, PID_OFFSET):
                f.add(name, us, v + off, v, off, 0.0, 0.0, 0.0, 0.0)
        for m, c in enumerate(chans):
            f.add("ESC", us, c - 1, 40.0 * log[f"P{m + 1}"][k])      # rpm: a stand-in the test knows
        if k % 10 == 0:
            f.add("BAT", us, 0, 11.9, 7.5)
            att = (math.degrees(log["roll"][k]), -math.degrees(log["pitch"][k]), -math.degrees(log["yaw"][k]) % 360.0)
            des = [a + ATT_OFFSET for a in att] if pid else [0.0, 0.0, 0.0]
            f.add("ATT", us, des[0], att[0], des[1], att[1], des[2], att[2])
    path = d / f"f{frame_type}.bin"
    path.write_bytes(f.bytes())
    return path, chans, (lo, hi)


PID_OFFSET = (0.11, -0.07, 0.05)     # rad/s, FRD: what PIDR/PIDP/PIDY's Tar add to the gyro in `write(pid=True)`
ATT_OFFSET = 2.0                     # deg: what ATT's Des* add to its attitude there


def test_the_rate_pids_targets_are_the_setpoint_when_logged_faster_than_rate(flight):
    """ArduCopter 4.x with the PID bit: PIDR/PIDP/PIDY's Tar (rad/s, FRD) on every row, RATE at a tenth of them:
    the rate setpoint is the targets (in our frame), at their rate; ATT's Des* are roll_sp, pitch_sp, yaw_sp."""
    log, _ = flight
    (t,) = read_foreign(str(write(flight, np.random.default_rng(7), 1, pid=True)[0]))
    for a, off, sign in zip("xyz", PID_OFFSET, (1.0, -1.0, -1.0)):
        assert np.allclose(t[f"setpoint_{a}"], log[f"gyro_{a}"] + sign * off, rtol=1e-4, atol=1e-5), a
    assert float(t.meta["setpoint_rate_hz"]) > 5 * float(t.meta["attitude_rate_hz"])
    ok = np.isfinite(t["roll_sp"]) & np.isfinite(t["roll"])
    assert np.allclose(t["roll_sp"][ok] - t["roll"][ok], math.radians(ATT_OFFSET), atol=1e-4)
    assert np.allclose(t["pitch_sp"][ok] - t["pitch"][ok], -math.radians(ATT_OFFSET), atol=1e-4)


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


# ArduPilot's own example logs (tests/data/ardupilot/README.md): ArduCopter 3.0-3.1 text dumps of real flights
EXAMPLES = REAL.parent


@pytest.fixture(scope="module")
def quad31():
    """nan.log: ArduCopter V3.1.1 on a Pixhawk, FRAME 1 (X), IMU at 50 Hz, RCOU at 10 Hz."""
    (e,) = each_log(str(EXAMPLES / "nan.log"))
    assert e.reason is None, e.reason
    return e.table


def test_an_arducopter_3_1_quadrotor_is_read_as_its_frame_and_throttle_range_say(quad31):
    t = quad31
    assert t.meta["firmware"].startswith("ArduCopter V3.1.1")
    assert np.allclose(rotors(t), FRAMES[1], atol=1e-4)                       # FRAME 1: X, today's FRAME_TYPE 1
    assert t.meta["motor_outputs"].startswith("RCOU Chan1, Chan2, Chan3, Chan4")
    assert t.meta["command_range"] == "1022 1997"                              # RC3_MIN, RC3_MAX
    P = np.vstack([t[f"P{i}"] for i in range(1, 5)])
    # armed and idle, each motor at RC3_MIN + MOT_SPIN_ARMED (100 us): the scale of the throttle channel's range
    assert np.median(P) == pytest.approx(255 * 100 / (1997 - 1022), abs=0.01)
    assert float(t.meta["rate_hz"]) == pytest.approx(50, abs=1) and float(t.meta["motor_rate_hz"]) == pytest.approx(10, abs=0.5)
    assert "before 3.3" in t.meta["log_faster"] and "IMU_FAST" in t.meta["log_faster"]
    rest = slice(0, 100)
    assert t["acc_z"][rest].mean() == pytest.approx(9.8, abs=0.1)              # FRD's -g is our +g
    assert t["battery_v"][0] == pytest.approx(15.32, abs=0.01)                # CURR's Volt: 1532 cV
    assert t.meta["battery_cells"] == "4" and t.meta["gyro_filter"] == "biquad 30"


def test_the_arducopter_3_1_log_never_left_the_ground_and_its_attitude_estimate_diverged(quad31):
    """What the data show: with the throttle up, the gyro and the accelerometer agree that the vehicle
    rolled about 25 deg to its left, the side the motor commands (through the X layout) push it; the
    barometer never rose; the autopilot's own roll estimate (ATT) ran the other way to about 90 deg,
    and its controller pushed against that until its crash check disarmed it."""
    t = quad31
    P = np.vstack([t[f"P{i}"] for i in range(1, 5)])
    up = np.flatnonzero(P.mean(axis=0) > 30)
    a, b = up[0], up[-1]
    assert 4.0 < t["t"][b] - t["t"][a] < 6.0
    roll_gyro = np.degrees(np.sum(t["gyro_x"][a:b] * np.diff(t["t"][a:b + 1])))
    tilt = np.degrees(np.arctan2(t["acc_y"], t["acc_z"]))
    roll_acc = tilt[b - 20:b].mean() - tilt[a - 30:a].mean()
    assert -30 < roll_gyro < -20 and abs(roll_gyro - roll_acc) < 5             # the vehicle rolled left
    y = np.array([r[1] for r in rotors(t)])
    assert np.mean(y @ P[:, a:b]) < 0                                          # the motors push it left
    assert np.degrees(t["roll"][b] - t["roll"][a]) > 80                       # ATT: right, to about 90 deg
    h = t["height"]
    assert np.nanmax(np.abs(h[a:b] - np.nanmean(h[:a]))) < 0.2                # the barometer: never off the ground
    across = np.hypot(t["acc_x"], t["acc_y"])[b - 150:b].mean() / 9.80665      # the ground's push across the body
    assert 0.35 < across < 0.5
    lines = (EXAMPLES / "nan.log").read_text().splitlines()
    assert lines.index("ERR, 12, 1") + 1 == lines.index("EV, 11", lines.index("ERR, 12, 1"))  # crash check, disarmed


def test_diagnose_refuses_the_arducopter_3_1_log_and_says_how_to_log_faster(tmp_path, capsys):
    out = tmp_path / "r.json"
    assert main(["diagnose", str(EXAMPLES / "nan.log"), "--json", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "10.0 Hz" in err and "before 3.3" in err and "left the ground" in err, err
    assert not out.exists()


REFUSED = {"underpowered.log": ("LOG_BITMASK 830", "gyro (IMU) and the motor outputs"),  # ArduCopter 3.0.1
           # an octocopter (MOT's Mot1..Mot8), now a frame this reader takes: its IMU and outputs not logged
           "robert_lefebvre_octo_PM.log": ("LOG_BITMASK 830", "gyro (IMU) and the motor outputs"),
           "tradheli_brownout.log": ("a traditional helicopter", "GGain")}


@pytest.mark.parametrize("name", sorted(REFUSED))
def test_an_arducopter_3_log_is_refused_for_what_it_is(name, tmp_path, capsys):
    out = tmp_path / "o.csv"
    assert main(["log", "import", str(EXAMPLES / name), str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and all(w in err for w in REFUSED[name]), err
    assert not out.exists()


def test_the_corpus_of_ardupilot_logs_gives_one_row_per_log(tmp_path):
    table = tmp_path / "ap.md"
    assert main(["diagnose", "--corpus", str(EXAMPLES), "--table", str(table), "--jobs", "1", "--quiet"]) == 0
    rows = {r.split("|")[1].strip(): r for r in table.read_text().splitlines()
            if r.split("|")[1:2] and r.split("|")[1].strip().endswith((".log", ".bin"))}
    assert set(rows) == {p.name for p in EXAMPLES.iterdir() if p.suffix in (".log", ".bin")}
    for name, words in REFUSED.items():
        assert all(w in rows[name] for w in words), rows[name]
    assert "10.0 Hz" in rows["nan.log"] and "too short to judge" in rows["backend_log_80k.bin"]
    blind = rows["mechanical_fail.log"].split("|")        # no IMU: the static tier on ATT's time base
    assert blind[5].strip() == "static" and "LOG_BITMASK 1854" in rows["mechanical_fail.log"], blind
    judged = rows["log171.bin"].split("|")
    # the one cause named is the rotors' drag in forward flight (acc_x), which the paper's model lacks: seen since
    # rotor_drag's fit takes the gyro's offsets as nuisances (sim/causes/rotor_drag.py)
    assert judged[7].strip().startswith("rotor_drag k") and judged[10].strip() == "" and "APM:Copter V3.3-dev" in judged[2]
    assert judged[9].strip().startswith("t: roll 5, pitch 6, yaw 7, thrust 8")   # docs/log-import.md
    assert judged[5].strip() == "dynamic (static too)" and "pattern: yaw trim" in judged[6]


# log171.bin (README.md): ArduCopter 3.3-dev, QUAD/X, IMU and RCOU at 50 Hz, 2.5 min in the air; then a
# crash, and 14 s on its back with its motors running until the log ends
CRASH = EXAMPLES / "log171.bin"
G = 9.80665


def _raw(path: Path) -> dict:
    """The log's own IMU (instance 0) and RCOU rows through pymavlink: {name: (n, k) array, time in s first}."""
    from pymavlink import DFReader
    r = DFReader.DFReader_binary(str(path))
    rows = {"IMU": [], "RCOU": []}
    while (m := r.recv_match(type=list(rows))) is not None:
        fields = ("AccX", "AccY", "AccZ") if m.get_type() == "IMU" else ("Ch1", "Ch2", "Ch3", "Ch4")
        rows[m.get_type()].append([m.TimeMS * 1e-3] + [getattr(m, f) for f in fields])
    return {k: np.array(v) for k, v in rows.items()}


def test_an_arducopter_3_3_log_is_read_with_its_own_field_names_and_filters():
    (e,) = each_log(str(CRASH))
    t = e.table
    assert t.meta["firmware"] == "APM:Copter V3.3-dev (ae3192b8)"                # 3.2-3.4 named themselves APM:Copter
    assert np.allclose(rotors(t), FRAMES[1], atol=1e-4)                          # FRAME 1: X
    assert t.meta["motor_outputs"].startswith("RCOU Ch1, Ch2, Ch3, Ch4") and t.meta["command_range"] == "1000 1900"
    assert t.meta["gyro_filter"] == t.meta["acc_filter"] == "biquad 20"         # INS_GYRO_FILTER, INS_ACCEL_FILTER
    assert float(t.meta["rate_hz"]) == pytest.approx(50, abs=1) and float(t.meta["motor_rate_hz"]) == pytest.approx(50, abs=1)
    raw = _raw(CRASH)["RCOU"]
    P = np.vstack([t[f"P{i}"] for i in range(1, 5)])
    k = np.rint(np.interp(raw[:, 0], t["t"] + raw[0, 0], np.arange(t["t"].size))).astype(int)
    ok = np.abs(t["t"][k] + raw[0, 0] - raw[:, 0]) < 1e-3                      # each RCOU row at its own time
    assert ok.mean() > 0.99
    expected = np.clip(255.0 * (raw[ok, 1:] - 1000.0) / 900.0, 0.0, 255.0).T
    assert np.allclose(P[:, k[ok]], expected, atol=1e-3)


def test_the_crash_of_the_arducopter_3_3_log_is_not_taken_as_flight():
    """The rows on its back with the motors running (the accelerometer's +g along FRD's z, the rotors'
    thrust can only give -z) are left out of the air, and no row after the crash's impact (past 5 g)
    is in it; the note says how long, as the log's own data count it."""
    raw = _raw(CRASH)
    imu, rc = raw["IMU"], raw["RCOU"]
    crash = imu[np.linalg.norm(imu[:, 1:], axis=1) > 5 * G, 0][0]
    running = np.interp(imu[:, 0], rc[:, 0], (rc[:, 1:] > 1000 + 9).all(axis=1).astype(float)) > 0.5
    on_its_back = float(((imu[:, 3] > 0) & running).sum() * np.median(np.diff(imu[:, 0])))
    assert crash == pytest.approx(239.2, abs=0.1) and 13.0 < on_its_back < 15.0  # the log's own story (README.md)
    (e,) = each_log(str(CRASH))
    f = load_file(e.table, Airframe())
    t0 = imu[0, 0]
    assert f.airborne.sum() * 0.02 > 140.0 and f.t[f.airborne].max() + t0 < crash
    note = next(n for n in f.notes if "on its side or its back" in n)
    assert float(note.split(" s with")[0]) == pytest.approx(on_its_back, abs=0.5), note


def test_an_arducopter_3_log_whose_rcou_names_no_pulses_is_refused_by_name(tmp_path, capsys):
    data = CRASH.read_bytes()
    assert data.count(b"TimeMS,Ch1,Ch2,Ch3,Ch4") == 1
    edited = tmp_path / "renamed.bin"
    edited.write_bytes(data.replace(b"TimeMS,Ch1,Ch2,Ch3,Ch4", b"TimeMS,Pw1,Pw2,Pw3,Pw4"))
    assert main(["log", "import", str(edited), str(tmp_path / "o.csv")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Pw1" in err and "no output pulses" in err, err


def test_taken_as_flight_the_crash_hides_the_vehicle_from_diagnose(tmp_path, capsys, monkeypatch):
    """Without the specific-force test (data.CONTACT_ACC_Z at minus infinity) the 14 s on its back are
    airborne, and the base model's roll and pitch effectiveness are no longer told from zero: the
    dynamic tier refuses, and the report is the static tier's, which says why."""
    from flightctl.sim.diagnose import data
    monkeypatch.setattr(data, "CONTACT_ACC_Z", -np.inf)
    assert main(["diagnose", str(CRASH), "--json", str(tmp_path / "r.json"), "--quiet"]) == 0
    rep = json.loads((tmp_path / "r.json").read_text())     # the dynamic tier refused; the static tier answers
    assert rep["tier"] == "static" and rep["cause"] == "none"
    assert "does not identify the vehicle's roll and pitch effectiveness" in rep["tier_why"], rep["tier_why"]


@pytest.fixture(scope="module")
def crash_csv(tmp_path_factory):
    """log171.bin imported as this project's CSV, and its diagnosis."""
    tmp = tmp_path_factory.mktemp("log171")
    csv = tmp / "log171.csv"
    assert main(["log", "import", str(CRASH), str(csv), "--quiet"]) == 0
    out = tmp / "r.json"
    assert main(["diagnose", str(csv), "--json", str(out), "--quiet"]) == 0
    return csv, json.loads(out.read_text())


def test_diagnose_judges_the_arducopter_3_3_flight_on_a_base_model_that_its_data_confirm(tmp_path, crash_csv):
    """From the .bin as from its CSV: the same finding, the rotors' drag alone (the one term of the flight the
    paper's model lacks, in the forward-flight channel acc_x, with a drag per unit speed no rotor exceeds), on a
    base model whose roll, pitch, yaw and thrust effectiveness are positive and significant (the X layout and
    the RCOU order confirmed by the data)."""
    out = tmp_path / "r.json"
    assert main(["diagnose", str(CRASH), "--json", str(out), "--quiet"]) == 0
    report = json.loads(out.read_text())
    assert report["causes"] == crash_csv[1]["causes"]                                 # the .bin reads as its CSV
    assert [c["cause"] for c in report["causes"]] == ["rotor_drag"], report["causes"]
    assert 0.0 < report["causes"][0]["parameters"]["k"] < 1.0 and report["causes"][0]["gain"] > 0.0
    base = report["base_model"]
    for k in ("k_p", "k_q", "k_r", "k_z"):                                     # roll, pitch, yaw, thrust: positive, t >= 2
        assert base[k]["value"] > 2.0 * base[k]["stderr"], (k, base[k])
    assert 140.0 < report["data"]["airborne_s"] < 170.0
    lo, hi = report["data"]["battery_v"]
    assert 14.5 < lo < hi < 16.6                                                 # CURR: 16.5 V at rest, a 4S pack


@pytest.mark.parametrize("seed", [1, 5])
def test_a_delay_shifted_into_the_arducopter_3_3_flight_is_found_on_top_of_its_own(crash_csv, tmp_path, seed):
    """A delay of 10-150 ms drawn at random, not told to the diagnosis: the commands logged `shift` rows
    (20 ms each at 50 Hz) before the motors act on them. The first round fits it within 5 ms (10 % above
    50 ms) on top of the log's own timing; from two rows on it is also named, as actuation_delay."""
    csv, report = crash_csv
    meta, names, rows = rows_and_header(csv.read_text())
    rng = np.random.default_rng(2700 + seed)
    d = float(rng.uniform(0.010, 0.150))
    dt = float(np.median(np.diff([float(r[0]) for r in rows])))
    shift = int(round(d / dt))
    delayed(names, rows, shift)
    out = tmp_path / "d.json"
    assert main(["diagnose", str(write_csv(meta, names, rows, tmp_path / "delayed.csv")), "--json", str(out), "--quiet"]) == 0
    hidden = json.loads(out.read_text())
    expected = delay_fit(report) + shift * dt
    tolerance = max(0.005, 0.1 * shift * dt)
    assert abs(delay_fit(hidden) - expected) <= tolerance, (d, delay_fit(report), delay_fit(hidden))
    named = {c["cause"]: c["parameters"] for c in hidden["causes"]}
    if shift >= 2:
        assert abs(named["actuation_delay"]["delay"] - expected) <= tolerance, (d, named)


@pytest.mark.parametrize("frame", [0, 1, 2, 3])
def test_a_simulated_flight_written_as_an_arducopter_3_1_text_dump_comes_back(flight, frame, tmp_path):
    """ArduCopter 3.1's MOT has no time stamp: each takes the time of the IMU line before it; FRAME is the
    orientation (0 plus, 1 X, 2 V, 3 H: the V was refused whole before sim/logs/frames.py); the motors
    span RC3_MIN..RC3_MAX, drawn at random."""
    log, _ = flight
    rng = np.random.default_rng(31 + frame)
    lo = float(rng.integers(980, 1120))
    hi = float(rng.integers(1850, 2050))
    rows = [("PARM", k, float(v)) for k, v in (("FRAME", frame), ("RC3_MIN", lo), ("RC3_MAX", hi), ("LOG_BITMASK", 1982))]
    rows += [("MSG", "ArduCopter V3.1 (5c6503e2)"), ("EV", 10)]
    ms = np.round((10.0 + log["t"]) * 1000).astype(int)
    kept, pwm_rows = [], {}
    for k in np.flatnonzero(np.diff(ms, prepend=-1) > 0):
        g = (log["gyro_x"][k], -log["gyro_y"][k], -log["gyro_z"][k])
        rows.append(("IMU", ms[k], *g, log["acc_x"][k], -log["acc_y"][k], -log["acc_z"][k]))
        kept.append(k)
        if len(kept) % 4 == 1:                                  # the motors at a quarter of the IMU's rate
            pwm = [int(round(lo + log[f"P{m}"][k] / 255.0 * (hi - lo))) for m in range(1, 5)]
            rows.append(("MOT", *pwm))
            pwm_rows[ms[k]] = pwm
            rows.append(("CURR", 400, 0, 1190, 750, 5000, 0.0))
    path = tmp_path / "ac31.log"
    path.write_text(text_log(["12", "", "ArduCopter V3.1 (5c6503e2)", "Free RAM: 1000", "APM 2"], rows), newline="")
    (t,) = read_foreign(str(path))
    assert np.allclose(rotors(t), FRAMES[frame], atol=1e-4)
    assert "AP_MotorsMatrix.cpp" in t.meta["rotors_source"] and f"FRAME {frame}" in t.meta["rotors_source"]
    if frame == 2:
        assert "QUAD/V" in t.meta["rotors_source"] and "+0.7981" in t.meta["rotors_source"]
    assert t.meta["command_range"] == f"{lo:g} {hi:g}" and t.meta["firmware"] == "ArduCopter V3.1 (5c6503e2)"
    assert np.allclose(t["t"], (ms[kept] - ms[kept][0]) / 1000.0)
    for a in "xyz":
        assert np.allclose(t[f"gyro_{a}"], log[f"gyro_{a}"][kept], rtol=1e-5, atol=1e-6)
    times = np.array(sorted(pwm_rows))
    last = times[np.searchsorted(times, ms[kept], side="right") - 1]     # each row holds the last MOT at or before it
    for m in range(1, 5):
        want = 255.0 * (np.array([pwm_rows[k][m - 1] for k in last]) - lo) / (hi - lo)
        assert np.allclose(t[f"P{m}"], np.clip(want, 0, 255), atol=1e-3), m
    assert np.nanmean(t["battery_v"]) == pytest.approx(11.9)                  # CURR's Volt in cV
    assert float(t.meta["motor_rate_hz"]) < float(t.meta["rate_hz"]) / 3


def test_a_damaged_arducopter_text_dump_is_read_up_to_its_damage_or_refused_in_one_line(tmp_path, capsys):
    data = (EXAMPLES / "nan.log").read_bytes()
    rng = np.random.default_rng(5)
    for k in range(8):
        cut = int(rng.integers(2000, len(data)))
        junk = rng.integers(0, 256, int(rng.integers(1, 400)), dtype=np.uint8).tobytes()
        path, out = tmp_path / f"d{k}.log", tmp_path / f"d{k}.csv"
        path.write_bytes(data[:cut] + (junk + data[cut:] if k % 2 else b""))    # cut, or bytes pasted in
        rc = main(["log", "import", str(path), str(out), "--quiet"])
        err = capsys.readouterr().err
        assert (rc == 0 and out.exists()) or (rc == 2 and err.count("\n") == 1 and str(path) in err
                                              and not out.exists()), err


def _messages(data: bytes):
    """(offset, length, name) of each message of a binary DataFlash log, by its FMT lengths (each message
    is 0xA3 0x95, its type byte, then its fields; FMT, type 128, defines a type's length and name)."""
    fmts = {128: (89, "FMT")}
    k = 0
    while k + 3 <= len(data) and data[k:k + 2] == b"\xa3\x95" and data[k + 2] in fmts:
        length, name = fmts[data[k + 2]]
        if name == "FMT":
            fmts[data[k + 3]] = (data[k + 4], data[k + 5:k + 9].rstrip(b"\0").decode())
        yield k, length, name
        k += length


def _edited(data: bytes, drop_ev=(), pin_rcou: bool = False) -> bytes:
    """log171.bin with its EV messages of the ids `drop_ev` cut out and, with `pin_rcou`, RCOU's four
    pulses (TimeMS, Ch1..Ch4: "Ihhhh") set to 1000 us, RC3_MIN: a disarmed ArduCopter's outputs."""
    out = []
    for k, n, name in _messages(data):
        m = data[k:k + n]
        if name == "EV" and m[3] in drop_ev:
            continue
        if name == "RCOU" and pin_rcou:
            m = m[:7] + struct.pack("<4h", *[1000] * 4) + m[15:]
        out.append(m)
    return b"".join(out)


@pytest.fixture(scope="module")
def jumped(flight):
    """A logger's clock reset mid-flight: every message's TimeUS from a drawn IMU sample on moved back by a
    drawn 1-5 s. (the log read unedited, the log read jumped, the unedited rows the jumped one keeps, the jump)."""
    rng = np.random.default_rng(4545)
    path, _, _ = write(flight, rng, 1)
    data = path.read_bytes()
    walked = list(_messages(data))
    imu = [i for i, (*_, name) in enumerate(walked) if name == "IMU"]
    k = int(rng.integers(len(imu) // 4, 3 * len(imu) // 4))
    jump = float(rng.uniform(1.0, 5.0))
    out = []
    for i, (o, n, name) in enumerate(walked):
        m = data[o:o + n]
        if i >= imu[k] and name != "FMT":          # every type dfwrite writes opens with its TimeUS (Q)
            m = m[:3] + struct.pack("<Q", struct.unpack_from("<Q", m, 3)[0] - int(round(jump * 1e6))) + m[11:]
        out.append(m)
    edited = path.with_name("jumped.bin")
    edited.write_bytes(b"".join(out))
    (a,), (b,) = read_foreign(str(path)), read_foreign(str(edited))
    assert len(a) == len(imu)                          # a row per IMU sample
    t = np.concatenate([a["t"][:k], a["t"][k:] - jump])
    return a, b, np.concatenate([np.ones(k, bool), t[k:] > t[:k].max()]), jump


def test_a_clock_that_jumps_back_mid_log_drops_its_repeated_rows_and_says_so(jumped):
    """The DataFlash reader drops the gyro samples whose time repeats one already logged, counts them in a
    note with the jump, and keeps the others as they were (docs/log-import.md; the Betaflight reader's own
    case: tests/sim/logs/test_log_import.py)."""
    a, b, keep, jump = jumped
    note = next(n for n in b.meta["import_notes"].splitlines() if "backward time dropped" in n)
    assert note.startswith(f"{int((~keep).sum())} gyro samples") and f"{jump:.3g} s" in note, (note, (~keep).sum())
    assert len(b) == keep.sum() and np.all(np.diff(b["t"]) > 0)
    for c in ("gyro_x", "gyro_y", "gyro_z"):
        assert np.allclose(b[c], a[c][keep]), c


def test_a_clock_that_jumps_back_mid_log_leaves_the_kept_rows_other_streams_as_they_were(jumped):
    """The other streams (RCOU, ATT, the accelerometer) jumped back with the gyro: their repeated samples are
    dropped too (sim/logs/common.flight_text, said in a note), so no kept row holds or interpolates a sample
    logged after the jump, but for the rows within one period of a slower stream of the seam, which interpolate
    between its last sample before the jump and its first after (the time between them is what the clock lost)."""
    a, b, keep, _ = jumped
    assert any("other streams' samples" in n for n in b.meta["import_notes"].splitlines())
    seam = b["t"][np.flatnonzero(~keep)[0]]
    for c, rate in (("P1", "motor_rate_hz"), ("acc_z", "rate_hz"), ("roll", "attitude_rate_hz")):
        far = np.abs(b["t"] - seam) > 1.0 / float(b.meta[rate])
        assert np.allclose(b[c][far], a[c][keep][far], equal_nan=True), c
        assert far.sum() > 0.99 * far.size


def test_a_log_that_opens_armed_is_read_on_its_other_sources(tmp_path, capsys):
    """ArduCopter with LOG_DISARMED 0 logs from the arming on, and a log may open armed: log171.bin
    (EV 8, 25, 10 ARMED, 15 AUTO_ARMED, 28 NOT_LANDED) with its EV ARMED cut out, as such a log has it,
    is read on AUTO_ARMED, NOT_LANDED and its motor outputs, said in a note; with every EV cut out, as
    a log with neither ARM nor EV; with its outputs pinned too, on its barometer's climb and return
(tests/sim/logs/test_dfarming_height.py has the logs refused as never armed)."""
    data = CRASH.read_bytes()
    walked = list(_messages(data))
    assert sum(n for _, n, _ in walked) > 0.99 * len(data) and sum(name == "EV" for *_, name in walked) == 5
    path = tmp_path / "opens_armed.bin"
    path.write_bytes(_edited(data, drop_ev=(10,)))
    (e,) = each_log(str(path))
    assert e.reason is None, e.reason
    note = next(n for n in e.table.meta["import_notes"].splitlines() if "opens armed" in n)
    assert "EV 15 AUTO_ARMED, 28 NOT_LANDED" in note and "RCOU Ch1, Ch2, Ch3, Ch4 up to 1853" in note, note
    assert e.running_s > 140.0                                   # the whole flight, as the unedited log's
    path.write_bytes(_edited(data, drop_ev=(8, 10, 15, 25, 28)))
    (e,) = each_log(str(path))
    assert e.reason is None and e.running_s > 140.0
    # its arming events cut and its outputs pinned at their disarmed pulse: its barometer still climbs 12 m and
    # comes back (dfarming.climbed), so it is read as armed and the outputs are said to disagree with the flight
    path.write_bytes(_edited(data, drop_ev=(10, 15, 28), pin_rcou=True))
    (e,) = each_log(str(path))
    note = next(n for n in e.table.meta["import_notes"].splitlines() if "sources disagree" in n)
    assert "the motor outputs at their disarmed pulse throughout, but" in note and "m back down" in note, note


def test_the_corpus_headline_counts_airborne_multirotor_flights_only(tmp_path):
    """A corpus of the real ArduCopter 3.3 flight, it edited into a plane and into a helicopter (FRAME_CLASS
    6), and the real 4.6 log on the ground: the headline counts one airborne multirotor flight, the two
    others as logs of another vehicle, not counted, and the ground log as holding no flight."""
    from flightctl.sim.diagnose.corpus import corpus, headline
    folder = tmp_path / "c"
    folder.mkdir()
    (folder / "flight.bin").write_bytes((EXAMPLES / "log171.bin").read_bytes())
    (folder / "plane.bin").write_bytes(REAL.read_bytes().replace(b"ArduCopter V4.6.2", b"ArduPlane V4.6.2\0"))
    (folder / "heli.bin").write_bytes(_patched(tmp_path, "FRAME_CLASS", 6.0).read_bytes())
    (folder / "ground.bin").write_bytes(REAL.read_bytes())
    rows = corpus(folder, jobs=1)
    line = headline(rows)
    assert line.startswith("**1 of 1 airborne multirotor flights get a diagnosis (100 %)**"), line
    assert "1 of the 4 logs hold no flight" in line and "2 are logs of another vehicle" in line, line
