"""`flightctl run`: the onboard service (systemd/flightctl.service runs it on the quadcopter; flightctl/service/).

    flightctl run [--board auto|pi|pi5] [--board-file B.toml] [--params P.toml] --plan-queue DIR --log DIR
    flightctl run --board pi|pi5|sim --plan PLAN.toml|NAME [--params P.toml] --log DIR [--calibrate S]
    flightctl run --board auto --stop-motors        (the unit's ExecStopPost)

The board is opened by name through the registry (flightctl/boards/__init__.py; `auto`, the default, is
`pi5` on a Raspberry Pi 5 and `pi` elsewhere); a plan is a plan file or a named plan
(flightctl/plans/__init__.py).

Lifecycle: the board comes up with the ESCs at the stop pulse (disarmed). Pre-arm checks follow,
each with a named reason: IMU frames good and the vehicle at rest (|a| near g), battery above the
threshold, ESC output really at the ESC frequency (`Motors.arm()` measures it; then `stop()` again).
Then READY=1 to systemd, and the service waits, disarmed, for a plan:
- `--plan` flies that plan once and exits;
- `--plan-queue DIR` validates each queued plan, refuses (moved aside with a one-line reason) a bad
  one and a stale one (written before the service started, or older than --plan-max-age), claims the
  oldest good one by renaming it into the log directory (atomic: a plan is flown at most once), flies
  it, and waits for the next one (flightctl/service/queue.py). A restarted service flies nothing queued
  before it started: a restart can never re-arm.
- neither: stays disarmed (stop pulse) until stopped.
A flight is `FlightLoop`: calibrate sitting still, arm, fly, land, at 450 Hz on the deadline-keeping
wall clock (`--board sim` paces the simulator with the same clock, in real time), writing the
contract flight log (DIR/flight-<UTC time>.csv) and a summary (…-summary.json). WATCHDOG=1 comes
from the loop (`on_tick`, every 0.5 s at most) and from the wait for a plan.

SIGTERM or SIGINT set the stop flag: the loop ends at its next iteration, the motors get zero thrust
(the loop's `finally`, then once more here), the log gets a last row with P1..P4 = 0 (the stop
command that was sent) and a `# partial:` line, STOPPING=1, exit 0.

Exit status: 0 stopped as asked; 1 stopped on an error, the motors stopped first: a device lost in
operation (pigpiod gone, the pigpiod dead-man fired, a bus error) is one line in the journal, anything
else (a bug) its traceback; the unit restarts, disarmed. 2 bad input (a flag, a parameter or plan
file). 3 nothing can fly (a device missing, a pre-arm check failed, arming refused, the log directory
not writable, $NOTIFY_SOCKET set but unusable: under systemd the watchdog would kill the flight):
the unit does not restart on it. Each is decided before READY=1.
"""
from __future__ import annotations

import argparse
import json
import logging
import math
import os
import signal
import sys
import threading
import time
from datetime import datetime, timezone
from pathlib import Path

from flightctl import __version__
from flightctl.battery import CELLS, FULL_CELL_V, LOW_CELL_V, implausible
from flightctl.boards import (MIN_BATTERY_V_RANGE, Board, BoardOptions, BoardUnavailable, check_options,
                              described, opener, stop_motors)
from flightctl.clock import freeze_gc
from flightctl.control.controller import FlightController
from flightctl.control.spin import SpinController
from flightctl.errors import InputError, Parser, seed
from flightctl.files import output_dir, write_atomic
from flightctl.hal import ArmingRefused, Hal, ImuSample
from flightctl.logfile import FLIGHT_COLUMNS, MAG_COLUMNS, FlightLogWriter, log_room
from flightctl.loop import FlightLoop, FlightResult
from flightctl.params import Params, dumps, load
from flightctl.plans.plan import Plan
from flightctl.service.queue import PLAN_MAX_AGE_RANGE_S, PLAN_MAX_AGE_S, PlanQueue, check_name, new_path
from flightctl.plans import load_plan
from flightctl.service.sdnotify import Notifier

EXIT_OK, EXIT_ERROR, EXIT_USAGE, EXIT_REFUSED = 0, 1, 2, 3
PLAN_POLL_S = 0.5
OUTPUT_CHECK_S = 2.0           # while disarmed, the ESC output is read back this often (drivers/esc.py)
REST_ACCEL = (0.8, 1.2)        # |a| / g at rest, for the pre-arm IMU check
DEAD_ACCEL = 0.05              # |a| / g at rest below which the accelerometer is dead, not the vehicle moving
# --calibrate: at least 90 loop periods at 450 Hz, whose mean of the gyro's white noise (0.17 deg/s a read,
# docs/estimator.md) leaves a bias within 0.02 deg/s (1 sigma), to 10 minutes sitting still
CALIBRATE_RANGE_S = (0.2, 600.0)

