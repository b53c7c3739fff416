"""`motor_dynamics(tau)`: each rotor's speed lags its command, and the body takes the reaction.

**Physics.** A motor does not change its propeller's speed at once: with the ESC's speed loop and
the propeller's inertia the speed Omega_i follows the commanded speed through a first-order lag,
d Omega_i / dt = (Omega_cmd,i - Omega_i) / tau, where the command is the speed at which eq. 27 gives
the thrust of eq. 26: Omega_cmd = sqrt(h1 (P - h2)^2 / c1). Thrust (eq. 27, c1 Omega_i^2) and rotor
torque (eq. 28) follow Omega_i, and so does the rotors' angular momentum Jp Omega of eq. 7 and 9,
Omega = sum s_i Omega_i with s_i = +1 for the counter-clockwise rotors 2 and 4 and -1 for the
clockwise 1 and 3 (conventions.md). What `motor_lag` leaves out is that changing that momentum
takes a torque from the motors, whose reaction acts on the body: the angular momentum balance of
body and rotors, d/dt (J w + Jp Omega z_b) + w x (J w + Jp Omega z_b) = tau, adds

    -Jp sum s_i d Omega_i / dt   about z_b

to eq. 7. Speeding up the counter-clockwise rotors (a yaw command to the negative side, whose drag
reaction -tau_2 - tau_4 turns the body clockwise) turns the body clockwise at once, before their drag
has grown: the reaction leads the drag torque. For the reference airframe a thrust change df of one
rotor in hover changes its speed by df / (2 sqrt(c1 B)) = 65 rad/s per N, so the reaction torque is
Jp 65 = 0.017 N m per N/s of thrust rate against the drag torque's g1 = 0.020 N m per N: above
about 1 rad/s the reaction dominates the yaw torque. Roll, pitch and heave are those of `motor_lag`
(to first order in the speed change), so the yaw channel tells the two apart.
"""
from __future__ import annotations

import numpy as np

from flightctl.physics import rotor_speed, thrust_from_command, thrust_from_speed
from flightctl.sim.causes.motor_lag import MotorLagFit, lag_held
from flightctl.sim.diagnose.candidate import TIMING_CHECK, GridCandidate, timing_not_physical, too_short_to_time
from flightctl.sim.diagnose.dataset import C, Change
from flightctl.sim.world.model import N_RIGID, Effect, Parameter

SPIN = (-1.0, 1.0, -1.0, 1.0)   # s_i: +1 counter-clockwise seen from above (motors 2, 4), -1 clockwise
FULL_P = 255.0                  # `p_full`'s default: eq. 26 to the end of the ESC's frame (no ceiling)


def speed_rate(w_cmd, w, tau, tau_down):
    """d Omega / dt of a rotor at speed w commanded to w_cmd: the lag tau while it speeds up, tau_down
    while it slows down (floats or arrays)."""
    return (w_cmd - w) / (tau_down + (tau - tau_down) * (w_cmd >= w))


def reaction_torque(Jp, spin_up):
    """The body's yaw torque from the rotors' spin-up sum s_i dOmega_i/dt: -Jp sum s_i dOmega_i/dt."""
    return -Jp * spin_up


class MotorDynamics(Effect):
    """Each rotor's speed follows its command through a first-order lag; the body takes its reaction.

    d Omega_i / dt = (Omega_cmd,i - Omega_i) / tau; thrust c1 Omega_i^2 (eq. 27), torque (eq. 28) and
    the momentum of eq. 9 follow Omega_i; the extra yaw torque is -Jp sum s_i d Omega_i / dt.

    `tau_down` (optional, default tau): the time constant while the rotor slows down. An ESC that
    brakes (active freewheeling, "damped light") drives the speed down as it drives it up; one that
    does not lets the rotor coast on its aerodynamic drag alone, J / (2 Q / Omega), several times
    slower (scripts/as_flown.py). Diagnose fits the symmetric lag (`tau` only).

    `p_full` (optional, P units, default 255): the ESC's full throttle. An RC ESC's input runs 1.0-2.0 ms
    and a longer pulse is full throttle, so the commanded speed stops rising there: eq. 26 at p_full is
    the rotor's thrust ceiling (the as-flown file: 2.0 ms of the 449 Hz frame, P = 229; the two-rotor
    mode, flightctl/control/spin.py, commands up to it)."""
    cause, n_states, uses_rotor, uses_wrench = "motor_dynamics", 4, True, True
    required = {"tau": Parameter("s", 1e-4, 5.0)}
    optional = {"tau_down": Parameter("s", 1e-4, 5.0), "p_full": Parameter("P units", 1.0, FULL_P)}
    # the rotor's speed changes at J dOmega/dt = the motor's torque less the drag's: at a given torque
    # both time constants are proportional to the rotor inertia, so their slowest plausible value is
    range_scales = {"tau": "Jp", "tau_down": "Jp"}
    compiled, compiled_hook = True, "reaction"
    _spin_up = 0.0   # sum s_i dOmega_i/dt of the last `rotor` call, for `wrench` (rad/s^2)

    def compiled_q(self):
        if self.offset != N_RIGID:      # the compiled plant keeps the rotors' speeds right after the body's
            return None
        p = self.parameters
        return {"tau": p["tau"], "tau_down": p.get("tau_down", p["tau"]), "p_full": p.get("p_full", FULL_P)}

    def initial_states(self, f_cmd):
        return [rotor_speed(f, self.a.c1) for f in f_cmd]

    def command(self, f_cmd):
        a = self.a
        top = thrust_from_command(self.parameters.get("p_full", FULL_P), a.h1, a.h2)
        # Omega_cmd, once per input (eq. 27), up to the ESC's full throttle (`physics.esc_command`: the same
        # as capping the command, eq. 26 being monotonic above its dead zone)
        self._w_cmd = [rotor_speed(f if f < top else top, a.c1) for f in f_cmd]

    def rotor(self, t, x, f_cmd, xdot):
        o, tau, c1, w_cmd = self.offset, self.parameters["tau"], self.a.c1, self._w_cmd
        down = self.parameters.get("tau_down", tau)
        f = [0.0, 0.0, 0.0, 0.0]
        spin_up = 0.0
        for i in range(4):
            w = x[o + i]
            dw = speed_rate(w_cmd[i], w, tau, down)
            if xdot is not None:
                xdot[o + i] = dw
            spin_up += SPIN[i] * dw
            f[i] = thrust_from_speed(w, c1)          # eq. 27
        self._spin_up = spin_up
        return f

    def wrench(self, t, x, f, vb, force, torque):
        torque[2] += reaction_torque(self.a.Jp, self._spin_up)


