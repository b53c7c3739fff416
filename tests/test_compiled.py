"""The compiled plant (sim/compiled.py, numba, the `fast` extra) integrates what the plain one does:
the same RK4 step and forces on random states and inputs for the base model and every ordered
choice of the effects it carries, and the same flight; a model with another effect stays plain."""
import itertools

import numpy as np
import pytest

from without import run_without

from flightctl.logfile import read_flight_log
from flightctl.params import Airframe, load
from flightctl.physics import rotor_speed
from flightctl.sim import causes, compiled
from flightctl.sim.model import N_RIGID, Model
from flightctl.sim.plant import Plant
from flightctl.sim.run import fly
from flightctl.sim.scenarios import SCENARIOS

needs_numba = pytest.mark.skipif(not compiled.enabled(), reason="numba is not installed (the `fast` extra)")

EFFECTS = {"rotor_inflow": {"k": 0.32, "hub": 0.02}, "motor_dynamics": {"tau": 0.05, "tau_down": 0.09},
           "rotor_drag": {"k": 1.1, "yaw": 0.05}}


def models():
    """The base model and every ordered choice of one to three compiled effects (the wrench order matters)."""
    a = Airframe()
    for n in range(len(EFFECTS) + 1):
        for names in itertools.permutations(EFFECTS, n):
            yield names, Model(a, tuple(causes.make(name, **EFFECTS[name]) for name in names))


def random_state(rng, model):
    x = np.concatenate([rng.uniform(-5, 5, 3), rng.uniform(-6, 6, 3), rng.uniform(-1.2, 1.2, 3),
                        rng.uniform(-8, 8, 3), rng.uniform(200.0, 900.0, model.n - N_RIGID)])
    u = tuple(rng.uniform(0.0, 255.0, 4)) + (rng.uniform(14.0, 16.8),)
    return x, u


@needs_numba
def test_compiled_rk4_step_and_forces_equal_the_plain_ones():
    rng = np.random.default_rng(11)
    fast = compiled.model_rk4()
    h = Airframe().dt
    seen = 0
    for names, model in models():
        codes, q = compiled.layout(model)
        plain = Plant(model, h)
        for _ in range(40):
            x, u = random_state(rng, model)
            want = plain._rk4(list(x), 0.0, u, h)
            f = model._commanded(u)
            cmd = np.array(f + [rotor_speed(v, model.a.c1) for v in f])
            got = fast(x, cmd, codes, q, h)
            np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12, err_msg=str(names))
            np.testing.assert_allclose(compiled.rk4(x, cmd, codes, q, h), want, rtol=1e-12, atol=1e-12)
            rotors = model.forces(0.0, list(x), u)             # what the battery and the chip ask for
            for plain_part, fast_part in zip(rotors, compiled.model_forces()(x, cmd, codes, q)):
                np.testing.assert_allclose(fast_part, plain_part, rtol=1e-12, atol=1e-12)
            # the plant's one call a period: the step in place, then the forces at the new state
            for ground in (False, True):
                stepped, out = x.copy(), np.empty(compiled.N_OUT)
                compiled.model_period()(stepped, np.array(u), codes, q, h, ground, out)
                kept = N_RIGID if ground else 0
                np.testing.assert_allclose(stepped[kept:], want[kept:], rtol=1e-12, atol=1e-12)
                assert (stepped[:kept] == x[:kept]).all()      # on the floor the rigid body stays put
                at = model.forces(0.0, stepped.tolist(), u)
                np.testing.assert_allclose(out, np.concatenate([np.ravel(part) for part in at]), rtol=1e-12,
                                           atol=1e-12)
            assert not np.allclose(got[:N_RIGID], x[:N_RIGID], rtol=0, atol=1e-9)
            seen += 1
    assert seen == 16 * 40


def test_a_model_with_another_effect_stays_plain():
    a = Airframe()
    assert compiled.layout(Model(a, (causes.make("actuation_delay", delay=0.002),))) is not None   # the plant's
    assert compiled.layout(Model(a, (causes.make("ground_effect", rotor_radius=0.15),))) is None
    twice = (causes.make("rotor_drag", k=1.0), causes.make("rotor_drag", k=0.5))
    assert compiled.layout(Model(a, twice)) is None
    assert compiled.layout(Model(a, (), vector=True)) is None
    assert Plant(Model(a, (causes.make("ground_effect", rotor_radius=0.15),)), a.dt)._period is None


@needs_numba
@pytest.mark.parametrize("name", ["paper-as-flown", None])
def test_a_flight_is_the_same_compiled_or_plain(tmp_path, monkeypatch, name):
    params = load(name)
    flown = fly(SCENARIOS["step_roll"](), params, tmp_path / "fast.csv", seed=4)
    for attr in ("model_period", "model_forces"):
        monkeypatch.setattr(compiled, attr, lambda: None)
    plain = fly(SCENARIOS["step_roll"](), params, tmp_path / "plain.csv", seed=4)
    assert flown.outcome == plain.outcome == "landed upright"
    for column in ("true_z", "true_roll", "roll", "P1", "gyro_x", "acc_z"):
        np.testing.assert_allclose(flown.log[column], plain.log[column], rtol=0, atol=1e-9)
    assert float(np.ptp(flown.log["true_roll"])) > 0.05    # it did fly the step


def test_the_as_flown_simulator_runs_without_numba(tmp_path):
    """The base install has no numba: the same command flies in plain Python."""
    r = run_without(("numba",), ["sim", "step_roll", "--params", "paper-as-flown", "--log", "f.csv", "--no-plot",
                                 "--quiet"], tmp_path)
    assert r.returncode == 0, r.stderr
    log = read_flight_log(tmp_path / "f.csv")
    assert len(log) > 4000 and float(np.nanmax(log["alt"])) > 0.5     # it flew
