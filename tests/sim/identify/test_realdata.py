"""The paper's propeller method against real thrust-stand data (../shared/data/real, never copied here)."""
import json

import numpy as np
import pytest

from flightctl.cli import main
from flightctl.logfile import read_table
from flightctl.sim.identify import realdata
from helpers.real import FLIGHTS, need

DATA = FLIGHTS.parent
STEP_FILES = sorted((DATA / "rcbenchmark").glob("StepsTest_2020*.csv"))


@pytest.fixture(autouse=True)
def real_data():
    need(DATA / "rcbenchmark")      # skipped without the shared data, but never in CI


@pytest.fixture(scope="module")
def analysis():
    return realdata.analyse(need(DATA))


def test_adapter_efficiency_agrees_with_the_stands_own_motor_efficiency():
    """tau w / (V I) from the converted columns (gf, RPM, µs -> SI) equals the stand's 'Motor Efficiency (%)',
    which it computes in its own units: the unit conversions are right."""
    column = "Motor Efficiency (%)"
    for path in STEP_FILES:
        run = realdata.read_rcbenchmark(path)
        stand = read_table(path, (column, realdata.RCB["rpm"], realdata.RCB["esc"]), allow_missing=(realdata.RCB["rpm"],))
        kept = (stand[realdata.RCB["rpm"]] > 0) & (stand[realdata.RCB["esc"]] > realdata.ESC_OFF_US)
        assert run.steps == kept.sum()  # the 2020 step tests log one row per step
        # to 0.1 percentage point: the stand computes it from samples that differ slightly from its log
        np.testing.assert_allclose(realdata.efficiency(run), stand[column][kept] / 100, rtol=0, atol=1e-3)
        assert np.all((run.P > 114) & (run.P < 230))  # 1000-2000 µs at 449 Hz


def test_electrical_torque_overstates_the_measured_torque(analysis):
    eta = np.concatenate([r["eta"] for r in analysis["runs"].values()])
    assert len(analysis["runs"]) == len(STEP_FILES) == 11
    assert np.all(eta < 1)  # V I / w > measured torque at every step of every file
    assert 0.2 < np.median(eta) < 0.8
    for r in analysis["runs"].values():
        assert np.corrcoef(r["eta"], np.arange(r["steps"]))[0, 1] > 0.5  # and more so at low speed


def test_extended_models_beat_the_paper_on_held_out_steps(analysis):
    for name, r in analysis["runs"].items():
        for split in realdata.SPLITS:
            rmse = r["rmse"][split]
            assert rmse[realdata.EXT_THRUST] < rmse[realdata.BASE_THRUST], (name, split)
            assert rmse[realdata.EXT_TORQUE] < rmse[realdata.BASE_TORQUE], (name, split)


def test_uiuc_thrust_coefficient_rises_with_speed(analysis):
    change = analysis["uiuc"]["change"]
    assert len(change) > 200
    assert np.median(change) > 0.05
    rel = analysis["uiuc"]["rel"]
    assert np.median(rel[realdata.EXT_THRUST]) < np.median(rel[realdata.BASE_THRUST])


def test_report_command_writes_small_figures_and_only_its_block(tmp_path, capsys):
    doc = tmp_path / "identification.md"
    doc.write_text(f"# Hand-written\n\n{realdata.BEGIN}\nold numbers\n{realdata.END}\n\nMore text.\n")
    assert main(["identify", "real-data", "--data", str(DATA), "--out", str(tmp_path)]) == 0
    for name in ("real_torque.png", "real_ct.png", "real_heldout.png"):
        assert 10_000 < (tmp_path / name).stat().st_size < 150_000
    text = doc.read_text()
    assert text.startswith("# Hand-written\n") and text.endswith("More text.\n")
    assert "old numbers" not in text and "| 2020-06-16_220513 |" in text
    assert "median gain" in capsys.readouterr().out


def test_converted_runs_go_through_identify_bench(tmp_path, capsys):
    bench, out = tmp_path / "bench.csv", tmp_path / "fit.json"
    assert main(["identify", "rcbenchmark", *map(str, STEP_FILES[2:4]), "--out", str(bench)]) == 0
    assert main(["identify", "bench", str(bench), "--json", str(out)]) == 0
    report = json.loads(out.read_text())
    assert report["motors"] == [1, 2]
    assert report["r2"]["thrust_omega"] > 0.99


def test_runs_without_speed_cannot_be_converted(tmp_path, capsys):
    no_speed = sorted((DATA / "rcbenchmark").glob("StepsTest2023*.csv"))[0]
    assert realdata.read_rcbenchmark(no_speed).steps == 0
    code = main(["identify", "rcbenchmark", str(no_speed), "--out", str(tmp_path / "bench.csv")])
    err = capsys.readouterr().err
    assert code == 2 and str(no_speed) in err and err.count("\n") == 1
    assert not (tmp_path / "bench.csv").exists()
