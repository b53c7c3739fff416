"""Issue 44: the paper's evidence (sim/sweeps/evidence.py), the posterior by rejection ABC
(sim/sweeps/posterior.py, scripts/as_flown_posterior.py) and its parameter file
(flightctl/vehicles/paper-posterior.toml).

- the observations' tolerances judge the figures they are given: values drawn from a seeded generator
  on both sides of each bound pass where, and only where, they are within it;
- the EMA is eq. 39's recursion;
- a small run of the whole pipeline on the batched simulator is consistent with itself: the draws that
  pass are those that pass every informative observation, the held-out table counts them, a Bayes factor
  is the ratio of the shares, and the block renders every observation and range;
- the posterior's file says where it comes from, its ranges lie inside the prior's, and a draw from it
  (its point) flies the paper flight with Table 4 and with Table 6 on the full path and lands;
- a bad `--params` path is one line on stderr, exit 2, nothing written.
"""
from __future__ import annotations

import json
import zlib
import subprocess
import sys

import numpy as np
import pytest

from helpers.script import load

from flightctl.params import load as load_params
from flightctl.sim.sweeps import evidence, montecarlo, posterior
from helpers.paths import ROOT

POST = load("as_flown_posterior")


def test_the_ema_is_eq_39s_recursion():
    rng = np.random.default_rng(44)
    x = rng.normal(0.0, 1.0, (500, 3))
    a = 1.0 - np.exp(-1.0 / 128.0)
    y = np.empty_like(x)
    y[0] = x[0]
    for i in range(1, len(x)):
        y[i] = y[i - 1] + a * (x[i] - y[i - 1])
    assert np.allclose(evidence.ema(x, 128), y, rtol=0, atol=1e-12)


def _figures(n, rng, **over):
    """Figures every observation passes, then `over`."""
    f = {"ema_pq": np.full(n, 0.005), "ema_r": np.full(n, 0.003), "ema_half_pq": np.full(n, 0.006),
         "fused_deg": np.full(n, 0.05), "alt_err_m": np.full(n, 0.02), "bank_err_deg": np.full(n, 0.3),
         "turn_err_deg": np.full(n, 1.0), "loop_hz": np.full(n, 450.0), "table4 holds": np.ones(n, bool),
         "table6 holds": np.ones(n, bool), "table6 beats table4": np.ones(n, bool)}
    f.update(over)
    return f


@pytest.mark.parametrize("key, bound, passes_below, obs", [
    ("ema_pq", evidence.P_Q_WITHIN, True, "ema within"),
    ("ema_r", evidence.R_WITHIN, True, "ema within"),
    ("ema_half_pq", evidence.P_Q_WITHIN / evidence.AMPLITUDE_K[1], False, "ema doubled past 64 dt"),
    ("fused_deg", evidence.COMPLEMENTARY_WITHIN_DEG, True, "complementary"),
    ("alt_err_m", evidence.HOVER_ALT_M, True, "figure 17 hover"),
    ("bank_err_deg", 1.0, True, "figure 17 hover"),
    ("turn_err_deg", 3.0, True, "figure 17 hover")])
def test_each_tolerance_passes_within_its_bound_and_fails_beyond_it(key, bound, passes_below, obs):
    rng = np.random.default_rng(zlib.crc32(key.encode()))
    v = bound * rng.uniform(0.3, 2.0, 400)
    verdict = evidence.verdicts(_figures(400, rng, **{key: v}))
    expected = (v <= bound) if passes_below else (v > bound)
    assert expected.any() and (~expected).any()
    assert np.array_equal(verdict[obs], expected)
    others = [o for o in evidence.IDS if o != obs]
    assert all(verdict[o].all() for o in others)      # one figure moves one observation
    assert np.array_equal(evidence.passes(verdict), expected)
    assert evidence.passes(verdict, leave_out=obs).all()


def test_the_loop_rate_is_judged_but_not_informative():
    rng = np.random.default_rng(1)
    v = evidence.verdicts(_figures(5, rng, loop_hz=np.array([449.0, 450.0, 460.0, 470.0, 471.0])))
    assert v["loop rate"].tolist() == [False, True, True, True, False]
    assert "loop rate" not in evidence.INFORMATIVE
    assert evidence.passes(v).all()


def test_a_bayes_factor_is_the_ratio_of_the_shares_with_its_error():
    f = posterior.bayes_factor(40, 1000, 10, 500)
    assert f["factor"] == pytest.approx(2.0)
    # delta method: the relative error of a ratio of two binomial shares
    assert f["error"] == pytest.approx(2.0 * np.sqrt(0.96 / 40 + 0.98 / 10))
    bound = posterior.bayes_factor(40, 1000, 0, 500)
    assert bound["bound"] == ">" and bound["value"] == pytest.approx(0.04 / (3 / 500))
    assert posterior.bayes_factor(0, 100, 5, 100)["bound"] == "<"


