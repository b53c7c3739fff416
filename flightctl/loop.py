"""The real-time loop, the same on the quadcopter and in simulation:

    clock tick -> Imu.read (SPI bytes -> SI) -> estimator -> PIDs -> mixer -> eq. 26 inverted
    -> Motors.write(counts) -> log row; the altitude task runs on rangefinder echoes (~45 Hz).

Lifecycle: calibrate sitting still (motors stopped), arm (the motors refuse for a named reason),
fly the plan, disarm on touchdown. The log starts at arming (its gyro columns are calibrated). Checks, each with a named reason: IMU frames going bad, a crash
(tilt past 60 degrees), a low battery (land), the altitude lost (descend slowly). Whatever ends the
loop - the plan, a stop request (SIGTERM), an exception - the motors are stopped last.
"""
from __future__ import annotations

import math
import threading
from dataclasses import dataclass, field
from typing import Callable

from flightctl.control.controller import FlightController
from flightctl.control.estimator import Calibration
from flightctl.hal import PWM_RANGE, Hal, ImuSample
from flightctl.logfile import FlightLogWriter
from flightctl.params import Params
from flightctl.plan import Move, Plan

MAX_BAD_IMU_FRAMES = 10         # consecutive (22 ms)
CRASH_TILT = math.radians(60)
LOW_CELL_V, CELLS = 3.5, 4      # land below 14.0 V on a 4S pack
LAND_SPEED = 0.3                # m/s, a landing commanded by the checks
LOST_ALT_S = 1.0                # no valid echo for this long in the air: descend blind
TOUCHDOWN_ALT, TOUCHDOWN_S = 0.05, 0.5


@dataclass
class FlightResult:
    reason: str = "plan complete"   # why the loop ended
    events: list[tuple[float, str]] = field(default_factory=list)
    iterations: int = 0
    overruns: int = 0               # deadlines missed by the wall clock (always 0 in simulation)


