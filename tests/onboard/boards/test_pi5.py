"""The pi5 board wired from its TOML file against its fakes (the sysfs PWM tree with the kernel's rules, the
GPIO chip behind gpiod's API, the register-level MPU-9250 and INA219), the board's detection from the
device tree's model string, and `flightctl run --board pi5 --stop-motors` (the unit's ExecStopPost)."""
from __future__ import annotations

import dataclasses
import logging

import pytest

from helpers.fakes.gpiochip import FakeGpioDevice
from helpers.fakes.sysfs_pwm import RP1_PWM0, FakePwmSysfs
from flightctl.boards import MIN_BATTERY_V, BoardOptions, BoardUnavailable, open_board, stop_motors
from flightctl.boards import detect
from flightctl.boards.pi5 import SECTIONS, load_board
from flightctl.clock import WallClock
from flightctl.drivers import pulses
from flightctl.drivers.hcsr04 import HcSr04
from flightctl.drivers.ina219 import Ina219
from flightctl.drivers.mpu9250 import Mpu9250
from flightctl.drivers.pwm_sysfs import SysfsPwmEsc
from flightctl.errors import InputError
from flightctl.hal import ImuSample
from flightctl.params import load
from flightctl.service.run import main
from flightctl.sim.world.devices import SensorNoise, World
from flightctl.sim.world.imu import SimMpu9250
from flightctl.sim.world.power import SimIna219, SimSMBus
from helpers.without import run_without

STOP = {0: 1000.0, 1: 1000.0, 2: 1000.0, 3: 1000.0}


def test_the_shipped_board_file_is_the_pi5_wiring():
    c = load_board()
    assert (c.pwm.chip, c.pwm.channels, c.pwm.pins) == (RP1_PWM0, (0, 1, 2, 3), (12, 13, 18, 19))
    assert c.gpio.chip == "pinctrl-rp1"
    assert (c.sonar.trigger_pin, c.sonar.echo_pin) == (23, 24)
    assert (c.imu.spi_bus, c.imu.spi_device, c.power.i2c_bus, c.power.address) == (0, 0, 1, 0x40)
    assert (c.esc.stop_us, c.esc.max_us, c.esc.deadman_ms) == (pulses.STOP_US, pulses.MAX_US, pulses.DEADMAN_MS)
    assert c.checks.min_battery_v == MIN_BATTERY_V


def test_every_pi5_board_file_key_has_a_unit_a_range_and_a_description():
    for section, cls in SECTIONS.items():
        for f in dataclasses.fields(cls):
            assert f.metadata["doc"], f"{section}.{f.name}"
            if f.type != "str":
                assert f.metadata["lo"] < f.metadata["hi"], f"{section}.{f.name}"


@pytest.mark.parametrize("text, message", [
    ("[pwm]\npins = [12, 13, 18, 17]\n", "GPIO 17 has no channel of the RP1's PWM0"),
    ("[pwm]\npins = [13, 12, 18, 19]\n", "GPIO 13 is the RP1's PWM0 channel 1, not channel 0"),
    ("[pwm]\nchannels = [0, 1, 2, 2]\n", "four different channels"),
    ("[pwm]\npins = [12, 13, 18]\nchannels = [0, 1, 2]\n", "four GPIOs"),
    ("[sonar]\ntrigger_pin = 12\n", "used twice"),
    ("[pigpio]\nport = 8888\n", r"unknown section \[pigpio\]"),
    ("[esc]\ntolerance_hz = 0.5\n", "esc.tolerance_hz: unknown key"),
    ("[gpio]\nchip = 4\n", "gpio.chip: expected a string"),
    ("[esc]\ndeadman_ms = 5\n", r"esc.deadman_ms: 5 ms is out of range \[20, 1000\]"),
])
def test_bad_pi5_board_files_are_refused_naming_the_key(tmp_path, text, message):
    path = tmp_path / "board.toml"
    path.write_text(text)
    with pytest.raises(InputError, match=message):
        load_board(path)


def test_another_pwm_chip_takes_any_pins(tmp_path):
    path = tmp_path / "board.toml"
    path.write_text('[pwm]\nchip = "pwmchip3"\nchannels = [4, 5, 6, 7]\npins = [5, 6, 16, 26]\n')
    assert load_board(path).pwm.channels == (4, 5, 6, 7)


