"""What is read from every real log of ../shared/data/real/flights/ (docs/log-import.md), and why a
log is refused or skipped: PX4 quadrotors as they are flown (8 outputs, 4 of them motors; motors on
UAVCAN; 10 Hz outputs and 9 Hz sensors declared), files of many logs (each log on its own), INAV,
a blackbox cut short, battery voltages and cell counts, and vehicles that are not quadrotors (a real
log edited with pyulog into a VTOL, an octocopter, a log that never armed)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from flightctl.cli import main
from flightctl.sim.logs import bbfields, each_log, read_foreign
from helpers.real import FLIGHTS, INDIFLIGHT, need

pyulog = pytest.importorskip("pyulog")
PX4 = FLIGHTS / "px4"


def rotor_signs(t, t0, t1, fc=2.0, tau=0.05):
    """Each rotor's lagged thrust against the angular accelerations (low-passed at fc): True where its
    roll and pitch effects have the signs of its position (right rolls left, rear pitches nose down)."""
    from scipy import signal
    time, fs = t["t"], float(t.meta["rate_hz"])
    P = np.vstack([t[f"P{i}"] for i in range(1, 5)])
    fly = (P > 20).all(axis=0) & (time > t0) & (time < t1)
    lag = math.exp(-1.0 / (fs * tau))
    thrust = signal.lfilter([1 - lag], [1, -lag], P, axis=1) ** 2
    rotors = [[float(v) for v in r.split()] for r in t.meta["rotors"].split(";")]
    sos = signal.butter(2, fc, fs=fs, output="sos")
    ok = []
    for axis, sign_of in (("gyro_x", lambda x, y: y), ("gyro_y", lambda x, y: -x)):
        acc = np.gradient(t[axis], time)
        X = np.column_stack([signal.sosfiltfilt(sos, f)[fly] for f in thrust] + [np.ones(fly.sum())])
        coef = np.linalg.lstsq(X, signal.sosfiltfilt(sos, acc)[fly], rcond=None)[0][:4]
        ok += [np.sign(c) == np.sign(sign_of(x, y)) for c, (x, y, _) in zip(coef, rotors)]
    return ok


def test_a_px4_quadrotor_with_eight_outputs_is_read_as_four_motors():
    path = need(PX4 / "quadrotor_local.ulg")
    (t,) = read_foreign(str(path))
    u = pyulog.ULog(str(path))
    p = u.initial_parameters
    # the motors are the outputs the log's own functions name, and those are the ones that move
    assert [p[f"PWM_MAIN_FUNC{i}"] for i in range(1, 5)] == [101, 102, 103, 104]
    assert t.meta["motor_outputs"].startswith("actuator_outputs[0] outputs 1, 2, 3, 4 (PWM_MAIN_FUNC")
    ao = u.get_dataset("actuator_outputs", 0).data
    assert all(np.std(ao[f"output[{i}]"]) > 50 for i in range(4)) and all(np.ptp(ao[f"output[{i}]"]) == 0 for i in range(4, 8))
    # the layout is PX4's own description (CA_ROTOR*: FRD, KM > 0 counter-clockwise) in our frame
    rotors = [[float(v) for v in r.split()] for r in t.meta["rotors"].split(";")]
    for i, (x, y, s) in enumerate(rotors):
        arm = math.hypot(p[f"CA_ROTOR{i}_PX"], p[f"CA_ROTOR{i}_PY"])
        assert (x, y, s) == pytest.approx((p[f"CA_ROTOR{i}_PX"] / arm, -p[f"CA_ROTOR{i}_PY"] / arm,
                                           math.copysign(1, p[f"CA_ROTOR{i}_KM"])), abs=1e-4)
    assert all(rotor_signs(t, 20.0, 85.0))             # the data agree with that layout
    assert float(t.meta["motor_rate_hz"]) == pytest.approx(10.0, abs=0.5)
    assert "SDLOG_PROFILE bit 4" in t.meta["import_notes"]
    assert t.meta["battery_cells"] == "8" and "BAT1_N_CELLS" in t.meta["battery_cells_source"]
    v = t["battery_v"][np.isfinite(t["battery_v"])]
    assert 8 * 3.3 < v.min() and v.max() < 8 * 4.35


def test_a_px4_quadrotor_on_uavcan_has_its_motors_and_rotor_speeds_found():
    (t,) = read_foreign(str(need(PX4 / "esc_status_log.ulg")))
    assert t.meta["motor_outputs"].startswith("actuator_outputs[1] outputs 1, 2, 3, 4")
    assert "UAVCAN" in t.meta["motor_outputs"] and t.meta["command_range"] == "0 8191"
    P = np.vstack([t[f"P{i}"] for i in range(1, 5)])
    flying = (P > 60).all(axis=0)
    assert flying.mean() > 0.8                          # 40 s of its 44 in the air
    w = np.vstack([t[f"omega{i}"] for i in range(1, 5)])
    assert np.nanmedian(w[:, flying]) * 60 / (2 * math.pi) == pytest.approx(2300, rel=0.25)   # esc_status rpm
    assert "sensor_combined gyro at 8.9 Hz: too slow" in t.meta["import_notes"]
    assert "SDLOG_PROFILE" in t.meta["log_faster"]     # what diagnose's refusal quotes
    assert t.meta["battery_cells"] == "6"


def _six_escs(u):
    """esc_status_log.ulg made a hexacopter (MAV_TYPE 13, PX4's CA_ROTOR0..5 of a hexa X): outputs 5 and 6
    and ESCs 4 and 5 are given the first two motors' at another scale each, so that a sixth motor read from
    the wrong column shows."""
    u.initial_parameters["MAV_TYPE"] = 13
    u.initial_parameters["CA_ROTOR_COUNT"] = 6
    for i, deg in enumerate((90, -90, -30, 150, 30, -150)):     # FRD positions at 0.3 m, spins alternating
        u.initial_parameters[f"CA_ROTOR{i}_PX"] = 0.3 * math.cos(math.radians(deg))
        u.initial_parameters[f"CA_ROTOR{i}_PY"] = 0.3 * math.sin(math.radians(deg))
        u.initial_parameters[f"CA_ROTOR{i}_KM"] = 0.05 * (-1) ** i
    for d in u.data_list:
        if d.name == "actuator_outputs" and d.multi_id == 1:
            d.data["output[4]"] = (d.data["output[0]"] * 0.97).astype(d.data["output[4]"].dtype)
            d.data["output[5]"] = (d.data["output[1]"] * 0.94).astype(d.data["output[5]"].dtype)
            d.data["noutputs"] = np.maximum(d.data["noutputs"], 6).astype(d.data["noutputs"].dtype)
        if d.name == "esc_status":
            d.data["esc[4].esc_rpm"] = (d.data["esc[0].esc_rpm"] * 1.1).astype(d.data["esc[4].esc_rpm"].dtype)
            d.data["esc[5].esc_rpm"] = (d.data["esc[1].esc_rpm"] * 0.8).astype(d.data["esc[5].esc_rpm"].dtype)
            d.data["esc_count"] = np.full_like(d.data["esc_count"], 6)


def test_a_px4_hexacopters_six_escs_are_read_as_omega1_to_omega6(tmp_path):
    """PX4's esc_status for N motors (issue 45): the six ESCs' esc_rpm are omega1..omega6 in the motors'
    order, each from its own ESC (the scales 1.1 and 0.8 given to ESCs 4 and 5 come back on omega5, omega6)."""
    (t,) = read_foreign(str(_edited_from(tmp_path, "esc_status_log.ulg", "hexa_escs.ulg", _six_escs)))
    assert "esc[0,1,2,3,4,5].esc_rpm" in t.meta["omega_source"] and "motors 1-6" in t.meta["omega_source"]
    assert "omega7" not in t.columns
    P = np.vstack([t[f"P{i}"] for i in range(1, 7)])
    w = np.vstack([t[f"omega{i}"] for i in range(1, 7)])
    flying = (P[:4] > 60).all(axis=0) & np.isfinite(w).all(axis=0) & (w[:2] > 50).all(axis=0)
    assert flying.mean() > 0.5
    assert np.median(w[4, flying] / w[0, flying]) == pytest.approx(1.1, abs=0.01)
    assert np.median(w[5, flying] / w[1, flying]) == pytest.approx(0.8, abs=0.01)
    assert np.nanmedian(w[:4, flying]) * 60 / (2 * math.pi) == pytest.approx(2300, rel=0.25)   # the real ESCs'
    # outputs 5 and 6 are motors 5 and 6 (UAVCAN's 0-8191 on 0-255: a scale is kept)
    assert np.median(P[4, flying] / P[0, flying]) == pytest.approx(0.97, abs=0.01)
    assert np.median(P[5, flying] / P[1, flying]) == pytest.approx(0.94, abs=0.01)


def test_a_hexacopters_figure_draws_its_six_motors(tmp_path):
    """sim/logs/figure.py draws every motor's command and rotor speed, not P1-P4 only (issue 45)."""
    pytest.importorskip("matplotlib")
    from flightctl.sim.logs import read_figure
    (t,) = read_foreign(str(_edited_from(tmp_path, "esc_status_log.ulg", "hexa_escs.ulg", _six_escs)))
    fig = read_figure(t)
    commands, speeds = fig.axes[1], fig.axes[-1]
    assert [ln.get_label() for ln in commands.lines] == [f"P{i}" for i in range(1, 7)]
    assert [ln.get_label() for ln in speeds.lines] == [f"omega{i}" for i in range(1, 7)]
    assert np.nanmax(speeds.lines[4].get_ydata()) == pytest.approx(1.1 * np.nanmax(speeds.lines[0].get_ydata()), rel=0.02)


def test_a_px4_log_with_zero_rotor_speeds_says_so():
    (t,) = read_foreign(str(need(PX4 / "roboto-test.ulg")))
    assert "esc_status rpm are all zero" in t.meta["import_notes"] and "omega1" not in t.columns


def _edited(tmp_path, name, change):
    return _edited_from(tmp_path, "quadrotor_local.ulg", name, change)


def _edited_from(tmp_path, source, name, change):
    """A real ULog of PX4/ changed by `change` and written by pyulog."""
    u = pyulog.ULog(str(need(PX4 / source)))
    change(u)
    out = tmp_path / name
    u.write_ulog(str(out))
    return out


def _never_armed(u):
    for d in u.data_list:
        if d.name == "actuator_armed":
            d.data["armed"][:] = 0
        if d.name == "vehicle_status":
            d.data["arming_state"][:] = 1


def _never_armed_on_the_bench(u):
    """Never armed, and its layout not set up (a board on the bench): CA_ROTOR1_PX/PY gone. The never-armed
    check comes first: the layout of a vehicle that never flew is no reason to give."""
    _never_armed(u)
    for k in ("CA_ROTOR1_PX", "CA_ROTOR1_PY"):
        u.initial_parameters.pop(k)


@pytest.mark.parametrize("name, change, words", [
    ("vtol.ulg", lambda u: u.initial_parameters.update(MAV_TYPE=22), "MAV_TYPE = 22: a VTOL"),
    # eight rotors declared, four outputs assigned (a whole octocopter is read: sim/logs/frames.py)
    ("octo.ulg", lambda u: u.initial_parameters.update(CA_ROTOR_COUNT=8), "assign motors [1, 2, 3, 4]: motors 1-8 are needed"),
    ("dodeca.ulg", lambda u: u.initial_parameters.update(CA_ROTOR_COUNT=14), "CA_ROTOR_COUNT = 14"),
    ("plane.ulg", lambda u: u.initial_parameters.update(CA_AIRFRAME=1), "CA_AIRFRAME = 1: a fixed wing"),
    ("hexa_x.ulg", lambda u: u.initial_parameters.update(PWM_MAIN_FUNC5=105, PWM_MAIN_FUNC6=106), "than the layout's 4"),
    ("unarmed.ulg", _never_armed, "never armed"),
    ("unarmed_no_layout.ulg", _never_armed_on_the_bench, "never armed")])
def test_a_real_px4_log_edited_into_another_vehicle_is_refused_by_name(tmp_path, capsys, name, change, words):
    path = _edited(tmp_path, name, change)
    out = tmp_path / "out.csv"
    assert main(["log", "import", str(path), str(out)]) == 2
    err = capsys.readouterr().err
    assert words in err and len(err.strip().splitlines()) == 1, err
    assert not out.exists()


def test_a_file_of_44_logs_reads_each_on_its_own():
    entries = each_log(str(need(FLIGHTS / "betaflight" / "btfl_all.bbl")))
    assert len(entries) == 44
    header_only = [e.index for e in entries if e.reason and e.reason.startswith("header only")]
    assert len(header_only) == 37 and 4 not in header_only
    four = entries[3]
    assert four.table is not None and four.seconds == pytest.approx(145, abs=3) and four.flight
    assert [e.index for e in entries if e.flight] == [4, 12]
    # log 12 starts with one frame 19.7 s before the others (dropped as junk): its motors were logged at the
    # loop's 500 Hz, not at the 112 Hz that its rows over a span with that gap would say
    twelve = entries[11].table
    assert float(twelve.meta["motor_rate_hz"]) == pytest.approx(500, rel=0.02)
    assert float(twelve.meta["rate_hz"]) == pytest.approx(500, rel=0.02) and "log_faster" not in twelve.meta
    v = four.table["battery_v"][np.isfinite(four.table["battery_v"])]
    assert four.table.meta["battery_cells"] == "4" and 4 * 2.9 < v.min() and v.max() < 4 * 4.3     # sags to 3 V a cell on punch-outs


def test_log_import_of_a_file_of_many_logs_says_which_hold_a_flight(tmp_path, capsys):
    path = need(FLIGHTS / "betaflight" / "btfl_all.bbl")
    assert main(["log", "import", str(path), str(tmp_path / "o.csv"), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "2 hold a flight (4: 145 s" in err and "--index" in err
    assert "header only" in err and "logs 2-3, 5-11" in err
    assert main(["log", "import", str(path), str(tmp_path / "o.csv"), "--index", "2", "--quiet"]) == 2
    assert "header only" in capsys.readouterr().err


def test_inav_logs_are_read_with_their_own_fields():
    entries = each_log(str(need(FLIGHTS / "inav" / "blackbox_log_2026-02-21_145057.TXT")))
    assert [round(e.seconds) for e in entries] == [2, 16, 8] and all(e.table is not None for e in entries)
    for e in entries:
        t = e.table
        assert t.meta["format"] == "inav blackbox" and t.meta["gyro_source"].startswith("gyroRaw")
        assert t["acc_z"][:50].mean() == pytest.approx(9.8, abs=0.5)
        v = t["battery_v"][np.isfinite(t["battery_v"])]
        assert t.meta["battery_cells"] == "4" and 15.9 < v.min() and v.max() < 16.1     # vbat in 0.01 V
        assert not e.flight                          # the motors never all ran: no flight in these logs
    assert "setpoint_x" in entries[2].table.columns and "rc_throttle" in entries[2].table.columns


def test_a_blackbox_cut_short_is_read_up_to_the_damage(tmp_path):
    data = need(INDIFLIGHT / "LOG00230.BFL").read_bytes()
    cut = tmp_path / "cut.BFL"
    cut.write_bytes(data[:-722])                     # what a crash or a power loss leaves
    (whole,) = read_foreign(str(INDIFLIGHT / "LOG00230.BFL"))
    (t,) = read_foreign(str(cut))
    assert len(whole) - 10 < len(t) < len(whole)
    assert "cut short" in t.meta["import_notes"] and f"byte {len(data) - 722}" in t.meta["import_notes"].replace(
        "byte 1789", "byte 1789")
    np.testing.assert_array_equal(t["gyro_x"][:1000], whole["gyro_x"][:1000])


def test_betaflight_voltages_are_in_their_packs_range():
    for name, cells, lo, hi in (("LOG00037.BFL", 6, 17.0, 23.0), ("btfl_002.bbl", 4, 13.0, 16.8)):
        (t,) = read_foreign(str(need(FLIGHTS / "betaflight" / name)))
        v = t["battery_v"][np.isfinite(t["battery_v"])]
        assert lo < v.min() and v.max() < hi and t.meta["battery_cells"] == str(cells), name
    # Betaflight before 4.0 logs 0.1 V (Blackbox Explorer's reading by version): a 2S pack at 7.4 V, not 0.7
    assert bbfields.battery_scale("betaflight", (3, 5, 7))[0] * 74 == pytest.approx(7.4)
    assert bbfields.battery_scale("betaflight", (4, 2, 0))[0] * 740 == pytest.approx(7.4)


def test_the_junk_rows_before_a_long_gap_are_dropped():
    (t,) = read_foreign(str(need(FLIGHTS / "betaflight" / "btfl_002.bbl")))
    assert "11 rows before a 17.47 s gap" in t.meta["import_notes"]
    assert np.diff(t["t"]).max() < 1.0 and t["battery_v"][np.isfinite(t["battery_v"])].min() > 13.0


def test_rotor_speeds_from_erpm_and_the_debug_modes():
    """Betaflight 4.3+'s eRPM[] and the DSHOT_RPM_TELEMETRY debug mode hold eRPM / 100: rpm = 100 eRPM
    / (poles / 2); RPM_FILTER holds the rotation in Hz. A frame drawn at random, read back."""
    rng = np.random.default_rng(5)
    erpm = rng.uniform(50, 400, (20, 4))
    poles = int(rng.choice([12, 14]))
    names = ["time", "gyroADC[0]", "gyroADC[1]", "gyroADC[2]", "accSmooth[0]", "accSmooth[1]", "accSmooth[2]"]
    names += [f"motor[{i}]" for i in range(4)] + [f"eRPM[{i}]" for i in range(4)] + [f"debug[{i}]" for i in range(4)]
    a = np.zeros((20, len(names)))
    a[:, 0] = np.arange(20) * 1000.0
    a[:, 6] = 2048
    a[:, 11:15] = erpm
    a[:, 15:19] = erpm / 7.0
    head = {"Firmware revision": "Betaflight 4.4.2 (abc) STM32F7X2", "motor_poles": poles, "motorOutput": [158, 2047]}
    imp = bbfields.imported("x.bbl", head, names, a, [])
    assert np.allclose(imp.streams["omega"].values.T, erpm * 100 / (poles / 2) * 2 * math.pi / 60)
    assert imp.meta["motor_poles"] == str(poles)
    for mode, scale in ((bbfields.DSHOT_RPM_TELEMETRY, 100 / (14 / 2) * 2 * math.pi / 60), (bbfields.RPM_FILTER, 2 * math.pi)):
        b = a.copy()
        b[:, 11:15] = 0
        imp = bbfields.imported("x.bbl", {"Firmware revision": "Betaflight 4.2.0", "debug_mode": mode}, names, b, [])
        assert np.allclose(imp.streams["omega"].values.T, erpm / 7.0 * scale), mode
        assert "debug" in imp.meta["omega_source"]
