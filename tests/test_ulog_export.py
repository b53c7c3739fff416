"""`flightctl log export`: a simulated flight's CSV as ULog, read back with pyulog (PX4's own reader)
and compared with the CSV, signs of the frame change included."""
from __future__ import annotations

import math

import numpy as np
import pytest

from flightctl import __version__
from flightctl.cli import main as cli
from flightctl.logfile import read_flight_log
from flightctl.params import load
from flightctl.plans.plan import Move, Plan
from flightctl.sim.flights.run import fly
from flightctl.sim.flights.scenarios import scenario

pyulog = pytest.importorskip("pyulog")


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """A 7 s flight (3150 rows) with positive roll, pitch and yaw steps, exported by the command."""
    d = tmp_path_factory.mktemp("ulog")
    plan = Plan([Move(0.0, "alt", 1.0, 2.0), Move(3.0, "roll", math.radians(6)),
                 Move(4.5, "pitch", math.radians(6)), Move(5.5, "yaw", math.radians(20))], 7.0, "signs")
    fly(scenario(plan), load(None), d / "f.csv", seed=1)
    assert cli(["log", "export", str(d / "f.csv"), str(d / "f.ulg")]) == 0
    return read_flight_log(d / "f.csv", extra=("true_roll",)), pyulog.ULog(str(d / "f.ulg"))


def euler(q):
    """Z-Y-X Euler angles of quaternions (w, x, y, z)."""
    w, x, y, z = q
    roll = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = np.arcsin(np.clip(2 * (w * y - z * x), -1, 1))
    yaw = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return roll, pitch, yaw


def topic(ulog, name):
    return ulog.get_dataset(name).data


def test_main_topics_have_every_row_with_the_csv_times(exported):
    csv, ulog = exported
    assert len(csv) > 1000
    for name in ("sensor_combined", "vehicle_attitude", "vehicle_attitude_setpoint", "actuator_outputs",
                 "vehicle_local_position", "battery_status"):
        d = topic(ulog, name)
        assert len(d["timestamp"]) == len(csv), name
        ts = d["timestamp"].astype(float) * 1e-6
        assert np.allclose(np.diff(ts), np.diff(csv["t"]), atol=1e-6)
    # the range only on rows where an echo arrived (about 45 Hz)
    sonar = topic(ulog, "distance_sensor")
    echo = np.isfinite(csv["range"])
    assert 100 < len(sonar["timestamp"]) == echo.sum()
    assert np.allclose(sonar["current_distance"], csv["range"][echo], rtol=1e-6)
    assert set(sonar["orientation"]) == {25}


def test_values_in_ned_frd(exported):
    csv, ulog = exported
    att = topic(ulog, "vehicle_attitude")
    roll, pitch, yaw = euler([att[f"q[{i}]"] for i in range(4)])
    assert np.allclose(roll, csv["roll"], atol=1e-5)            # roll keeps its sign
    assert np.allclose(pitch, -csv["pitch"], atol=1e-5)         # our nose-down is their nose-up
    wrap = (yaw + csv["yaw"] + np.pi) % (2 * np.pi) - np.pi
    assert np.allclose(wrap, 0.0, atol=1e-5)
    assert roll.max() > math.radians(4) and pitch.min() < -math.radians(4)   # the steps are there
    sp = topic(ulog, "vehicle_attitude_setpoint")
    assert np.allclose(sp["roll_body"], csv["roll_sp"], atol=1e-6)
    assert np.allclose(sp["pitch_body"], -csv["pitch_sp"], atol=1e-6)
    imu = topic(ulog, "sensor_combined")
    assert np.allclose(imu["gyro_rad[0]"], csv["gyro_x"], rtol=1e-6, atol=1e-6)
    assert np.allclose(imu["gyro_rad[1]"], -csv["gyro_y"], rtol=1e-6, atol=1e-6)
    assert np.allclose(imu["accelerometer_m_s2[2]"], -csv["acc_z"], rtol=1e-6)   # -g at rest, FRD
    pos = topic(ulog, "vehicle_local_position")
    assert np.allclose(pos["z"], -csv["alt"], atol=1e-6)
    out = topic(ulog, "actuator_outputs")
    params = ulog.initial_parameters
    assert np.allclose(out["output[0]"], csv["P1"] / 255 * 1e6 / params["FC_ESC_PWM_HZ"], rtol=1e-5)
    assert 1000 < np.median(out["output[0]"]) < 2000      # an ESC pulse in microseconds


