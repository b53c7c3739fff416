"""The quadcopter's board: the drivers wired from a TOML board file (pins, SPI, I2C), behind the HAL.

    hal = pi_board(params)                         # the shipped flightctl/board_pi.toml
    board = open_pi_board(params, "my_board.toml") # the same, with the config and close()

The ESC output is started first, so the ESCs see the stop pulse as early as possible; then the IMU
(wrong chip -> `ImuError`), the sonar and the power monitor. If a device fails, what was opened is
closed again (the ESCs stay at the stop pulse in pigpiod) and the error propagates. The devices can
be passed in (`pi=`, `spi=`, `smbus=`), which is how the tests wire this board to fakes.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

from flightctl.clock import WallClock
from flightctl.drivers.esc import PigpioEsc
from flightctl.drivers.hcsr04 import HcSr04
from flightctl.drivers.ina219 import Ina219
from flightctl.drivers.mpu9250 import Mpu9250
from flightctl.errors import InputError, read_toml
from flightctl.hal import Hal
from flightctl.params import Params

DEFAULT_BOARD_FILE = "board_pi.toml"
RESERVED_PINS = {2: "I2C SDA", 3: "I2C SCL", 7: "SPI CE1", 8: "SPI CE0", 9: "SPI MISO", 10: "SPI MOSI",
                 11: "SPI SCLK", 14: "UART TX", 15: "UART RX"}


class BoardUnavailable(Exception):
    """A device of the board cannot be reached (pigpiod not running, no SPI or I2C device node)."""


@dataclass(frozen=True)
class PigpioConfig:
    host: str = "127.0.0.1"
    port: int = 8888


@dataclass(frozen=True)
class EscConfig:
    pins: tuple[int, ...] = (17, 27, 22, 25)
    stop_us: int = 1000
    max_us: int = 2100
    deadman_ms: int = 100
    tolerance_hz: float = 0.5


@dataclass(frozen=True)
class ImuConfig:
    spi_bus: int = 0
    spi_device: int = 0
    spi_mode: int = 3


@dataclass(frozen=True)
class SonarConfig:
    trigger_pin: int = 23
    echo_pin: int = 24


@dataclass(frozen=True)
class PowerConfig:
    i2c_bus: int = 1
    address: int = 0x40
    shunt_ohm: float = 0.002
    max_current_a: float = 60.0


@dataclass(frozen=True)
class ChecksConfig:
    min_battery_v: float = 14.4


@dataclass(frozen=True)
class BoardConfig:
    pigpio: PigpioConfig = field(default_factory=PigpioConfig)
    esc: EscConfig = field(default_factory=EscConfig)
    imu: ImuConfig = field(default_factory=ImuConfig)
    sonar: SonarConfig = field(default_factory=SonarConfig)
    power: PowerConfig = field(default_factory=PowerConfig)
    checks: ChecksConfig = field(default_factory=ChecksConfig)
    path: str = "(defaults)"


def _value(where: str, f: dataclasses.Field, value):
    want = type(f.default) if f.default is not dataclasses.MISSING else None
    if want is tuple:
        if not isinstance(value, list) or not all(isinstance(v, int) and not isinstance(v, bool) for v in value):
            raise InputError(f"{where}: expected a list of integers, got {value!r}")
        return tuple(value)
    if want is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise InputError(f"{where}: expected a number, got {value!r}")
        return float(value)
    if want is int and (isinstance(value, bool) or not isinstance(value, int)):
        raise InputError(f"{where}: expected an integer, got {value!r}")
    if want is str and not isinstance(value, str):
        raise InputError(f"{where}: expected a string, got {value!r}")
    return value


def load_board(path: str | Path | None = None) -> BoardConfig:
    """Read and check a board file; None reads the shipped flightctl/board_pi.toml."""
    if path is None:
        name = DEFAULT_BOARD_FILE
        data = read_toml(name, resources.files("flightctl").joinpath(DEFAULT_BOARD_FILE).read_text())
    else:
        name = str(path)
        data = read_toml(name)
    sections = {f.name: f for f in dataclasses.fields(BoardConfig) if f.name != "path"}
    built = {}
    for section, table in data.items():
        if section not in sections:
            raise InputError(f"{name}: unknown section [{section}] (known: {', '.join(sections)})")
        if not isinstance(table, dict):
            raise InputError(f"{name}: {section}: expected a table [{section}]")
        cls = sections[section].default_factory
        fields = {f.name: f for f in dataclasses.fields(cls)}
        values = {}
        for key, value in table.items():
            if key not in fields:
                raise InputError(f"{name}: {section}.{key}: unknown key (known: {', '.join(fields)})")
            values[key] = _value(f"{name}: {section}.{key}", fields[key], value)
        built[section] = cls(**values)
    config = BoardConfig(**built, path=name)
    _check(config)
    return config


def _check(c: BoardConfig) -> None:
    where = c.path
    pins = list(c.esc.pins) + [c.sonar.trigger_pin, c.sonar.echo_pin]
    if len(c.esc.pins) != 4:
        raise InputError(f"{where}: esc.pins: four GPIOs needed (motor 1..4), got {list(c.esc.pins)}")
    for p in pins:
        if not 0 <= p <= 31:
            raise InputError(f"{where}: GPIO {p} is not a user GPIO (0..31)")
        if p in RESERVED_PINS:
            raise InputError(f"{where}: GPIO {p} is the {RESERVED_PINS[p]} pin")
    if len(set(pins)) != len(pins):
        raise InputError(f"{where}: a GPIO is used twice among esc.pins and the sonar pins: {pins}")
    if not 0 < c.esc.stop_us < c.esc.max_us:
        raise InputError(f"{where}: esc: need 0 < stop_us < max_us")
    if not 0x03 <= c.power.address <= 0x77:
        raise InputError(f"{where}: power.address 0x{c.power.address:X} is not a 7-bit I2C address")
    if c.power.shunt_ohm <= 0 or c.power.max_current_a <= 0:
        raise InputError(f"{where}: power: shunt_ohm and max_current_a must be positive")


@dataclass
class PiBoard:
    hal: Hal
    config: BoardConfig
    pi: object
    closers: list = field(default_factory=list)

    def close(self) -> None:
        """Leave the ESCs at the stop pulse and release every device (safe to call twice)."""
        closers, self.closers = self.closers, []
        for close in reversed(closers):
            try:
                close()
            except Exception:
                pass


def connect_pigpio(config: BoardConfig):
    import pigpio

    pi = pigpio.pi(config.pigpio.host, config.pigpio.port, show_errors=False)
    if not pi.connected:
        raise BoardUnavailable(f"cannot reach pigpiod at {config.pigpio.host}:{config.pigpio.port} "
                               "(is pigpiod.service running?)")
    return pi


def open_pi_board(params: Params, config_path: str | Path | None = None, *, pi=None, spi=None, smbus=None,
                  config: BoardConfig | None = None) -> PiBoard:
    config = config if config is not None else load_board(config_path)
    a = params.airframe
    closers = []
    try:
        if pi is None:
            pi = connect_pigpio(config)
            closers.append(pi.stop)
        e = config.esc
        motors = PigpioEsc(pi, e.pins, a.esc_pwm_hz, e.stop_us, e.max_us, e.deadman_ms, e.tolerance_hz)
        motors.start()
        closers.append(motors.close)
        if spi is None:
            spi = _open_spi(config.imu)
            closers.append(spi.close)
        imu = Mpu9250(spi)
        imu.start()
        sonar = HcSr04(pi, config.sonar.trigger_pin, config.sonar.echo_pin)
        sonar.start()
        closers.append(sonar.stop)
        if smbus is None:
            smbus = _open_smbus(config.power.i2c_bus)
            closers.append(smbus.close)
        power = Ina219(smbus, config.power.address, config.power.shunt_ohm, config.power.max_current_a,
                       bus_name=f"/dev/i2c-{config.power.i2c_bus}")
        power.start()
    except BaseException:
        for close in reversed(closers):
            try:
                close()
            except Exception:
                pass
        raise
    hal = Hal(imu=imu, motors=motors, rangefinder=sonar, power=power, clock=WallClock(a.dt))
    return PiBoard(hal, config, pi, closers)


def _open_spi(c: ImuConfig):
    import spidev

    spi = spidev.SpiDev()
    try:
        spi.open(c.spi_bus, c.spi_device)
    except OSError as e:
        raise BoardUnavailable(f"cannot open /dev/spidev{c.spi_bus}.{c.spi_device} ({e.strerror}); "
                               "is SPI enabled (raspi-config nonint do_spi 0) and the user in group spi?") from None
    spi.mode = c.spi_mode
    return spi


def _open_smbus(bus: int):
    import smbus2

    try:
        return smbus2.SMBus(bus)
    except OSError as e:
        raise BoardUnavailable(f"cannot open /dev/i2c-{bus} ({e.strerror}); "
                               "is I2C enabled (raspi-config nonint do_i2c 0) and the user in group i2c?") from None


def pi_board(params: Params, config_path: str | Path | None = None, **devices) -> Hal:
    """The quadcopter's Hal (what `flightctl.boards.make_hal("pi", params)` returns)."""
    return open_pi_board(params, config_path, **devices).hal
