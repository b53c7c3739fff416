"""`com_offset(dx, dy)`: the centre of mass is off the thrust centre."""
from __future__ import annotations

import dataclasses

import numpy as np

from flightctl.sim.identify.diagnose.candidate import AffineCandidate
from flightctl.sim.identify.diagnose.data import Layout
from flightctl.sim.identify.diagnose.dataset import C
from flightctl.sim.world.model import Effect, Parameter


class ComOffset(Effect):
    """The centre of mass is off the thrust centre by (dx, dy) in the body frame.

    Each thrust acts at (x_i - dx, y_i - dy), which adds (-dy, +dx) times the total thrust to the
    roll and pitch torques."""
    cause, uses_wrench = "com_offset", True
    required = {"dx": Parameter("m", -0.5, 0.5), "dy": Parameter("m", -0.5, 0.5)}

    def wrench(self, t, x, f, vb, force, torque):
        total = f[0] + f[1] + f[2] + f[3]
        torque[0] -= self.parameters["dy"] * total
        torque[1] += self.parameters["dx"] * total


class ComOffsetFit(AffineCandidate):
    """Torques (-dy, +dx) times the total thrust T: -dy T / Jxx on p_dot, +dx T / Jyy on q_dot."""
    effect = ComOffset
    explains = "total thrust (N)"
    changes_thrust = True    # folded as the rotors' positions from the centre of mass, not as an added term

    def columns(self):
        ds = self.ds
        Gx, Gy = [], []
        for i in range(len(ds.files)):
            T = ds.thrust_of(i).sum(axis=0)
            x = np.zeros((C, T.size))
            y = np.zeros((C, T.size))
            x[1] = T / ds.a.Jyy
            y[0] = -T / ds.a.Jxx
            Gx.append(x)
            Gy.append(y)
        return None, [ds.flat_filtered(Gx), ds.flat_filtered(Gy)]

    def to_parameters(self, theta):
        return {"dx": round(float(theta[0]), 5), "dy": round(float(theta[1]), 5)}

    def fold(self, parameters):
        """Into the chain as what it is: every rotor at (x_i - dx, y_i - dy) from the centre of mass, so
        that what later changes the thrusts (ground effect, a weak motor, a lag) changes this torque too,
        as in the plant."""
        ds = self.ds
        lay = ds.vehicle.layout
        dx, dy = parameters["dx"] / ds.a.l, parameters["dy"] / ds.a.l      # in the layout's units
        if lay.unit == "m":
            dx, dy = parameters["dx"], parameters["dy"]
        shifted = Layout(tuple(x - dx for x in lay.x), tuple(y - dy for y in lay.y), lay.spin, lay.unit,
                         lay.source + f"; centre of mass at ({parameters['dx']:g}, {parameters['dy']:g})")
        ds.vehicle = dataclasses.replace(ds.vehicle, layout=shifted)
        ds.rebase()

    def explanatory(self):
        return self.ds.thrust.sum(axis=0)
