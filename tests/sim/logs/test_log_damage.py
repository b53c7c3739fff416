"""Issue 49: damaged foreign logs are said, never hidden and never a parser's exception name. A real
ULog with one data message damaged by a seeded bit flip (in its header: the size or the message id,
which pyulog can tell; a flip in a payload is a wrong value no reader can tell, as ULog has no
checksum) is read with the rows it lost counted, in the import's output and in diagnose's report, and
pyulog's warnings stay off stdout; a real blackbox log with a header line garbled (seeded) is one line
on stderr naming the file, no exception class in it, exit 2, nothing written."""
from __future__ import annotations

import json
import re
import struct
from pathlib import Path

import numpy as np
import pytest

from flightctl.cli import main
from flightctl.logfile import read_flight_log
from helpers.real import FLIGHTS, need
from helpers.paths import DATA

pytest.importorskip("pyulog")

ROBOTO = FLIGHTS / "px4" / "roboto-test.ulg"
CLASS_NAME = re.compile(r"\b[A-Za-z_]*(Error|Exception)\b|Error:")


def _data_messages(raw: bytes) -> list[int]:
    """The offsets of the ULog's data messages (ULog's framing: uint16 size, uint8 type, the payload)."""
    off, out = 16, []
    while off + 3 <= len(raw):
        size, kind = struct.unpack_from("<HB", raw, off)
        if kind == ord("D"):
            out.append(off)
        off += 3 + size
    return out


def _flipped(seed: int, fields: tuple[int, ...], log=ROBOTO) -> bytes:
    """A real ULog with one bit flipped in one byte (of `fields`: offsets in the message's header, 0-1
    its size, 3-4 its message id) of a data message, both drawn from the seed."""
    raw = need(log).read_bytes()
    rng = np.random.default_rng(seed)
    msgs = _data_messages(raw)
    k = msgs[int(rng.integers(len(msgs)))] + int(rng.choice(fields))
    out = bytearray(raw)
    out[k] ^= 1 << int(rng.integers(8))
    return bytes(out)


def _rows(path) -> int:
    return len(read_flight_log(path, min_rows=10))


@pytest.fixture(scope="module")
def intact(tmp_path_factory):
    out = tmp_path_factory.mktemp("intact") / "intact.csv"
    assert main(["log", "import", str(need(ROBOTO)), str(out), "--quiet"]) == 0
    assert "damaged" not in read_flight_log(out, min_rows=10).meta
    return _rows(out)


@pytest.mark.parametrize("seed", [3, 11, 29])
def test_a_damaged_ulog_says_the_rows_it_lost(tmp_path, capsys, intact, seed):
    """A flipped size: pyulog skips the message and what follows until it finds its place again; the
    import counts the rows lost (the test counts them against the intact log) and says so on its
    output line and in `# damaged:`."""
    bad = tmp_path / "bad.ulg"
    bad.write_bytes(_flipped(seed, (0, 1)))
    capsys.readouterr()
    assert main(["log", "import", str(bad), str(tmp_path / "bad.csv"), "--quiet"]) == 0
    out = capsys.readouterr().out
    assert out.count("\n") == 1 and "damaged:" in out
    damaged = read_flight_log(tmp_path / "bad.csv", min_rows=10).meta["damaged"]
    said = int(re.search(r"(\d+) rows lost", damaged)[1])
    lost = intact - _rows(tmp_path / "bad.csv")
    # the damaged message itself, and a row at either end the reader trims, are the counts' difference
    assert lost > 0 and abs(said - lost) <= 3, (said, lost)


def test_diagnose_says_the_damage(tmp_path, capsys):
    """A flight (esc_status_log.ulg: roboto-test.ulg's motors run for under a second) with a flipped size:
    the diagnosis is made and its report says the damage and the rows lost."""
    bad = tmp_path / "bad.ulg"
    bad.write_bytes(_flipped(3, (0, 1), FLIGHTS / "px4" / "esc_status_log.ulg"))
    report = tmp_path / "r.json"
    assert main(["diagnose", str(bad), "--json", str(report), "--quiet"]) == 0
    notes = json.loads(report.read_text())["notes"]
    assert any("damaged: pyulog found corrupt data" in n and "rows lost" in n for n in notes), notes
    assert "damaged: pyulog found corrupt data" in capsys.readouterr().out


