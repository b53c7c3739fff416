"""A motor at full command while the vehicle rolls away (issue 45, "Frames"; sim/diagnose/static/pinned.py,
docs/diagnose.md "A motor at full command"), in `flightctl diagnose`'s static tier:

- a real crash: ArduPilot's LogAnalyzer example mechanical_fail.log (ArduCopter 3.1, quad X, MOT and ATT at
  10 Hz) tips over mid-flight; the motor and the time are worked out here from the log's own columns in a few
  lines; the check names that motor at that time, and says what 10 Hz cannot tell and how to log faster;
- a simulated loss: a quadrotor flown on eq. 7 and 26 by an ArduCopter-like loop (attitude P, rate PI,
  AP_MotorsMatrix's QUAD/X mixer clipped at the outputs' limits) and written as ArduCopter DataFlash, one
  rotor's thrust gone at a time, the motor and the time drawn from a seeded generator and never told to the
  diagnosis: the check names that motor within LOST_TOL_S of the drawn time. This project's own loop names a
  lost motor within 20 ms and stops it (flightctl/control/motor_loss.py), so its own log never shows a motor
  held at full command: the loop here is the firmware's that does not;
- healthy flights get no such finding: the same simulated flight without the loss, the real Betaflight
  LOG00037.BFL (punch-outs that pin all four motors at once), and the real ArduCopter 3.3 log171.bin, whose
  crash leaves motor 2 at its maximum for 14 s on its back (on the ground, not tipping).
"""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from flightctl.cli import main
from flightctl.sim.logs.dfwrite import DataFlash
from helpers.paths import DATA
from helpers.real import FLIGHTS, need

pytest.importorskip("pymavlink")
# AP_MotorsMatrix::setup_motors, MOTOR_FRAME_QUAD / MOTOR_FRAME_TYPE_X: (angle from the nose, clockwise
# positive, and the yaw factor: +1 counter-clockwise) of motors 1-4
QUAD_X = ((45, 1), (-135, 1), (-45, -1), (135, -1))
M, L, J, K = 1.6, 0.25, np.array([0.015, 0.015, 0.028]), 0.016      # kg, m, kg m^2, m (torque per thrust)
H2, TW, G = 20.0, 2.2, 9.80665                                       # dead zone (P), thrust to weight, m/s^2
H1 = TW * M * G / 4.0 / (255.0 - H2) ** 2                            # N per P^2 (eq. 26)
PWM = (1100.0, 1900.0)
RATE, TAU_MOTOR = 400, 0.03                                          # Hz, s
LOST_TOL_S = 0.15       # s: the span starts this near the drawn loss (the loop pins the motor within tens of ms)
MECH = DATA / "ardupilot" / "mechanical_fail.log"


def fly_quad(rng: np.random.Generator, lost: int | None, lost_at: float, seconds: float = 40.0):
    """Rows at RATE of (t, P (4,), gyro (3,), acc (3,), roll, pitch, yaw, roll_sp, pitch_sp, z) of a quad X: at rest
    4 s, a climb to about 15 m, hover with the pilot's slow attitude wander, a descent; rotor `lost` (1-4, or None)
    gives no thrust from `lost_at` s on. The rows end when it hits the ground."""
    ang = np.radians([a for a, _ in QUAD_X])
    x, y = L * np.cos(ang), -L * np.sin(ang)               # ours: x forward, y left (the angle is clockwise)
    s = np.array([k for _, k in QUAD_X], float)
    dt = 1.0 / RATE
    att, w, z, vz = np.zeros(3), np.zeros(3), 0.0, 0.0
    f = np.zeros(4)
    integ, integ_z = np.zeros(3), 0.0
    dist, lift, wander = np.zeros(3), 0.0, np.zeros(2)
    scale = np.ones(4)
    out = []
    for k in range(int(seconds * RATE)):
        t = k * dt
        if lost is not None and t >= lost_at:
            scale[lost - 1] = 0.0
        on = 4.0 <= t < seconds - 2.0
        climb = 0.0 if not on else (1.2 if t < 16.5 else -1.0 if t > seconds - 16.0 else 0.0)
        dist += -dist * dt / 0.5 + rng.normal(0.0, 0.04, 3) * math.sqrt(dt)        # N m, turbulent
        lift += -lift * dt / 1.0 + rng.normal(0.0, 0.6) * math.sqrt(dt)            # N
        wander += -wander * dt / 3.0 + rng.normal(0.0, 0.05, 2) * math.sqrt(dt)    # rad: the pilot's sticks
        airborne = z > 0.0 or vz > 0.0
        target = np.array([wander[0], wander[1], 0.0])
        if on:
            err = 6.0 * (target - att) - w
            integ += err * dt * airborne
            u = J * (25.0 * err + 8.0 * integ)                        # N m asked (roll, pitch, yaw)
            verr = climb - vz
            integ_z += verr * dt
            T = M * (G + 3.0 * verr + 1.5 * integ_z)
            # AP_MotorsMatrix's mixer in thrust: throttle + roll y_i + pitch x_i + yaw s_i, clipped at the outputs
            c = T / 4.0 + u[0] * y / (y @ y) - u[1] * x / (x @ x) - u[2] * s / (K * (s @ s))
            c = np.clip(c, 0.02 * H1 * (255 - H2) ** 2, H1 * (255 - H2) ** 2)
            P = H2 + np.sqrt(c / H1)
        else:
            P = np.zeros(4)
        f_cmd = np.where(P > H2, scale * H1 * (P - H2) ** 2, 0.0)
        f += (f_cmd - f) * dt / TAU_MOTOR
        thrust = float(f.sum())
        torque = np.array([y @ f, -(x @ f), -K * (s @ f)]) + dist * airborne
        if airborne:
            w = w + dt * (torque - np.cross(w, J * w)) / J
            att = att + dt * w
            vz += ((thrust + lift) * math.cos(att[0]) * math.cos(att[1]) / M - G) * dt
            z += vz * dt
            if z < 0.0:
                break
            spec = np.array([0.0, 0.0, (thrust + lift) / M])
        else:
            w, vz = np.zeros(3), (1e-6 if thrust + lift > M * G else 0.0)
            spec = np.array([G * math.sin(att[1]), -G * math.sin(att[0]), G])
        acc = spec + rng.normal(0.0, 0.05 + 1.5 * float(np.mean(P)) / 255.0, 3)      # the rotors' vibration
        out.append((t, P.copy(), w + rng.normal(0.0, 0.003, 3), acc, *att, *target[:2], z))
    return out


