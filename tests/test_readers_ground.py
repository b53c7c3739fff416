"""The ground told from the air, and a log too short to hold a flight, on real logs
(../shared/data/real/flights; docs/real-flights.md): a vehicle held still with its motors at the hover's
command is on the ground whatever the motors do (`data.at_rest`), and a 0.2 s idle snippet of a real
Betaflight log is called too short, not a dead sensor."""
from __future__ import annotations

import numpy as np
import pytest

from flightctl.cli import main
from flightctl.logfile import read_flight_log
from flightctl.params import Airframe
from flightctl.sim.identify.diagnose.data import FOREIGN_COLUMNS, IMU_COLUMNS, REST_S, all_running, load_file
from real import FLIGHTS, need, rows_and_header, write

pytest.importorskip("pyulog")


def _imported(tmp_path, path, name):
    out = tmp_path / name
    assert main(["log", "import", str(need(path)), str(out), "--quiet"]) == 0
    return out


def test_a_vehicle_held_still_with_its_motors_at_the_hovers_command_is_not_airborne(tmp_path):
    """quadrotor_local.ulg sits disarmed, motors at 0, for its first 4.9 s (on the ground: nothing holds it
    up). Its commands there are rewritten to the hover's, times a level drawn at random: a vehicle stuck
    or tied down at full thrust, as the motors alone would call flight. Its own IMU still says the ground."""
    csv = _imported(tmp_path, FLIGHTS / "px4" / "quadrotor_local.ulg", "ql.csv")
    meta, names, rows = rows_and_header(csv.read_text())
    t = np.array([float(r[0]) for r in rows])
    cols = [names.index(f"P{i}") for i in range(1, 5)]
    P = np.array([[float(r[j]) for j in cols] for r in rows]).T
    ground = np.arange(int(np.argmax(all_running(P))))       # before the motors first run
    assert t[ground[-1]] - t[ground[0]] > 4.0
    hover = float(np.median(P.mean(axis=0)[t > t[0] + 20.0]))
    rng = np.random.default_rng(35)
    level = hover * rng.uniform(0.95, 1.15, size=4)
    for k in ground:
        for j, v in zip(cols, level):
            rows[k][j] = f"{v:.3f}"
    held = write(meta, names, rows, tmp_path / "held.csv")
    f = load_file(read_flight_log(str(held), extra=FOREIGN_COLUMNS), Airframe())
    dt = float(np.median(np.diff(f.t)))
    inner = ground[(t[ground] > t[ground[0]] + REST_S) & (t[ground] < t[ground[-1]] - REST_S)]
    assert not f.airborne[inner].any()
    assert any("IMU held still" in n and "on the ground" in n for n in f.notes)
    # the flight itself is still flight: 20-85 s, a hover and its manoeuvres
    air = (f.t > t[0] + 20.0) & (f.t < t[0] + 85.0)
    assert f.airborne[air].mean() > 0.95, f.airborne[air].mean()
    assert f.airborne.sum() * dt < (t[-1] - t[0]) - 4.0


def test_an_idle_snippet_is_called_too_short_not_a_dead_sensor(tmp_path, capsys):
    """btfl_002.bbl cut 2,600 bytes after its header (as a log stopped at once): 0.2 s of frames, the motors
    at Betaflight's idle, the gyro in whole deg/s reading one value on every row of an axis (a sensor at
    rest, not a dead one)."""
    from flightctl.sim.logs import each_log
    from flightctl.sim.logs.blackbox import header_end
    data = need(FLIGHTS / "betaflight" / "btfl_002.bbl").read_bytes()
    path = tmp_path / "idle.bbl"
    path.write_bytes(data[:header_end(data) + 2600])
    (e,) = each_log(str(path))
    t = e.table
    assert t["t"].size < 120 and e.running_s < 0.2
    assert [c for c in IMU_COLUMNS if np.ptp(t[c]) == 0]        # the case: a column that never changes
    out = tmp_path / "r.json"
    assert main(["diagnose", str(path), "--json", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "too short" in err and "idle" in err and "dead" not in err, err
    assert len(err.strip().splitlines()) == 1 and not out.exists()
