"""Naming a lost motor: the loop's detector (docs/safety.md, "Losing a motor"), from what the loop has:
the gyro, the accelerometer and the thrusts it commanded one loop earlier (the mixer's, through the
motor time constant the parameter file carries, if any). Eq. 7 turned around gives the roll and pitch
torques the body felt, `J dw/dt + w x (J w + Jp Omega z_b)` (the gyro differenced), and the specific
force along z_b the collective thrust; what the commanded thrusts predict (the "+" layout, eq. 25; the
rotors' speeds, eq. 27, following them through the motor time constant) is subtracted, both low-passed over FILTER_S
(two EMAs of half of it: the rotors' vibration lines and the
gyro's noise, differenced, kept out), and their slow parts (BIAS_S: a centre of mass off the
middle, a battery that sags, a weak motor) are taken away. A stopped rotor (or a lost propeller) i
leaves its whole thrust missing: the torque residual points along its arm and the collective one is
down by its thrust; a weak one (a failing ESC, a chipped propeller) leaves part of it missing. The
smaller of the two, as a fraction of the thrust motor i was asked for, is its missing share. Above
THRESHOLD for LOOPS loops of calm flight it names motor i at once; above WEAK for WEAK_LOOPS loops
(calm when the count began) it names motor i too, each with the share it misses, and `flown_on_four` decides what the
loop does with it. A rotor lag the model lacks, in a manoeuvre, looks like a missing thrust in the torque
for tens of milliseconds, but not in the collective (the two sides of an axis change in opposite
directions); and the count only starts in calm flight (the body rates, low-passed, below CALM): a
vehicle already tumbling is not read as a lost rotor. It looks at any height: a vehicle resting on
the floor has the floor carrying weight and torque, and nothing is looked for while the floor may be
holding it: from arming, and from a touchdown's jolt (the low-passed collective residual JOLT above the
commanded thrusts), until the sonar sees it above the floor (`lifted`), for at least JOLT_S after the
jolt (a hop, legs settling); and while the loop's altitude is the floor's (`update`'s `low`). A
vehicle that limit-cycles down onto the floor in the middle of a plan, its attitude integrals wound up,
gives the floor a torque and a weight to carry that look like a lost motor.
"""
from __future__ import annotations

from math import radians, sqrt

from flightctl.control.spin_design import motor_time_constant
from flightctl.hal import ImuSample
from flightctl.params import Params

FILTER_S = 0.01          # s: the residuals' low-pass (two EMAs of FILTER_S / 2)
BIAS_S = 0.5             # s: their slow part, followed while no motor is suspected
THRESHOLD = 0.45         # of the suspected motor's commanded thrust, missing in torque and in collective (above
#                          1 - TRIM: a stopping rotor named this early is never flown on four), ...
LOOPS = 5                # ... for this many loops (11 ms) in a row: lost
WEAK = 0.15              # missing at least this share ...
WEAK_LOOPS = 45          # ... for this many loops (100 ms) in a row: named with its share
CALM = 1.0               # rad/s: |p| + |q| low-passed over CALM_S: the count starts only below this
CALM_S = 0.1
TRIM = 0.6               # a motor giving less than this share of its command is not flown on four ...
TRIM_TILT = radians(10)  # ... nor one whose missing thrust the P term leaves this tilt for
JOLT = 0.5 * 9.80665     # m/s^2 of specific force above the commanded thrusts': the floor met (a touchdown) ...
JOLT_S = 0.5             # s: ... after which nothing is looked for this long (a hop, legs settling)
HIGH = 1.6               # a residual beyond this many times the motor's thrust is not one motor's
OPPOSITE = (2, 3, 0, 1)  # motor index -> the index of the motor across the frame


