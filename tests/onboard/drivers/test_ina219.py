"""The INA219 driver against the simulated chip (flightctl.sim.world.power: the registers of TI SBOS448 behind
the smbus2.SMBus calls), with the battery's true voltage and current set by hand and the noise off.
Register values are worked out here from the datasheet's encodings."""
from __future__ import annotations

import math

import pytest

from flightctl.drivers import ina219_regs as reg
from flightctl.drivers.ina219 import HOLD_READS, Ina219, PowerMonitorError
from flightctl.hal import PowerMonitor
from flightctl.params import Airframe
from flightctl.sim.world.devices import SensorNoise, World
from flightctl.sim.world.power import SimIna219, SimSMBus

SHUNT = 0.002      # ohm
CAL = 11184        # trunc(0.04096 / ((60 A / 32768) * 2 mOhm)): the driver's calibration for 60 A


def chip(battery_v: float = 16.0, current_a: float = 0.0, **kw) -> SimIna219:
    world = World(Airframe(), noise=SensorNoise.off())
    world.battery.voltage, world.battery.current = battery_v, current_a
    return SimIna219(world, SHUNT, **kw)


def started(**battery) -> tuple[Ina219, SimIna219, SimSMBus]:
    dev = chip(**battery)
    bus = SimSMBus(dev)
    ina = Ina219(bus, 0x40, shunt_ohm=SHUNT, max_current_a=60.0, bus_name="/dev/i2c-1")
    ina.start()
    return ina, dev, bus


def battery(dev: SimIna219):
    return dev.world.battery


def test_reads_battery_voltage_and_current_in_si():
    ina, dev, _ = started(battery_v=16.2, current_a=12.5)
    assert isinstance(ina, PowerMonitor)
    v, i = ina.read()
    assert v == pytest.approx(16.2, abs=0.004 + 1e-5)       # 4 mV bus LSB
    assert i == pytest.approx(12.5, abs=0.005)               # 10 uV / 2 mOhm shunt LSB
    battery(dev).current = -1.0                              # charging (negative shunt voltage)
    assert ina.read()[1] == pytest.approx(-1.0, abs=0.005)


def test_registers_hold_the_datasheet_encodings():
    """16.2 V and 12.5 A: shunt 25 mV = 2500 LSB; bus on IN- 16.175 V = 4043.75 -> 4044 LSB in bits 15..3
    with CNVR; CURRENT = 2500 * 11184 / 4096 = 6826; POWER = 6826 * 4044 / 5000 = 5520."""
    ina, dev, bus = started(battery_v=16.2, current_a=12.5)
    assert ina.calibration == CAL
    assert bus.read_i2c_block_data(0x40, reg.SHUNT_VOLTAGE, 2) == [0x09, 0xC4]              # 2500
    assert bus.read_i2c_block_data(0x40, reg.BUS_VOLTAGE, 2) == [0x7E, 0x62]                # 4044 << 3 | CNVR
    assert bus.read_i2c_block_data(0x40, reg.CURRENT, 2) == [0x1A, 0xAA]                    # 6826
    assert bus.read_i2c_block_data(0x40, reg.POWER, 2) == [0x15, 0x90]                      # 5520
    assert bus.read_i2c_block_data(0x40, reg.BUS_VOLTAGE, 2)[1] & reg.BUS_CNVR            # a new conversion
    battery(dev).current = -1.0                             # -2 mV = -200 LSB, two's complement
    assert bus.read_i2c_block_data(0x40, reg.SHUNT_VOLTAGE, 2) == [0xFF, 0x38]
    assert bus.read_i2c_block_data(0x40, reg.CURRENT, 2) == list((-546 & 0xFFFF).to_bytes(2, "big"))


def test_reading_power_clears_the_conversion_ready_bit():
    dev = chip(battery_v=15.0, current_a=2.0)
    dev.write(reg.CONFIG, reg.CONFIG_RESET_VALUE & ~7 | 0b011)   # shunt and bus, triggered: one conversion
    assert dev.read(reg.BUS_VOLTAGE) & reg.BUS_CNVR
    dev.read(reg.POWER)
    assert not dev.read(reg.BUS_VOLTAGE) & reg.BUS_CNVR


