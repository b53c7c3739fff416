"""`gyro_lag(tau)`: the gyro the log holds lags the body rates through a first-order low-pass that the
log does not declare (the rate path has more lag than the model has).

Where it comes from on a vehicle: a gyro low-pass that nobody wrote into the log (the chip's DLPF set
lower than the driver says: the MPU-9250's settings delay the rate by 1-33 ms, RM-MPU-9250A-00
register 26; a software filter between the driver and the logger; a logger that records the D path's
filtered rate instead of the raw one). The contract's log holds the gyro "before the EMA filter"; a
log that breaks that has the EMA's lag in it.

What the equation-error frame sees (docs/diagnose.md, "The rate path"): the measured angular
acceleration is the differenced logged gyro, so a filter L of the gyro makes it L(p_dot): the
commands' effect on p, q and r arrives late and rounded, as with a motor lag. The accelerometer does
not pass through it, so the thrust's effect on acc_z stays on time: a motor lag or an actuation delay
lags acc_z as well, and that is what tells them apart. The prediction is the base model's through the
same filter on the three gyro channels only; folded into the model (the chain), the filter joins the
log's declared gyro filters (`DataSet.add_gyro_filter`), through which every later prediction goes.

More noise on the gyro is not a cause in this frame: the low-pass that both sides share removes most
of it, and what is left is a prediction error no model of the commands can reduce (docs/diagnose.md).
"""
from __future__ import annotations

import copy
import math

from flightctl.sim.causes.motor_lag import MotorLagFit
from flightctl.sim.diagnose.candidate import (MAX_TIMING_S, GridCandidate, timing_not_physical,
                                                       too_short_to_time)
from flightctl.sim.diagnose.dataset import Change
from flightctl.sim.world.model import Effect, Parameter


def pt1_gain(dt: float, tau: float) -> float:
    """The gain k of the exact discrete first-order lag y' = (x - y) / tau over a step dt of an input
    held over the step: y_k = y_(k-1) + k (x_k - y_(k-1)), k = 1 - exp(-dt / tau) (1 at tau = 0)."""
    return 1.0 - math.exp(-dt / tau) if tau > 0.0 else 1.0


class GyroLag(Effect):
    """The logged gyro lags the body rates through a first-order low-pass the log does not declare."""
    cause, uses_gyro = "gyro_lag", True
    required = {"tau": Parameter("s", 0.0, 1.0)}
    compiled = True     # it acts on the simulated IMU, not the plant

    def attach(self, airframe, offset):
        super().attach(airframe, offset)
        self._y = None                    # the filter's output at the last read

    def gyro(self, dt, p, q, r):
        if self._y is None:               # the first read: the filter starts in equilibrium
            self._y = [p, q, r]
        else:
            k, y = pt1_gain(dt, self.parameters["tau"]), self._y
            y[0] += k * (p - y[0])
            y[1] += k * (q - y[1])
            y[2] += k * (r - y[2])
        return tuple(self._y)


def gyro_stage(tau: float, fs: float) -> tuple[list, list]:
    """(b, a) of the lag at the log's rate fs, as `scipy.signal.lfilter` takes it (`pt1_gain`)."""
    k = pt1_gain(1.0 / fs, tau)
    return [k, 0.0], [1.0, k - 1.0]


def with_lag(ds, tau: float) -> None:
    """The data set's model with the gyro lag in it (`DataSet.add_gyro_filter`), and every term it carries
    (a parameter file's effects, the chain's causes that add to the prediction) predicted again through
    it: a carried motor lag's change of the angular acceleration reaches the log through the gyro too."""
    from flightctl.sim.causes import CAUSES   # here: the registry imports this module
    ds.carried, ds.carried_parameters = dict(ds.carried), dict(ds.carried_parameters)
    if GyroLag.cause in ds.carried:           # a carried gyro lag: this one replaces it
        ds.r_base = ds.r_base + ds.carried.pop(GyroLag.cause)
        del ds.carried_parameters[GyroLag.cause]
    ds.add_gyro_filter(*gyro_stage(tau, ds.fs))
    for cause, parameters in ds.carried_parameters.items():
        term = CAUSES[cause].candidate(ds).predict(parameters)
        ds.r_base = ds.r_base + ds.carried[cause] - term
        ds.carried[cause] = term


GYRO_LAG_CHECK = (f"a lag of 0-{1e3 * MAX_TIMING_S:.0f} ms: the MPU-9250's gyro DLPF settings delay the rate by "
                  "1-33 ms (RM-MPU-9250A-00, register 26) and the paper's EMA of 8-128 periods at 450 Hz by 18-284 ms "
                  "(docs/as-flown.md)")


class GyroLagFit(GridCandidate):
    """The base model's prediction of p_dot, q_dot and r_dot through the lag, causal over each whole
    file (the accelerometer's channels unchanged); a 41-point grid over tau (0 and 2 ms to 0.3 s,
    geometric, as `motor_lag`'s), refined between the best point's neighbours."""
    effect = GyroLag
    changes_thrust = dynamic = True    # folded into the base model's sensing, first; timed by the commands
    explains = "angular acceleration the model predicts from the commands (rad/s^2)"
    grid = MotorLagFit.grid
    physical_check = GYRO_LAG_CHECK
    # a lag or a delay of the rotors makes the gyro follow the commands late alike; only the rotors' lag
    # the accelerometer's z too (docs/diagnose.md, "Two lags at once")
    lookalikes = ("actuation_delay", "motor_lag", "motor_dynamics")

    def delta(self, tau):
        ds = self.ds
        if tau <= 0.0:
            return Change(self.r_base - ds.base_without(self.cause), ds.base_free)
        lagged = copy.copy(ds)
        with_lag(lagged, tau)
        return Change(self.r_base - lagged.r_base, lagged.base_free)

    def fold(self, parameters):
        with_lag(self.ds, float(parameters["tau"]))

    def not_named(self, result):
        return too_short_to_time(result, self.ds)

    def physical(self, result):
        return timing_not_physical(result, "no gyro filter lags that long (the commands and the rates the log shows "
                                           "do not match in time)")
