"""The INA219 driver against a fake SMBus (the smbus2.SMBus methods) with a register-level INA219."""
from __future__ import annotations

import math

import pytest

from fakes.smbus import FakeIna219, FakeSMBus
from flightctl.drivers import ina219_regs as reg
from flightctl.drivers.ina219 import HOLD_READS, Ina219, PowerMonitorError
from flightctl.hal import PowerMonitor


def started(**chip) -> tuple[Ina219, FakeIna219, FakeSMBus]:
    dev = FakeIna219(**chip)
    bus = FakeSMBus({0x40: dev})
    ina = Ina219(bus, 0x40, shunt_ohm=dev.shunt_ohm, max_current_a=60.0, bus_name="/dev/i2c-1")
    ina.start()
    return ina, dev, bus


def test_reads_battery_voltage_and_current_in_si():
    ina, dev, _ = started(battery_v=16.2, current_a=12.5)
    assert isinstance(ina, PowerMonitor)
    v, i = ina.read()
    assert v == pytest.approx(16.2, abs=0.004 + 1e-5)       # 4 mV bus LSB
    assert i == pytest.approx(12.5, abs=0.005)               # 10 uV / 2 mOhm shunt LSB
    dev.current_a = -1.0                                     # charging (negative shunt voltage)
    assert ina.read()[1] == pytest.approx(-1.0, abs=0.005)


def test_configuration_and_calibration_are_written_and_read_back():
    ina, dev, _ = started()
    assert dev.regs[reg.CONFIG] == ina.config
    # 32 V bus range; 60 A x 2 mOhm = 120 mV: the +-160 mV gain
    assert ina.config & reg.BRNG_32V and (ina.config >> reg.PG_SHIFT) & 3 == 2
    assert dev.regs[reg.CALIBRATION] == ina.calibration > 0
    assert ina.current_lsb == pytest.approx(60.0 / 32768)


def test_no_device_is_named():
    bus = FakeSMBus({})
    with pytest.raises(PowerMonitorError, match="0x40 on /dev/i2c-1: no answer"):
        Ina219(bus, 0x40, bus_name="/dev/i2c-1").start()


@pytest.mark.parametrize("fault, shown", [("ones", "0xFFFF"), ("zeros", "0x0000")])
def test_bus_error_words_at_start_are_refused(fault, shown):
    dev = FakeIna219()
    bus = FakeSMBus({0x40: dev})
    bus.fault = fault
    with pytest.raises(PowerMonitorError, match=shown):
        Ina219(bus, 0x40).start()


def test_a_chip_that_ignores_writes_is_refused():
    dev = FakeIna219()
    dev.ignore_writes = True
    with pytest.raises(PowerMonitorError, match="read back"):
        Ina219(FakeSMBus({0x40: dev}), 0x40).start()


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
    dev = FakeIna219()
    bus = FakeSMBus({0x40: dev})
    assert bus.read_word_data(0x40, reg.CONFIG) == 0x9F39     # SMBus is little-endian, the INA219 is not
    assert bus.read_i2c_block_data(0x40, reg.CONFIG, 2) == [0x39, 0x9F]
