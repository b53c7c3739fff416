"""The compiled plant (sim/compiled.py, numba, the `fast` extra) integrates what the plain one does:
the same RK4 step on random states and inputs, and the same flight."""
import numpy as np
import pytest

from flightctl.params import Airframe, load
from flightctl.sim import compiled
from flightctl.sim.model import Model, rk4_rigid
from flightctl.sim.plant import Plant
from flightctl.sim.run import fly
from flightctl.sim.scenarios import SCENARIOS

needs_numba = pytest.mark.skipif(not compiled.enabled(), reason="numba is not installed (the `fast` extra)")


def random_states(rng, n):
    for _ in range(n):
        x = np.concatenate([rng.uniform(-5, 5, 3), rng.uniform(-6, 6, 3), rng.uniform(-1.2, 1.2, 3),
                            rng.uniform(-8, 8, 3)])
        u = tuple(rng.uniform(0.0, 255.0, 4)) + (rng.uniform(14.0, 16.8),)
        yield x, u


@needs_numba
def test_compiled_rk4_step_equals_the_plain_plant_step():
    rng = np.random.default_rng(11)
    a = Airframe()
    model = Model(a)
    plain = Plant(Model(a), a.dt)
    plain._fast = None
    fast = compiled.rk4_rigid()
    c = np.array(model.rigid_constants)
    h = a.dt
    for x, u in random_states(rng, 200):
        want = plain._rk4(list(x), 0.0, u, h)
        agg = np.array(model.aggregate(0.0, list(x), u))
        got = fast(x, agg, h, c)
        np.testing.assert_allclose(got, want, rtol=1e-13, atol=1e-12)
        np.testing.assert_allclose(rk4_rigid(x, agg, h, c), want, rtol=1e-13, atol=1e-12)   # the plain source
        assert not np.array_equal(got, x)


@needs_numba
def test_a_flight_is_the_same_compiled_or_plain(tmp_path, monkeypatch):
    params = load(None)
    flown = fly(SCENARIOS["step_roll"](), params, tmp_path / "fast.csv", seed=4)
    monkeypatch.setattr(compiled, "rk4_rigid", lambda: None)
    plain = fly(SCENARIOS["step_roll"](), params, tmp_path / "plain.csv", seed=4)
    assert flown.outcome == plain.outcome == "landed upright"
    for column in ("true_z", "true_roll", "roll", "P1", "gyro_x"):
        np.testing.assert_allclose(flown.log[column], plain.log[column], rtol=0, atol=1e-9)
    assert float(np.ptp(flown.log["true_roll"])) > 0.05    # it did fly the step