def write_arducopter(rows, path, rng, every: int) -> None:
    """The flight as an ArduCopter 4.x quad X's log (FRAME_CLASS 1, FRAME_TYPE 1, MOT_THST_EXPO 1 above MOT_SPIN_MIN),
    IMU, RCOU, ATT, BAT and BARO on every `every`-th row (RATE / every Hz)."""
    f = DataFlash()
    f.add("MSG", 1000, "ArduCopter V4.5.7 (1a2b3c4d)")
    params = {"FRAME_CLASS": 1, "FRAME_TYPE": 1, "MOT_PWM_MIN": PWM[0], "MOT_PWM_MAX": PWM[1], "MOT_BAT_VOLT_MAX": 16.8,
              "MOT_THST_EXPO": 1.0, "MOT_SPIN_MIN": H2 / 255.0, "MOT_SPIN_MAX": 1.0}
    params.update({f"SERVO{m}_FUNCTION": 32 + m for m in range(1, 5)})
    for k, v in params.items():
        f.add("PARM", 1000, k, float(v))
    f.add("ARM", 3_000_000, 1)
    for k, (t, P, gyro, acc, roll, pitch, yaw, roll_sp, pitch_sp, z) in enumerate(rows):
        if k % every:
            continue
        us = int(round((10.0 + t) * 1e6))
        f.add("IMU", us, 0, gyro[0], -gyro[1], -gyro[2], acc[0], -acc[1], -acc[2])       # FRD: y and z change sign
        f.add("RCOU", us - 5, *[int(round(PWM[0] + p / 255.0 * (PWM[1] - PWM[0]))) for p in P], *[0] * 10)
        amps = 1.5 + 25.0 * float(np.mean(P) / 255.0) ** 2
        f.add("BAT", us, 0, float(16.4 - 0.02 * amps - 0.004 * t + rng.normal(0.0, 0.01)), float(amps))
        f.add("ATT", us, math.degrees(roll_sp), math.degrees(roll), -math.degrees(pitch_sp), -math.degrees(pitch), 0.0,
              -math.degrees(yaw) % 360.0)
        f.add("BARO", us, 0, float(z + rng.normal(0.0, 0.05)))
    path.write_bytes(f.bytes())


def diagnose(path, tmp) -> dict:
    out = tmp / (path.stem + ".json")
    assert main(["diagnose", str(path), "--json", str(out), "--quiet"]) == 0
    return json.loads(out.read_text())


