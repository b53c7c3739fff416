"""`flightctl tune` (issue 17; sim/tune.py): the paper's section 3.3 procedure automated. The criteria on
known responses, then the whole procedure on the base model against Table 4."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from flightctl.cli import main
from flightctl.params import TABLE4, load
from flightctl.sim import tune


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
