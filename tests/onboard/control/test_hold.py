"""flightctl/control/hold.py: the one zero-order hold of a delayed input, against the plant integrated."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from flightctl.control.hold import delayed, split_delay


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_the_hold_of_a_delayed_input_is_the_integrated_plant(seed):
    rng = np.random.default_rng(seed)
    n, ni = int(rng.integers(2, 6)), int(rng.integers(1, 3))
    A, B = rng.normal(size=(n, n)) * 20.0, rng.normal(size=(n, ni))
    dt = 1.0 / float(rng.uniform(100.0, 1000.0))
    delay = float(rng.uniform(0.0, 4.0)) * dt
    Phi_I, Ga, Gb, m = delayed(A, B, dt, delay)
    assert m == int(delay // dt)
    d = delay - m * dt
    x0, u_old, u_new = rng.normal(size=n), rng.normal(size=ni), rng.normal(size=ni)
    sol = solve_ivp(lambda t, x: A @ x + B @ (u_old if t < d else u_new), (0.0, dt), x0, rtol=1e-12, atol=1e-14,
                    max_step=dt / 200)
    np.testing.assert_allclose(x0 + Phi_I @ x0 + Ga @ u_old + Gb @ u_new, sol.y[:, -1], rtol=1e-8, atol=1e-11)


def test_a_whole_number_of_periods_has_no_fraction():
    dt = 1.0 / 450.0
    assert split_delay(3 * dt, dt) == (3, 0.0)
    A, B = np.array([[-5.0]]), np.array([[1.0]])
    _, Ga, Gb, m = delayed(A, B, dt, 2 * dt)
    assert m == 2 and not Ga.any()
    np.testing.assert_allclose(Gb, (1.0 - np.exp(-5.0 * dt)) / 5.0, rtol=1e-12)
