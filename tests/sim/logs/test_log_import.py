"""`flightctl log import` and `flightctl.sim.logs` on the shipped real logs (docs/log-import.md): every
log is read with the rates the flights README publishes, its frames are ours (checked against the
log's own quaternion and gravity, and the motors' effect on the gyro), commands are held between
their samples, the import and the CSV it writes are the same table, and damaged or unknown files are
refused in one line with exit status 2, nothing written."""
from __future__ import annotations

import math

import numpy as np
import pytest

from flightctl.cli import main
from flightctl.logfile import read_flight_log
from flightctl.sim.logs import EXTRA_COLUMNS, read_foreign
from helpers.real import FLIGHTS, INDIFLIGHT, need
from helpers.paths import DATA

# (file, duration s, row rate Hz, motor rate Hz): the figures of ../shared/data/real/flights/README.md
PUBLISHED = (("indiflight/LOG00230.BFL", 26.0, 500.0, 500.0),
             ("betaflight/LOG00037.BFL", 17.0, 1000.0, 1000.0),
             ("px4/roboto-test.ulg", 9.0, 194.0, 10.0))


@pytest.fixture(scope="module")
def tables():
    return {name: read_foreign(str(need(FLIGHTS / name)))[0] for name, *_ in PUBLISHED}


@pytest.mark.parametrize("name, duration, rate, motor_rate", PUBLISHED)
def test_each_log_is_read_at_its_published_rates(tables, name, duration, rate, motor_rate):
    t = tables[name]
    assert t["t"][-1] == pytest.approx(duration, rel=0.05)
    assert float(t.meta["rate_hz"]) == pytest.approx(rate, rel=0.05)
    assert float(t.meta["motor_rate_hz"]) == pytest.approx(motor_rate, rel=0.15)   # PX4: the main outputs' share
    assert t.meta["vehicle"] == "foreign" and len(t.meta["rotors"].split(";")) == 4


def test_at_rest_the_accelerometer_reads_plus_g_up(tables):
    for name, t in tables.items():       # every log starts on the ground or in a hand, before take-off
        assert t["acc_z"][:50].mean() == pytest.approx(9.8, abs=0.5), name
        assert np.hypot(t["acc_x"][:50].mean(), t["acc_y"][:50].mean()) < 1.5, name


def test_the_indiflight_gyro_turns_the_way_its_own_quaternion_does(tables):
    """Our Euler angles from the log's quaternion (body FRD to NED, converted), differentiated, against
    the gyro in controlled flight, where the angles are small and their rates are the body rates:
    the same sign and size on every axis."""
    t = tables["indiflight/LOG00230.BFL"]
    time = t["t"]
    sel = (time > 11.0) & (time < 24.0)
    for angle, rate in (("roll", "gyro_x"), ("pitch", "gyro_y"), ("yaw", "gyro_z")):
        d = np.gradient(np.unwrap(t[angle]), time)[sel]
        assert np.corrcoef(d, t[rate][sel])[0, 1] > 0.9, angle
        assert np.std(d) == pytest.approx(np.std(t[rate][sel]), rel=0.2), angle


def test_each_rotor_turns_the_vehicle_the_way_its_position_says(tables):
    """A rotor's thrust, lagged, against the angular acceleration: the roll and pitch signs of each
    rotor's effect are those of its declared position (our frame: y left, x forward)."""
    t = tables["indiflight/LOG00230.BFL"]
    time, fs = t["t"], float(t.meta["rate_hz"])
    P = np.vstack([t[f"P{i}"] for i in range(1, 5)])
    fly = (P > 2.55).all(axis=0) & (time > 12.0)
    lag = math.exp(-1.0 / (fs * 0.025))
    from scipy import signal
    thrust = signal.lfilter([1 - lag], [1, -lag], P + 40.0, axis=1) ** 2
    rotors = [[float(v) for v in r.split()] for r in t.meta["rotors"].split(";")]
    sos = signal.butter(2, 8.0, fs=fs, output="sos")
    for axis, sign_of in (("gyro_x", lambda x, y: y), ("gyro_y", lambda x, y: -x)):
        acc = np.gradient(t[axis], time)
        X = np.column_stack([signal.sosfiltfilt(sos, f)[fly] for f in thrust] + [np.ones(fly.sum())])
        coef = np.linalg.lstsq(X, signal.sosfiltfilt(sos, acc)[fly], rcond=None)[0][:4]
        assert all(np.sign(c) == np.sign(sign_of(x, y)) for c, (x, y, _) in zip(coef, rotors)), (axis, coef)


