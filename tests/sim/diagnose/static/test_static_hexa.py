"""A hexacopter's weak motor found by the static tier (issue 45, item 5): a hexacopter flown here and
written as ArduCopter DataFlash at ArduCopter's default log rates (IMU 25 Hz; RCOU, BAT and ATT 10 Hz),
with a weak motor drawn at random (which one and how weak, from a seeded generator, never told to the
diagnosis): `diagnose` reads its frame (FRAME_CLASS 2, FRAME_TYPE 1: AP_MotorsMatrix's HEXA/X), the
dynamic tier refuses it by name (its model is a quadrotor's), and the static tier names that motor with
its thrust for its command within 3 % of the drawn scale; on the flight without one it names none.

This project's simulator flies its own quadrotor only (sim/world: the paper's four rotors), so the
hexacopter is flown by the loop below on the same physics the static tier reads, written out with none
of the diagnosis's code: a rigid body (eq. 7 without the gyroscopic terms), thrust f = h1 (P - h2)^2 per
rotor (eq. 26) through a first-order motor lag, reaction torque k f with the rotor's spin, ArduPilot's
hexa X mixer (AP_MotorsMatrix::setup_motors, MOTOR_FRAME_HEXA / MOTOR_FRAME_TYPE_X: motor angles and
yaw factors) in thrust (MOT_THST_EXPO 1), an attitude and climb-rate loop with integrators that find the
hover's trim, a turbulent torque and lift (Ornstein-Uhlenbeck) and vibration on the accelerometer.
"""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from flightctl.cli import main
from flightctl.sim.logs.dfwrite import DataFlash

pytest.importorskip("pymavlink")
# AP_MotorsMatrix::setup_motors, MOTOR_FRAME_HEXA, MOTOR_FRAME_TYPE_X: (angle from the nose, clockwise
# positive, and the yaw factor: +1 counter-clockwise) of motors 1-6
HEXA_X = ((90, -1), (-90, 1), (-30, -1), (150, 1), (30, 1), (-150, -1))
M, L, J, K = 2.0, 0.30, np.array([0.030, 0.030, 0.055]), 0.016       # kg, m, kg m^2, m (torque per thrust)
H2, TW, G = 20.0, 2.2, 9.80665                                       # dead zone (P), thrust to weight, m/s^2
H1 = TW * M * G / 6.0 / (255.0 - H2) ** 2                            # N per P^2 (eq. 26)
PWM = (1100.0, 1900.0)
RATE, IMU_EVERY, SLOW_EVERY = 400, 16, 40                            # Hz; 25 Hz and 10 Hz
TAU_MOTOR = 0.03                                                      # s


