"""Attitude from the IMU: EMA on the gyro (eq. 36-39), tilt from the accelerometer (eq. 30-31), yaw
from the magnetometer (eq. 32 restated for this project's frames), fused by complementary filters
(eq. 33-35) with the values of Table 5; plus the still-average bias calibration of section 4.4.4.
"""
from __future__ import annotations

from math import atan2, cos, exp, pi, sin, sqrt

from flightctl.hal import ImuSample
from flightctl.params import Filters


def tilt_from_accel(ax: float, ay: float, az: float) -> tuple[float, float]:
    """Eq. 30-31: roll = atan2(a_y, a_z), pitch = atan2(-a_x, sqrt(a_y^2 + a_z^2))."""
    return atan2(ay, az), atan2(-ax, sqrt(ay * ay + az * az))


def heading_from_mag(mx: float, my: float, mz: float, roll: float, pitch: float) -> float:
    """Eq. 32 for a body frame x forward, y left, z up (the paper's is North-East-Down): level the
    body-frame field with Ry(pitch) Rx(roll), then yaw = atan2(-m_y, m_x) of the levelled field."""
    sr, cr, sp, cp = sin(roll), cos(roll), sin(pitch), cos(pitch)
    lx = cp * mx + sp * (sr * my + cr * mz)
    ly = cr * my - sr * mz
    return atan2(-ly, lx)


ESTIMATORS = ("flight", "paper")
TWO_PI = 2.0 * pi


class AttitudeEstimator:
    """The onboard estimator. `update` runs once per loop; the controller reads `roll, pitch, yaw`
    and their rates `droll, dpitch, dyaw` (the measured derivative of eq. 24's D term).

    Two structures, both with the constants of Table 5 (docs/estimator.md says why):
    - "paper", section 4.4 read literally: the EMA-filtered gyro (eq. 36-39) is integrated in the
      complementary filters (eq. 33-35), the D term differentiates the fused angle (eq. 24), and the
      accelerometer corrects tilt at Table 5's 0.284 s in flight as on the ground.
    - "flight" (the default): the D term takes the gyro through an EMA of its own, of time constant
      `tau_rate` (Filters; 0: the gyro as the chip delivers it, its own low-pass only): the 0.284 s
      EMA of Table 5 in the D path costs the roll loop most of its phase margin (`flightctl
      analyze`), so the vehicle's rate path is a range (docs/estimator.md). Roll and pitch integrate
      the unfiltered gyro less an in-flight bias estimate. On
      the ground the accelerometer corrects tilt with Table 5's alpha (where the paper tuned it,
      and where it reads tilt); in flight it corrects through a proportional-integral complementary
      filter (Mahony's form, both poles at -1/tau_tilt_air) whose time constant is long beside the
      rotor-drag time M/k over which a flying multirotor's accelerometer comes to read tilt again.
      The integral term follows a wandering gyro bias, so the tilt stays bounded in long flights.
      Without rotor drag (the base model) the accelerometer reads no tilt in flight: tau_tilt_air = 0
      turns the correction off there.
    Yaw is fused with the magnetometer (eq. 32 restated for z up, eq. 35) in both.
    """
    __slots__ = ("a_ema", "a_rp", "a_yaw", "k_air", "ki_air", "paper", "in_flight", "p", "q", "r",
                 "roll", "pitch", "yaw", "droll", "dpitch", "dyaw", "bx", "by", "tilt_bias", "yaw_bias",
                 "use_mag", "roll_bias", "pitch_bias", "tau_rate", "a_rate", "rate_dt")

    def __init__(self, filters: Filters, structure: str = "flight"):
        if structure not in ESTIMATORS:
            raise ValueError(f"unknown estimator {structure!r} (known: {', '.join(ESTIMATORS)})")
        self.a_ema, self.a_rp, self.a_yaw = filters.alpha_ema, filters.alpha_roll_pitch, filters.alpha_yaw
        w = 1.0 / filters.tau_tilt_air if filters.tau_tilt_air > 0.0 else 0.0   # 0: no correction in flight
        self.k_air, self.ki_air = 2.0 * w, w * w    # (s + w)^2 = s^2 + k s + ki: critically damped
        self.tau_rate, self.a_rate, self.rate_dt = filters.tau_rate, 1.0, 0.0   # the D path's EMA (eq. 39's alpha)
        self.paper = structure == "paper"
        self.in_flight = False
        self.set_reference((0.0, 0.0), 0.0, False)

    def set_reference(self, tilt_bias: tuple[float, float], yaw_bias: float, use_mag: bool) -> None:
        """The calibration's accelerometer-angle biases and magnetic heading reference; restarts."""
        self.tilt_bias, self.yaw_bias, self.use_mag = tilt_bias, yaw_bias, use_mag
        self.roll_bias, self.pitch_bias = tilt_bias
        self.roll = self.pitch = self.yaw = 0.0
        self.p = self.q = self.r = 0.0
        self.droll = self.dpitch = self.dyaw = 0.0
        self.bx = self.by = 0.0     # in-flight gyro bias estimate (rad/s), body x and y

    def update(self, s: ImuSample, dt: float) -> None:
        """One loop: `s` holds calibrated gyro rates (the still bias removed)."""
        roll, pitch, yaw = self.roll, self.pitch, self.yaw
        sr, cr, sp, cp = sin(roll), cos(roll), sin(pitch), cos(pitch)
        if self.paper:
            a = self.a_ema
            b = 1.0 - a
            p = self.p = a * s.gx + b * self.p      # eq. 36-38
            q = self.q = a * s.gy + b * self.q
            r = self.r = a * s.gz + b * self.r
        else:
            p, q, r = s.gx - self.bx, s.gy - self.by, s.gz
        w = q * sr + r * cr                         # Z-Y-X Euler-angle rates of the body rates
        droll, dpitch, dyaw = p + w * sp / cp, q * cr - r * sr, w / cp
        if not self.paper and self.tau_rate > 0.0:  # the D term's rates through their EMA (eq. 36-39's form)
            if dt != self.rate_dt:
                self.rate_dt, self.a_rate = dt, 1.0 - exp(-dt / self.tau_rate)
            a = self.a_rate
            b = 1.0 - a
            fp = self.p = a * p + b * self.p
            fq = self.q = a * q + b * self.q
            fr = self.r = a * r + b * self.r
            fw = fq * sr + fr * cr
            rate_roll, rate_pitch, rate_yaw = fp + fw * sp / cp, fq * cr - fr * sr, fw / cp
        else:
            rate_roll, rate_pitch, rate_yaw = droll, dpitch, dyaw
        roll_g, pitch_g, yaw_g = roll + droll * dt, pitch + dpitch * dt, yaw + dyaw * dt
        ax, ay, az = s.ax, s.ay, s.az
        if self.paper or not self.in_flight:        # eq. 30-31, 33-34 with Table 5's alpha
            a = self.a_rp
            roll_g = a * roll_g + (1.0 - a) * (atan2(ay, az) - self.roll_bias)
            pitch_g = a * pitch_g + (1.0 - a) * (atan2(-ax, sqrt(ay * ay + az * az)) - self.pitch_bias)
        else:                                       # the in-flight PI correction
            er = atan2(ay, az) - self.roll_bias - roll_g
            ep = atan2(-ax, sqrt(ay * ay + az * az)) - self.pitch_bias - pitch_g
            k = self.k_air * dt
            roll_g += k * er
            pitch_g += k * ep
            ki = self.ki_air * dt                   # the error in Euler rates, back to body x and y
            self.bx -= ki * er
            self.by -= ki * (ep * cr)
        if self.use_mag and s.mag_fresh:         # eq. 35, the difference taken across +-pi
            # level the field with the chip's own tilt (estimate plus mounting bias), as the
            # calibration did when it took the heading reference
            yaw_mag = heading_from_mag(s.mx, s.my, s.mz, roll_g + self.roll_bias,
                                       pitch_g + self.pitch_bias) - self.yaw_bias
            yaw_g += (1.0 - self.a_yaw) * ((yaw_mag - yaw_g + pi) % TWO_PI - pi)
        yaw_g = (yaw_g + pi) % TWO_PI - pi
        if self.paper:   # eq. 24 literally: the difference quotient of the fused angles
            rate_roll, rate_pitch = (roll_g - roll) / dt, (pitch_g - pitch) / dt
            rate_yaw = ((yaw_g - yaw + pi) % TWO_PI - pi) / dt
        self.droll, self.dpitch, self.dyaw = rate_roll, rate_pitch, rate_yaw
        self.roll, self.pitch, self.yaw = roll_g, pitch_g, yaw_g