def flown_on_four(params: Params, motor: int, giving: float) -> bool:
    """The rule for a motor (1..4) named with the share it gives (`giving`, 0..1): flown on four
    rotors (the loop lands on them) when it gives at least TRIM and the paper's PID (eq. 24) holds the
    tilt its missing thrust leaves within TRIM_TILT; else the loss mode (control/spin.py). With the
    other side of its axis lowered by u and its own raised by u (eq. 25), the torques balance at
    u = B (1 - S) / (1 + S), which the P term gives at a tilt error u / kp (the I terms of Table 4
    and 6 are negligible over a landing)."""
    g, B = params.gains, params.airframe.B
    kp = g.kp_theta if motor in (1, 3) else g.kp_phi
    if not giving >= TRIM or kp <= 0.0:
        return False
    return B * (1.0 - giving) / ((1.0 + giving) * kp) <= TRIM_TILT


class MotorLossDetector:
    """`update` every loop in flight, before the controller mixes anew; it returns the motor (1..4)
    found missing thrust the loop it is sure, else 0, with `missing` the share it misses (0..1) and
    `fast` whether the fast test named it (its rotor may still be running down: at least that share).
    `accept()`: the loop flies on with that motor (a weak one): its missing thrust becomes part of
    the residuals' slow part."""
    __slots__ = ("km", "kf", "kb", "kc", "fl", "sx", "sy", "sz", "rx", "ry", "rz", "bx", "by", "bz", "calm", "count",
                 "strong", "missing", "fast", "seen", "damp", "hold", "floor", "jolt_loops", "p", "q", "half", "quiet", "ic1",
                 "c1", "w", "Jxx", "Jyy", "Jp", "jx",
                 "jy", "l", "iM", "M", "il")

    def __init__(self, params: Params, tau_motor: float | None = None):
        a = params.airframe
        dt = a.dt
        tau = motor_time_constant(params) if tau_motor is None else tau_motor
        self.km = dt / (tau + dt)
        self.kf, self.kb, self.kc = dt / (0.5 * FILTER_S + dt), dt / (BIAS_S + dt), dt / (CALM_S + dt)
        self.half = 0.5 * a.B              # a commanded thrust counts as at least this (near-idle rotors)
        # a collective drop (N) at most this cannot be WEAK of any motor's thrust (each counts as
        # at least `half`): no motor is suspected, and the loop need not look at each (most loops)
        self.quiet = WEAK * self.half
        # the airframe's constants of eq. 7, 9 and 27, bound once (the loop reads them every period)
        self.c1, self.ic1, self.Jxx, self.Jyy, self.Jp = a.c1, 1.0 / a.c1, a.Jxx, a.Jyy, a.Jp
        self.jx, self.jy = a.Jzz - a.Jyy, a.Jxx - a.Jzz
        # the roll and pitch damping of the rotors' airflow the file carries (rotor_inflow: 2 k l^2 of the
        # thrust changes and the hub moment, for four rotors at hover): torque the rotors gave, too
        self.damp = 2.0 * params.effect_value("rotor_inflow", "k") * a.l * a.l + params.effect_value("rotor_inflow", "hub")
        self.l, self.il, self.M, self.iM = a.l, 1.0 / a.l, a.M, 1.0 / a.M
        self.fl = [0.0, 0.0, 0.0, 0.0]
        self.w = [0.0, 0.0, 0.0, 0.0]
        self.count = [0, 0, 0, 0]
        self.strong = [0, 0, 0, 0]
        self.missing, self.fast = 0.0, False
        self.seen = 0.0          # the largest missing share any motor showed this loop in calm flight
        self.jolt_loops = int(JOLT_S / dt + 0.5)
        self.reset(a.B)

    def reset(self, f0: float) -> None:
        """At take-off: the rotors at f0 each, nothing suspected."""
        for i in range(4):
            self.fl[i] = f0
            self.w[i] = sqrt(f0 * self.ic1)
            self.count[i] = self.strong[i] = 0
        self.rx = self.ry = self.rz = self.bx = self.by = self.bz = self.sx = self.sy = self.sz = 0.0
        self.calm = 0.0
        self.hold = 0
        self.floor = True        # on the floor at arming, until the sonar sees it leave (`lifted`)
        self.p = self.q = None

    def lifted(self) -> None:
        """A valid sonar altitude above the floor's: the floor no longer carries the vehicle."""
        self.floor = False

    def update(self, s: ImuSample, f: list[float], dt: float, low: bool = False) -> int:
        """`low`: the loop's altitude is the floor's (flightctl/loop.py TOUCHDOWN_ALT)."""
        # the rotors' speeds now (eq. 27), from the thrusts commanded one loop earlier through the motor
        # time constant (the speed lags, as the plant's motor_dynamics has it), and their thrusts
        w, km, ic1, c1 = self.w, self.km, self.ic1, self.c1
        w0 = w[0] = w[0] + km * (sqrt(f[0] * ic1) - w[0])
        w1 = w[1] = w[1] + km * (sqrt(f[1] * ic1) - w[1])
        w2 = w[2] = w[2] + km * (sqrt(f[2] * ic1) - w[2])
        w3 = w[3] = w[3] + km * (sqrt(f[3] * ic1) - w[3])
        fl = self.fl
        f0 = fl[0] = c1 * w0 * w0
        f1 = fl[1] = c1 * w1 * w1
        f2 = fl[2] = c1 * w2 * w2
        f3 = fl[3] = c1 * w3 * w3
        p, q, r = s.gx, s.gy, s.gz
        if self.p is None:
            self.p, self.q = p, q
            return 0
        l = self.l
        Om = -w0 + w1 - w2 + w3                      # eq. 9
        JpOm = self.Jp * Om
        # eq. 7 turned around: the torque the body felt, less the one the commanded thrusts give
        d = self.damp
        tx = self.Jxx * (p - self.p) / dt + q * r * self.jx + q * JpOm + d * p - l * (f1 - f3)
        ty = self.Jyy * (q - self.q) / dt + p * r * self.jy - p * JpOm + d * q - l * (f2 - f0)
        tz = s.az - (f0 + f1 + f2 + f3) * self.iM
        self.p, self.q = p, q
        kf = self.kf                               # two EMAs of FILTER_S / 2: a critically damped low-pass
        sx = self.sx = self.sx + kf * (tx - self.sx)
        sy = self.sy = self.sy + kf * (ty - self.sy)
        sz = self.sz = self.sz + kf * (tz - self.sz)
        rx = self.rx = self.rx + kf * (sx - self.rx)
        ry = self.ry = self.ry + kf * (sy - self.ry)
        rz = self.rz = self.rz + kf * (sz - self.rz)
        self.calm += self.kc * ((p if p > 0 else -p) + (q if q > 0 else -q) - self.calm)
        count, strong = self.count, self.strong
        fall = (self.bz - rz) * self.M             # the collective thrust missing (N)
        if rz > JOLT:                              # the floor pushing up: a touchdown (low-passed: not the
            #                                      rotors' vibration on the accelerometer)
            self.hold = self.jolt_loops
            self.floor = True
        elif self.hold > 0:
            self.hold -= 1
        if self.hold or self.floor or low or fall <= self.quiet:   # the floor may carry weight and torque
            count[0] = count[1] = count[2] = count[3] = strong[0] = strong[1] = strong[2] = strong[3] = 0
            self.seen = 0.0
        else:
            ex, ey = rx - self.bx, ry - self.by
            lost, half, calm, seen = 0, self.half, self.calm < CALM, 0.0
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
                if calm and share > seen:
                    seen = share
                if WEAK < share < HIGH and (calm or count[i] > 0):
                    count[i] += 1
                    strong[i] = strong[i] + 1 if share > THRESHOLD and calm else 0
                    if strong[i] >= LOOPS or count[i] >= WEAK_LOOPS:
                        lost, self.missing, self.fast = i + 1, share, strong[i] >= LOOPS
                else:
                    count[i] = strong[i] = 0
            self.seen = seen
            if lost:
                return lost
            if count[0] or count[1] or count[2] or count[3]:
                return 0
        kb = self.kb                               # nothing suspected: the residuals' slow part
        self.bx += kb * (rx - self.bx)
        self.by += kb * (ry - self.by)
        self.bz += kb * (rz - self.bz)
        return 0

    def accept(self) -> None:
        """Fly on with the motor just named (weak, trimmed): what it misses is the residuals' new slow
        part, and nothing is suspected."""
        self.bx, self.by, self.bz = self.rx, self.ry, self.rz
        for i in range(4):
            self.count[i] = self.strong[i] = 0
