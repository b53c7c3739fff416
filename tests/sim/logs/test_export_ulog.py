"""`flightctl log export`: a simulated flight's CSV as ULog, read back with pyulog (PX4's own reader)
and compared with the CSV, signs of the frame change included."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from flightctl import __version__
from flightctl.cli import main as cli
from flightctl.logfile import FLIGHT_COLUMNS, MAG_COLUMNS, read_flight_log
from flightctl.params import load
from flightctl.plans.plan import Move, Plan
from flightctl.sim.flights.run import fly
from flightctl.sim.flights.scenarios import scenario
from helpers.real import FLIGHTS, need

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


def test_an_exported_log_read_as_px4s_has_the_same_samples(exported, tmp_path):
    """sim -> export of PX4's topics alone (`px4_only`: as another vehicle's PX4 log, without what makes
    it flightctl's own) -> PX4's reading of it: every sample within the ULog's float32 quantisation,
    the range on its own rows, the vehicle the paper's + layout."""
    from flightctl.sim.logs import read_foreign
    from flightctl.sim.logs.export import export
    csv, _ = exported
    export(csv.path, tmp_path / "px4.ulg", px4_only=True)
    ulog = pyulog.ULog(str(tmp_path / "px4.ulg"))
    assert "flightctl_columns" not in ulog.msg_info_dict and "flightctl_log" not in {d.name for d in ulog.data_list}
    path = tmp_path / "f.ulg"
    ulog.write_ulog(str(path))                     # (pyulog writes back what it read: the same file)
    (back,) = read_foreign(str(path))
    assert back.meta["vehicle"] == "foreign"
    assert len(back) == len(csv)
    for c in ("P1", "P2", "P3", "P4", "gyro_x", "gyro_y", "gyro_z", "acc_x", "acc_y", "acc_z", "battery_v", "roll",
              "pitch", "alt"):
        assert np.allclose(back[c], csv[c], rtol=1e-6, atol=1e-5), c
    assert np.array_equal(np.isfinite(back["range"]), np.isfinite(csv["range"]))
    rotors = [[float(v) for v in r.split()] for r in back.meta["rotors"].split(";")]
    assert rotors == [[1, 0, -1], [0, 1, 1], [-1, 0, -1], [0, -1, 1]]          # motor 1 North, clockwise
    assert back.meta["command"].startswith("P = 255 actuator_motors")


def _same_columns(a, b, what: str) -> None:
    """Log b has log a's columns, in order, and each column's values: t to the microsecond (the CSV's
    %.6f), every other value to float32's precision (half its last place: 2^-24 of the value, ULog's
    float fields), empty cells where a has them."""
    assert list(b.columns) == list(a.columns), what
    assert len(b) == len(a) > 100, what
    for c in a.columns:
        x, y = a[c], b[c]
        assert np.array_equal(np.isnan(x), np.isnan(y)), (what, c)
        ok = np.isfinite(x)
        tol = 0.5e-6 if c == "t" else 2.0 ** -24 * np.abs(x[ok])
        assert np.all(np.abs(y[ok] - x[ok]) <= tol), (what, c, float(np.max(np.abs(y[ok] - x[ok]))))


