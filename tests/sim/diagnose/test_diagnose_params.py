"""`flightctl diagnose --params P` carries the parameter file's `[[effect]]` tables into its base model
(docs/measured-data.md; docs/diagnose.md, "A base model with effects"): flown and diagnosed through the
CLI, with sensor noise, on the shipped as-flown model (rotor_inflow, motor_dynamics, rotor_drag)."""
from __future__ import annotations

import json

import numpy as np
import pytest

from flightctl import params as paramfile
from flightctl.cli import main
from helpers.diagnose_cases import close_enough, draw

AS_FLOWN = "paper-as-flown"


def _fly(tmp, name, seed, *extra):
    log = tmp / f"{name}.csv"
    # 0, or 1 if the landing touches the floor too fast (helpers.diagnose_cases.run_case)
    assert main(["sim", "hover_low", "--params", AS_FLOWN, "--log", str(log), "--seed", str(seed),
                 "--no-plot", "--quiet", *extra]) in (0, 1)
    assert log.is_file()
    return log


def _diagnose(log, out, *extra):
    assert main(["diagnose", str(log), "--json", str(out), "--quiet", *extra]) == 0
    return json.loads(out.read_text())


def _quiet_imu(tmp) -> str:
    """The as-flown file without its [sensors] table: the plant's terms with the reference airframe's
    IMU. The vehicle's gyro noise (docs/as-flown.md) raises the floor of every held-out RMSE, which
    would hide the terms' own share of it; the effects, which diagnose carries, are the file's."""
    lines, skip = [], False
    for line in (paramfile.VEHICLES / f"{AS_FLOWN}.toml").read_text().splitlines():
        if line.startswith("["):
            skip = line.strip() == "[sensors]"
        if not skip:
            lines.append(line)
    path = tmp / "as-flown-quiet-imu.toml"
    path.write_text("\n".join(lines) + "\n")
    assert paramfile.load(path).effects == paramfile.load(AS_FLOWN).effects
    return str(path)


@pytest.fixture(scope="module")
def as_flown_log(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("asflown")
    return _fly(tmp, "as_flown", 3, "--params", _quiet_imu(tmp))


def test_base_model_with_the_files_effects_holds_the_plant(as_flown_log, tmp_path):
    carried = {e.cause: dict(e.parameters) for e in paramfile.load(AS_FLOWN).effects}
    assert set(carried) == {"rotor_inflow", "motor_dynamics", "rotor_drag", "actuation_delay"}
    bare = _diagnose(as_flown_log, tmp_path / "bare.json")
    full = _diagnose(as_flown_log, tmp_path / "full.json", "--params", AS_FLOWN)
    # without the effects the paper's model misses what the plant has; with them nothing is missing
    assert bare["cause"] in carried, bare["cause"]
    assert full["cause"] == "none" and full["parameters"] == {}, (full["cause"], full["parameters"])
    assert full["rmse_base"] < 0.8 * bare["rmse_base"], (full["rmse_base"], bare["rmse_base"])
    assert full["data"]["base_effects"] == [{"cause": c, "parameters": p} for c, p in carried.items()]
    assert bare["data"]["base_effects"] == []
    # a candidate of a carried cause is refitted in its place: it finds the carried value again and
    # gains nothing over the base model that already has it
    cands = {c["cause"]: c for c in full["candidates"]}
    for cause in ("rotor_inflow", "motor_dynamics"):
        ok, what = close_enough(cause, carried[cause], cands[cause]["parameters"])
        assert ok, (cause, what, cands[cause]["parameters"])
        assert abs(cands[cause]["gain"]) < 0.005, cands[cause]
    # rotor_drag is not judged by hover_low's motion (no horizontal speed), but it is carried
    assert not cands["rotor_drag"]["significant"]


def test_hidden_com_offset_on_top_of_the_as_flown_model(tmp_path):
    rng = np.random.default_rng(2024)
    cause, truth = draw(rng, "com_offset")
    effect = "com_offset:" + ",".join(f"{k}={v!r}" for k, v in truth.items())
    log = _fly(tmp_path, "com", 7, "--effect", effect)
    rep = _diagnose(log, tmp_path / "com.json", "--params", AS_FLOWN)
    assert rep["cause"] == "com_offset", (rep["cause"], rep["parameters"])
    ok, what = close_enough(cause, truth, rep["parameters"])
    assert ok, (what, truth, rep["parameters"])
    assert rep["gain"] > 0.05


@pytest.mark.parametrize("effect, words", [
    ('cause = "warp"\nx = 1.0', ("unknown effect", "warp")),
    ('cause = "rotor_drag"\nk = -1.0', ("rotor_drag", "out of range")),
])
def test_bad_carried_effect_is_one_line(as_flown_log, tmp_path, capsys, effect, words):
    p = tmp_path / "bad.toml"
    p.write_text(f"[[effect]]\n{effect}\n")
    out = tmp_path / "out.json"
    assert main(["diagnose", str(as_flown_log), "--params", str(p), "--json", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    for w in words:
        assert w in err, err
    assert not out.exists()