class MotorDynamicsFit(GridCandidate):
    """The commanded speeds (eq. 26, 27) through the exact lag of the held command: thrust c1
    Omega^2 from the speed averaged over the period, and -Jp sum s_i dOmega_i/dt / Jzz on r_dot
    from the speed change over the period; the grid of `motor_lag`. For an identified vehicle, whose
    Jp / Jzz is not known, that reaction is a free column of the fit (its coefficient is reported
    in the identification)."""
    effect = MotorDynamics
    changes_thrust = dynamic = needs_yaw = True
    explains = "rotor spin-up sum s_i dOmega_i/dt (rad/s^2)"
    grid = MotorLagFit.grid
    physical_check = TIMING_CHECK
    twin, times_actuation, lookalikes = "motor_lag", True, ("gyro_lag",)
    cached = True     # its change is the base model's thrusts changed: no carried term enters it

    def _speeds(self, i, tau):
        """(the drive (K, 4, n) of the lagged speeds, sum s_i dOmega_i/dt (n,)) of file i."""
        ds, a = self.ds, self.ds.a
        W = rotor_speed(ds.F[i], a.c1)
        if tau <= 0:
            return ds.D[i], np.zeros(W.shape[1])
        at_rows, mean = lag_held(W, tau, ds.fs)
        dW = np.zeros_like(W)
        dW[:, :-1] = np.diff(at_rows, axis=1) * ds.fs
        return ds.drive(thrust_from_speed(mean, a.c1), mean), np.asarray(ds.vehicle.layout.spin) @ dW

    def delta(self, tau):
        ds = self.ds
        preds, reaction = [], []
        for i in range(len(ds.files)):
            D, spin_up = self._speeds(i, tau)
            extra = np.zeros((3, D.shape[-1]))
            extra[2] = -ds.a.Jp * spin_up
            preds.append(ds.predict_file(i, D, torque_extra=extra))
            r = np.zeros((C, D.shape[-1]))
            r[2] = -spin_up
            reaction.append(r)
        ch = ds.delta_filtered(preds)
        if not ds.vehicle.identified:
            return ch
        return Change(ch.delta, np.concatenate([ds.flat_filtered(reaction)[None], ch.free]))

    def fold(self, parameters):
        """The lagged speeds' thrusts into the base; the reaction a carried term (a free column of
        an identified vehicle)."""
        ds, tau = self.ds, parameters["tau"]
        D, reaction = [], []
        for i in range(len(ds.files)):
            Di, spin_up = self._speeds(i, tau)
            r = np.zeros((C, Di.shape[-1]))
            r[2] = -spin_up
            D.append(Di)
            reaction.append(r)
        ds.rebase(D)
        column = ds.flat_filtered(reaction)
        if ds.vehicle.identified:
            ds.extra_free.append(column)
            ds.rebase()
        else:
            ds.carry(self.cause, parameters, column * ds.a.Jp / ds.a.Jzz)

    def run(self):
        result = super().run()
        self._tau = result.parameters["tau"]
        return result

    def not_named(self, result):
        return too_short_to_time(result, self.ds)

    def physical(self, result):
        return timing_not_physical(result)

    def explanatory(self):
        return self.ds.flat([self._speeds(i, self._tau)[1] for i in range(len(self.ds.files))])
