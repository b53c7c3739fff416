"""`flightctl tune` (issue 17; sim/sweeps/tune.py): the paper's section 3.3 procedure automated. The criteria on
known responses, then the whole procedure on the base model against Table 4."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from flightctl.cli import main
from flightctl.params import TABLE4, load
from flightctl.sim.sweeps import tune


@pytest.mark.parametrize("f", [0.5, 1.0, 3.7])
def test_oscillations_are_periods_in_the_settling_time(f):
    t = np.arange(0, 4, 1 / 450)
    y = 1 - np.cos(2 * np.pi * f * t)              # an undamped step response at f Hz
    assert tune.oscillations(t, y) == pytest.approx(tune.SETTLE_S * f, rel=0.01)
    assert tune.oscillations(t, np.minimum(t, 1.0)) == 0.0


def test_one_overshoot_is_allowed_but_no_fall_back_beyond_the_tolerance():
    t = np.arange(0, 4, 1 / 450)
    for zeta, remains in ((0.3, True), (0.7, False)):
        wn = 10.0
        wd = wn * math.sqrt(1 - zeta ** 2)
        y = 1 - np.exp(-zeta * wn * t) * (np.cos(wd * t) + zeta * wn / wd * np.sin(wd * t))
        assert tune.oscillation_remains(t, y, 0.02) is remains


def test_the_procedure_reproduces_table4_closely_and_writes_its_gains(tmp_path):
    """kp at the paper's oscillation counts lands 5-16 % under Table 4's (the paper stepped kp by
    hand past the threshold); kd at 'no oscillation after the single overshoot' about half of Table
    4's, whose loops have no overshoot at all (docs/tune.md)."""
    out, js = tmp_path / "g.toml", tmp_path / "t.json"
    assert main(["tune", "--out", str(out), "--json", str(js)]) == 0
    found = json.loads(js.read_text())
    g = load(out).gains
    for ch, name in tune.NAME.items():
        kp, kd = getattr(g, f"kp_{name}"), getattr(g, f"kd_{name}")
        assert found[ch]["kp"] == pytest.approx(kp) and found[ch]["oscillations_at_kp"] >= tune.OSCILLATIONS[ch]
        assert 0.8 * getattr(TABLE4, f"kp_{name}") < kp <= getattr(TABLE4, f"kp_{name}")
        assert 0.4 * getattr(TABLE4, f"kd_{name}") < kd < getattr(TABLE4, f"kd_{name}")
        assert getattr(g, f"ki_{name}") == 0.0
    assert "flightctl tune" in out.read_text()


def test_the_strict_reading_gives_table4s_damping(tmp_path):
    """No overshoot beyond the allowable error: kd within 25 % of Table 4's on every channel."""
    out = tmp_path / "s.toml"
    assert main(["tune", "--strict", "--out", str(out)]) == 0
    g = load(out).gains
    for name in tune.NAME.values():
        assert getattr(g, f"kd_{name}") == pytest.approx(getattr(TABLE4, f"kd_{name}"), rel=0.25)


def _slow_motors(lo: float, hi: float):
    """paper-as-flown with the motor time constant's range narrowed to [lo, hi], the rotor inertia at its
    nominal value (a drawn Jp would move the range's top: sim/sweeps/montecarlo.py `draw`)."""
    import dataclasses
    from flightctl.sim import causes
    p = causes.load_vehicle("paper-as-flown")
    effects = tuple(dataclasses.replace(e, ranges=tuple((n, lo, hi) if n == "tau" else (n, a, b) for n, a, b in e.ranges))
                    if e.cause == "motor_dynamics" else e for e in p.effects)
    return dataclasses.replace(p, effects=effects, ranges=())


