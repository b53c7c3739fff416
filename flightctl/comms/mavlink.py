"""MAVLink to a ground station (QGroundControl, Mission Planner, pymavlink): `--mavlink URL` on
`flightctl run` and `flightctl sim`. Needs pymavlink, an optional extra (`pip install '.[mavlink]' in the flightctl checkout`);
imported only when `--mavlink` is given.

URL is pymavlink's connection string: `udpout:HOST:PORT` (send to a ground station), `udpin:HOST:PORT`
(wait for one), or a serial telemetry radio `/dev/ttyAMA0,57600`. MAVLink 2, common dialect,
system 1, component 1 (the autopilot).

The loop sees a narrow interface (flightctl/loop.py): `poll()` once per iteration gives a command of
the ground station or None; `may_arm()` says whether it may arm now; `tick(...)` hands it the values it
already has, once per iteration; `start(result)` lets the link follow the loop's events. Nothing
here touches the network in the loop's thread: `tick` keeps a snapshot every STREAM_EVERY loops in
a bounded queue; one I/O thread sends the stream and answers the commands. A lost link therefore
never slows or stops the loop: the plan goes on (and a send that fails is counted, not raised).

Stream (frames converted here only, flightctl/comms/frames.py: ours NWU/FLU, MAVLink NED/FRD):
HEARTBEAT (quadrotor, armed flag, custom_mode = MODES) and SYS_STATUS and BATTERY_STATUS at 1 Hz;
ATTITUDE, LOCAL_POSITION_NED (z only: x, y and the speeds are NaN, not estimated), SERVO_OUTPUT_RAW
(ESC pulse, us) at loop_hz / STREAM_EVERY = 50 Hz; DISTANCE_SENSOR on each new sonar echo (at most
at the stream rate); STATUSTEXT for every event of the loop, every refusal and every command.

Commands: COMMAND_LONG COMPONENT_ARM_DISARM: arm only with a plan loaded and the pre-arm checks
passed (`ready()`; otherwise DENIED with the reason in a STATUSTEXT); a disarm with param2 = 21196
(forced) is the kill switch: motors stopped at the next loop, in the air too; a plain disarm in
flight is DENIED (land instead). NAV_LAND: the loop's controlled landing. PARAM_REQUEST_LIST and
PARAM_REQUEST_READ: PARAM_VALUE of every parameter, read-only (PARAM_SET is answered with the
unchanged value and a STATUSTEXT). Parameter ids are the names of flightctl/params.py without the
table (`kp_phi`, `alpha_yaw`), SI units as there; a name longer than MAVLink's 16 characters is
shortened by ALIASES.
"""
from __future__ import annotations

import collections
import dataclasses
import math
import os
import threading
import time

from flightctl.errors import InputError
from flightctl.comms.frames import euler_ned, pulse_us, vector_ned
from flightctl.hal import PWM_RANGE
from flightctl.params import Params

STREAM_EVERY = 9                 # loop iterations per ATTITUDE (50 Hz at 450 Hz)
SLOW_S = 1.0                     # HEARTBEAT, SYS_STATUS, BATTERY_STATUS period (wall clock)
FORCE_MAGIC = 21196              # ARM_DISARM param2: force (MAVLink's value)
MODES = {"standby": 0, "calibrating": 1, "flying": 2, "landing": 3, "landed": 4}
ALIASES = {"battery_nominal_v": "batt_nominal_v"}
SONAR_CM = (2, 400)              # HC-SR04 range
SENSORS = ("3D_GYRO", "3D_ACCEL", "ANGULAR_RATE_CONTROL", "ATTITUDE_STABILIZATION", "Z_ALTITUDE_CONTROL",
           "MOTOR_OUTPUTS")   # SYS_STATUS: present, enabled and healthy


def parameters(params: Params) -> list[tuple[str, float]]:
    """(MAVLink id, value) of every parameter, in the schema's order."""
    out = []
    for table in (params.airframe, params.gains, params.filters):
        for f in dataclasses.fields(table):
            out.append((ALIASES.get(f.name, f.name), float(getattr(table, f.name))))
    return out


def _severity(mav, what: str) -> int:
    if what.startswith("stopped"):
        return mav.MAV_SEVERITY_CRITICAL
    if "refused" in what or "failed" in what or "lost" in what or "low" in what:
        return mav.MAV_SEVERITY_WARNING
    return mav.MAV_SEVERITY_INFO