def test_export_and_import_are_inverses_on_every_column(exported, tmp_path, capsys):
    """CSV -> ULog -> CSV (`log export`, `log import`): every column of the contract (formats.md's table,
    the setpoints and the magnetometer included) and the simulator's truth come back row for row, and
    the header lines as they were; the file says it is flightctl's own, and the PX4 topics that hold
    the setpoints and the magnetometer hold them in PX4's frames and units."""
    from flightctl.sim.logs.export import TRUTH
    csv_path = Path(exported[0].path)
    assert cli(["log", "export", str(csv_path), str(tmp_path / "f.ulg")]) == 0
    assert cli(["log", "import", str(tmp_path / "f.ulg"), str(tmp_path / "back.csv")]) == 0
    a = read_flight_log(csv_path, extra=TRUTH)
    b = read_flight_log(tmp_path / "back.csv", extra=TRUTH)
    assert set(FLIGHT_COLUMNS + MAG_COLUMNS + TRUTH) == set(a.columns)         # the flight logs every column
    for c in ("roll_sp", "pitch_sp", "yaw_sp", "alt_sp", "mag_x", "mag_y", "mag_z"):
        assert np.nanmax(np.abs(a[c])) > 0, c                                    # (something to lose)
    _same_columns(a, b, "sim")
    assert b.meta == a.meta
    ulog = pyulog.ULog(str(tmp_path / "f.ulg"))
    assert ulog.msg_info_dict["sys_name"] == "flightctl"
    mag = topic(ulog, "vehicle_magnetometer")
    assert np.allclose(mag["magnetometer_ga[1]"], -a["mag_y"] * 1e4, rtol=1e-6)     # Gauss, FRD
    sp = topic(ulog, "vehicle_local_position_setpoint")
    assert np.allclose(sp["z"], -a["alt_sp"], atol=1e-6)


@pytest.mark.parametrize("log", ["px4/roboto-test.ulg", "betaflight/LOG00037.BFL"])
def test_an_imported_log_comes_back_whole_through_the_ulog(tmp_path, log):
    """A real flight imported (its extra columns: the current, the rate setpoint, the sticks, the PID
    terms, the filtered gyro; the estimates empty, the attitude setpoint where PX4 logs it), exported and imported
    again: the same columns, the same header lines."""
    from flightctl.sim.logs.common import EXTRA
    src = need(FLIGHTS / log)
    assert cli(["log", "import", str(src), str(tmp_path / "a.csv"), "--quiet"]) == 0
    assert cli(["log", "export", str(tmp_path / "a.csv"), str(tmp_path / "a.ulg")]) == 0
    assert cli(["log", "import", str(tmp_path / "a.ulg"), str(tmp_path / "b.csv"), "--quiet"]) == 0
    a = read_flight_log(tmp_path / "a.csv", extra=EXTRA, min_rows=10)
    b = read_flight_log(tmp_path / "b.csv", extra=EXTRA, min_rows=10)
    assert {"current", "setpoint_x"} <= set(a.columns)
    assert np.isfinite(a["roll_sp"]).any() == log.startswith("px4")   # PX4's vehicle_attitude_setpoint
    _same_columns(a, b, log)
    assert b.meta == a.meta


def test_diagnose_reads_its_own_ulog_as_the_csv(exported, tmp_path):
    """diagnose's reading of the exported ULog is the CSV's table (the project's vehicle, not another
    one's: no `# vehicle: foreign`), so both give one diagnosis."""
    from flightctl.sim.diagnose.cli import read_logs
    csv_path = Path(exported[0].path)
    assert cli(["log", "export", str(csv_path), str(tmp_path / "f.ulg")]) == 0
    (a,) = read_logs([str(csv_path)], None, lambda *m: None)
    (b,) = read_logs([str(tmp_path / "f.ulg")], None, lambda *m: None)
    assert "vehicle" not in b.meta and b.meta == a.meta
    _same_columns(a, b, "diagnose")


def test_diagnose_of_its_own_ulog_is_the_csvs(exported, tmp_path, capsys):
    """The whole command: `diagnose F.ulg` names what `diagnose F.csv` names, with the same figures."""
    csv_path = Path(exported[0].path)
    assert cli(["log", "export", str(csv_path), str(tmp_path / "f.ulg")]) == 0
    reports = []
    for log in (csv_path, tmp_path / "f.ulg"):
        assert cli(["diagnose", str(log), "--json", str(tmp_path / "r.json"), "--quiet"]) == 0
        # each log's step responses and predictions name the file they were measured on
        reports.append(json.loads((tmp_path / "r.json").read_text().replace(json.dumps(str(log))[1:-1], "LOG")))
    for r in reports:
        for s in r.get("steps", []):
            s.pop("file")
    a, b = ({k: v for k, v in r.items() if k not in ("runtime_s", "data", "notes")} for r in reports)
    assert a == b and a["rmse_base"] > 0
