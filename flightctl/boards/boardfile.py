"""What the two Raspberry Pi boards share (`pi`: pigpio on a Pi 3/4, flightctl/boards/pi.py; `pi5`: the
kernel's PWM and GPIO character device on a Pi 5, flightctl/boards/pi5.py): the board file's schema
machinery, the sections both files have (IMU, sonar, power monitor, pre-arm checks), and the SPI and I2C
devices they open the same way. Nothing here imports a Pi library at module level.

A board file is TOML. Every key has a type, a unit, a range and a description (dataclass field metadata,
`key()` below); the board's shipped file gives the wiring, a file given with --board-file replaces the
keys it names, a key neither gives takes the schema's default. Every problem is one line naming the key.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from importlib import resources

from flightctl.boards import MIN_BATTERY_V, MIN_BATTERY_V_RANGE, BoardUnavailable
from flightctl.drivers import pulses
from flightctl.drivers.hcsr04 import HcSr04
from flightctl.drivers.ina219 import Ina219
from flightctl.drivers.mpu9250 import Mpu9250
from flightctl.errors import InputError, number
from flightctl.files import read_toml
from flightctl.schema import check_range, entry

RESERVED_PINS = {2: "I2C SDA", 3: "I2C SCL", 7: "SPI CE1", 8: "SPI CE0", 9: "SPI MISO", 10: "SPI MOSI",
                 11: "SPI SCLK", 14: "UART TX", 15: "UART RX"}
GPIO = ("BCM GPIO", 0, 31)
CALIBRATE_S = 60.0          # s sitting still before arming on the vehicle: the paper's 60 s
# the [esc] pulse keys of both boards (their defaults: drivers/pulses.py); `check_pulses` below
STOP_US = ("us", 500, 1500, "stop pulse: zero thrust, keeps the ESCs armed", pulses.STOP_US)
MAX_US = ("us", 1000, 2200, "longest pulse; on-times are clamped to [stop_us, max_us]", pulses.MAX_US)


def key(unit: str, lo, hi, doc: str, default=dataclasses.MISSING):
    """One schema entry (flightctl/schema.py); no default: the shipped board file gives it."""
    return entry(default, unit, lo, hi, doc)


@dataclass(frozen=True)
class ImuConfig:
    spi_bus: int = key("", 0, 6, "SPI bus of the MPU-9250 (/dev/spidevBUS.DEVICE)")
    spi_device: int = key("", 0, 2, "SPI chip select")
    spi_mode: int = key("", 0, 3, "SPI mode (the MPU-9250 takes 0 or 3)")


@dataclass(frozen=True)
class SonarConfig:
    trigger_pin: int = key(*GPIO, "HC-SR04 trigger")
    echo_pin: int = key(*GPIO, "HC-SR04 echo (through a 5 V -> 3.3 V divider)")


@dataclass(frozen=True)
class PowerConfig:
    i2c_bus: int = key("", 0, 22, "I2C bus of the INA219 (/dev/i2c-BUS)")
    address: int = key("", 0x03, 0x77, "7-bit I2C address of the INA219")
    shunt_ohm: float = key("ohm", 1e-4, 10.0, "the power module's shunt resistor")
    max_current_a: float = key("A", 0.1, 400.0, "largest current measured: sets the INA219 gain and LSB")


@dataclass(frozen=True)
class ChecksConfig:
    min_battery_v: float = key("V", *MIN_BATTERY_V_RANGE, "refuse to arm below this battery voltage", MIN_BATTERY_V)


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
    for v in items:
        check_range(where, v, m)
    return tuple(value) if kind.startswith("tuple") else float(value) if kind == "float" else value


def _read(name: str, data: dict, sections: dict) -> dict[str, dict]:
    out: dict[str, dict] = {}
    for section, table in data.items():
        if section not in sections:
            raise InputError(f"{name}: unknown section [{section}] (known: {', '.join(sections)})")
        if not isinstance(table, dict):
            raise InputError(f"{name}: {section}: expected a table [{section}]")
        fields = {f.name: f for f in dataclasses.fields(sections[section])}
        for k, value in table.items():
            if k not in fields:
                raise InputError(f"{name}: {section}.{k}: unknown key (known: {', '.join(fields)})")
            out.setdefault(section, {})[k] = _value(f"{name}: {section}.{k}", fields[k], value)
    return out


def load_sections(shipped: str, sections: dict, path=None) -> tuple[dict, str]:
    """The sections of a board file over the board's shipped file `shipped` (in flightctl/boards):
    ({section: its dataclass}, the name of the file read)."""
    text = resources.files("flightctl.boards").joinpath(shipped).read_text()
    values = _read(shipped, read_toml(shipped, text), sections)
    name = shipped
    if path is not None:
        name = str(path)
        for section, table in _read(name, read_toml(name), sections).items():
            values.setdefault(section, {}).update(table)
    out = {}
    for section, cls in sections.items():
        given = values.get(section, {})
        for f in dataclasses.fields(cls):
            if f.name not in given and f.default is dataclasses.MISSING:
                raise InputError(f"{name}: {section}.{f.name}: missing ({f.metadata['doc']})")
        out[section] = cls(**given)
    return out, name


def check_pins(where: str, esc_pins, sonar: SonarConfig, what: str = "esc.pins") -> None:
    """Four ESC pins, none of them a bus pin, no pin used twice among them and the sonar's."""
    pins = list(esc_pins) + [sonar.trigger_pin, sonar.echo_pin]
    if len(esc_pins) != 4:
        raise InputError(f"{where}: {what}: four GPIOs needed (motor 1..4), got {list(esc_pins)}")
    for p in pins:
        if p in RESERVED_PINS:
            raise InputError(f"{where}: GPIO {p} is the {RESERVED_PINS[p]} pin")
    if len(set(pins)) != len(pins):
        raise InputError(f"{where}: a GPIO is used twice among {what} and the sonar pins: {pins}")


