"""The quadcopter's board on a Raspberry Pi 5 ("pi5" in `flightctl.boards`): the same HAL, drivers and
control code as the pigpio board of a Pi 3/4 (flightctl/boards/pi.py), with the two pigpio parts replaced
by the kernel's interfaces, which the Pi 5's RP1 I/O chip offers and pigpio cannot reach:

- the four ESC signals: the RP1's hardware PWM (PWM0, four channels at 449 Hz on GPIO 12, 13, 18, 19)
  through the kernel's sysfs PWM interface (drivers/pwm_sysfs.py), with its dead-man process;
- the HC-SR04: the trigger and the echo through the GPIO character device (libgpiod 2.x), the echo
  timed by the kernel's edge timestamps (drivers/gpio_cdev.py under the one sonar driver, drivers/hcsr04.py);
- the MPU-9250 over spidev and the INA219 over smbus2, as on the Pi 3/4.

    board = open_pi5_board(params)                   # the shipped flightctl/boards/pi5.toml
    board = open_pi5_board(params, "my_board.toml")  # its keys replace the shipped file's

The board file has the schema of flightctl/boards/boardfile.py; its [pwm] and [gpio] sections are this
board's own. The ESC output is started first (the stop pulse as early as possible); if a device fails,
what was opened is closed again (the ESC channels released: lines low, no signal) and the error
propagates. The devices can be passed in (`pwm_root=`, `pwm_fs=`, `gpio_chip=`, `spi=`, `smbus=`,
`clock=`), which is how the tests wire this board to its fakes.
"""
from __future__ import annotations

import glob
import importlib
import os
import time
from dataclasses import dataclass
from pathlib import Path

from flightctl.boards import Board, BoardOptions, BoardUnavailable, missing_module
from flightctl.boards.boardfile import (CALIBRATE_S, GPIO, MAX_US, STOP_US, ChecksConfig, ImuConfig, PowerConfig,
                                        SonarConfig, check_pins, check_pulses, closer, key, load_sections,
                                        start_sensors)
from flightctl.clock import WallClock
from flightctl.drivers import pulses
from flightctl.drivers.gpio_cdev import CdevGpio, GpioBusy
from flightctl.drivers.ina219 import PowerMonitorError
from flightctl.drivers.mpu9250 import ImuError
from flightctl.drivers.pulses import EscError
from flightctl.drivers.pwm_sysfs import SYSFS_PWM, SysfsPwmEsc, release
from flightctl.errors import InputError
from flightctl.hal import Hal
from flightctl.params import Params

DEFAULT_BOARD_FILE = "pi5.toml"
RP1_PWM0 = "1f00098000.pwm"             # the RP1's PWM0 (rp1.dtsi: pwm@98000)
# the header GPIOs of the RP1's PWM0 channels (RP1 peripherals datasheet; pinctrl-rp1: GPIO 12, 13 at
# function a0, 14, 15 at a0, 18, 19 at a3)
RP1_PWM0_CHANNEL = {12: 0, 13: 1, 14: 2, 15: 3, 18: 2, 19: 3}
GPIO_WAIT_S = 5.0                       # at boot: the GPIO chip, and udev giving it to group gpio


@dataclass(frozen=True)
class PwmConfig:
    chip: str = key("", None, None, "the PWM chip: its device (1f00098000.pwm, the RP1's PWM0) or pwmchipN")
    channels: tuple[int, ...] = key("", 0, 15, "the four PWM channels of motor 1 (N), 2 (W), 3 (S), 4 (E)")
    pins: tuple[int, ...] = key(*GPIO, "the header GPIOs those channels reach (for the messages and the checks)")


@dataclass(frozen=True)
class EscConfig:
    stop_us: int = key(*STOP_US)
    max_us: int = key(*MAX_US)
    deadman_ms: int = key("ms", 20, 1000, "the dead-man process stops the motors this long after the last "
                          "command", pulses.DEADMAN_MS)


@dataclass(frozen=True)
class GpioConfig:
    chip: str = key("", None, None, "the GPIO character device: its label (pinctrl-rp1) or a /dev/gpiochipN path")


SECTIONS = {"pwm": PwmConfig, "esc": EscConfig, "gpio": GpioConfig, "imu": ImuConfig, "sonar": SonarConfig,
            "power": PowerConfig, "checks": ChecksConfig}


@dataclass(frozen=True)
class Pi5Config:
    pwm: PwmConfig
    esc: EscConfig
    gpio: GpioConfig
    imu: ImuConfig
    sonar: SonarConfig
    power: PowerConfig
    checks: ChecksConfig
    path: str


def load_board(path: str | Path | None = None) -> Pi5Config:
    """Read and check a board file over the shipped flightctl/boards/pi5.toml (None: the shipped one)."""
    sections, name = load_sections(DEFAULT_BOARD_FILE, SECTIONS, path)
    c = Pi5Config(**sections, path=name)
    check_pins(name, c.pwm.pins, c.sonar, "pwm.pins")
    if len(c.pwm.channels) != 4 or len(set(c.pwm.channels)) != 4:
        raise InputError(f"{name}: pwm.channels: four different channels needed (motor 1..4), got {list(c.pwm.channels)}")
    if c.pwm.chip == RP1_PWM0:
        for pin, channel in zip(c.pwm.pins, c.pwm.channels):
            if pin not in RP1_PWM0_CHANNEL:
                raise InputError(f"{name}: pwm.pins: GPIO {pin} has no channel of the RP1's PWM0 "
                                 "(GPIO 12, 13, 18, 19 have)")
            if RP1_PWM0_CHANNEL[pin] != channel:
                raise InputError(f"{name}: pwm: GPIO {pin} is the RP1's PWM0 channel {RP1_PWM0_CHANNEL[pin]}, "
                                 f"not channel {channel}")
    check_pulses(name, c.esc)
    return c


