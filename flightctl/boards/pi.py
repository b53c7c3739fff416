"""The quadcopter's board ("pi" in `flightctl.boards`): the drivers wired from a TOML board file
(pins, SPI, I2C), behind the HAL.

    board = open_pi_board(params)                    # the shipped flightctl/boards/pi.toml
    board = open_pi_board(params, "my_board.toml")   # its keys replace the shipped file's

The board file has a schema, like the parameters: every key has a type, a unit, a range and a
description (the dataclasses below). The shipped flightctl/boards/pi.toml holds the wiring of the
reference quadcopter; a board file given with --board-file replaces the keys it names; a key that
neither gives takes the schema's default (the ESC timings are the ESC driver's own, drivers/esc.py;
the battery threshold is every board's, flightctl/boards/__init__.py). Every problem is one line naming the key.

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

from flightctl.boards import MIN_BATTERY_V, Board, BoardOptions, BoardUnavailable, missing_module
from flightctl.clock import WallClock
from flightctl.drivers import esc
from flightctl.drivers.esc import EscError, PigpioEsc
from flightctl.drivers.hcsr04 import HcSr04
from flightctl.drivers.ina219 import Ina219, PowerMonitorError
from flightctl.drivers.mpu9250 import ImuError, Mpu9250
from flightctl.errors import InputError, number, read_toml
from flightctl.hal import Hal
from flightctl.params import Params

DEFAULT_BOARD_FILE = "pi.toml"
PI_CALIBRATE_S = 60.0          # s sitting still before arming: the paper's 60 s
RESERVED_PINS = {2: "I2C SDA", 3: "I2C SCL", 7: "SPI CE1", 8: "SPI CE0", 9: "SPI MISO", 10: "SPI MOSI",
                 11: "SPI SCLK", 14: "UART TX", 15: "UART RX"}


def _key(unit: str, lo, hi, doc: str, default=dataclasses.MISSING):
    """One schema entry (dataclass field metadata); no default: the shipped board file gives it."""
    return field(default=default, metadata=dict(unit=unit, lo=lo, hi=hi, doc=doc))


GPIO = ("BCM GPIO", 0, 31)


@dataclass(frozen=True)
class PigpioConfig:
    host: str = _key("", None, None, "pigpiod's address (it is bound to localhost only)")
    port: int = _key("TCP port", 1, 65535, "pigpiod's port")


@dataclass(frozen=True)
class EscConfig:
    pins: tuple[int, ...] = _key(*GPIO, "the four ESC signals, motor 1 (N), 2 (W), 3 (S), 4 (E)")
    stop_us: int = _key("us", 500, 1500, "stop pulse: zero thrust, keeps the ESCs armed", esc.STOP_US)
    max_us: int = _key("us", 1000, 2200, "longest pulse; on-times are clamped to [stop_us, max_us]", esc.MAX_US)
    deadman_ms: int = _key("ms", 20, 1000, "pigpiod stops the motors this long after the last command",
                           esc.DEADMAN_MS)
    tolerance_hz: float = _key("Hz", 0.05, 5.0, "arming is refused if the measured output is further from "
                               "esc_pwm_hz", esc.FREQUENCY_TOLERANCE_HZ)


@dataclass(frozen=True)
class ImuConfig:
    spi_bus: int = _key("", 0, 6, "SPI bus of the MPU-9250 (/dev/spidevBUS.DEVICE)")
    spi_device: int = _key("", 0, 2, "SPI chip select")
    spi_mode: int = _key("", 0, 3, "SPI mode (the MPU-9250 takes 0 or 3)")


@dataclass(frozen=True)
class SonarConfig:
    trigger_pin: int = _key(*GPIO, "HC-SR04 trigger")
    echo_pin: int = _key(*GPIO, "HC-SR04 echo (through a 5 V -> 3.3 V divider)")


@dataclass(frozen=True)
class PowerConfig:
    i2c_bus: int = _key("", 0, 22, "I2C bus of the INA219 (/dev/i2c-BUS)")
    address: int = _key("", 0x03, 0x77, "7-bit I2C address of the INA219")
    shunt_ohm: float = _key("ohm", 1e-4, 10.0, "the power module's shunt resistor")
    max_current_a: float = _key("A", 0.1, 400.0, "largest current measured: sets the INA219 gain and LSB")


@dataclass(frozen=True)
class ChecksConfig:
    min_battery_v: float = _key("V", 0.0, 60.0, "refuse to arm below this battery voltage", MIN_BATTERY_V)


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


def _value(where: str, f: dataclasses.Field, value):
    m, kind = f.metadata, f.type
    if kind == "str":
        if not isinstance(value, str) or not value:
            raise InputError(f"{where}: expected a string, got {repr(value)[:40]}")
        return value
    if kind == "tuple[int, ...]":
        if not isinstance(value, list) or not all(isinstance(v, int) and not isinstance(v, bool) for v in value):
            raise InputError(f"{where}: expected a list of integers, got {repr(value)[:40]}")
        items = value
    elif kind == "int":
        if isinstance(value, bool) or not isinstance(value, int):
            raise InputError(f"{where}: expected an integer, got {repr(value)[:40]}")
        items = [value]
    else:
        if number(value) is None:
            raise InputError(f"{where}: expected a number, got {str(value)[:40]}")
        items = [value]
    unit = f" {m['unit']}" if m["unit"] else ""
    for v in items:
        if not m["lo"] <= v <= m["hi"]:
            shown = f"{v:g}" if number(v) is not None else f"{str(v)[:37]}..."
            raise InputError(f"{where}: {shown}{unit} is out of range [{m['lo']:g}, {m['hi']:g}]")
    return tuple(value) if kind.startswith("tuple") else float(value) if kind == "float" else value


def _read(name: str, data: dict) -> dict[str, dict]:
    out: dict[str, dict] = {}
    for section, table in data.items():
        if section not in SECTIONS:
            raise InputError(f"{name}: unknown section [{section}] (known: {', '.join(SECTIONS)})")
        if not isinstance(table, dict):
            raise InputError(f"{name}: {section}: expected a table [{section}]")
        fields = {f.name: f for f in dataclasses.fields(SECTIONS[section])}
        for key, value in table.items():
            if key not in fields:
                raise InputError(f"{name}: {section}.{key}: unknown key (known: {', '.join(fields)})")
            out.setdefault(section, {})[key] = _value(f"{name}: {section}.{key}", fields[key], value)
    return out


def load_board(path: str | Path | None = None) -> BoardConfig:
    """Read and check a board file over the shipped flightctl/boards/pi.toml (None: the shipped one)."""
    text = resources.files("flightctl.boards").joinpath(DEFAULT_BOARD_FILE).read_text()
    values = _read(DEFAULT_BOARD_FILE, read_toml(DEFAULT_BOARD_FILE, text))
    name = DEFAULT_BOARD_FILE
    if path is not None:
        name = str(path)
        for section, table in _read(name, read_toml(name)).items():
            values.setdefault(section, {}).update(table)
    sections = {}
    for section, cls in SECTIONS.items():
        given = values.get(section, {})
        for f in dataclasses.fields(cls):
            if f.name not in given and f.default is dataclasses.MISSING:
                raise InputError(f"{name}: {section}.{f.name}: missing ({f.metadata['doc']})")
        sections[section] = cls(**given)
    config = BoardConfig(**sections, path=name)
    _check(config)
    return config


def _check(c: BoardConfig) -> None:
    """What the ranges of single keys cannot say."""
    where = c.path
    pins = list(c.esc.pins) + [c.sonar.trigger_pin, c.sonar.echo_pin]
    if len(c.esc.pins) != 4:
        raise InputError(f"{where}: esc.pins: four GPIOs needed (motor 1..4), got {list(c.esc.pins)}")
    for p in pins:
        if p in RESERVED_PINS:
            raise InputError(f"{where}: GPIO {p} is the {RESERVED_PINS[p]} pin")
    if len(set(pins)) != len(pins):
        raise InputError(f"{where}: a GPIO is used twice among esc.pins and the sonar pins: {pins}")
    if not c.esc.stop_us < c.esc.max_us:
        raise InputError(f"{where}: esc: need stop_us < max_us, got {c.esc.stop_us} and {c.esc.max_us}")


def connect_pigpio(config: BoardConfig):
    import pigpio

    pi = pigpio.pi(config.pigpio.host, config.pigpio.port, show_errors=False)
    if not pi.connected:
        raise BoardUnavailable(f"cannot reach pigpiod at {config.pigpio.host}:{config.pigpio.port} "
                               "(is pigpiod.service running?)")
    return pi


def _closer(closers: list):
    """Call the closers, last opened first, each once (safe to call twice); errors are ignored."""
    def close() -> None:
        while closers:
            try:
                closers.pop()()
            except Exception:
                pass
    return close


def open_pi_board(params: Params, config_path: str | Path | None = None, *, pi=None, spi=None, smbus=None,
                  config: BoardConfig | None = None) -> Board:
    config = config if config is not None else load_board(config_path)
    a = params.airframe
    closers: list = []
    close = _closer(closers)
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
        close()
        raise
    hal = Hal(imu=imu, motors=motors, rangefinder=sonar, power=power, clock=WallClock(a.dt))
    return Board(hal, "pi", config.checks.min_battery_v, PI_CALIBRATE_S, close,
                 meta={"board_file": config.path, "esc_pins": str(list(config.esc.pins)), **imu.filters()})


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