class MavlinkLink:
    """The ground station link; `close()` stops its thread and closes the connection."""

    def __init__(self, url: str, params: Params, arm_required: bool = False):
        os.environ.setdefault("MAVLINK20", "1")     # before pymavlink picks its dialect
        from pymavlink import mavutil
        from pymavlink.dialects.v20 import common as mav
        self.defs = mav
        self.sensors = sum(getattr(mav, f"MAV_SYS_STATUS_SENSOR_{name}") for name in SENSORS)
        self.conn = mavutil.mavlink_connection(url, source_system=1, source_component=1, dialect="common",
                                               autoreconnect=True)
        self.mav = self.conn.mav
        self.params = parameters(params)
        self.esc_hz = params.airframe.esc_pwm_hz
        self.arm_required = arm_required
        self._not_ready = "no plan loaded"          # why an ARM is refused; None: it may arm
        self._arm = threading.Event()
        self.inbox: collections.deque[str] = collections.deque()      # "kill", "land" for the loop
        self._stream: collections.deque[tuple] = collections.deque(maxlen=256)
        self._texts: collections.deque[tuple[int, str]] = collections.deque(maxlen=256)
        self._events: list | None = None
        self._sent_events = 0
        self.mode, self.armed, self.flying = "standby", False, False
        self.battery_v = math.nan
        self.send_errors = 0
        self._t0: float | None = None
        self._i = 0
        self._last_echo = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="mavlink", daemon=True)
        self._thread.start()

    # --- what the service says ---------------------------------------------------------------
    def ready(self, plan: str) -> None:
        """A plan is loaded and the pre-arm checks passed: an ARM is accepted."""
        self._not_ready = None
        self.text(f"ready: plan {plan} loaded, pre-arm checks passed")

    def text(self, what: str, severity: int | None = None) -> None:
        self._texts.append((_severity(self.defs, what) if severity is None else severity, what))

    # --- the loop's interface ----------------------------------------------------------------
    def start(self, result) -> None:
        """A flight begins: follow `result.events`."""
        self._events, self._sent_events = result.events, 0
        self.mode, self.armed, self.flying = "calibrating", False, False
        self.inbox.clear()

    def may_arm(self) -> bool:
        return not self.arm_required or self._arm.is_set()

    def poll(self) -> str | None:
        return self.inbox.popleft() if self.inbox else None

    def tick(self, t, armed, flying, landing, sample, est, alt, echo, battery_v, counts, sp) -> None:
        """Once per loop iteration; `counts` are the four PWM counts written (0..PWM_RANGE)."""
        self._i += 1
        if echo is not None and echo == echo:
            self._last_echo = echo
        if self._i % STREAM_EVERY:
            return
        self._stream.append((t, armed, flying, landing, est.roll, est.pitch, est.yaw, sample.gx, sample.gy,
                             sample.gz, alt, self._last_echo, battery_v, tuple(counts)))
        self._last_echo = None

    def end(self) -> None:
        """The flight ended: disarmed, waiting for the next plan."""
        self._arm.clear()
        self.armed = self.flying = False
        self.mode = "standby"
        self._not_ready = "no plan loaded"

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        self._flush_events()
        self._send_texts()
        try:
            self.conn.close()
        except OSError:
            pass

    # --- the I/O thread ----------------------------------------------------------------------
    def _run(self) -> None:
        next_slow = 0.0
        while not self._stop.is_set():
            self._receive()
            self._flush_events()
            self._send_texts()
            while self._stream:
                self._send_stream(self._stream.popleft())
            now = time.monotonic()
            if now >= next_slow:
                next_slow = now + SLOW_S
                self._send_slow()
            self._stop.wait(0.005)

    def _send(self, fn, *args) -> None:
        try:
            fn(*args)
        except OSError:                  # no ground station (yet, or any more): the flight goes on
            self.send_errors += 1

    def _ms(self, t: float) -> int:
        if self._t0 is None:
            self._t0 = t
        return int((t - self._t0) * 1000) & 0xFFFFFFFF

    def _send_stream(self, s: tuple) -> None:
        t, armed, flying, landing, roll, pitch, yaw, gx, gy, gz, alt, echo, volts, p = s
        self.armed, self.flying, self.battery_v = armed, flying, volts
        self.mode = ("landing" if landing else "flying") if flying else ("landed" if armed else "calibrating")
        ms = self._ms(t)
        r, q, y = euler_ned(roll, pitch, yaw)
        wx, wy, wz = vector_ned(gx, gy, gz)
        self._send(self.mav.attitude_send, ms, r, q, y, wx, wy, wz)
        nan = math.nan
        self._send(self.mav.local_position_ned_send, ms, nan, nan, vector_ned(0.0, 0.0, alt)[2], nan, nan, nan)
        us = [int(round(pulse_us(c * 255.0 / PWM_RANGE, self.esc_hz))) for c in p]
        self._send(self.mav.servo_output_raw_send, (ms * 1000) & 0xFFFFFFFF, 0, *us, 0, 0, 0, 0)
        if echo is not None:
            cm = int(round(echo * 100))
            self._send(self.mav.distance_sensor_send, ms, SONAR_CM[0], SONAR_CM[1], cm,
                       self.defs.MAV_DISTANCE_SENSOR_ULTRASOUND, 0, self.defs.MAV_SENSOR_ROTATION_PITCH_270, 255)

    def _send_slow(self) -> None:
        base = self.defs.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | self.defs.MAV_MODE_FLAG_AUTO_ENABLED
        if self.armed and self.flying:
            base |= self.defs.MAV_MODE_FLAG_SAFETY_ARMED
        state = {"standby": self.defs.MAV_STATE_STANDBY, "calibrating": self.defs.MAV_STATE_CALIBRATING,
                 "flying": self.defs.MAV_STATE_ACTIVE, "landing": self.defs.MAV_STATE_ACTIVE,
                 "landed": self.defs.MAV_STATE_STANDBY}[self.mode]
        self._send(self.mav.heartbeat_send, self.defs.MAV_TYPE_QUADROTOR, self.defs.MAV_AUTOPILOT_GENERIC, base,
                   MODES[self.mode], state)
        mv = int(self.battery_v * 1000) if math.isfinite(self.battery_v) else 0xFFFF
        self._send(self.mav.sys_status_send, self.sensors, self.sensors, self.sensors, 0, mv, -1, -1, 0, 0, 0, 0, 0, 0)
        self._send(self.mav.battery_status_send, 0, self.defs.MAV_BATTERY_FUNCTION_ALL, self.defs.MAV_BATTERY_TYPE_LIPO,
                   0x7FFF, [mv] + [0xFFFF] * 9, -1, -1, -1, -1)

    def _flush_events(self) -> None:
        events = self._events
        if events is None:
            return
        while self._sent_events < len(events):
            t, what = events[self._sent_events]
            self._sent_events += 1
            self.text(what)

    def _send_texts(self) -> None:
        while self._texts:
            severity, what = self._texts.popleft()
            for k in range(0, max(len(what), 1), 50):          # STATUSTEXT holds 50 characters
                self._send(self.mav.statustext_send, severity, what[k:k + 50].encode())

    def _receive(self) -> None:
        while True:
            try:
                msg = self.conn.recv_match(blocking=False)
            except OSError:
                return
            if msg is None:
                return
            kind = msg.get_type()
            if kind == "COMMAND_LONG":
                self._command(msg)
            elif kind == "PARAM_REQUEST_LIST":
                for k, (name, value) in enumerate(self.params):
                    self._param(k, name, value)
            elif kind == "PARAM_REQUEST_READ":
                self._param_read(msg.param_id, msg.param_index)
            elif kind == "PARAM_SET":
                self.text(f"parameters are read-only here: edit the parameter file ({msg.param_id})",
                          self.defs.MAV_SEVERITY_WARNING)
                self._param_read(msg.param_id, -1)

    def _param(self, k: int, name: str, value: float) -> None:
        self._send(self.mav.param_value_send, name.encode(), value, self.defs.MAV_PARAM_TYPE_REAL32, len(self.params), k)

    def _param_read(self, name: str, index: int) -> None:
        for k, (n, value) in enumerate(self.params):
            if k == index or (index < 0 and n == name):
                self._param(k, n, value)
                return

    def _ack(self, command: int, ok: bool, why: str = "") -> None:
        if why:                         # the reason before the answer
            self.text(why, self.defs.MAV_SEVERITY_INFO if ok else self.defs.MAV_SEVERITY_WARNING)
            self._send_texts()
        self._send(self.mav.command_ack_send, command,
                   self.defs.MAV_RESULT_ACCEPTED if ok else self.defs.MAV_RESULT_DENIED)

    def _command(self, msg) -> None:
        cmd = msg.command
        if cmd == self.defs.MAV_CMD_COMPONENT_ARM_DISARM:
            if msg.param1 >= 0.5:
                if self.armed:
                    self._ack(cmd, True, "arm: already armed")
                elif self._not_ready is not None:
                    self._ack(cmd, False, f"arming refused: {self._not_ready}")
                elif not self.arm_required:
                    self._ack(cmd, True, "arm: this flight arms by itself after calibrating")
                else:
                    self._arm.set()
                    self._ack(cmd, True, "arm accepted: arming after calibration")
            elif int(msg.param2) == FORCE_MAGIC:
                self.inbox.append("kill")
                self._ack(cmd, True, "kill: forced disarm, motors stopped")
            elif self.flying:
                self._ack(cmd, False, "disarm refused in flight: send NAV_LAND, or force it (kill)")
            else:
                self._arm.clear()
                self._ack(cmd, True, "disarmed")
        elif cmd == self.defs.MAV_CMD_NAV_LAND:
            if self.flying:
                self.inbox.append("land")
                self._ack(cmd, True, "land accepted")
            else:
                self._ack(cmd, False, "land refused: not flying")
        else:
            self._send(self.mav.command_ack_send, cmd, self.defs.MAV_RESULT_UNSUPPORTED)


def open_link(url: str, params: Params, arm_required: bool = False) -> MavlinkLink:
    """The link, or an InputError naming what is wrong (pymavlink missing, a bad URL)."""
    try:
        return MavlinkLink(url, params, arm_required)
    except ModuleNotFoundError as e:
        raise InputError(f"--mavlink needs the Python module {e.name!r}: "
                         "pip install '.[mavlink]' in the flightctl checkout") from None
    except (OSError, ValueError) as e:
        raise InputError(f"--mavlink {url}: cannot open ({e}); pymavlink's forms: udpout:HOST:PORT, "
                         "udpin:HOST:PORT, tcp:HOST:PORT, tcpin:HOST:PORT or a serial device DEV[,BAUD]") from None
