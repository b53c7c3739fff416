"""Logs without an accelerometer (issue 42, part 2: Betaflight 3.x racers fly with it switched off) get
the dynamic tier on the gyro and the motors, the thrust named as unanswered: a real log whose
accelerometer is zeroed gives the roll, pitch and yaw effectiveness it gives with it, within their
uncertainty, and a blackbox log without accSmooth fields is read, not refused."""
from __future__ import annotations

import copy

import numpy as np
import pytest

from flightctl import params as paramfile
from flightctl.logfile import read_flight_log
from flightctl.sim.diagnose.basemodel import NO_THRUST, identify
from flightctl.sim.diagnose.data import NO_ACCELEROMETER
from flightctl.sim.diagnose.rotorspeed import rotor_speed_lag
from flightctl.sim.diagnose.verdict import _files, diagnose
from flightctl.sim.logs import bbfields, read_foreign
from flightctl.sim.logs.common import flight_text
from helpers.real import FLIGHTS, need

A = paramfile.load(None).airframe
QUIET = lambda *_: None


def _zeroed(tab):
    out = copy.copy(tab)
    out.columns = dict(tab.columns)
    for c in ("acc_x", "acc_y", "acc_z"):
        out.columns[c] = np.zeros_like(tab[c])
    return out


def _slopes(tab):
    """Each axis' effectiveness at the median command, d(rate_dot)/dP = 2 k (P_med - h2), and its error
    (the value per P^2 depends on h2, which the thrust channel helps to place: the slope does not)."""
    files = _files([tab], A, [], QUIET)
    vehicle, notes = identify(files, 12.0, QUIET, rotor_speed_lag(files))
    r = vehicle.identification
    arm = r["median_P"]["value"] - r["h2"]["value"]
    return {k: (2 * r[k]["value"] * arm, 2 * r[k]["stderr"] * arm) for k in ("k_p", "k_q", "k_r")}, r, notes


@pytest.fixture(scope="module")
def ar8():
    return read_foreign(str(need(FLIGHTS / "betaflight" / "LOG00037.BFL")))[0]


def test_a_zeroed_accelerometer_gives_the_same_roll_pitch_and_yaw_effectiveness(ar8):
    with_acc, _, _ = _slopes(ar8)
    without, report, notes = _slopes(_zeroed(ar8))
    for k in ("k_p", "k_q", "k_r"):
        (a, ea), (b, eb) = with_acc[k], without[k]
        assert b > 2 * eb, (k, b, eb)                        # identified on the gyro alone
        assert abs(a - b) < 2 * np.hypot(ea, eb), (k, with_acc[k], without[k])
    assert report["k_z"].get("unanswered") and NO_THRUST in notes, (report["k_z"], notes)


def test_a_zeroed_accelerometer_reaches_the_dynamic_tier_and_says_what_it_cannot_answer(ar8):
    d = diagnose([_zeroed(ar8)], A, progress=QUIET)
    rep = d.report()
    assert rep["tier"] == "dynamic", rep.get("tier_why")
    assert any(NO_ACCELEROMETER in n for n in rep["notes"]), rep["notes"]
    assert rep["base_model"]["k_z"]["unanswered"]
    assert np.isfinite(rep["rmse_base"]) and rep["rmse_base"] > 0
    # the drag on the accelerometer is not judged, not scored with a gain of 0 (issue 42 part 2)
    why = {e["cause"]: e["why"] for e in rep["not_judged"]}
    assert "no accelerometer" in why.get("rotor_drag", ""), rep["not_judged"]
    assert "rotor_drag" not in {c["cause"] for c in rep["candidates"]}


def test_a_blackbox_log_without_acc_fields_is_read_with_empty_accelerometer_columns(tmp_path):
    rng = np.random.default_rng(3)
    names = ["time", "gyroADC[0]", "gyroADC[1]", "gyroADC[2]"] + [f"motor[{i}]" for i in range(4)]
    a = np.zeros((400, len(names)))
    a[:, 0] = np.arange(400) * 1000.0
    a[:, 1:4] = rng.normal(0, 20, (400, 3))
    a[:, 4:8] = rng.uniform(1100, 1500, (400, 4))
    imp = bbfields.imported("x.bbl", {"Firmware revision": "Betaflight 3.1.5 (4646f9d) OMNIBUSF4",
                                      "motorOutput": [1000, 2000]}, names, a, [])
    path = tmp_path / "x.csv"
    path.write_text(flight_text(imp))
    tab = read_flight_log(path)
    assert np.isnan(tab["acc_z"]).all() and np.isfinite(tab["gyro_x"]).all()
    assert "accelerometer" in tab.meta["import_notes"]