def test_parameters_and_version(exported):
    """Every parameter under PX4's 16-character limit, each named once, and the information message
    `flightctl_params` gives each short name's full name back."""
    csv, ulog = exported
    params, ref = ulog.initial_parameters, load(None)
    assert all(len(name) <= 16 for name in params)
    names = dict(pair.split("=") for pair in ulog.msg_info_dict["flightctl_params"].split(";"))
    full = {v: params[k] for k, v in names.items()}
    assert full["M"] == pytest.approx(ref.airframe.M, rel=1e-6)
    assert full["gains.kp_phi"] == pytest.approx(ref.gains.kp_phi, rel=1e-6)
    assert full["filters.alpha_roll_pitch"] == pytest.approx(ref.filters.alpha_roll_pitch, rel=1e-6)
    assert len(names) == len(full) == len(vars(ref.airframe)) + len(vars(ref.gains)) + len(vars(ref.filters))
    assert params["MAV_TYPE"] == 2 and params["CA_ROTOR_COUNT"] == 4
    info = ulog.msg_info_dict
    assert info["ver_sw"] == csv.meta["software"]
    major, minor, patch, kind = ulog.get_version_info()
    assert f"{major}.{minor}.{patch}" == __version__ and kind == 255      # a release


def test_bad_input_is_one_line(tmp_path, capsys):
    bad = tmp_path / "bad.csv"
    bad.write_text("t,P1\n0,1\n")
    assert cli(["log", "export", str(bad), str(tmp_path / "x.ulg")]) == 2
    err = capsys.readouterr().err
    assert "missing column" in err and len(err.strip().splitlines()) == 1
    assert cli(["log", "export", str(bad), str(tmp_path / "x.csv")]) == 2
    assert not (tmp_path / "x.ulg").exists()


def test_flight_review_topics(exported):
    """vehicle_status (armed, a mission), vehicle_angular_velocity (the gyro, FRD), vehicle_rates_setpoint
    (the rate the PD commands: kp/kd times the angle error) and actuator_motors (P / 255)."""
    csv, ulog = exported
    status = topic(ulog, "vehicle_status")
    assert set(status["arming_state"]) == {2} and set(status["nav_state"]) == {3}
    assert len(status["timestamp"]) == pytest.approx(csv["t"][-1], abs=1.5)        # one a second
    w = topic(ulog, "vehicle_angular_velocity")
    assert np.allclose(w["xyz[0]"], csv["gyro_x"], atol=1e-6) and np.allclose(w["xyz[2]"], -csv["gyro_z"], atol=1e-6)
    sp = topic(ulog, "vehicle_rates_setpoint")
    g = load(None).gains
    assert np.allclose(sp["roll"], g.kp_phi / g.kd_phi * (csv["roll_sp"] - csv["roll"]), rtol=1e-5, atol=1e-6)
    assert np.allclose(sp["pitch"], -g.kp_theta / g.kd_theta * (csv["pitch_sp"] - csv["pitch"]), rtol=1e-5, atol=1e-6)
    motors = topic(ulog, "actuator_motors")
    assert np.allclose(motors["control[3]"], csv["P4"] / 255.0, atol=1e-6)


def test_an_exported_log_reads_back_with_the_same_samples(exported, tmp_path):
    """sim -> export -> import: every sample within the ULog's float32 quantisation, the range on its
    own rows, the vehicle the paper's + layout, and diagnose reads it."""
    from flightctl.sim.logs import read_foreign
    csv, ulog = exported
    path = tmp_path / "f.ulg"
    ulog.write_ulog(str(path))                     # (pyulog writes back what it read: the same file)
    (back,) = read_foreign(str(path))
    assert len(back) == len(csv)
    for c in ("P1", "P2", "P3", "P4", "gyro_x", "gyro_y", "gyro_z", "acc_x", "acc_y", "acc_z", "battery_v", "roll",
              "pitch", "alt"):
        assert np.allclose(back[c], csv[c], rtol=1e-6, atol=1e-5), c
    assert np.array_equal(np.isfinite(back["range"]), np.isfinite(csv["range"]))
    rotors = [[float(v) for v in r.split()] for r in back.meta["rotors"].split(";")]
    assert rotors == [[1, 0, -1], [0, 1, 1], [-1, 0, -1], [0, -1, 1]]          # motor 1 North, clockwise
    assert back.meta["command"].startswith("P = 255 actuator_motors")
