"""The real-time loop, the same on the quadcopter and in simulation:

    clock tick -> Imu.read (SPI bytes -> SI) -> estimator -> PIDs -> mixer -> eq. 26 inverted
    -> Motors.write(counts) -> log row; the altitude task runs on rangefinder echoes (~45 Hz).

Lifecycle: calibrate sitting still (motors stopped), arm (the motors refuse for a named reason),
fly the plan, disarm on touchdown. The log starts at arming (its gyro columns are calibrated). Checks, each with a named reason: IMU frames going bad, a crash
(flightctl/safety.py: tilt past 60 degrees), a low battery (land), a battery reading no pack can give
(flightctl/battery.py: not armed; in the air, land), the altitude lost (land on the accelerometer).
The motors are cut in the air only for a crash, bad IMU frames or a stop request (SIGTERM, the kill
command); every ordinary event lands under control (`_land`: level, descend at LAND_SPEED on the
vertical estimate, feel for the floor, stop when the accelerometer confirms it: control/landing.py): the plan ending in the air (a landing move after `duration` included), the log writer
failing (a full disk; the writer drops rows, never stops the loop), a failed watchdog ping (the notify
socket lost: systemd would kill the process), a plan that fails or gives a non-finite setpoint.
Event times are seconds since arming, the log's `t`. Whatever ends the loop - the plan, a stop
request, an exception - the motors are stopped last.
"""
from __future__ import annotations

import math
import threading
from dataclasses import dataclass, field
from typing import Callable

from flightctl.battery import CELLS, LOW_CELL_V, implausible
from flightctl.control.controller import FlightController
from flightctl.control.estimator import Calibration
from flightctl.control.motor_loss import MotorLossDetector, flown_on_four
from flightctl.control.spin import SpinController
from flightctl.hal import PWM_RANGE, Hal, ImuSample
from flightctl.logfile import FlightLogWriter
from flightctl.params import Params
from flightctl.plans.plan import Move, Plan
from flightctl.safety import CRASH_TILT, LEFT_GROUND_ALT

MAX_BAD_IMU_FRAMES = 10         # consecutive refused IMU frames flown on the last good sample (22 ms),
#                                 then the motors stop (drivers/mpu9250.py's checks; docs/safety.md)
LAND_SPEED = 0.3                # m/s, a landing commanded by the checks
LOST_ALT_S = 1.0                # no valid echo for this long in the air: descend blind
TOUCHDOWN_ALT, TOUCHDOWN_S = 0.05, 0.5
LAND_LEVEL_S = 1.0              # s: roll and pitch ramp back to level when a landing begins
LAND_SLACK_S = 30.0             # s beyond the descent for the touchdown to be detected
STALL_PERIODS = 1.5             # a tick later than this many periods after the last: the loop stalled
MAX_STALL_EVENTS = 10           # stalls named in events (a loaded CPU is not a flood); all are counted
ATTITUDE_LOST = math.radians(20)   # roll or pitch this far from its setpoint ...
ATTITUDE_LOST_LOOPS = 9            # ... for this many loops (20 ms): a motor or propeller lost (named)


@dataclass
class FlightResult:
    reason: str = "plan complete"   # why the loop ended
    events: list[tuple[float, str]] = field(default_factory=list)
    iterations: int = 0
    overruns: int = 0               # deadlines the loop reached late (the clock's count: the wall clock's on the
    #                                 Pi, the late clock's in simulation, sim/world/lateness.py; else 0)
    stalls: int = 0                 # ticks that came after missed ones (STALL_PERIODS; the first MAX_STALL_EVENTS named)
    t_arm: float | None = None      # clock time of arming (log time 0)
    max_alt: float = 0.0            # highest altitude estimate in flight (m)


