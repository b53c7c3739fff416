"""`battery_sag(v_nominal)`: the thrust scales with the square of the battery voltage."""
from __future__ import annotations

import math

import numpy as np

from flightctl.sim.identify.diagnose.candidate import AffineCandidate
from flightctl.sim.world.model import Effect, Parameter

SAG_MIN_SPAN = 0.01      # battery_sag needs the voltage to vary by 1 % (5th to 95th percentile)


class BatterySag(Effect):
    """Thrust scales with (battery_v / v_nominal)^2: the propeller was identified at v_nominal."""
    cause, uses_scale = "battery_sag", True
    required = {"v_nominal": Parameter("V", 1.0, 60.0)}

    def scale(self, t, x, u, s):
        k = (u[4] / self.parameters["v_nominal"]) ** 2
        for i in range(4):
            s[i] *= k


class BatterySagFit(AffineCandidate):
    """Thrust times (V / v_nominal)^2: D = (c V^2 - 1) G with G the thrust-proportional part of the
    prediction, affine in c = 1 / v_nominal^2."""
    effect = BatterySag
    changes_thrust = True
    explains = "battery voltage (V)"

    def why_not(self):
        V = self.ds.V
        if not np.isfinite(V).all():
            return "battery_v is missing in flight"
        lo, hi = np.percentile(V, [5, 95])
        span = (hi - lo) / np.median(V)
        if span < SAG_MIN_SPAN:
            return (f"battery_v hardly varies in flight ({100 * span:.2f} % from the 5th to the 95th "
                    f"percentile, {100 * SAG_MIN_SPAN:g} % needed): a constant voltage only rescales the thrust")
        return None

    def columns(self):
        ds = self.ds
        G = [ds.thrust_columns(i).sum(axis=0) for i in range(len(ds.files))]
        G0 = -ds.flat_filtered(G)
        G1 = ds.flat_filtered([g * f.battery_v ** 2 for g, f in zip(G, ds.files)])
        return G0, [G1]

    def scales(self, parameters):
        return [(f.battery_v / parameters["v_nominal"]) ** 2 for f in self.ds.files]

    def why_not_carried(self):
        return None if np.isfinite(self.ds.V).all() else "battery_v is missing in flight"

    def from_parameters(self, parameters):
        return [1.0 / parameters["v_nominal"] ** 2]

    def to_parameters(self, theta):
        c = float(theta[0])
        return {"v_nominal": round(1.0 / math.sqrt(c), 3) if c > 0 else None}

    def not_named(self, result):
        if result.parameters.get("v_nominal") is None:
            return "battery_sag: the fit wants no voltage dependence (1/v_nominal^2 <= 0): not named"
        return None

    def explanatory(self):
        return self.ds.V
