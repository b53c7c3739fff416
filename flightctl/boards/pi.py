"""The quadcopter's board ("pi" in `flightctl.boards`): the drivers wired from a TOML board file
(pins, SPI, I2C), behind the HAL.

    board = open_pi_board(params)                    # the shipped flightctl/boards/pi.toml
    board = open_pi_board(params, "my_board.toml")   # its keys replace the shipped file's

The board file has a schema, like the parameters: every key has a type, a unit, a range and a
description (the dataclasses below). The shipped flightctl/boards/pi.toml holds the wiring of the
reference quadcopter; a board file given with --board-file replaces the keys it names; a key that
neither gives takes the schema's default (the ESC timings are the ESC drivers' own, drivers/pulses.py and esc.py;
the battery threshold is every board's, flightctl/boards/__init__.py). Every problem is one line naming the key.

The ESC output is started first, so the ESCs see the stop pulse as early as possible; then the IMU
(wrong chip -> `ImuError`), the sonar and the power monitor. If a device fails, what was opened is
closed again (the ESCs stay at the stop pulse in pigpiod) and the error propagates. The devices can
be passed in (`pi=`, `spi=`, `smbus=`), which is how the tests wire this board to fakes.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from flightctl.boards import Board, BoardOptions, BoardUnavailable, missing_module
from flightctl.boards.boardfile import (CALIBRATE_S, GPIO, MAX_US, STOP_US, ChecksConfig, ImuConfig, PowerConfig,
                                        SonarConfig, check_pins, check_pulses, closer, key, load_sections,
                                        start_sensors)
from flightctl.clock import WallClock
from flightctl.drivers import esc
from flightctl.drivers.esc import EscError, PigpioEsc
from flightctl.drivers.ina219 import PowerMonitorError
from flightctl.drivers.mpu9250 import ImuError
from flightctl.hal import Hal
from flightctl.params import Params

DEFAULT_BOARD_FILE = "pi.toml"


@dataclass(frozen=True)
class PigpioConfig:
    host: str = key("", None, None, "pigpiod's address (it is bound to localhost only)")
    port: int = key("TCP port", 1, 65535, "pigpiod's port")


@dataclass(frozen=True)
class EscConfig:
    pins: tuple[int, ...] = key(*GPIO, "the four ESC signals, motor 1 (N), 2 (W), 3 (S), 4 (E)")
    stop_us: int = key(*STOP_US)
    max_us: int = key(*MAX_US)
    deadman_ms: int = key("ms", 20, 1000, "pigpiod stops the motors this long after the last command",
                          esc.DEADMAN_MS)
    tolerance_hz: float = key("Hz", 0.05, 5.0, "arming is refused if the measured output is further from "
                              "esc_pwm_hz", esc.FREQUENCY_TOLERANCE_HZ)


SECTIONS = {"pigpio": PigpioConfig, "esc": EscConfig, "imu": ImuConfig, "sonar": SonarConfig,
            "power": PowerConfig, "checks": ChecksConfig}


@dataclass(frozen=True)
class BoardConfig:
    pigpio: PigpioConfig
    esc: EscConfig
    imu: ImuConfig
    sonar: SonarConfig
    power: PowerConfig
    checks: ChecksConfig
    path: str               # the board file read (or the shipped one)


def load_board(path: str | Path | None = None) -> BoardConfig:
    """Read and check a board file over the shipped flightctl/boards/pi.toml (None: the shipped one)."""
    sections, name = load_sections(DEFAULT_BOARD_FILE, SECTIONS, path)
    config = BoardConfig(**sections, path=name)
    _check(config)
    return config


def _check(c: BoardConfig) -> None:
    """What the ranges of single keys cannot say."""
    check_pins(c.path, c.esc.pins, c.sonar)
    check_pulses(c.path, c.esc)


def connect_pigpio(config: BoardConfig):
    import pigpio

    pi = pigpio.pi(config.pigpio.host, config.pigpio.port, show_errors=False)
    if not pi.connected:
        raise BoardUnavailable(f"cannot reach pigpiod at {config.pigpio.host}:{config.pigpio.port} "
                               "(is pigpiod.service running?)")
    return pi


def open_pi_board(params: Params, config_path: str | Path | None = None, *, pi=None, spi=None, smbus=None,
                  clock=None, config: BoardConfig | None = None) -> Board:
    config = config if config is not None else load_board(config_path)
    a = params.airframe
    closers: list = []
    close = closer(closers)
    try:
        if pi is None:
            pi = connect_pigpio(config)
            closers.append(pi.stop)
        e = config.esc
        motors = PigpioEsc(pi, e.pins, a.esc_pwm_hz, e.stop_us, e.max_us, e.deadman_ms, e.tolerance_hz)
        motors.start()
        closers.append(motors.close)
        imu, sonar, power = start_sensors(config, pi, spi, smbus, closers)
    except BaseException:
        close()
        raise
    hal = Hal(imu=imu, motors=motors, rangefinder=sonar, power=power, clock=clock or WallClock(a.dt))
    return Board(hal, "pi", config.checks.min_battery_v, CALIBRATE_S, close,
                 meta={"board_file": config.path, "esc_pins": str(list(config.esc.pins)), **imu.filters()})


def open_board(params: Params, options: BoardOptions) -> Board:
    """The registry's opener: a device that is missing or wrong is `BoardUnavailable`."""
    try:
        return open_pi_board(params, options.board_file, **options.devices)
    except (ImuError, PowerMonitorError, EscError) as e:
        raise BoardUnavailable(str(e)) from e
    except ModuleNotFoundError as e:        # spidev or smbus2, imported when their device is opened
        raise missing_module("pi", e) from None


def stop_motors(params: Params, options: BoardOptions) -> str:
    """The stop pulse on every ESC, whatever the last controller left in pigpiod (ExecStopPost)."""
    config = load_board(options.board_file)
    pi = connect_pigpio(config)
    try:
        esc.stop_motors(pi, config.esc.pins, params.airframe.esc_pwm_hz, config.esc.stop_us)
    finally:
        pi.stop()
    return f"stop pulse ({config.esc.stop_us} us) on GPIO {list(config.esc.pins)}"
