"""Losing a motor, and landing anyway: the paper's fail-safe direction (its reference 6: Mueller and
D'Andrea, "Stability and control of a quadrocopter despite the complete loss of one, two, or three
propellers", ICRA 2014), flown by the onboard loop in plain Python. docs/safety.md, "Losing a motor".

**Detection** (`MotorLossDetector`), from what the loop has: the gyro, the accelerometer and the
thrusts it commanded one loop earlier (the mixer's, through the motor time constant the parameter
file carries, if any). Eq. 7 turned around gives the roll and pitch torques the body felt,
`J dw/dt + w x (J w + Jp Omega z_b)` (the gyro differenced), and the specific force along z_b the
collective thrust; what the commanded thrusts predict (the "+" layout, eq. 25) is subtracted, both
low-passed over FILTER_S, and their slow parts (BIAS_S: a centre of mass off the middle, a battery
that sags, a weak motor) are taken away. A stopped rotor (or a lost propeller) i leaves its whole
thrust missing: the torque residual points along its arm and the collective one is down by its
thrust. Both, as fractions of the thrust motor i was asked for, above THRESHOLD for LOOPS loops
name motor i. A rotor lag the model lacks, in a manoeuvre, looks like a missing thrust in the
torque for tens of milliseconds, but not in the collective (the two sides of an axis change in
opposite directions); and the count only starts in calm flight (the body rates, low-passed, below
CALM) above MIN_ALT: a vehicle already tumbling, or touching the floor, is not read as a lost rotor.

**Flight on two rotors.** With a rotor lost the opposite one is stopped too, and the remaining pair,
on one arm, carries the weight: both spin the same way, so their reaction torques (eq. 28) turn the
body about z_b until the yaw drag (eq. 6) balances them, gamma1 r^2 = 2 (g1 f + g2) with f = M g / 2,
about 26 rad/s on the reference airframe. Yaw is given up; the direction of the thrust axis, n (the
world's up seen in the body frame), is controlled through the one torque the pair can give, about
the axis across its arm: the spin, and the rotors' own angular momentum (Jp Omega, eq. 9), turn it
into control of both components of n. The gains are a discrete LQR on eq. 7 linearised about the
spin (p, q, n_x, n_y, and the pair's torque through the motor time constant), computed once here
for a schedule of spin rates and rotor momenta and chosen by the measured r and the rotors' speeds
(through the motor time constant). The collective is the loop's landing (flightctl/control/landing.py:
a descent at a set speed on the vertical estimate, the floor felt with the accelerometer), divided by
the cosine of the thrust axis' tilt.
"""
from __future__ import annotations

from math import asin, atan2, cos, sin, sqrt

from flightctl.control.mixer import count_from_thrust
from flightctl.hal import ImuSample
from flightctl.params import Params

FILTER_S = 0.01          # s: the residuals' low-pass
BIAS_S = 0.5             # s: their slow part, followed while no motor is suspected
THRESHOLD = 0.6          # of the suspected motor's commanded thrust, missing in torque and in collective
LOOPS = 14               # loops (31 ms) in a row
CALM = 1.0               # rad/s: |p| + |q| low-passed over CALM_S: the count starts only below this
CALM_S = 0.1
MIN_ALT = 0.3            # m: below this a residual is the floor's
HIGH = 1.6               # a residual beyond this many times the motor's thrust is not one motor's
OPPOSITE = (2, 3, 0, 1)  # motor index -> the index of the motor across the frame
SPIN_STEP = 2.0          # rad/s between the scheduled gain sets, ...
RATE_SCALE, AXIS_SCALE = 0.5, 0.2    # rad/s, -: the LQR's acceptable body rate and tilt of n
OMEGA_STEPS = 4          # ... and steps of the rotors' momentum, from none to the pair's in hover
EPS_DAMPING = 0.05       # 1/s: see _pair_model


def motor_time_constant(params: Params) -> float:
    """The motor time constant the parameter file carries (a `motor_dynamics` or `motor_lag` effect,
    as `flightctl bench --profile step` writes it), else 0."""
    for e in params.effects:
        if e.cause in ("motor_dynamics", "motor_lag"):
            return float(dict(e.parameters)["tau"])
    return 0.0


