"""`flightctl diagnose` on bad or thin input: one line naming file, row or column, exit status 2,
nothing written; and candidates the data cannot judge are listed with the reason, not guessed."""
from __future__ import annotations

import json

import numpy as np
import pytest

from flightctl.cli import main
from helpers.diagnose_cases import quick_plan


@pytest.fixture(scope="module")
def flight(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("diag")
    path = tmp / "flight.csv"
    main(["sim", "--plan", str(quick_plan(tmp)), "--log", str(path), "--seed", "5", "--no-plot", "--quiet",
          "--effect", "com_offset:dx=0.01,dy=0"])   # 0, or 1 if it lands too fast (helpers.diagnose_cases.run_case)
    assert path.is_file()
    return path


def _lines(path):
    return path.read_text().splitlines(keepends=True)


def _header_index(lines):
    return next(i for i, s in enumerate(lines) if not s.startswith("#"))


def _rewrite(src, dst, edit):
    lines = _lines(src)
    h = _header_index(lines)
    header = lines[h].rstrip("\n").split(",")
    rows = [s.rstrip("\n").split(",") for s in lines[h + 1:]]
    header, rows = edit(header, rows)
    dst.write_text("".join(lines[:h]) + ",".join(header) + "\n" + "".join(",".join(r) + "\n" for r in rows))
    return dst


def _fails(tmp_path, capsys, log, *words):
    out = tmp_path / "out.json"
    assert main(["diagnose", str(log), "--json", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert str(log) in err
    for w in words:
        assert w in err, err
    assert not out.exists()


def test_missing_column_is_named(tmp_path, capsys, flight):
    def drop(header, rows):
        i = header.index("gyro_y")
        return header[:i] + header[i + 1:], [r[:i] + r[i + 1:] for r in rows]
    _fails(tmp_path, capsys, _rewrite(flight, tmp_path / "f.csv", drop), "gyro_y")


def test_non_numeric_cell_names_row_and_column(tmp_path, capsys, flight):
    def spoil(header, rows):
        rows[500][header.index("acc_z")] = "abc"
        return header, rows
    _fails(tmp_path, capsys, _rewrite(flight, tmp_path / "f.csv", spoil), "acc_z", "row")


def test_time_not_increasing_is_named(tmp_path, capsys, flight):
    def spoil(header, rows):
        i = header.index("t")
        rows[800][i] = rows[798][i]
        return header, rows
    _fails(tmp_path, capsys, _rewrite(flight, tmp_path / "f.csv", spoil), "'t'", "row")


def test_too_short_log(tmp_path, capsys, flight):
    _fails(tmp_path, capsys, _rewrite(flight, tmp_path / "f.csv", lambda h, r: (h, r[:300])), "too short")


def test_motors_off_on_the_ground_is_too_short_to_judge(tmp_path, capsys, flight):
    def ground(header, rows):
        rows = rows[:1500]   # 3.3 s on the ground: motors off
        for k in ("P1", "P2", "P3", "P4"):
            i = header.index(k)
            for r in rows:
                r[i] = "0"
        return header, rows
    _fails(tmp_path, capsys, _rewrite(flight, tmp_path / "f.csv", ground), "too short to judge", "airborne")


def test_missing_output_directory_writes_nothing(tmp_path, capsys, flight):
    out = tmp_path / "nowhere" / "out.json"
    assert main(["diagnose", str(flight), "--json", str(out), "--quiet"]) == 2
    assert "nowhere" in capsys.readouterr().err
    assert not out.exists()


def test_no_range_and_constant_battery_are_not_judged(tmp_path, capsys, flight):
    def strip(header, rows):
        ir, ib = header.index("range"), header.index("battery_v")
        for r in rows:
            r[ir] = ""
            r[ib] = "15.9"
        return header, rows
    log = _rewrite(flight, tmp_path / "f.csv", strip)
    out = tmp_path / "out.json"
    assert main(["diagnose", str(log), "--json", str(out), "--quiet"]) == 0
    rep = json.loads(out.read_text())
    skipped = {c["cause"]: c["why"] for c in rep["not_judged"]}
    assert set(skipped) == {"ground_effect", "battery_sag", "rotor_inflow"}
    assert "range" in skipped["ground_effect"] and "battery_v" in skipped["battery_sag"]
    assert "range" in skipped["rotor_inflow"]
    assert rep["cause"] == "com_offset"


def test_two_logs_and_plots(tmp_path, capsys, flight):
    def first_half(header, rows):   # a second file: the first half of the same flight's log again
        return header, rows[:len(rows) // 2]
    other = _rewrite(flight, tmp_path / "g.csv", first_half)
    out, prefix = tmp_path / "out.json", tmp_path / "diag"
    steps_png = tmp_path / "steps.png"
    assert main(["diagnose", str(flight), str(other), "--json", str(out), "--plot", str(prefix), "--steps", str(steps_png),
                 "--quiet"]) == 0
    rep = json.loads(out.read_text())
    # each file's measured steps (docs/steps.md): no rate setpoint logged; the attitude loop's from roll_sp, which
    # the 21 s plan's two bank steps leave to too few windows (the excitation gate); and each file's gains
    assert [s["file"] for s in rep["steps"]] == [str(flight), str(other)] and steps_png.read_bytes()[:4] == b"\x89PNG"
    assert rep["steps"][0]["rate"]["why"].startswith("no rate setpoint in the log")
    assert "windows in the air have the setpoint varying" in rep["steps"][1]["attitude"]["x"]["why"]
    assert [c["firmware"] for c in rep["controller"]] == ["flightctl", "flightctl"]
    assert rep["cause"] == "com_offset" and abs(rep["parameters"]["dx"] - 0.01) < 0.002
    assert set(rep) >= {"cause", "parameters", "rmse_base", "rmse_extended", "gain", "metric", "candidates"}
    assert [c["gain"] for c in rep["candidates"]] == sorted((c["gain"] for c in rep["candidates"]), reverse=True)
    assert np.isclose(rep["gain"], 1 - rep["rmse_extended"] / rep["rmse_base"], atol=1e-4)
    named = rep["candidates"][0]
    assert named["cause"] == "com_offset" and named["significant"] and named["significant_in"]
    channels = rep["channels"]
    for c in rep["candidates"]:   # each channel judged on its own too: gain = 1 - rmse_ext / rmse_base
        assert list(c["channels"]) == list(channels)
    for ch, v in named["channels"].items():
        assert np.isclose(v["gain"], 1 - channels[ch]["rmse_extended"] / channels[ch]["rmse_base"], atol=1e-3)
    for k in ("residuals", "explained"):
        png = tmp_path / f"diag-{k}.png"
        assert png.read_bytes()[:4] == b"\x89PNG"
    text = capsys.readouterr().out
    assert "verdict: com_offset" in text and "Ljung-Box" in text


def test_an_error_after_a_good_log_is_the_only_line_on_stderr(tmp_path, capsys, flight):
    """Without --quiet, and with the first log good: progress must not come before the error line."""
    bad = _rewrite(flight, tmp_path / "bad.csv", lambda h, r: (h, r[:5]))
    out = tmp_path / "out.json"
    assert main(["diagnose", str(flight), str(bad), "--json", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(bad) in err, err
    assert not out.exists()


def test_progress_shows_each_stage_with_its_time_when_stderr_is_not_a_terminal(tmp_path, capsys, flight):
    """capsys is not a terminal: the progress lines come all the same, each with the time elapsed, and
    --quiet silences them."""
    out = tmp_path / "out.json"
    assert main(["diagnose", str(flight), "--json", str(out)]) == 0
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) > 10 and all(line.startswith("diagnose: [") and " s] " in line for line in lines), lines[:3]
    assert any("airborne" in line for line in lines) and "done in" in lines[-1]
    elapsed = [float(line.split("[", 1)[1].split(" s]", 1)[0]) for line in lines]
    assert elapsed == sorted(elapsed)
    assert main(["diagnose", str(flight), "--json", str(out), "--quiet"]) == 0
    assert capsys.readouterr().err == ""