@pytest.fixture
def fakes(tmp_path):
    params = load(None)
    world = World(params.airframe, noise=SensorNoise.off())
    world.battery.voltage, world.battery.current = 16.1, 0.4
    pwm, gpio = FakePwmSysfs(tmp_path), FakeGpioDevice()
    gpio.attach_sonar(23, 24, 0.8)
    devices = dict(pwm_root=str(pwm.root), pwm_fs=pwm, gpio_chip=gpio.chip(), spi=SimMpu9250(world),
                   smbus=SimSMBus(SimIna219(world)))
    yield params, pwm, gpio, devices
    gpio.close()


def test_the_registry_opens_the_pi5_board_with_every_driver(fakes):
    params, pwm, gpio, devices = fakes
    board = open_board("pi5", params, BoardOptions(devices=devices))
    hal = board.hal
    assert board.name == "pi5" and board.world is None and board.calibrate_s == 60.0
    assert isinstance(hal.motors, SysfsPwmEsc) and isinstance(hal.imu, Mpu9250)
    assert isinstance(hal.rangefinder, HcSr04) and isinstance(hal.power, Ina219) and isinstance(hal.clock, WallClock)
    assert board.meta["esc_pins"] == "[12, 13, 18, 19]"
    assert pwm.on_times_us() == STOP                                # disarmed: the stop pulse
    assert hal.imu.read(ImuSample())
    assert hal.power.read()[0] == pytest.approx(16.1, abs=0.01)
    hal.rangefinder.trigger()
    for _ in range(200):
        r = hal.rangefinder.poll()
        if r is not None:
            break
        hal.clock.wait_next()
    assert r == pytest.approx(0.8, abs=1e-3)
    assert gpio.chip().get_line_info(24).consumer == "flightctl"
    board.close()
    board.close()
    assert pwm.exported() == [] and not gpio.chip().get_line_info(24).used


def test_a_wrong_imu_releases_what_was_opened(fakes):
    params, pwm, gpio, devices = fakes
    devices["spi"] = SimMpu9250(World(params.airframe, noise=SensorNoise.off()), who_am_i=0x70)
    with pytest.raises(BoardUnavailable, match="WHO_AM_I returned 0x70"):
        open_board("pi5", params, BoardOptions(devices=devices))
    assert pwm.exported() == []


def test_a_held_sonar_line_is_board_unavailable_naming_the_holder(fakes):
    params, pwm, gpio, devices = fakes
    gpio.hold(24, "dht11")
    with pytest.raises(BoardUnavailable, match="GPIO 24 is held by 'dht11'"):
        open_board("pi5", params, BoardOptions(devices=devices))
    assert pwm.exported() == []


def test_a_held_pwm_channel_is_board_unavailable_and_run_exits_3_with_one_line(fakes, tmp_path, caplog):
    params, pwm, gpio, devices = fakes
    pwm.write(pwm.dirs[RP1_PWM0] / "export", "0")
    with pytest.raises(BoardUnavailable, match=r"motor 1 \(GPIO 12, pwmchip2 channel 0\) is already exported"):
        open_board("pi5", params, BoardOptions(devices=devices))
    with caplog.at_level(logging.ERROR, logger="flightctl.run"):
        rc = main(["--board", "pi5", "--plan", "hover", "--log", str(tmp_path)], devices=devices)
    assert rc == 3
    errors = [r.getMessage() for r in caplog.records if r.levelno >= logging.ERROR]
    assert len(errors) == 1 and errors[0].startswith("not flying: motor 1 (GPIO 12, pwmchip2 channel 0)")
    assert pwm.exported() == [0]                                  # not ours: left alone


def test_a_write_the_kernel_refuses_at_start_up_is_exit_3_with_one_line_naming_the_file(fakes, tmp_path, caplog):
    """Issue 36: a refused write escaped as a traceback (exit 1, restarted three times)."""
    params, pwm, gpio, devices = fakes
    pwm.clock_off = True                                          # rp1_pwm_apply(): no clock rate, EINVAL
    with caplog.at_level(logging.ERROR, logger="flightctl.run"):
        rc = main(["--board", "pi5", "--plan", "hover", "--log", str(tmp_path)], devices=devices)
    assert rc == 3
    errors = [r.getMessage() for r in caplog.records if r.levelno >= logging.ERROR]
    assert len(errors) == 1 and "\n" not in errors[0] and "Traceback" not in caplog.text
    assert errors[0].startswith(f"not flying: {pwm.root / 'pwmchip2' / 'pwm0' / 'period'}: writing 2227171 failed")
    assert pwm.exported() == []