class MotorLossDetector:
    """`update` every loop in flight, before the controller mixes anew; it returns the lost motor
    (1..4) the loop it is sure, else 0."""
    __slots__ = ("km", "kf", "kb", "kc", "fl", "rx", "ry", "rz", "bx", "by", "bz", "calm", "count",
                 "p", "q", "half", "quiet", "ic1", "Jxx", "Jyy", "Jp", "jx", "jy", "l", "iM", "M", "il")

    def __init__(self, params: Params, tau_motor: float | None = None):
        a = params.airframe
        dt = a.dt
        tau = motor_time_constant(params) if tau_motor is None else tau_motor
        self.km = dt / (tau + dt)
        self.kf, self.kb, self.kc = dt / (FILTER_S + dt), dt / (BIAS_S + dt), dt / (CALM_S + dt)
        self.half = 0.5 * a.B              # a commanded thrust counts as at least this (near-idle rotors)
        # a collective drop (N) at most this cannot be THRESHOLD of any motor's thrust (each counts as
        # at least `half`): no motor is suspected, and the loop need not look at each (most loops)
        self.quiet = THRESHOLD * self.half
        # the airframe's constants of eq. 7, 9 and 27, bound once (the loop reads them every period)
        self.ic1, self.Jxx, self.Jyy, self.Jp = 1.0 / a.c1, a.Jxx, a.Jyy, a.Jp
        self.jx, self.jy = a.Jzz - a.Jyy, a.Jxx - a.Jzz
        self.l, self.il, self.M, self.iM = a.l, 1.0 / a.l, a.M, 1.0 / a.M
        self.fl = [0.0, 0.0, 0.0, 0.0]
        self.count = [0, 0, 0, 0]
        self.reset(a.B)

    def reset(self, f0: float) -> None:
        """At take-off: the rotors at f0 each, nothing suspected."""
        for i in range(4):
            self.fl[i] = f0
            self.count[i] = 0
        self.rx = self.ry = self.rz = self.bx = self.by = self.bz = 0.0
        self.calm = 0.0
        self.p = self.q = None

    def update(self, s: ImuSample, f: list[float], alt: float, dt: float) -> int:
        fl, km = self.fl, self.km
        f0 = fl[0] = fl[0] + km * (f[0] - fl[0])    # the thrusts now, from the commands (one loop late)
        f1 = fl[1] = fl[1] + km * (f[1] - fl[1])
        f2 = fl[2] = fl[2] + km * (f[2] - fl[2])
        f3 = fl[3] = fl[3] + km * (f[3] - fl[3])
        p, q, r = s.gx, s.gy, s.gz
        if self.p is None:
            self.p, self.q = p, q
            return 0
        ic1, l = self.ic1, self.l
        Om = -sqrt(f0 * ic1) + sqrt(f1 * ic1) - sqrt(f2 * ic1) + sqrt(f3 * ic1)   # eq. 9 with eq. 27
        JpOm = self.Jp * Om
        # eq. 7 turned around: the torque the body felt, less the one the commanded thrusts give
        tx = self.Jxx * (p - self.p) / dt + q * r * self.jx + q * JpOm - l * (f1 - f3)
        ty = self.Jyy * (q - self.q) / dt + p * r * self.jy - p * JpOm - l * (f2 - f0)
        tz = s.az - (f0 + f1 + f2 + f3) * self.iM
        self.p, self.q = p, q
        kf = self.kf
        rx = self.rx = self.rx + kf * (tx - self.rx)
        ry = self.ry = self.ry + kf * (ty - self.ry)
        rz = self.rz = self.rz + kf * (tz - self.rz)
        self.calm += self.kc * ((p if p > 0 else -p) + (q if q > 0 else -q) - self.calm)
        count = self.count
        fall = (self.bz - rz) * self.M             # the collective thrust missing (N)
        if alt <= MIN_ALT or fall <= self.quiet:   # below MIN_ALT a residual is the floor's
            count[0] = count[1] = count[2] = count[3] = 0
        else:
            ex, ey = rx - self.bx, ry - self.by
            lost, half, calm = 0, self.half, self.calm < CALM
            il = self.il
            # the missing torque of motor i lies along its arm: +y for 1, -x for 2, -y for 3, +x for 4
            for i in range(4):
                fi = fl[i]
                if fi < half:
                    fi = half
                along = ey if i == 0 else -ex if i == 1 else -ey if i == 2 else ex
                share = along * il / fi
                drop = fall / fi
                if drop < share:
                    share = drop
                if THRESHOLD < share < HIGH and (calm or count[i] > 0):
                    count[i] += 1
                    if count[i] >= LOOPS:
                        lost = i + 1
                else:
                    count[i] = 0
            if count[0] or count[1] or count[2] or count[3]:
                return lost
        kb = self.kb                               # nothing suspected: the residuals' slow part
        self.bx += kb * (rx - self.bx)
        self.by += kb * (ry - self.by)
        self.bz += kb * (rz - self.bz)
        return 0


