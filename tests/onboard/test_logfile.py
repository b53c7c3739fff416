"""flightctl.logfile: CSV readers with one-line errors naming file, row (line number) and column,
and the flight log writer read back."""
import io
import math

import numpy as np
import pytest

from flightctl.errors import InputError
from flightctl.logfile import (FLIGHT_COLUMNS, MAG_COLUMNS, FlightLogWriter, read_flight_log,
                               read_table)

RANGE = FLIGHT_COLUMNS.index("range")


def row(t, **cells):
    """A flight-log row as CSV cells: every column a number unless given."""
    values = {c: f"{0.5 + i / 10:g}" for i, c in enumerate(FLIGHT_COLUMNS)}
    values["t"] = f"{t:g}"
    values.update({k: str(v) for k, v in cells.items()})
    return ",".join(values[c] for c in FLIGHT_COLUMNS)


def write(tmp_path, lines, name="flight.csv"):
    p = tmp_path / name
    p.write_text("\n".join(lines) + "\n")
    return p


def header(columns=FLIGHT_COLUMNS):
    return ",".join(columns)


def test_read_flight_log_values_meta_and_nan_range(tmp_path):
    p = write(tmp_path, ["# software: flightctl 0.1.0",
                         "# board: sim",
                         header(),
                         row(0.0, range=""),
                         row(0.01, range="1.234", battery_v=""),
                         "# a comment between rows",
                         row(0.02, range="nan")])
    t = read_flight_log(p)
    assert len(t) == 3
    np.testing.assert_array_equal(t["t"], [0.0, 0.01, 0.02])
    assert math.isnan(t["range"][0]) and t["range"][1] == 1.234 and math.isnan(t["range"][2])
    assert math.isnan(t["battery_v"][1]) and t["battery_v"][0] == pytest.approx(0.5 + 12 / 10)
    assert t["P1"][0] == pytest.approx(0.6)
    assert t.meta == {"software": "flightctl 0.1.0", "board": "sim"}
    assert [t.row_line(i) for i in range(3)] == [4, 5, 7]
    assert "mag_x" not in t


def test_optional_mag_columns(tmp_path):
    cols = FLIGHT_COLUMNS + MAG_COLUMNS
    p = write(tmp_path, [header(cols), row(0.0) + ",1e-5,2e-5,-4e-5", row(0.1) + ",,,"])
    t = read_flight_log(p)
    assert t["mag_x"][0] == 1e-5 and t["mag_z"][0] == -4e-5
    assert all(math.isnan(t[c][1]) for c in MAG_COLUMNS)


def test_missing_column(tmp_path):
    cols = tuple(c for c in FLIGHT_COLUMNS if c != "yaw")
    p = write(tmp_path, ["# x: y", header(cols), ",".join(["0"] * len(cols)), ",".join(["1"] * len(cols))])
    with pytest.raises(InputError) as e:
        read_flight_log(p)
    msg = str(e.value)
    assert msg.startswith(str(p)) and "missing column 'yaw'" in msg and "line 2" in msg


def test_non_numeric_cell_names_row_and_column(tmp_path):
    p = write(tmp_path, ["# meta: 1", header(), row(0.0), row(0.01, roll="abc"), row(0.02)])
    with pytest.raises(InputError) as e:
        read_flight_log(p)
    msg = str(e.value)
    assert str(p) in msg and "row 4" in msg and "'roll'" in msg and "'abc'" in msg


def test_empty_required_cell(tmp_path):
    p = write(tmp_path, [header(), row(0.0), row(0.01), row(0.02, gyro_y="")])
    with pytest.raises(InputError) as e:
        read_flight_log(p)
    msg = str(e.value)
    assert "row 4" in msg and "'gyro_y'" in msg and "empty" in msg


def test_an_empty_estimate_or_setpoint_is_a_missing_value(tmp_path):
    """docs/measured-data.md: empty cells are missing values; a log of another autopilot may have no
    angle setpoints or estimates. The measurements and commands stay required on every row."""
    p = write(tmp_path, [header(), row(0.0), row(0.01, roll="", alt_sp=""), row(0.02)])
    t = read_flight_log(p)
    assert np.isnan(t["roll"][1]) and np.isnan(t["alt_sp"][1]) and t["roll"][0] == t["roll"][2]


def test_short_row_is_an_empty_cell(tmp_path):
    p = write(tmp_path, [header(), row(0.0), ",".join(row(0.01).split(",")[:7])])   # cut after gyro_y
    with pytest.raises(InputError) as e:
        read_flight_log(p)
    assert "row 3" in str(e.value) and "'gyro_z'" in str(e.value)


def test_infinite_cell(tmp_path):
    p = write(tmp_path, [header(), row(0.0), row(0.01, pitch="inf")])
    with pytest.raises(InputError) as e:
        read_flight_log(p)
    assert "row 3" in str(e.value) and "'pitch'" in str(e.value) and "not finite" in str(e.value)


