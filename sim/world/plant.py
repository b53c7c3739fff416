"""The simulated quadcopter: the model integrated with fixed-step RK4, a floor, and a delayed input.

The controller holds its commands for one loop period (zero-order hold), so the plant integrates
each period in `substeps` RK4 steps (SUBSTEPS by default) with the input constant across a step. An
actuation delay d holds the command of d earlier: it changes once per period, d mod dt into it. The
plant applies, over the period, the two commands' average weighted by the time each holds
(`delayed`): the same impulse, correct to second order in dt at any d
(exact for a whole number of periods), at the cost of one RK4 step where splitting the period
would take two. Time is counted
in integers, loop periods, and computed from them (`t = n dt` plus the offset within one), never
summed: after n periods it is `n dt` whatever the substep count, so that the loop sees the same clock
at 1 and at 20 substeps. A loop tick that comes late (sim/world/lateness.py) splits its period in two
(`advance_part`, then `advance`), each command acting from the moment it was issued (`issue_times`). The floor: the
vehicle rests on z = 0 until its thrust lifts it, and
a touchdown stops it (level, at rest), recording the touchdown speed; a yaw spin it lands with (a
two-rotor landing's 25 rad/s, flightctl/control/spin.py) is braked by its feet's friction on the
floor (`floor_spin`), not stopped at once. The floor's stopping force is
in the accelerometer's truth: the speed lost, spread evenly over CONTACT_S after the contact (a stiff
landing gear; what matters is its integral, the speed lost, which an integrating estimator needs;
the chip clips the peak at its full scale as a real one does).
"""
from __future__ import annotations

from collections import deque

import numpy as np

CONTACT_S = 0.02   # s: the landing gear's stopping time at a touchdown
# the landing feet's dry friction on the floor (plastic or rubber feet on a hard floor: 0.3-0.8, engineering
# tables of friction coefficients; the middle), at the arm's length l from the centre (legs under the motors)
FEET_MU = 0.5
# RK4 steps per loop period (per segment): one. The fastest poles of the models, 1/tau = 50 1/s for
# 20 ms motors and the bank loops' 10-30 rad/s, are 0.11 and under 0.07 of dt = 2.2 ms, where RK4's
# error is (lambda h)^5 / 120, under 1e-7 per step (tests/sim/world/test_model.py: 1 against 20 substeps).
SUBSTEPS = 1


class Diverged(Exception):
    """The plant's state is no longer finite at plant time `t`: the simulated vehicle (or its
    integration) blew up."""

    def __init__(self, t: float):
        super().__init__(f"the plant's state is not finite at t = {t:.3f} s")
        self.t = t

from flightctl.sim.world import compiled
from flightctl.sim.world.model import N_RIGID, PHI, PSI, Q, R, THETA, VX, VY, VZ, X, Y, Z, Forces, Model, P


def floor_brake(weight: float, l: float, Jzz: float) -> float:
    """rad/s^2: the yaw deceleration of a vehicle of this weight (N) spinning on its feet, Coulomb
    friction FEET_MU weight at the arm l over the yaw inertia Jzz (eq. 7's yaw row)."""
    return FEET_MU * weight * l / Jzz


def floor_spin(r: float, dt: float, brake: float) -> tuple[float, float]:
    """(the yaw rate, the yaw angle turned) dt after a spin r on the floor, decelerated at `brake`
    rad/s^2 to rest (the angle exact: the mean rate while it turns)."""
    dr = brake * dt
    if r > dr:
        return r - dr, (r - 0.5 * dr) * dt
    if r < -dr:
        return r + dr, (r + 0.5 * dr) * dt
    return 0.0, 0.5 * r * abs(r) / brake if brake > 0.0 else 0.0


def time_weighted(before: float, now: float, frac: float) -> float:
    """One command over a period whose first `frac` holds `before` and the rest `now`: their average
    weighted by time (the batched simulator's compiled loop, sim/sweeps/twin_loop.py, takes it too)."""
    return before * frac + now * (1.0 - frac)


def delayed(before, now, frac: float):
    """The input over a period whose first `frac` holds the command `before` and the rest `now`,
    each entry `time_weighted`."""
    return tuple(time_weighted(b, c, frac) for b, c in zip(before, now))


