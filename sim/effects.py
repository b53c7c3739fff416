"""The candidate extensions of `measured-data.md`, each a term on the `sim.model.Effect` seam.

`parse("motor_lag:tau=0.05")` builds one from the command-line form of `flightctl sim --effect`.
"""
from __future__ import annotations

import math

from flightctl.errors import InputError
from flightctl.sim.model import R, Z, Effect


class MotorLag(Effect):
    """Each thrust follows its command through a first-order lag: d f / dt = (f_cmd - f) / tau."""
    cause, n_states, uses_rotor = "motor_lag", 4, True
    required = {"tau": (1e-4, 5.0)}

    def initial_states(self, f_cmd):
        return list(f_cmd)

    def rotor(self, t, x, f_cmd, xdot):
        o, tau = self.offset, self.parameters["tau"]
        f = x[o:o + 4]
        if xdot is not None:
            for i in range(4):
                xdot[o + i] = (f_cmd[i] - f[i]) / tau
        return f


class ActuationDelay(Effect):
    """Each thrust follows its command after a pure delay (the plant delays the input)."""
    cause = "actuation_delay"
    required = {"delay": (0.0, 1.0)}

    def __init__(self, **parameters):
        super().__init__(**parameters)
        self.delay = self.parameters["delay"]


class GroundEffect(Effect):
    """Thrust rises near the ground: f / f_inf = 1 / (1 - (R / 4 z)^2) (Cheeseman and Bennett).

    The formula diverges at z = R / 4; it is held at its value for z = R / 2 (factor 4/3) below that,
    where it is no longer valid anyway."""
    cause, uses_scale, state_dependent = "ground_effect", True, True
    required = {"rotor_radius": (0.005, 1.0)}

    def scale(self, t, x, u, s):
        radius = self.parameters["rotor_radius"]
        z = max(x[Z], 0.5 * radius)
        k = 1.0 / (1.0 - (radius / (4.0 * z)) ** 2)
        for i in range(4):
            s[i] *= k


class BatterySag(Effect):
    """Thrust scales with (battery_v / v_nominal)^2: the propeller was identified at v_nominal."""
    cause, uses_scale = "battery_sag", True
    required = {"v_nominal": (1.0, 60.0)}

    def scale(self, t, x, u, s):
        k = (u[4] / self.parameters["v_nominal"]) ** 2
        for i in range(4):
            s[i] *= k


class MotorWeak(Effect):
    """One motor gives a fraction `scale` of its modelled thrust and torque."""
    cause, uses_scale = "motor_weak", True
    required = {"motor": (1, 4), "scale": (0.0, 2.0)}

    def __init__(self, **parameters):
        super().__init__(**parameters)
        if self.parameters["motor"] != int(self.parameters["motor"]):
            raise InputError("motor_weak: motor must be 1, 2, 3 or 4")
        self._i = int(self.parameters["motor"]) - 1

    def scale(self, t, x, u, s):
        s[self._i] *= self.parameters["scale"]


class LinearYawDrag(Effect):
    """An extra yaw drag torque gamma0 r (the linear law of eq. 5 beside eq. 6)."""
    cause, uses_wrench = "linear_yaw_drag", True
    required = {"gamma0": (0.0, 10.0)}

    def wrench(self, t, x, f, vb, force, torque):
        torque[2] -= self.parameters["gamma0"] * x[R]


class RotorDrag(Effect):
    """Horizontal drag on the body, -k (u, v) in the body frame (blade flapping and induced drag)."""
    cause, uses_wrench = "rotor_drag", True
    required = {"k": (0.0, 20.0)}

    def wrench(self, t, x, f, vb, force, torque):
        k = self.parameters["k"]
        force[0] -= k * vb[0]
        force[1] -= k * vb[1]


class ComOffset(Effect):
    """The centre of mass is off the thrust centre by (dx, dy) in the body frame: each thrust acts at
    (x_i - dx, y_i - dy), which adds (-dy, +dx) times the total thrust to the roll and pitch torques."""
    cause, uses_wrench = "com_offset", True
    required = {"dx": (-0.5, 0.5), "dy": (-0.5, 0.5)}

    def wrench(self, t, x, f, vb, force, torque):
        total = f[0] + f[1] + f[2] + f[3]
        torque[0] -= self.parameters["dy"] * total
        torque[1] += self.parameters["dx"] * total


EFFECTS = {cls.cause: cls for cls in (MotorLag, ActuationDelay, GroundEffect, BatterySag, MotorWeak,
                                      LinearYawDrag, RotorDrag, ComOffset)}
CAUSES = ("none",) + tuple(EFFECTS)


def make(cause: str, **parameters: float) -> Effect:
    if cause not in EFFECTS:
        raise InputError(f"unknown effect {cause!r} (known: {', '.join(EFFECTS)})")
    cls = EFFECTS[cause]
    missing = set(cls.required) - set(parameters)
    unknown = set(parameters) - set(cls.required)
    if missing or unknown:
        raise InputError(f"{cause}: takes {', '.join(cls.required)}"
                         + (f"; missing {', '.join(sorted(missing))}" if missing else "")
                         + (f"; unknown {', '.join(sorted(unknown))}" if unknown else ""))
    for name, (lo, hi) in cls.required.items():
        v = parameters[name]
        if not (math.isfinite(v) and lo <= v <= hi):
            raise InputError(f"{cause}: {name}={v:g} is out of range [{lo:g}, {hi:g}]")
    return cls(**parameters)


def parse(text: str) -> Effect:
    """`CAUSE:name=value,name=value`, as `flightctl sim --effect` takes it."""
    cause, _, args = text.partition(":")
    parameters = {}
    for item in filter(None, args.split(",")):
        name, sep, value = item.partition("=")
        try:
            parameters[name.strip()] = float(value)
        except ValueError:
            sep = ""
        if not sep:
            raise InputError(f"--effect {text!r}: expected CAUSE:name=value,... (bad item {item!r})")
    return make(cause.strip(), **parameters)