log = logging.getLogger("flightctl.run")


# --- the flight log with its teardown row --------------------------------------------------------
class TeardownLog(FlightLogWriter):
    """The contract log, plus one last row at close: the stop command (P1..P4 = 0) that the loop's
    `finally` sent after its last iteration, one period later, the other columns as last seen."""

    def __init__(self, out, meta, extra=(), period: float = 1 / 450.0):
        super().__init__(out, meta, extra, background=True)   # a slow card drops rows, never stalls the loop
        self.period = period
        self.last: tuple | None = None

    def append(self, row: tuple) -> None:
        self.last = row
        super().append(row)

    def close(self) -> None:
        last = self.last
        if self._f is not None and last is not None and any(last[1:5]):
            self.last = None
            super().append((last[0] + self.period, 0.0, 0.0, 0.0, 0.0) + last[5:11] + ("",) + last[12:])
        super().close()


# --- checks --------------------------------------------------------------------------------------
def prearm(hal: Hal, params: Params, min_battery_v: float) -> list[str]:
    """Named reasons not to arm; empty when the vehicle may fly. Leaves the motors stopped."""
    reasons = []
    sample, good = ImuSample(), 0
    for _ in range(5):
        good += hal.imu.read(sample)
    if not good:
        why = getattr(hal.imu, "why", None) or "all 0x00 or 0xFF"
        reasons.append(f"IMU: every frame refused ({why})" + (": no IMU on the bus" if "bus" in why else ""))
    else:
        a = math.sqrt(sample.ax ** 2 + sample.ay ** 2 + sample.az ** 2) / params.airframe.g
        if a < DEAD_ACCEL or getattr(hal.imu, "why", None) == "accelerometer reads zero":
            reasons.append(f"IMU: the accelerometer reads {a:.2f} g at rest: accelerometer faulty")
        elif not REST_ACCEL[0] <= a <= REST_ACCEL[1]:
            reasons.append(f"IMU: |a| = {a:.2f} g at rest (expected 1 g): vehicle moving or IMU faulty")
    v, _ = hal.power.read()
    why = implausible(v, CELLS)
    if why is not None:
        reasons.append(why)
    elif not v >= min_battery_v:
        reasons.append(f"battery {v:.2f} V below {min_battery_v:.2f} V")
    try:
        hal.motors.arm()
    except ArmingRefused as e:
        reasons.append(str(e))
    finally:
        hal.motors.stop()
    return reasons