def test_pyulog_warnings_are_notes_not_stdout(tmp_path, capsys):
    """A flipped high byte of a message id: pyulog prints "Warning: no subscription found ..." on
    stdout; the import's stdout is its one line, and the warning is in the log's notes."""
    bad = tmp_path / "bad.ulg"
    bad.write_bytes(_flipped(7, (4,)))
    capsys.readouterr()
    assert main(["log", "import", str(bad), str(tmp_path / "bad.csv"), "--quiet"]) == 0
    cap = capsys.readouterr()
    assert cap.out.count("\n") == 1 and "Warning" not in cap.out + cap.err
    notes = read_flight_log(tmp_path / "bad.csv", min_rows=10).meta["import_notes"]
    assert "pyulog: Warning: no subscription found for message id" in notes


BLACKBOX = [("pid-analyzer", "example_smooth_tune.BBL"), ("betaflight", "LOG00037.BFL")]


def _blackbox(which: tuple[str, str]) -> Path:
    folder, name = which
    tests_data = DATA / folder / name
    return tests_data if tests_data.exists() else need(FLIGHTS / folder / name)


@pytest.mark.parametrize("which", BLACKBOX, ids=[b[1] for b in BLACKBOX])
def test_a_garbled_blackbox_header_is_one_line_without_a_class_name(tmp_path, capsys, which):
    """Garbled headers (seeded: a header line, a byte in it after `H `, a byte put there); each either
    still reads or is refused with one line naming the file and no exception class; most are refused."""
    from flightctl.sim.logs.blackbox import header_end
    raw = _blackbox(which).read_bytes()
    head = header_end(raw)
    lines = [m.span() for m in re.finditer(rb"H [^\n]*\n", raw[:head])]
    rng = np.random.default_rng(49)
    refused = 0
    for k in range(16):
        a, z = lines[int(rng.integers(len(lines)))]
        garbled = bytearray(raw[:head + 200_000])
        garbled[int(rng.integers(a + 2, z - 1))] = int(rng.choice(list(b":,x-9\xff\x00")))
        src, out = tmp_path / f"g{k}.bbl", tmp_path / f"g{k}.csv"
        src.write_bytes(bytes(garbled))
        code = main(["log", "import", str(src), str(out), "--quiet"])
        err = capsys.readouterr().err
        if code == 0:
            continue
        refused += 1
        assert code == 2 and err.count("\n") == 1 and str(src) in err, err
        assert not CLASS_NAME.search(err.split("error: ", 1)[1]), err
        assert not out.exists()
    assert refused >= 4, refused


def test_a_damaged_own_ulog_keeps_its_other_rows_exact(tmp_path, capsys):
    """flightctl's own ULog (roboto-test.ulg imported, then exported) with a flipped size: read back as
    its CSV less the rows lost, each row kept the CSV's own (the same time, each value the CSV's or, where
    the topic holding it lost that sample, empty: never another row's), the loss said in `# damaged:`."""
    csv, ulg = tmp_path / "a.csv", tmp_path / "a.ulg"
    assert main(["log", "import", str(need(ROBOTO)), str(csv), "--quiet"]) == 0
    assert main(["log", "export", str(csv), str(ulg)]) == 0
    bad = tmp_path / "bad.ulg"
    bad.write_bytes(_flipped(5, (0, 1), ulg))
    capsys.readouterr()
    assert main(["log", "import", str(bad), str(tmp_path / "b.csv"), "--quiet"]) == 0
    assert "damaged:" in capsys.readouterr().out
    a, b = read_flight_log(csv, min_rows=10), read_flight_log(tmp_path / "b.csv", min_rows=10)
    said = int(re.search(r"(\d+) rows lost", b.meta["damaged"])[1])
    assert 0 < len(a) - len(b) and abs(said - (len(a) - len(b))) <= 3, (said, len(a) - len(b))
    rows = np.searchsorted(a["t"], b["t"])
    assert np.array_equal(a["t"][rows], b["t"])
    for c in a.columns:
        x, y = a[c][rows], b[c]
        assert np.array_equal(x[np.isfinite(y)], y[np.isfinite(y)]) and not np.isfinite(y[np.isnan(x)]).any(), c