def test_commands_are_held_between_their_samples(tables):
    t = tables["px4/roboto-test.ulg"]          # actuator_outputs at 10 Hz, rows at 194 Hz
    P = t["P1"]
    changes = np.flatnonzero(np.diff(P) != 0)
    assert changes.size < P.size / 10
    assert np.min(np.diff(changes)) >= 5       # about 19 rows between two commands


def test_the_import_and_the_csv_it_writes_are_the_same_table(tmp_path):
    log = need(INDIFLIGHT / "LOG00258.BFL")
    out = tmp_path / "log.csv"
    assert main(["log", "import", str(log), str(out), "--quiet"]) == 0
    direct = read_foreign(str(log))[0]
    again = read_flight_log(out, extra=EXTRA_COLUMNS)
    assert direct.meta == again.meta
    assert set(direct.columns) == set(again.columns)
    for name, x in direct.columns.items():
        np.testing.assert_array_equal(x, again[name], err_msg=name)


def _refused(capsys, args, out=None):
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    if out is not None:
        assert not out.exists()
    return err


def test_damaged_and_unknown_logs_are_refused_in_one_line(tmp_path, capsys):
    source = need(INDIFLIGHT / "LOG00259.BFL").read_bytes()
    ulog = need(FLIGHTS / "px4" / "roboto-test.ulg").read_bytes()
    out = tmp_path / "out.csv"
    cases = {
        "empty.bbl": b"",
        "cut.bfl": source[:2000],                                 # the header only, no frames
        "text.ulg": b"t,P1\n0,1\n",
        "noise.BFL": bytes(np.random.default_rng(1).integers(0, 256, 50000, dtype=np.uint8)),
        "cut.ulg": ulog[:3000],
        "hexa.ulg": ulog.replace(b"int32_t MAV_TYPE\x02\x00\x00\x00", b"int32_t MAV_TYPE\x0d\x00\x00\x00"),
        "log.txt": b"H Product:Blackbox flight data recorder\n",
    }
    for name, data in cases.items():
        path = tmp_path / name
        path.write_bytes(data)
        err = _refused(capsys, ["log", "import", str(path), str(out)], out)
        assert name in err
    assert "MAV_TYPE = 13" in _refused(capsys, ["log", "import", str(tmp_path / "hexa.ulg"), str(out)])
    flipped = bytearray(source)
    for k in range(3000, len(flipped), 997):                       # bit flips through the frames
        flipped[k] ^= 0x5A
    (tmp_path / "flipped.bfl").write_bytes(bytes(flipped))
    status = main(["log", "import", str(tmp_path / "flipped.bfl"), str(out), "--quiet"])
    err = capsys.readouterr().err.strip()
    assert status in (0, 2) and "Traceback" not in err          # read around the damage, or refused in one line
    assert status == 0 or not out.exists()


def test_bad_arguments_are_refused_in_one_line(tmp_path, capsys):
    log = str(need(INDIFLIGHT / "LOG00259.BFL"))
    out = tmp_path / "out.csv"
    assert "does not exist" in _refused(capsys, ["log", "import", log, str(out), "--index", "2"], out)
    assert "directory" in _refused(capsys, ["log", "import", log, str(tmp_path / "no" / "out.csv")])
    assert "should end in .csv" in _refused(capsys, ["log", "import", log, str(tmp_path / "out.txt")])
    assert "does not exist" in _refused(capsys, ["diagnose", log, "--index", "3", "--json", str(tmp_path / "r.json")])
    assert "cannot read" in _refused(capsys, ["diagnose", str(tmp_path / "missing.ulg"), "--json",
                                              str(tmp_path / "r.json")])