def _gpiod_chip(path: str):
    """`gpiod.Chip(path)`, or None if `path` is not a GPIO character device."""
    import gpiod

    return gpiod.Chip(path) if gpiod.is_gpiochip_device(path) else None


def open_gpio_chip(name: str, *, pattern: str = "/dev/gpiochip*", open_chip=_gpiod_chip, wait_s: float = GPIO_WAIT_S,
                   clock=time.monotonic, sleep=time.sleep):
    """The `gpiod.Chip` labelled `name` (or at the path `name`), among the devices `pattern` matches (the
    RP1's "pinctrl-rp1" is gpiochip4 on early 6.6 kernels and gpiochip0 later). At boot the chip may not
    be there yet, or not yet group gpio's (udev): looked for again until `wait_s` has passed."""
    end = clock() + wait_s
    while True:
        try:
            return _find_gpio_chip(name, pattern, open_chip)
        except BoardUnavailable:
            if clock() > end:
                raise
        sleep(0.1)


def _find_gpio_chip(name: str, pattern: str, open_chip):
    paths = [name] if name.startswith("/") else sorted(glob.glob(pattern))
    seen = []
    for path in paths:
        try:
            chip = open_chip(path)
        except PermissionError:
            raise BoardUnavailable(f"cannot open {path} (permission denied); is the user in group gpio?") from None
        except OSError as e:
            raise BoardUnavailable(f"cannot open {path} ({e.strerror})") from None
        if chip is None:
            continue
        label = chip.get_info().label
        if name == path or label == name:
            return chip
        seen.append(f"{path} ({label})")
        chip.close()
    raise BoardUnavailable(f"no GPIO chip {name!r} (there: {', '.join(seen) or 'none'})")


def open_pi5_board(params: Params, config_path: str | Path | None = None, *, pwm_root: str = SYSFS_PWM,
                   pwm_fs=os, gpio_chip=None, spi=None, smbus=None, clock=None,
                   config: Pi5Config | None = None) -> Board:
    config = config if config is not None else load_board(config_path)
    for library, given in (("gpiod", gpio_chip), ("spidev", spi), ("smbus2", smbus)):
        if given is None:           # a missing library is named before any device is touched
            importlib.import_module(library)
    a = params.airframe
    closers: list = []
    close = closer(closers)
    try:
        p, e = config.pwm, config.esc
        motors = SysfsPwmEsc(p.chip, p.channels, a.esc_pwm_hz, e.stop_us, e.max_us, e.deadman_ms,
                             pins=p.pins, root=pwm_root, fs=pwm_fs)
        closers.append(motors.close)
        motors.start()
        if gpio_chip is None:
            gpio_chip = open_gpio_chip(config.gpio.chip)
            closers.append(gpio_chip.close)
        lines = CdevGpio(gpio_chip, config.sonar.trigger_pin, config.sonar.echo_pin)
        lines.start()
        closers.append(lines.close)
        imu, sonar, power = start_sensors(config, lines, spi, smbus, closers)
    except BaseException:
        close()
        raise
    hal = Hal(imu=imu, motors=motors, rangefinder=sonar, power=power, clock=clock or WallClock(a.dt))
    return Board(hal, "pi5", config.checks.min_battery_v, CALIBRATE_S, close,
                 meta={"board_file": config.path, "esc_pwm": f"{p.chip} channels {list(p.channels)}",
                       "esc_pins": str(list(p.pins)), **imu.filters()})


def open_board(params: Params, options: BoardOptions) -> Board:
    """The registry's opener: a device that is missing, wrong or held by another process is
    `BoardUnavailable`."""
    try:
        return open_pi5_board(params, options.board_file, **options.devices)
    except (ImuError, PowerMonitorError, EscError, GpioBusy) as e:
        raise BoardUnavailable(str(e)) from e
    except ModuleNotFoundError as e:        # gpiod, spidev or smbus2, imported when their device is opened
        raise missing_module("pi5", e) from None


def stop_motors(params: Params, options: BoardOptions) -> str:
    """Whatever the last controller left on the ESC channels: the stop pulse, then the channels disabled
    and unexported (the lines low: no signal, zero thrust). The unit's ExecStopPost."""
    config = load_board(options.board_file)
    devices = options.devices
    try:
        done = release(devices.get("pwm_root", SYSFS_PWM), config.pwm.chip, config.pwm.channels,
                       config.esc.stop_us, fs=devices.get("pwm_fs", os))
    except EscError as e:
        raise BoardUnavailable(str(e)) from e
    if not done:
        return f"no ESC channel of {config.pwm.chip} was exported: nothing to stop"
    return (f"stop pulse ({config.esc.stop_us} us), then disabled and unexported: {', '.join(done)} of "
            f"{config.pwm.chip} (GPIO {list(config.pwm.pins)})")