def test_the_point_is_the_passing_draw_nearest_the_posteriors_median():
    rng = np.random.default_rng(5)
    draws = {("a", "x"): rng.uniform(0, 1, 301), ("b", "y"): rng.uniform(0, 10, 301)}
    ok = rng.uniform(0, 1, 301) < 0.5
    k = posterior.nearest_median(draws, ok)
    assert ok[k]
    for v in draws.values():
        post = v[ok]
        assert abs(np.mean(post < v[k]) - 0.5) < 0.2


def test_a_small_run_of_the_pipeline_is_consistent(tmp_path):
    result = POST.run(24, 8, 7, 1, terms=("rotor_inflow",), candidates=(), progress=False)
    result = json.loads(json.dumps(result))              # what the JSON holds
    a = POST.analyse(result)
    v = a["verdicts"]
    both = np.logical_and.reduce([v[i] for i in evidence.INFORMATIVE])
    assert np.array_equal(a["ok"], both) and a["passed"] == int(both.sum()) == result["models"]["prior"]["passed"]
    assert {o: int(x.sum()) for o, x in v.items()} == result["models"]["prior"]["observations"]
    for h in a["held_out"]:
        k_given, n_given = h["posterior"]
        assert k_given == a["passed"] and n_given >= a["passed"]
        assert h["prior"] == [int(v[h["observation"]].sum()), 24]
    f = next(x for x in a["factors"] if x["what"] == "rotor_inflow")
    assert f["n"] == 8
    off = result["models"]["without rotor_inflow"]["passed"]
    if a["passed"] and off:
        assert f["factor"] == pytest.approx((a["passed"] / 24) / (off / 8))
    text = POST.render(result)
    for o in evidence.IDS:
        assert f"| {o} |" in text
    for key in result["draws"]:
        assert f"| `{key}` |" in text
    assert len(result["draws"]) == len(montecarlo.ranged(load_params("paper-as-flown")))


def test_the_posterior_file_says_what_it_is_and_lies_inside_the_prior():
    text = (ROOT / "flightctl" / "vehicles" / "paper-posterior.toml").read_text()
    assert "rejection ABC" in text and "scripts/as_flown_posterior.py" in text
    post, prior = load_params("paper-posterior"), load_params("paper-as-flown")
    inside = {(c, n): (lo, hi) for c, n, lo, hi in montecarlo.ranged(prior)}
    spans = montecarlo.ranged(post)
    assert [(c, n) for c, n, _, _ in spans] == list(inside)
    for c, n, lo, hi in spans:
        assert inside[(c, n)][0] - 1e-12 <= lo <= hi <= inside[(c, n)][1] + 1e-12, (c, n)
    for name, _, _ in post.ranges:
        assert "posterior" in post.source(name)


def test_the_posterior_file_is_what_its_run_gives(tmp_path):
    result = json.loads((ROOT / "docs" / "as-flown-posterior.json").read_text())
    POST.write_vehicle(result, tmp_path / "p.toml")
    assert (tmp_path / "p.toml").read_text() == (ROOT / "flightctl" / "vehicles" / "paper-posterior.toml").read_text()
    a = POST.analyse(result)
    assert a["ok"][a["point"]]                           # the file's point is a draw that passed


@pytest.mark.parametrize("gains", ["table4", "table6"])
def test_a_draw_from_the_posterior_flies_the_paper_flight_and_lands(tmp_path, gains):
    log = tmp_path / f"{gains}.csv"
    r = subprocess.run([sys.executable, "-P", "-m", "flightctl.cli", "sim", "paper", "--params", "paper-posterior",
                        "--gains", gains, "--log", str(log), "--quiet"], cwd=tmp_path, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr[-2000:]
    assert log.is_file()
    assert "landed" in (r.stdout + r.stderr)


def test_a_bad_params_path_is_one_line_and_exit_2(tmp_path):
    log = tmp_path / "f.csv"
    r = subprocess.run([sys.executable, "-P", "-m", "flightctl.cli", "sim", "paper", "--params",
                        str(tmp_path / "no" / "such.toml"), "--log", str(log)], cwd=tmp_path, capture_output=True,
                       text=True)
    assert r.returncode == 2
    assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr
    assert not log.exists() and list(tmp_path.iterdir()) == []