def test_a_log_is_known_by_its_content_not_its_name(tmp_path):
    """A ULog named `.ulog`, a DataFlash log named `.dat` and a blackbox log named `.log` are read as
    what their bytes are (their magic), the same tables as under their own names; a folder's other
    files are named, with why they were not read, never skipped silently."""
    from flightctl.sim.diagnose.corpus import NOT_A_LOG, find_logs
    dataflash = DATA / "ardupilot" / "backend_log_80k.bin"
    cases = ((need(FLIGHTS / "px4" / "roboto-test.ulg"), "flight.ulog"), (dataflash, "flight.dat"),
             (need(INDIFLIGHT / "LOG00259.BFL"), "flight.log"))
    folder = tmp_path / "corpus"
    folder.mkdir()
    for source, name in cases:
        (folder / name).write_bytes(source.read_bytes())
        (a,), (b,) = read_foreign(str(source)), read_foreign(str(folder / name))
        assert a.meta["format"] == b.meta["format"] and sorted(a.columns) == sorted(b.columns), name
        for c in ("t", "P1", "gyro_x", "acc_z"):
            assert np.array_equal(a[c], b[c], equal_nan=True), (name, c)
    (folder / "README.md").write_text("# three logs\n")
    (folder / "LICENSE.txt").write_text("MIT\n")
    others = []
    assert [p.name for p in find_logs(folder, others)] == ["flight.dat", "flight.log", "flight.ulog"]
    assert sorted((p.name, why) for p, why in others) == [("LICENSE.txt", NOT_A_LOG), ("README.md", NOT_A_LOG)]


def test_a_clock_that_jumps_back_drops_its_repeated_rows_and_says_so():
    """Betaflight 3.0's clock can jump back mid-flight while loopIteration runs on: a real Betaflight
    3.1.5 log (tests/data/pid-analyzer/example_smooth_tune.BBL) with its frames' time moved back by a
    jump drawn from a seeded generator, at a row so drawn, is read: the rows whose time repeats one
    already logged are dropped and counted, the rest kept in order."""
    from flightctl.sim.logs import blackbox, bbfields
    from flightctl.sim.logs.common import flight_text, to_table
    path = DATA / "pid-analyzer" / "example_smooth_tune.BBL"
    data = path.read_bytes()
    ((s, e),) = blackbox.split(data)
    parser = blackbox._parser(str(path), data[s:e])
    names, a, notes = blackbox.frames(parser, blackbox.header_end(data[s:e]), len(data))
    t = a[:, names.index("time")] * 1e-6
    rng = np.random.default_rng(45)
    jump = float(rng.uniform(3.0, 8.0))
    k = int(rng.integers(t.size // 4, t.size // 2))
    edited = a.copy()
    edited[k:, names.index("time")] -= jump * 1e6
    lost = int(np.sum(t[k:] - jump <= t[:k].max()))             # the rows the jump repeats
    own = int(np.sum(np.diff(t) <= 0))                            # the log's own few repeated times
    assert lost > 0.9 * jump * 1900
    imp = bbfields.imported("jumped.BBL", dict(parser.headers), names, edited, list(notes))
    table = to_table(flight_text(imp), "jumped.BBL")
    note = next(n for n in table.meta["import_notes"].splitlines() if "backward time" in n)
    assert lost <= int(note.split(" frames")[0]) <= lost + own, (lost, own, note)
    assert f"{jump:.3g} s" in note and "loopIteration continuous" in note, note
    assert np.all(np.diff(table["t"]) > 0)
    whole = to_table(flight_text(bbfields.imported("whole.BBL", dict(parser.headers), names, a, list(notes))), "w")
    assert whole["t"].size - lost - own <= table["t"].size <= whole["t"].size - lost
    assert table["t"][-1] == pytest.approx(whole["t"][-1] - jump, abs=0.01)


def test_a_byte_identical_copy_is_counted_once_and_named(tmp_path):
    """The same real log under two names (a copy kept beside its original, as public log folders hold)
    is one flight: the corpus diagnoses the first and lists the copy as a duplicate of it, and the
    headline counts it once, saying so."""
    from flightctl.sim.diagnose.corpus import _jobs, find_logs, headline
    folder = tmp_path / "corpus"
    (folder / "b").mkdir(parents=True)
    data = need(FLIGHTS / "px4" / "roboto-test.ulg").read_bytes()
    (folder / "a.ulg").write_bytes(data)
    (folder / "b" / "copy.ulg").write_bytes(data)
    (folder / "b" / "other.ulg").write_bytes(need(FLIGHTS / "px4" / "esc_status_log.ulg").read_bytes())
    todo, refused = _jobs(folder, find_logs(folder))
    assert [r.log for r in todo] == ["a.ulg", "b/other.ulg"]
    (dup,) = refused
    assert dup.log == "b/copy.ulg" and dup.status == "duplicate" and "copy of a.ulg" in dup.reason
    assert dup.cells()[4] == "duplicate"
    line = headline(todo + refused)
    assert "of 2 airborne multirotor flights" in line and "of the 2 logs" in line and "1 file a byte-identical copy" in line, line