def fly_hexa(rng: np.random.Generator, scale: np.ndarray, seconds: float = 75.0):
    """Rows at RATE of (t, P (6,), gyro (3,), acc (3,), roll, pitch, yaw, climb) of a hexacopter whose
    rotors give `scale` (6,) of eq. 26's thrust: at rest 6 s, a climb to 2 m, hover with the pilot's
    slow attitude wander, a descent and a landing."""
    ang = np.radians([a for a, _ in HEXA_X])
    x, y = L * np.cos(ang), -L * np.sin(ang)               # ours: x forward, y left (the angle is clockwise)
    s = np.array([k for _, k in HEXA_X], float)
    n = int(seconds * RATE)
    dt = 1.0 / RATE
    att, w, z, vz = np.zeros(3), np.zeros(3), 0.0, 0.0
    f = np.zeros(6)
    integ, integ_z = np.zeros(3), 0.0
    dist, lift = np.zeros(3), 0.0
    wander = np.zeros(2)
    out = []
    for k in range(n):
        t = k * dt
        on = 6.0 <= t < seconds - 3.0
        climb = 0.0 if not on else (0.6 if t < 9.5 else -0.5 if t > seconds - 8.0 else 0.0)
        dist += -dist * dt / 0.5 + rng.normal(0.0, 0.06, 3) * math.sqrt(dt)        # N m, turbulent
        lift += -lift * dt / 1.0 + rng.normal(0.0, 0.8) * math.sqrt(dt)            # N
        wander += -wander * dt / 3.0 + rng.normal(0.0, 0.05, 2) * math.sqrt(dt)    # rad: the pilot's sticks
        airborne = z > 0.0 or vz > 0.0
        if on:
            target = np.array([wander[0], wander[1], 0.0])
            rate_sp = 6.0 * (target - att)
            err = rate_sp - w
            integ += err * dt * airborne
            u = J * (25.0 * err + 8.0 * integ)                        # N m asked (roll, pitch, yaw)
            verr = climb - vz
            integ_z += verr * dt
            T = M * (G + 3.0 * verr + 1.5 * integ_z)
            # AP_MotorsMatrix's mixer in thrust: throttle + roll y_i + pitch x_i + yaw s_i
            c = (T / 6.0 + u[0] * y / (y @ y) - u[1] * x / (x @ x) - u[2] * s / (K * (s @ s)))
            c = np.clip(c, 0.02 * H1 * (255 - H2) ** 2, H1 * (255 - H2) ** 2)
            P = H2 + np.sqrt(c / H1)
        else:
            P = np.zeros(6)
        f_cmd = np.where(P > H2, scale * H1 * (P - H2) ** 2, 0.0)
        f += (f_cmd - f) * dt / TAU_MOTOR
        thrust = float(f.sum())
        torque = np.array([y @ f, -(x @ f), -K * (s @ f)]) + dist * airborne
        if airborne:
            w = w + dt * (torque - np.cross(w, J * w)) / J
            att = att + dt * w
            az = (thrust + lift) * math.cos(att[0]) * math.cos(att[1]) / M - G
            vz += az * dt
            z += vz * dt
            if z < 0.0:
                z, vz, w, att[:2] = 0.0, 0.0, np.zeros(3), 0.0
            spec = np.array([0.0, 0.0, (thrust + lift) / M])
        else:
            w, vz = np.zeros(3), 0.0
            if thrust + lift > M * G:
                vz = 1e-6
            spec = np.array([G * math.sin(att[1]), -G * math.sin(att[0]), G])
        spin = float(np.mean(P)) / 255.0
        acc = spec + rng.normal(0.0, 0.05 + 1.5 * spin, 3)            # the rotors' vibration
        gyro = w + rng.normal(0.0, 0.003, 3)
        out.append((t, P.copy(), gyro, acc, att[0], att[1], att[2], vz, f.copy()))
    return out


C_OMEGA = H1 * 200.0 ** 2 / 1200.0 ** 2    # N s^2: eq. 27's f = c Omega^2, 1200 rad/s at P = H2 + 200


def write_arducopter(rows, path, rng, esc: bool = False):
    """The flight as an ArduCopter 4.x hexacopter's log at its default rates (FRAME_CLASS 2, FRAME_TYPE 1,
    SERVO1-6_FUNCTION 33-38, the thrust curve declared as eq. 26: MOT_THST_EXPO 1 above MOT_SPIN_MIN); with
    `esc`, each motor's ESC telemetry too (ESC instances 0-5 on outputs 1-6, RPM at 10 Hz: the speed its
    thrust turns, eq. 27, with 1 % noise)."""
    f = DataFlash()
    f.add("MSG", 1000, "ArduCopter V4.5.7 (1a2b3c4d)")
    params = {"FRAME_CLASS": 2, "FRAME_TYPE": 1, "MOT_PWM_MIN": PWM[0], "MOT_PWM_MAX": PWM[1],
              "MOT_BAT_VOLT_MAX": 16.8, "MOT_THST_EXPO": 1.0, "MOT_SPIN_MIN": H2 / 255.0, "MOT_SPIN_MAX": 1.0}
    params.update({f"SERVO{m}_FUNCTION": 32 + m for m in range(1, 7)})
    for k, v in params.items():
        f.add("PARM", 1000, k, float(v))
    f.add("ARM", 3_000_000, 1)
    for k, (t, P, gyro, acc, roll, pitch, yaw, _, thrusts) in enumerate(rows):
        us = int(round((10.0 + t) * 1e6))
        if k % IMU_EVERY == 0:       # FRD: y and z change sign
            f.add("IMU", us, 0, gyro[0], -gyro[1], -gyro[2], acc[0], -acc[1], -acc[2])
        if k % SLOW_EVERY == 0:
            pwm = [int(round(PWM[0] + p / 255.0 * (PWM[1] - PWM[0]))) for p in P] + [0] * 8
            amps = 1.5 + 25.0 * float(np.mean(P) / 255.0) ** 2
            f.add("RCOU", us - 5, *pwm)
            f.add("BAT", us, 0, float(16.4 - 0.02 * amps - 0.004 * t + rng.normal(0.0, 0.01)), float(amps))
            f.add("ATT", us, 0.0, math.degrees(roll), 0.0, -math.degrees(pitch), 0.0, -math.degrees(yaw) % 360.0)
            if esc:
                for i, fi in enumerate(thrusts):
                    rpm = math.sqrt(max(fi, 0.0) / C_OMEGA) * 60.0 / (2.0 * math.pi) * (1.0 + rng.normal(0.0, 0.01))
                    f.add("ESC", us + 10 + i, i, float(rpm))
    path.write_bytes(f.bytes())
    return path


