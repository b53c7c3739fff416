"""Nothing named that the data cannot carry (docs/diagnose.md, "Physical checks"): each cause's size is
checked against the log's own data or a published range before it is named, and one that fits but
fails is reported as "fits, but not physical" with the reason. And `flightctl diagnose --corpus`."""
from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from flightctl.cli import main
from flightctl.logfile import read_flight_log
from flightctl.params import load
from flightctl.sim.causes import CAUSES
from flightctl.sim.diagnose.basemodel import equivalent
from flightctl.sim.diagnose.candidate import MAX_TIMING_S, Result
from flightctl.sim.diagnose.data import FOREIGN_COLUMNS, load_file
from flightctl.sim.diagnose.dataset import DataSet, Vehicle
from helpers.real import FLIGHTS, need
from helpers.diagnose_cases import draw
from test_diagnose_vehicle import fly, rewrite


@pytest.fixture(scope="module")
def foreign(tmp_path_factory):
    """LOG00037 (a 6S pack logged at 17.6-22.6 V) as a data set of an identified vehicle."""
    csv = tmp_path_factory.mktemp("physical") / "LOG00037.csv"
    assert main(["log", "import", str(need(FLIGHTS / "betaflight" / "LOG00037.BFL")), str(csv), "--quiet"]) == 0
    f = load_file(read_flight_log(str(csv), extra=FOREIGN_COLUMNS), load(None).airframe)
    return f


def dataset(f) -> DataSet:
    return DataSet([f], Vehicle(equivalent(0.0), f.layout, (0.0, 0.0, 0.0), identified=True))


def physical(ds, cause, **parameters):
    return CAUSES[cause].candidate(ds).physical(Result(cause, parameters))


def test_a_battery_nominal_voltage_outside_the_packs_measured_range_is_not_physical(foreign):
    ds = dataset(foreign)
    V = foreign.battery_v[np.isfinite(foreign.battery_v)]
    assert physical(ds, "battery_sag", v_nominal=float(np.median(V))) is None
    for v in (40.8, 0.5 * float(V.min()), 1.2 * float(V.max())):
        why = physical(ds, "battery_sag", v_nominal=v)
        assert why is not None and "outside" in why and "this pack showed" in why, (v, why)


def test_the_declared_cell_count_bounds_the_nominal_voltage(foreign):
    ds = dataset(dataclasses.replace(foreign, battery_cells=4))
    why = physical(ds, "battery_sag", v_nominal=20.0)      # inside the measured range, above 4 x 4.35 V
    assert why is not None and "4-cell" in why, why
    assert physical(dataset(dataclasses.replace(foreign, battery_cells=6)), "battery_sag", v_nominal=20.0) is None


def test_the_other_checks(foreign):
    ds = dataset(foreign)
    for cause in ("motor_lag", "actuation_delay", "motor_dynamics", "gyro_lag"):
        name = next(iter(CAUSES[cause].parameters))
        assert physical(ds, cause, **{name: 0.15}) is None
        assert "end of the 0-300 ms search" in physical(ds, cause, **{name: MAX_TIMING_S})
    assert physical(ds, "rotor_drag", k=0.5) is None                 # per unit mass: k/M in 1/s
    assert "above" in physical(ds, "rotor_drag", k=2.9)
    assert physical(ds, "com_offset", dx=0.05, dy=-0.05) is None     # arm lengths: 0.07 of the arm
    assert "reach" in physical(ds, "com_offset", dx=0.3, dy=0.0)     # X layout: the rotors reach 0.71 along x
    assert "outside" in physical(ds, "motor_weak", motor=2, scale=0.4)
    assert physical(ds, "motor_weak", motor=2, scale=0.8) is None


def test_a_battery_sag_that_fits_outside_the_declared_pack_is_reported_and_not_named(tmp_path):
    """A simulated flight with battery_sag hidden at a size drawn from the seeded generator (the 4S pack
    of the simulator, v_nominal 14.6-17.4 V): named when the log says 4 cells, not physical when it
    says 3 (9-13 V), and then reported with the reason."""
    log, truth = fly(tmp_path, "battery_sag", 2601)
    reports = {}
    for cells in (4, 3):
        csv = rewrite(log, tmp_path / f"cells{cells}.csv", [f"battery_cells: {cells}"])
        out = tmp_path / f"cells{cells}.json"
        assert main(["diagnose", str(csv), "--json", str(out), "--quiet"]) == 0
        reports[cells] = json.loads(out.read_text())
    assert reports[4]["cause"] == "battery_sag", reports[4]["causes"]
    assert [c["cause"] for c in reports[3]["causes"]] != ["battery_sag"] and reports[3]["cause"] != "battery_sag"
    (entry,) = [c for c in reports[3]["not_physical"] if c["cause"] == "battery_sag"]
    assert "3-cell" in entry["why"] and entry["parameters"]["v_nominal"] == pytest.approx(truth["v_nominal"], rel=0.02)


def test_the_corpus_command_writes_one_row_per_log_in_parallel(tmp_path, capsys):
    folder = tmp_path / "logs"
    (folder / "sub").mkdir(parents=True)
    csv = folder / "LOG00258.csv"
    assert main(["log", "import", str(need(FLIGHTS / "indiflight" / "LOG00258.BFL")), str(csv), "--quiet"]) == 0
    (folder / "sub" / "broken.bbl").write_text("not a log\n")
    (folder / "sub" / "notes.md").write_text("not a log either: not read\n")
    doc = tmp_path / "doc.md"
    doc.write_text("# before\n<!-- diagnose --corpus table: begin -->\nold\n<!-- diagnose --corpus table: end -->\nafter\n")
    out = tmp_path / "rows.json"
    assert main(["diagnose", "--corpus", str(folder), "--table", str(doc), "--json", str(out), "--jobs", "2",
                 "--quiet"]) == 0
    text = doc.read_text()
    assert text.startswith("# before\n") and text.endswith("after\n") and "\nold\n" not in text
    rows = [r for r in text.splitlines() if r.startswith("| ") and not r.startswith("| log |")]
    assert [r.split(" | ")[0] for r in rows] == ["| LOG00258.csv", "| sub/broken.bbl"]
    assert "not a blackbox log" in rows[1]
    logs = json.loads(out.read_text())["logs"]
    assert [entry["status"] for entry in logs] == ["diagnosed", "refused"]
    single = tmp_path / "single.json"
    assert main(["diagnose", str(csv), "--json", str(single), "--quiet"]) == 0
    assert logs[0]["report"]["causes"] == json.loads(single.read_text())["causes"]


@pytest.mark.parametrize("args, words", [
    (["--corpus", "nowhere", "--table", "t.md"], "not a folder"),
    (["--corpus", "."], "--table"),
    (["--corpus", ".", "--table", "t.md", "--index", "2"], "--index"),
])
def test_corpus_bad_input_is_one_line(tmp_path, capsys, monkeypatch, args, words):
    monkeypatch.chdir(tmp_path)
    assert main(["diagnose", *args]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and words in err, err
