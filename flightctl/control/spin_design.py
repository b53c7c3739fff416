"""The design of the loop's flight on two rotors (flightctl/control/spin.py): the spin the pair settles
at, eq. 7 linearised about it, and a discrete LQR gain schedule over the spin rate and the rotors'
momentum; computed at start-up, never in the air, and kept on disk by a hash of what it depends on.

**The model.** With the rotor across the lost one stopped too, the remaining pair, on one arm, turns
the same way: their reaction torques (eq. 28) spin the body about z_b until the yaw drag (eq. 6, with
the file's linear yaw drag if it carries one) balances them, gamma1 r^2 + gamma0 r = 2 (g1 f + g2),
f = M g / 2 (`equilibrium_spin`). About a spin r, with the rotors' momentum H = Jp Omega (eq. 9),
eq. 7 and the kinematics of n (the world's up seen in the body, dn/dt = -w x n) are, for x = (p, q,
n_x, n_y) and the pair's torque across its arm (`pair_model`):

    Jxx dp/dt = tau_x - ((Jzz - Jyy) r + H) q - d_x p       dn_x/dt =  r n_y - q
    Jyy dq/dt = tau_y + ((Jzz - Jxx) r + H) p - d_y q       dn_y/dt = -r n_x + p

The damping d of each axis is what the parameter file carries from the rotors' airflow, for the two
rotors that run (rotor_inflow's hub moment and its inflow damping on the pair's own axis, 2 k l^2
sqrt(2); 0 on the base model) and a token EPS_DAMPING (a solvable Riccati equation where the other axis'
gyroscopic coupling vanishes, below). The pair's torque follows its command through the file's motor
time constant (a fifth state) and its delay chain (`actuation_delay`: the model held over one loop with
its input delay = m dt + delta late, the commands still in the chain as states: `discrete`,
`augmented`). The gains are the discrete LQR of this model on a grid of spin rates from R_LO (a yaw turn
against the pair's spin when the motor is lost: the pair brakes it, through zero spin) to past the
equilibrium, and of rotor momenta from none to OMEGA_TOP of the pair's own in hover; the loop
interpolates them (bilinear) at the measured rate and the rotors' modelled speeds. The rates reach the
gains through the file's rate path (`[filters] tau_rate`, the D term's EMA), built around eq. 7's
prediction from the last loop (`rate_filter`): the loop as it runs, filter, torque model and gains, is
`loop_parts` and `closed_loop`, and each point's gains are judged on it over the file's ranges (`plants`: Jp, the motor
time constant, the delay chain).

**Where it is weak.** The torque reaches the other axis only through the coupling
(Jzz - Jyy) r + H (pair 1-3) or (Jzz - Jxx) r + H (pair 2-4). The rotors turn against the spin
(H < 0 in the spin's direction), so the coupling vanishes at r_s = Jp |Omega| / (Jzz - Jyy): 26 rad/s
with Table 2's Jp at the pair's hover speed, right at the equilibrium spin; 9.7 rad/s with the
as-flown file's 1e-4. There that axis is not steered, only damped (`spectral_radius` of `closed_loop`
at each point; docs/safety.md tabulates the worst over the file's ranges).

**Where it cannot work** (`unusable`): no spin (the pair's torque 2 (g1 f + g2) not positive), no
drag to settle it (gamma1 = gamma0 = 0), or an equilibrium beyond the gyro's full scale (the driver's
+-2000 deg/s): the loop then flies without the two-rotor mode and says so at start-up.
"""
from __future__ import annotations

import hashlib
import math
from typing import NamedTuple

from flightctl.blas import OneBlasThread
from flightctl.cachedir import cached_json
from flightctl.control.hold import delayed, split_delay
from flightctl.drivers import mpu9250_regs as reg
from flightctl.params import Params