def test_stop_motors_releases_the_channels_a_dead_controller_left(fakes):
    params, pwm, gpio, devices = fakes
    board = open_board("pi5", params, BoardOptions(devices=devices))
    board.hal.motors.arm()
    board.hal.motors.write([34000] * 4)
    board.hal.motors._exported.clear()           # the process dies here: its channels stay exported, motors on
    assert pwm.exported() == [0, 1, 2, 3] and pwm.on_times_us()[0] > 1800
    assert main(["--board", "pi5", "--stop-motors"], devices=devices) == 0
    assert pwm.exported() == []
    assert any(p.endswith("pwm0/duty_cycle") and v == "1000000" for p, v, _ in pwm.stores[-12:])
    assert "nothing to stop" in stop_motors("pi5", params, BoardOptions(devices=devices))
    board.close()


def test_stop_motors_without_the_pwm_chip_fails_loudly(tmp_path, caplog):
    with caplog.at_level(logging.ERROR, logger="flightctl.run"):
        assert main(["--board", "pi5", "--stop-motors"], devices=dict(pwm_root=str(tmp_path / "none"))) == 1
    assert "stop-motors: no PWM chips" in caplog.text


# --- which board: the device tree's model (tests/onboard/boards/test_detect_sandbox.py: inside the unit's sandbox) -----
@pytest.fixture
def model(tmp_path, monkeypatch):
    path = tmp_path / "sys" / "firmware" / "devicetree" / "base" / "model"
    path.parent.mkdir(parents=True)
    monkeypatch.setattr(detect, "MODEL_PATHS", (str(path), str(tmp_path / "proc" / "device-tree" / "model")))
    return path


@pytest.mark.parametrize("name, board", [("Raspberry Pi 5 Model B Rev 1.0", "pi5"),
                                         ("Raspberry Pi Compute Module 5 Rev 1.0", "pi5"),
                                         ("Raspberry Pi 500 Rev 1.0", "pi5"),
                                         ("Raspberry Pi 4 Model B Rev 1.5", "pi"),
                                         ("Raspberry Pi 3 Model B Plus Rev 1.3", "pi"), (None, "pi")])
def test_auto_is_pi5_on_a_raspberry_pi_5_and_pi_elsewhere(model, name, board):
    if name is not None:
        model.write_bytes(name.encode() + b"\0")            # the device tree's string ends in NUL
    assert detect.detected() == board


def test_the_pi_board_refuses_a_raspberry_pi_5_saying_to_use_pi5(model, tmp_path, caplog):
    model.write_bytes(b"Raspberry Pi 5 Model B Rev 1.0\0")
    with pytest.raises(BoardUnavailable, match=r"this is a Raspberry Pi 5 Model B Rev 1.0: pigpio does not run on "
                                               r"it .* use --board pi5"):
        open_board("pi", load(None))
    with caplog.at_level(logging.ERROR, logger="flightctl.run"):
        assert main(["--board", "pi", "--plan", "hover", "--log", str(tmp_path)]) == 3
        assert main(["--board", "pi", "--stop-motors"]) == 1
    assert caplog.text.count("use --board pi5") == 2


def test_auto_opens_the_pi5_board_on_a_raspberry_pi_5(model, fakes):
    model.write_bytes(b"Raspberry Pi 5 Model B Rev 1.0\0")
    params, pwm, gpio, devices = fakes
    board = open_board("auto", params, BoardOptions(devices=devices))
    assert board.name == "pi5" and pwm.exported() == [0, 1, 2, 3]
    board.close()


