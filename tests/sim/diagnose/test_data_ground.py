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
from flightctl.sim.diagnose.data import FOREIGN_COLUMNS, IMU_COLUMNS, REST_S, SMOOTH_S, all_running, load_file
from helpers.real import FLIGHTS, need, rows_and_header, write
from helpers.paths import DATA

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


def _edited(table, **columns):
    """The table with some columns replaced (a seeded edit of a real log's imported rows)."""
    import dataclasses
    return dataclasses.replace(table, columns={**table.columns, **columns}, meta=dict(table.meta))


def test_an_accelerometer_logged_z_down_is_found_at_rest_and_turned():
    """INDIflight logs can hold an accelerometer that reads -g on z at rest (an INDIflight hover was
    refused as "0.0 s of airborne data": every row a contact force). The shipped INDIflight throw
    (indiflight/LOG00230.BFL, 6 s still before its throw) with its accelerometer's z reversed is found
    so from gravity's direction at rest, and read as the unedited log; one whose gravity lies along x
    (its x and z swapped) is refused as not in the body frame, naming the column."""
    from flightctl.errors import InputError
    from flightctl.sim.logs import read_foreign
    (table,) = read_foreign(str(need(FLIGHTS / "indiflight" / "LOG00230.BFL")))
    whole = load_file(table, Airframe())
    assert whole.airborne.sum() * 0.002 > 5.0 and not any("gravity" in n for n in whole.notes)
    down = load_file(_edited(table, acc_z=-table["acc_z"]), Airframe())
    note = next(n for n in down.notes if "gravity's -z" in n)
    z = float(note.split("m/s^2")[0].split(", ")[-1])
    assert z == pytest.approx(-9.69, abs=0.1), note                  # what the log's rest reads
    assert np.array_equal(down.airborne, whole.airborne) and np.allclose(down.acc, whole.acc)
    with pytest.raises(InputError, match="column 'acc_z': the accelerometer is not in the body frame"):
        load_file(_edited(table, acc_x=table["acc_z"], acc_z=table["acc_x"]), Airframe())


def test_motors_spinning_on_the_ground_that_shake_the_accelerometer_are_not_flight(tmp_path):
    """A quad on the ground with its motors up shakes its accelerometer more than its gyro (a Betaflight
    4.4 log: the gyro moving under 0.0015 rad/s, the specific force 0.06-0.11 m/s^2, taken for 8 s of
    flight). quadrotor_local.ulg's first 4.9 s on the ground, its commands set to the hover's and its
    specific force shaken along z by a slow swing whose size (0.06-0.11 m/s^2 in 1 s, averaged over
    0.5 s) is drawn from a seeded generator: still on the ground; the flight still flight."""
    csv = _imported(tmp_path, FLIGHTS / "px4" / "quadrotor_local.ulg", "ql.csv")
    meta, names, rows = rows_and_header(csv.read_text())
    t = np.array([float(r[0]) for r in rows])
    cols = [names.index(f"P{i}") for i in range(1, 5)]
    P = np.array([[float(r[j]) for j in cols] for r in rows]).T
    ground = np.arange(int(np.argmax(all_running(P))))
    hover = float(np.median(P.mean(axis=0)[t > t[0] + 20.0]))
    rng = np.random.default_rng(44)
    level = hover * rng.uniform(0.95, 1.05, size=4)
    swing = float(rng.uniform(0.06, 0.11))            # m/s^2 moved in 1 s by the 0.5 s mean
    period = 2.0                                      # s: a half period in the 1 s window
    gain = np.sinc(SMOOTH_S / period)                 # the 0.5 s moving mean's gain at 1 / period
    az = names.index("acc_z")
    phase = rng.uniform(0, 2 * np.pi)
    for k in ground:
        for j, v in zip(cols, level):
            rows[k][j] = f"{v:.3f}"
        shake = 0.5 * swing / gain * np.sin(2 * np.pi * t[k] / period + phase)
        rows[k][az] = f"{float(rows[k][az]) + shake:.6g}"
    held = write(meta, names, rows, tmp_path / "shaken.csv")
    table = read_flight_log(str(held), extra=FOREIGN_COLUMNS)
    force = np.sqrt(sum(table[c] ** 2 for c in ("acc_x", "acc_y", "acc_z")))
    n = int(round(SMOOTH_S / float(np.median(np.diff(t)))))
    mean = np.convolve(force, np.ones(n) / n, mode="same")
    inner = ground[(t[ground] > t[ground[0]] + REST_S) & (t[ground] < t[ground[-1]] - REST_S)]
    window = int(round(REST_S / float(np.median(np.diff(t)))))
    moved = [np.ptp(mean[k - window // 2:k + window // 2]) for k in inner]
    assert np.median(moved) > 0.05                     # past the specific force's own limit of rest
    f = load_file(table, Airframe())
    assert not f.airborne[inner].any()
    assert any("IMU held still" in n and "on the ground" in n for n in f.notes)
    air = (f.t > t[0] + 20.0) & (f.t < t[0] + 85.0)
    assert f.airborne[air].mean() > 0.95, f.airborne[air].mean()


def test_the_landing_detector_is_weighed_against_the_airborne_rows(tmp_path):
    """The autopilot's own landing detector is read (PX4's vehicle_land_detected.landed; ArduCopter's EV
    NOT_LANDED / LAND_COMPLETE) and set beside the rows taken as airborne: on quadrotor_local.ulg and
    log171.bin they agree; with the detector's flag rewritten to 'landed' over a window of the hover (its
    start and length drawn from a seeded generator) the disagreement is said, sized to the window less
    the detector's lag at either end (data.LANDED_LAG_S)."""
    from flightctl.sim.diagnose.data import LANDED_LAG_S
    from flightctl.sim.logs import each_log
    for path in (FLIGHTS / "px4" / "quadrotor_local.ulg", DATA / "ardupilot" / "log171.bin"):
        (e,) = each_log(str(need(path)))
        f = load_file(e.table, Airframe())
        assert any(n.startswith("the landing detector agrees") for n in f.notes), (path.name, f.notes)
    csv = _imported(tmp_path, FLIGHTS / "px4" / "quadrotor_local.ulg", "ql.csv")
    meta, names, rows = rows_and_header(csv.read_text())
    t = np.array([float(r[0]) for r in rows])
    rng = np.random.default_rng(4547)
    start, length = float(rng.uniform(30.0, 60.0)), float(rng.uniform(5.0, 15.0))
    j = names.index("landed")
    for k in np.flatnonzero((t >= start) & (t < start + length)):
        rows[k][j] = "1"
    f = load_file(read_flight_log(str(write(meta, names, rows, tmp_path / "said_landed.csv")), extra=FOREIGN_COLUMNS),
                  Airframe())
    note = next(n for n in f.notes if n.startswith("the landing detector and the IMU disagree"))
    said = float(note.split(": ")[1].split(" s")[0])
    assert said == pytest.approx(length - 2 * LANDED_LAG_S, abs=0.3), (start, length, note)
