"""`flightctl identify pendulum` (eq. 17-18) and `flightctl identify rotor` (eq. 19-21)."""
import json

import numpy as np
import pytest

from flightctl import params
from flightctl.cli import main

Z = 5.0
J_TRUE = {"x": 0.014002764, "y": 0.014267729, "z": 0.029487252}  # paper, Table 2
M, G = 2.0, 9.80665  # a mass other than the default, given with --params
SIGMA_T = 0.002      # s, on each measured period
TRIALS = 30


def test_pendulum_recovers_the_inertias_with_the_mass_from_params(tmp_path):
    rng = np.random.default_rng(17)
    rows, expected = [], {}
    for axis, J in J_TRUE.items():
        r = rng.uniform(0.26, 0.30, TRIALS)
        T = 2 * np.pi * np.sqrt((J + M * r ** 2) / (M * G * r))  # eq. 17-18 solved for T
        rows += [f"{axis},{ri:.6f},{Ti:.6f}" for ri, Ti in zip(r, T + rng.normal(0, SIGMA_T, TRIALS))]
        dJ_dT = 2 * M * G * r * T / (2 * np.pi) ** 2
        expected[axis] = np.sqrt(np.sum((dJ_dT * SIGMA_T) ** 2)) / TRIALS  # stderr of the mean of the trials
    csv = tmp_path / "pendulum.csv"
    csv.write_text("axis,pivot_distance,period\n" + "\n".join(rows) + "\n")
    toml = tmp_path / "quad.toml"
    toml.write_text(f"M = {M}\n")
    out, png = tmp_path / "fit.json", tmp_path / "fit.png"
    assert main(["identify", "pendulum", str(csv), "--params", str(toml), "--json", str(out),
                 "--write-params", str(toml), "--plot", str(png)]) == 0
    report = json.loads(out.read_text())
    assert report["M"] == M
    for axis, J in J_TRUE.items():
        name = f"J{axis}{axis}"
        assert abs(report[name]["value"] - J) < Z * expected[axis], name
        assert abs(report[name]["stderr"] / expected[axis] - 1) < Z / np.sqrt(2 * (TRIALS - 1)), name
    airframe = params.load(toml).airframe
    assert (airframe.M, airframe.Jzz) == (M, report["Jzz"]["value"])
    assert png.read_bytes()[:4] == b"\x89PNG"


def test_rotor_inertia_is_the_average_of_blade_disc_plus_motor_cylinder(tmp_path):
    blades = [(0.0130, 0.1524), (0.0132, 0.1524), (0.0129, 0.1520), (0.0131, 0.1524)]  # kg, m
    motors = [(0.066, 0.0140), (0.065, 0.0140), (0.067, 0.0141), (0.066, 0.0139)]
    rows = [f"{i},blade,{m},{r}" for i, (m, r) in enumerate(blades, 1)]
    rows += [f"{i},motor,{m},{r}" for i, (m, r) in enumerate(motors, 1)]
    csv = tmp_path / "rotor.csv"
    csv.write_text("rotor,part,mass,radius\n" + "\n".join(rows) + "\n")
    out, toml, png = tmp_path / "fit.json", tmp_path / "p.toml", tmp_path / "fit.png"
    assert main(["identify", "rotor", str(csv), "--json", str(out), "--write-params", str(toml),
                 "--plot", str(png)]) == 0
    per_rotor = np.array([0.5 * mb * rb ** 2 + 0.5 * mm * rm ** 2 for (mb, rb), (mm, rm) in zip(blades, motors)])
    report = json.loads(out.read_text())
    assert report["Jp"]["value"] == pytest.approx(per_rotor.mean(), rel=1e-12)
    assert report["Jp"]["stderr"] == pytest.approx(per_rotor.std(ddof=1) / 2, rel=1e-9)
    assert report["per_rotor"]["3"]["Jp"] == pytest.approx(per_rotor[2], rel=1e-12)
    assert params.load(toml).airframe.Jp == pytest.approx(per_rotor.mean(), rel=1e-12)
    assert png.exists()