def test_robust_mode_finds_bank_gains_that_fly_where_table4_crashes_on_slow_motors(monkeypatch):
    """With motors of 100-150 ms (the slow half of the as-flown range), where Table 4's roll and pitch
    gains, tuned on the instant-thrust base model, crash, the robust search from them finds smaller
    bank gains that fly and land in a clearly larger share of the same draws and ring less (the Monte
    Carlo's judgement, sim/sweeps/judge.py), reports what the batched simulator gives again, and is
    the best of its grid by its own ranking."""
    monkeypatch.setattr(tune, "COARSE", (0.2, 0.45, 1.0))
    monkeypatch.setattr(tune, "FINE", (0.9, 1.0, 1.12))
    params = _slow_motors(0.10, 0.15)
    base = TABLE4
    gains, found = tune.robust(params, base, 6, seed=4, scenario="step_roll")
    assert found["flies"] >= found["procedure"]["flies"] + 0.5
    assert found["score"] is not None
    assert found["procedure"]["score"] is None or found["score"] < found["procedure"]["score"]
    assert gains.kp_phi < base.kp_phi and gains.kp_theta < base.kp_theta
    assert (gains.kp_z, gains.kd_psi) == (base.kp_z, base.kd_psi)     # the other loops stay the procedure's
    again = tune.shares(params, [gains], 6, seed=4, scenario="step_roll")[0]
    assert again == {k: found[k] for k in ("flies", "holds", "score")}
    assert max((g["holds"], g["flies"]) for g in found["grid"]) == (found["holds"], found["flies"])


@pytest.mark.slow
def test_robust_cli_writes_the_gains_their_provenance_and_both_plots(tmp_path, monkeypatch):
    monkeypatch.setattr(tune, "COARSE", (0.3, 1.0))
    monkeypatch.setattr(tune, "FINE", (0.9, 1.0))
    out, js, png = tmp_path / "g.toml", tmp_path / "t.json", tmp_path / "t.png"
    assert main(["tune", "--params", "paper-as-flown", "--robust", "2", "--scenario", "step_roll", "--out", str(out),
                 "--json", str(js), "--plot", str(png)]) == 0
    found = json.loads(js.read_text())["robust"]
    g = load(out).gains
    assert g.kp_phi == pytest.approx(found["kp_factor"] * found["procedure_gains"]["kp_phi"])
    assert "flightctl tune --robust 2" in out.read_text()
    assert png.stat().st_size > 10000 and (tmp_path / "t-grid.png").stat().st_size > 10000
    assert 0.0 <= found["table4"]["holds"] <= found["table4"]["flies"] <= 1.0
    assert 0.0 <= found["table6"]["holds"] <= found["table6"]["flies"] <= 1.0


def test_a_step_holds_when_it_rings_and_holds_within_its_band_whatever_the_estimators_bias():
    """judge.holds, the robust search's criterion, on three vehicles flying step_roll's bank: one held
    steady with the estimator's bias of a drawn 0.6-1 degree (it holds: the bias is the estimator's),
    one still swinging by a drawn 1.5-3 degrees peak to peak, one whose controller holds a drawn
    1.5-3 degrees off its command (neither holds); each with the others' figures unchanged."""
    from flightctl.sim.flights.scenarios import SCENARIOS
    from flightctl.sim.sweeps import judge
    rng = np.random.default_rng(31)
    step = SCENARIOS["step_roll"]().steps[0]
    t = np.arange(0.0, step.t + step.window + 1.0, 1 / 450)
    bias, swing, off = np.radians(rng.uniform(0.6, 1.0)), np.radians(rng.uniform(1.5, 3.0)), np.radians(rng.uniform(1.5, 3.0))
    cmd = np.where(t >= step.t, step.end, step.start)
    est = np.stack([cmd, cmd, cmd + off * (t >= step.t)], axis=1)
    true = est + np.stack([np.full_like(t, bias), 0.5 * swing * np.sin(2 * np.pi * 1.3 * t), np.zeros_like(t)], axis=1)
    log = {"t": t, "true_roll": true, "roll": est}
    figures = judge.step_figures(log, [step], 0.0)
    assert judge.holds(figures, np.array([True, True, True])).tolist() == [True, False, False]
    assert judge.holds(figures, np.array([False, True, True])).tolist() == [False, False, False]   # a crash never holds
    assert abs(figures[0]["bias"][0] - np.degrees(bias)) < 1e-9 and figures[0]["ringing"][1] > 1.0
