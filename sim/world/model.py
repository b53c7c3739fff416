"""The paper's identified dynamic model: 6-DOF rigid body (eq. 7, vector form), yaw drag (eq. 6),
rotor gyroscopic term (eq. 9) and propellers (eq. 26-28), with a seam for the candidate extensions.

One signature for the base model and every extension: `Model.f(t, x, u) -> xdot`, i.e.
`f(t, x, u, params)` with the parameters bound in the `Model`. The state is

    x = [x, y, z, vx, vy, vz, phi, theta, psi, p, q, r] + states of the extensions

(position and velocity inertial, x North, y West, z Up; Z-Y-X Euler angles; body rates), and the
input is `u = (P1, P2, P3, P4, battery_v)`: the command values of eq. 26 and the battery voltage.
`Model.f` is scalar code (the simulator's inner loop); the functions before it take numpy arrays
too, so that fits evaluate the same equations on many samples at once (the batched simulator flies
many vehicles through the compiled copy, sim/world/compiled.py). The propeller and yaw-drag
equations (eq. 6, 26-28) live in `flightctl.physics`, shared with the onboard mixer and the fits.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from math import cos, sin

from flightctl.params import Airframe
from flightctl.physics import rotor_speed, rotor_torque, thrust_from_command, yaw_drag

N_RIGID = 12
_ZERO = (0.0, 0.0, 0.0)
X, Y, Z, VX, VY, VZ, PHI, THETA, PSI, P, Q, R = range(N_RIGID)


def _trig(v):
    return np if isinstance(v, np.ndarray) else math


def remainder(x: float, y: float) -> float:
    """Python's x % y for y > 0, to the bit, without fmod's division where x is within y of [0, y):
    fmod(x, y) is then x (or x - y, exact by Sterbenz's lemma) and CPython's sign rule adds y to a
    negative one (`float_rem`); anything else goes to %. For the compiled loops (an angle's wrap,
    a rotor's phase), where a call of fmod costs more than the rest of the wrap."""
    if 0.0 < x < y:
        return x
    if y <= x < y + y:
        return x - y
    if -y < x < 0.0:
        return x + y
    return x % y


def body_torques(f1, f2, f3, f4, t1, t2, t3, t4, l: float):
    """Roll, pitch and yaw torques of the "+" configuration (conventions.md, eq. 25 layout)."""
    return l * (f2 - f4), l * (f3 - f1), t1 - t2 + t3 - t4


def angular_acceleration(p, q, r, tau_phi, tau_theta, tau_psi, Omega, tau_d, Jxx, Jyy, Jzz, Jp):
    """Eq. 7 (vector form): J dw/dt = tau - w x (J w + Jp Omega z_b) - tau_d z_b.

    Eq. 8 as printed has the q row wrong (sign and Jxx for Jyy); this is the correct expansion."""
    hz = Jzz * r + Jp * Omega
    dp = (tau_phi - (q * hz - r * Jyy * q)) / Jxx
    dq = (tau_theta - (r * Jxx * p - p * hz)) / Jyy
    dr = (tau_psi - (p * Jyy * q - q * Jxx * p) - tau_d) / Jzz
    return dp, dq, dr


def rigid_derivative(vx, vy, vz, sf, cf, st, ct, sp, cp, p, q, r, fx, fy, fz, tau_phi, tau_theta, tau_psi, Omega,
                     Jxx, Jyy, Jzz, Jp, iM, g, gamma1, gamma2):
    """The rigid body's twelve derivatives (the state's order, `Model`): M dv/dt = R (F_ext + sum f z_b)
    - M g z, eq. 7 with eq. 6's yaw drag, and the Z-Y-X Euler-angle kinematics, from the velocity, the
    attitude's sines and cosines (phi, theta, psi), the body rates, and the rotors' body force, torques
    and Omega (eq. 9). Plain arithmetic on floats or arrays (sim/world/compiled.py compiles it)."""
    # R = Rz(psi) Ry(theta) Rx(phi) applied to the body force (fx, fy, fz)
    up = sf * fy + cf * fz
    bx = ct * fx + st * up
    by = cf * fy - sf * fz
    dphi, dtheta, dpsi = euler_rates(sf, cf, st, ct, p, q, r)
    tau_d = yaw_drag(r, gamma1, gamma2)  # eq. 6
    dp, dq, dr = angular_acceleration(p, q, r, tau_phi, tau_theta, tau_psi, Omega, tau_d, Jxx, Jyy, Jzz, Jp)
    return (vx, vy, vz,
            (cp * bx - sp * by) * iM, (sp * bx + cp * by) * iM, (-st * fx + ct * up) * iM - g,
            dphi, dtheta, dpsi, dp, dq, dr)


def euler_rates(sf, cf, st, ct, p, q, r):
    """The Z-Y-X Euler angles' rates (phi, theta, psi) of the body rates p, q, r, from the sines and
    cosines of phi and theta."""
    w = q * sf + r * cf
    return p + w * st / ct, q * cf - r * sf, w / ct


def rotation(phi, theta, psi):
    """R = Rz(psi) Ry(theta) Rx(phi), body to inertial, as nine entries row by row."""
    m = _trig(phi)
    return rotation_from_trig(m.sin(phi), m.cos(phi), m.sin(theta), m.cos(theta), m.sin(psi), m.cos(psi))


def rotation_from_trig(sf, cf, st, ct, sp, cp):
    """`rotation` from the sines and cosines of phi, theta and psi (for a caller that has them)."""
    return (cp * ct, cp * st * sf - sp * cf, cp * st * cf + sp * sf,
            sp * ct, sp * st * sf + cp * cf, sp * st * cf - cp * sf,
            -st, ct * sf, ct * cf)


def body_velocity(Rm, vx, vy, vz):
    """R^T v: the inertial velocity in the body frame, R = `rotation` as nine entries."""
    return (Rm[0] * vx + Rm[3] * vy + Rm[6] * vz, Rm[1] * vx + Rm[4] * vy + Rm[7] * vz,
            Rm[2] * vx + Rm[5] * vy + Rm[8] * vz)


def aggregate(f1, f2, f3, f4, t1, t2, t3, t4, w1, w2, w3, w4, Fx, Fy, Fz, Tx, Ty, Tz, l):
    """What the rigid body needs from the rotors: the body force (fx, fy, fz), the roll, pitch and yaw
    torques ("+" layout, eq. 25, with the effects' extra force F and torque T) and eq. 9's Omega
    = -w1 + w2 - w3 + w4 (motors 1 and 3 turn clockwise)."""
    return (Fx, Fy, Fz + f1 + f2 + f3 + f4, l * (f2 - f4) + Tx, l * (f3 - f1) + Ty, t1 - t2 + t3 - t4 + Tz,
            -w1 + w2 - w3 + w4)


class Parameter(NamedTuple):
    """One parameter of an effect: its SI unit and the range `flightctl.sim.causes.make` accepts."""
    unit: str
    lo: float
    hi: float


class Effect:
    """A candidate extension (docs/measured-data.md): the plant side of one cause of
    `flightctl.sim.causes`, whose module also holds its diagnose fit. A subclass declares

    - `cause`: its name in docs/measured-data.md; `required`: {parameter name: Parameter(unit, lo, hi)}
      (what diagnose fits and reports); `optional`: the same for parameters a parameter file may add
      (the effect's own default when absent); `range_scales`: a parameter whose plausible range
      ends where an airframe value's does (a time constant proportional to an inertia);
    - the hooks it uses (`uses_rotor`, `uses_scale`, `uses_wrench`, or `delay`) and overrides them;
      the base does nothing at every hook.

    The hooks, in the order the model calls them within one evaluation of the forces (so an effect
    may carry a value from its `rotor` to its `wrench`):

    - `delay`: the commands reach the motors this much later (applied by the plant to `u`);
    - `command(f_cmd)`: a rotor effect sees each new input's commanded thrusts (eq. 26) once, before
      the `rotor` calls that take them, and keeps what depends on the input only;
    - `rotor(t, x, f_cmd, xdot)`: its own states (`n_states`, placed at `offset`) turn the
      commanded thrusts into rotor thrusts, writing their derivatives into `xdot` (None when only
      the forces are wanted); the rotor speed of eq. 9 follows the returned thrusts (eq. 27);
    - `scale(t, x, u, s)`: multiplies each rotor's thrust and torque (list `s` of four);
    - `wrench(t, x, f, vb, force, torque)`: adds a body-frame force and torque (lists of three),
      given the thrusts `f` and the body-frame velocity `vb`.

    A sensor effect (`uses_gyro`) changes what the IMU reports, not the plant: the simulated chip
    (`SimMpu9250`) passes each read's body rates through `gyro(dt, p, q, r) -> (p, q, r)` (dt after
    the last read), after its own noise and filter, so that the driver, the controller and the log
    all see it; the model never calls it.

    The model calls `attach(airframe, offset)` once before use: `self.a` is then the airframe.
    """
    cause = "none"
    required: dict[str, Parameter] = {}
    optional: dict[str, Parameter] = {}
    # parameter -> airframe value whose draw moves the top of its range in proportion (the Monte
    # Carlo, sim/sweeps/montecarlo.py: `draw`); the file's range top belongs to the top of that value's range
    range_scales: dict[str, str] = {}
    n_states = 0
    offset = 0
    delay = 0.0
    uses_rotor = uses_scale = uses_wrench = uses_gyro = False
    state_dependent = False   # its `scale` reads the state (the model then cannot cache the forces)
    # the compiled plant (sim/world/compiled.py): `compiled`, it carries this effect; `compiled_hook`, the
    # name of its wrench hook there (None: none, a scale or a delay read elsewhere); `compiled_q()`, its
    # entries of the compiled parameters q by name (None: this instance cannot be compiled)
    compiled = False
    compiled_hook: str | None = None
    a: Airframe | None = None

    def __init__(self, **parameters: float):
        self.parameters = dict(parameters)

    def compiled_q(self) -> dict[str, float] | None:
        return {}

    def attach(self, airframe: Airframe, offset: int) -> None:
        self.a, self.offset = airframe, offset

    def initial_states(self, f_cmd: list[float]) -> list[float]:
        return []

    def gyro(self, dt: float, p: float, q: float, r: float) -> tuple[float, float, float]:
        return p, q, r

    def command(self, f_cmd: list[float]) -> None:
        """A rotor effect's view of each new input, before the `rotor` calls that take these
        commanded thrusts: what depends on the input only is computed here, once per input."""

    def __repr__(self):
        args = ",".join(f"{k}={v:g}" for k, v in self.parameters.items())
        return f"{self.cause}:{args}" if args else self.cause


class Forces(NamedTuple):
    """The rotors at one state and input: thrusts `f` (N), reaction torques `tau` (N m, eq. 28), the
    effects' extra body-frame `force` (N) and `torque` (N m), and the speeds `w` (rad/s, eq. 27)."""
    f: list
    tau: list
    force: tuple
    torque: tuple
    w: list


class Model:
    """The base model with extensions bound: `f(t, x, u)` is the one model signature."""

    def __init__(self, airframe: Airframe, effects: tuple[Effect, ...] = (), bearing: bool = False):
        self.a = airframe
        self.effects = tuple(effects)
        n = N_RIGID
        for e in self.effects:
            e.attach(airframe, n)
            n += e.n_states
        self.n = n
        self.delay = sum(e.delay for e in self.effects)
        self._rotor = [e for e in self.effects if e.uses_rotor]
        self._scale = [e for e in self.effects if e.uses_scale]
        self._wrench = [e for e in self.effects if e.uses_wrench]
        # without rotor states, state-dependent scales or wrenches, the forces depend on the input
        # only, which is constant across an integration step: compute them once per input
        self._cacheable = not (self._rotor or self._wrench or any(e.state_dependent for e in self._scale))
        self._cached_u = None     # the input of `_cached`: (its forces, their aggregate), when cacheable
        self._cached = None
        self._command_u = None   # the input of `_f_cmd`, the commanded thrusts (eq. 26)
        self._f_cmd = None
        # gamma2 is the friction of the yaw-drag test bearing: zero in free flight (eq. 6).
        self.gamma2 = airframe.gamma2 if bearing else 0.0
        self._iM = 1.0 / airframe.M
        self._constants = self.rigid_constants

    def initial_state(self, u) -> list[float]:
        x = [0.0] * N_RIGID
        f_cmd = self._commanded(u)
        for e in self.effects:
            x += e.initial_states(f_cmd)
        return x

    def _commanded(self, u) -> list[float]:
        """The commanded thrusts of eq. 26, computed once per input (by value: a list changed in
        place is a new input); the rotor effects see each new input first in their `command` hook."""
        key = tuple(u)
        if key != self._command_u:
            a = self.a
            h1, h2 = a.h1, a.h2
            self._command_u = key
            self._f_cmd = [thrust_from_command(u[0], h1, h2), thrust_from_command(u[1], h1, h2),
                           thrust_from_command(u[2], h1, h2), thrust_from_command(u[3], h1, h2)]
            for e in self._rotor:
                e.command(self._f_cmd)
        return self._f_cmd

    def _per_input(self, t, x, u):
        """(forces, aggregate) of a cacheable model, whose forces depend on the input only: computed
        once per input (by value: a list changed in place must not return stale forces)."""
        key = tuple(u)
        if key != self._cached_u:
            rotors = self._forces(t, x, u)
            self._cached_u, self._cached = key, (rotors, self._aggregate(rotors))
        return self._cached

    def forces(self, t, x, u, xdot=None, Rm=None) -> Forces:
        """The rotors (eq. 26-28 and the extensions) and the extra body wrench. `Rm`: the rotation
        of x's attitude when the caller has it (`rotation_from_trig`), for the body velocity."""
        if self._cacheable:
            return self._per_input(t, x, u)[0]
        return self._forces(t, x, u, xdot, Rm)

    def _forces(self, t, x, u, xdot=None, Rm=None) -> Forces:
        a = self.a
        f = self._commanded(u)
        for e in self._rotor:
            f = e.rotor(t, x, f, xdot)
        g1, g2 = a.g1, a.g2
        tau = [rotor_torque(f[0], g1, g2), rotor_torque(f[1], g1, g2),   # eq. 28
               rotor_torque(f[2], g1, g2), rotor_torque(f[3], g1, g2)]
        if self._scale:
            s = [1.0, 1.0, 1.0, 1.0]
            for e in self._scale:
                e.scale(t, x, u, s)
            f = [f[i] * s[i] for i in range(4)]
            tau = [tau[i] * s[i] for i in range(4)]
        c1 = a.c1
        w = [rotor_speed(f[0], c1), rotor_speed(f[1], c1), rotor_speed(f[2], c1), rotor_speed(f[3], c1)]
        if not self._wrench:
            return Forces(f, tau, _ZERO, _ZERO, w)
        force, torque = [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]
        if Rm is None:
            Rm = rotation(x[PHI], x[THETA], x[PSI])
        vb = body_velocity(Rm, x[VX], x[VY], x[VZ])
        for e in self._wrench:
            e.wrench(t, x, f, vb, force, torque)
        return Forces(f, tau, force, torque, w)

    def _aggregate(self, rotors: Forces):
        """`aggregate` of the rotors' forces."""
        (f1, f2, f3, f4), (t1, t2, t3, t4), (Fx, Fy, Fz), (Tx, Ty, Tz), (w1, w2, w3, w4) = rotors
        return aggregate(f1, f2, f3, f4, t1, t2, t3, t4, w1, w2, w3, w4, Fx, Fy, Fz, Tx, Ty, Tz, self.a.l)

    @property
    def rigid_constants(self) -> tuple[float, ...]:
        """The airframe's constants of `rigid_derivative`, in its order after Omega."""
        a = self.a
        return (a.Jxx, a.Jyy, a.Jzz, a.Jp, self._iM, a.g, a.gamma1, self.gamma2)

    def f(self, t, x, u):
        """xdot = f(t, x, u): `rigid_derivative` with the rotors' and the effects' forces. Scalar code
        (fast); the functions above it take arrays too, for fitting and for the batched simulator."""
        xdot = [0.0] * self.n   # the rotor effects write their own states' derivatives (beyond N_RIGID)
        phi, theta, psi = x[6], x[7], x[8]
        sf, cf, st, ct, sp, cp = sin(phi), cos(phi), sin(theta), cos(theta), sin(psi), cos(psi)
        if self._cacheable:
            fx, fy, fz, tau_phi, tau_theta, tau_psi, Omega = self._per_input(t, x, u)[1]
        else:
            Rm = rotation_from_trig(sf, cf, st, ct, sp, cp) if self._wrench else None
            fx, fy, fz, tau_phi, tau_theta, tau_psi, Omega = self._aggregate(self._forces(t, x, u, xdot, Rm))
        xdot[:N_RIGID] = rigid_derivative(x[3], x[4], x[5], sf, cf, st, ct, sp, cp, x[9], x[10], x[11],
                                          fx, fy, fz, tau_phi, tau_theta, tau_psi, Omega, *self._constants)
        return xdot

    def specific_force(self, t, x, u, forces: Forces | None = None):
        """What an accelerometer at the centre of mass reads, body frame: (sum f z_b + F_ext) / M.
        `forces`: `forces(t, x, u)` when the caller has them already."""
        f, _, force, _, _ = self.forces(t, x, u) if forces is None else forces
        M = self.a.M
        return force[0] / M, force[1] / M, (force[2] + f[0] + f[1] + f[2] + f[3]) / M