@pytest.mark.parametrize("times,bad_line", [((0.0, 0.01, 0.01), 4), ((0.0, 0.02, 0.01, 0.03), 4),
                                           ((0.5, 0.4), 3)])
def test_time_not_increasing(tmp_path, times, bad_line):
    p = write(tmp_path, [header()] + [row(t) for t in times])
    with pytest.raises(InputError) as e:
        read_flight_log(p)
    msg = str(e.value)
    assert f"row {bad_line}" in msg and "'t'" in msg and "not increasing" in msg


def test_too_short(tmp_path):
    p = write(tmp_path, [header(), row(0.0)])
    with pytest.raises(InputError, match="too short"):
        read_flight_log(p)
    p = write(tmp_path, [header(), row(0.0), row(0.5)])
    with pytest.raises(InputError, match="too short to judge"):
        read_flight_log(p, min_seconds=1.0)
    assert len(read_flight_log(p, min_seconds=0.5)) == 2


def test_empty_and_missing_files(tmp_path):
    p = write(tmp_path, ["# only: comments"])
    with pytest.raises(InputError, match="no header"):
        read_flight_log(p)
    with pytest.raises(InputError, match="cannot read"):
        read_flight_log(tmp_path / "absent.csv")


def test_read_table_text_columns_and_errors(tmp_path):
    p = write(tmp_path, ["axis,pivot_distance,period", "x,0.30,1.12", "y,0.31,1.13", "z,0.29,bad"])
    with pytest.raises(InputError) as e:
        read_table(p, ("axis", "pivot_distance", "period"), text_columns=("axis",))
    assert "row 4" in str(e.value) and "'period'" in str(e.value) and "'bad'" in str(e.value)
    p = write(tmp_path, ["axis,pivot_distance,period", "x,0.30,1.12", "y, 0.31 ,1.13"])
    with pytest.raises(InputError, match=r"row 3: column 'pivot_distance': ' 0.31 ' is not a number \(spaces around"):
        read_table(p, ("axis", "pivot_distance", "period"), text_columns=("axis",))
    p = write(tmp_path, ["axis,pivot_distance,period", "x,0.30,1.12", " y ,0.31,1.13"])
    t = read_table(p, ("axis", "pivot_distance", "period"), text_columns=("axis",))
    assert list(t["axis"]) == ["x", "y"]
    np.testing.assert_array_equal(t["pivot_distance"], [0.30, 0.31])


def flight_row(t, P, rng):
    return (t, P, P + 1, P + 2, P + 3, 0.01, -0.02, 0.03, -0.1, 0.2, 9.81, rng, 15.9,
            0.001, -0.002, 0.5, 1.25, 0.0, 0.0, 0.5, 1.5)


def test_writer_round_trip(tmp_path):
    p = tmp_path / "log.csv"
    rows = [flight_row(k / 450, 172.0 + k / 7, "%.4f" % (1 + k / 100) if k % 3 == 0 else "")
            for k in range(10)]
    with FlightLogWriter(p, {"software": "flightctl test", "scenario": "hover"}, chunk=4) as w:
        for r in rows:
            w.append(r)
    assert w.count == 10
    t = read_flight_log(p)
    assert t.meta == {"software": "flightctl test", "scenario": "hover"}
    assert len(t) == 10
    for i, c in enumerate(FLIGHT_COLUMNS):
        if c == "range":
            want = [float(r[i]) if r[i] else math.nan for r in rows]
            np.testing.assert_array_equal(t[c], want)
        else:
            np.testing.assert_allclose(t[c], [r[i] for r in rows], rtol=1e-5, atol=1e-6)
    assert t["t"] == pytest.approx([k / 450 for k in range(10)], abs=5e-7)


def test_writer_extra_columns_and_stream(tmp_path):
    buf = io.StringIO()
    w = FlightLogWriter(buf, {"board": "sim"}, extra=MAG_COLUMNS)
    w.append(flight_row(0.0, 150.0, "") + (2e-5, 0.0, -4e-5))
    w.append(flight_row(0.1, 151.0, "0.8000") + (2.1e-5, 1e-6, -4e-5))
    w.close()
    assert not buf.closed                # not ours to close
    p = tmp_path / "x.csv"
    p.write_text(buf.getvalue())
    t = read_flight_log(p)
    np.testing.assert_allclose(t["mag_x"], [2e-5, 2.1e-5])
    assert t["range"][1] == 0.8 and math.isnan(t["range"][0])


def test_writer_multiline_meta_round_trip(tmp_path):
    p = tmp_path / "log.csv"
    params_text = "M = 1.645  # kg\nl = 0.2475  # m\n"
    with FlightLogWriter(p, {"params": params_text, "board": "sim"}) as w:
        w.append(flight_row(0.0, 150.0, ""))
        w.append(flight_row(0.1, 150.0, ""))
    t = read_flight_log(p)
    assert t.meta["board"] == "sim"
    assert t.meta["params"] == params_text.rstrip("\n")