def test_without_gpiod_the_pi5_board_says_which_extra_to_install(tmp_path):
    r = run_without(("gpiod", "spidev"), ["run", "--board", "pi5", "--plan", "hover", "--log", "logs"], tmp_path)
    assert r.returncode == 3
    lines = [line for line in r.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and "pip install '.[pi5]'" in lines[0], r.stderr


# --- the GPIO chip by its label (the real gpiod's device check; the fake chip where gpiod.Chip opens) ---
class Chips:
    """/dev/gpiochipN as a kernel numbers them: each path a FakeGpioDevice of that label, the files made so
    the lookup's glob finds them; `denied`: how many more opens get EACCES (udev not yet run)."""

    def __init__(self, dev, labels: dict[str, str], denied: int = 0):
        self.devices = {}
        for name, label in labels.items():
            (dev / name).write_text("")
            self.devices[str(dev / name)] = FakeGpioDevice(name=name, label=label)
        self.denied, self.opened, self.closed = denied, [], []

    def open(self, path: str):
        if self.denied:
            self.denied -= 1
            raise PermissionError(13, "Permission denied", path)
        chip = self.devices[path].chip(path)
        self.opened.append(path)
        close = chip.close
        chip.close = lambda: (self.closed.append(path), close())
        return chip

    def shut(self) -> None:
        for d in self.devices.values():
            d.close()


EARLY_66 = {"gpiochip0": "gpio-brcmstb@107d508500", "gpiochip1": "gpio-brcmstb@107d508520",
            "gpiochip2": "gpio-brcmstb@107d517c00", "gpiochip3": "gpio-brcmstb@107d517c20", "gpiochip4": "pinctrl-rp1"}
LATER = {"gpiochip0": "pinctrl-rp1", "gpiochip10": "gpio-brcmstb@107d508500", "gpiochip11": "gpio-brcmstb@107d508520"}


@pytest.mark.parametrize("labels", [EARLY_66, LATER], ids=["6.6 early: gpiochip4", "later: gpiochip0"])
def test_the_gpio_chip_is_found_by_its_label_whatever_its_number(tmp_path, labels):
    from flightctl.boards.pi5 import open_gpio_chip

    chips = Chips(tmp_path, labels)
    try:
        chip = open_gpio_chip("pinctrl-rp1", pattern=str(tmp_path / "gpiochip*"), open_chip=chips.open, wait_s=0)
        want = next(n for n, label in labels.items() if label == "pinctrl-rp1")
        assert chip.path == str(tmp_path / want) and chip.get_info().num_lines == 54
        assert sorted(chips.closed) == sorted(p for p in chips.opened if p != chip.path)   # the others closed
        with pytest.raises(BoardUnavailable, match=r"no GPIO chip 'pinctrl-rp2' \(there: .*gpiochip0 \("):
            open_gpio_chip("pinctrl-rp2", pattern=str(tmp_path / "gpiochip*"), open_chip=chips.open, wait_s=0)
        by_path = open_gpio_chip(str(tmp_path / "gpiochip0"), open_chip=chips.open, wait_s=0)
        assert by_path.get_info().label == labels["gpiochip0"]
    finally:
        chips.shut()


def test_at_boot_the_gpio_chip_is_waited_for_until_udev_gives_it_to_group_gpio(tmp_path):
    from flightctl.boards.pi5 import GPIO_WAIT_S, open_gpio_chip

    t = [0.0]
    sleep = lambda s: t.__setitem__(0, t[0] + s)             # noqa: E731
    chips = Chips(tmp_path, {"gpiochip0": "pinctrl-rp1"}, denied=3)
    try:
        chip = open_gpio_chip("pinctrl-rp1", pattern=str(tmp_path / "gpiochip*"), open_chip=chips.open,
                              clock=lambda: t[0], sleep=sleep)
        assert chip.get_info().label == "pinctrl-rp1" and 0.25 < t[0] < 0.35
        chips.denied = 10 ** 6                                 # no udev rule at all
        with pytest.raises(BoardUnavailable, match=r"gpiochip0 \(permission denied\); is the user in group gpio"):
            open_gpio_chip("pinctrl-rp1", pattern=str(tmp_path / "gpiochip*"), open_chip=chips.open,
                           clock=lambda: t[0], sleep=sleep)
        assert t[0] >= GPIO_WAIT_S
    finally:
        chips.shut()


def test_files_that_are_not_gpio_devices_are_passed_over_by_gpiod(tmp_path):
    """The real binding's device check: a regular file and /dev/null named gpiochipN are no chips."""
    from flightctl.boards.pi5 import open_gpio_chip

    (tmp_path / "gpiochip0").write_text("")
    (tmp_path / "gpiochip1").symlink_to("/dev/null")
    with pytest.raises(BoardUnavailable, match=r"^no GPIO chip 'pinctrl-rp1' \(there: none\)$"):
        open_gpio_chip("pinctrl-rp1", pattern=str(tmp_path / "gpiochip*"), wait_s=0)
