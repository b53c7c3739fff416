"""The compiled plant (sim/world/compiled.py; numba, in the default install where it has wheels)
integrates what the plain one does: the same RK4 step and forces on random states and inputs for the
base model and every ordered choice of the effects it carries, and the same flight; a model with
another effect stays plain."""
import itertools
import os

import numpy as np
import pytest

from helpers.without import run_without

from flightctl.logfile import read_flight_log
from flightctl.params import Airframe, load
from flightctl.physics import rotor_speed
from flightctl.sim import causes
from flightctl.sim.world import compiled, imu
from flightctl.sim.world.model import N_RIGID, Model
from flightctl.sim.world.plant import Plant
from flightctl.sim.flights.run import fly
from flightctl.sim.flights.scenarios import SCENARIOS

needs_numba = pytest.mark.skipif(not compiled.enabled(), reason="numba is not installed (a platform without its wheels)")

EFFECTS = {"rotor_inflow": {"k": 0.32, "hub": 0.02}, "motor_dynamics": {"tau": 0.05, "tau_down": 0.09},
           "rotor_drag": {"k": 1.1, "yaw": 0.05}}


WEAK = {"motor": 3, "scale": 0.83}     # motor_weak: a scale hook (its place among the effects does not matter)


def models():
    """The base model and every ordered choice of one to three compiled effects (the wrench order matters),
    each without and with a weak motor."""
    a = Airframe()
    for n in range(len(EFFECTS) + 1):
        for names in itertools.permutations(EFFECTS, n):
            effects = tuple(causes.make(name, **EFFECTS[name]) for name in names)
            yield names, Model(a, effects)
            yield names + ("motor_weak",), Model(a, effects + (causes.make("motor_weak", **WEAK),))


def random_state(rng, model):
    x = np.concatenate([rng.uniform(-5, 5, 3), rng.uniform(-6, 6, 3), rng.uniform(-1.2, 1.2, 3),
                        rng.uniform(-8, 8, 3), rng.uniform(200.0, 900.0, model.n - N_RIGID)])
    u = tuple(rng.uniform(0.0, 255.0, 4)) + (rng.uniform(14.0, 16.8),)
    return x, u


@needs_numba
def test_the_compiled_step_and_forces_equal_the_plain_ones():
    rng = np.random.default_rng(11)
    h = Airframe().dt
    seen = 0
    for names, model in models():
        codes, q = compiled.layout(model)
        plain = Plant(model, h)
        for _ in range(40):
            x, u = random_state(rng, model)
            want = plain._rk4(list(x), 0.0, u, h)
            f = model._commanded(u)
            cmd = tuple(f + [rotor_speed(v, model.a.c1) for v in f])
            wk = compiled.work(len(x))
            compiled.rk4(x, cmd, codes, q, h, wk, False)                                         # (plain)
            np.testing.assert_allclose(wk[4 * len(x):5 * len(x)], want, rtol=1e-12, atol=1e-12)
            rotors = model.forces(0.0, list(x), u)             # what the battery and the chip ask for
            for plain_part, fast_part in zip(rotors, compiled.model_forces()(x, *u[:4], codes, q)):
                np.testing.assert_allclose(fast_part, plain_part, rtol=1e-12, atol=1e-12)
            # the plant's one call a period: the step in place, then the forces at the new state
            for ground in (True, False):
                stepped, out = x.copy(), np.empty(compiled.N_OUT)
                compiled.model_period()(stepped, *u[:4], codes, q, h, ground, out)
                kept = N_RIGID if ground else 0
                np.testing.assert_allclose(stepped[kept:], want[kept:], rtol=1e-12, atol=1e-12, err_msg=str(names))
                assert (stepped[:kept] == x[:kept]).all()      # on the floor the rigid body stays put
                at = model.forces(0.0, stepped.tolist(), u)
                np.testing.assert_allclose(out, np.concatenate([np.ravel(part) for part in at]), rtol=1e-12,
                                           atol=1e-12)
            assert not np.allclose(stepped[:N_RIGID], x[:N_RIGID], rtol=0, atol=1e-9)   # it moved in the air
            seen += 1
    assert seen == 2 * 16 * 40


