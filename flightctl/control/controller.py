"""The flight controller: estimator, four PIDs (eq. 24) and the mixer (eq. 25-26), and after a lost
motor the two-rotor controller (control/spin.py) on the landing's thrust. No I/O: the loop feeds it IMU
samples, echoes and setpoints and sends the PWM counts it leaves in `counts`."""
from __future__ import annotations

from math import cos, pi
from typing import TYPE_CHECKING

from flightctl.control.estimator import AttitudeEstimator
from flightctl.control.landing import Landing, Vertical
from flightctl.control.mixer import Mixer
from flightctl.control.pid import Pid
from flightctl.hal import ImuSample
from flightctl.params import Params
from flightctl.safety import LEFT_GROUND_ALT

if TYPE_CHECKING:
    from flightctl.control.spin import SpinController

MAX_CORRECT_DT = 0.05   # s: the vertical estimate's correction after a gap in the echoes, at most
TWO_PI = 2.0 * pi


class FlightController:
    __slots__ = ("est", "mixer", "pid_z", "pid_roll", "pid_pitch", "pid_yaw", "counts",
                 "uz", "alt", "alt_prev", "alt_sp", "alt_t", "sonar_period", "vert", "landing", "landing_on",
                 "B", "spin")

    def __init__(self, params: Params, estimator=None, structure: str = "flight"):
        a, g = params.airframe, params.gains
        B = self.B = a.B  # Table 3: every u within [-B, B]
        self.est = estimator if estimator is not None else AttitudeEstimator(params.filters, structure)
        self.mixer = Mixer(a)
        self.pid_z = Pid(g.kp_z, g.ki_z, g.kd_z, B)
        self.pid_roll = Pid(g.kp_phi, g.ki_phi, g.kd_phi, B)
        self.pid_pitch = Pid(g.kp_theta, g.ki_theta, g.kd_theta, B)
        self.pid_yaw = Pid(g.kp_psi, g.ki_psi, g.kd_psi, B, angle=True)
        self.counts = [0, 0, 0, 0]
        self.sonar_period = 1.0 / a.sonar_hz
        self.vert = Vertical()
        self.landing = Landing(a.M)
        self.spin = None        # the two-rotor controller, once a motor is lost (`start_two_rotors`)
        self.reset()

    def reset(self) -> None:
        """Back to the state on the ground before take-off."""
        for pid in (self.pid_z, self.pid_roll, self.pid_pitch, self.pid_yaw):
            pid.reset()
        self.uz = 0.0
        self.alt = self.alt_prev = 0.0
        self.alt_sp = 0.0
        self.alt_t = None
        self.landing_on = False

    def arm(self, s: ImuSample) -> None:
        """At arming, on the floor: the vertical estimate starts at rest at z = 0; the estimator is in
        flight from now on (its in-flight tilt correction)."""
        self.vert.reset(s.ax, s.ay, s.az)
        self.est.in_flight = True

    def touchdown(self) -> None:
        """On the floor after the flight, the motors stopped: the estimator's ground filter again."""
        self.est.in_flight = False

    def land(self, speed: float) -> None:
        """From now on u_z comes from the landing (flightctl/control/landing.py), not the altitude
        PID: a descent at `speed` (m/s) from the hover thrust the PID has learned, to a touchdown the
        accelerometer confirms (`landing.landed`)."""
        self.landing.start(self.pid_z.integral, speed)
        self.landing_on = True

    def on_range(self, distance: float, t: float) -> None:
        """The altitude task, run on each echo (about 45 Hz): the range along -z_b, levelled by the
        estimated tilt, is the altitude. A failed measurement (NaN: no echo, or closer than the
        sensor's 2 cm, as on the floor) holds the last altitude near the floor, so that a rising
        setpoint lifts the vehicle off it; above LEFT_GROUND_ALT the vertical estimate
        (flightctl/control/landing.py: the accelerometer since the last echo) stands in for it."""
        dt = t - self.alt_t if self.alt_t is not None else self.sonar_period
        self.alt_t = t
        if distance == distance:
            est = self.est
            self.alt = alt = distance * cos(est.roll) * cos(est.pitch)
            if dt > 0.0:
                self.vert.correct(alt, dt if dt < MAX_CORRECT_DT else MAX_CORRECT_DT)
        elif self.alt > LEFT_GROUND_ALT:   # lower, a lost echo is the floor's
            self.alt = self.vert.z
        if self.landing_on:
            return
        if dt > 0.0:   # eq. 24: the derivative is the difference quotient of the altitude
            self.uz = self.pid_z.update(self.alt_sp, self.alt, (self.alt - self.alt_prev) / dt, dt)
            self.alt_prev = self.alt

    def step(self, s: ImuSample, dt: float, roll_sp: float, pitch_sp: float, yaw_sp: float,
             alt_sp: float) -> list[int]:
        est = self.est
        est.update(s, dt)
        self.alt_sp = alt_sp
        roll, pitch = est.roll, est.pitch
        vert = self.vert
        vert.predict(s.ax, s.ay, s.az, roll, pitch, dt)
        if self.landing_on:
            self.uz = self.landing.step(vert, dt)
            self.alt = vert.z
        self.mixer.mix(self.uz,
                       self.pid_roll.update(roll_sp, roll, est.droll, dt),
                       self.pid_pitch.update(pitch_sp, pitch, est.dpitch, dt),
                       self.pid_yaw.update(yaw_sp, est.yaw, est.dyaw, dt),
                       roll, pitch, self.counts)
        return self.counts

    def start_two_rotors(self, spin: SpinController, lost: int) -> None:
        """Motor `lost` (1..4) is gone: from now on `step_two_rotors` flies the pair of the other arm
        (`spin`, built at start-up: its gains come from a disk cache) from the attitude now and the
        thrusts the mixer commanded last; the loop's landing (`land`) gives the thrust."""
        est = self.est
        spin.start(lost, est.roll, est.pitch, est.yaw, self.mixer.f)
        self.spin = spin

    def step_two_rotors(self, s: ImuSample, dt: float) -> list[int]:
        """One loop on two rotors: the landing's thrust per motor (control/landing.py) as the pair's
        total, the attitude the spin controller integrates in place of the estimator's (yaw given up:
        the spin's, wrapped), the vertical estimate on it; the pair's counts."""
        spin, vert, est = self.spin, self.vert, self.est
        counts = spin.step(s, dt, 4.0 * (self.B + self.landing.step(vert, dt)))
        est.roll, est.pitch = roll, pitch = spin.tilt()
        est.yaw = (spin.yaw + pi) % TWO_PI - pi
        vert.predict(s.ax, s.ay, s.az, roll, pitch, dt)
        self.alt = vert.z
        return counts
