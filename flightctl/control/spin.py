"""Losing a motor, and landing anyway: the paper's fail-safe direction (its reference 6: Mueller and
D'Andrea, "Stability and control of a quadrocopter despite the complete loss of one, two, or three
propellers", ICRA 2014), flown by the onboard loop in plain Python. docs/safety.md, "Losing a motor".

The detector that names the motor is flightctl/control/motor_loss.py; the design (the spin, the
linearised model, the LQR gain schedule and its cache) flightctl/control/spin_design.py.

**Flight on two rotors** (`SpinController`). The rotor across the lost one is stopped too, and the
remaining pair, on one arm, carries the weight: both spin the same way, so their reaction torques
(eq. 28) turn the body about z_b until the yaw drag (eq. 6) balances them. Yaw is given up. The
loop's attitude is integrated from the gyro alone, exactly over each loop (Rodrigues): the world's
three axes seen in the body (the third is n, the world's up), since the accelerometer no longer sees
gravity in a spin. The pair's one torque, across its arm, steers the thrust axis through the spin and
the rotors' momentum (spin_design.py): the gains, interpolated every loop at the measured spin rate and
the rotors' modelled speeds, drive a world direction d seen in the body to z_b. d is the vertical
tilted against the horizontal velocity, which the accelerometer integrated in the world frame gives
(the tilt and the speed the loss itself gave the vehicle; an error in the starting attitude is not
seen: docs/safety.md gives the drift): a braking acceleration of at most BRAKE_TILT, over
BRAKE_S. The collective is the loop's landing (flightctl/control/landing.py: a descent at a set speed
on the vertical estimate, the floor felt with the accelerometer), divided by the cosine of the thrust
axis' tilt.
"""
from __future__ import annotations

from math import asin, atan2, cos, radians, sin, sqrt, tan

from flightctl.control import spin_design
from flightctl.control.mixer import count_from_thrust
from flightctl.control.motor_loss import OPPOSITE
from flightctl.hal import ImuSample
from flightctl.params import Params
from flightctl.physics import thrust_from_command

BRAKE_S = 1.5                 # s: the horizontal speed's time constant while braking
BRAKE_TILT = radians(8.0)     # rad: the largest tilt given to braking


