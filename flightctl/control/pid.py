"""PID with the derivative on the measurement (eq. 23-24), output and integral capped (Table 3)."""
from __future__ import annotations

import math

TWO_PI = 2.0 * math.pi


def wrap(angle: float) -> float:
    """An angle into [-pi, pi)."""
    return (angle + math.pi) % TWO_PI - math.pi


class Pid:
    """u = kp e - kd dy/dt + ki sum(e dt) (eq. 24) with |u| <= limit and the integral held within the
    limit (anti-windup). The caller gives the measured derivative dy/dt: eq. 24's difference
    quotient, or a filtered gyro rate. `angle=True` wraps the error to [-pi, pi)."""
    __slots__ = ("kp", "ki", "kd", "limit", "angle", "integral")

    def __init__(self, kp: float, ki: float, kd: float, limit: float, angle: bool = False):
        self.kp, self.ki, self.kd, self.limit, self.angle = kp, ki, kd, limit, angle
        self.integral = 0.0

    def reset(self) -> None:
        self.integral = 0.0

    def update(self, setpoint: float, y: float, dy: float, dt: float) -> float:
        e = setpoint - y
        if self.angle:
            e = (e + math.pi) % TWO_PI - math.pi
        lim = self.limit
        i = self.integral + self.ki * e * dt
        self.integral = i = lim if i > lim else -lim if i < -lim else i
        u = self.kp * e - self.kd * dy + i
        return lim if u > lim else -lim if u < -lim else u
