"""`com_offset(dx, dy)`: the centre of mass is off the thrust centre."""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from flightctl.sim.diagnose.candidate import AffineCandidate
from flightctl.sim.diagnose.data import Layout
from flightctl.sim.diagnose.dataset import C
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


# The centre of mass must lie well inside the rotors: in hover the rotors on the heavy side carry
# (h + d) / (h - d) times the thrust of the others, h the rotors' reach in the offset's direction (the
# layout's support: the largest projection of a rotor's position on it). At d = h / 4 that is 1.67: a
# vehicle hovering at 40-50 % of full thrust (a thrust-to-weight ratio of 2-2.5) then has its heavy
# side at 67-83 % before any manoeuvre, about what it can fly with; farther out it could not hold
# attitude in a manoeuvre. The offsets met in the tests are 0.02-0.08 of the arm.
MAX_OFFSET = 0.25


def reach(layout: Layout, ux: float, uy: float) -> float:
    """How far the rotors reach from the centre in the direction (ux, ux) (unit vector): the layout's
    support function, max_i (x_i ux + y_i uy), in the layout's units."""
    return max(x * ux + y * uy for x, y in zip(layout.x, layout.y))


class ComOffsetFit(AffineCandidate):
    """Torques (-dy, +dx) times the total thrust T: -dy T / Jxx on p_dot, +dx T / Jyy on q_dot."""
    effect = ComOffset
    explains = "total thrust (N)"
    physical_check = (f"(dx, dy) well inside the rotors: at most {MAX_OFFSET:g} of the rotors' reach in its direction "
                      f"(the heavy side then carries 1.67 times the other's thrust in hover: a vehicle hovering at "
                      f"40-50 % of full thrust is near its limit)")
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

    def why_not(self):
        if self.ds.vehicle.identified:
            return ("the centre of mass is identified in the base model of this vehicle (base_model.com), apart "
                    "from the rotors' gains")
        return None

    def physical(self, result):
        dx, dy = result.parameters["dx"], result.parameters["dy"]
        d = math.hypot(dx, dy)
        if d == 0.0:
            return None
        lay = self.ds.vehicle.layout
        h = reach(lay, dx / d, dy / d) * (1.0 if lay.unit == "m" or self.ds.vehicle.identified else self.ds.a.l)
        if d > MAX_OFFSET * h:
            unit = "m" if lay.unit == "m" else "arm lengths"
            return (f"the centre of mass {d:.3g} {unit} off the thrust centre is {d / h:.2f} of the rotors' reach "
                    f"({h:.3g} {unit}) in that direction, more than {MAX_OFFSET:g}: outside what the vehicle could hover with")
        return None

    def explanatory(self):
        return self.ds.thrust.sum(axis=0)
