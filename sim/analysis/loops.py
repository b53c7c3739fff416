"""Each loop of the flight controller about hover, as flightctl flies it, and its figures.

A loop (roll, pitch, yaw, altitude) is, in the order a command travels:
- the channel's PID of eq. 24 (derivative on the measurement, integral summed with the loop's dt);
- the mixer of eq. 25 (u_z on every rotor; +-u_phi on rotors 2 and 4; -+u_theta on 1 and 3; +-u_psi
  alternating), then eq. 26 inverted, linearised at the hover command: dP = df / (2 h1 (P - h2));
- the plant of `linear.linearise` under the loop's sample-and-hold: the command computed at a
  sample is held until the next and first shows in the sensors one loop period later (450 Hz);
- the measurement the PID reads: the onboard estimator linearised as it runs
  (`linear.impulse_responses`, `linear.realise`) on the IMU's signals as the chip delivers them,
  each through its DLPF's first-order stage as the simulated chip filters it (`measured`), or the
  true state for perfect state feedback
  (`truth`, the paper's simulation). The altitude task
  runs on sonar echoes (`FlightController.on_range`): at 45 Hz, each range taken at its trigger and
  used when its echo ends (4-5 loop periods later at hover), its derivative the difference quotient
  between echoes; with perfect state feedback the true altitude at every loop period.

The loop is broken at the plant input (the channel's effort u, N) for the margins; the step
response is that of the true output to a setpoint step, at the loop rate.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import control
import numpy as np
from scipy.linalg import eig

from flightctl.drivers.hcsr04 import US_PER_M
from flightctl.errors import InputError
from flightctl.params import Params
from flightctl.sim.analysis.linear import IMU, LinearPlant, discrete, impulse_responses, realise, sampled
from flightctl.drivers.mpu9250 import dlpf_delays
from flightctl.sim.world.devices import SimGpio

CHANNELS = ("roll", "pitch", "yaw", "alt")
MIX = {"alt": (1, 1, 1, 1), "roll": (0, 1, 0, -1), "pitch": (-1, 0, 1, 0), "yaw": (1, -1, 1, -1)}  # eq. 25
GAIN = {"roll": "phi", "pitch": "theta", "yaw": "psi", "alt": "z"}   # eq. 24 gain names: kp_phi, ...
SETTLING_BAND = 0.05        # as the simulator's step metrics (flightctl.sim.flights.metrics)
TRIGGER_S = 10e-6           # the HC-SR04 trigger pulse (flightctl.drivers.hcsr04)
MIN_HORIZON, MAX_HORIZON = 20.0, 120.0   # s, of the step responses
DRIFT_RATE = 1e-4           # 1/s: a closed-loop mode slower than this (a time constant beyond 2.8 h)
                            # is drift, not dynamics (rounding moves a pole at 0 by ~1e-6 at most)
SEEN_SHARE = 0.01           # a mode with 1 % of the largest share of the step response is one it shows
DEADBEAT = 1e-6             # |z| below this: a mode at the z-plane's origin, a pure delay of the discrete
                            # loop (a sample held one period), with no frequency or damping of its own;
                            # its log(z) / T is rounding (once printed as wn 8664.58, then 8640.68, rad/s)


def _modal(s, period: float):
    """The modes with dynamics: neither drift (|s| < DRIFT_RATE) nor deadbeat (|z| = |1 + T s| < DEADBEAT)."""
    return (np.abs(s) >= DRIFT_RATE) & (np.abs(1.0 + period * np.asarray(s)) >= DEADBEAT)


@dataclass
class Loop:
    channel: str
    period: float                 # s: the loop's sampling period (1/45 s for the sonar's altitude task)
    L: control.StateSpace         # return ratio at the plant input (negative feedback), discrete
    T: control.StateSpace         # setpoint -> true output, discrete
    poles: np.ndarray             # the modes of T's response (`modes`), in z
    t: np.ndarray                 # s: the step response of the true output at the 450 Hz loop rate
    y: np.ndarray                 # (the sonar's altitude loop simulated between its 45 Hz samples)
    figures: dict[str, float]


def pid(params: Params, channel: str, dt: float):
    """Eq. 24 as `Pid.update` computes it: i_k = i_(k-1) + ki e_k dt, u_k = kp e_k - kd dy_k + i_k,
    e = r - y; inputs (r, y, dy), output u; delta form, its state i_(k-1) (none without ki)."""
    g = params.gains
    kp, ki, kd = (getattr(g, f"k{k}_{GAIN[channel]}") for k in "pid")
    k = kp + ki * dt
    D = np.array([[k, -k, -kd]])
    if ki == 0.0:
        return np.zeros((0, 0)), np.zeros((0, 3)), np.zeros((1, 0)), D
    return np.zeros((1, 1)), np.array([[ki, -ki, 0.0]]), np.ones((1, 1)), D


def altitude_task(dt: float):
    """`on_range`: the altitude is the range (levelled by cos(roll) cos(pitch), 1 at hover) and its
    derivative the difference quotient over the time between echoes; delta form, input the range,
    outputs (alt, dalt), its state the last range."""
    return (np.array([[-1.0 / dt]]), np.array([[1.0 / dt]]),
            np.array([[0.0], [-1.0 / dt]]), np.array([[1.0], [1.0 / dt]]))


def series(first, second):
    """(A, B, C, D) of `second` after `first` (the same algebra in delta form)."""
    A1, B1, C1, D1 = first
    A2, B2, C2, D2 = second
    n1, n2 = A1.shape[0], A2.shape[0]
    A = np.block([[A1, np.zeros((n1, n2))], [B2 @ C1, A2]])
    return A, np.vstack([B1, B2 @ D1]), np.hstack([D2 @ C1, C2]), D2 @ D1


def to_control(sys, T: float) -> control.StateSpace:
    A, B, C, D = sys
    return control.ss(*discrete(A, B, T), C, D, T)


def imu_delays() -> dict[str, float]:
    """s, per IMU field: the time constant of the chip's DLPF stage, the register map's delay of the
    filter the onboard driver configures (the simulated chip's, sim/world/imu.py); the magnetometer
    has none."""
    g, a = dlpf_delays()
    return {"gx": g, "gy": g, "gz": g, "ax": a, "ay": a, "az": a, "mx": 0.0, "my": 0.0, "mz": 0.0}


def measured(plant: LinearPlant, period: float, first):
    """The IMU rows of the sampled plant `first` as the chip delivers them: each through its DLPF's
    first-order stage y_k = a y_(k-1) + (1 - a) x_k, a = exp(-T / tc), updated at each read. (A, B,
    C, D) with `first`'s states first (delta form: a stage's state is its last output)."""
    Ad, Bd, Cd, Dd = first
    tcs = imu_delays()
    a = np.array([math.exp(-period / tcs[f]) if tcs[f] > 0.0 else 0.0 for f in IMU])
    n = len(IMU)
    filt = (np.diag((a - 1.0) / period), np.diag((1.0 - a) / period), np.diag(a), np.diag(1.0 - a))
    return series((Ad, Bd, Cd[plant.rows(IMU)], Dd[:n]), filt)


def echo_ticks(alt: float, dt: float) -> int:
    """Loop periods from a sonar trigger to the loop that reads its echo (the end of the echo: the
    pulse, the module's delay and the flight there and back, as the simulated HC-SR04 makes them)."""
    return math.ceil((TRIGGER_S + SimGpio.ECHO_DELAY_S + alt * US_PER_M * 1e-6) / dt - 1e-9)


def build(params: Params, plant: LinearPlant, structure, channel: str, responses=None,
          horizon: float | None = None) -> Loop:
    """The loop of `channel` with the estimator `structure` ('truth', a name of ESTIMATORS or a
    function making an estimator from the parameters); `responses` are the estimator's impulse
    responses when already computed; the step response runs for `horizon` s (default: until the
    dominant mode has decayed to 1 %, within 20 to 120 s)."""
    a = params.airframe
    dt = a.dt
    P0 = plant.u0[:4]
    mix = np.array(MIX[channel]) / (2.0 * a.h1 * (P0 - a.h2))   # eq. 25, then eq. 26 inverted, linearised
    B = plant.B @ mix[:, None]
    D = plant.D @ mix[:, None]
    sonar = channel == "alt" and structure != "truth"
    every = max(1, round(a.loop_hz / a.sonar_hz))
    lag = echo_ticks(plant.x0[2], dt) if sonar else 0
    if lag >= every:
        raise InputError(f"at {plant.x0[2]:g} m the sonar's echo outlasts its trigger period")
    period = dt * every if sonar else dt
    Ad, Bd, Cd, Dd = sampled(plant.A, B, plant.C, D, period, plant.delay + lag * dt)
    if channel == "alt":
        meas = series((Ad, Bd, Cd[plant.rows(["range"])], Dd[:1]), altitude_task(period))
    elif structure == "truth":
        meas = (Ad, Bd, Cd[plant.rows([channel, "d" + channel])], Dd[:2])
    else:
        Y = responses if responses is not None else hover_responses(params, plant, structure)
        meas = series(measured(plant, period, (Ad, Bd, Cd, Dd)), realise(Y, [channel, "d" + channel], dt))
    # the plant side: u -> [true output, y, dy]
    A, Bg = meas[0], meas[1]
    C = np.vstack([np.hstack([Cd[plant.rows([channel])], np.zeros((1, A.shape[0] - Ad.shape[0]))]), meas[2]])
    Ak, Bk, Ck, Dk = pid(params, channel, period)
    Cm = C[1:]
    L = series((A, Bg, Cm, np.zeros((2, 1))), (Ak, Bk[:, 1:], Ck, Dk[:, 1:]))
    L = to_control((L[0], L[1], -L[2], -L[3]), period)
    nk = Ak.shape[0]
    Tcl = (np.block([[A + Bg @ Dk[:, 1:] @ Cm, Bg @ Ck], [Bk[:, 1:] @ Cm, Ak]]),
           np.vstack([Bg @ Dk[:, :1], Bk[:, :1]]), np.hstack([C[:1], np.zeros((1, nk))]), np.zeros((1, 1)))
    T = to_control(Tcl, period)
    s, share = modes(*Tcl[:3])
    if horizon is None:   # long enough for the dominant mode to settle within the band
        zeta, wn = dominant(s, share, period)
        horizon = float(np.clip(5.0 / (zeta * wn), MIN_HORIZON, MAX_HORIZON)) if zeta * wn > 0 else MIN_HORIZON
    if sonar:
        t, y = sonar_step(plant, B, D, (Ak, Bk, Ck, Dk), period, lag, dt, horizon)
    else:
        t, y = step(T, horizon)
    final = float(np.real(share.sum()))   # where the step settles: the modes' settled parts (D = 0)
    return Loop(channel, period, L, T, 1.0 + period * s, t, y, figures(L, s, share, period, t, y, final))


def step(T: control.StateSpace, horizon: float):
    """The unit step response of the discrete system T over `horizon` seconds (what
    `control.step_response` computes, without its per-sample overhead: it runs for every loop)."""
    n = int(round(horizon / T.dt))
    x, y = np.zeros(T.nstates), np.empty(n)
    A, b, c, d = T.A, T.B[:, 0], T.C[0], float(T.D[0, 0])
    for k in range(n):
        y[k] = c @ x + d
        x = A @ x + b
    return np.arange(n) * T.dt, y


def hover_responses(params: Params, plant: LinearPlant, structure):
    """The estimator's impulse responses about the IMU signals at the plant's trim."""
    return impulse_responses(params, structure, dict(zip(IMU, map(float, plant.y0[:len(IMU)]))),
                             params.airframe.dt)


def sonar_step(plant: LinearPlant, B, D, K, period: float, lag: int, dt: float, horizon: float):
    """The altitude step at the 450 Hz loop rate: the plant at dt (with its actuation delay), the
    altitude task and PID every `period` on the range taken at the trigger, their u_z applied from
    the loop that reads the echo (`lag` periods later) and held."""
    Ad, Bd, Cd, _ = sampled(plant.A, B, plant.C, D, dt, plant.delay)
    Ad, Bd = discrete(Ad, Bd, dt)
    c_range, c_true = Cd[plant.rows(["range"])][0], Cd[plant.rows(["alt"])][0]
    Aa, Ba, Ca, Da = altitude_task(period)
    Aa, Ba = discrete(Aa, Ba, period)
    Ak, Bk = discrete(K[0], K[1], period)
    Ck, Dk = K[2], K[3]
    every = round(period / dt)
    n = int(round(horizon / dt))
    x, xa, xk = np.zeros(Ad.shape[0]), np.zeros(Aa.shape[0]), np.zeros(Ak.shape[0])
    u, pending = 0.0, None
    y = np.empty(n)
    for k in range(n):
        y[k] = c_true @ x
        if k % every == 0:
            rng = c_range @ x
            alt = Ca @ xa + Da[:, 0] * rng          # (alt, dalt)
            xa = Aa @ xa + Ba[:, 0] * rng
            e_in = np.array([1.0, alt[0], alt[1]])  # a unit setpoint step at t = 0
            pending = (k + lag, float((Ck @ xk + Dk @ e_in)[0]))
            xk = Ak @ xk + Bk @ e_in
        if pending is not None and k == pending[0]:
            u, pending = pending[1], None
        x = Ad @ x + Bd[:, 0] * u
    return np.arange(n) * dt, y


def modes(A, B, C, tol: float = 1e-9):
    """The closed-loop modes of the true output's response: the eigenvalues s_i of the delta-form A
    that the setpoint reaches and the output sees, each with its (signed, complex) share of the step
    response.

    Mode i, with right and left eigenvectors v_i and w_i, is reached as far as b leans on w_i and
    seen as far as c leans on v_i (the PBH test as angles, free of the states' units); a mode whose
    cosine is below tol either way is not the loop's (such as the position, which no loop holds:
    rounding leaves ~1e-15 there; a PI zero cancelling its own pole sits near 1e-10 and changes
    nothing). In delta form mode i settles at -(c v_i)(w_i b) / ((w_i v_i) s_i)."""
    lam, W, V = eig(A, left=True, right=True)
    Wh = W.conj().T
    b, c = B[:, 0], C[0]
    reach = np.abs(Wh @ b) / np.linalg.norm(W, axis=0) / max(np.linalg.norm(b), 1e-300)
    seen = np.abs(c @ V) / np.linalg.norm(V, axis=0) / max(np.linalg.norm(c), 1e-300)
    keep = (reach > tol) & (seen > tol)
    with np.errstate(divide="ignore", invalid="ignore"):
        share = -(c @ V) * (Wh @ b) / np.einsum("ij,ji->i", Wh, V) / lam
    return lam[keep], share[keep]


def dominant(s, share, period: float) -> tuple[float, float]:
    """Damping ratio and natural frequency (rad/s) of the closed-loop mode with the largest share of
    the step response, drift and deadbeat modes aside."""
    live = _modal(s, period)
    if not live.any():
        return math.nan, math.nan
    size = np.abs(share[live])
    i = np.flatnonzero(live)[int(np.argmax(np.where(np.isfinite(size), size, 0.0)))]
    sc = np.log(complex(1.0 + period * s[i])) / period
    wn = abs(sc)
    return (-sc.real / wn if wn > 0 else 1.0), wn


def least_damped(s, share, period: float) -> tuple[float, float]:
    """Damping ratio and natural frequency (rad/s) of the least damped closed-loop mode that the step
    response sees (its share at least SEEN_SHARE of the largest), drift modes aside: the figure a
    phase margin speaks of. The largest share alone can be a real pole (damping 1) while a small,
    barely damped or growing oscillation rides on it (1.000 was once printed at a 4 degree margin).
    Negative for a growing mode. Deadbeat modes (a delay's) are no mode a margin speaks of."""
    live = _modal(s, period)
    size = np.where(np.isfinite(np.abs(share)), np.abs(share), np.inf)
    seen = live & (size >= SEEN_SHARE * np.max(size[live], initial=0.0))
    if not seen.any():
        return math.nan, math.nan
    sc = np.log((1.0 + period * s[seen]).astype(complex)) / period
    wn = np.abs(sc)
    zeta = np.where(wn > 0, -sc.real / np.where(wn > 0, wn, 1.0), 1.0)
    i = int(np.lexsort((-size[seen], np.round(zeta, 9)))[0])   # among equals (real poles), the largest share
    return float(zeta[i]), float(wn[i])


def margins(L: control.StateSpace) -> dict[str, float]:
    """Margins of the loop L over 0.01 rad/s to the Nyquist frequency (below, a period of ten minutes
    is not the loop's business): the phase margin at the gain crossover where it is smallest, and the
    gain margin as the factor by which the gain may rise (the lowest phase crossover above |L| = 1;
    loops with an integral term also cross at low frequency, where only a gain fall would harm)."""
    w = np.logspace(-2.0, math.log10(math.pi / L.dt), 600)[:-1]
    gm, pm, _, wpc, wgc, _ = control.stability_margins(control.frd(L, w), returnall=True)
    gm, pm, wpc, wgc = (np.atleast_1d(np.asarray(v, float)) for v in (gm, pm, wpc, wgc))
    up = gm > 1.0
    i = int(np.argmin(np.where(up, gm, np.inf))) if up.any() else None
    j = int(np.argmin(np.abs(pm))) if pm.size else None
    return {"gain_margin_db": 20.0 * math.log10(gm[i]) if i is not None else math.inf,
            "phase_crossover_rad_s": float(wpc[i]) if i is not None else math.nan,
            "phase_margin_deg": float(pm[j]) if j is not None else math.inf,
            "crossover_rad_s": float(wgc[j]) if j is not None else math.nan}


def figures(L, s, share, period: float, t, y, final: float) -> dict[str, float]:
    """The loop's figures. `stable`: every closed-loop mode of the true output decays; `drift`: a
    mode decays slower than DRIFT_RATE (the true output creeps away from a held setpoint: the
    estimate parts from the truth at low frequency). Step figures only for a stable loop."""
    drift = bool(np.any(np.abs(s) < DRIFT_RATE))
    stable = not drift and bool(np.all(np.abs(1.0 + period * s) < 1.0))
    out = {"stable": stable, "drift": drift, **margins(L)}
    zeta, wn = least_damped(s, share, period)
    out.update(damping=float(zeta), natural_rad_s=float(wn))
    if stable:   # the final value is given: a lightly damped loop still rings at the horizon
        try:
            info = control.step_info(y, t, final_output=final, SettlingTimeThreshold=SETTLING_BAND)
            out.update(rise_s=float(info["RiseTime"]), overshoot=float(info["Overshoot"]) / 100.0,
                       settling_s=float(info["SettlingTime"]))
        except (IndexError, ValueError):   # a response too slow to rise within the horizon
            out.update(rise_s=math.nan, overshoot=math.nan, settling_s=math.nan)
    else:
        out.update(rise_s=math.nan, overshoot=math.nan, settling_s=math.nan)
    return out