# --- the service ---------------------------------------------------------------------------------
class Service:
    def __init__(self, args, params: Params, board: Board, notifier: Notifier, stop: threading.Event):
        self.args, self.params, self.board, self.notifier, self.stop = args, params, board, notifier, stop
        self.log_dir = Path(args.log)
        self.calibrate_s = args.calibrate if args.calibrate is not None else board.calibrate_s
        self.min_battery_v = args.min_battery_v if args.min_battery_v is not None else board.min_battery_v
        self.flights: list[FlightResult] = []
        self.link = None            # the ground station (flightctl/comms/mavlink.py), with --mavlink
        self.started = time.time()  # plans queued before this are never flown (planqueue.py)
        self.tampered: str | None = None   # what another process did to the ESC output: never arm again
        self._next_output_check = 0.0

    def watch_output(self) -> None:
        """While disarmed: read the ESC output back (boards whose motors can: both Pi boards' ESC
        drivers); if another process changed it, put the stop pulse back, say so, and refuse to arm
        until the service is restarted by hand."""
        check = getattr(self.board.hal.motors, "check_output", None)
        now = time.monotonic()
        if check is None or now < self._next_output_check:
            return
        self._next_output_check = now + OUTPUT_CHECK_S
        try:
            check()
        except Exception as e:
            if self.tampered is None:
                self.tampered = f"{e}: refusing to arm until restarted"
                log.error("%s", self.tampered)
                self.notifier.status(f"disarmed: {self.tampered}")

    def check(self, plan: Plan | None = None) -> None:
        """The pre-arm checks, and with a plan, its flight log's room on the log directory's disk."""
        if self.tampered is not None:
            raise ArmingRefused(self.tampered)
        reasons = prearm(self.board.hal, self.params, self.min_battery_v)
        if plan is not None:
            try:
                log_room(self.log_dir, self.calibrate_s + plan.duration, self.params.airframe.loop_hz,
                         len(FLIGHT_COLUMNS + MAG_COLUMNS + self.board.extra_columns))
            except InputError as e:
                reasons.append(str(e))
        if reasons:
            raise ArmingRefused("; ".join(reasons))

    def run(self, plan: Plan | None) -> None:
        self.check(plan)
        self.notifier.ready(f"disarmed, {self.board.name} board, pre-arm checks passed")
        log.info("ready: disarmed, ESCs at the stop pulse")
        if plan is not None:
            self.fly(plan)
        elif self.args.plan_queue:
            self.serve_queue(Path(self.args.plan_queue))
        else:
            log.info("no plan: holding the stop pulse until stopped")
            while not self.stop.wait(PLAN_POLL_S):
                self.notifier.tick()
                self.watch_output()

    def serve_queue(self, queue: Path) -> None:
        plans = PlanQueue(queue, self.log_dir, started=self.started, max_age_s=self.args.plan_max_age)
        plans.open()
        while not self.stop.is_set():
            self.notifier.tick()
            self.watch_output()
            taken = plans.take()
            if plans.refused:
                name, reason = plans.refused.pop()
                plans.refused.clear()
                self.notifier.status(f"disarmed: plan {name} refused: {reason}")
            if taken is None:
                self.stop.wait(PLAN_POLL_S)
                continue
            plan, claimed = taken
            try:
                self.check(plan)
            except ArmingRefused as e:      # this plan is not flown; the service stays up, disarmed
                log.error("plan %s not flown: %s", plan.name, e)
                self.notifier.status(f"disarmed: plan {plan.name} refused: {e}")
                if self.link is not None:
                    self.link.text(f"plan {plan.name} refused: {e}")
                continue
            self.fly(plan, plan_file=claimed)

    def fly(self, plan: Plan, plan_file: Path | None = None) -> FlightResult:
        params, board, hal = self.params, self.board, self.board.hal
        if not plan.lands():
            log.warning("plan %s does not end at altitude 0: the loop lands when it ends", plan.name)
        plan.restart()
        path = new_path(self.log_dir, "flight", f"{plan.name}.csv")
        meta = {"software": f"flightctl {__version__}", "board": board.name, "plan": plan.name,
                "plan_file": str(plan_file or self.args.plan), "calibrate_s": self.calibrate_s,
                "loop_hz": params.airframe.loop_hz, "esc_pwm_hz": params.airframe.esc_pwm_hz,
                "started": datetime.now(timezone.utc).isoformat(timespec="seconds"), **board.meta,
                "params": dumps(params)}
        flight_log = TeardownLog(path, meta, MAG_COLUMNS + board.extra_columns, params.airframe.dt)
        loop = FlightLoop(hal, params, plan, flight_log, FlightController(params), calibrate_s=self.calibrate_s,
                          stop=self.stop, on_tick=self.notifier.tick, extra_row=board.extra_row,
                          telemetry=self.link)
        if self.link is not None:       # the pre-arm checks passed (run, serve_queue): the pilot may arm
            self.link.ready(plan.name)
        self.notifier.status(f"flying {plan.name}: calibrating {self.calibrate_s:g} s, then arming")
        log.info("flight %s: calibrating %g s, log %s", plan.name, self.calibrate_s, path)
        freeze_gc()
        result = loop.run()
        for t, what in result.events:
            log.info("  %8.3f s  %s", t, what)
        log.info("flight %s ended: %s (%d iterations, %d overruns)", plan.name, result.reason,
                 result.iterations, result.overruns)
        wall = getattr(hal.clock, "wall", hal.clock)     # the wall clock, or the one that paces the simulator
        summary = {"plan": plan.name, "log": path.name, "reason": result.reason, "events": result.events,
                   "iterations": result.iterations, "overruns": result.overruns,
                   "skipped_periods": getattr(wall, "skipped", 0), "max_late_s": getattr(wall, "max_late_s", None)}
        summary["log_dropped_rows"], summary["log_error"] = flight_log.dropped, flight_log.error
        if flight_log.dropped:
            log.error("flight log %s: %d rows dropped (%s)", path, flight_log.dropped, flight_log.error)
        try:                             # whole or not at all: a full disk leaves no empty summary
            write_atomic(path.with_name(path.stem + "-summary.json"), json.dumps(summary, indent=1) + "\n")
        except InputError as e:          # the journal has the summary above
            log.error("flight summary not written: %s", e)
        self.notifier.status(f"disarmed after {plan.name}: {result.reason}")
        self.flights.append(result)
        if self.link is not None:
            self.link.end()
        return result