def diagnose(path, tmp) -> dict:
    out = tmp / (path.stem + ".json")
    assert main(["diagnose", str(path), "--json", str(out), "--quiet"]) == 0
    return json.loads(out.read_text())


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_hexacopters_weak_motor_drawn_at_random_is_named_with_its_size(tmp_path, seed):
    rng = np.random.default_rng(4500 + seed)
    motor, size = int(rng.integers(1, 7)), float(rng.uniform(0.75, 0.92))
    scale = np.ones(6)
    scale[motor - 1] = size
    rep = diagnose(write_arducopter(fly_hexa(rng, scale), tmp_path / f"hexa{seed}.bin", rng), tmp_path)
    assert rep["tier"] == "static" and "quadrotor's" in rep["tier_why"] and "6 rotors" in rep["tier_why"]
    st = rep["static"]
    assert "HEXA/X" in st["layout"]["source"] and "AP_MotorsMatrix.cpp" in st["layout"]["source"]
    p = st["pattern"]
    assert p["verdict"] == f"weak motor {motor}", (motor, size, p)
    fit = next(f for f in p["hypotheses"] if f["hypothesis"] == f"weak motor {motor}")
    assert fit["thrust_scale"] == pytest.approx(size, abs=0.03), (size, fit)


def test_nothing_is_named_on_the_hexacopter_without_a_weak_motor(tmp_path, capsys):
    rng = np.random.default_rng(4500)
    rep = diagnose(write_arducopter(fly_hexa(rng, np.ones(6)), tmp_path / "hexa0.bin", rng), tmp_path)
    assert "    frame: ArduPilot's HEXA/X (FRAME_CLASS 2, FRAME_TYPE 1" in capsys.readouterr().out   # the text report
    st = rep["static"]
    assert st["pattern"]["verdict"] == "none", st["pattern"]
    assert np.allclose(st["motors"]["share"], 1.0, atol=0.03), st["motors"]
    assert st["hover"]["passed"] and st["hover"]["thrust_share"] == pytest.approx(1.0 / TW, rel=0.05), st["hover"]


def test_a_hexacopters_rotor_speeds_name_its_weak_motor_by_its_speed_per_command(tmp_path):
    """The six ESCs' RPM (ArduPilot's ESC message, one instance per motor output) read for a hexacopter
    (they were read for quads only: "ESC telemetry of 6 motors not read"), through the static tier's
    N-motor path: the speed-per-command curve over six rotors and the weak motor told by its speed. Motor
    and scale drawn from a seeded generator; the speed gain is sqrt(scale) (eq. 27: f = c Omega^2)."""
    rng = np.random.default_rng(4545)
    motor, size = int(rng.integers(1, 7)), float(rng.uniform(0.70, 0.90))
    scale = np.ones(6)
    scale[motor - 1] = size
    rep = diagnose(write_arducopter(fly_hexa(rng, scale), tmp_path / "hexa_esc.bin", rng, esc=True), tmp_path)
    st = rep["static"]
    speeds = st["pattern"]["rotor_speeds"]
    assert speeds is not None and len(speeds["speed_gain"]) == 6, st["pattern"]
    weak = speeds["weak_motor"]
    assert weak["motor"] == motor, (motor, size, speeds)
    assert weak["speed_gain"] == pytest.approx(math.sqrt(size), abs=0.02), (size, weak)
    assert weak["thrust_scale"] == pytest.approx(size, abs=0.04), (size, weak)