def _pair_model(a, pair: tuple[int, int], r: float, Om: float, tau_m: float):
    """Eq. 7 linearised about a spin r, the rotors' summed speed Om (eq. 9), for the torque of the
    rotor pair `pair`: continuous (A, B) for x = (p, q, n_x, n_y[, torque]) and the torque command (N m)."""
    import numpy as np
    hz = a.Jzz * r + a.Jp * Om
    # near the equilibrium spin hz - Jyy r nearly vanishes and p is barely reachable: its marginal mode
    # gets a token damping (EPS_DAMPING; the rotors' inflow damps p far more, docs/as-flown.md) so that
    # the Riccati equation has a solution at every scheduled rate
    A = np.array([[-EPS_DAMPING, -(hz - a.Jyy * r) / a.Jxx, 0.0, 0.0],
                  [(hz - a.Jxx * r) / a.Jyy, 0.0, 0.0, 0.0],
                  [0.0, -1.0, 0.0, r],                     # dn/dt = -w x n, about n = (0, 0, 1)
                  [1.0, 0.0, -r, 0.0]])
    b = np.array([0.0, 1.0 / a.Jyy, 0.0, 0.0]) if pair == (0, 2) else np.array([1.0 / a.Jxx, 0.0, 0.0, 0.0])
    if tau_m <= 0.0:
        return A, b[:, None]
    A5 = np.zeros((5, 5))
    A5[:4, :4] = A
    A5[:4, 4] = b
    A5[4, 4] = -1.0 / tau_m
    B5 = np.zeros((5, 1))
    B5[4, 0] = 1.0 / tau_m
    return A5, B5


_GAINS: dict = {}   # (airframe, motor time constant) -> {pair: gain schedule}


def _lqr(A, B, dt: float, weights) -> list[float]:
    """The discrete LQR gain of (A, B) held over dt, for the state weights and a unit input weight."""
    import numpy as np
    from scipy.linalg import expm, solve_discrete_are
    n = A.shape[0]
    M = np.zeros((n + 1, n + 1))
    M[:n, :n], M[:n, n:] = A * dt, B * dt
    E = expm(M)
    Ad, Bd = E[:n, :n], E[:n, n:]
    Q = np.diag(weights[:n])
    R = np.array([[1.0]])
    P = solve_discrete_are(Ad, Bd, Q, R)
    K = np.linalg.solve(R + Bd.T @ P @ Bd, Bd.T @ P @ Ad)
    return [float(k) for k in K[0]]


