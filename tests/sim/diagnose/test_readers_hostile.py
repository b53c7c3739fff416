"""Issue 10, defect 6: hostile input files. Each case was a traceback, a hang or a confident answer
from nonsense; each must now be one line on stderr naming the file (exit status 2) and write nothing."""
from __future__ import annotations

import json
import os
import threading

import numpy as np
import pytest

from flightctl.cli import main
from flightctl.errors import InputError
from flightctl.files import read_text
from flightctl.logfile import read_flight_log
from flightctl.boards.pi import load_board
from flightctl.plans.plan import read_plan_file
from flightctl import params as paramfile
from helpers.identify_rows import HEADER, PENDULUM, bench_rows, yaw_rows


def _refused(capsys, argv, *words):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.endswith("\n") and err.count("\n") == 1, err
    for w in words:
        assert w in err, err
    return err


def _identify(tmp_path, kind, data: bytes, *extra):
    path = tmp_path / f"{kind}.csv"
    path.write_bytes(data)
    out = tmp_path / "out.json"
    return path, out, ["identify", kind, str(path), "--json", str(out), *extra]


def _bench(rows=None) -> str:
    return HEADER["bench"] + "\n" + "\n".join(rows or bench_rows()) + "\n"


def test_utf16_file_is_refused_by_name(tmp_path, capsys):
    path, out, argv = _identify(tmp_path, "bench", _bench().encode("utf-16"))
    _refused(capsys, argv, str(path), "UTF-16")
    assert not out.exists()


def test_non_utf8_byte_names_the_line(tmp_path, capsys):
    data = _bench().encode().replace(b"motor,P", b"motor\xb5,P")
    path, out, argv = _identify(tmp_path, "bench", data)
    _refused(capsys, argv, str(path), "line 1", "0xb5", "not UTF-8")


def test_byte_order_mark_is_read_as_utf8(tmp_path, capsys):
    path, out, argv = _identify(tmp_path, "bench", b"\xef\xbb\xbf" + _bench().encode())
    assert main(argv) == 0, capsys.readouterr().err
    assert json.loads(out.read_text())["h1"]["value"] > 0


def test_duplicated_column_is_refused_not_silently_the_last(tmp_path, capsys):
    rows = [r + ",1" for r in bench_rows()]
    path, out, argv = _identify(tmp_path, "bench", (HEADER["bench"] + ",thrust\n" + "\n".join(rows)).encode())
    _refused(capsys, argv, str(path), "'thrust'", "twice")


def test_five_megabyte_line_is_one_line_error(tmp_path, capsys):
    path, out, argv = _identify(tmp_path, "bench", (_bench() + "1," + "9" * 5_000_000 + "\n").encode())
    _refused(capsys, argv, str(path), "characters long")


@pytest.mark.parametrize("cell", ["1e300", "-1e300", "1e308"])
def test_huge_values_are_refused_naming_the_column(tmp_path, capsys, cell):
    rows = bench_rows()
    cells = rows[3].split(",")
    cells[2] = cell
    rows[3] = ",".join(cells)
    path, out, argv = _identify(tmp_path, "bench", _bench(rows).encode())
    _refused(capsys, argv, str(path), "row 5", "'thrust'")
    assert not out.exists()


@pytest.mark.parametrize("column", ["torque", "yaw_rate"])
def test_huge_yaw_drag_value_is_refused_naming_the_column(tmp_path, capsys, column):
    """The old fit took 1e300: a torque gave exit 0 with Infinity in the JSON, a yaw rate a traceback."""
    rows = yaw_rows()
    cells = rows[0].split(",")
    cells[HEADER["yaw-drag"].split(",").index(column)] = "1e300"
    rows[0] = ",".join(cells)
    path, out, argv = _identify(tmp_path, "yaw-drag", (HEADER["yaw-drag"] + "\n" + "\n".join(rows) + "\n").encode())
    _refused(capsys, argv, str(path), "row 2", repr(column))
    assert not out.exists()


def test_plausible_duplicated_column_is_refused(tmp_path, capsys):
    """A second 'thrust' column at twice the first: the old reader used the last copy and wrote h1
    doubled, exit 0."""
    rows = [r + f",{2 * float(r.split(',')[2]):.6g}" for r in bench_rows()]
    path, out, argv = _identify(tmp_path, "bench", (HEADER["bench"] + ",thrust\n" + "\n".join(rows) + "\n").encode())
    _refused(capsys, argv, str(path), "'thrust'", "twice")
    assert not out.exists()