@needs_numba
def test_the_compiled_sines_and_cosines_are_maths():
    """LLVM turns a sine and a cosine of one angle into libm's `sincos` (`attitude_trig`): the same bits as
    `math.sin` and `math.cos`, which the plain plant calls apart, from the attitude's angles through rotor
    phases to the largest doubles."""
    import math
    trig = compiled.functions()["attitude_trig"]
    rng = np.random.default_rng(5)
    wk = compiled.work(N_RIGID)
    x = np.zeros(N_RIGID)
    angles = np.concatenate([rng.uniform(-1.6, 1.6, 30000), rng.uniform(-7.0, 7.0, 30000),
                             rng.uniform(-1e4, 1e4, 15000), rng.uniform(-1e9, 1e9, 15000),
                             np.sign(rng.uniform(-1, 1, 15000)) * 10.0 ** rng.uniform(-300, 308, 15000),
                             [0.0, -0.0, 5e-324, math.pi, 0.855469, 2.426265, 105414350.0, 1e22, 1.7976931348623157e308]])
    angles = np.concatenate([angles, np.zeros(-len(angles) % 3)])
    for phi, theta, psi in angles.reshape(-1, 3).tolist():
        x[6:9] = phi, theta, psi
        got = trig(x, 0, wk)
        assert got == (math.sin(phi), math.cos(phi), math.sin(theta), math.cos(theta), math.sin(psi), math.cos(psi))


def test_the_vibration_lines_sines_and_cosines_are_within_an_ulp_of_libms():
    """`imu.sincos` (the chip's rotor lines, arithmetic alone): within 2^-52 of libm's sine and cosine over
    the lines' angles and beyond, the same bits compiled and plain, sin^2 + cos^2 = 1 to an ulp, and libm's
    own values where its reduction would no longer be exact (|x| >= 1e5, a NaN)."""
    import math
    rng = np.random.default_rng(8)
    angles = np.concatenate([rng.uniform(-1.6, 1.6, 20000), rng.uniform(-40.0, 40.0, 40000),
                             rng.uniform(-1e5, 1e5, 5000), np.arange(-400, 401) * (math.pi / 4),
                             np.sign(rng.uniform(-1, 1, 2000)) * 10.0 ** rng.uniform(-300, 0, 2000),
                             [0.0, -0.0, 5e-324, math.pi, 99999.99, 1e5, 1e22]]).tolist()
    fast = compiled.compiled_copy(imu.sincos) if compiled.enabled() else None
    worst = 0.0
    for x in angles:
        s, c = imu.sincos(x)
        if fast is not None:
            assert fast(x) == (s, c), x
        if abs(x) >= 1e5:
            assert (s, c) == (math.sin(x), math.cos(x))
            continue
        worst = max(worst, abs(s - math.sin(x)), abs(c - math.cos(x)))
        assert abs(s * s + c * c - 1.0) <= 4e-16, x
    assert 0.0 < worst <= 2.0 ** -52
    assert all(v != v for v in imu.sincos(math.nan))


