"""Faults injected at the simulated devices' boundary: each wraps a device of the sim board
after it is built, from `at` seconds of simulated time, so that the real drivers and the onboard loop
meet them exactly as on the quadcopter. `parse("imu_frozen:at=5")` -> a Fault;
`Fault.apply(hal, world, log)` (`log`: the flight log writer, for the disk fault only).

- imu_frozen: every IMU burst from `at` returns the bytes of the last one before it (the chip's SPI
  transfer, `SimMpu9250.xfer2`);
- imu_garbage: random bytes; imu_intermittent: one burst in `every` (20) is random bytes;
- gyro_saturation: the gyro x word stuck at +32767 (full scale);
- accel_zero: the three accelerometer words read 0 (a dead accelerometer; the gyro lives on);
- sonar_silent: the HC-SR04 gives no echo edges at all (`SimGpio.gpio_trigger` schedules none; the
  driver's pigpio watchdog reports the quiet line);
- sonar_stuck: the echo line goes high and stays there (`SimGpio.stick_echo_high`);
- battery_critical: the battery's terminal voltage falls to `cell` V per cell (3.3) under the INA219,
  and the motors get that voltage (eq. 26);
- motor_stop: motor `motor` (1..4, default 1) gives no thrust in the plant while the loop still
  commands it (the PWM counts reach the plant; its P is replaced by 0);
- motor_partial: motor `motor` gives `share` (0..1) of the thrust it is commanded (a failing ESC, a
  chipped propeller): its P is replaced by the one whose thrust that is (eq. 26: P' = h2 + sqrt(share)
  (P - h2)), so that its speed and torque (eq. 27-28) follow; motor_stop is share 0;
- cpu_stall: once, at `at`, the loop misses `ms` (50) of ticks: the sim clock jumps while the motors
  hold their last command (an ESC keeps its last pulse width);
- log_full: every write of the flight log from `at` raises OSError ENOSPC (a full card);
- loop_late: from `at`, the loop's ticks come late as a loaded Pi's do, drawn from the distribution
  `dist` (`busy`, `quiet`, `paper`: sim/world/loop_lateness/, scripts/loop_lateness.py) with `rate`
  times its share of late ticks (1), seeded by `seed` (the flight's seed): the board's clock becomes a
  `sim.world.lateness.LateClock`, and a late tick acts late on the plant.
"""
from __future__ import annotations

import errno
import random
from dataclasses import dataclass, field

from flightctl.battery import CELLS   # the simulated pack is the vehicle's 4S (sim/world/power.py)
from flightctl.drivers import mpu9250_regs as reg
from flightctl.errors import InputError
from flightctl.sim.world.lateness import LateClock, load, names

_GYRO_X = 1 + 8   # byte offset of GYRO_XOUT_H in the burst's reply (after the address byte)


@dataclass
class Fault:
    name: str
    at: float = 5.0                       # s of simulated time (the world's clock) when it begins;
                                          # `flightctl sim --fault` and sim.run.fly count it from arming
    options: dict = field(default_factory=dict)

    def apply(self, hal, world, log=None) -> None:
        name = self.name
        if name in _IMU:
            _imu(self, hal, world)
        elif name == "sonar_silent":
            gpio, inner = world.gpio, world.gpio.gpio_trigger
            gpio.gpio_trigger = lambda pin, pulse_len=10, level=1: (
                0 if world.t >= self.at else inner(pin, pulse_len, level))
        elif name == "sonar_stuck":
            _at(world, self.at, world.gpio.stick_echo_high)
        elif name == "battery_critical":
            battery, inner, v = world.battery, world.battery.advance, self.options.get("cell", 3.3) * CELLS

            def advance(dt):
                inner(dt)
                if world.t >= self.at:
                    battery.voltage = min(battery.voltage, v)
            battery.advance = advance
        elif name in ("motor_stop", "motor_partial"):
            _motor(world, self.at, int(self.options.get("motor", 1)) - 1,
                   self.options.get("share", 0.5) if name == "motor_partial" else 0.0)
        elif name == "cpu_stall":
            clock, inner = hal.clock, hal.clock.wait_next
            missed = max(1, round(self.options.get("ms", 50.0) / 1000.0 / clock.period))
            state = {"done": False}

            def wait_next():
                t = inner()
                if not state["done"] and t >= self.at:
                    state["done"] = True
                    for _ in range(missed):
                        t = inner()
                return t
            clock.wait_next = wait_next
        elif name == "loop_late":
            o = self.options
            hal.clock = LateClock(world, load(o.get("dist", "busy")), o.get("rate", 1.0), int(o.get("seed", world.seed)),
                                  self.at)
        elif name == "log_full":
            if log is None:
                raise InputError("log_full: the flight has no log")
            log._f = _FullDisk(log._f, world, self.at)


_IMU = ("imu_frozen", "imu_garbage", "imu_intermittent", "gyro_saturation", "accel_zero")


