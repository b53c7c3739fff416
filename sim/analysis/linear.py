"""The linear pieces of `flightctl analyze`, each taken from the code that flies, not from a formula:

- the plant linearised about hover through the model seam (`Model.f`, `Model.specific_force`): a
  numerical Jacobian at the trim state and command, so that every effect bound to the `Model`
  (motor lag or dynamics, rotor inflow, drag, ...) and its own states are in it;
- its sampled-data form: commands held from each sampling instant (zero-order hold), reaching the
  rotors after the model's actuation delay, the sensors read at the instants;
- the onboard estimator linearised as `flightctl.control` runs it: its impulse responses about
  hover, realised as a state-space system (eigensystem realisation), whatever its structure.

Every sampled system here is held in delta form (Middleton and Goodwin, "Digital control and
estimation: a unified approach", 1990): x_(k+1) = x_k + T (A x_k + B u_k), y_k = C x_k + D u_k, so
A holds rates (1/s). At 450 Hz the usual form x_(k+1) = Ad x_k + ... has Ad = I + T A within 1e-2
of the identity, and the closed-loop poles near z = 1 (integrators, slow filters) that decide
stability lose most of their digits to it; in delta form they keep them. `discrete` converts.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.linalg import schur, svd
from scipy.optimize import root

from flightctl.control.controller import FlightController
from flightctl.control.estimator import Calibration
from flightctl.control.hold import delayed
from flightctl.errors import InputError
from flightctl.hal import ImuSample
from flightctl.params import Params
from flightctl.physics import command_from_thrust
from flightctl.sim.world.devices import EARTH_FIELD_T
from flightctl.sim.world.model import N_RIGID, P, PHI, PSI, Q, R, THETA, VZ, Z, Model, rotation

IMU = ("gx", "gy", "gz", "ax", "ay", "az", "mx", "my", "mz")   # the fields of an ImuSample (SI)
TRUTH = ("roll", "pitch", "yaw", "alt", "droll", "dpitch", "dyaw")   # what perfect state feedback reads
SIGNALS = IMU + ("range",) + TRUTH
EST = ("roll", "pitch", "yaw", "droll", "dpitch", "dyaw")      # what the PIDs read from the estimator
TRIM_TOLERANCE = 1e-9      # largest |xdot| left at the trim (SI units per second)


@dataclass
class LinearPlant:
    """x' = A dx + B dP, y = C dx + D dP about the hover trim (x0, u0); inputs dP1..dP4 (eq. 26 command
    values), outputs the `SIGNALS`; `delay` is the model's actuation delay (s)."""
    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    x0: np.ndarray
    u0: np.ndarray
    y0: np.ndarray     # the SIGNALS at the trim
    delay: float

    def rows(self, names) -> list[int]:
        return [SIGNALS.index(n) for n in names]


def signals(model: Model, x, u) -> list[float]:
    """The `SIGNALS` of state x under input u: gyro (body rates), accelerometer (specific force), the
    magnetic field in the body frame, the sonar range along -z_b, and the true attitude, altitude and
    Euler-angle rates (what `TruthEstimator` reads)."""
    Rm = np.array(rotation(x[PHI], x[THETA], x[PSI])).reshape(3, 3)
    m = Rm.T @ np.array(EARTH_FIELD_T)
    xdot = model.f(0.0, x, u)
    return [x[P], x[Q], x[R], *model.specific_force(0.0, x, u), *m,
            x[Z] / (math.cos(x[PHI]) * math.cos(x[THETA])),
            x[PHI], x[THETA], x[PSI], x[Z], xdot[PHI], xdot[THETA], xdot[PSI]]


def trim(model: Model, alt: float, battery_v: float) -> tuple[np.ndarray, np.ndarray]:
    """Hover at `alt`: the four commands and the effects' states for which nothing accelerates."""
    a = model.a
    P0 = command_from_thrust(a.B, a.h1, a.h2)      # eq. 26 inverted at the base thrust M g / 4
    x_guess = model.initial_state((P0,) * 4 + (battery_v,))
    n_ext = model.n - N_RIGID

    def state(z):
        x = [0.0] * N_RIGID + list(z[4:])
        x[Z] = alt
        return x, list(z[:4]) + [battery_v]

    def residual(z):
        x, u = state(z)
        xdot = model.f(0.0, x, u)
        return [xdot[VZ], xdot[P], xdot[Q], xdot[R]] + xdot[N_RIGID:]

    sol = root(residual, [P0] * 4 + list(x_guess[N_RIGID:N_RIGID + n_ext]), method="hybr")
    x, u = state(sol.x)
    worst = max(abs(v) for v in model.f(0.0, x, u))
    if not sol.success or worst > TRIM_TOLERANCE * max(1.0, a.g):
        raise InputError(f"the model has no hover at {alt:g} m (largest acceleration left {worst:.3g})")
    return np.array(x), np.array(u)


