"""The hardware abstraction layer: one narrow Protocol per device kind.

Backends are siblings: the Pi drivers in `flightctl.drivers` and the simulated devices in
`flightctl.sim.world.devices`, wired into a `Hal` only by the boards of the registry `flightctl.boards`
(`flightctl/boards/pi.py`, `sim/world/board.py`). The simulated backends sit at the
lowest boundary that can be emulated (SPI register reads, GPIO edges with microsecond ticks, PWM
counts), so the real drivers' decode and timing code runs in every simulation.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Protocol, runtime_checkable

PWM_RANGE = 40000  # pigpio's largest PWM range: the paper's "0..255 scaled to 40000"


class ImuSample:
    """One IMU reading in SI units, body frame. Allocated once and filled in place every loop."""
    __slots__ = ("ax", "ay", "az", "gx", "gy", "gz", "mx", "my", "mz", "mag_fresh")

    def __init__(self):
        self.ax = self.ay = self.az = 0.0  # specific force, m/s^2 (level at rest: (0, 0, +g))
        self.gx = self.gy = self.gz = 0.0  # body rates p, q, r in rad/s
        self.mx = self.my = self.mz = 0.0  # magnetic field, body frame, T
        self.mag_fresh = False             # mx..mz hold a valid field (the AK8963 updates at 100 Hz: repeats)


@runtime_checkable
class SpiDevice(Protocol):
    """The part of `spidev.SpiDev` the drivers use."""
    max_speed_hz: int

    def xfer2(self, data: list[int]) -> list[int]: ...


# pigpio's protocol values for the calls below (pigpio.py: INPUT, OUTPUT, EITHER_EDGE, and the level
# TIMEOUT of a watchdog report), kept here so that the simulator runs without the Pi libraries
GPIO_INPUT, GPIO_OUTPUT, EITHER_EDGE, LEVEL_TIMEOUT = 0, 1, 2, 2


def tick_diff(t1: int, t2: int) -> int:
    """Microseconds from tick t1 to t2 across the 32-bit wrap (as `pigpio.tickDiff`)."""
    return (t2 - t1) & 0xFFFFFFFF


@runtime_checkable
class Gpio(Protocol):
    """The part of `pigpio.pi` the HC-SR04 driver uses (edges arrive as `func(gpio, level, tick)`)."""

    def set_mode(self, gpio: int, mode: int) -> int: ...
    def gpio_trigger(self, user_gpio: int, pulse_len: int = 10, level: int = 1) -> int: ...
    def callback(self, user_gpio: int, edge: int, func: Callable[[int, int, int], None]): ...
    def set_watchdog(self, user_gpio: int, wdog_timeout: int) -> int: ...
    def get_current_tick(self) -> int: ...


@runtime_checkable
class Imu(Protocol):
    def start(self) -> None: ...
    def read(self, out: ImuSample) -> bool:
        """Fill `out`; False if the frame is bad (bus error pattern, stuck data)."""
        ...


@runtime_checkable
class Motors(Protocol):
    def arm(self) -> None:
        """Check the output really runs at the ESC frequency; raise `ArmingRefused` otherwise."""
        ...

    def write(self, counts: list[int]) -> None:
        """Four PWM counts on the 0..PWM_RANGE scale (duty cycle of the ESC signal)."""
        ...

    def stop(self) -> None:
        """Zero thrust on every motor. Must be safe to call at any time, more than once."""
        ...


@runtime_checkable
class Rangefinder(Protocol):
    def trigger(self) -> None: ...
    def poll(self) -> float | None:
        """The distance of an echo that arrived since the last poll, in m; NaN for a failed
        measurement (no echo, stuck echo, out of range); None if nothing new."""
        ...


@runtime_checkable
class PowerMonitor(Protocol):
    def read(self) -> tuple[float, float]:
        """Battery voltage in V and current in A."""
        ...


@runtime_checkable
class Clock(Protocol):
    period: float

    def now(self) -> float: ...
    def wait_next(self) -> float:
        """Block until the next loop deadline and return its time in s. In simulation this is
        where the world advances by one period (lock-step); on the Pi it keeps wall-clock deadlines."""
        ...


class ArmingRefused(Exception):
    """The vehicle will not arm; the message names the reason."""


@dataclass
class Hal:
    imu: Imu
    motors: Motors
    rangefinder: Rangefinder
    power: PowerMonitor
    clock: Clock