def test_writer_kept_table_line_numbers_match_the_file(tmp_path):
    p = tmp_path / "log.csv"
    w = FlightLogWriter(p, {"params": "a = 1\nb = 2\nc = 3", "board": "sim"}, keep=True)
    for k in range(3):
        w.append(flight_row(k / 10, 150.0, ""))
    w.close()
    kept = w.table()
    read = read_flight_log(p)
    assert [kept.row_line(i) for i in range(3)] == [read.row_line(i) for i in range(3)] == [6, 7, 8]


class FullAfter:
    """A file that takes `room` characters, then fails every write with ENOSPC (a full card)."""

    def __init__(self, path, room):
        self.f, self.name, self.room = open(path, "w"), str(path), room

    def write(self, s):
        if len(s) > self.room:
            raise OSError(28, "No space left on device")
        self.room -= len(s)
        return self.f.write(s)

    def flush(self):
        self.f.flush()

    def fileno(self):
        return self.f.fileno()

    def close(self):
        self.f.close()


def many_rows(n):
    return [flight_row(k / 450, 150.0 + k / 100, "%.4f" % (1 + k / 1000) if k % 10 == 0 else "") for k in range(n)]


def test_the_child_process_writer_writes_the_same_file(tmp_path):
    rows = many_rows(1000)
    meta = {"params": "a = 1\nb = 2", "board": "sim"}
    for name, process in (("in.csv", False), ("child.csv", True)):
        with FlightLogWriter(tmp_path / name, meta, chunk=45, keep=True, process=process) as w:
            for r in rows:
                w.append(r)
            if process:
                assert w._child is not None and w._child.is_alive()   # formatting in another process
        assert (w.count, w.dropped, w.failed) == (1000, 0, False)
    assert (tmp_path / "child.csv").read_bytes() == (tmp_path / "in.csv").read_bytes()
    assert len(read_flight_log(tmp_path / "child.csv")) == 1000


def test_the_child_process_writer_reports_a_full_card_and_counts_what_it_dropped(tmp_path):
    card = FullAfter(tmp_path / "f.csv", room=20000)
    w = FlightLogWriter(card, {"k": "v"}, chunk=45, process=True)
    rows = many_rows(900)
    for r in rows:
        w.append(r)
    w.close()
    card.close()
    assert w.failed and "No space left" in w.error
    assert 0 < w.count < 900 and w.count + w.dropped == 900
    assert len(read_flight_log(tmp_path / "f.csv")) == w.count    # what was written is whole rows


def test_a_killed_child_process_writer_is_a_failed_log_not_a_hang(tmp_path):
    w = FlightLogWriter(tmp_path / "f.csv", {"k": "v"}, chunk=45, keep=True, process=True)
    for r in many_rows(90):
        w.append(r)
    w._child.kill()
    w._child.join(5)
    for r in many_rows(90):
        w.append(r)
    w.close()
    assert w.failed and "process" in w.error
    assert w.count + w.dropped == 180 and w.dropped >= 90


def _written_log(tmp_path, n=40, partial=None):
    p = tmp_path / "log.csv"
    with FlightLogWriter(p, {"board": "sim"}, chunk=7) as w:
        for k in range(n):
            w.append(flight_row(k / 450, 172.0 + k / 7, ""))
        w.partial = partial
    return p


def test_a_log_cut_mid_row_is_read_without_that_row_and_says_so(tmp_path, capsys):
    """The card filled, or a copy stopped half-way: the file ends inside a row, at a byte drawn at
    random (seeded) within it. The rows before it are read; the cut one is left out, with one word."""
    p = _written_log(tmp_path)
    data = p.read_bytes()
    last = data.rstrip(b"\n").rfind(b"\n") + 1                    # the last row's first byte
    at = int(np.random.default_rng(39).integers(last + 1, len(data) - 1))
    p.write_bytes(data[:at])
    t = read_flight_log(p)
    assert len(t) == 39 and t["t"][-1] == pytest.approx(38 / 450, abs=5e-7)
    assert capsys.readouterr().err == f"{p}: cut short: its last line (42) ends mid-row, without a newline; read without it\n"
    p.write_bytes(data)                                           # whole: not a word
    assert len(read_flight_log(p)) == 40 and capsys.readouterr().err == ""


def test_a_partial_log_is_read_with_its_reason(tmp_path, capsys):
    p = _written_log(tmp_path, partial="interrupted (Ctrl-C) at t = 0.087 s")
    assert len(read_flight_log(p)) == 40
    err = capsys.readouterr().err
    assert err.startswith(f"{p}: cut short: the log says `# partial: interrupted (Ctrl-C) at t = 0.087 s, after 40 rows`")
