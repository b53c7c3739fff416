"""The mixer of eq. 25 with the tilt correction of u_z and the limits of Table 3, then eq. 26
inverted (thrust -> command value P, `flightctl.physics`) and P -> PWM counts on pigpio's 0..40000 range."""
from __future__ import annotations

from math import cos

from flightctl.hal import PWM_RANGE
from flightctl.params import Airframe
from flightctl.physics import command_from_thrust

MIN_TILT_COSINE = 0.5  # beyond 60 degrees of tilt the u_z correction is held (and the vehicle is lost)
SCALE = PWM_RANGE / 255.0   # P (0..255) -> counts, conventions.md


def count_from_thrust(f: float, h1: float, h2: float) -> int:
    """Eq. 26 inverted (thrust f >= 0 -> command value P), within the ESC's range, as a PWM count."""
    P = command_from_thrust(f, h1, h2)
    return int(SCALE * (P if P < 255.0 else 255.0) + 0.5)


class Mixer:
    __slots__ = ("B", "fmax", "h1", "h2", "f")

    def __init__(self, a: Airframe):
        self.B = a.B                       # base thrust M g / 4 (eq. 25)
        self.fmax = 2.0 * a.B              # Table 3: 0 <= f_i <= 2B
        self.h1, self.h2 = a.h1, a.h2
        self.f = [0.0, 0.0, 0.0, 0.0]      # the last thrusts, N (for logs and tests)

    def mix(self, uz: float, uphi: float, utheta: float, upsi: float, roll: float, pitch: float,
            counts: list[int]) -> None:
        """Eq. 25: f = B + u_z / (cos(roll) cos(pitch)) + [-u_t, +u_p, +u_t, -u_p] + [+u_y, -u_y, +u_y, -u_y],
        each u already within [-B, B] (the PIDs' limit), each f clipped to [0, 2B]; written as counts."""
        c = cos(roll) * cos(pitch)
        base = self.B + uz / (c if c > MIN_TILT_COSINE else MIN_TILT_COSINE)
        fmax, h1, h2, count = self.fmax, self.h1, self.h2, count_from_thrust
        f = self.f
        # each within [0, fmax]; NaN -> 0: never a NaN command (the four written out: the 450 Hz loop)
        fi = base - utheta + upsi
        f[0] = fi = fmax if fi > fmax else fi if fi > 0.0 else 0.0
        counts[0] = count(fi, h1, h2)
        fi = base + uphi - upsi
        f[1] = fi = fmax if fi > fmax else fi if fi > 0.0 else 0.0
        counts[1] = count(fi, h1, h2)
        fi = base + utheta + upsi
        f[2] = fi = fmax if fi > fmax else fi if fi > 0.0 else 0.0
        counts[2] = count(fi, h1, h2)
        fi = base - uphi - upsi
        f[3] = fi = fmax if fi > fmax else fi if fi > 0.0 else 0.0
        counts[3] = count(fi, h1, h2)
