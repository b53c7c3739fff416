"""`flightctl identify yaw-drag`: eq. 6 recovered from synthetic steady spins with known noise."""
import json

import numpy as np

from flightctl import params
from flightctl.cli import main
from flightctl.logfile import Table
from flightctl.params import Airframe
from flightctl.sim.identify import yaw_drag

Z = 5.0
GAMMA1, GAMMA2 = 4.86291e-4, 1.22958e-3  # paper, Table 2
SIGMA = 2e-4  # N m, on the applied torque
RATES = np.concatenate([-np.linspace(0.5, 3.0, 12), np.linspace(0.5, 3.0, 12)])  # rad/s, both directions


def spins(rng) -> Table:
    tau = (GAMMA1 * RATES ** 2 + GAMMA2) * np.sign(RATES) + rng.normal(0, SIGMA, RATES.size)
    return Table("mem.csv", {"torque": tau, "yaw_rate": RATES}, {}, np.arange(RATES.size) + 2)


def expected_stderr() -> np.ndarray:
    A = np.column_stack([RATES * np.abs(RATES), np.sign(RATES)])
    return np.sqrt(np.diag(SIGMA ** 2 * np.linalg.inv(A.T @ A)))


def test_yaw_drag_recovers_gamma1_gamma2_through_the_cli(tmp_path):
    table = spins(np.random.default_rng(11))
    csv = tmp_path / "yaw_drag.csv"
    np.savetxt(csv, np.column_stack([table["torque"], RATES]), delimiter=",", header="torque,yaw_rate",
               comments="", fmt="%.10g")
    out, toml, png = tmp_path / "fit.json", tmp_path / "p.toml", tmp_path / "fit.png"
    assert main(["identify", "yaw-drag", str(csv), "--json", str(out), "--write-params", str(toml),
                 "--plot", str(png)]) == 0
    assert png.read_bytes()[:4] == b"\x89PNG"
    report = json.loads(out.read_text())
    dof = RATES.size - 2
    for name, truth, sigma in zip(("gamma1", "gamma2"), (GAMMA1, GAMMA2), expected_stderr()):
        assert abs(report[name]["value"] - truth) < Z * sigma
        assert abs(report[name]["stderr"] / sigma - 1) < Z / np.sqrt(2 * dof)
    assert abs(report["residual_rms"]["torque"] / SIGMA - 1) < Z / np.sqrt(2 * dof)
    assert report["spins"] == {"positive": 12, "negative": 12}
    airframe = params.load(toml).airframe
    assert (airframe.gamma1, airframe.gamma2) == (report["gamma1"]["value"], report["gamma2"]["value"])


def test_yaw_drag_stderr_matches_the_scatter_over_seeds():
    """(estimate - truth) / reported stderr has mean 0 and standard deviation 1 over many noise draws."""
    n = 200
    z = []
    for seed in range(n):
        report = yaw_drag.identify(spins(np.random.default_rng(seed)), Airframe()).report
        z.append([(report[k]["value"] - truth) / report[k]["stderr"] for k, truth in (("gamma1", GAMMA1), ("gamma2", GAMMA2))])
    z = np.array(z)
    assert np.all(np.abs(z.mean(axis=0)) < Z / np.sqrt(n))
    assert np.all(np.abs(z.std(axis=0) - 1) < Z / np.sqrt(2 * n))
