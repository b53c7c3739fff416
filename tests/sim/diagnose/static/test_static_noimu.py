"""The static tier of a log without a gyro or accelerometer (docs/diagnose.md, "Static tier"; docs/log-import.md,
"ArduPilot"): ArduCopter's LOG_BITMASK without its IMU bit logs the attitude (ATT) and the motor outputs at
10 Hz. The reader takes ATT's samples as the rows (`common.time_base`), the gyro and acc columns empty and
`# imu: none: ...` saying why; the static tier's hover rows come from the attitude's rates and a steady
logged height.

- the real tests/data/ardupilot/mechanical_fail.log (ArduCopter 3.1: ATT and MOT without time stamps, put
  on the clock of its GPS fixes' board time) reaches the static tier through `flightctl diagnose`, with the
  dynamic tier's refusal and the LOG_BITMASK advice, and its imported CSV gives the same findings;
- a simulated flight with a weak motor drawn from a seeded generator, written as ArduCopter DataFlash
  without IMU messages (sim/logs/dfwrite.py's `without`), has that motor named and sized through ATT's time
  base, as the same flight with its IMU does (tests/sim/diagnose/static/test_static_sim.py);
- the contract: an IMU column empty on every row is read only with the `# imu:` line, and one empty on a
  few rows is bad input.
"""
from __future__ import annotations

import json

import numpy as np
import pytest

from flightctl.cli import main
from flightctl.errors import InputError
from flightctl.logfile import read_flight_log

pytest.importorskip("pymavlink")

from test_static_sim import AP_FROM_SIM, arducopter, diagnose, fly  # noqa: E402
from helpers.paths import DATA

LOG = DATA / "ardupilot" / "mechanical_fail.log"
NAMED = ("yaw trim", "centre of mass", "centre of mass and yaw trim") + tuple(f"weak motor {m}" for m in range(1, 5))


@pytest.fixture(scope="module")
def tmp(tmp_path_factory):
    return tmp_path_factory.mktemp("static_noimu")


@pytest.fixture(scope="module")
def real(tmp):
    out = tmp / "mf.json"
    assert main(["diagnose", str(LOG), "--json", str(out), "--quiet"]) == 0
    return json.loads(out.read_text())


def test_the_attitude_is_the_time_base_on_the_gps_clock(tmp):
    csv = tmp / "mf.csv"
    assert main(["log", "import", str(LOG), str(csv), "--quiet"]) == 0
    t = read_flight_log(csv)
    assert t.meta["imu"].startswith("none: the gyro (IMU) was not logged: LOG_BITMASK 1854 lacks bit 7")
    assert all(np.isnan(t[c]).all() for c in ("gyro_x", "gyro_z", "acc_z"))
    dt = np.diff(t["t"])
    # two ATT for each 5 Hz GPS fix, spread over the interval between fixes: 10 Hz, none at the same time
    assert np.median(dt) == pytest.approx(0.1, abs=0.002) and dt.min() > 0.05, (np.median(dt), dt.min())
    assert 105.0 < t["t"][-1] < 115.0                       # 551 fixes over 110 s of the board's clock
    assert np.isfinite(t["roll"]).all() and np.isfinite(t["P1"]).all()


def test_the_real_log_without_an_imu_reaches_the_static_tier(real):
    assert real["tier"] == "static" and real["cause"] == "none" and real["candidates"] == []
    why = real["tier_why"]
    assert "no gyro or accelerometer logged" in why and "LOG_BITMASK 1854 lacks bit 7 (IMU, 128); add 128" in why, why
    st = real["static"]
    assert st["rates"]["sensors_hz"] == pytest.approx(10, abs=0.5) and st["rates"]["motors_hz"] == pytest.approx(10, abs=0.5)
    h = st["hover"]
    assert 0.0 < h["thrust_share"] < 1.0 and h["thrust_share_stderr"] < 0.2 * h["thrust_share"], h
    assert "no IMU" in h["acc_z_source"]
    # docs/diagnose.md: its steady-height rows are a forward flight tilted ~25 degrees: the thrust check fails
    assert not h["passed"] and h["acc_z"] > 1.05 * 9.80665, h
    share, err = np.array(st["motors"]["share"]), np.array(st["motors"]["stderr"])
    assert np.all(share > 0) and share.mean() == pytest.approx(1.0, abs=1e-3)
    near = np.all(np.abs(share - 1.0) <= 3.0 * err)
    assert near or st["pattern"]["verdict"] in NAMED, st["pattern"]
    assert st["not_judged"]["vibration"] == "neither VIBE nor an accelerometer in the log"
    # its pack is a 4S (FS_BATT_VOLTAGE 14 V, 3.5 V a cell) resting at 16.91 V: 4 cells, not ceil(16.91 / 4.2) = 5
    assert st["battery"]["cells"] == 4 and st["battery"]["resistance"]["passed"], st["battery"]


def test_the_imported_csv_gives_the_same_static_findings(tmp, real):
    csv = tmp / "mf2.csv"
    assert main(["log", "import", str(LOG), str(csv), "--quiet"]) == 0
    out = tmp / "mf2.json"
    assert main(["diagnose", str(csv), "--json", str(out), "--quiet"]) == 0
    rep = json.loads(out.read_text())
    assert rep["tier"] == "static" and rep["static"] == real["static"]