GYRO_MAX = math.radians(32767.0 / reg.GYRO_LSB_PER_DPS[3])   # rad/s: the driver's +-2000 deg/s (34.9)
R_LO = -8.0              # rad/s: the schedule's lowest spin (against the pair's direction)
SPIN_STEP = 2.0          # rad/s between scheduled spin rates
OMEGA_STEPS = 5          # steps of the rotors' momentum, from none ...
OMEGA_TOP = 1.25         # ... to this much of the pair's summed speed in hover
RATE_SCALE, AXIS_SCALE = 1.0, 0.2    # rad/s, -: the LQR's acceptable body rate and tilt of n
EPS_DAMPING = 0.05       # 1/s
ROBUST_JP = 4            # rotor inertias across the file's range at which each candidate is judged
SCHEMA = 4               # bump when the design changes: the disk cache's key includes it
PAIRS = ((0, 2), (1, 3))
MOTOR_CAUSES = ("motor_dynamics", "motor_lag")


class Inputs(NamedTuple):
    """Every number the design depends on (the cache's key), the vehicle's nominal values and the
    ranges its robustness is judged over: the rotor inertia, the motor time constant, the delay chain."""
    schema: int
    M: float
    g: float
    l: float
    Jxx: float
    Jyy: float
    Jzz: float
    Jp: float
    c1: float
    g1: float
    g2: float
    gamma1: float
    dt: float
    gamma0: float        # linear_yaw_drag, N m s/rad
    k_in: float          # rotor_inflow's k, N s/m per rotor
    hub: float           # rotor_inflow's hub moment, N m s/rad for four rotors
    tau: float           # the motor time constant (0: none)
    Jp_lo: float
    Jp_hi: float
    tau_lo: float
    tau_hi: float
    delay: float         # the delay chain from the IMU read to the rotors (actuation_delay), s
    delay_lo: float
    delay_hi: float
    tau_rate: float      # the vehicle's rate path: the EMA on the gyro's p and q ([filters] tau_rate)


def motor_time_constant(params: Params) -> float:
    """The motor time constant the parameter file carries (a `motor_dynamics` or `motor_lag` effect,
    as `flightctl bench --profile step` writes it), else 0."""
    e = params.effect(MOTOR_CAUSES)
    return float(dict(e.parameters)["tau"]) if e is not None else 0.0


def esc_full_throttle(params: Params) -> float:
    """The ESC's full-throttle command P the file carries (`motor_dynamics`' `p_full`: eq. 26's thrust
    stops rising there), else 255, the end of its frame."""
    return params.effect_value("motor_dynamics", "p_full") or 255.0


def design_inputs(params: Params, tau_motor: float | None = None) -> Inputs:
    """The design's inputs from the parameter file: its airframe, the rotors' airflow terms, the motor
    time constant (`tau_motor` instead where given), the delay chain and the rate path, each with the
    range the file gives it. The motor time constant's top follows the rotor inertia (at a given motor
    torque it is proportional to Jp, as the file's source says): the range's top times Jp over the top
    of Jp's range."""
    a = params.airframe
    tau = motor_time_constant(params) if tau_motor is None else tau_motor
    lo, hi = next(((lo, hi) for name, lo, hi in params.ranges if name == "Jp"), (a.Jp, a.Jp))
    t_lo, t_hi = params.effect_range(MOTOR_CAUSES, "tau", tau) if tau_motor is None else (tau, tau)
    if hi > a.Jp and t_hi > tau:
        t_hi = max(tau, t_hi * a.Jp / hi)
    delay = params.effect_value("actuation_delay", "delay")
    d_lo, d_hi = params.effect_range("actuation_delay", "delay", delay)
    return Inputs(SCHEMA, a.M, a.g, a.l, a.Jxx, a.Jyy, a.Jzz, a.Jp, a.c1, a.g1, a.g2, a.gamma1, a.dt,
                  params.effect_value("linear_yaw_drag", "gamma0"), params.effect_value("rotor_inflow", "k"),
                  params.effect_value("rotor_inflow", "hub"), tau, lo, hi, t_lo, t_hi, delay, d_lo, d_hi,
                  params.filters.tau_rate)


def pair_torque(d: Inputs) -> float:
    """The pair's summed reaction torque carrying the weight, 2 (g1 f + g2), f = M g / 2 (eq. 28)."""
    return 2.0 * (d.g1 * d.M * d.g / 2.0 + d.g2)


