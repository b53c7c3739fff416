"""The pi board wired from its TOML file, against the fakes: a fake pigpiod (ESC output, sonar) through
the real pigpio client, the register-level MPU-9250 as the SPI device, the simulated INA219 on its I2C bus."""
from __future__ import annotations

import pytest

import dataclasses

from helpers.fakes.pigpiod import running
from flightctl.boards import MIN_BATTERY_V, BoardOptions, BoardUnavailable, open_board
from flightctl.clock import WallClock
from flightctl.drivers import esc
from flightctl.drivers.esc import PigpioEsc
from flightctl.drivers.hcsr04 import HcSr04
from flightctl.drivers.ina219 import Ina219
from flightctl.drivers.mpu9250 import ImuError, Mpu9250
from flightctl.errors import InputError
from flightctl.hal import ImuSample
from flightctl.params import load
from flightctl.boards.pi import SECTIONS, load_board, open_pi_board
from flightctl.sim.world.devices import SensorNoise, World
from flightctl.sim.world.imu import SimMpu9250
from flightctl.sim.world.power import SimIna219, SimSMBus


def test_the_shipped_board_file_is_the_quadcopters_wiring():
    config = load_board()
    assert config.esc.pins == (17, 27, 22, 25)
    assert (config.sonar.trigger_pin, config.sonar.echo_pin) == (23, 24)
    assert (config.imu.spi_bus, config.imu.spi_device) == (0, 0)
    assert (config.power.i2c_bus, config.power.address) == (1, 0x40)
    assert config.pigpio.host == "127.0.0.1"
    # what the shipped file leaves out: the ESC driver's own defaults and every board's battery threshold
    assert (config.esc.stop_us, config.esc.max_us, config.esc.deadman_ms, config.esc.tolerance_hz) == \
        (esc.STOP_US, esc.MAX_US, esc.DEADMAN_MS, esc.FREQUENCY_TOLERANCE_HZ)
    assert config.checks.min_battery_v == MIN_BATTERY_V


def test_every_board_file_key_has_a_unit_a_range_and_a_description():
    for section, cls in SECTIONS.items():
        for f in dataclasses.fields(cls):
            m = f.metadata
            assert m["doc"], f"{section}.{f.name}"
            if f.type != "str":
                assert m["lo"] < m["hi"], f"{section}.{f.name}"
                if f.default is not dataclasses.MISSING:
                    assert m["lo"] <= f.default <= m["hi"], f"{section}.{f.name}"


def test_a_board_file_replaces_only_the_keys_it_gives(tmp_path):
    path = tmp_path / "board.toml"
    path.write_text("[esc]\npins = [5, 6, 13, 19]\nstop_us = 1050\n[power]\nshunt_ohm = 0.0005\n")
    config, shipped = load_board(path), load_board()
    assert config.esc.pins == (5, 6, 13, 19) and config.esc.stop_us == 1050
    assert config.esc.max_us == shipped.esc.max_us
    assert config.power.shunt_ohm == 0.0005 and config.power.address == shipped.power.address
    assert (config.imu, config.sonar, config.pigpio) == (shipped.imu, shipped.sonar, shipped.pigpio)
    assert config.path == str(path)


@pytest.mark.parametrize("text, message", [
    ("[esc]\npinz = [1, 2, 3, 4]\n", "esc.pinz: unknown key"),
    ("[motors]\n", "unknown section [motors]"),
    ("[esc]\npins = [17, 27, 22]\n", "four GPIOs"),
    ("[esc]\npins = [17, 27, 22, 9]\n", "GPIO 9 is the SPI MISO pin"),
    ("[sonar]\ntrigger_pin = 17\n", "used twice"),
    ("[power]\naddress = \"0x40\"\n", "power.address: expected an integer"),
    ("[esc]\nstop_us = 1400\nmax_us = 1300\n", "stop_us < max_us"),
    ("[esc]\ndeadman_ms = 0\n", "esc.deadman_ms: 0 ms is out of range [20, 1000]"),
    ("[power]\naddress = 0x80\n", "power.address: 128 is out of range [3, 119]"),
    ("[esc]\npins = [17, 27, 22, 40]\n", "esc.pins: 40 BCM GPIO is out of range [0, 31]"),
    ("[power]\nshunt_ohm = true\n", "power.shunt_ohm: expected a number"),
    ("[checks]\nmin_battery_v = 99\n", "checks.min_battery_v: 99 V is out of range"),
    ("esc = 3\n", "esc: expected a table"),
])
def test_bad_board_files_are_refused_naming_the_key(tmp_path, text, message):
    path = tmp_path / "board.toml"
    path.write_text(text)
    with pytest.raises(InputError, match=message.replace("[", r"\[").replace("]", r"\]")):
        load_board(path)