def jacobian(fun, z0: np.ndarray, rel: float = 1e-6, floor: float = 1e-9) -> np.ndarray:
    """Central differences of `fun` (a list in, a list out) about z0, steps rel * max(1, |z|).
    Entries below `floor` times the largest of their row are the differences' rounding (about
    1e-10 of it) and are set to zero: the channels that are decoupled at hover stay exactly so."""
    cols = []
    for i in range(len(z0)):
        h = rel * max(1.0, abs(z0[i]))
        zp, zm = z0.copy(), z0.copy()
        zp[i] += h
        zm[i] -= h
        cols.append((np.asarray(fun(list(zp))) - np.asarray(fun(list(zm)))) / (2 * h))
    J = np.column_stack(cols)
    J[np.abs(J) < floor * np.max(np.abs(J), axis=1, keepdims=True)] = 0.0
    return J


def linearise(model: Model, alt: float, battery_v: float) -> LinearPlant:
    """The plant about hover at `alt`, through the model seam (state and command Jacobians)."""
    x0, u0 = trim(model, alt, battery_v)
    n = model.n
    z0 = np.concatenate([x0, u0[:4]])

    def split(z):
        return z[:n], z[n:] + [battery_v]

    fx = jacobian(lambda z: model.f(0.0, *split(z)), z0)
    gy = jacobian(lambda z: signals(model, *split(z)), z0)
    y0 = np.array(signals(model, list(x0), list(u0)))
    return LinearPlant(fx[:, :n], fx[:, n:], gy[:, :n], gy[:, n:], x0, u0, y0, model.delay)


def discrete(A, B, T: float):
    """Delta form (A, B) at period T -> the usual discrete form (I + T A, T B)."""
    return np.eye(A.shape[0]) + T * A, T * B


def sampled(A, B, C, D, T: float, delay: float = 0.0):
    """The plant x' = A x + B u, y = C x + D u under commands u_k held from each instant t_k = k T
    (zero-order hold) and reaching it `delay` later; outputs read at t_k, where the input acting is
    the command m + 1 periods old. In delta form (module docstring).

    With delay = m T + d (0 <= d < T): x_(k+1) = Phi(T) x_k + Phi(T - d) Gamma(d) u_(k-m-1)
    + Gamma(T - d) u_(k-m), and y_k = C x_k + D u_(k-m-1). The last m + 1 commands are states."""
    n, ni = B.shape
    Phi_I, Gam_a, Gam_b, m = delayed(A, B, T, delay)     # flightctl/control/hold.py
    slots = m + 1
    N = n + ni * slots

    def slot(j):   # the command u_(k-1-j)
        return slice(n + ni * j, n + ni * (j + 1))

    Ad, Bd = np.zeros((N, N)), np.zeros((N, ni))   # the delta form: (x_(k+1) - x_k) / T
    Ad[:n, :n] = Phi_I / T
    Ad[:n, slot(m)] += Gam_a / T
    if m == 0:
        Bd[:n] = Gam_b / T
    else:
        Ad[:n, slot(m - 1)] += Gam_b / T
    Ad[slot(0), slot(0)] = -np.eye(ni) / T
    Bd[slot(0)] = np.eye(ni) / T
    for j in range(1, slots):
        Ad[slot(j), slot(j - 1)] = np.eye(ni) / T
        Ad[slot(j), slot(j)] = -np.eye(ni) / T
    Cd = np.zeros((C.shape[0], N))
    Cd[:, :n] = C
    Cd[:, slot(m)] = D
    return Ad, Bd, Cd, np.zeros((C.shape[0], ni))


# The estimator is perturbed by one-sample impulses that move its angles by about 1e-6..1e-5 rad:
# small enough for its trigonometry to be linear to ~1e-10, large enough for rounding not to matter.
PERTURBATION = {"gx": 2e-3, "gy": 2e-3, "gz": 2e-3, "ax": 1e-4, "ay": 1e-4, "az": 1e-4,
                "mx": 1e-10, "my": 1e-10, "mz": 1e-10}
ERA_BLOCKS = 48            # Hankel block rows and columns: impulse responses of 97 samples (the D path's EMA
                           # of the as-flown file did not fit in 65)
ERA_TOLERANCE = 1e-7       # singular values below this fraction of the largest are rounding
CHECK_SAMPLES = 1024       # the realisation must reproduce the responses this long (2.3 s at 450 Hz)


def structure_factory(structure):
    """A name of flightctl's ESTIMATORS -> a function making that onboard estimator from the
    parameters (the controller's own choice); a callable is taken as such a function."""
    if callable(structure):
        return structure
    return lambda params: FlightController(params, None, structure).est


