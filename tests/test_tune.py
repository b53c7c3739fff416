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


@pytest.mark.xfail(strict=True, reason="the robust search's criterion (every step within 1 degree of its command) was "
                   "met on the batch's ideal sensors; the batch now flies the vehicle's own IMU, whose estimator bias "
                   "(0.6-1 degree, docs/as-flown.md) no gains remove: the criterion needs the paper's judgement")
def test_robust_mode_lowers_the_bank_gains_for_slow_motors(monkeypatch):
    """With motors of 100-150 ms (the slow half of the as-flown range), where Table 4's roll and pitch
    gains, tuned on the instant-thrust base model, ring or crash in the Monte Carlo, the robust
    search from them finds smaller bank gains that settle in a clearly larger share of the same
    draws, and reports the share it found as the batched simulator gives it again."""
    monkeypatch.setattr(tune, "COARSE", (0.2, 0.45, 1.0))
    monkeypatch.setattr(tune, "FINE", (0.9, 1.0, 1.12))
    params = _slow_motors(0.10, 0.15)
    base = TABLE4
    gains, found = tune.robust(params, base, 6, seed=4, scenario="step_roll")
    assert found["settles"] >= found["procedure"]["settles"] + 0.5
    assert gains.kp_phi < base.kp_phi and gains.kp_theta < base.kp_theta
    assert (gains.kp_z, gains.kd_psi) == (base.kp_z, base.kd_psi)     # the other loops stay the procedure's
    again = tune.shares(params, [gains], 6, seed=4, scenario="step_roll")[0]
    assert again == {"flies": found["flies"], "settles": found["settles"]}
    assert max(g["settles"] for g in found["grid"]) == found["settles"]


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
    assert 0.0 <= found["table4"]["settles"] <= 1.0 and 0.0 <= found["table6"]["settles"] <= 1.0
