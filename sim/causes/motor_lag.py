"""`motor_lag(tau)`: each rotor's thrust follows its command through a first-order lag."""
from __future__ import annotations

import math

import numpy as np

from flightctl.sim.diagnose.candidate import (MAX_TIMING_S, TIMING_CHECK, GridCandidate, timing_not_physical,
                                                       too_short_to_time)
from flightctl.sim.world.model import Effect, Parameter


class MotorLag(Effect):
    """Each thrust follows its command through a first-order lag: d f / dt = (f_cmd - f) / tau."""
    cause, n_states, uses_rotor = "motor_lag", 4, True
    required = {"tau": Parameter("s", 1e-4, 5.0)}

    def initial_states(self, f_cmd):
        return list(f_cmd)

    def rotor(self, t, x, f_cmd, xdot):
        o, tau = self.offset, self.parameters["tau"]
        f = x[o:o + 4]
        if xdot is not None:
            for i in range(4):
                xdot[o + i] = (f_cmd[i] - f[i]) / tau
        return f


def lag_held(U: np.ndarray, tau: float, fs: float) -> tuple[np.ndarray, np.ndarray]:
    """A first-order lag y' = (u - y) / tau of a zero-order-held input U (k, n), exact, started in
    equilibrium: (y at the sample instants, y averaged over each period from row k to k+1)."""
    from scipy import signal   # here, not at the top: `flightctl sim` imports the causes for their effects
    dt = 1.0 / fs
    a = math.exp(-dt / tau)
    b_, a_ = [0.0, 1.0 - a], [1.0, -a]
    y, _ = signal.lfilter(b_, a_, U, axis=1, zi=signal.lfilter_zi(b_, a_)[None, :] * U[:, :1])
    return y, U + (y - U) * (tau / dt) * (1.0 - a)


class MotorLagFit(GridCandidate):
    """Each rotor's eq. 26 thrust through the exact lag of the held command, averaged over the
    period; a 41-point grid over tau (0 and 2 ms to 0.3 s, geometric: the whole physical range),
    refined between the best point's neighbours."""
    effect = MotorLag
    changes_thrust = dynamic = True
    explains = "rate of change of the commanded total |thrust differences| (N/s)"
    grid = np.concatenate([[0.0], np.geomspace(0.002, MAX_TIMING_S, 40)])
    physical_check = TIMING_CHECK
    twin, times_actuation, lookalikes = "motor_dynamics", True, ("gyro_lag",)
    cached = True     # its change is the base model's thrusts changed: no carried term enters it

    def thrusts(self, parameters):
        ds, tau = self.ds, parameters["tau"]
        return [lag_held(D.reshape(-1, D.shape[-1]), tau, ds.fs)[1].reshape(D.shape) if tau > 0 else D for D in ds.D]

    def delta(self, tau):
        ds = self.ds
        return ds.delta_filtered([ds.predict_file(i, D) for i, D in enumerate(self.thrusts({"tau": tau}))])

    def not_named(self, result):
        return too_short_to_time(result, self.ds)

    def physical(self, result):
        return timing_not_physical(result)
