"""sim/sweeps/batch.py on the engine's workers: several groups per task, the same flights as in one process."""
from __future__ import annotations

import numpy as np
import pytest

from flightctl.params import load
from flightctl.sim import engine
from flightctl.sim.flights.scenarios import SCENARIOS
from flightctl.sim.sweeps import batch
from flightctl.sim.sweeps.montecarlo import draw
from flightctl.sim.world import compiled


@pytest.mark.skipif(not (compiled.enabled() and engine.available()), reason="numba and Dask (the fleet extra)")
def test_groups_packed_into_tasks_fly_as_in_one_process(monkeypatch):
    """Groups of 3 (so that the 2 workers' TASKS each take several, some more than others): each vehicle's
    outcome, seconds and judged record equal to the one-process flight's, in the vehicles' order, and
    the progress reaching 1 task by task."""
    monkeypatch.setattr(batch, "GROUP", 3)
    params = load("paper-as-flown")
    n = 29
    plan = SCENARIOS["step_roll"]().plan
    draws = draw(params, n, seed=48)
    seeds = list(np.random.default_rng(48).integers(0, 1 << 30, n))
    seen = []
    try:
        two = batch.simulate(params, plan, n, draws, seeds=seeds, record=(0.0, 1.5), until=2.0, workers=2,
                             progress=seen.append)
    finally:
        engine.close()
    one = batch.simulate(params, plan, n, draws, seeds=seeds, record=(0.0, 1.5), until=2.0, workers=1)
    assert two.outcome == one.outcome and two.vehicle_steps == one.vehicle_steps
    np.testing.assert_array_equal(two.seconds, one.seconds)
    for column in ("true_roll", "roll", "yaw"):
        np.testing.assert_array_equal(two.log[column], one.log[column])
    assert len(seen) == 2 * batch.TASKS and seen[-1] == 1.0 and seen == sorted(seen)