def equilibrium_spin(d: Inputs) -> float:
    """gamma1 r^2 + gamma0 r = 2 (g1 f + g2): the spin the pair settles at (inf without drag)."""
    T, gamma1, gamma0 = pair_torque(d), d.gamma1, d.gamma0
    if gamma1 > 0.0:
        return (-gamma0 + math.sqrt(gamma0 * gamma0 + 4.0 * gamma1 * T)) / (2.0 * gamma1) if T > 0.0 else 0.0
    return T / gamma0 if gamma0 > 0.0 else math.inf


def unusable(d: Inputs) -> str:
    """Why the two-rotor mode cannot work on this vehicle, or ''."""
    if not pair_torque(d) > 0.0:
        return (f"the rotor pair's reaction torque 2 (g1 f + g2) = {pair_torque(d):.3g} N m is not positive: "
                "no spin to steer the thrust axis with")
    r = equilibrium_spin(d)
    if not r <= GYRO_MAX:
        return (f"its spin on two rotors ({r:.3g} rad/s from gamma1 = {d.gamma1:.3g}) is beyond the gyro's "
                f"full scale ({GYRO_MAX:.1f} rad/s)")
    return ""


def pair_speed(d: Inputs) -> float:
    """The pair's summed rotor speed carrying the weight, 2 sqrt(f / c1), f = M g / 2 (eq. 27)."""
    return 2.0 * math.sqrt(d.M * d.g / 2.0 / d.c1)


def damping(d: Inputs, pair) -> tuple[float, float]:
    """The roll and pitch damping (N m s/rad) the rotors' airflow gives the pair (module docstring)."""
    own = 2.0 * d.k_in * d.l * d.l * math.sqrt(2.0)        # the inflow's damping on the pair's axis (f = 2B)
    return (0.5 * d.hub + (own if pair == (1, 3) else 0.0) + EPS_DAMPING * d.Jxx,
            0.5 * d.hub + (own if pair == (0, 2) else 0.0) + EPS_DAMPING * d.Jyy)


def pair_model(d: Inputs, pair: tuple[int, int], r: float, H: float):
    """Continuous (A, B) at spin r and rotor momentum H = Jp Omega (module docstring), for x = (p, q,
    n_x, n_y[, torque]) and the torque command (N m) across the pair's arm."""
    import numpy as np
    Jxx, Jyy, Jzz, tau = d.Jxx, d.Jyy, d.Jzz, d.tau
    dx, dy = damping(d, pair)
    A = np.array([[-dx / Jxx, -((Jzz - Jyy) * r + H) / Jxx, 0.0, 0.0],
                  [((Jzz - Jxx) * r + H) / Jyy, -dy / Jyy, 0.0, 0.0],
                  [0.0, -1.0, 0.0, r],
                  [1.0, 0.0, -r, 0.0]])
    b = np.array([0.0, 1.0 / Jyy, 0.0, 0.0]) if pair == (0, 2) else np.array([1.0 / Jxx, 0.0, 0.0, 0.0])
    if tau <= 0.0:
        return A, b[:, None]
    A5 = np.zeros((5, 5))
    A5[:4, :4] = A
    A5[:4, 4] = b
    A5[4, 4] = -1.0 / tau
    B5 = np.zeros((5, 1))
    B5[4, 0] = 1.0 / tau
    return A5, B5


def discrete(A, B, dt: float, delay: float = 0.0):
    """(Phi, Ga, Gb, m): the model held over dt (zero-order hold) with its input `delay` s late:
    x_{k+1} = Phi x_k + Ga u_{k-m-1} + Gb u_{k-m}, with delay = m dt + delta (flightctl/control/hold.py)."""
    import numpy as np
    Phi_I, Ga, Gb, m = delayed(A, B, dt, delay)
    return np.eye(A.shape[0]) + Phi_I, Ga, Gb, m