def test_negative_g1_is_refused(tmp_path, capsys):
    """Torque from V I / w falling as the thrust rises (tau = 0.3 - 0.02 f, every current positive):
    eq. 28 fits g1 = -0.02, outside the schema's physical range."""
    P = np.arange(130.0, 210.0, 10.0)
    f = 1.49e-3 * (P - 120) ** 2
    w = np.sqrt(f / 1.47e-5)
    current = (0.3 - 0.02 * f) * w / 14.8
    assert (current > 0).all()
    rows = [f"1,{p:g},{fi:.6g},{wi:.6g},14.8,{i:.6g}" for p, fi, wi, i in zip(P, f, w, current)]
    path, out, argv = _identify(tmp_path, "bench", _bench(rows).encode())
    err = _refused(capsys, argv, str(path), "g1", "physical range")
    assert "gamma1" not in err and "-0.02" in err, err
    assert not out.exists()


def test_zero_current_gives_no_nan_in_the_json(tmp_path, capsys):
    rows = [",".join(r.split(",")[:5] + ["0"]) for r in bench_rows()]
    path, out, argv = _identify(tmp_path, "bench", _bench(rows).encode())
    _refused(capsys, argv, str(path))
    assert not out.exists()


def test_negated_torques_give_no_negative_gamma1(tmp_path, capsys):
    rows = [f"{-float(r.split(',')[0]):.6g},{r.split(',')[1]}" for r in yaw_rows()]
    path, out, argv = _identify(tmp_path, "yaw-drag", (HEADER["yaw-drag"] + "\n" + "\n".join(rows)).encode())
    _refused(capsys, argv, str(path), "gamma1", "physical range")


def test_pendulum_inertia_beyond_the_schema_is_refused(tmp_path, capsys):
    rows = [r.rsplit(",", 1)[0] + f",{900 + k}" for k, r in enumerate(PENDULUM)]   # periods of 15 minutes
    path, out, argv = _identify(tmp_path, "pendulum", (HEADER["pendulum"] + "\n" + "\n".join(rows)).encode())
    _refused(capsys, argv, str(path), "Jxx", "physical range")


def test_deeply_nested_toml_is_one_line(tmp_path, capsys):
    bad = tmp_path / "deep.toml"
    bad.write_text("x = " + "[" * 5000 + "]" * 5000 + "\n")
    path, out, argv = _identify(tmp_path, "bench", _bench().encode(), "--params", str(bad))
    _refused(capsys, argv, str(bad), "nested too deeply")
    for read in (read_plan_file, load_board):
        with pytest.raises(InputError, match="nested too deeply"):
            read(bad)


def test_integer_beyond_float_range_in_toml(tmp_path):
    bad = tmp_path / "big.toml"
    bad.write_text(f"M = {10 ** 400}\n")
    with pytest.raises(InputError, match="M: .* out of range"):
        paramfile.load(bad)
    bad.write_text(f"duration = {10 ** 400}\n")
    with pytest.raises(InputError, match="duration"):
        read_plan_file(bad)
    bad.write_text(f"[power]\nshunt_ohm = {10 ** 400}\n")
    with pytest.raises(InputError, match="shunt_ohm"):
        load_board(bad)


def _with_timeout(fn, seconds=5.0):
    """fn() in a thread; what it raised or returned, or 'hang' after `seconds`."""
    box = {}

    def run():
        try:
            box["value"] = fn()
        except BaseException as e:      # noqa: BLE001 - handed back to the test
            box["value"] = e
    th = threading.Thread(target=run, daemon=True)
    th.start()
    th.join(seconds)
    return box.get("value", "hang")


@pytest.mark.parametrize("reader", [read_text, read_flight_log, read_plan_file, load_board, paramfile.load],
                         ids=["text", "flight log", "plan", "board", "params"])
def test_named_pipe_is_refused_without_opening_it_for_a_read(tmp_path, reader):
    fifo = tmp_path / "pipe.csv"
    os.mkfifo(fifo)
    got = _with_timeout(lambda: reader(fifo))
    if got == "hang":                   # unblock the reader so the thread can end
        os.close(os.open(fifo, os.O_WRONLY | os.O_NONBLOCK))
    assert isinstance(got, InputError), got
    assert "named pipe" in str(got) and "\n" not in str(got)


def test_directory_is_refused(tmp_path):
    """A regression guard, not a reproduction: the old readers already refused a directory."""
    with pytest.raises(InputError, match="a directory"):
        read_text(tmp_path)


READERS = [read_text, read_flight_log, read_plan_file, load_board, paramfile.load]
READER_IDS = ["text", "flight log", "plan", "board", "params"]


