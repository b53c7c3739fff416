"""One centre of mass per flight (sim/diagnose/static/centre.py, issue 45): on the INDIflight logs that
measured their rotor speeds (../shared/data/real/flights/indiflight, omegaUnfiltered) the report names the
rotor speeds' figure, which an independent computation from the same log's speeds reproduces, and keeps the
base model's and the commands' as checks; the commands' figure, once each rotor's thrust per command from
its speed is in it, agrees with the speeds' (on LOG00257 the commands alone put dy at 0.65x of it)."""
from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from flightctl.cli import main
from flightctl.logfile import read_flight_log
from flightctl.params import Airframe
from flightctl.sim.diagnose.data import FOREIGN_COLUMNS, Layout, load_file
from flightctl.sim.diagnose.rotorspeed import rotor_gain_check, trim_pattern
from flightctl.sim.diagnose.static import centre
from helpers.real import INDIFLIGHT, need

pytest.importorskip("orangebox")


DOC = Path(__file__).resolve().parents[4] / "docs" / "diagnose.md"


def doc_row(name: str, com: dict) -> str:
    """The row of docs/diagnose.md's "Centre of mass" table for this report's `centre_of_mass`: the one
    figure, then each check (in `SOURCES` order) with its agreement."""
    def cell(c):
        return f"{c['dx']:+.4f} ± {c['stderr'][0]:.2g}, {c['dy']:+.4f} ± {c['stderr'][1]:.2g}"
    checks = {c["source"]: c for c in com["checks"]}
    cells = [f"{com['source']}: {cell(com)}"]
    for src in (centre.BASE, centre.GAINS, centre.COMMANDS):
        c = checks[src]
        cells.append(f"{cell(c)}: {'agrees' if c['agree'] else 'disagrees'} ({c['sigmas'][0]:g}, {c['sigmas'][1]:g} σ)")
    assert "flag" not in checks[centre.COMMANDS], checks[centre.COMMANDS]
    w = checks[centre.COMMANDS]["with_speeds"]
    cells.append(f"{w['dx']:+.4f}, {w['dy']:+.4f}")
    return f"| indiflight/{name} | " + " | ".join(cells) + " |"


def independent(csv) -> tuple[float, float, float]:
    """(dx, dy, h2): d = sum_i mean(Omega_i^2) r_i / sum_i mean(Omega_i^2) over every airborne row with all four
    speeds (not the report's hover blocks, not its jackknife, the layout's positions from their own mean), and
    the median over the rotors of the command at which each rotor's straight line Omega_i(P_i) (numpy's polyfit
    on the same rows) reaches zero: eq. 26's h2 as the speeds give it."""
    f = load_file(read_flight_log(str(csv), extra=FOREIGN_COLUMNS), Airframe())
    ok = f.airborne & np.isfinite(f.omega).all(axis=0)
    w = f.omega[:, ok].astype(float)
    m = (w * w).mean(axis=1)
    R = np.column_stack([f.layout.x, f.layout.y])
    R = R - R.mean(axis=0)
    d = m @ R / m.sum()
    lines = [np.polyfit(np.asarray(f.P, float)[i, ok], w[i], 1) for i in range(4)]
    return float(d[0]), float(d[1]), float(np.median([-b / a for a, b in lines]))


@pytest.mark.parametrize("name", ["LOG00230.BFL", "LOG00257.BFL"])
def test_the_flights_one_centre_of_mass_is_its_rotor_speeds_and_an_independent_computation_agrees(tmp_path, name):
    csv = tmp_path / "f.csv"
    assert main(["log", "import", str(need(INDIFLIGHT / name)), str(csv), "--quiet"]) == 0
    assert main(["diagnose", str(csv), "--json", str(tmp_path / "r.json"), "--quiet"]) in (0, 1)
    rep = json.loads((tmp_path / "r.json").read_text())
    com = rep["centre_of_mass"]
    assert com["source"] == centre.SPEEDS and len(com["stderr"]) == 2
    dx, dy, h2 = independent(csv)
    # the static tier reads the commands through the speeds' curve, not an assumed h2 = 0 (issue 45)
    got = re.match(r"eq\. 26 with h2 = (-?[\d.]+) of the log's rotor speeds", rep["static"]["thrust_curve"])
    assert got and abs(float(got[1]) - h2) <= 0.1 and h2 < -0.1 * 255, (rep["static"]["thrust_curve"], h2)
    for got, want, se in ((com["dx"], dx, com["stderr"][0]), (com["dy"], dy, com["stderr"][1])):
        assert abs(got - want) <= 3 * se + 0.003, (name, com, (dx, dy))
    checks = {c["source"]: c for c in com["checks"]}
    assert set(checks) == {centre.BASE, centre.GAINS, centre.COMMANDS}
    for c in checks.values():      # each check's verdict is its difference against the combined standard errors
        z = [abs(c[k] - com[k]) / np.hypot(e, f) for k, e, f in zip(("dx", "dy"), c["stderr"], com["stderr"])]
        near = [abs(c[k] - com[k]) <= centre.AGREE_ABS for k in ("dx", "dy")]
        assert c["agree"] == all(a <= centre.AGREE_SIGMA or b for a, b in zip(z, near)), c
    gains = checks[centre.GAINS]   # the dynamic tier's hover balance, its speeds' part out: within its errors
    assert gains["agree"] and all(e > 0 for e in gains["stderr"]), gains
    w = checks[centre.COMMANDS]["with_speeds"]      # the commands with each rotor's own thrust per command
    assert abs(w["dx"] - com["dx"]) <= 0.003 and abs(w["dy"] - com["dy"]) <= 0.003, (w, com)
    section = DOC.read_text().split("### Centre of mass", 1)[1].split("\n## ", 1)[0]
    assert doc_row(name, com) in section, f"docs/diagnose.md, Centre of mass: the row is now\n{doc_row(name, com)}"