def augmented(held, slots: int):
    """(Ad, Bd) of the held model with its last `slots` commands as states: z = (x, u_{k-1}, ...,
    u_{k-slots}), the input u_k (`slots` >= m + 1)."""
    import numpy as np
    Phi, Ga, Gb, m = held
    n = Phi.shape[0]
    N = n + slots
    Ad, Bd = np.zeros((N, N)), np.zeros((N, 1))
    Ad[:n, :n] = Phi
    Ad[:n, n + m] += Ga[:, 0]                 # u_{k-m-1}: slot m + 1
    if m == 0:
        Bd[:n, 0] += Gb[:, 0]                 # u_k itself
    else:
        Ad[:n, n + m - 1] += Gb[:, 0]         # u_{k-m}: slot m
    Bd[n, 0] = 1.0                            # the new u_{k-1}
    for j in range(1, slots):
        Ad[n + j, n + j - 1] = 1.0
    return Ad, Bd


def torque_scale(d: Inputs) -> float:
    """The pair's largest torque across its arm at hover thrust, l M g (N m: one rotor carrying all,
    the other at zero): the LQR's unit of input."""
    return d.l * d.M * d.g


def slots(d: Inputs) -> int:
    """The commands the controller keeps: those the delay chain still holds, m + 1."""
    return split_delay(d.delay, d.dt)[0] + 1


def gain_count(d: Inputs) -> int:
    """(p, q, n_x, n_y, torque, the commands in the delay chain): the gains at each scheduled point."""
    return 5 + slots(d)


def torque_model(tau: float, dt: float, delay: float) -> tuple[float, float, float, int]:
    """(phi, ga, gb, m): the pair's torque at the next loop from the commands, through the motor time
    constant and the delay chain, as the controller models it: tau_{k+1} = phi tau_k + ga u_{k-m-1} +
    gb u_{k-m} (`discrete` of the torque's own row; tau = 0: the torque is the command)."""
    m, delta = split_delay(delay, dt)
    if tau <= 0.0:
        return 0.0, 0.0, 1.0, m
    late = math.exp(-(dt - delta) / tau)
    return late * math.exp(-delta / tau), late * (1.0 - math.exp(-delta / tau)), 1.0 - late, m


def rate_filter(d: Inputs) -> float:
    """The gain of the controller's rate filter: an EMA (eq. 36-39's form) of the vehicle's rate path
    time constant ([filters] tau_rate) around eq. 7's prediction from the last loop (1: the gyro as it is)."""
    return 1.0 - math.exp(-d.dt / d.tau_rate) if d.tau_rate > 0.0 else 1.0


def lqr(d: Inputs, pair, r: float, H: float) -> list[float]:
    """The discrete LQR gain (torque per unit state) at (r, H), on the model held over one loop with
    the delay chain: (p, q, n_x, n_y, torque, the commands still in the chain)."""
    import numpy as np
    from scipy.linalg import solve_discrete_are
    A, B = pair_model(d, pair, r, H)
    u_max = torque_scale(d)
    k = slots(d)
    Ad, Bd = augmented(discrete(A, B * u_max, d.dt, d.delay), k)
    n = A.shape[0]
    Q = np.diag([1.0 / RATE_SCALE ** 2] * 2 + [1.0 / AXIS_SCALE ** 2] * 2 + [0.0] * (n - 4 + k))
    R = np.array([[1.0]])
    P = solve_discrete_are(Ad, Bd, Q, R)
    K = np.linalg.solve(R + Bd.T @ P @ Bd, Bd.T @ P @ Ad)[0]
    # in the loop's units: torque per unit of (p, q, n, torque); the commands in the chain are torques
    # already (the LQR's input and its past values are per u_max alike)
    return [float(x) * u_max for x in K[:n]] + [0.0] * (5 - n) + [float(x) for x in K[n:]]


