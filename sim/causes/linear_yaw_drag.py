"""`linear_yaw_drag(gamma0)`: an extra yaw drag torque proportional to the yaw rate."""
from __future__ import annotations

import numpy as np

from flightctl.sim.diagnose.candidate import AffineCandidate
from flightctl.sim.diagnose.dataset import C
from flightctl.sim.world.model import R, Effect, Parameter

YAW_MIN_RATE = 0.2       # rad/s: linear_yaw_drag needs yaw rates at least this (95th percentile)


class LinearYawDrag(Effect):
    """An extra yaw drag torque gamma0 r (the linear law of eq. 5 beside eq. 6)."""
    cause, uses_wrench = "linear_yaw_drag", True
    required = {"gamma0": Parameter("N m s", 0.0, 10.0)}

    def wrench(self, t, x, f, vb, force, torque):
        torque[2] -= self.parameters["gamma0"] * x[R]


class LinearYawDragFit(AffineCandidate):
    """-gamma0 r / Jzz on r_dot, by weighted least squares."""
    effect = LinearYawDrag
    explains = "yaw rate r (rad/s)"
    needs_yaw = True

    def why_not(self):
        r95 = np.percentile(np.abs(self.ds.w[2]), 95)
        if r95 < YAW_MIN_RATE:
            return f"no yaw motion to judge it (95th percentile |r| = {r95:.3f} rad/s, {YAW_MIN_RATE:g} needed)"
        return None

    def columns(self):
        ds = self.ds
        G = []
        for i in range(len(ds.files)):
            x = np.zeros((C, ds.files[i].t.size))
            x[2] = -ds.wmid[i][2] / ds.a.Jzz
            G.append(x)
        return None, [ds.flat_filtered(G)]

    def to_parameters(self, theta):
        return {"gamma0": float(f"{theta[0]:.4g}")}

    def explanatory(self):
        return self.ds.w[2]