@needs_numba
def test_the_compiled_chip_writes_the_plain_ones_registers():
    """`imu.chip_frame` compiled and plain, from the same state, constants and noise: the same
    register bytes and the same state after, over random truths, rotors and read intervals, with a
    value beyond the int16 range (and beyond int64: clipped, never wrapped) now and then."""
    rng = np.random.default_rng(5)
    fast = imu.chip_frame_compiled()
    noise = rng.standard_normal(64)
    for k in range(300):
        s = rng.uniform(-3.0, 3.0, imu.N_CHIP_STATE)
        c = rng.uniform(-0.5, 0.5, imu.N_CHIP_CONST)
        c[[imu._C_A_LSB, imu._C_G_LSB]] = rng.uniform(1e3, 2e4, 2)
        c[[imu._C_KA, imu._C_KG]] = rng.uniform(0.0, 1.0, 2)
        c[[imu._C_TC2, imu._C_PERIOD, imu._C_A_DELAY, imu._C_TCG2, imu._C_G_DELAY]] = \
            rng.uniform(1e-6, 5e-3, 5)
        c[imu._C_KV] = rng.choice([0.0, rng.uniform(0.0, 0.01)])
        c[imu._C_KVG] = rng.choice([0.0, rng.uniform(0.0, 0.01)])
        c[[imu._C_BB, imu._C_H2, imu._C_H3, imu._C_YAW]] = rng.uniform(0.0, 1.0, 4)
        c[[imu._C_BBA, imu._C_BBQ]] = imu.read_gains(c, float(rng.uniform(1e-4, 5e-3)))[2:]
        truth = list(rng.uniform(-20.0, 20.0, 6))
        if k % 10 == 0:
            truth[k % 6] = rng.choice([1e5, -1e5, 1e30, -1e30, np.inf])
        rotors = list(rng.uniform(-1.0, 8.0, 4)) + list(rng.uniform(0.0, 900.0, 4))
        rest = [float(rng.uniform(0.0, 100.0)), float(rng.choice([0.0, 1 / 450])), float(rng.uniform(20.0, 40.0)),
                bool(k % 7)]
        regs_plain, regs_fast = bytearray(128), np.zeros(128, dtype=np.uint8)
        s_plain = s.tolist()
        imu.chip_frame(regs_plain, s_plain, c.tolist(), noise.tolist(), 3, *truth, *rotors, *rest)
        fast(regs_fast, s, c, noise, 3, *truth, *rotors, *rest)
        assert bytes(regs_fast) == bytes(regs_plain), k
        np.testing.assert_allclose(s, s_plain, rtol=1e-13, atol=1e-13)
    assert imu._i16(1e30) == 32767 and imu._i16(-np.inf) == -32768 and imu._i16(-2.5) == -3
    with pytest.raises(ValueError):
        imu._i16(float("nan"))


def test_a_model_with_another_effect_stays_plain():
    a = Airframe()
    assert compiled.layout(Model(a, (causes.make("actuation_delay", delay=0.002),))) is not None   # the plant's
    assert compiled.layout(Model(a, (causes.make("ground_effect", rotor_radius=0.15),))) is None
    twice = (causes.make("rotor_drag", k=1.0), causes.make("rotor_drag", k=0.5))
    assert compiled.layout(Model(a, twice)) is None
    assert Plant(Model(a, (causes.make("ground_effect", rotor_radius=0.15),)), a.dt)._period is None


@needs_numba
@pytest.mark.parametrize("name", ["paper-as-flown", None])
def test_a_flight_is_the_same_compiled_or_plain(tmp_path, monkeypatch, name):
    params = load(name)
    flown = fly(SCENARIOS["step_roll"](), params, tmp_path / "fast.csv", seed=4)
    for attr in ("model_period", "model_forces"):
        monkeypatch.setattr(compiled, attr, lambda: None)
    monkeypatch.setattr(imu, "chip_frame_compiled", lambda: None)
    plain = fly(SCENARIOS["step_roll"](), params, tmp_path / "plain.csv", seed=4)
    assert flown.outcome == plain.outcome == "landed upright"
    for column in ("true_z", "true_roll", "roll", "P1", "gyro_x", "acc_z"):
        np.testing.assert_allclose(flown.log[column], plain.log[column], rtol=0, atol=1e-9)
    assert float(np.ptp(flown.log["true_roll"])) > 0.05    # it did fly the step


def test_the_as_flown_simulator_runs_without_numba(tmp_path):
    """A platform without numba's wheels: the same command flies in plain Python, and says so once."""
    env = {k: v for k, v in os.environ.items() if k != compiled.PLAIN_SAID}
    r = run_without(("numba",), ["sim", "step_roll", "--params", "paper-as-flown", "--log", "f.csv", "--no-plot",
                                 "--quiet"], tmp_path, env)
    assert r.returncode == 0, r.stderr
    assert r.stderr.count("numba is not installed here: the simulated world runs as plain Python") == 1, r.stderr
    log = read_flight_log(tmp_path / "f.csv")
    assert len(log) > 4000 and float(np.nanmax(log["alt"])) > 0.5     # it flew