def loop_parts(d: Inputs, pair, r: float, H_true: float, true: Inputs):
    """The loop as spin.py flies it, linearised at spin r, on the plant `true` (its Jp, motor time
    constant and delay; rotor momentum H_true) with the controller designed on `d`: the rate filter
    around eq. 7's prediction (at the design's momentum, H = Jp Omega with the file's Jp), the torque
    model through the design's time constant and delay. (M0, c, rows): with gains K, the matrix that
    maps the loop's whole state from one loop to the next is M0 + c (-K rows) (`closed_loop`): the
    command is -K rows X, and c is where it enters."""
    import numpy as np
    A, B = pair_model(true, pair, r, H_true)
    Phi, Ga, Gb, mt = discrete(A, B, d.dt, true.delay)
    n = A.shape[0]
    phi, ga, gb, mn = torque_model(d.tau, d.dt, d.delay)
    S = max(mt, mn) + 2                       # the commands kept in the analysis
    # X = (x [n], u_{k-1} .. u_{k-S} [S], p_hat_{k-1}, q_hat_{k-1}, tau_hat_k, tau_hat_{k-1})
    N = n + S + 4
    iu, ip, iq, it, itp = n, n + S, n + S + 1, n + S + 2, n + S + 3
    eye = np.eye(N)
    Ac, _ = pair_model(d, pair, r, H_true * d.Jp / true.Jp if true.Jp > 0 else H_true)   # the controller's model
    bcol = (0.0, 1.0 / d.Jyy) if pair == (0, 2) else (1.0 / d.Jxx, 0.0)
    a = rate_filter(d)
    tq = 0.5 * (eye[it] + eye[itp])
    pred_p = eye[ip] + d.dt * (Ac[0, 0] * eye[ip] + Ac[0, 1] * eye[iq] + bcol[0] * tq)
    pred_q = eye[iq] + d.dt * (Ac[1, 0] * eye[ip] + Ac[1, 1] * eye[iq] + bcol[1] * tq)
    p_hat = (1.0 - a) * pred_p + a * eye[0]
    q_hat = (1.0 - a) * pred_q + a * eye[1]
    rows = np.array([p_hat, q_hat, eye[2], eye[3], eye[it]] + [eye[iu + j] for j in range(mn + 1)])
    M0, c = np.zeros((N, N)), np.zeros(N)

    def enter(i, k, coef):                    # row i takes coef u_{k-k}: the command itself, or the chain
        if k == 0:
            c[i] += coef
        else:
            M0[i, iu + k - 1] += coef
    M0[:n, :n] = Phi
    for i in range(n):
        enter(i, mt + 1, Ga[i, 0])
        enter(i, mt, Gb[i, 0])
    c[iu] = 1.0
    for j in range(1, S):
        M0[iu + j, iu + j - 1] = 1.0
    M0[ip], M0[iq] = p_hat, q_hat
    M0[it, it] = phi
    enter(it, mn + 1, ga)
    enter(it, mn, gb)
    M0[itp, it] = 1.0
    return M0, c, rows


def closed_loop(parts, K):
    """The loop's matrix from `loop_parts` and the gains K."""
    import numpy as np
    M0, c, rows = parts
    return M0 - np.outer(c, np.asarray(K[:rows.shape[0]]) @ rows)


def spectral_radius(M) -> float:
    import numpy as np
    return float(max(abs(np.linalg.eigvals(M))))


def plants(d: Inputs) -> list[Inputs]:
    """The vehicles each candidate gain is judged on: rotor inertias across the file's range (the
    coupling's sign, below), the corners of Jp and the motor time constant's ranges, and the delay
    chain's ends."""
    import numpy as np
    out = {d._replace(Jp=float(J)) for J in np.geomspace(d.Jp_lo, d.Jp_hi, ROBUST_JP)} if d.Jp_hi > d.Jp_lo else {d}
    for J in (d.Jp_lo, d.Jp_hi):
        for t in (d.tau_lo, d.tau_hi):
            out.add(d._replace(Jp=J, tau=t))
    for dl in (d.delay_lo, d.delay_hi):
        out.add(d._replace(delay=dl))
    return sorted(out)


def grid(d: Inputs) -> tuple[list[float], list[float]]:
    """The scheduled spin rates (in the pair's direction, rad/s) and rotor momenta (Jp Omega against
    it, kg m^2/s)."""
    top = min(GYRO_MAX, 1.5 * equilibrium_spin(d))
    rates = [R_LO + SPIN_STEP * k for k in range(int((top - R_LO) / SPIN_STEP) + 2)]
    H_full = d.Jp * pair_speed(d)
    return rates, [H_full * OMEGA_TOP * j / OMEGA_STEPS for j in range(OMEGA_STEPS + 1)]