class FlightLoop:
    def __init__(self, hal: Hal, params: Params, plan: Plan, log: FlightLogWriter | None = None,
                 controller: FlightController | None = None, calibrate_s: float = 60.0,
                 stop: threading.Event | None = None, on_tick: Callable[[int], None] | None = None,
                 extra_row: Callable[[], tuple] | None = None):
        self.hal, self.params, self.plan, self.log = hal, params, plan, log
        self.ctl = controller if controller is not None else FlightController(params)
        self.calibrate_s = calibrate_s
        self.stop = stop if stop is not None else threading.Event()
        self.on_tick = on_tick          # e.g. the systemd watchdog ping
        self.extra_row = extra_row      # extra log columns (the simulator's truth)
        self.result = FlightResult()

    def _event(self, t: float, what: str) -> None:
        self.result.events.append((t, what))

    def run(self) -> FlightResult:
        hal = self.hal
        try:
            hal.motors.stop()
            self._fly()
        finally:
            hal.motors.stop()
            if self.log is not None:
                self.log.close()
        return self.result

    def _fly(self) -> None:
        hal, ctl, plan, a = self.hal, self.ctl, self.plan, self.params.airframe
        clock, imu, motors, sonar, power = hal.clock, hal.imu, hal.motors, hal.rangefinder, hal.power
        sample = ImuSample()
        calibration = Calibration()
        res = self.result
        log_append = self.log.append if self.log is not None else None
        extra = self.extra_row
        stop_counts = [0, 0, 0, 0]
        p_per_count = 255.0 / PWM_RANGE
        sonar_every = max(1, round(a.loop_hz / a.sonar_hz))
        power_every = max(1, round(a.loop_hz / 10.0))
        dt = clock.period
        t0 = clock.now()
        t_arm = t0 + self.calibrate_s
        armed = flying = False
        bad_frames = 0
        battery_v, _ = power.read()
        last_echo = t_touch = None
        landing = False
        i = 0
        while not self.stop.is_set():
            t = clock.wait_next()
            i += 1
            if self.on_tick is not None:
                self.on_tick(i)
            if imu.read(sample):
                calibration.correct(sample)
                bad_frames = 0
            else:
                bad_frames += 1
                if bad_frames > MAX_BAD_IMU_FRAMES:
                    res.reason = "stopped: IMU frames bad"
                    self._event(t - t0, res.reason)
                    break
            if i % power_every == 0:
                battery_v, _ = power.read()
            if i % sonar_every == 0:
                sonar.trigger()
            echo = sonar.poll()
            range_cell = ""
            if not armed:
                calibration.add(sample)
                counts = stop_counts
                sp = plan.sp
                if t >= t_arm:
                    calibration.apply(ctl.est)
                    motors.arm()
                    armed = flying = ctl.est.in_flight = True
                    last_echo = t
                    self._event(t - t0, "armed")
            else:
                sp = plan.at(t - t_arm)
                if echo is not None:
                    if echo == echo:
                        range_cell = "%.4f" % echo
                        last_echo = t
                    if flying:
                        ctl.on_range(echo, t)
                if flying:
                    counts = ctl.step(sample, dt, sp[0], sp[1], sp[2], sp[3])
                    est = ctl.est
                    if not (abs(est.roll) <= CRASH_TILT and abs(est.pitch) <= CRASH_TILT):   # NaN too
                        res.reason = "stopped: crash (tilt past 60 degrees)"
                        self._event(t - t0, res.reason)
                        break
                    if not landing and battery_v < LOW_CELL_V * CELLS:
                        landing = self._land(t - t_arm, ctl.alt, "battery low: landing")
                        plan = self.plan
                    if t - last_echo > LOST_ALT_S and ctl.alt > TOUCHDOWN_ALT:
                        ctl.uz = -0.1 * a.B    # no altitude: descend slowly, open loop
                        ctl.alt = max(ctl.alt - LAND_SPEED * dt, 0.0)
                        if not landing:
                            landing = self._land(t - t_arm, ctl.alt, "altitude lost: descending")
                            plan = self.plan
                    if sp[3] <= 0.0 and ctl.alt < TOUCHDOWN_ALT and (plan.lands() or landing):
                        t_touch = t_touch if t_touch is not None else t
                        if t - t_touch > TOUCHDOWN_S:
                            flying = ctl.est.in_flight = False
                            motors.stop()
                            self._event(t - t0, "landed: motors stopped")
                    else:
                        t_touch = None
                else:
                    counts = stop_counts
                    ctl.step(sample, dt, 0.0, 0.0, ctl.est.yaw, 0.0)   # keep estimating on the ground
                if t - t_arm >= plan.duration:
                    break
            if flying:
                motors.write(counts)
            if log_append is not None and armed:   # the log starts at arming, with the gyro calibrated
                est = ctl.est
                row = (t - t_arm, counts[0] * p_per_count, counts[1] * p_per_count, counts[2] * p_per_count,
                       counts[3] * p_per_count, sample.gx, sample.gy, sample.gz, sample.ax, sample.ay, sample.az, range_cell, battery_v,
                       est.roll, est.pitch, est.yaw, ctl.alt, sp[0], sp[1], sp[2], sp[3],
                       sample.mx, sample.my, sample.mz)
                log_append(row + extra() if extra is not None else row)
        res.iterations = i
        if self.stop.is_set():
            res.reason = "stopped: stop requested"
            self._event(clock.now() - t0, res.reason)

    def _land(self, t_plan: float, alt: float, why: str) -> bool:
        """Replace the rest of the plan by a descent from here at LAND_SPEED and a touchdown."""
        self._event(t_plan + self.calibrate_s, why)
        ramp = max(alt, 0.0) / LAND_SPEED
        self.plan = plan = Plan([m for m in self.plan.moves if m.t <= t_plan]
                                + [Move(t_plan, "alt", 0.0, ramp)], self.plan.duration + ramp + 5.0)
        plan.at(t_plan)
        return True