def _imu(fault: Fault, hal, world) -> None:
    chip = hal.imu.spi
    inner = chip.xfer2
    rng = random.Random(int(fault.options.get("seed", 1)))
    every = int(fault.options.get("every", 20))
    state = {"last": None, "n": 0}
    burst = reg.READ | reg.ACCEL_XOUT_H
    name = fault.name

    def xfer2(data):
        rx = inner(data)
        if data[0] != burst:
            return rx
        if world.t < fault.at:
            state["last"] = list(rx)
            return rx
        state["n"] += 1
        if name == "imu_frozen":
            return list(state["last"])
        if name == "imu_garbage" or (name == "imu_intermittent" and state["n"] % every == 0):
            return [0] + [rng.randrange(256) for _ in rx[1:]]
        if name == "gyro_saturation":
            rx = list(rx)
            rx[_GYRO_X], rx[_GYRO_X + 1] = 0x7F, 0xFF
        if name == "accel_zero":
            rx = [rx[0]] + [0] * 6 + list(rx[7:])
        return rx
    chip.xfer2 = xfer2


def _motor(world, at: float, k: int, share: float) -> None:
    """From `at`, motor k's command value P gives `share` of its thrust (eq. 26); share 0: P = 0."""
    plant, inner, h2 = world.plant, world.plant.command, world.plant.model.a.h2
    root = share ** 0.5

    def command(P1, P2, P3, P4, battery_v):
        P = [P1, P2, P3, P4]
        if world.t >= at:
            P[k] = h2 + root * (P[k] - h2) if share > 0.0 and P[k] > h2 else 0.0
        inner(P[0], P[1], P[2], P[3], battery_v)
    plant.command = command


def _at(world, at: float, action) -> None:
    """Call `action()` once, at the first world step that reaches `at`."""
    inner, state = world.advance, {"done": False}

    def advance(dt):
        inner(dt)
        if not state["done"] and world.t >= at:
            state["done"] = True
            action()
    world.advance = advance


class _FullDisk:
    """The log's file object: from `at` (simulated time) every write raises ENOSPC, writing nothing."""

    def __init__(self, f, world, at: float):
        self._f, self._world, self._at = f, world, at

    def write(self, text: str) -> int:
        if self._world.t >= self._at:
            raise OSError(errno.ENOSPC, "No space left on device")
        return self._f.write(text)

    def flush(self) -> None:
        self._f.flush()

    def close(self) -> None:
        self._f.close()


FAULTS = _IMU + ("sonar_silent", "sonar_stuck", "battery_critical", "motor_stop", "motor_partial", "cpu_stall",
                   "log_full")
# a load rather than a fault: the loop names none of it (a tick late by whole periods is a stall it names),
# so it is flown in docs/safety.md's late-loop section, not in the fault matrix (`flightctl sim faults`)
LOADS = ("loop_late",)
_LIMITS = {"cell": (2.5, 4.2), "motor": (1, 4), "ms": (20.0, 100.0), "every": (2, 1e6), "share": (0.0, 1.0),
           "rate": (0.0, 1000.0)}   # the brief's 20-100 ms
# the keys each fault takes besides `at` (an unknown key is refused, never ignored)
_KEYS = {"imu_garbage": ("seed",), "imu_intermittent": ("every", "seed"), "battery_critical": ("cell",),
         "motor_stop": ("motor",), "motor_partial": ("motor", "share"), "cpu_stall": ("ms",),
         "loop_late": ("dist", "rate", "seed")}
_NAMED = {"dist": names}   # keys whose value is a name, not a number: the names they take


def parse(text: str) -> Fault:
    """NAME[:k=v,...]: `at` (s) for all; `every`, `seed` (IMU), `cell` (V, battery_critical), `motor`
    (1..4, motor_stop, motor_partial), `share` (0..1, motor_partial: default 0.5), `ms` (20..100, cpu_stall),
    `dist` (a name), `rate` (0..1000) and `seed` (loop_late)."""
    name, _, rest = text.partition(":")
    if name not in FAULTS + LOADS:
        raise InputError(f"--fault {text}: unknown fault {name!r} (known: {', '.join(FAULTS + LOADS)})")
    opts = {}
    allowed = ("at",) + _KEYS.get(name, ())
    for kv in filter(None, rest.split(",")):
        k, sep, v = kv.partition("=")
        k = k.strip()
        if k not in allowed:
            raise InputError(f"--fault {text}: unknown key {k!r} for {name} (known: {', '.join(allowed)})")
        if k in opts:
            raise InputError(f"--fault {text}: {k} given twice")
        if k in _NAMED:
            if v not in _NAMED[k]():
                raise InputError(f"--fault {text}: {k} must be one of {', '.join(_NAMED[k]())}")
            opts[k] = v
            continue
        try:
            opts[k] = float(v) if sep else None
        except ValueError:
            raise InputError(f"--fault {text}: {k}={v} is not a number") from None
    at = opts.pop("at", 5.0)
    if at is None or not 0.0 <= at < 1e6:
        raise InputError(f"--fault {text}: at must be a time in s")
    for k, v in opts.items():
        if k in _NAMED:
            continue
        lo, hi = _LIMITS.get(k, (0, 2**31))
        if v is None or not lo <= v <= hi:
            raise InputError(f"--fault {text}: {k} must be a number in {lo:g}..{hi:g}")
    return Fault(name, at, opts)