def test_triggered_and_power_down_modes_hold_their_conversion():
    dev = chip(battery_v=15.0, current_a=2.0)
    dev.write(reg.CONFIG, reg.CONFIG_RESET_VALUE & ~7 | 0b011)
    held = dev.read(reg.BUS_VOLTAGE) >> reg.BUS_SHIFT, dev.read(reg.SHUNT_VOLTAGE)
    assert held == (round((15.0 - 0.004) / 0.004), 400)      # 14.996 V; 4 mV = 400 LSB
    battery(dev).voltage, battery(dev).current = 14.0, 5.0
    assert (dev.read(reg.BUS_VOLTAGE) >> reg.BUS_SHIFT, dev.read(reg.SHUNT_VOLTAGE)) == held
    dev.write(reg.CONFIG, reg.CONFIG_RESET_VALUE & ~7)       # power-down: still held
    assert (dev.read(reg.BUS_VOLTAGE) >> reg.BUS_SHIFT, dev.read(reg.SHUNT_VOLTAGE)) == held
    dev.write(reg.CONFIG, reg.CONFIG_RESET_VALUE)            # continuous again: the new values
    assert dev.read(reg.SHUNT_VOLTAGE) == 1000 and dev.read(reg.BUS_VOLTAGE) >> reg.BUS_SHIFT == 3498


def test_an_overcurrent_clips_at_the_pga_range_and_sets_ovf_so_the_driver_holds():
    """100 A x 2 mOhm = 200 mV, beyond the +-160 mV of the gain the driver picks for 60 A: the shunt
    register stops at 16000 LSB, and CURRENT = 16000 * 11184 / 4096 = 43687 overflows int16 (OVF)."""
    ina, dev, bus = started(battery_v=15.8, current_a=20.0)
    good = ina.read()
    battery(dev).current = 100.0
    assert dev.read(reg.SHUNT_VOLTAGE) == 16000
    assert dev.read(reg.BUS_VOLTAGE) & reg.BUS_OVF
    assert ina.read() == good and ina.errors == 1


def test_configuration_and_calibration_are_written_and_read_back():
    ina, dev, _ = started()
    assert dev.regs[reg.CONFIG] == ina.config
    # 32 V bus range; 60 A x 2 mOhm = 120 mV: the +-160 mV gain
    assert ina.config & reg.BRNG_32V and (ina.config >> reg.PG_SHIFT) & 3 == 2
    assert dev.regs[reg.CALIBRATION] == ina.calibration > 0
    assert ina.current_lsb == pytest.approx(60.0 / 32768)


def test_reset_restores_the_power_on_registers():
    ina, dev, _ = started(battery_v=16.0, current_a=3.0)
    ina.read()
    dev.write(reg.CALIBRATION, 0x1235)
    assert dev.read(reg.CALIBRATION) == 0x1234                  # bit 0 does not take a 1
    dev.write(reg.CONFIG, reg.RST)
    assert dev.read(reg.CONFIG) == 0x399F and dev.read(reg.CALIBRATION) == 0 and dev.read(reg.CURRENT) == 0


def test_no_device_is_named():
    with pytest.raises(PowerMonitorError, match="0x40 on /dev/i2c-1: no answer"):
        Ina219(SimSMBus(), 0x40, bus_name="/dev/i2c-1").start()


@pytest.mark.parametrize("fault, shown", [("ones", "0xFFFF"), ("zeros", "0x0000")])
def test_bus_error_words_at_start_are_refused(fault, shown):
    bus = SimSMBus(chip())
    bus.fault = fault
    with pytest.raises(PowerMonitorError, match=shown):
        Ina219(bus, 0x40).start()


def test_a_chip_that_ignores_writes_is_refused():
    dev = chip()
    dev.ignore_writes = True
    with pytest.raises(PowerMonitorError, match="read back"):
        Ina219(SimSMBus(dev), 0x40).start()


@pytest.mark.parametrize("fault", ["nack", "ones", "zeros"])
def test_a_failing_bus_in_flight_holds_the_last_reading_then_gives_nan(fault):
    ina, dev, bus = started(battery_v=15.5, current_a=8.0)
    good = ina.read()
    bus.fault = fault
    for _ in range(HOLD_READS):
        assert ina.read() == good
    v, i = ina.read()
    assert math.isnan(v) and math.isnan(i)
    assert ina.errors == HOLD_READS + 1
    bus.fault = None
    assert ina.read()[0] == pytest.approx(15.5, abs=0.005)


def test_word_reads_are_byte_swapped_like_smbus():
    bus = SimSMBus(chip())
    assert bus.read_word_data(0x40, reg.CONFIG) == 0x9F39     # SMBus is little-endian, the INA219 is not
    assert bus.read_i2c_block_data(0x40, reg.CONFIG, 2) == [0x39, 0x9F]