def chips():
    params = load(None)
    world = World(params.airframe, noise=SensorNoise.off())
    world.battery.voltage, world.battery.current = 16.1, 0.4
    return params, SimMpu9250(world), SimSMBus(SimIna219(world))


def test_pi_board_wires_every_driver_from_the_board_file(tmp_path):
    params, spi, bus = chips()
    board_file = tmp_path / "board.toml"
    board_file.write_text("[esc]\npins = [5, 6, 13, 19]\n[sonar]\ntrigger_pin = 20\necho_pin = 21\n")
    with running() as (fake, pi):
        board = open_pi_board(params, board_file, pi=pi, spi=spi, smbus=bus)
        hal = board.hal
        assert isinstance(hal.motors, PigpioEsc) and hal.motors.pins == (5, 6, 13, 19)
        assert isinstance(hal.imu, Mpu9250) and isinstance(hal.rangefinder, HcSr04)
        assert isinstance(hal.power, Ina219) and isinstance(hal.clock, WallClock)
        assert hal.rangefinder.trigger_pin == 20
        assert hal.clock.period == pytest.approx(1 / 450)
        assert fake.live_wave().on_times() == {5: 1000, 6: 1000, 13: 1000, 19: 1000}   # disarmed, stop pulse
        assert hal.imu.read(ImuSample())
        assert hal.power.read()[0] == pytest.approx(16.1, abs=0.01)
        assert fake.watchdogs.get(21)            # the sonar's echo watchdog is set
        board.close()
        assert fake.live_wave().on_times()[5] == 1000


def test_the_registry_opens_the_pi_board_by_name():
    params, spi, bus = chips()
    with running() as (fake, pi):
        board = open_board("pi", params, BoardOptions(devices=dict(pi=pi, spi=spi, smbus=bus)))
        assert board.name == "pi" and isinstance(board.hal.motors, PigpioEsc) and board.world is None
        assert board.min_battery_v == MIN_BATTERY_V and board.calibrate_s == 60.0
        assert board.meta["esc_pins"] == "[17, 27, 22, 25]"
        board.close()
        board.close()                            # safe twice
        assert fake.live_wave().on_times() == {17: 1000, 27: 1000, 22: 1000, 25: 1000}


def test_a_wrong_chip_through_the_registry_is_board_unavailable():
    params, _, bus = chips()
    wrong = SimMpu9250(World(params.airframe, noise=SensorNoise.off()), who_am_i=0x70)
    with running() as (fake, pi):
        with pytest.raises(BoardUnavailable, match="WHO_AM_I returned 0x70"):
            open_board("pi", params, BoardOptions(devices=dict(pi=pi, spi=wrong, smbus=bus)))
        assert fake.live_wave().on_times() == {17: 1000, 27: 1000, 22: 1000, 25: 1000}


def test_a_wrong_imu_leaves_the_escs_at_the_stop_pulse(tmp_path):
    params, _, bus = chips()
    wrong = SimMpu9250(World(params.airframe, noise=SensorNoise.off()), who_am_i=0x70)
    with running() as (fake, pi):
        with pytest.raises(ImuError, match="0x70"):
            open_pi_board(params, None, pi=pi, spi=wrong, smbus=bus)
        assert fake.live_wave().on_times() == {17: 1000, 27: 1000, 22: 1000, 25: 1000}
        assert not fake.script_running()