def test_a_base_model_whose_h2_sits_at_its_bound_is_flagged_and_not_chosen():
    rng = np.random.default_rng(45)
    d = rng.uniform(-0.05, 0.05, (2, 2))
    base = {"identified": True, "com": {"dx": d[0, 0], "dy": d[0, 1], "stderr": [0.002, 0.002], "unit": "arm lengths"},
            "h2": {"value": -999.95, "at_bound": True}}
    static = {"thrust_curve": "eq. 26 with h2 from the rotor speeds",
              "pattern": {"com": {"dx": d[1, 0], "dy": d[1, 1], "stderr": [0.001, 0.001], "unit": "arm lengths"}}}
    one = centre.one(base, static)
    assert one["source"] == centre.COMMANDS and (one["dx"], one["dy"]) == (d[1, 0], d[1, 1])
    (check,) = one["checks"]
    assert check["source"] == centre.BASE and "at the end of its search" in check["flag"]
    assert centre.one({**base, "h2": {"value": 40.0, "at_bound": False}}, static)["source"] == centre.BASE
    assert centre.one(None, None) is None


def _x_layout(rng) -> Layout:
    """An X or a +, turned by a drawn angle, arm 1, the spins alternating."""
    turn = rng.choice((0.0, np.pi / 4)) + rng.uniform(-0.1, 0.1)
    a = turn + np.arange(4) * np.pi / 2
    return Layout(tuple(np.cos(a)), tuple(np.sin(a)), (1.0, -1.0, 1.0, -1.0), unit="arm")


def test_the_dynamic_tiers_hover_gains_give_the_drawn_centre_of_mass_with_true_errors_and_a_check_only():
    """Hover gains made of a drawn weak motor and a drawn centre of mass's trim, noise of a drawn size on
    them, the weak motor's speed per command in the speeds: rotor_gain_check's centre of mass (what the
    speeds leave) is the drawn one, its standard errors the spread of the noise's draws, and in `one` it is
    a check only, agreeing or not as the speeds' figure is within its errors or not."""
    rng = np.random.default_rng(4545)
    layout = _x_layout(rng)
    d = rng.uniform(-0.04, 0.04, 2)
    gain = np.ones(4)
    gain[rng.integers(4)] = rng.uniform(0.75, 0.9)              # a weak motor
    sd = rng.uniform(0.003, 0.01)
    clean = gain * (1.0 + trim_pattern(layout) @ d)
    speeds = {"speed_gain": list(np.sqrt(gain))}                 # its speed gives its thrust (eq. 27)
    got = []
    for _ in range(400):
        g = clean * (1.0 + sd * rng.standard_normal(4))
        check = rotor_gain_check(g / g.mean(), [sd] * 4, layout, speeds)
        got.append([check["com"]["dx"], check["com"]["dy"]])
    got, se = np.array(got), np.array(check["com"]["stderr"])
    assert np.abs(got.mean(axis=0) - d).max() < 4 * se.max() / np.sqrt(len(got)) + 1e-4, (got.mean(axis=0), d)
    assert np.all(np.abs(got.std(axis=0) / se - 1.0) < 0.2), (got.std(axis=0), se)
    base = {"identified": True, "com": {"dx": d[0], "dy": d[1], "stderr": [0.005, 0.005], "unit": "arm lengths"},
            "h2": {"value": -60.0, "at_bound": False}}
    for off, agree in ((0.5, True), (8.0, False)):              # the speeds' figure within, then beyond, the errors
        shift = off * np.hypot(se, 0.001) * rng.choice((-1.0, 1.0), 2)
        static = {"pattern": {"rotor_speeds": {"com": {"dx": check["com"]["dx"] + shift[0],
                                                       "dy": check["com"]["dy"] + shift[1],
                                                       "stderr": [0.001, 0.001], "unit": "arm lengths"}}}}
        one = centre.one(base, static, check)
        assert one["source"] == centre.SPEEDS
        (gains,) = [c for c in one["checks"] if c["source"] == centre.GAINS]
        assert gains["agree"] is agree, (off, gains)
    one = centre.one({**base, "h2": {"value": -999.95, "at_bound": True}}, None, check)
    assert one["source"] == centre.BASE                          # the gains' figure is never the one named ...
    (gains,) = one["checks"]
    assert gains["source"] == centre.GAINS and "at the end of its search" in gains["flag"]   # ... and flagged with it
