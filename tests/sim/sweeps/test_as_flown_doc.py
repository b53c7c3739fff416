"""docs/as-flown.md's Monte Carlo block and the README's table of the paper's facts are what
scripts/as_flown_mc.py renders from the committed Monte Carlo (docs/as-flown-mc.json); the JSON's
shares are its draws' outcomes counted; and under `-m slow` a small Monte Carlo, re-run through the
same script, renders a block of the same shape."""
from __future__ import annotations

import json

import pytest

from flightctl.sim.docs import block as _block
from helpers.script import load


def _script():
    return load("as_flown_mc")


def test_the_docs_and_the_readme_hold_what_the_committed_monte_carlo_renders():
    mc = _script()
    result = json.loads(mc.JSON.read_text())
    assert _block(mc.DOC.read_text(), mc.BEGIN, mc.END) == mc.render(result)
    assert _block(mc.README.read_text(), mc.FACTS_BEGIN, mc.FACTS_END) == mc.facts(result)


def test_the_committed_shares_count_the_draws():
    from flightctl.sim.sweeps import judge
    mc = _script()
    result = json.loads(mc.JSON.read_text())
    rows, n = result["draws"], result["n"]
    assert len(rows) == n >= 100
    for g in ("table4", "table6"):
        assert result["share"][g]["flies"] == sum(r[g]["flies"] for r in rows) / n
    for r in rows:   # each draw's verdict follows from its two flights
        assert {k: r[k] for k in judge.verdict(r["table4"], r["table6"])} == judge.verdict(r["table4"], r["table6"])
    assert result["paired"]["paper's account"] == sum(r["paper's account"] for r in rows) / n


@pytest.mark.slow
def test_a_small_monte_carlo_renders_through_the_script(tmp_path):
    from flightctl.sim.sweeps import montecarlo
    mc = _script()
    result = montecarlo.run("paper-as-flown", "paper", 4, seed=3)
    block = mc.render(result)
    assert block.count("\n| Table") == 2 and "paper's account holds in" in block
    assert len(montecarlo.deciding(result)) == len(result["ranges"])
    montecarlo.plot_deciding(result, tmp_path / "d.png")
    assert (tmp_path / "d.png").stat().st_size > 0