class Plant:
    def __init__(self, model: Model, dt: float, substeps: int = SUBSTEPS, battery_v: float = 16.0):
        self.model = model
        self.dt = dt
        self.substeps = substeps
        self.periods = 0                                  # loop periods integrated so far
        self.t = 0.0                                      # periods * dt (+ substeps * h within one)
        self.u = (0.0, 0.0, 0.0, 0.0, battery_v)
        self._next = self.u                               # the last command, applied from now on
        self.x = model.initial_state(self.u)
        self.on_ground = True
        self.touchdowns: list[tuple[float, float]] = []  # (time, vertical speed at contact)
        self._stop = (-1.0, 0.0)                          # (time, vertical speed) of the last contact
        periods = model.delay / dt                        # the delay in loop periods: whole and fraction
        self._whole = int(periods + 1e-9)
        self._frac = periods - self._whole if periods - self._whole > 1e-9 else 0.0
        # the commands of the last whole + 2 periods: [0] is the one before the delayed, [1] the delayed
        self._queue: deque = deque([self.u] * (self._whole + 2), maxlen=self._whole + 2)
        self._forces_at = None                            # (t, x, u) of `_forces`
        self._forces: Forces | None = None
        # a model with the effects sim/world/compiled.py carries (the base model's and the as-flown file's)
        # integrates compiled where numba is installed (`compiled.period`: the same functions and scheme
        # as `_rk4`, and the forces at the new state in the same call); the others in plain Python
        laid_out = compiled.layout(model)
        self._period = compiled.model_period() if laid_out is not None else None
        self._fast_forces = compiled.model_forces() if laid_out is not None else None
        self._codes, self._q = laid_out if laid_out is not None else (None, None)
        self._out = np.empty(compiled.N_OUT)
        self._into = 0.0                                  # the fraction of this period integrated (`advance_part`)
        self._issued: deque | None = None                 # the commands at their issue times (`issue_times`)

    def command(self, P1: float, P2: float, P3: float, P4: float, battery_v: float) -> None:
        """The input from now on (after the actuation delay, if any)."""
        self._next = u = (P1, P2, P3, P4, battery_v)
        issued = self._issued
        if issued is not None:
            if issued[-1][0] == self.periods and issued[-1][1] == self._frac + self._into:
                issued.pop()                              # issued again at the same moment: the last counts
            issued.append((self.periods, self._frac + self._into, u))

    @property
    def into(self) -> float:
        """How far into this loop period the plant is (0 but after `advance_part`)."""
        return self._into

    def advance(self, dt: float) -> None:
        """Integrate to the end of this loop period (the `dt` of the plant) with the last command held."""
        if self._issued is not None:                      # commands at their issue times (`issue_times`)
            self._integrate(self._into, 1.0, self._held(self._into, 1.0))
            return
        if self.model.delay:
            q = self._queue
            q.append(self._next)
            u = delayed(q[0], q[1], self._frac) if self._frac else q[1]
        else:
            u = self._next
        self._integrate(0.0, 1.0, u)

    def advance_part(self, frac: float) -> None:
        """Integrate to `frac` (0..1) of this loop period with the commands held: a loop tick that comes
        late (sim/world/lateness.py) reads its sensors there and issues its command there. Only after
        `issue_times`."""
        self._integrate(self._into, frac, self._held(self._into, frac))

    def issue_times(self) -> None:
        """From now on each command acts from the moment it is issued (plus the actuation delay) rather
        than from its period's start: a late tick's command then acts late (`advance_part`). With every
        command issued on its period's start the flight is the same, bit for bit (the inputs are the
        same sums: tests/sim/world/test_lateness.py)."""
        # (issue period, the delay's fraction plus the issue's within its period, the command): the
        # queue's commands, issued one a period before this one, and the last command, issued now
        p, q = self.periods, self._queue
        self._issued = deque([(p - len(q) + i, self._frac, c) for i, c in enumerate(q)] + [(p, self._frac, self._next)])

    def _held(self, a: float, b: float):
        """The input over [a, b] of this period (fractions of it): each command issued at `issue +
        into` acts from `issue + into + delay` until the next one does, and the input is their average
        weighted by the time each holds (`delayed`'s rule; the same sums where every `into` is 0)."""
        issued, p, whole = self._issued, self.periods, self._whole
        while len(issued) > 1 and (issued[1][0] - p + whole) + issued[1][1] <= a:
            issued.popleft()                              # a later one acts from before a
        span = b - a
        u = None
        for k, (n, lag, cmd) in enumerate(issued):
            start = (n - p + whole) + lag
            if start >= b:
                break
            end = (issued[k + 1][0] - p + whole) + issued[k + 1][1] if k + 1 < len(issued) else b
            w = (end if end < b else b) - (start if start > a else a)
            if w <= 0.0:
                continue
            share = w / span if span != 1.0 else w
            u = [c * share for c in cmd] if u is None else [s + c * share for s, c in zip(u, cmd)]
        return tuple(u)

    def _integrate(self, a: float, b: float, u) -> None:
        """The plant from `a` to `b` (fractions of this loop period) under input `u`, in `substeps`
        RK4 steps; at b = 1 the period is done and the time is its count times dt."""
        t0 = self.periods * self.dt
        self.u = u
        n = self.substeps
        h = (b - a) * self.dt / n
        ta = a * self.dt
        fresh = False                                     # `_out` holds the forces at the state now
        for j in range(1, n + 1):
            x, t = self.x, self.t
            t_end = t0 + (ta + j * h)
            ground = self.on_ground and not self._lifts(x, u)
            if ground and len(x) == N_RIGID:              # nothing moves
                self.t = t_end
                fresh = False
                continue
            try:
                self.x = self._step(x, t, u, h, ground)   # on the floor, the extensions' states (motor lag)
            except (ValueError, OverflowError):          # math on an infinite angle
                raise Diverged(t) from None
            if not ground:
                self.on_ground = False
                s = sum(self.x)
                if s - s != 0.0:                          # a NaN or an infinity anywhere in the state
                    raise Diverged(t_end)
            self.t = t_end
            if not ground and self.x[Z] < 0.0:
                self._touch_down()
            fresh = ground or not self.on_ground          # (a touchdown changes the state in place)
        if self.on_ground and self.x[R] != 0.0:           # a spin it landed with, braked by its feet
            a_ = self.model.a
            self.x[R], turned = floor_spin(self.x[R], (b - a) * self.dt, floor_brake(a_.M * a_.g, a_.l, a_.Jzz))
            self.x[PSI] += turned
            fresh = False
        if b == 1.0:
            self.periods += 1
            self._into = 0.0
            self.t = self.periods * self.dt
        else:
            self._into = b
            self.t = t0 + b * self.dt
        if fresh and self._period is not None:            # the compiled step's forces prime `forces()`
            o = self._out.tolist()
            self._forces_at = (self.t, tuple(self.x), tuple(u))
            self._forces = Forces(o[0:4], o[4:8], o[8:11], o[11:14], o[14:18])

    def _step(self, x, t, u, h, ground: bool) -> list[float]:
        """x after one RK4 step of h (on the floor, `ground`, the rigid body's states kept): compiled
        (`compiled.period`, which leaves the forces at the new state in `_out`) or plain (`_rk4`)."""
        if self._period is None:
            y = self._rk4(x, t, u, h)
            return x[:N_RIGID] + y[N_RIGID:] if ground else y
        xa = np.array(x)
        self._period(xa, u[0], u[1], u[2], u[3], self._codes, self._q, h, ground, self._out)
        return xa.tolist()

    def _rk4(self, x, t, u, h):
        f, hh = self.model.f, 0.5 * h
        k1 = f(t, x, u)
        k2 = f(t + hh, [a + hh * b for a, b in zip(x, k1)], u)
        k3 = f(t + hh, [a + hh * b for a, b in zip(x, k2)], u)
        k4 = f(t + h, [a + h * b for a, b in zip(x, k3)], u)
        h6 = h / 6.0
        return [a + h6 * (b + 2.0 * (c + d) + e) for a, b, c, d, e in zip(x, k1, k2, k3, k4)]

    def _lifts(self, x, u) -> bool:
        """On the floor the vehicle stays put until the vertical thrust exceeds its weight."""
        _, _, fz = self.model.specific_force(self.t, x, u, self.forces())
        return fz > self.model.a.g

    def forces(self) -> Forces:
        """The rotors now (`Model.forces` at the plant's time, state and input), computed once for
        each: the floor, the battery and the IMU (specific force, vibration) all ask at one state.
        Compared by value, so that a state or input changed in place is seen."""
        key = (self.t, tuple(self.x), tuple(self.u))
        if key != self._forces_at:
            if self._fast_forces is None:
                self._forces_at, self._forces = key, self.model.forces(self.t, self.x, self.u)
            else:
                u = self.u
                f, tau, force, torque, w = self._fast_forces(np.array(self.x), u[0], u[1], u[2], u[3],
                                                             self._codes, self._q)
                self._forces_at, self._forces = key, Forces(f.tolist(), tau.tolist(), force, torque, w.tolist())
        return self._forces

    def _touch_down(self) -> None:
        x = self.x
        if x[VZ] < -0.01:   # not the hop of a thrust that only just equals the weight
            self.touchdowns.append((self.t, x[VZ]))
        self._stop = (self.t, x[VZ])
        for i in (Z, VX, VY, VZ, PHI, THETA, P, Q):    # the yaw spin goes on, braked (`floor_spin`)
            x[i] = 0.0
        self.on_ground = True

    def specific_force(self) -> tuple[float, float, float]:
        """Accelerometer truth: on the floor the reaction of the floor, (0, 0, g), and for CONTACT_S
        after a touchdown the force that stopped it."""
        t_stop, vz = self._stop
        stopping = -vz / CONTACT_S if 0.0 <= self.t - t_stop < CONTACT_S else 0.0   # level at contact
        if self.on_ground:
            return 0.0, 0.0, self.model.a.g + stopping
        fx, fy, fz = self.model.specific_force(self.t, self.x, self.u, self.forces())
        return fx, fy, fz + stopping

    @property
    def position(self):
        return self.x[X], self.x[Y], self.x[Z]

    @property
    def attitude(self):
        return self.x[PHI], self.x[THETA], self.x[PSI]

    @property
    def rates(self):
        return self.x[P], self.x[Q], self.x[R]