class FlightLoop:
    def __init__(self, hal: Hal, params: Params, plan: Plan, log: FlightLogWriter | None = None,
                 controller: FlightController | None = None, calibrate_s: float = 60.0,
                 stop: threading.Event | None = None, on_tick: Callable[[int], bool | None] | None = None,
                 extra_row: Callable[[], tuple] | None = None, telemetry=None):
        self.hal, self.params, self.plan, self.log = hal, params, plan, log
        self.ctl = controller if controller is not None else FlightController(params)
        self.calibrate_s = calibrate_s
        self.stop = stop if stop is not None else threading.Event()
        self.on_tick = on_tick          # e.g. the systemd watchdog ping; False: the ping failed
        self.extra_row = extra_row      # extra log columns (the simulator's truth)
        self.telemetry = telemetry      # a ground station link (flightctl/comms/mavlink.py): start, poll, may_arm, tick
        self.result = FlightResult()
        self.t_arm = 0.0                # clock time of arming (event times are since then)
        self._why = ""                  # why the loop began a landing the plan did not ask for
        self.stop_reason = "stop requested"   # what `stop` means here (the simulator: Ctrl-C)

    def _event(self, t: float, what: str) -> None:
        self.result.events.append((t - self.t_arm, what))

    def run(self) -> FlightResult:
        """Fly; whatever ends it, the motors are stopped and the log closed, with a `# partial:` line
        when the flight was cut short (a stop request, Ctrl-C, an error)."""
        hal = self.hal
        cut = None
        try:
            hal.motors.stop()
            self._fly()
            if self.stop.is_set():
                cut = self.result.reason
        except BaseException as e:
            cut = "interrupted" if isinstance(e, KeyboardInterrupt) else f"ended by an error ({type(e).__name__})"
            raise
        finally:
            hal.motors.stop()
            if self.log is not None:
                if cut is not None and self.log.partial is None:
                    t = hal.clock.now() - self.t_arm
                    self.log.partial = f"{cut} at t = {t:.3f} s" if t >= 0.0 else f"{cut} before arming"
                self.log.close()
                if self.log.dropped:
                    self._event(hal.clock.now(), f"log: {self.log.dropped} rows dropped ({self.log.error})")
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
        self.t_arm = t_arm = t0 + self.calibrate_s
        armed = flying = False
        bad_frames = 0
        imu_seen: set[str] = set()   # reasons of refused IMU frames already named in an event
        imu_saturated = False
        battery_v, _ = power.read()
        battery_why = implausible(battery_v, CELLS)   # None, or why the reading is no pack's
        battery_said = False
        last_echo = t_touch = None
        landing = log_failed = blind = finished = False
        max_alt = 0.0
        i = 0
        t_prev = None
        stalls = off_loops = 0
        detector, spin = MotorLossDetector(self.params), SpinController(self.params)
        spinning = False             # a motor lost: flying on two rotors, yaw given up (control/spin.py)
        vert = ctl.vert
        tel = self.telemetry
        if tel is not None:
            tel.start(res)
        while not self.stop.is_set():
            t = clock.wait_next()
            i += 1
            if t_prev is not None and t - t_prev > STALL_PERIODS * dt:   # missed ticks: fly on (hold)
                stalls += 1
                if stalls <= MAX_STALL_EVENTS:
                    self._event(t, f"loop stalled {1000 * (t - t_prev):.0f} ms "
                                   f"({round((t - t_prev) / dt) - 1} ticks missed): holding")
            t_prev = t
            cmd = tel.poll() if tel is not None else None      # "kill" or "land" from the ground station
            if cmd == "kill":
                res.reason = "stopped: killed by the ground station (forced disarm)"
                self._event(t, res.reason)
                break
            if self.on_tick is not None and self.on_tick(i) is False and flying and not landing:
                landing = self._land(t, ctl.alt, "watchdog ping failed (notify socket lost): landing")
                plan = self.plan
            if imu.read(sample):
                calibration.correct(sample)
                bad_frames = 0
                if imu_saturated is False and getattr(imu, "saturated", False):
                    imu_saturated = True      # flown on the full-scale value; the crash check decides
                    self._event(t, "IMU saturated (a word at full scale): flying on the clipped value")
            else:
                bad_frames += 1
                why = getattr(imu, "why", "") or "bad frame"
                if why not in imu_seen:       # once per reason: an intermittent fault is not a flood
                    imu_seen.add(why)
                    self._event(t, f"IMU frame refused ({why}): holding the last good sample")
                if bad_frames > MAX_BAD_IMU_FRAMES:
                    self._event(t, f"IMU frames bad ({why}) for {bad_frames} loops: motors stopped")
                    res.reason = "stopped: IMU frames bad"
                    self._event(t, res.reason)
                    break
            if i % power_every == 0:
                battery_v, _ = power.read()
                battery_why = implausible(battery_v, CELLS)
            if i % sonar_every == 0:
                sonar.trigger()
            echo = sonar.poll()
            range_cell = ""
            if not armed:
                calibration.add(sample)
                counts = stop_counts
                sp = plan.sp
                if t >= t_arm and battery_why is not None:    # pre-arm: a reading no pack gives
                    res.reason = f"stopped: not armed: {battery_why}"
                    self._event(t, res.reason)
                    break
                if t >= t_arm and (tel is None or tel.may_arm()):
                    if tel is not None and tel.arm_required:   # armed by the ground station: the log starts now
                        self.t_arm = t_arm = t
                    calibration.apply(ctl.est)
                    ctl.arm(sample)
                    motors.arm()
                    armed = flying = ctl.est.in_flight = True
                    detector.reset(a.B)
                    last_echo = t
                    res.t_arm = t_arm
                    self._event(t, "armed")
                    if spin.why_not:
                        self._event(t, f"no two-rotor landing after a lost motor on this vehicle: {spin.why_not}")
            else:
                try:
                    sp = plan.at(t - t_arm)
                    s = sp[0] + sp[1] + sp[2] + sp[3]
                    if s - s != 0.0:                                  # NaN or infinite
                        raise ValueError("a non-finite setpoint")
                except Exception as e:
                    if landing:
                        raise                                        # the landing plan itself: a bug
                    if not flying:                                   # on the ground, motors stopped
                        res.reason = f"stopped: plan failed ({e})"
                        self._event(t, res.reason)
                        break
                    landing = self._land(t, ctl.alt, f"plan failed ({e}): landing")
                    plan = self.plan
                    sp = plan.sp
                if log_failed is False and self.log is not None and self.log.failed:
                    log_failed = True
                    if flying and not landing:
                        landing = self._land(t, ctl.alt, f"log write failed ({self.log.error}): landing")
                        plan = self.plan
                        sp = plan.sp
                if cmd == "land" and flying and not landing:
                    landing = self._land(t, ctl.alt, "land commanded by the ground station: landing")
                    plan = self.plan
                if echo is not None:
                    if echo == echo:
                        range_cell = "%.4f" % echo
                        last_echo = t
                    if flying:
                        ctl.on_range(echo, t)
                        if echo == echo and ctl.alt > TOUCHDOWN_ALT:
                            detector.lifted()          # off the floor: a lost motor is looked for
                if flying:
                    lost = 0 if spinning else detector.update(sample, ctl.mixer.f, dt, ctl.alt < TOUCHDOWN_ALT)
                    if lost:
                        giving = 1.0 - detector.missing
                        if spin.why_not or flown_on_four(self.params, lost, giving):
                            detector.accept()          # flown on four rotors: a weak motor, or no other way
                            self._weak(t, lost, giving, spin.why_not, landing, ctl.alt)
                            landing = True
                        else:
                            spinning = landing = True
                            self._spin(t, lost, giving, detector.fast, spin, ctl.alt)
                        plan = self.plan
                        sp = plan.sp
                    est = ctl.est
                    if spinning:               # the landing's thrust, on two rotors
                        uz = ctl.landing.step(vert, dt)
                        counts = spin.step(sample, dt, 4.0 * (a.B + uz))
                        est.roll, est.pitch = roll, pitch = spin.tilt()
                        est.yaw = (spin.yaw + math.pi) % (2.0 * math.pi) - math.pi
                        vert.predict(sample.ax, sample.ay, sample.az, roll, pitch, dt)
                        ctl.alt = vert.z
                    else:
                        counts = ctl.step(sample, dt, sp[0], sp[1], sp[2], sp[3])
                    if not (abs(est.roll) <= CRASH_TILT and abs(est.pitch) <= CRASH_TILT):   # NaN too
                        res.reason = f"stopped: crash (tilt past {math.degrees(CRASH_TILT):.0f} degrees)"
                        self._event(t, res.reason)
                        break
                    if not spinning and (abs(est.roll - sp[0]) > ATTITUDE_LOST or abs(est.pitch - sp[1]) > ATTITUDE_LOST):
                        off_loops += 1
                        if off_loops == ATTITUDE_LOST_LOOPS:     # the crash check stops at CRASH_TILT
                            self._event(t, "attitude not held for %d loops: motor %d commanded hardest "
                                           "(a motor or propeller lost?)" % (off_loops, counts.index(max(counts)) + 1))
                    else:
                        off_loops = 0
                    if ctl.alt > max_alt:
                        max_alt = ctl.alt
                    if battery_why is not None and not battery_said:   # the low check is blind on it
                        battery_said = True
                        if landing:
                            self._event(t, battery_why + ": the landing goes on")
                        else:
                            landing = self._land(t, ctl.alt, battery_why + ": landing")
                            plan = self.plan
                    if not landing and battery_v < LOW_CELL_V * CELLS:
                        landing = self._land(t, ctl.alt, "battery low: landing")
                        plan = self.plan
                    if not blind and t - last_echo > LOST_ALT_S and ctl.alt > TOUCHDOWN_ALT:   # (NaN at the floor)
                        blind = True           # descend on the accelerometer (control/landing.py)
                        why = f"altitude lost (no valid echo for {LOST_ALT_S:g} s)"
                        if landing:
                            self._event(t, why + ": the landing goes on, on the accelerometer")
                        else:
                            landing = self._land(t, ctl.vert.z, why + ": landing")
                            plan = self.plan
                    if landing:                # the accelerometer confirms the floor
                        touched = ctl.landing.landed
                    else:                      # the plan's own landing, on the sonar
                        if sp[3] <= 0.0 and ctl.alt < TOUCHDOWN_ALT and plan.lands():
                            t_touch = t_touch if t_touch is not None else t
                        else:
                            t_touch = None
                        touched = t_touch is not None and t - t_touch > TOUCHDOWN_S
                    if touched:
                        flying = ctl.est.in_flight = False
                        motors.stop()
                        self._event(t, "landed: motors stopped")
                        if max_alt < LEFT_GROUND_ALT:
                            self._event(t, f"never left the ground (highest altitude {max_alt:.2f} m)")
                        if self._why:
                            res.reason = "landed: " + self._why.rsplit(": ", 1)[0]
                        counts = stop_counts
                        # the loop's own landing is the plan's end; so is a touchdown confirmed after it
                        finished = landing or t - t_arm >= plan.duration
                else:
                    counts = stop_counts
                    ctl.step(sample, dt, 0.0, 0.0, ctl.est.yaw, 0.0)   # keep estimating on the ground
                if t - t_arm >= plan.duration and not finished:
                    if not flying:
                        break
                    if landing:          # the landing's own end: the touchdown was never detected
                        res.reason = "stopped: no touchdown detected by the end of the landing"
                        self._event(t, res.reason)
                        break
                    if max_alt < LEFT_GROUND_ALT:   # the sonar never saw it leave the floor: nothing to land
                        motors.stop()
                        self._event(t, f"never left the ground (highest altitude {max_alt:.2f} m): motors stopped")
                        break
                    if t_touch is None:        # (else the plan's own touchdown is under way: it ends within TOUCHDOWN_S)
                        landing = self._land(t, ctl.alt, f"plan ended in the air at {ctl.alt:.2f} m: landing")
                        plan = self.plan
            if flying:
                motors.write(counts)
            if log_append is not None and armed:   # the log starts at arming, with the gyro calibrated
                est = ctl.est
                row = (t - t_arm, counts[0] * p_per_count, counts[1] * p_per_count, counts[2] * p_per_count,
                       counts[3] * p_per_count, sample.gx, sample.gy, sample.gz, sample.ax, sample.ay, sample.az, range_cell, battery_v,
                       est.roll, est.pitch, est.yaw, ctl.alt, sp[0], sp[1], sp[2], sp[3],
                       sample.mx, sample.my, sample.mz)
                log_append(row + extra() if extra is not None else row)
            if tel is not None:
                tel.tick(t, armed, flying, landing, sample, ctl.est, ctl.alt, echo, battery_v, counts, sp)
            if finished:
                break
        res.iterations = i
        res.overruns = getattr(clock, "overruns", 0)
        res.stalls = stalls
        res.max_alt = max_alt
        if self.stop.is_set():
            res.reason = f"stopped: {self.stop_reason}"
            self._event(clock.now(), res.reason)

    def _spin(self, t: float, lost: int, giving: float, fast: bool, spin: SpinController, alt: float) -> None:
        """Motor `lost` is gone (control/spin.py): from now on the spin controller flies the two rotors
        of the other arm down, on the landing's thrust (`_land`: the rest of the plan becomes a descent,
        the log's setpoint)."""
        est = self.ctl.est
        spin.start(lost, est.roll, est.pitch, est.yaw, self.ctl.mixer.f)
        a, b = (m + 1 for m in spin.pair)
        self._land(t, alt, f"motor {lost} lost ({'at least ' if fast else ''}{100 * (1 - giving):.0f} % of its "
                           f"thrust missing in torque and "
                           f"collective): motors {lost} and {spin.off[1] + 1} stopped, flying on motors {a} and {b}, "
                           f"yaw given up, spinning up toward {spin.r_bar:.0f} rad/s: landing")
        self._why = f"motor {lost} lost: landing on two rotors"   # even where the plan was landing already

    def _weak(self, t: float, motor: int, giving: float, why_not: str, landing: bool, alt: float) -> None:
        """Motor `motor` gives only `giving` of its thrust, and the loop flies on with four rotors
        (control/motor_loss.py `flown_on_four`, or no two-rotor mode on this vehicle): it lands."""
        what = (f"motor {motor} weak (giving about {100 * giving:.0f} % of its commanded thrust): flying on "
                f"four rotors" if not why_not else
                f"motor {motor} lost ({100 * (1 - giving):.0f} % of its thrust missing in torque and collective): "
                f"no two-rotor mode on this vehicle, flying on four rotors")
        if landing:
            self._event(t, what)
        else:
            self._land(t, alt, what + ": landing")

    def _land(self, t: float, alt: float, why: str) -> bool:
        """From clock time `t`: replace the rest of the plan by roll and pitch back to level and a
        descent at LAND_SPEED to a touchdown, within LAND_SLACK_S of the descent's end. The thrust
        comes from the landing (control/landing.py) from now on; the plan's altitude ramp is the log's
        setpoint."""
        self._event(t, why)
        self.ctl.land(LAND_SPEED)
        alt_sp = self.plan.sp[3]
        self._why = why if not alt_sp <= TOUCHDOWN_ALT else ""     # the plan was not landing already
        t_plan = t - self.t_arm
        ramp = max(alt, 0.0) / LAND_SPEED
        kept = [m for m in self.plan.moves if m.t <= t_plan and math.isfinite(m.value)]
        self.plan = plan = Plan(kept + [Move(t_plan, "roll", 0.0, LAND_LEVEL_S), Move(t_plan, "pitch", 0.0, LAND_LEVEL_S),
                                        Move(t_plan, "alt", 0.0, ramp)],
                                t_plan + ramp + LAND_SLACK_S, self.plan.name, self.plan.doc)
        plan.at(t_plan)
        return True