# Errors of the devices and their libraries, raised in operation (pigpiod gone: its socket reset or a
# short reply; the dead-man's EscError; a bus's OSError): one line, not a traceback.
_DEVICE_MODULES = ("pigpio", "smbus2", "spidev", "serial", "gpiod", "flightctl.drivers", "flightctl.boards",
                   "flightctl.comms", "flightctl.hal")


def device_error(e: BaseException) -> bool:
    import struct
    module = type(e).__module__ or ""
    return (isinstance(e, (OSError, EOFError, struct.error, ArmingRefused))
            or any(module == m or module.startswith(m + ".") for m in _DEVICE_MODULES))


def describe(e: BaseException) -> str:
    """A device error in one line, its kind named."""
    import struct
    text = " ".join(str(e).split()) or "(no message)"
    if isinstance(e, struct.error):          # pigpio unpacks a reply that never came
        return f"a device's reply cut short ({text}): its daemon (pigpiod) gone?"
    if isinstance(e, ConnectionError):
        return f"{type(e).__name__}: {text}: a device's daemon (pigpiod) gone?"
    return f"{type(e).__name__}: {text}"


def stop_motors_main(args, params: Params, devices: dict | None = None) -> int:
    """The stop pulse on every ESC, whatever the last controller left on them (ExecStopPost)."""
    try:
        done = stop_motors(args.board, params, _options(args, devices))
    except BoardUnavailable as e:
        log.error("stop-motors: %s", e)
        return EXIT_ERROR
    log.info("stop-motors: %s", done)
    return EXIT_OK


def _options(args, devices: dict | None = None) -> BoardOptions:
    return BoardOptions(board_file=args.board_file, seed=args.seed, realtime=True, link=args.link,
                        devices=devices or {})


def parse_args(argv: list[str]) -> argparse.Namespace:
    p = Parser(prog="flightctl run", description=__doc__.split("\n\n")[0])
    p.add_argument("--board", default="auto", help=f"the board to fly (default auto): {described()}")
    p.add_argument("--params", help="parameter file (TOML); default: the reference airframe")
    p.add_argument("--board-file", help="pi or pi5 board wiring (TOML); default: the shipped "
                                        "flightctl/boards/pi.toml or pi5.toml")
    p.add_argument("--plan", help="a plan TOML file, or a named plan (hover, paper, ...)")
    p.add_argument("--plan-queue", metavar="DIR", help="fly each plan file put into DIR, once, in turn")
    p.add_argument("--log", default=".", metavar="DIR", help="directory for flight logs (default: .)")
    p.add_argument("--plan-max-age", type=float, default=PLAN_MAX_AGE_S, metavar="S",
                   help=f"refuse a queued plan written more than S seconds ago (default {PLAN_MAX_AGE_S:g}; "
                        f"{PLAN_MAX_AGE_RANGE_S[0]:g} to {PLAN_MAX_AGE_RANGE_S[1]:g})")
    p.add_argument("--calibrate", type=float, metavar="S",
                   help="seconds sitting still before arming (default: the board's, 60 s on the quadcopter; "
                        f"{CALIBRATE_RANGE_S[0]:g} to {CALIBRATE_RANGE_S[1]:g})")
    p.add_argument("--min-battery-v", type=float, metavar="V",
                   help="refuse to arm below this battery voltage (default: the board's; "
                        f"{MIN_BATTERY_V_RANGE[0]:g} to {MIN_BATTERY_V_RANGE[1]:g} V on the {CELLS}S pack)")
    p.add_argument("--seed", type=seed, default=0, help="simulator seed (--board sim; a whole number from 0)")
    p.add_argument("--link", help="--board hil: serial:/dev/serial0,921600 or tcp:HOST:PORT (docs/hil.md)")
    p.add_argument("--stop-motors", action="store_true", help="only put the stop pulse on the ESCs and exit")
    p.add_argument("--mavlink", metavar="URL",
                   help="a ground station (udpout:HOST:PORT, udpin:HOST:PORT, /dev/ttyAMA0,57600): telemetry, "
                        "and the pilot arms (ARM_DISARM), lands or kills from it; pip install '.[mavlink]' in the flightctl checkout")
    args = p.parse_args(argv)
    if args.plan and args.plan_queue:
        p.error("--plan and --plan-queue exclude each other")
    check_options(args.board, args.board_file, args.link)
    for flag, folder in (("--log", args.log), ("--plan-queue", args.plan_queue)):
        if folder is not None and os.path.exists(folder) and not os.path.isdir(folder):
            p.error(f"{flag} {folder}: not a directory")
    # a safety threshold outside its range is refused, never a check turned off (a nan compares false)
    for flag, value, (lo, hi), unit, why in (
            ("--plan-max-age", args.plan_max_age, PLAN_MAX_AGE_RANGE_S, "s", "a plan older is stale"),
            ("--calibrate", args.calibrate, CALIBRATE_RANGE_S, "s", "the gyro bias is averaged over it"),
            ("--min-battery-v", args.min_battery_v, MIN_BATTERY_V_RANGE, "V",
             f"from the {LOW_CELL_V:g} V a cell lands at to the {FULL_CELL_V:g} V of a full one, {CELLS} cells")):
        if value is not None and not lo <= value <= hi:
            p.error(f"{flag} {value:g}: {lo:g} to {hi:g} {unit} ({why})")
    return args