@pytest.mark.parametrize("seed", [1, 2])
def test_a_weak_motor_is_named_through_the_attitudes_time_base(tmp, seed):
    rng = np.random.default_rng(3900 + seed)
    motor, scale = int(rng.integers(1, 5)), float(rng.uniform(0.75, 0.92))
    log = fly(tmp, f"weak{seed}", f"motor_weak:motor={motor},scale={scale:.4f}")
    baro = log["alt"] + rng.normal(0.0, 0.1, len(log))     # a barometer's noise on the flight's altitude
    rep = diagnose(arducopter(log, tmp / f"weak{seed}.bin", baro=baro, imu=False), tmp)
    assert rep["tier"] == "static" and "lacks bit 7 (IMU, 128)" in rep["tier_why"], rep["tier_why"]
    st = rep["static"]
    ap = AP_FROM_SIM.index(motor) + 1
    p = st["pattern"]
    assert p["verdict"] == f"weak motor {ap}", (motor, ap, scale, p)
    fit = next(f for f in p["hypotheses"] if f["hypothesis"] == f"weak motor {ap}")
    assert fit["thrust_scale"] == pytest.approx(scale, abs=0.03), (scale, fit)
    assert st["hover"]["passed"], st["hover"]


def test_an_imu_column_is_empty_on_every_row_or_on_none(tmp, capsys):
    csv = tmp / "mf3.csv"
    assert main(["log", "import", str(LOG), str(csv), "--quiet"]) == 0
    text = csv.read_text()
    (tmp / "no_line.csv").write_text("".join(line for line in text.splitlines(keepends=True)
                                             if not line.startswith("# imu:")))
    capsys.readouterr()
    out = tmp / "no_line.json"
    assert main(["diagnose", str(tmp / "no_line.csv"), "--json", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "'# imu: none ...' line" in err and not out.exists(), err
    lines = text.splitlines()
    header = next(i for i, line in enumerate(lines) if not line.startswith("#"))
    col = lines[header].split(",").index("gyro_x")
    row = lines[header + 5].split(",")
    row[col] = "0.01"                                      # one gyro cell among empty ones
    lines[header + 5] = ",".join(row)
    (tmp / "one_cell.csv").write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError) as e:
        read_flight_log(tmp / "one_cell.csv")
    assert "column 'gyro_x'" in str(e.value) and "an empty cell" in str(e.value), e.value


def test_what_docs_say_of_the_failure_is_in_the_data(tmp):
    """docs/log-import.md: at 91.1 s the front-left motor 3 is commanded to its highest at once, yet the
    vehicle pitches nose down and rolls left (towards it), then falls about 95 m in 15 s."""
    csv = tmp / "mf4.csv"
    assert main(["log", "import", str(LOG), str(csv), "--quiet"]) == 0
    t = read_flight_log(csv, extra=("height",))
    P = np.vstack([t[f"P{i}"] for i in range(1, 5)])
    k = int(np.argmax(np.abs(np.diff(P, axis=1)).max(axis=0) > 50.0)) + 1   # the first jump of a command
    assert t["t"][k] == pytest.approx(91.1, abs=0.15) and int(np.argmax(P[:, k])) == 2, (t["t"][k], P[:, k])
    assert P[2, k] >= P[2].max() - 1.0                      # motor 3 at its highest of the flight
    after = (t["t"] > t["t"][k]) & (t["t"] < t["t"][k] + 1.0)
    assert np.degrees(t["pitch"][k + 2]) > np.degrees(t["pitch"][k]) + 5.0       # nose further down (ours: +)
    assert np.degrees(t["roll"][after]).min() < -60.0                            # rolled to its left
    h = t["height"]
    fall = h[k] - h[(t["t"] > t["t"][k] + 14.0) & (t["t"] < t["t"][k] + 16.0)].min()
    assert 80.0 < fall < 110.0, fall


def test_a_log_with_neither_imu_nor_attitude_is_refused_naming_both(tmp, capsys):
    from flightctl.sim.logs.dfwrite import DataFlash
    f = DataFlash(without=("IMU", "ATT"))
    f.add("MSG", 1000, "ArduCopter V4.5.7 (1a2b3c4d)")
    for k, v in {"FRAME_CLASS": 1, "FRAME_TYPE": 1, "LOG_BITMASK": 1024, "MOT_PWM_MIN": 1000, "MOT_PWM_MAX": 2000}.items():
        f.add("PARM", 1000, k, float(v))
    for k in range(200):
        f.add("RCOU", 2000 + 100_000 * k, *([1500] * 4 + [0] * 10))
    path = tmp / "blind.bin"
    path.write_bytes(f.bytes())
    capsys.readouterr()
    assert main(["log", "import", str(path), str(tmp / "blind.csv")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "lacks bit 7 (IMU, 128)" in err and "nor ATT" in err, err
    assert not (tmp / "blind.csv").exists()
