"""The pilot's judge (sim/sweeps/judge.py: `bounded`, `verdict`): a flight holds when it lands upright
and every bank and turn rings within the bound taken from sec. 3.3's tuning steps, its own held error
within SETTLED_DEG; the paper's account needs both gain sets to hold. Flights' figures drawn by a
seeded generator; the committed Monte Carlo re-judged over the bound (scripts/as_flown_mc.py)."""
from __future__ import annotations

import json
import random

from flightctl.sim.flights.metrics import SETTLED_DEG
from flightctl.sim.sweeps import judge
from helpers.script import load

CHANNELS = ("roll", "pitch", "yaw")


def _flight(r: random.Random, flies: bool = True) -> dict:
    """A flight's summary with every channel within its bound and band, at a random fraction of them."""
    out = {"flies": flies, "score": None}
    for ch in CHANNELS:
        out[ch] = {"ringing_deg": r.uniform(0.0, 1.0) * judge.RING_BOUND_DEG[ch],
                   "held_deg": r.uniform(0.0, 1.0) * SETTLED_DEG[ch], "damping": 0.5, "bias_deg": 1.0}
    out["score"] = max(out[ch]["ringing_deg"] / SETTLED_DEG[ch] for ch in CHANNELS)
    return out


def test_a_flight_holds_until_one_channel_rings_or_strays_past_its_bound():
    r = random.Random(3701)
    for _ in range(200):
        f = _flight(r)
        assert judge.bounded(f)
        assert not judge.bounded({**f, "flies": False})          # a crash or a hard landing never holds
        ch, what = r.choice(CHANNELS), r.choice(("ringing_deg", "held_deg"))
        limit = judge.RING_BOUND_DEG[ch] if what == "ringing_deg" else SETTLED_DEG[ch]
        over = {**f, ch: {**f[ch], what: limit * r.uniform(1.001, 5.0)}}
        assert not judge.bounded(over), (ch, what)
        if what == "ringing_deg":   # a looser bound lets it hold again
            assert judge.bounded(over, scale=over[ch][what] / judge.RING_BOUND_DEG[ch] + 1e-9)


def test_the_account_needs_both_tables_within_the_bound_and_implies_the_landing_only_one():
    r = random.Random(3702)
    seen = set()
    for _ in range(400):
        t4, t6 = _flight(r, r.random() < 0.8), _flight(r, r.random() < 0.8)
        if r.random() < 0.5:        # Table 4 limit-cycles in a bank
            t4["roll"]["ringing_deg"] = judge.RING_BOUND_DEG["roll"] * r.uniform(1.01, 10.0)
            t4["score"] = max(t4["score"], t4["roll"]["ringing_deg"] / SETTLED_DEG["roll"])
        v = judge.verdict(t4, t6)
        account = judge.bounded(t4) and judge.bounded(t6) and t6["score"] < t4["score"]
        assert v["paper's account"] == account
        assert not v["paper's account"] or v["paper's account, landing only"]
        assert v["paper's account, landing only"] == (t4["flies"] and t6["flies"] and t6["score"] < t4["score"])
        seen.add((v["paper's account"], v["paper's account, landing only"]))
    assert seen == {(True, True), (False, True), (False, False)}


def test_over_the_committed_monte_carlo_a_looser_bound_never_holds_fewer():
    mc = load("as_flown_mc")
    result = mc.rejudge(json.loads(mc.JSON.read_text()))
    curve = mc.over_bound(result)
    for a, b in zip(curve, curve[1:]):
        assert all(x <= y for x, y in zip(a[1:4], b[1:4])), (a, b)
    n = result["n"]
    landing = sum(r["paper's account, landing only"] for r in result["draws"])
    assert curve[-1][3] <= landing <= n
    _, b4, b6, account = next(c[:4] for c in curve if c[0] == 1.0)
    assert account == round(result["paired"]["paper's account"] * n) <= min(b4, b6)