class SpinController:
    """The loop's controller after a motor is lost: `start(lost, ...)` once, `step(...)` every loop."""
    __slots__ = ("a", "tau_m", "r_bar", "gains", "pair", "off", "sign", "nx", "ny", "nz", "u_act", "u",
                 "counts", "idle", "yaw", "w", "om_full", "kw")

    def __init__(self, params: Params, tau_motor: float | None = None):
        a = self.a = params.airframe
        self.tau_m = motor_time_constant(params) if tau_motor is None else tau_motor
        f = a.M * a.g / 2.0
        self.r_bar = sqrt(2.0 * (a.g1 * f + a.g2) / a.gamma1)   # gamma1 r^2 = 2 (g1 f + g2), eq. 6 and 28
        self.om_full = 2.0 * sqrt(f / a.c1)         # the pair's summed speed carrying the weight (eq. 27)
        self.kw = a.dt / self.tau_m if self.tau_m > a.dt else 1.0   # the rotors' speeds per loop
        self.idle = count_from_thrust(0.0, a.h1, a.h2)   # the dead zone's edge: no thrust, the ESC armed
        key = (a, self.tau_m)
        if key not in _GAINS:        # once per vehicle and process: at start-up, never in the air
            _GAINS[key] = {pair: self._schedule(pair) for pair in ((0, 2), (1, 3))}
        self.gains = _GAINS[key]
        self.w = [0.0, 0.0, 0.0, 0.0]   # the rotors' speeds (eq. 27), through the motor time constant
        self.counts = [0, 0, 0, 0]
        self.pair = None

    def _schedule(self, pair: tuple[int, int]) -> list[list[list[float]]]:
        """LQR gains [j][k] for the rotors' summed speed j * OMEGA_STEPS-th of the pair's own in hover
        (it builds up as the stopped rotors run down and the pair speeds up) and spin rates k * SPIN_STEP
        up to 1.5 r_bar, both in the pair's direction."""
        a = self.a
        sign = 1.0 if pair == (0, 2) else -1.0   # 1 and 3 turn clockwise: their reaction is +z (conventions.md)
        F = a.M * a.g
        # weights: 1 / (acceptable value)^2 of p, q (rad/s), n_x, n_y, and the torque (N m)
        u_max = a.l * F / 2.0
        weights = [1.0 / RATE_SCALE ** 2, 1.0 / RATE_SCALE ** 2, 1.0 / AXIS_SCALE ** 2, 1.0 / AXIS_SCALE ** 2, 0.0]
        from numpy.linalg import LinAlgError
        out = []
        for j in range(OMEGA_STEPS + 1):
            row, k = [], 0
            while k * SPIN_STEP <= 1.5 * self.r_bar:
                A, B = _pair_model(a, pair, sign * k * SPIN_STEP, -sign * self.om_full * j / OMEGA_STEPS,
                                      self.tau_m)
                try:
                    row.append([g * u_max for g in _lqr(A, B * u_max, a.dt, weights)])
                except LinAlgError:   # e.g. no spin and no rotor momentum: the axis along the pair cannot
                    row.append(None)  # be turned at all; the nearest solved point's gains stand in
                k += 1
            out.append(row)
        solved = [(j, k) for j, row in enumerate(out) for k, K in enumerate(row) if K is not None]
        for j, row in enumerate(out):
            for k, K in enumerate(row):
                if K is None:
                    jj, kk = min(solved, key=lambda jk: (abs(jk[0] - j) + abs(jk[1] - k), -jk[0]))
                    row[k] = out[jj][kk]
        return out

    def start(self, lost: int, roll: float, pitch: float, yaw: float, f: list[float]) -> None:
        """Motor `lost` (1..4) is gone: stop it and the one across, fly on the other two; `f` the
        thrusts commanded last (the rotors' speeds now, for their momentum)."""
        i = lost - 1
        keep = tuple(sorted(j for j in range(4) if j not in (i, OPPOSITE[i])))
        self.pair, self.off = keep, (i, OPPOSITE[i])
        c1 = self.a.c1
        for m in range(4):
            self.w[m] = sqrt((f[m] if f[m] > 0.0 else 0.0) / c1)
        self.w[i] = 0.0                               # the lost one: stopped, or its propeller gone
        self.sign = 1.0 if keep == (0, 2) else -1.0
        cr, cp = cos(roll), cos(pitch)
        self.nx, self.ny, self.nz = -sin(pitch), sin(roll) * cp, cr * cp   # the world's up in the body
        self.u_act = self.u = 0.0
        self.yaw = yaw

    def tilt(self) -> tuple[float, float]:
        """Roll and pitch (Z-Y-X) of the body whose up is n."""
        nx = self.nx if -1.0 < self.nx < 1.0 else (1.0 if self.nx > 0 else -1.0)
        return atan2(self.ny, self.nz), -asin(nx)

    def step(self, s: ImuSample, dt: float, F: float) -> list[int]:
        """One loop: the pair's commands for the total thrust F (N) along the vertical (the loop's
        landing, control/landing.py, asks for it) and the torque that turns n back up."""
        a = self.a
        p, q, r = s.gx, s.gy, s.gz
        # n, the world's up in the body, turns by -w dt (Rodrigues, exact for a constant rate)
        nx, ny, nz = self.nx, self.ny, self.nz
        w2 = p * p + q * q + r * r
        if w2 > 0.0:
            w = sqrt(w2)
            th = w * dt
            ux, uy, uz = -p / w, -q / w, -r / w
            c, sn = cos(th), sin(th)
            d = (ux * nx + uy * ny + uz * nz) * (1.0 - c)
            nx, ny, nz = (nx * c + (uy * nz - uz * ny) * sn + ux * d,
                          ny * c + (uz * nx - ux * nz) * sn + uy * d,
                          nz * c + (ux * ny - uy * nx) * sn + uz * d)
            norm = 1.0 / sqrt(nx * nx + ny * ny + nz * nz)
            nx, ny, nz = nx * norm, ny * norm, nz * norm
        self.nx, self.ny, self.nz = nx, ny, nz
        self.yaw += r * dt
        # the pair's torque: the gain set of the spin rate and the rotors' momentum now
        w = self.w
        sign = self.sign
        jw = int(-sign * (-w[0] + w[1] - w[2] + w[3]) / self.om_full * OMEGA_STEPS + 0.5)   # eq. 9
        row = self.gains[self.pair][jw if 0 <= jw <= OMEGA_STEPS else (0 if jw < 0 else OMEGA_STEPS)]
        k = int(sign * r / SPIN_STEP + 0.5)
        K = row[k if 0 <= k < len(row) else (0 if k < 0 else len(row) - 1)]
        if self.tau_m > 0.0:
            self.u_act += (self.u - self.u_act) * dt / self.tau_m
            u = -(K[0] * p + K[1] * q + K[2] * nx + K[3] * ny + K[4] * self.u_act)
        else:
            u = -(K[0] * p + K[1] * q + K[2] * nx + K[3] * ny)
        F = F / (nz if nz > 0.5 else 0.5)        # along the thrust axis, tilted from the vertical
        F = F if F > 0.0 else 0.0
        lim = a.l * F * 0.5                        # each rotor's thrust stays >= 0
        u = lim if u > lim else -lim if u < -lim else u
        self.u = u
        i, j = self.pair
        half, d = 0.5 * F, u / (2.0 * a.l)
        # pair (1, 3): tau_theta = l (f3 - f1); pair (2, 4): tau_phi = l (f2 - f4)
        fi, fj = (half - d, half + d) if self.pair == (0, 2) else (half + d, half - d)
        # up to the ESC's full command: on two rotors the limits of Table 3 (f <= 2B) would leave no
        # margin, and the motors give far more (eq. 26 at P = 255)
        counts = self.counts
        fi = fi if fi > 0.0 else 0.0
        fj = fj if fj > 0.0 else 0.0
        counts[i] = count_from_thrust(fi, a.h1, a.h2)
        counts[j] = count_from_thrust(fj, a.h1, a.h2)
        o1, o2 = self.off
        counts[o1] = counts[o2] = self.idle
        # the rotors' speeds (eq. 27) follow through the motor time constant: their momentum for the gains
        k, c1 = self.kw, a.c1
        w[i] += k * (sqrt(fi / c1) - w[i])
        w[j] += k * (sqrt(fj / c1) - w[j])
        w[o1] -= k * w[o1]
        w[o2] -= k * w[o2]
        return counts
