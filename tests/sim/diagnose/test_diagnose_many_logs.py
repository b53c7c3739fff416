"""`flightctl diagnose FILE` of a file of many logs (a blackbox file holds one per arming): each log
that can be judged is diagnosed on its own, the others are named with their reason; exit 0 when at
least one was judged, else 2 with one line naming every reason (docs/diagnose.md)."""
from __future__ import annotations

import json

from flightctl.cli import main
from helpers.real import FLIGHTS, INDIFLIGHT, need


def _header_only() -> bytes:
    """Log 2 of btfl_all.bbl: a Betaflight header and its end-of-log event, no frames."""
    data = need(FLIGHTS / "betaflight" / "btfl_all.bbl").read_bytes()
    return data[10240:13816]


def test_each_log_that_holds_a_flight_is_judged_and_the_others_named(tmp_path, capsys):
    path = tmp_path / "three.BFL"
    path.write_bytes(need(INDIFLIGHT / "LOG00258.BFL").read_bytes() + _header_only()
                     + need(INDIFLIGHT / "LOG00259.BFL").read_bytes())
    out = tmp_path / "r.json"
    assert main(["diagnose", str(path), "--json", str(out), "--quiet"]) == 0
    text = capsys.readouterr().out
    report = json.loads(out.read_text())
    logs = {entry["index"]: entry for entry in report["logs"]}
    assert [logs[i]["judged"] for i in (1, 2, 3)] == [True, False, True]
    assert logs[2]["reason"].startswith("header only")
    assert report["cause"] == logs[1]["report"]["cause"] and "log 1" in report["logs_note"]
    assert "log 1 of 3" in text and "log 3 of 3" in text and "skipped: log 2: header only" in text


def test_a_file_without_a_log_to_judge_is_refused_naming_every_reason(tmp_path, capsys):
    out = tmp_path / "r.json"
    path = need(FLIGHTS / "inav" / "blackbox_log_2026-02-21_145057.TXT")
    assert main(["diagnose", str(path), "--json", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    # none of the three left the ground (logs 1 and 2 idle; log 3's motor 3 held at its minimum for half a
    # second of take-off): each is too short, said with its own numbers
    assert len(err.splitlines()) == 1 and "not logged" not in err
    assert all(f"log {i}: too short to judge" in err for i in (1, 2, 3)) and err.count("idle") == 3, err
    assert not out.exists()
    empty = tmp_path / "empty.bbl"
    empty.write_bytes(_header_only() * 2)
    assert main(["diagnose", str(empty), "--json", str(out)]) == 2
    assert "logs 1-2: header only" in capsys.readouterr().err and not out.exists()
