"""The real-time loop, the same on the quadcopter and in simulation:

    clock tick -> Imu.read (SPI bytes -> SI) -> estimator -> PIDs -> mixer -> eq. 26 inverted
    -> Motors.write(counts) -> log row; the altitude task runs on rangefinder echoes (~45 Hz).

Lifecycle, as the loop's phases (`PHASES`, docs/architecture.md): `ground` (calibrate sitting still,
motors stopped; then arm, or the motors refuse for a named reason), `flying` (the plan), `landing`
(the loop's own, `_land`), `on two rotors` (a motor lost), `done` (disarmed on touchdown). The log starts at arming
(its gyro columns are calibrated). Checks, each with a named reason: IMU frames going bad, a crash
(flightctl/safety.py: tilt past 60 degrees), a low battery (land), a battery reading no pack can give
(flightctl/battery.py: not armed; in the air, land), the altitude lost (land on the accelerometer).
The motors are cut in the air only for a crash, bad IMU frames or a stop request (SIGTERM, the kill
command); every ordinary event lands under control (`_land`: level, descend at LAND_SPEED on the
vertical estimate, feel for the floor, stop when the accelerometer confirms it: control/landing.py): the plan ending
in the air (a landing move after `duration` included), the log writer
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
P_PER_COUNT = 255.0 / PWM_RANGE    # the log's motor columns: the command value P (0..255) of a PWM count

# The loop's phases (`FlightLoop.phase`), in the order a flight meets them; each tick runs the phase's
# own work (docs/architecture.md, "The loop's phases").
GROUND = "ground"            # on the floor before arming, motors stopped: the calibration takes the samples
FLYING = "flying"            # armed: the plan flown, its own landing (a touchdown the sonar reads) included
LANDING = "landing"          # the loop's own landing (`_land`: level, descend, the accelerometer feels the floor)
TWO_ROTORS = "on two rotors"  # a motor lost: the controller flies the other arm's pair down (control/spin.py)
DONE = "done"                # touched down, motors stopped: the estimate and the log's rows to the plan's end
PHASES = (GROUND, FLYING, LANDING, TWO_ROTORS, DONE)


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
        self.phase = GROUND             # the loop's phase (PHASES); `run` flies them in order
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
        """The loop: each tick the checks that hold in every phase (a stall, the ground station's kill,
        the watchdog's ping), the sensing, then the phase's own work, the motors and the log's row."""
        clock, tel, motors = self.hal.clock, self.telemetry, self.hal.motors
        res = self.result
        self._begin()
        on_tick, row = self.on_tick, self._row if self.log is not None else None
        i = 0
        if tel is not None:
            tel.start(res)
        while not self.stop.is_set():
            t = clock.wait_next()
            i += 1
            self._stalled(t)
            cmd = tel.poll() if tel is not None else None      # "kill" or "land" from the ground station
            if cmd == "kill":
                self._stop(t, "stopped: killed by the ground station (forced disarm)")
                break
            if on_tick is not None and on_tick(i) is False and self.phase is FLYING:
                self._land(t, self.ctl.alt, "watchdog ping failed (notify socket lost): landing")
            if self._sense(t, i):
                break
            if self.phase is GROUND:
                if self._ground(t):
                    break
            elif self._setpoint(t) or self._armed(t, cmd) or self._plan_end(t):
                break
            phase = self.phase
            if phase is not GROUND:
                if phase is not DONE:
                    motors.write(self.counts)
                if row is not None:           # the log starts at arming, with the gyro calibrated
                    row(t)
            if tel is not None:
                tel.tick(t, phase is not GROUND, phase is not GROUND and phase is not DONE,
                         phase is LANDING or phase is TWO_ROTORS, self.sample, self.ctl.est, self.ctl.alt,
                         self.echo, self.battery_v, self.counts, self.sp)
            if self._last:
                break
        res.iterations = i
        res.overruns = getattr(clock, "overruns", 0)
        res.stalls = self._stalls
        res.max_alt = self.max_alt
        if self.stop.is_set():
            res.reason = f"stopped: {self.stop_reason}"
            self._event(clock.now(), res.reason)

    def _begin(self) -> None:
        """The flight's state before the first tick: on the ground, calibrating until `t_arm`."""
        hal, a = self.hal, self.params.airframe
        self.phase = GROUND
        self.sample = ImuSample()
        self.calibration = Calibration()
        self.counts = self._stopped = [0, 0, 0, 0]
        self._sonar_every = max(1, round(a.loop_hz / a.sonar_hz))
        self._power_every = max(1, round(a.loop_hz / 10.0))
        self._dt = hal.clock.period
        self.t_arm = hal.clock.now() + self.calibrate_s
        self._bad_frames = 0
        self._imu_seen: set[str] = set()   # reasons of refused IMU frames already named in an event
        self._imu_saturated = False
        self.battery_v, _ = hal.power.read()
        self._battery_why = implausible(self.battery_v, CELLS)   # None, or why the reading is no pack's
        self._battery_said = False
        self._last_echo = self._t_touch = None
        self._log_failed = self._blind = self._last = False
        self.max_alt = 0.0
        self._t_prev = None
        self._stalls = self._off_loops = 0
        self.echo, self.range_cell = None, ""
        self.sp = self.plan.sp
        self.detector, self.spin = MotorLossDetector(self.params), SpinController(self.params)

    def _stop(self, t: float, reason: str) -> bool:
        """The loop ends now, for `reason` (the motors are stopped by `run`)."""
        self.result.reason = reason
        self._event(t, reason)
        return True

    # -- the checks of every phase ------------------------------------------------------------------
    def _stalled(self, t: float) -> None:
        """Missed ticks: named (the first MAX_STALL_EVENTS), counted, flown on (hold)."""
        t_prev, dt = self._t_prev, self._dt
        if t_prev is not None and t - t_prev > STALL_PERIODS * dt:
            self._stalls += 1
            if self._stalls <= MAX_STALL_EVENTS:
                self._event(t, f"loop stalled {1000 * (t - t_prev):.0f} ms "
                               f"({round((t - t_prev) / dt) - 1} ticks missed): holding")
        self._t_prev = t

    # -- the sensing --------------------------------------------------------------------------------
    def _sense(self, t: float, i: int) -> bool:
        """The IMU's frame (calibrated; a refused one holds the last sample, too many stop the loop:
        True), the power monitor at 10 Hz, the sonar's trigger and its echo (`echo`, `range_cell`)."""
        hal, sample = self.hal, self.sample
        imu = hal.imu
        if imu.read(sample):
            self.calibration.correct(sample)
            self._bad_frames = 0
            if self._imu_saturated is False and getattr(imu, "saturated", False):
                self._imu_saturated = True      # flown on the full-scale value; the crash check decides
                self._event(t, "IMU saturated (a word at full scale): flying on the clipped value")
        else:
            self._bad_frames = bad = self._bad_frames + 1
            why = getattr(imu, "why", "") or "bad frame"
            if why not in self._imu_seen:       # once per reason: an intermittent fault is not a flood
                self._imu_seen.add(why)
                self._event(t, f"IMU frame refused ({why}): holding the last good sample")
            if bad > MAX_BAD_IMU_FRAMES:
                self._event(t, f"IMU frames bad ({why}) for {bad} loops: motors stopped")
                return self._stop(t, "stopped: IMU frames bad")
        if i % self._power_every == 0:
            self.battery_v, _ = hal.power.read()
            self._battery_why = implausible(self.battery_v, CELLS)
        if i % self._sonar_every == 0:
            hal.rangefinder.trigger()
        self.echo = hal.rangefinder.poll()
        self.range_cell = ""
        return False

    # -- ground: calibrating, then arming -----------------------------------------------------------
    def _ground(self, t: float) -> bool:
        """On the floor, motors stopped: the calibration takes the sample; at `t_arm` the loop arms
        (into FLYING), or refuses to (a battery reading no pack gives: True, the loop ends)."""
        self.calibration.add(self.sample)
        self.counts = self._stopped
        self.sp = self.plan.sp
        if t < self.t_arm:
            return False
        if self._battery_why is not None:                # pre-arm: a reading no pack gives
            return self._stop(t, f"stopped: not armed: {self._battery_why}")
        tel = self.telemetry
        if tel is None or tel.may_arm():
            if tel is not None and tel.arm_required:   # armed by the ground station: the log starts now
                self.t_arm = t
            ctl = self.ctl
            self.calibration.apply(ctl.est)
            ctl.arm(self.sample)
            self.hal.motors.arm()
            self.phase = FLYING
            self.detector.reset(self.params.airframe.B)
            self._last_echo = t
            self.result.t_arm = self.t_arm
            self._event(t, "armed")
            if self.spin.why_not:
                self._event(t, f"no two-rotor landing after a lost motor on this vehicle: {self.spin.why_not}")
        return False

    # -- armed: flying, landing, on two rotors, done ------------------------------------------------
    def _setpoint(self, t: float) -> bool:
        """The plan's setpoints now (`sp`); a plan that fails or gives a non-finite one lands (on the
        floor after the flight: the loop ends, True)."""
        try:
            sp = self.sp = self.plan.at(t - self.t_arm)
            s = sp[0] + sp[1] + sp[2] + sp[3]
            if s - s != 0.0:                                  # NaN or infinite
                raise ValueError("a non-finite setpoint")
        except Exception as e:
            phase = self.phase
            if phase is LANDING or phase is TWO_ROTORS:
                raise                                        # the landing plan itself: a bug
            if phase is DONE:                                # on the ground, motors stopped
                return self._stop(t, f"stopped: plan failed ({e})")
            self._land(t, self.ctl.alt, f"plan failed ({e}): landing")
            self.sp = self.plan.sp
        return False

    def _armed(self, t: float, cmd: str | None) -> bool:
        """One tick of an armed phase: the requests to land, the echo to the altitude task, then in the
        air the controller, the checks and the touchdown; on the floor after the flight the estimate
        alone. True: the loop ends (a crash)."""
        log, ctl = self.log, self.ctl
        if self._log_failed is False and log is not None and log.failed:
            self._log_failed = True
            if self.phase is FLYING:
                self._land(t, ctl.alt, f"log write failed ({log.error}): landing")
                self.sp = self.plan.sp
        if cmd == "land" and self.phase is FLYING:
            self._land(t, ctl.alt, "land commanded by the ground station: landing")
        echo = self.echo
        in_air = self.phase is not DONE
        if echo is not None:
            if echo == echo:
                self.range_cell = "%.4f" % echo
                self._last_echo = t
            if in_air:
                ctl.on_range(echo, t)
                if echo == echo and ctl.alt > TOUCHDOWN_ALT:
                    self.detector.lifted()          # off the floor: a lost motor is looked for
        if not in_air:
            self.counts = self._stopped
            ctl.step(self.sample, self._dt, 0.0, 0.0, ctl.est.yaw, 0.0)   # keep estimating on the ground
            return False
        self._motor_loss(t)
        if self.phase is TWO_ROTORS:               # the landing's thrust, on two rotors
            self.counts = ctl.step_two_rotors(self.sample, self._dt)
        else:
            sp = self.sp
            self.counts = ctl.step(self.sample, self._dt, sp[0], sp[1], sp[2], sp[3])
        if self._checks(t):
            return True
        self._touchdown(t)
        return False

    def _motor_loss(self, t: float) -> None:
        """The lost-motor check (control/motor_loss.py), before the controller mixes anew: a weak
        motor is flown on four rotors and landed (LANDING), a lost one on two (TWO_ROTORS)."""
        if self.phase is TWO_ROTORS:
            return
        ctl, detector, spin = self.ctl, self.detector, self.spin
        lost = detector.update(self.sample, ctl.mixer.f, self._dt, ctl.alt < TOUCHDOWN_ALT)
        if not lost:
            return
        giving = 1.0 - detector.missing
        if spin.why_not or flown_on_four(self.params, lost, giving):
            detector.accept()          # flown on four rotors: a weak motor, or no other way
            self._weak(t, lost, giving, spin.why_not, self.phase is LANDING, ctl.alt)
        else:
            self._spin(t, lost, giving, detector.fast, spin, ctl.alt)
        self.sp = self.plan.sp

    def _checks(self, t: float) -> bool:
        """The checks in the air, on the estimate the controller left: a crash (True: the loop ends),
        the attitude not held, the highest altitude, the battery (no pack's reading, low), the altitude
        lost; each landing it asks for begins here (`_land`)."""
        ctl = self.ctl
        est = ctl.est
        if not (abs(est.roll) <= CRASH_TILT and abs(est.pitch) <= CRASH_TILT):   # NaN too
            return self._stop(t, f"stopped: crash (tilt past {math.degrees(CRASH_TILT):.0f} degrees)")
        sp = self.sp
        if self.phase is not TWO_ROTORS and (abs(est.roll - sp[0]) > ATTITUDE_LOST or abs(est.pitch - sp[1]) > ATTITUDE_LOST):
            self._off_loops += 1
            if self._off_loops == ATTITUDE_LOST_LOOPS:     # the crash check stops at CRASH_TILT
                counts = self.counts
                self._event(t, "attitude not held for %d loops: motor %d commanded hardest "
                               "(a motor or propeller lost?)" % (self._off_loops, counts.index(max(counts)) + 1))
        else:
            self._off_loops = 0
        alt = ctl.alt
        if alt > self.max_alt:
            self.max_alt = alt
        why = self._battery_why
        if why is not None and not self._battery_said:   # the low check is blind on it
            self._battery_said = True
            if self.phase is not FLYING:
                self._event(t, why + ": the landing goes on")
            else:
                self._land(t, alt, why + ": landing")
        if self.phase is FLYING and self.battery_v < LOW_CELL_V * CELLS:
            self._land(t, alt, "battery low: landing")
        if not self._blind and t - self._last_echo > LOST_ALT_S and alt > TOUCHDOWN_ALT:   # (NaN at the floor)
            self._blind = True           # descend on the accelerometer (control/landing.py)
            why = f"altitude lost (no valid echo for {LOST_ALT_S:g} s)"
            if self.phase is not FLYING:
                self._event(t, why + ": the landing goes on, on the accelerometer")
            else:
                self._land(t, ctl.vert.z, why + ": landing")
        return False

    def _touchdown(self, t: float) -> None:
        """The floor reached: in the loop's own landing the accelerometer confirms it, in the plan's
        the sonar reads the floor for TOUCHDOWN_S. Then the motors stop (DONE); the loop's own landing,
        or a touchdown after the plan's end, ends the loop after this tick's row."""
        ctl = self.ctl
        if self.phase is not FLYING:        # the accelerometer confirms the floor
            touched = ctl.landing.landed
        else:                               # the plan's own landing, on the sonar
            if self.sp[3] <= 0.0 and ctl.alt < TOUCHDOWN_ALT and self.plan.lands():
                self._t_touch = self._t_touch if self._t_touch is not None else t
            else:
                self._t_touch = None
            touched = self._t_touch is not None and t - self._t_touch > TOUCHDOWN_S
        if not touched:
            return
        own = self.phase is not FLYING
        self.phase = DONE
        ctl.touchdown()
        self.hal.motors.stop()
        self._event(t, "landed: motors stopped")
        if self.max_alt < LEFT_GROUND_ALT:
            self._event(t, f"never left the ground (highest altitude {self.max_alt:.2f} m)")
        if self._why:
            self.result.reason = "landed: " + self._why.rsplit(": ", 1)[0]
        self.counts = self._stopped
        # the loop's own landing is the plan's end; so is a touchdown confirmed after it
        self._last = own or t - self.t_arm >= self.plan.duration

    def _plan_end(self, t: float) -> bool:
        """The plan's time is up: on the floor the loop ends (True); in the loop's own landing the
        touchdown was never detected (True); a vehicle the sonar never saw leave the floor stops
        (True); in the air the loop lands."""
        if t - self.t_arm < self.plan.duration or self._last:
            return False
        phase = self.phase
        if phase is DONE:
            return True
        if phase is not FLYING:          # the landing's own end: the touchdown was never detected
            return self._stop(t, "stopped: no touchdown detected by the end of the landing")
        if self.max_alt < LEFT_GROUND_ALT:   # the sonar never saw it leave the floor: nothing to land
            self.hal.motors.stop()
            self._event(t, f"never left the ground (highest altitude {self.max_alt:.2f} m): motors stopped")
            return True
        if self._t_touch is None:        # (else the plan's own touchdown is under way: it ends within TOUCHDOWN_S)
            self._land(t, self.ctl.alt, f"plan ended in the air at {self.ctl.alt:.2f} m: landing")
        return False

    # -- the log's row ------------------------------------------------------------------------------
    def _row(self, t: float) -> None:
        """One row of the flight log (logfile.py's columns), and the simulator's truth after it."""
        ctl, s, counts, sp = self.ctl, self.sample, self.counts, self.sp
        est = ctl.est
        k = P_PER_COUNT
        row = (t - self.t_arm, counts[0] * k, counts[1] * k, counts[2] * k, counts[3] * k,
               s.gx, s.gy, s.gz, s.ax, s.ay, s.az, self.range_cell, self.battery_v,
               est.roll, est.pitch, est.yaw, ctl.alt, sp[0], sp[1], sp[2], sp[3], s.mx, s.my, s.mz)
        extra = self.extra_row
        self.log.append(row + extra() if extra is not None else row)

    # -- the landings -------------------------------------------------------------------------------
    def _spin(self, t: float, lost: int, giving: float, fast: bool, spin: SpinController, alt: float) -> None:
        """Motor `lost` is gone (control/spin.py): from now on the spin controller flies the two rotors
        of the other arm down, on the landing's thrust (`_land`: the rest of the plan becomes a descent,
        the log's setpoint). The phase is TWO_ROTORS from now on."""
        self.ctl.start_two_rotors(spin, lost)
        a, b = (m + 1 for m in spin.pair)
        self._land(t, alt, f"motor {lost} lost ({'at least ' if fast else ''}{100 * (1 - giving):.0f} % of its "
                           f"thrust missing in torque and "
                           f"collective): motors {lost} and {spin.off[1] + 1} stopped, flying on motors {a} and {b}, "
                           f"yaw given up, spinning up toward {spin.r_bar:.0f} rad/s: landing")
        self._why = f"motor {lost} lost: landing on two rotors"   # even where the plan was landing already
        self.phase = TWO_ROTORS

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

    def _land(self, t: float, alt: float, why: str) -> None:
        """From clock time `t` (the phase LANDING): replace the rest of the plan by roll and pitch back to level and a
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
        self.phase = LANDING
