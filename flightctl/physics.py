"""The paper's equations shared by the onboard mixer, the simulator's model and the identification fits:
one copy of each. Every function takes floats (the 450 Hz loop and the simulator's scalar model) and
numpy arrays alike (the fits evaluate them on many samples at once), without numpy on the float path.

Symbols and units as in conventions.md: P the ESC command value (0-255), f a rotor's thrust (N),
omega its speed (rad/s), tau its reaction torque (N m), r the yaw rate (rad/s).
"""
from __future__ import annotations

from math import sqrt

G = 9.80665   # standard gravity, m/s^2 (paper, Table 2): the g of accelerometer LSB/g and of gram-force


def thrust_from_command(P, h1: float, h2: float):
    """Eq. 26: f = h1 (P - h2)^2 above the dead zone P > h2, and 0 in it (the parabola would rise again)."""
    d = P - h2
    d = (d + abs(d)) * 0.5   # max(d, 0) for floats and arrays alike
    return h1 * d * d


def esc_command(P: float, p_full: float) -> float:
    """The command an ESC acts on: P, up to its full throttle p_full, above which eq. 26's thrust stops
    rising (an RC ESC's input runs 1.0-2.0 ms: a longer pulse is full throttle). Floats only."""
    return P if P < p_full else p_full


def command_from_thrust(f: float, h1: float, h2: float) -> float:
    """Eq. 26 inverted, the mixer's side: P = h2 + sqrt(f / h1) for a thrust f >= 0 (floats only).
    Zero thrust gives P = h2, the edge of the dead zone, so the command is continuous in f."""
    return h2 + sqrt(f / h1)


def thrust_from_speed(omega, c1: float):
    """Eq. 27: f = c1 omega^2."""
    return c1 * omega * omega


def rotor_speed(f, c1: float):
    """Eq. 27 inverted: omega = sqrt(f / c1); a negative thrust (eq. 26 never gives one) counts as 0."""
    return ((f + abs(f)) * 0.5 / c1) ** 0.5


def rotor_torque(f, g1: float, g2: float):
    """Eq. 28: tau = (g1 f + g2) sgn(f); thrust is never negative, so sgn(f) is 1 for f > 0, else 0."""
    return (g1 * f + g2) * (f > 0)


def yaw_drag(r, gamma1: float, gamma2: float):
    """Eq. 6: tau_d = (gamma1 r^2 + gamma2) sgn(r); gamma2 is the test bearing's friction, 0 in flight."""
    return (gamma1 * r * r + gamma2) * ((r > 0) * 1.0 - (r < 0) * 1.0)