@pytest.mark.parametrize("reader", READERS, ids=READER_IDS)
def test_character_device_is_refused_without_reading_it(reader):
    """/dev/zero never ends: a reader that opens it and reads reads forever (the old readers did)."""
    got = _with_timeout(lambda: reader("/dev/zero"))
    assert isinstance(got, InputError), got
    assert "/dev/zero" in str(got) and "a character device" in str(got) and "\n" not in str(got)


@pytest.mark.parametrize("command", [["identify", "bench", "/dev/zero", "--json"],
                                     ["diagnose", "/dev/zero", "--quiet", "--json"]], ids=["identify", "diagnose"])
def test_character_device_is_refused_at_the_cli(tmp_path, capsys, command):
    out = tmp_path / "out.json"
    got = _with_timeout(lambda: main([*command, str(out)]))
    assert got == 2, got
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "/dev/zero" in err and "a character device" in err, err
    assert not out.exists()


# ---- diagnose's reader: a flight log made in the simulator, then damaged --------------------------

from test_diagnose_errors import _rewrite, flight  # noqa: E402,F401  (the module fixture)


def _set(column, value, rows_from=0):
    def edit(header, rows):
        i = header.index(column)
        return header, [r[:i] + [value if k >= rows_from else r[i]] + r[i + 1:] for k, r in enumerate(rows)]
    return edit


@pytest.mark.parametrize("column, value, words", [
    ("P1", "-170", ["'P1'", "-170", "0-255"]),
    ("P3", "1000", ["'P3'", "1000"]),
    ("battery_v", "0", ["'battery_v'"]),
    ("battery_v", "-3", ["'battery_v'"]),
    ("acc_z", "9.80665", ["'acc_z'", "every row"]),
    ("gyro_x", "0", ["'gyro_x'", "every row"]),
    ("P1", "0", ["'P1'", "motor 1 never runs"]),
])
def test_diagnose_refuses_impossible_columns(tmp_path, capsys, flight, column, value, words):  # noqa: F811
    log = _rewrite(flight, tmp_path / "f.csv", _set(column, value))
    out = tmp_path / "out.json"
    _refused(capsys, ["diagnose", str(log), "--json", str(out), "--quiet"], str(log), *words)
    assert not out.exists()


def test_diagnose_all_zero_accelerometer_is_judged_on_its_gyro(tmp_path, capsys, flight):  # noqa: F811
    log = tmp_path / "f.csv"
    for c in ("acc_x", "acc_y", "acc_z"):
        _rewrite(flight if c == "acc_x" else log, log, _set(c, "0"))
    # An accelerometer that reads zero is no accelerometer (issue 42 part 2): the flight is judged on its
    # gyro and its motors, and the report says the accelerometer's questions are unanswered.
    from flightctl.sim.diagnose.data import NO_ACCELEROMETER
    out = tmp_path / "o.json"
    assert main(["diagnose", str(log), "--json", str(out), "--quiet"]) == 0
    rep = json.loads(out.read_text())
    rep = rep[0] if isinstance(rep, list) else rep
    assert rep["tier"] == "dynamic", rep.get("tier_why")
    assert any(NO_ACCELEROMETER in n for n in rep["notes"]), rep["notes"]


def test_diagnose_reads_a_byte_order_mark(tmp_path, flight):  # noqa: F811
    log = tmp_path / "bom.csv"
    log.write_bytes(b"\xef\xbb\xbf" + flight.read_bytes())
    table = read_flight_log(log)
    assert np.array_equal(table["t"], read_flight_log(flight)["t"])


@pytest.mark.parametrize("column, second", [("P1", lambda v: f"{0.9 * float(v):.3f}"),
                                            ("battery_v", lambda v: f"{float(v) - 0.3:.3f}" if v else v)],
                         ids=["P1 at 0.9x", "battery_v 0.3 V lower"])
def test_diagnose_refuses_a_duplicated_column(tmp_path, capsys, flight, column, second):  # noqa: F811
    """A plausible second copy of a column (another logger's): the old reader silently used the last
    copy and diagnosed the flight, exit 0."""
    def dup(header, rows):
        i = header.index(column)
        return header + [column], [r + [second(r[i])] for r in rows]
    log = _rewrite(flight, tmp_path / "f.csv", dup)
    out = tmp_path / "out.json"
    _refused(capsys, ["diagnose", str(log), "--json", str(out), "--quiet"], str(log), repr(column), "twice")
    assert not out.exists()