class SpinController:
    """The loop's controller after a motor is lost: `start(lost, ...)` once, `step(...)` every loop.
    `why_not`: why the two-rotor mode cannot work on this vehicle ('' when it can)."""
    __slots__ = ("a", "tau_m", "r_bar", "why_not", "sched", "rates", "r0", "nk", "hstep", "nj", "pair",
                 "off", "sign", "e", "u_act", "u_prev", "counts", "idle", "f_full", "yaw", "w", "kw", "Jp", "vx", "vy",
                 "amax", "kv", "g", "K", "ng", "chain", "phi", "ga", "gb", "m", "a_rate", "ph", "qh", "fresh",
                 "jx", "jy", "ex", "ey", "bx", "by", "d")

    def __init__(self, params: Params, tau_motor: float | None = None):
        a = self.a = params.airframe
        d = spin_design.design_inputs(params, tau_motor)
        self.tau_m = d.tau
        self.why_not = spin_design.unusable(d)
        self.r_bar = spin_design.equilibrium_spin(d)
        self.kw = a.dt / self.tau_m if self.tau_m > a.dt else 1.0   # the rotors' speeds per loop
        self.idle = count_from_thrust(0.0, a.h1, a.h2)   # the dead zone's edge: no thrust, the ESC armed
        self.f_full = thrust_from_command(spin_design.esc_full_throttle(params), a.h1, a.h2)   # its ceiling, N
        self.Jp, self.g = a.Jp, a.g
        # the design's model, as the loop runs it: the pair's torque through the motor time constant and
        # the delay chain (tau_{k+1} = phi tau_k + ga u_{k-m-1} + gb u_{k-m}), the commands still in the
        # chain, and the rate filter around eq. 7's prediction (spin_design.closed_loop)
        self.phi, self.ga, self.gb, self.m = spin_design.torque_model(d.tau, d.dt, d.delay)
        self.ng = spin_design.gain_count(d)
        self.chain = [0.0] * spin_design.slots(d)        # u_{k-1}, u_{k-2}, ...
        self.a_rate = spin_design.rate_filter(d)
        self.jx, self.jy = (a.Jzz - a.Jyy) / a.Jxx, (a.Jzz - a.Jxx) / a.Jyy
        self.bx, self.by = 1.0 / a.Jxx, 1.0 / a.Jyy
        self.ex = self.ey = 0.0
        self.sched = None
        if not self.why_not:          # once per vehicle: at start-up, never in the air (cached on disk)
            s = spin_design.load(d)
            self.sched = {pair: [[tuple(K) for K in row] for row in s["%d,%d" % pair]] for pair in spin_design.PAIRS}
            self.rates = s["rates"]
            self.r0, self.nk = self.rates[0], len(self.rates)
            self.hstep, self.nj = s["momenta"][1], len(s["momenta"])
        self.amax = a.g * tan(BRAKE_TILT)
        self.kv = 1.0 / BRAKE_S
        self.w = [0.0, 0.0, 0.0, 0.0]   # the rotors' speeds (eq. 27), through the motor time constant
        self.e = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]   # the world's x, y and up in the body
        self.counts = [0, 0, 0, 0]
        self.K = [0.0] * self.ng
        self.pair = None
        self.d = d

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
        # R^T = (Rz Ry Rx)^T: its columns are the world's axes seen in the body (conventions.md)
        cr, sr, cp, sp, cy, sy = cos(roll), sin(roll), cos(pitch), sin(pitch), cos(yaw), sin(yaw)
        e = self.e
        e[0], e[1], e[2] = cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr   # world x
        e[3], e[4], e[5] = sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr   # world y
        e[6], e[7], e[8] = -sp, cp * sr, cp * cr                                     # world up: n
        # the pair's torque across its arm now, from the four-rotor mixer's last thrusts (eq. 25), and the
        # commands still in the delay chain: those thrusts too
        tq = self.a.l * c1 * ((self.w[2] ** 2 - self.w[0] ** 2) if keep == (0, 2) else (self.w[1] ** 2 - self.w[3] ** 2))
        self.u_act = self.u_prev = tq
        for k in range(len(self.chain)):
            self.chain[k] = tq
        dx, dy = spin_design.damping(self.d, keep)
        self.ex, self.ey = dx / self.a.Jxx, dy / self.a.Jyy
        self.fresh = True
        self.vx = self.vy = 0.0
        self.yaw = yaw

    def tilt(self) -> tuple[float, float]:
        """Roll and pitch (Z-Y-X) of the body whose up is n."""
        e = self.e
        nx = e[6] if -1.0 < e[6] < 1.0 else (1.0 if e[6] > 0 else -1.0)
        return atan2(e[7], e[8]), -asin(nx)

    def gains(self, r: float) -> list[float]:
        """The scheduled gains (into `K`), bilinear in the spin rate r (gyro) and the rotors' momentum
        (their modelled speeds, eq. 9), both in the pair's direction."""
        w, sign = self.w, self.sign
        h = -sign * self.Jp * (-w[0] + w[1] - w[2] + w[3]) / self.hstep
        h = 0.0 if h < 0.0 else self.nj - 1.001 if h > self.nj - 1.001 else h
        k = (sign * r - self.r0) * (1.0 / spin_design.SPIN_STEP)
        k = 0.0 if k < 0.0 else self.nk - 1.001 if k > self.nk - 1.001 else k
        j0, k0 = int(h), int(k)
        fh, fk = h - j0, k - k0
        rows = self.sched[self.pair]
        A, B = rows[j0][k0], rows[j0][k0 + 1]
        C, D = rows[j0 + 1][k0], rows[j0 + 1][k0 + 1]
        a, b, c = (1.0 - fh) * (1.0 - fk), (1.0 - fh) * fk, fh * (1.0 - fk)
        dd = fh * fk
        K = self.K
        for m in range(self.ng):
            K[m] = a * A[m] + b * B[m] + c * C[m] + dd * D[m]
        return K

    def step(self, s: ImuSample, dt: float, F: float) -> list[int]:
        """One loop: the pair's commands for the total thrust F (N) along the vertical (the loop's
        landing, control/landing.py, asks for it) and the torque that turns the thrust axis to d."""
        a, e = self.a, self.e
        p, q, r = s.gx, s.gy, s.gz
        # the world's axes in the body turn by -w dt (Rodrigues, exact for a constant rate)
        w2 = p * p + q * q + r * r
        if w2 > 0.0:
            wn = sqrt(w2)
            ux, uy, uz = -p / wn, -q / wn, -r / wn
            c, sn = cos(wn * dt), sin(wn * dt)
            c1 = 1.0 - c
            for o in (0, 3, 6):
                x, y, z = e[o], e[o + 1], e[o + 2]
                d = (ux * x + uy * y + uz * z) * c1
                e[o] = x * c + (uy * z - uz * y) * sn + ux * d
                e[o + 1] = y * c + (uz * x - ux * z) * sn + uy * d
                e[o + 2] = z * c + (ux * y - uy * x) * sn + uz * d
        nx, ny, nz = e[6], e[7], e[8]
        norm = 1.0 / sqrt(nx * nx + ny * ny + nz * nz)
        nx, ny, nz = e[6], e[7], e[8] = nx * norm, ny * norm, nz * norm
        self.yaw += r * dt
        # the horizontal velocity: the specific force in the world frame, integrated
        ax, ay, az = s.ax, s.ay, s.az
        vx = self.vx = self.vx + (e[0] * ax + e[1] * ay + e[2] * az) * dt
        vy = self.vy = self.vy + (e[3] * ax + e[4] * ay + e[5] * az) * dt
        # d: the vertical tilted to brake it, seen in the body
        bx, by = -self.kv * vx, -self.kv * vy
        b2 = bx * bx + by * by
        if b2 > self.amax * self.amax:
            k = self.amax / sqrt(b2)
            bx, by = bx * k, by * k
        gi = 1.0 / self.g
        dx = (bx * e[0] + by * e[3]) * gi + nx
        dy = (bx * e[1] + by * e[4]) * gi + ny
        # the body rates through the rate filter: an EMA around eq. 7's prediction from the last loop (the
        # pair's torque over it, the gyroscopic coupling of the spin and the rotors' momentum, the damping)
        w = self.w
        if self.fresh:
            self.ph, self.qh, self.fresh = p, q, False
        else:
            ph, qh, t_mid = self.ph, self.qh, 0.5 * (self.u_prev + self.u_act)
            H = self.Jp * (-w[0] + w[1] - w[2] + w[3])
            if self.pair == (0, 2):
                pp = ph + dt * (-(self.jx * r + H * self.bx) * qh - self.ex * ph)
                qp = qh + dt * ((self.jy * r + H * self.by) * ph - self.ey * qh + t_mid * self.by)
            else:
                pp = ph + dt * (-(self.jx * r + H * self.bx) * qh - self.ex * ph + t_mid * self.bx)
                qp = qh + dt * ((self.jy * r + H * self.by) * ph - self.ey * qh)
            ar = self.a_rate
            self.ph, self.qh = pp + ar * (p - pp), qp + ar * (q - qp)
        # the pair's torque: the gains at the spin rate and the rotors' momentum now, on the state the
        # design has (the filtered rates, the thrust axis, the modelled torque, the commands in the chain)
        K = self.gains(r)
        chain = self.chain
        u = -(K[0] * self.ph + K[1] * self.qh + K[2] * dx + K[3] * dy + K[4] * self.u_act)
        for k in range(len(chain)):
            u -= K[5 + k] * chain[k]
        F = F / (nz if nz > 0.5 else 0.5)        # along the thrust axis, tilted from the vertical
        F = F if F > 0.0 else 0.0
        lim = a.l * F                              # each rotor's thrust stays >= 0
        u = lim if u > lim else -lim if u < -lim else u
        # the modelled torque at the next loop (through the delay chain and the motor time constant)
        m = self.m
        self.u_prev = self.u_act
        self.u_act = self.phi * self.u_act + self.ga * chain[m] + self.gb * (chain[m - 1] if m > 0 else u)
        for k in range(len(chain) - 1, 0, -1):
            chain[k] = chain[k - 1]
        chain[0] = u
        i, j = self.pair
        half, d = 0.5 * F, u / (2.0 * a.l)
        # pair (1, 3): tau_theta = l (f3 - f1); pair (2, 4): tau_phi = l (f2 - f4)
        fi, fj = (half - d, half + d) if self.pair == (0, 2) else (half + d, half - d)
        # up to the ESC's full throttle: on two rotors the limits of Table 3 (f <= 2B) would leave no
        # margin, and the motors give more (eq. 26 at the ESC's full throttle, the file's p_full)
        # past it, both give up the excess alike: the torque (their difference) before the collective, as
        # a mixer that saturates keeps the attitude (ArduPilot's AP_MotorsMatrix::output_armed_stabilizing)
        counts = self.counts
        over = (fi if fi > fj else fj) - self.f_full
        if over > 0.0:
            fi, fj = fi - over, fj - over
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
