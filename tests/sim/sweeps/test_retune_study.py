"""The paper's retuning in simulation (scripts/retune_study.py, docs/tune.md's `retune study` block): the block is
the table of the stored run (docs/retune-study.json, tests/project/test_docs.py re-checks that), and here a few of the
stored run's vehicles are flown again, from the same seeds, and must give the same rows: the hidden vehicle (its
drawn airframe and, for some, a motor lag, an actuation delay or a weak motor drawn by the study's seeded generator
and never given to `tune --from-log`), the three gain sets' verdicts and what the log gave; for both stored runs, the
vehicles of paper-as-flown's ranges and those of the posterior its flights leave (docs/retune-study-posterior.json)."""
from __future__ import annotations

import json

import pytest

from helpers.script import load
from helpers.paths import ROOT

STUDY = load("retune_study")
RUNS = {"prior": "retune-study.json", "posterior": "retune-study-posterior.json"}


@pytest.fixture(scope="module", params=sorted(RUNS))
def stored(request):
    """A stored run: the hidden vehicles of paper-as-flown's ranges, or of the posterior its flights leave."""
    res = json.loads((ROOT / "docs" / RUNS[request.param]).read_text())
    assert res.get("population", "prior") == request.param
    return res


def test_the_table_counts_its_rows_and_the_hidden_effects_are_drawn_not_told(stored):
    STORED = stored
    rows = STORED["rows"]
    assert len(rows) == STORED["vehicles"] >= 100
    hidden = [r["hidden"] for r in rows if r["hidden"]]
    assert 0.3 < len(hidden) / len(rows) < 0.7                      # the share of 0.5, drawn
    assert {h.split(":")[0] for h in hidden} == set(STUDY.HIDDEN)
    assert len(set(hidden)) == len(hidden)                         # sizes drawn, not a fixed list
    text = STUDY.markdown(STORED)
    t4 = next(line for line in text.splitlines() if line.startswith("| Table 4 |"))
    assert f"of {len(rows)}" in t4
    # the code under test is told nothing of the effect: from_log's arguments are the log, the airframe, targets
    import inspect
    from flightctl.sim.sweeps import fromlog
    assert list(inspect.signature(fromlog.from_log).parameters)[:3] == ["table", "a", "targets"]


def test_three_stored_vehicles_flown_again_give_their_rows(stored):
    STORED = stored
    rows = STORED["rows"]
    flew = [r["vehicle"] for r in rows if r["table4"]["flies"]][:1]        # one whose log can be tuned from
    hid = [r["vehicle"] for r in rows if r["hidden"] and r["vehicle"] not in flew][:2]
    only = sorted(flew + hid)
    again = STUDY.study(STORED["vehicles"], STORED["seed"], STORED["hidden_share"], lambda m: None, only=only,
                        population=STORED.get("population", "prior"))
    assert [r["vehicle"] for r in again["rows"]] == only
    assert again["rows"] == [rows[k] for k in only]
