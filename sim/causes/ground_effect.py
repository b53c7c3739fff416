"""`ground_effect(rotor_radius)`: the thrust rises near the ground."""
from __future__ import annotations

import numpy as np

from flightctl.sim.diagnose.candidate import GridCandidate
from flightctl.sim.diagnose.dataset import C
from flightctl.sim.world.model import Z, Effect, Parameter

GE_MAX_Z = 0.6           # m: ground effect is judged only with airborne time below this
GE_MIN_S = 1.0           # s of it


def factor(z, radius: float):
    """f / f_inf = 1 / (1 - (R / 4 z)^2) (Cheeseman and Bennett), for z >= R / 2 (floats or arrays)."""
    return 1.0 / (1.0 - (radius / (4.0 * z)) ** 2)


class GroundEffect(Effect):
    """Thrust rises near the ground: f / f_inf = 1 / (1 - (R / 4 z)^2) (Cheeseman and Bennett).

    The formula diverges at z = R / 4; it is held at its value for z = R / 2 (factor 4/3) below that,
    where it is no longer valid anyway."""
    cause, uses_scale, state_dependent = "ground_effect", True, True
    required = {"rotor_radius": Parameter("m", 0.005, 1.0)}

    def scale(self, t, x, u, s):
        radius = self.parameters["rotor_radius"]
        z, lo = x[Z], 0.5 * radius
        k = factor((z + lo + abs(z - lo)) * 0.5, radius)   # max(z, R / 2) for floats and arrays alike
        for i in range(4):
            s[i] *= k


class GroundEffectFit(GridCandidate):
    """Every rotor's thrust and torque times the factor at the levelled range (interpolated between
    echoes); a 46-point grid over R from 0 to 0.45 m."""
    effect = GroundEffect
    changes_thrust = True
    explains = "altitude from the range (m)"
    grid = np.linspace(0.0, 0.45, 46)

    def why_not(self):
        z = self.ds.z
        if not np.isfinite(z).any():
            return "no range readings in flight: the altitude near the ground is unknown"
        low = np.isfinite(z) & (z < GE_MAX_Z)
        if low.sum() / self.ds.fs_flat < GE_MIN_S:
            return (f"only {low.sum() / self.ds.fs_flat:.1f} s airborne below {GE_MAX_Z:g} m "
                    f"({GE_MIN_S:g} s needed) to see the thrust rise near the ground")
        return None

    def _factors(self, R):
        return [factor(np.maximum(np.nan_to_num(f.z, nan=10.0), 0.5 * R), R) for f in self.ds.files]

    def scales(self, parameters):
        R = parameters["rotor_radius"]
        return self._factors(R) if R > 0 else [1.0] * len(self.ds.files)

    def delta(self, R):
        ds = self.ds
        if R <= 0:
            return np.zeros((C, ds.n))
        return ds.delta_filtered([ds.predict_file(i, D, scale=np.broadcast_to(s, D.shape[1:]))
                                  for i, (D, s) in enumerate(zip(ds.D, self._factors(R)))])

    def explanatory(self):
        return self.ds.z
