"""The zero-order hold of a linear model with a delayed input, the one copy (the two-rotor LQR design,
flightctl/control/spin_design.py, and the sampled-data analysis, sim/analysis/linear.py, both use it).

x' = A x + B u, u held from each instant t_k = k dt and reaching the plant `delay` = m dt + d later
(0 <= d < dt): over one period the input acting is u_(k-m-1) for the first d and u_(k-m) for the rest,
so that exactly (Astrom and Wittenmark, Computer-Controlled Systems, sec. 2.3)

    x_(k+1) = Phi(dt) x_k + Phi(dt - d) Gamma(d) u_(k-m-1) + Gamma(dt - d) u_(k-m),

Phi(t) = e^(A t), Gamma(t) = int_0^t e^(A s) ds B. Phi - I is computed as A Psi(t), Psi = int_0^t
e^(A s) ds (Van Loan's block exponential), so that it does not lose its digits to the identity: the
delta form (Phi - I) / dt of a loop at 450 Hz keeps them. Imports scipy when called, not on import.
"""
from __future__ import annotations

import math


def split_delay(delay: float, dt: float) -> tuple[int, float]:
    """The delay as m whole periods and a fraction d of one: delay = m dt + d, 0 <= d < dt (a d below
    1e-12 dt is rounding and is 0)."""
    m = int(math.floor(delay / dt + 1e-9))
    d = max(delay - m * dt, 0.0)
    return m, (0.0 if d < 1e-12 * dt else d)


def zoh(A, B, t: float):
    """(Phi(t) - I, Gamma(t)) of x' = A x + B u with u held over t (the module docstring)."""
    import numpy as np
    from scipy.linalg import expm
    n, ni = B.shape
    M = np.zeros((2 * n + ni, 2 * n + ni))
    M[:n, :n], M[:n, n:2 * n], M[:n, 2 * n:] = A, np.eye(n), B
    E = expm(M * t)
    return A @ E[:n, n:2 * n], E[:n, 2 * n:]


def delayed(A, B, dt: float, delay: float = 0.0):
    """(Phi - I, Ga, Gb, m): x_(k+1) = Phi x_k + Ga u_(k-m-1) + Gb u_(k-m), Phi = Phi(dt), Ga = Phi(dt - d)
    Gamma(d), Gb = Gamma(dt - d), delay = m dt + d (the module docstring). Ga is zero without a fraction d."""
    import numpy as np
    m, d = split_delay(delay, dt)
    Phi_I, _ = zoh(A, B, dt)
    late_I, Gb = zoh(A, B, dt - d)
    Ga = (np.eye(A.shape[0]) + late_I) @ zoh(A, B, d)[1] if d > 0.0 else np.zeros_like(Gb)
    return Phi_I, Ga, Gb, m
