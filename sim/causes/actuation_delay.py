"""`actuation_delay(delay)`: each rotor's thrust follows its command after a pure delay."""
from __future__ import annotations

import math

import numpy as np

from flightctl.sim.causes.motor_lag import MotorLagFit
from flightctl.sim.diagnose.candidate import (MAX_TIMING_S, TIMING_CHECK, GridCandidate, timing_not_physical,
                                                       too_short_to_time)
from flightctl.sim.world.model import Effect, Parameter


class ActuationDelay(Effect):
    """Each thrust follows its command after a pure delay (the plant delays the input)."""
    cause = "actuation_delay"
    required = {"delay": Parameter("s", 0.0, 1.0)}
    compiled = True     # the plant delays the input (`delay`): no wrench hook

    @property
    def delay(self):
        return self.parameters["delay"]   # (an array, one per vehicle, in the batched simulator)


def shift(F, s: float):
    """F (..., n) delayed by s samples, linearly interpolated between samples (the average over the
    period when s is a delay in loop periods), the first value held before the start."""
    if s <= 0:
        return F
    m, frac = int(math.floor(s)), s - math.floor(s)
    return (1.0 - frac) * _shift(F, m) + frac * _shift(F, m + 1)


def _shift(F, m):
    """F delayed by m samples, the first value held before the start."""
    if m <= 0:
        return F
    out = np.empty_like(F)
    out[..., m:] = F[..., :-m]
    out[..., :m] = F[..., :1]
    return out


class ActuationDelayFit(GridCandidate):
    """The thrust series shifted by the delay, linearly interpolated between periods (the average
    over the period); a grid over the whole physical range, 0 to 300 ms (2.5 ms steps to 50 ms, 5 ms to
    100 ms, then 10 ms), refined between the best point's neighbours."""
    effect = ActuationDelay
    changes_thrust = dynamic = True
    explains = MotorLagFit.explains
    grid = np.concatenate([np.arange(0.0, 0.05, 0.0025), np.arange(0.05, 0.1, 0.005),
                           np.arange(0.1, MAX_TIMING_S + 1e-9, 0.01)])
    physical_check = TIMING_CHECK
    times_actuation, lookalikes = True, ("gyro_lag",)
    cached = True     # its change is the base model's thrusts changed: no carried term enters it

    def thrusts(self, parameters):
        ds, d = self.ds, parameters["delay"]
        return [shift(D, d * ds.fs) for D in ds.D]      # the delay in loop periods

    def delta(self, d):
        ds = self.ds
        return ds.delta_filtered([ds.predict_file(i, D) for i, D in enumerate(self.thrusts({"delay": d}))])

    def not_named(self, result):
        return too_short_to_time(result, self.ds)

    def physical(self, result):
        return timing_not_physical(result)