class Calibration:
    """Section 4.4.4: sit still, average the gyro (its bias), the accelerometer angles (their bias)
    and the magnetometer heading (the yaw reference). The paper sat for 1 minute."""

    def __init__(self):
        self.n = self.n_mag = 0
        self.sums = [0.0] * 7   # gx, gy, gz, roll, pitch, cos(heading), sin(heading)
        self.gyro_bias = (0.0, 0.0, 0.0)

    def add(self, s: ImuSample) -> None:
        self.n += 1
        m = self.sums
        m[0] += s.gx
        m[1] += s.gy
        m[2] += s.gz
        roll, pitch = tilt_from_accel(s.ax, s.ay, s.az)
        m[3] += roll
        m[4] += pitch
        if s.mag_fresh:
            h = heading_from_mag(s.mx, s.my, s.mz, roll, pitch)
            self.n_mag += 1
            m[5] += cos(h)
            m[6] += sin(h)

    def apply(self, estimator) -> None:
        """Fix the gyro bias (subtract it with `correct`) and give the estimator its references."""
        if self.n == 0:
            raise RuntimeError("calibration took no IMU samples")
        m, n = self.sums, self.n
        self.gyro_bias = (m[0] / n, m[1] / n, m[2] / n)
        use_mag = self.n_mag > 0
        estimator.set_reference((m[3] / n, m[4] / n), atan2(m[6], m[5]) if use_mag else 0.0, use_mag)

    def correct(self, s: ImuSample) -> None:
        b = self.gyro_bias
        s.gx -= b[0]
        s.gy -= b[1]
        s.gz -= b[2]
