"""The landing the loop commands itself (flightctl/loop.py `_land`: a low battery, the altitude lost,
a full disk, the end of a plan in the air): a descent at a set speed on a vertical estimate that
needs no sonar, then a touchdown that the accelerometer confirms. The paper's altitude PID (eq. 24)
flies the plans; it tracks a descending setpoint late and then fast (1.4 m/s at the floor after a
0.3 m/s ramp from a hover), and it needs the sonar.

`Vertical` estimates the altitude z, the vertical speed v and the accelerometer's bias along the
vertical b (z up, m, m/s, m/s^2) every loop: the world-z component of the measured specific force,
less g and b, is integrated, and each valid sonar altitude corrects all three (a complementary
filter of third order, its three poles at -W). The sonar corrects the bias through the whole flight,
so without the sonar (silent, stuck) the estimate runs on the accelerometer alone, its bias frozen:
a 0.01 m/s^2 error in b costs 4 cm over a 3 s descent from 1 m. An upward acceleration beyond
what the rotors can give (IMPACT) is the floor stopping the vehicle: the estimate is put at rest on
it, since a hard touchdown's jolt clips at the chip's full scale and its integral is lost.

`Landing` holds a vertical speed of -speed with a PI loop around the hover thrust the altitude PID
had learned (its integral), as thrust per motor (N, the unit of eq. 25's u_z). Below TOUCH_ALT, or
when the descent stops (the floor met above the estimate's zero), it lowers the thrust steadily and watches the
accelerometer: on the floor the floor carries the weight
and the vertical acceleration stays near 0 however low the thrust; in the air a thrust below the
hover thrust accelerates the vehicle down in proportion. A thrust below LANDED_THRUST of the hover
thrust with the acceleration within LANDED_ACCEL of 0 for LANDED_S is a touchdown (`landed`); a
vehicle still in the air (the acceleration past FALLING_ACCEL down, or FALLING_SPEED gained down since the feel
began) goes back to the descent
with its altitude estimate raised, and tries again lower.
"""
from __future__ import annotations

from math import cos, sin

from flightctl.physics import G

W = 2.5                  # rad/s: the vertical filter's three poles
KV, KI = 2.0, 1.0        # 1/s, 1/s^2: the descent's speed loop (thrust per motor = M/4 (KV e + KI int e))
TOUCH_ALT = 0.10         # m: below this estimate the thrust is lowered to feel for the floor ...
STALLED_SPEED, STALLED_S = 0.1, 0.5   # ... as when the descent stops (slower than this, this long)
RAMP = 0.5               # the thrust falls by this fraction of the hover thrust per second while feeling
LANDED_THRUST = 0.6      # of the hover thrust ...
LANDED_ACCEL = 0.08 * G  # ... with the vertical acceleration within this of 0 ...
LANDED_S = 0.25          # ... for this long: on the floor
FALLING_ACCEL = 0.15 * G  # feeling for the floor and accelerating down past this: still in the air
FALLING_SPEED = 0.3      # m/s: ... or gaining this much speed down since the feel began
RETRY_S = 0.5            # s: after such a miss, the descent before feeling again
IMPACT = 2.0 * G         # m/s^2 up beyond g: the rotors give at most 2 M g (Table 3: f_i <= 2B)
ACCEL_TAU = 0.05         # s: the low-pass on the acceleration the touchdown test reads


class Vertical:
    """z, v and the accelerometer bias b along the vertical, from the IMU and the sonar altitude."""
    __slots__ = ("z", "v", "b", "a", "k1", "k2", "k3")

    def __init__(self, w: float = W):
        self.k1, self.k2, self.k3 = 3.0 * w, 3.0 * w * w, w * w * w   # (s + w)^3
        self.z = self.v = self.b = self.a = 0.0

    def reset(self, ax: float, ay: float, az: float) -> None:
        """On the floor, level and still (at arming): z = v = 0, the bias from this reading."""
        self.z = self.v = self.a = 0.0
        self.b = az - G

    def predict(self, ax: float, ay: float, az: float, roll: float, pitch: float, dt: float) -> None:
        """One loop: the specific force rotated to the world's z (Z-Y-X Euler angles), less g and b."""
        cp = cos(pitch)
        a = self.a = -sin(pitch) * ax + sin(roll) * cp * ay + cos(roll) * cp * az - G - self.b
        if a > IMPACT:          # more than the rotors can give: the floor is stopping the vehicle
            self.z = self.v = 0.0   # (its jolt clips at the chip's full scale: its integral is lost)
            return
        self.z += (self.v + 0.5 * a * dt) * dt
        self.v += a * dt

    def correct(self, z_measured: float, dt: float) -> None:
        """A valid sonar altitude, `dt` after the last one."""
        r = z_measured - self.z
        self.z += self.k1 * dt * r
        self.v += self.k2 * dt * r
        self.b -= self.k3 * dt * r


class Landing:
    """A descent at -speed, then the touchdown (see the module's docstring). `step` gives u_z."""
    __slots__ = ("M4", "B", "speed", "trim", "integral", "feeling", "uz", "a_low", "t_still", "landed",
                 "t_retry", "v_feel", "descending", "t_stalled")

    def __init__(self, M: float):
        self.M4, self.B = M / 4.0, M * G / 4.0
        self.start(0.0, 0.0)

    def start(self, trim: float, speed: float) -> None:
        """Begin a descent at `speed` (m/s) from the hover u_z the altitude loop had learned (its
        integral)."""
        self.trim, self.uz, self.speed = trim, trim, speed
        self.integral = self.a_low = self.t_still = self.t_retry = self.v_feel = self.t_stalled = 0.0
        self.feeling = self.landed = self.descending = False

    def step(self, vert: Vertical, dt: float) -> float:
        B, hover = self.B, self.B + self.trim            # per-motor thrust holding the weight
        self.a_low += (vert.a - self.a_low) * (dt / ACCEL_TAU)
        if not self.feeling:
            v = vert.v
            e = -self.speed - v
            self.integral += KI * e * dt
            uz = self.trim + self.M4 * (KV * e + self.integral)
            if v < -0.5 * self.speed:
                self.descending = True
            self.t_stalled = self.t_stalled + dt if self.descending and v > -STALLED_SPEED else 0.0
            if self.t_retry > 0.0:
                self.t_retry -= dt
            elif vert.z < TOUCH_ALT or self.t_stalled > STALLED_S:
                self.feeling, self.t_still, self.v_feel = True, 0.0, v
        else:
            uz = self.uz - RAMP * hover * dt
            if self.a_low < -FALLING_ACCEL or vert.v - self.v_feel < -FALLING_SPEED:   # in the air: descend again
                self.feeling, self.t_retry = False, RETRY_S
                self.descending, self.t_stalled = False, 0.0
                self.integral = 0.0
                uz = self.uz
            elif B + uz < LANDED_THRUST * hover and -LANDED_ACCEL < self.a_low < LANDED_ACCEL:
                self.t_still += dt
                self.landed = self.t_still >= LANDED_S
            else:
                self.t_still = 0.0
        uz = B if uz > B else -B if uz < -B else uz
        self.uz = uz
        return uz
