"""The pi board wired from its TOML file, against the fakes: a fake pigpiod (ESC output, sonar) through
the real pigpio client, the register-level MPU-9250 as the SPI device, a fake SMBus with an INA219."""
from __future__ import annotations

import pytest

from fakes.pigpiod import running
from fakes.smbus import FakeIna219, FakeSMBus
from flightctl.boards import make_hal
from flightctl.clock import WallClock
from flightctl.drivers.esc import PigpioEsc
from flightctl.drivers.hcsr04 import HcSr04
from flightctl.drivers.ina219 import Ina219
from flightctl.drivers.mpu9250 import ImuError, Mpu9250
from flightctl.errors import InputError
from flightctl.hal import ImuSample
from flightctl.params import load
from flightctl.pi import BoardConfig, load_board, open_pi_board
from flightctl.sim.devices import SensorNoise, SimMpu9250, World


def test_the_shipped_board_file_is_the_defaults():
    config = load_board()
    assert config.esc.pins == (17, 27, 22, 25)
    assert (config.sonar.trigger_pin, config.sonar.echo_pin) == (23, 24)
    assert (config.imu.spi_bus, config.imu.spi_device) == (0, 0)
    assert (config.power.i2c_bus, config.power.address) == (1, 0x40)
    assert config.pigpio.host == "127.0.0.1"
    defaults = BoardConfig()
    assert (config.esc, config.imu, config.sonar, config.power, config.checks) == \
        (defaults.esc, defaults.imu, defaults.sonar, defaults.power, defaults.checks)


@pytest.mark.parametrize("text, message", [
    ("[esc]\npinz = [1, 2, 3, 4]\n", "esc.pinz: unknown key"),
    ("[motors]\n", "unknown section [motors]"),
    ("[esc]\npins = [17, 27, 22]\n", "four GPIOs"),
    ("[esc]\npins = [17, 27, 22, 9]\n", "GPIO 9 is the SPI MISO pin"),
    ("[sonar]\ntrigger_pin = 17\n", "used twice"),
    ("[power]\naddress = \"0x40\"\n", "power.address: expected an integer"),
    ("[esc]\nstop_us = 2200\n", "stop_us < max_us"),
])
def test_bad_board_files_are_refused_naming_the_key(tmp_path, text, message):
    path = tmp_path / "board.toml"
    path.write_text(text)
    with pytest.raises(InputError, match=message.replace("[", r"\[").replace("]", r"\]")):
        load_board(path)


def chips():
    params = load(None)
    world = World(params.airframe, noise=SensorNoise.off())
    return params, SimMpu9250(world), FakeSMBus({0x40: FakeIna219(battery_v=16.1, current_a=0.4)})


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


def test_make_hal_pi_reaches_the_pi_board():
    params, spi, bus = chips()
    with running() as (fake, pi):
        hal = make_hal("pi", params, pi=pi, spi=spi, smbus=bus)
        assert isinstance(hal.motors, PigpioEsc)
        hal.motors.stop()
        hal.rangefinder.stop()


def test_a_wrong_imu_leaves_the_escs_at_the_stop_pulse(tmp_path):
    params, _, bus = chips()
    wrong = SimMpu9250(World(params.airframe, noise=SensorNoise.off()), who_am_i=0x70)
    with running() as (fake, pi):
        with pytest.raises(ImuError, match="0x70"):
            open_pi_board(params, None, pi=pi, spi=wrong, smbus=bus)
        assert fake.live_wave().on_times() == {17: 1000, 27: 1000, 22: 1000, 25: 1000}
        assert not fake.script_running()