def robust_gains(d: Inputs, pair, r: float, frac: float, models=None) -> tuple[list[float] | None, float]:
    """The gains at spin r (signed, the pair's direction) and the pair's rotor speed `frac` of its hover
    one, with the worst spectral radius they give over `plants(d)`. The gyroscopic coupling
    (Jzz - Jyy) r + H changes sign between r_s at the bottom and at the top of Jp's range, and a gain
    designed on the wrong sign destabilises the other axis; a slow motor wants other gains than a fast
    one. The candidates are the LQR on the nominal model, on a model without the coupling (which never
    relies on its sign), and on the nominal model with the slowest motor; the loop takes the one whose
    worst radius is smallest."""
    from numpy.linalg import LinAlgError
    sign = 1.0 if pair == (0, 2) else -1.0
    speed = pair_speed(d) * frac
    models = plants(d) if models is None else models
    coupling = (d.Jzz - d.Jyy) if pair == (0, 2) else (d.Jzz - d.Jxx)
    candidates = [(d, d.Jp * speed), (d, sign * coupling * r)]
    if d.tau_hi > d.tau:
        candidates.append((d._replace(tau=d.tau_hi), d.Jp * speed))
    best, parts = (None, float("nan")), None
    for design, Hd in candidates:
        try:
            K = lqr(design, pair, r, -sign * Hd)
        except (LinAlgError, ValueError):     # no spin, no momentum: one axis cannot be turned at all
            continue
        if parts is None:
            parts = [loop_parts(d, pair, r, -sign * t.Jp * speed, t) for t in models]
        worst = max(spectral_radius(closed_loop(pt, K)) for pt in parts)
        if best[0] is None or worst < best[1] - 1e-12:     # a tie (a marginal point) keeps the first
            best = (K, worst)
    return best


def schedule(d: Inputs) -> dict:
    """{"rates", "momenta", "radius": {pair: [j][k]}, (pair as "i,j"): gains [j][k] (`gain_count`) over
    `grid`, in the pair's signs: pair 1-3 turns clockwise (its reaction +z, conventions.md), so it
    spins the body at +r with its rotors' momentum -H about z_b; pair 2-4 the other way."""
    rates, momenta = grid(d)
    out: dict = {"rates": rates, "momenta": momenta, "radius": {}}
    models = plants(d)
    for pair in PAIRS:
        sign = 1.0 if pair == (0, 2) else -1.0
        rows, radii = [], []
        for j in range(len(momenta)):
            row, rad = [], []
            for r in rates:
                K, worst = robust_gains(d, pair, sign * r, OMEGA_TOP * j / OMEGA_STEPS, models)
                row.append(K)
                rad.append(worst)
            rows.append(row)
            radii.append(rad)
        solved = [(j, k) for j, row in enumerate(rows) for k, K in enumerate(row) if K is not None]
        for j, row in enumerate(rows):
            for k, K in enumerate(row):
                if K is None:             # the nearest solved point's gains stand in
                    jj, kk = min(solved, key=lambda jk: (abs(jk[0] - j) + abs(jk[1] - k), -jk[0]))
                    row[k] = rows[jj][kk]
        out["%d,%d" % pair] = rows
        out["radius"]["%d,%d" % pair] = radii
    return out


_MEMORY: dict = {}


def key(d: tuple) -> str:
    """The cache's name for the schedule of `d`: a hash of it and of the design's own constants."""
    constants = (R_LO, SPIN_STEP, OMEGA_STEPS, OMEGA_TOP, RATE_SCALE, AXIS_SCALE, EPS_DAMPING, GYRO_MAX, ROBUST_JP)
    return hashlib.sha256(repr((d, constants)).encode()).hexdigest()[:20]


def load(d: tuple) -> dict:
    """`schedule(d)`, computed once: from this process' memory, else from the user's cache folder's
    spin-KEY.json (flightctl/cachedir.py), else computed (with one BLAS thread) and written there."""
    k = key(d)
    if k not in _MEMORY:
        def compute():
            with OneBlasThread():
                return schedule(d)
        _MEMORY[k] = cached_json(f"spin-{k}.json", list(d), compute, "the two-rotor landing's gain cache")
    return _MEMORY[k]
