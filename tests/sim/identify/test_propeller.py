"""`flightctl identify bench`: eq. 26-28 recovered from synthetic bench data with known noise.

Tolerances come from the noise and the design: the standard error a fit should have is computed
here from the noise level and the true model (sigma^2 (J^T J)^-1), and every check allows Z of them.
"""
import json

import numpy as np
import pytest

from flightctl import params
from flightctl.cli import main
from flightctl.logfile import BENCH_COLUMNS, Table
from flightctl.sim.identify.propeller import fit_bench, fit_motor, motor_points

Z = 5.0  # standard errors allowed: a false failure about once in a million checks
TRUE = {"h1": 1.49e-3, "h2": 120.0, "c1": 1.47e-5, "g1": 0.020, "g2": 0.002}  # conventions.md defaults
SIGMA_F, SIGMA_TAU = 0.02, 5e-4  # N, N m
P_GRID = np.linspace(100.0, 250.0, 31)  # 5 points in the dead zone P <= h2
V = 14.8


def bench_rows(rng, motors=(1, 2, 3, 4)) -> np.ndarray:
    """motor, P, thrust, omega, voltage, current; thrust and torque (through the current) noisy."""
    rows = []
    for m in motors:
        f = TRUE["h1"] * np.clip(P_GRID - TRUE["h2"], 0, None) ** 2
        w = np.sqrt(f / TRUE["c1"])
        tau = TRUE["g1"] * f + TRUE["g2"] + rng.normal(0, SIGMA_TAU, f.size)
        current = np.where(w > 0, tau * np.where(w > 0, w, 1) / V, 0.1)
        rows.append(np.column_stack([np.full(f.size, m), P_GRID, f + rng.normal(0, SIGMA_F, f.size), w,
                                     np.full(f.size, V), current]))
    return np.vstack(rows)


def write_csv(path, rows):
    np.savetxt(path, rows, delimiter=",", header=",".join(BENCH_COLUMNS), comments="", fmt="%.10g")
    return path


def expected_stderr(n_motors: int) -> tuple[dict[str, float], int]:
    """The standard error of each averaged parameter from the noise and the design, and the smallest
    residual degrees of freedom of the per-motor fits."""
    x = P_GRID[P_GRID > TRUE["h2"]] - TRUE["h2"]
    J26 = np.column_stack([x ** 2, -2 * TRUE["h1"] * x])
    f = TRUE["h1"] * np.clip(P_GRID - TRUE["h2"], 0, None) ** 2
    w2 = f / TRUE["c1"]
    A28 = np.column_stack([f[f > 0], np.ones(np.sum(f > 0))])
    one = {**dict(zip(("h1", "h2"), np.sqrt(np.diag(SIGMA_F ** 2 * np.linalg.inv(J26.T @ J26))))),
           "c1": SIGMA_F / np.sqrt(np.sum(w2 ** 2)),
           **dict(zip(("g1", "g2"), np.sqrt(np.diag(SIGMA_TAU ** 2 * np.linalg.inv(A28.T @ A28)))))}
    return {k: v / np.sqrt(n_motors) for k, v in one.items()}, len(A28) - 2


def test_bench_recovers_parameters_and_their_stderr(tmp_path, capsys):
    csv = write_csv(tmp_path / "bench.csv", bench_rows(np.random.default_rng(7)))
    out, toml, png = tmp_path / "fit.json", tmp_path / "fitted.toml", tmp_path / "fit.png"
    assert main(["identify", "bench", str(csv), "--json", str(out), "--write-params", str(toml),
                 "--plot", str(png)]) == 0
    report = json.loads(out.read_text())
    sigma, dof = expected_stderr(4)
    # the averaged stderr pools 4 fits: its relative scatter is 1 / sqrt(2 * 4 * dof)
    ratio_tol = Z / np.sqrt(2 * 4 * dof)
    for name, truth in TRUE.items():
        assert abs(report[name]["value"] - truth) < Z * sigma[name], name
        assert abs(report[name]["stderr"] / sigma[name] - 1) < ratio_tol, name
        assert set(report[name]) == {"value", "stderr"}
    assert report["residual_rms"]["thrust_omega"] == pytest.approx(SIGMA_F, rel=Z / np.sqrt(2 * 4 * 31))
    assert report["residual_rms"]["torque"] == pytest.approx(SIGMA_TAU, rel=Z / np.sqrt(2 * 4 * dof))
    assert all(r2 > 0.999 for r2 in report["r2"].values())
    assert sorted(report["per_motor"]) == ["1", "2", "3", "4"]
    assert "motor_spread" in report and "stderr_method" in report
    assert params.load(toml).airframe.h1 == pytest.approx(report["h1"]["value"])
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "h1 =" in capsys.readouterr().out


def test_bench_stderr_matches_the_scatter_over_seeds():
    """(estimate - truth) / reported stderr has mean 0 and standard deviation 1 over many noise draws."""
    n = 100
    z = {k: [] for k in TRUE}
    for seed in range(n):
        rows = bench_rows(np.random.default_rng(1000 + seed), motors=(1,))
        fits = fit_motor(motor_points(*rows[:, 1:].T))
        for fit in fits.values():
            for name in fit.names:
                z[name].append((fit[name] - TRUE[name]) / fit.error(name))
    for name, values in z.items():
        assert abs(np.mean(values)) < Z / np.sqrt(n), name
        assert abs(np.std(values) - 1) < Z / np.sqrt(2 * n), name


def test_write_params_updates_an_existing_file_and_keeps_other_values(tmp_path):
    toml = tmp_path / "quad.toml"
    toml.write_text("M = 2.0\n")
    csv = write_csv(tmp_path / "bench.csv", bench_rows(np.random.default_rng(3)))
    assert main(["identify", "bench", str(csv), "--json", str(tmp_path / "a.json"), "--write-params", str(toml)]) == 0
    airframe = params.load(toml).airframe
    assert airframe.M == 2.0
    assert airframe.c1 == pytest.approx(TRUE["c1"], rel=0.01)
    assert "flightctl identify bench" in toml.read_text()


def test_average_of_two_motors_is_the_mean_of_their_values():
    rows = bench_rows(np.random.default_rng(5), motors=(2, 4))
    table = Table("mem.csv", dict(zip(BENCH_COLUMNS, rows.T)), {}, np.arange(len(rows)) + 2)
    result = fit_bench(table)
    for name in TRUE:
        assert result.value[name] == pytest.approx(np.mean([result.motor_values(m)[name] for m in (2, 4)]))
