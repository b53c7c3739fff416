"""Our frames to the aerospace ones of MAVLink and PX4's ULog, at those edges only.

Ours (conventions.md): inertial x North, y West, z Up; body x forward (motor 1), y left, z up; Z-Y-X
Euler angles. MAVLink and ULog: inertial North-East-Down, body Forward-Right-Down, Z-Y-X Euler angles.
Both pairs differ by the half turn T = diag(1, -1, -1) about x, so R_ned = T R_ours T: roll keeps its
sign, pitch and yaw change it (our positive pitch is nose down, theirs nose up); vectors keep x and
negate y and z (altitude z up is -z down). Scalars only: called once per message, never on arrays
in the loop.
"""
from __future__ import annotations

import math


def euler_ned(roll: float, pitch: float, yaw: float) -> tuple[float, float, float]:
    """Our Z-Y-X Euler angles (rad) as FRD-to-NED angles (rad), yaw wrapped to [-pi, pi)."""
    return roll, -pitch, (-yaw + math.pi) % (2 * math.pi) - math.pi


def vector_ned(x: float, y: float, z: float) -> tuple[float, float, float]:
    """A vector of ours (body FLU or inertial NWU) in FRD or NED: positions, rates, accelerations."""
    return x, -y, -z


def quaternion(roll: float, pitch: float, yaw: float) -> tuple[float, float, float, float]:
    """(w, x, y, z) of the Z-Y-X Euler angles roll, pitch, yaw (already in the target frames)."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return (cr * cp * cy + sr * sp * sy, sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy)


def pulse_us(p: float, esc_pwm_hz: float) -> float:
    """The ESC pulse width (us) of command P (0-255 = 0-100 % duty, conventions.md) at the ESC rate."""
    return p / 255.0 * 1e6 / esc_pwm_hz