def main(argv: list[str] | None = None, devices: dict | None = None) -> int:
    """`devices`: what the board uses instead of opening its own (BoardOptions.devices; the tests' fakes)."""
    args = parse_args(list(sys.argv[1:] if argv is None else argv))
    if not logging.getLogger().handlers:
        logging.basicConfig(level=logging.INFO, format="flightctl run: %(message)s", stream=sys.stderr)
    params = load(args.params)
    if args.stop_motors:
        return stop_motors_main(args, params, devices)
    plan = check_name(load_plan(args.plan), args.plan) if args.plan else None
    try:
        open_board = opener(args.board)         # an unknown board is an InputError (exit 2)
    except BoardUnavailable as e:
        log.error("not flying: %s", e)
        return EXIT_REFUSED

    # The motor-loss gain schedule (control/spin_design.py: LQR solves, README's speed table, or read from its
    # disk cache keyed by the parameters) is solved now:
    # before the board opens (a HIL link is live from then on, and its PC side gives up on a silent
    # flight side), before READY, never between a plan's arrival and its take-off.
    SpinController(params)
    try:                                        # the flight logs' directory, before READY
        output_dir(args.log, "--log")
    except InputError as e:
        log.error("not flying: %s", e)
        return EXIT_REFUSED
    stop = threading.Event()

    def on_signal(signum, frame):
        log.info("%s: stopping", signal.Signals(signum).name)
        stop.set()

    notifier = Notifier.from_env()
    if notifier.enabled and not notifier.status("starting: disarmed"):
        log.error("not flying: NOTIFY_SOCKET=%s cannot be reached: under systemd, the watchdog pings would "
                  "fail in flight", notifier.address)
        notifier.close()
        return EXIT_REFUSED
    previous = {s: signal.signal(s, on_signal) for s in (signal.SIGTERM, signal.SIGINT)}
    board = link = None
    try:
        if args.mavlink:                        # imported only when asked for (pymavlink is an extra)
            from flightctl.comms.mavlink import open_link
            link = open_link(args.mavlink, params, arm_required=True)
        try:
            board = open_board(params, _options(args, devices))
        except BoardUnavailable as e:
            log.error("not flying: %s", e)
            return EXIT_REFUSED
        service = Service(args, params, board, notifier, stop)
        service.link = link
        try:
            service.run(plan)
        except ArmingRefused as e:
            log.error("not flying: %s", e)
            if link is not None:
                link.text(f"arming refused: {e}")
            return EXIT_REFUSED
        return EXIT_OK
    except InputError:
        raise                                   # a bad board file: one line, exit 2 (flightctl.cli)
    except Exception as e:
        if device_error(e):
            log.error("stopping on a device error, the motors stopped: %s", describe(e))
        else:
            log.exception("stopping on an error")
        return EXIT_ERROR
    finally:
        if board is not None:
            try:
                board.hal.motors.stop()
            except Exception as e:              # pigpiod gone: the dead-man or ExecStopPost stops them
                log.error("zero thrust could not be sent: %s", describe(e))
            try:
                board.close()
            except Exception as e:
                log.error("the board could not be closed: %s", describe(e))
        if link is not None:
            link.close()
        notifier.stopping()
        notifier.close()
        for s, handler in previous.items():
            signal.signal(s, handler)


if __name__ == "__main__":
    sys.exit(main())