def check_pulses(where: str, esc) -> None:
    """The [esc] section's stop pulse shorter than its longest pulse."""
    if not esc.stop_us < esc.max_us:
        raise InputError(f"{where}: esc: need stop_us < max_us, got {esc.stop_us} and {esc.max_us}")


def closer(closers: list):
    """Call the closers, last opened first, each once (safe to call twice); errors are ignored."""
    def close() -> None:
        while closers:
            try:
                closers.pop()()
            except Exception:
                pass
    return close


def open_spi(c: ImuConfig):
    import spidev

    spi = spidev.SpiDev()
    try:
        spi.open(c.spi_bus, c.spi_device)
    except OSError as e:
        raise BoardUnavailable(f"cannot open /dev/spidev{c.spi_bus}.{c.spi_device} ({e.strerror}); "
                               "is SPI enabled (raspi-config nonint do_spi 0) and the user in group spi?") from None
    spi.mode = c.spi_mode
    return spi


def open_smbus(bus: int):
    import smbus2

    try:
        return smbus2.SMBus(bus)
    except OSError as e:
        raise BoardUnavailable(f"cannot open /dev/i2c-{bus} ({e.strerror}); "
                               "is I2C enabled (raspi-config nonint do_i2c 0) and the user in group i2c?") from None


def start_sensors(config, gpio, spi, smbus, closers: list) -> tuple[Mpu9250, HcSr04, Ina219]:
    """The IMU on `spi` (opened from config.imu if None), the sonar on `gpio` (pigpio's calls:
    `pigpio.pi`, or the GPIO character device's lines) and the power monitor on `smbus` (opened from
    config.power if None), each started; what is opened is added to `closers`."""
    if spi is None:
        spi = open_spi(config.imu)
        closers.append(spi.close)
    imu = Mpu9250(spi)
    imu.start()
    sonar = HcSr04(gpio, config.sonar.trigger_pin, config.sonar.echo_pin)
    sonar.start()
    closers.append(sonar.stop)
    if smbus is None:
        smbus = open_smbus(config.power.i2c_bus)
        closers.append(smbus.close)
    power = Ina219(smbus, config.power.address, config.power.shunt_ohm, config.power.max_current_a,
                   bus_name=f"/dev/i2c-{config.power.i2c_bus}")
    power.start()
    return imu, sonar, power
