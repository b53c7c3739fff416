"""The firmware's controller read from the log (sim/logs/controller.py): the gains in physical units
predict the P term the firmware itself logged (Betaflight's axisP against its setpoint and filtered
gyro, ArduPilot's PIDR), PX4's ideal form is K times P, this project's own log gives its parameter
file's gains, and what a log cannot give is named."""
from __future__ import annotations

import json
import re

import numpy as np
import pytest

from flightctl.logfile import Table
from flightctl.params import dumps, load
from flightctl.sim.logs import controller, read_foreign
from helpers.real import FLIGHTS, need
from helpers.paths import DATA

pytest.importorskip("pyulog")


def _controller(table) -> dict:
    return controller.of_table(table)


def test_betaflight_gains_predict_its_logged_p_term():
    """LOG00037 (Betaflight 4.2): axisP / 1000 (the mixer's share) regressed on setpoint - filtered gyro (rad/s)
    below the TPA breakpoint has the header's P in physical units as its slope, within 10 % on roll and pitch."""
    from orangebox import Parser
    path = need(FLIGHTS / "betaflight" / "LOG00037.BFL")
    table = read_foreign(str(path))[0]
    c = _controller(table)
    header = Parser.load(str(path)).headers
    below_tpa = table["rc_throttle"] < (header["tpa_breakpoint"] - 1000) / 1000.0
    for ax, key in (("x", "rollPID"), ("y", "pitchPID")):
        kp = c["axes"][ax]["kp"]
        assert kp["raw"] == header[key][0] and kp["unit"] == "1/(rad/s)"
        e = table[f"setpoint_{ax}"] - table[f"gyro_f_{ax}"]
        p = table[f"pid_p_{ax}"]
        ok = np.isfinite(e) & np.isfinite(p) & below_tpa
        slope = float(e[ok] @ p[ok]) / float(e[ok] @ e[ok])
        assert abs(slope / kp["value"] - 1.0) < 0.10, (ax, slope, kp)
        assert np.corrcoef(e[ok], p[ok])[0, 1] > 0.98
    assert c["loop_hz"]["value"] == pytest.approx(1e6 / (header["looptime"] * header["pid_process_denom"]))
    assert c["filters"]["dterm_lowpass_hz"]["value"] == header["dterm_lowpass_hz"]
    assert c["axes"]["x"]["kf"]["value"] is None and c["axes"]["x"]["kf"]["raw"] == header["feedforward_weight"][0]


def test_ardupilot_gains_predict_its_logged_pidr():
    """ArduCopter 4.6's PIDR: P is ATC_RAT_RLL_P times the rate error (rad/s), on every sample."""
    from pymavlink import DFReader
    path = DATA / "ardupilot" / "backend_log_80k.bin"
    c = _controller(read_foreign(str(path))[0])
    r = DFReader.DFReader_binary(str(path))
    pidr = []
    while (m := r.recv_msg()) is not None:
        if m.get_type() == "PIDR":
            pidr.append((m.Err, m.P))
    assert len(pidr) >= 3
    kp = c["axes"]["x"]["kp"]["value"]
    for err, p in pidr:
        assert p == pytest.approx(kp * err, rel=1e-3)
    assert c["loop_hz"]["value"] == 400 and c["filters"]["gyro_lowpass_hz"]["value"] > 0
    assert c["axes"]["x"]["fltd_hz"]["value"] > 0


def test_px4_gains_are_k_times_p_and_an_old_arducopter_names_what_it_lacks():
    from pyulog import ULog
    path = need(FLIGHTS / "px4" / "quadrotor_local.ulg")
    c = _controller(read_foreign(str(path))[0])
    p = ULog(str(path), ["vehicle_status"]).initial_parameters
    for ax, name in zip("xyz", ("ROLL", "PITCH", "YAW")):
        assert c["axes"][ax]["kp"]["value"] == pytest.approx(p[f"MC_{name}RATE_K"] * p[f"MC_{name}RATE_P"], rel=1e-6)
        assert c["axes"][ax]["kd"]["value"] == pytest.approx(p[f"MC_{name}RATE_K"] * p[f"MC_{name}RATE_D"], rel=1e-6)
    assert c["loop_hz"]["value"] == p["IMU_GYRO_RATEMAX"]
    old = _controller(read_foreign(str(DATA / "ardupilot" / "log171.bin"))[0])
    assert not old["axes"] and any(u.startswith("ATC_RAT_RLL_P") for u in old["unread"])
    assert any(u.startswith("loop_hz (SCHED_LOOP_RATE") for u in old["unread"])


def test_inav_gains_predict_its_logged_p_term():
    """INAV 9.0.1 (the 10-inch's three logs): the header's P over pid.h's 31, per rad/s, over motorOutput's span
    (the share of the logged motor range a unit of it moves) predicts the logged axisP (in the motor's units,
    the reader's / 1000) regressed on setpoint - gyro: within 5 % on roll and pitch, correlation over 0.93."""
    for table in read_foreign(str(need(FLIGHTS / "inav" / "blackbox_log_2026-02-21_145057.TXT"))):
        c = _controller(table)
        assert c["firmware"] == "inav" and not any("physical scaling" in u for u in c["unread"])
        lo, hi = (float(v) for v in re.search(r"\(motor - ([\d.]+)\) / \(([\d.]+) - ", table.meta["command"]).groups())
        for ax in "xy":
            kp = c["axes"][ax]["kp"]
            e = table[f"setpoint_{ax}"] - table[f"gyro_f_{ax}"]
            p = table[f"pid_p_{ax}"]
            ok = np.isfinite(e) & np.isfinite(p)
            slope = float(e[ok] @ p[ok]) / float(e[ok] @ e[ok])
            assert abs(slope / (kp["value"] * (hi - lo) / 1000.0) - 1.0) < 0.05, (table.path, ax, slope, kp)
            assert np.corrcoef(e[ok], p[ok])[0, 1] > 0.93


def test_this_projects_log_gives_its_parameter_files_gains():
    params = load("paper-as-flown")
    n = 10
    cols = {"t": np.arange(n) * 0.01}
    c = _controller(Table("own.csv", cols, {"params": dumps(params)}, np.arange(n) + 2))
    g = params.gains
    for ax, name in zip("xyz", ("phi", "theta", "psi")):
        for k in "pid":
            assert c["axes"][ax][f"k{k}"]["value"] == pytest.approx(getattr(g, f"k{k}_{name}"))
    assert c["loop_hz"]["value"] == params.airframe.loop_hz
    assert c["filters"]["tau_rate_s"]["value"] == params.filters.tau_rate
    none = _controller(Table("bare.csv", cols, {}, np.arange(n) + 2))
    assert none["unread"] and "no parameter file" in none["unread"][0]
    assert json.loads(controller.encode(c)) == c
