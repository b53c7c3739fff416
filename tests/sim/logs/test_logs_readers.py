"""The table of log readers (sim/logs/__init__.py, READERS): a log is read by its content, its magic
bytes, whatever the file is named; a file whose name claims a format its bytes do not have is refused
in one line that names the formats known; a format is one row."""
from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from flightctl.errors import InputError
from flightctl.sim import logs
from flightctl.sim.logs import Reader, count_logs, each_log, kind
from helpers.paths import DATA, ROOT

HERE = DATA
DATAFLASH = HERE / "ardupilot" / "backend_log_80k.bin"
DATAFLASH_TEXT = HERE / "ardupilot" / "nan.log"
BLACKBOX = HERE / "pid-analyzer" / "example_smooth_tune.BBL"
ULOG = ROOT.parent / "shared" / "data" / "real" / "flights" / "px4" / "roboto-test.ulg"


def renamed(tmp_path, source: Path, name: str) -> str:
    path = tmp_path / name
    shutil.copyfile(source, path)
    return str(path)


@pytest.mark.parametrize("source, name, expected", [
    (DATAFLASH, "flight.ulg", "dataflash"), (DATAFLASH, "flight.bbl", "dataflash"), (DATAFLASH, "flight.csv", "dataflash"),
    (BLACKBOX, "flight.bin", "blackbox"), (BLACKBOX, "flight.ulg", "blackbox"),
    (DATAFLASH_TEXT, "flight.bin", "dataflash-text"), (DATAFLASH_TEXT, "flight", "dataflash-text")])
def test_a_renamed_log_is_known_by_its_content(tmp_path, source, name, expected):
    assert kind(renamed(tmp_path, source, name)) == kind(str(source)) == expected


def test_a_dataflash_log_named_ulg_is_read_as_dataflash(tmp_path):
    (e,) = each_log(renamed(tmp_path, DATAFLASH, "flight.ulg"))
    (same,) = each_log(str(DATAFLASH))
    assert e.reason is None and same.reason is None
    assert e.seconds == same.seconds > 0.0 and (e.table["t"] == same.table["t"]).all()


def test_a_blackbox_file_named_bin_holds_its_logs(tmp_path):
    assert count_logs(renamed(tmp_path, BLACKBOX, "flight.bin")) == count_logs(str(BLACKBOX)) >= 1


def test_a_ulog_named_bin_is_read_as_a_ulog(tmp_path):
    if not ULOG.exists():
        pytest.skip(f"{ULOG} (the shared data) is not here")
    path = renamed(tmp_path, ULOG, "flight.bin")
    assert kind(path) == "ulog"
    (e,) = each_log(path)
    (same,) = each_log(str(ULOG))
    assert e.reason is None and same.reason is None
    assert e.seconds == same.seconds > 0.0 and (e.table["t"] == same.table["t"]).all()


@pytest.mark.parametrize("name, called", [("junk.ulg", "not a ULog"), ("junk.bin", "not an ArduPilot DataFlash log"),
                                          ("junk.bbl", "not a blackbox log")])
def test_unknown_content_under_a_log_s_name_is_refused_naming_the_formats_known(tmp_path, name, called):
    path = tmp_path / name
    path.write_bytes(b"\x00\x01 not a log of any kind \xff" * 50)
    with pytest.raises(InputError) as e:
        kind(str(path))
    line = str(e.value)
    assert line.startswith(f"{path}: {called}") and "\n" not in line
    for r in logs.READERS:
        assert r.what in line and "/".join(r.suffixes) in line


def test_a_file_of_no_known_content_and_no_log_s_name_is_refused_by_the_readers(tmp_path):
    path = tmp_path / "notes.dat"
    path.write_text("a,b\n1,2\n")
    assert kind(str(path)) is None                       # not another autopilot's: this project's CSV, maybe
    with pytest.raises(InputError, match="unknown log type .dat: its content is none of PX4's ULog"):
        each_log(str(path))


def test_a_format_is_one_row(tmp_path, monkeypatch):
    """A row added to READERS (magic bytes, a reader by name, several logs per file) is chosen by the
    content, before any other row's suffix, and its split counts the logs."""
    row = Reader("probe", "a probe log", (".ulg",), b"PROBE1", "flightctl.sim.logs.blackbox:read",
                 split="builtins:list", called="a probe log", missing="no PROBE1")
    monkeypatch.setattr(logs, "READERS", (row,) + logs.READERS)
    monkeypatch.setattr(logs, "BY_NAME", {r.name: r for r in logs.READERS})
    path = tmp_path / "x.ulg"
    path.write_bytes(b"PROBE1abc")
    assert kind(str(path)) == "probe"
    assert count_logs(str(path)) == len(b"PROBE1abc")    # builtins.list of the bytes: one "log" a byte