def impulse_responses(params: Params, structure, hover_imu: dict[str, float], dt: float) -> np.ndarray:
    """The onboard estimator linearised about hover as it runs: calibrated like the loop does it,
    `in_flight` set as at arming, then fed the hover IMU signals with a one-sample impulse on each
    input in turn (both signs: central differences). Returns Y[k, output, input], the response of the
    `EST` outputs k samples after an impulse of PERTURBATION on each `IMU` input.

    The magnetometer is taken as fresh on every sample (it is on one in four at 450 Hz): the analysis
    needs a time-invariant estimator; with a consistent field its correction does not move the yaw
    estimate, so its rate barely matters to the loop."""
    make = structure_factory(structure)

    def fresh():
        est = make(params)
        s = ImuSample()
        for name, v in hover_imu.items():
            setattr(s, name, v)
        s.mag_fresh = True
        cal = Calibration()
        for _ in range(8):
            cal.add(s)
        cal.apply(est)
        est.in_flight = True   # as the loop sets it at arming
        for _ in range(8):
            est.update(s, dt)
        return est, s

    n = CHECK_SAMPLES
    Y = np.zeros((n, len(EST), len(IMU)))
    for j, name in enumerate(IMU):
        runs = []
        for sign in (1.0, -1.0):
            est, s = fresh()
            base = getattr(s, name)
            out = np.empty((n, len(EST)))
            for k in range(n):
                setattr(s, name, base + sign * PERTURBATION[name] if k == 0 else base)
                est.update(s, dt)
                out[k] = [getattr(est, o) for o in EST]
            runs.append(out)
        Y[:, :, j] = (runs[0] - runs[1]) / 2.0     # the response to +PERTURBATION, central differences
    return Y


def realise(Y: np.ndarray, outputs: list[str], dt: float):
    """A minimal delta-form (A, B, C, D) of the estimator from its `impulse_responses`, for the
    `outputs` one loop reads, by ERA, inputs per unit of each IMU signal; checked against the
    responses over CHECK_SAMPLES (a structure that is not time-invariant about hover fails)."""
    Y = Y[:, [EST.index(o) for o in outputs], :]
    size = np.max(np.abs(Y), axis=(0, 1))
    used = np.flatnonzero(size > 1e-9 * size.max())
    A, Bu, C, D = era(Y[:, :, used], ERA_BLOCKS, ERA_TOLERANCE, dt)
    A = snap_integrators(A)
    Az, Bz = discrete(A, Bu, dt)
    check, M = [D], Bz
    for _ in range(1, len(Y)):
        check.append(C @ M)
        M = Az @ M
    err = np.max(np.abs(np.array(check) - Y[:, :, used])) / np.max(np.abs(Y))
    if err > 1e-4:
        raise RuntimeError(f"the estimator is not time-invariant about hover (its realisation misses "
                           f"its impulse responses by {err:.1e})")
    scale = np.array([PERTURBATION[name] for name in IMU])
    B, Dfull = np.zeros((A.shape[0], len(IMU))), np.zeros((len(outputs), len(IMU)))
    B[:, used], Dfull[:, used] = Bu, D
    return A, B / scale, C, Dfull / scale


def era(Y: np.ndarray, s: int, tol: float, dt: float):
    """Eigensystem realisation (Juang and Pappa, 1985) in delta form: C (I + dt A)^(k-1) dt B = Y[k]
    (k >= 1) and D = Y[0], from the block Hankel matrix H0 of Y[1 .. 2 s] and its SVD; the order is
    the number of singular values above tol times the largest. The shifted Hankel matrix enters as
    H1 - H0, differences of successive responses, so the slow poles keep their digits."""
    p, m = Y.shape[1:]
    k = 1 + np.arange(s)[:, None] + np.arange(s)[None, :]

    def hankel(Z):   # block (i, j) is Z[1 + i + j]
        return Z[k].transpose(0, 2, 1, 3).reshape(s * p, s * m)

    H0, dH = hankel(Y), hankel(np.diff(Y, axis=0))
    U, S, Vt = svd(H0, full_matrices=False)
    n = int(np.count_nonzero(S > tol * S[0])) if S[0] > 0 else 0
    if n == 0:
        return np.zeros((0, 0)), np.zeros((0, m)), np.zeros((p, 0)), Y[0]
    r = np.sqrt(S[:n])
    Un, Vn = U[:, :n], Vt[:n]
    A = (Un.T @ dH @ Vn.T) / np.outer(r, r) / dt
    return A, (r[:, None] * Vn)[:, :m] / dt, (Un * r)[:p], Y[0]


def snap_integrators(A: np.ndarray, within: float = 1e-6) -> np.ndarray:
    """Delta-form A with its real eigenvalues within `within` (1/s) of 0 put at 0 (on the diagonal of
    its ordered real Schur form): integrators, whose realisation from rounded responses leaks at a
    time constant of days. Left leaking, an integrator that duplicates the plant's (an angle
    integrated from the gyro) splits the closed loop's pole at 0 instead of cancelling against it."""
    T, Z, k = schur(A, output="real", sort=lambda re, im: abs(re) < within and abs(im) < within)
    if k == 0:
        return A
    T[range(k), range(k)] = 0.0
    return Z @ T @ Z.T