@pytest.mark.parametrize("seed, every", [(1, 10), (2, 10), (3, 40)])
def test_a_motor_lost_in_flight_is_named_at_the_time_it_was_lost(tmp_path, capsys, seed, every):
    """At 40 Hz and at ArduCopter's default 10 Hz: the drawn motor, from the drawn time, and at 10 Hz what the
    rate cannot tell."""
    rng = np.random.default_rng(4560 + seed)
    motor, lost_at = int(rng.integers(1, 5)), float(rng.uniform(20.0, 26.0))
    path = tmp_path / f"lost{seed}.bin"
    write_arducopter(fly_quad(rng, motor, lost_at), path, rng, every)
    rep = diagnose(path, tmp_path)
    full = rep["static"]["motor_at_full"]
    assert full["named"] == motor, (motor, lost_at, full)
    s = next(x for x in full["spans"] if x["motor"] == motor and not x["tumbling"])
    assert s["start_s"] == pytest.approx(lost_at, abs=LOST_TOL_S + 1.0 / (RATE / every)), (lost_at, s)
    assert s["long"] and s["held_s"] >= 0.5 and s["opposite_at_floor"] > 0.0, s
    assert f"motor {motor}'s thrust lost" in full["verdict"] and f"motor {motor} at full command" in capsys.readouterr().out
    assert (full["rate"] is not None) == (every == 40) and (full["rate"] is None or "10 Hz" in full["rate"]), full["rate"]


def test_no_motor_is_named_on_the_same_flight_without_a_loss(tmp_path):
    rng = np.random.default_rng(4560)
    path = tmp_path / "healthy.bin"
    write_arducopter(fly_quad(rng, None, 0.0), path, rng, 10)
    full = diagnose(path, tmp_path)["static"]["motor_at_full"]
    assert full["named"] is None and full["spans"] == [], full
    assert full["verdict"].startswith("none: no motor sat at full command"), full


def test_the_arducopter_3_1_crash_names_the_motor_it_tipped_toward(tmp_path, capsys):
    """mechanical_fail.log, read here from its own columns: the first row of the flight (all four motors above
    idle, past its take-off) where a motor's command reaches the log's highest, and the tilt's change over the
    next 0.2 s, which points at one rotor's side (its direction (-y, x) on the log's layout: the side that goes
    down). That is the same rotor (docs/log-import.md: its front-left motor 3 at 91.1 s), and the check names it
    from that row, and says what 10 Hz hides and how to log faster."""
    from flightctl.sim.logs import read_foreign
    (table,) = read_foreign(str(need(MECH)))
    t, roll, pitch = table["t"], table["roll"], table["pitch"]
    P = np.vstack([table[f"P{i}"] for i in range(1, 5)])
    flying = np.flatnonzero((P.min(axis=0) > 25) & (t > 20))          # armed (idle 33 of 255), past its take-off
    ceiling = P[:, flying].max()
    k0 = next(k for k in flying if P[:, k].max() >= ceiling - 0.5)
    k1 = int(np.searchsorted(t, t[k0] + 0.2))
    change = np.array([roll[k1] - roll[k0], pitch[k1] - pitch[k0]])
    x, y = (np.array([float(v.split()[c]) for v in table.meta["rotors"].split(";")]) for c in (0, 1))
    side = np.column_stack([-y, x]) / np.hypot(x, y)[:, None]
    motor = int(np.argmax(P[:, k0])) + 1
    assert int(np.argmax(side @ change)) + 1 == motor, (motor, change)
    full = diagnose(need(MECH), tmp_path)["static"]["motor_at_full"]
    assert full["named"] == motor, (motor, full)
    s = next(x for x in full["spans"] if x["motor"] == motor and not x["tumbling"])
    assert s["start_s"] == pytest.approx(t[k0], abs=0.01) and s["ceiling"] == pytest.approx(ceiling, abs=0.01), (t[k0], s)
    assert not s["long"] and "logged at 10 Hz" in full["rate"] and "whatever LOG_BITMASK says" in full["rate"], full
    assert f"motor at full command: motor {motor} at full command" in capsys.readouterr().out


@pytest.mark.parametrize("path", [DATA / "ardupilot" / "log171.bin", FLIGHTS / "betaflight" / "LOG00037.BFL"])
def test_real_flights_without_a_lost_motor_get_no_such_finding(tmp_path, path):
    """log171.bin's crash leaves motor 2 at its maximum for 14 s on its back (README.md): on the ground, where
    it does not tip; LOG00037.BFL's punch-outs pin all four motors at full throttle together."""
    from flightctl.params import Airframe
    from flightctl.sim.diagnose.data import load_file
    from flightctl.sim.diagnose.static.pinned import motor_at_full
    from flightctl.sim.logs import read_foreign
    tables = read_foreign(str(need(path)))
    files = [load_file(t, Airframe()) for t in tables]
    full = motor_at_full(files, tables, min(float(t.meta["motor_rate_hz"]) for t in tables), "")
    assert full["named"] is None and full["spans"] == [], full
