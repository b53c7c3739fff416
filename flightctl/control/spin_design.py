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
gyroscopic coupling vanishes, below). The pair's torque follows its command through the motor time
constant (a fifth state). The gains are the discrete LQR of this model held over one loop, on a grid
of spin rates from R_LO (a yaw turn against the pair's spin when the motor is lost: the pair brakes
it, through zero spin) to past the equilibrium, and of rotor momenta from none to OMEGA_TOP of the
pair's own in hover; the loop interpolates them (bilinear) at the measured rate and the rotors'
modelled speeds.

**Where it is weak.** The torque reaches the other axis only through the coupling
(Jzz - Jyy) r + H (pair 1-3) or (Jzz - Jxx) r + H (pair 2-4). The rotors turn against the spin
(H < 0 in the spin's direction), so the coupling vanishes at r_s = Jp |Omega| / (Jzz - Jyy): 26 rad/s
with Table 2's Jp at the pair's hover speed, right at the equilibrium spin; 9.7 rad/s with the
as-flown file's 1e-4. There that axis is not steered, only damped (`radius` gives the closed
loop's spectral radius at each point; docs/safety.md tabulates it).

**Where it cannot work** (`unusable`): no spin (the pair's torque 2 (g1 f + g2) not positive), no
drag to settle it (gamma1 = gamma0 = 0), or an equilibrium beyond the gyro's full scale (the driver's
+-2000 deg/s): the loop then flies without the two-rotor mode and says so at start-up.
"""
from __future__ import annotations

import hashlib
import json
import math
import os
from pathlib import Path

from flightctl.drivers import mpu9250_regs as reg
from flightctl.params import Params

GYRO_MAX = math.radians(32767.0 / reg.GYRO_LSB_PER_DPS[3])   # rad/s: the driver's +-2000 deg/s (34.9)
R_LO = -8.0              # rad/s: the schedule's lowest spin (against the pair's direction)
SPIN_STEP = 2.0          # rad/s between scheduled spin rates
OMEGA_STEPS = 5          # steps of the rotors' momentum, from none ...
OMEGA_TOP = 1.25         # ... to this much of the pair's summed speed in hover
RATE_SCALE, AXIS_SCALE = 1.0, 0.2    # rad/s, -: the LQR's acceptable body rate and tilt of n
EPS_DAMPING = 0.05       # 1/s
SCHEMA = 2               # bump when the design changes: the disk cache's key includes it
PAIRS = ((0, 2), (1, 3))


def motor_time_constant(params: Params) -> float:
    """The motor time constant the parameter file carries (a `motor_dynamics` or `motor_lag` effect,
    as `flightctl bench --profile step` writes it), else 0."""
    for e in params.effects:
        if e.cause in ("motor_dynamics", "motor_lag"):
            return float(dict(e.parameters)["tau"])
    return 0.0


def effect_value(params: Params, cause: str, name: str) -> float:
    """A parameter of an effect the parameter file carries, 0 where it carries none."""
    for e in params.effects:
        if e.cause == cause:
            return float(dict(e.parameters).get(name, 0.0))
    return 0.0


def design_inputs(params: Params, tau_motor: float | None = None) -> tuple:
    """Every number the design depends on, in a fixed order (the cache's key)."""
    a = params.airframe
    tau = motor_time_constant(params) if tau_motor is None else tau_motor
    lo, hi = next(((lo, hi) for name, lo, hi in params.ranges if name == "Jp"), (a.Jp, a.Jp))
    return (SCHEMA, a.M, a.g, a.l, a.Jxx, a.Jyy, a.Jzz, a.Jp, a.c1, a.g1, a.g2, a.gamma1, a.dt,
            effect_value(params, "linear_yaw_drag", "gamma0"), effect_value(params, "rotor_inflow", "k"),
            effect_value(params, "rotor_inflow", "hub"), tau, lo, hi)


def pair_torque(d: tuple) -> float:
    """The pair's summed reaction torque carrying the weight, 2 (g1 f + g2), f = M g / 2 (eq. 28)."""
    M, g, g1, g2 = d[1], d[2], d[9], d[10]
    return 2.0 * (g1 * M * g / 2.0 + g2)


def equilibrium_spin(d: tuple) -> float:
    """gamma1 r^2 + gamma0 r = 2 (g1 f + g2): the spin the pair settles at (inf without drag)."""
    T, gamma1, gamma0 = pair_torque(d), d[11], d[13]
    if gamma1 > 0.0:
        return (-gamma0 + math.sqrt(gamma0 * gamma0 + 4.0 * gamma1 * T)) / (2.0 * gamma1) if T > 0.0 else 0.0
    return T / gamma0 if gamma0 > 0.0 else math.inf


def unusable(d: tuple) -> str:
    """Why the two-rotor mode cannot work on this vehicle, or ''."""
    if not pair_torque(d) > 0.0:
        return (f"the rotor pair's reaction torque 2 (g1 f + g2) = {pair_torque(d):.3g} N m is not positive: "
                "no spin to steer the thrust axis with")
    r = equilibrium_spin(d)
    if not r <= GYRO_MAX:
        return (f"its spin on two rotors ({r:.3g} rad/s from gamma1 = {d[11]:.3g}) is beyond the gyro's "
                f"full scale ({GYRO_MAX:.1f} rad/s)")
    return ""


def pair_speed(d: tuple) -> float:
    """The pair's summed rotor speed carrying the weight, 2 sqrt(f / c1), f = M g / 2 (eq. 27)."""
    return 2.0 * math.sqrt(d[1] * d[2] / 2.0 / d[8])


def pair_model(d: tuple, pair: tuple[int, int], r: float, H: float):
    """Continuous (A, B) at spin r and rotor momentum H = Jp Omega (module docstring), for x = (p, q,
    n_x, n_y[, torque]) and the torque command (N m) across the pair's arm."""
    import numpy as np
    l, Jxx, Jyy, Jzz, k_in, hub, tau = d[3], d[4], d[5], d[6], d[14], d[15], d[16]
    own = 2.0 * k_in * l * l * math.sqrt(2.0)        # the inflow's damping on the pair's axis (f = 2B)
    dx = 0.5 * hub + (own if pair == (1, 3) else 0.0) + EPS_DAMPING * Jxx
    dy = 0.5 * hub + (own if pair == (0, 2) else 0.0) + EPS_DAMPING * Jyy
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


def discrete(A, B, dt: float):
    """(Ad, Bd): the model held over dt (zero-order hold)."""
    import numpy as np
    from scipy.linalg import expm
    n = A.shape[0]
    E = np.zeros((n + 1, n + 1))
    E[:n, :n], E[:n, n:] = A * dt, B * dt
    E = expm(E)
    return E[:n, :n], E[:n, n:]


def torque_scale(d: tuple) -> float:
    """The pair's largest torque across its arm, l M g / 2 (N m): the LQR's unit of input."""
    return d[3] * d[1] * d[2] / 2.0


def radius(d: tuple, pair, r: float, H: float, K, held=None) -> float:
    """The spectral radius of the loop closed by the gains K on the model of `d` at (r, H), held
    over one loop (`held`: that model's `discrete` (Ad, Bd), when the caller has it): below 1 the
    linearised loop is stable, its slowest mode decaying by that factor a loop."""
    import numpy as np
    if held is None:
        A, B = pair_model(d, pair, r, H)
        held = discrete(A, B, d[12])
    Ad, Bd = held
    return float(max(abs(np.linalg.eigvals(Ad - Bd @ np.array(K[:Ad.shape[0]])[None, :]))))


def with_jp(d: tuple, Jp: float) -> tuple:
    """`d` with another rotor inertia."""
    return d[:7] + (Jp,) + d[8:]


def lqr(d: tuple, pair, r: float, H: float) -> list[float]:
    """The discrete LQR gain (torque per unit state) at (r, H)."""
    import numpy as np
    from scipy.linalg import solve_discrete_are
    A, B = pair_model(d, pair, r, H)
    u_max = torque_scale(d)
    Ad, Bd = discrete(A, B * u_max, d[12])
    n = A.shape[0]
    Q = np.diag([1.0 / RATE_SCALE ** 2] * 2 + [1.0 / AXIS_SCALE ** 2] * 2 + [0.0] * (n - 4))
    R = np.array([[1.0]])
    P = solve_discrete_are(Ad, Bd, Q, R)
    K = np.linalg.solve(R + Bd.T @ P @ Bd, Bd.T @ P @ Ad)[0] * u_max
    return [float(k) for k in K] + [0.0] * (5 - n)


def grid(d: tuple) -> tuple[list[float], list[float]]:
    """The scheduled spin rates (in the pair's direction, rad/s) and rotor momenta (Jp Omega against
    it, kg m^2/s)."""
    top = min(GYRO_MAX, 1.5 * equilibrium_spin(d))
    rates = [R_LO + SPIN_STEP * k for k in range(int((top - R_LO) / SPIN_STEP) + 2)]
    H_full = d[7] * pair_speed(d)
    return rates, [H_full * OMEGA_TOP * j / OMEGA_STEPS for j in range(OMEGA_STEPS + 1)]


ROBUST_JP = 4            # rotor inertias across the file's range at which each candidate is judged


def robust_gains(d: tuple, pair, r: float, frac: float) -> tuple[list[float] | None, float]:
    """The gains at spin r (signed, the pair's direction) and the pair's rotor speed `frac` of its hover
    one, with the worst spectral radius they give over the file's rotor inertia range (d[17], d[18]).
    The gyroscopic coupling (Jzz - Jyy) r + H changes sign between r_s at the bottom and at the top of
    Jp's range, and a gain designed on the wrong sign destabilises the other axis: the candidates are
    the LQR on the nominal Jp and on a model without the coupling (which never relies on its sign),
    and the loop takes the one whose worst radius over the range is smallest."""
    import numpy as np
    from numpy.linalg import LinAlgError
    sign = 1.0 if pair == (0, 2) else -1.0
    speed = pair_speed(d) * frac
    lo, hi = d[17], d[18]
    if not hi > lo:
        try:
            K = lqr(d, pair, r, -sign * d[7] * speed)
        except (LinAlgError, ValueError):     # no spin, no momentum: one axis cannot be turned at all
            return None, float("nan")
        return K, radius(d, pair, r, -sign * d[7] * speed, K)
    trues = []
    for J in np.geomspace(lo, hi, ROBUST_JP):
        t = with_jp(d, float(J))
        A, B = pair_model(t, pair, r, -sign * J * speed)
        trues.append(discrete(A, B, d[12]))
    coupling = (d[6] - d[5]) if pair == (0, 2) else (d[6] - d[4])
    best = (None, float("nan"))
    for Hd in (d[7] * speed, sign * coupling * r):
        try:
            K = lqr(d, pair, r, -sign * Hd)
        except (LinAlgError, ValueError):
            continue
        worst = max(radius(d, pair, r, 0.0, K, held) for held in trues)
        if best[0] is None or worst < best[1]:
            best = (K, worst)
    return best


_BLAS_NAMES = ("openblas", "scipy_openblas")   # + _set_num_threads, or + _set_num_threads64_ (64-bit ints)


class OneBlasThread:
    """Within it, OpenBLAS (numpy's and scipy's, found among the process' loaded libraries) runs one
    thread. Its threads on the design's 5x5 problems cost more than the work: on a loaded 2-core machine
    the schedule took 12 s of CPU with them and 0.7 s without (scripts/benchmark.py). Linux; elsewhere,
    or without OpenBLAS, nothing changes."""

    def __enter__(self):
        import ctypes
        import numpy  # noqa: F401  (their libraries loaded, to be found)
        import scipy.linalg  # noqa: F401
        self.restore = []
        try:
            with open("/proc/self/maps") as f:
                paths = {line.split()[-1] for line in f if "openblas" in line.lower() and "/" in line}
        except OSError:
            return self
        for path in paths:
            try:
                lib = ctypes.CDLL(path)
            except OSError:
                continue
            for base in _BLAS_NAMES:
                get = getattr(lib, base + "_get_num_threads", None) or getattr(lib, base + "_get_num_threads64_", None)
                put = getattr(lib, base + "_set_num_threads", None) or getattr(lib, base + "_set_num_threads64_", None)
                if get is not None and put is not None:
                    self.restore.append((put, get()))
                    put(1)
                    break
        return self

    def __exit__(self, *exc):
        for put, n in self.restore:
            put(n)
        return False


def schedule(d: tuple) -> dict:
    """{"rates", "momenta", "radius": {pair: [j][k]}, (pair as "i,j"): gains [j][k] (5 each)} over
    `grid`, in the pair's signs: pair 1-3 turns clockwise (its reaction +z, conventions.md), so it
    spins the body at +r with its rotors' momentum -H about z_b; pair 2-4 the other way."""
    rates, momenta = grid(d)
    out: dict = {"rates": rates, "momenta": momenta, "radius": {}}
    for pair in PAIRS:
        sign = 1.0 if pair == (0, 2) else -1.0
        rows, radii = [], []
        for j in range(len(momenta)):
            row, rad = [], []
            for r in rates:
                K, worst = robust_gains(d, pair, sign * r, OMEGA_TOP * j / OMEGA_STEPS)
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


def cache_dir() -> Path | None:
    """FLIGHTCTL_CACHE, else $XDG_CACHE_HOME/flightctl, else ~/.cache/flightctl (None: no home)."""
    if os.environ.get("FLIGHTCTL_CACHE"):
        return Path(os.environ["FLIGHTCTL_CACHE"])
    base = os.environ.get("XDG_CACHE_HOME") or (os.path.join(os.path.expanduser("~"), ".cache")
                                                 if os.path.expanduser("~") != "~" else "")
    return Path(base) / "flightctl" if base else None


_MEMORY: dict = {}


def key(d: tuple) -> str:
    """The cache's name for the schedule of `d`: a hash of it and of the design's own constants."""
    constants = (R_LO, SPIN_STEP, OMEGA_STEPS, OMEGA_TOP, RATE_SCALE, AXIS_SCALE, EPS_DAMPING, GYRO_MAX)
    return hashlib.sha256(repr((d, constants)).encode()).hexdigest()[:20]


def load(d: tuple) -> dict:
    """`schedule(d)`, computed once: from this process' memory, else from the cache folder's
    spin-KEY.json, else computed and written there (atomically; a folder that cannot be written is
    no error: the schedule is then computed at each start)."""
    k = key(d)
    if k in _MEMORY:
        return _MEMORY[k]
    folder = cache_dir()
    path = folder / f"spin-{k}.json" if folder is not None else None
    s = None
    if path is not None:
        try:
            s = json.loads(path.read_text())
            if s.get("inputs") != list(d):
                s = None
        except (OSError, ValueError):
            s = None
    if s is None:
        with OneBlasThread():
            s = schedule(d)
        s["inputs"] = list(d)
        if path is not None:
            try:
                folder.mkdir(parents=True, exist_ok=True)
                tmp = path.with_suffix(f".{os.getpid()}.tmp")
                tmp.write_text(json.dumps(s))
                os.replace(tmp, path)
            except OSError:
                pass
    _MEMORY[k] = s
    return s
