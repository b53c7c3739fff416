"""INA219 battery voltage and current monitor over I2C (smbus2), behind the `PowerMonitor` protocol.

The INA219 sits on the high side with its shunt in the battery lead. It measures the shunt voltage
(10 uV LSB) and the bus voltage on IN- (4 mV LSB). The battery voltage is bus + shunt; the current is
the shunt voltage over the shunt resistance, computed here from the shunt register rather than read
from the CURRENT register, so that it does not depend on the calibration register surviving a
brown-out (a reset INA219 reads a current of 0 A, which would look like a healthy idle battery).
The calibration register is still written, so the chip's CURRENT and POWER registers are usable.

Registers are 16-bit, most significant byte first: they are read with `read_i2c_block_data(addr, reg,
2)` (wire order, no byte swap) and written with `write_i2c_block_data(addr, reg, [msb, lsb])`.

Failures: `start()` raises `PowerMonitorError` naming what it saw (no answer on the bus, all-0x00 or
all-0xFF words, a configuration that does not read back). In flight, `read()` never raises: a bus
error or a math-overflow flag repeats the last good reading for up to `HOLD_READS` reads and then
returns NaN (the log shows the gap; the loop's low-battery check cannot trip on a bus glitch).
All-0x00 words from both registers count as a failed read (no battery reads 0 V only on the bench).
"""
from __future__ import annotations

import math

from flightctl.drivers import ina219_regs as reg

HOLD_READS = 5


class PowerMonitorError(Exception):
    """The INA219 is absent, not answering, or not configurable."""


class Ina219:
    def __init__(self, bus, address: int = reg.DEFAULT_ADDRESS, shunt_ohm: float = 0.002,
                 max_current_a: float = 60.0, bus_name: str = "i2c"):
        if shunt_ohm <= 0.0 or max_current_a <= 0.0:
            raise ValueError("shunt_ohm and max_current_a must be positive")
        self.bus, self.address, self.bus_name = bus, address, bus_name
        self.shunt_ohm, self.max_current_a = shunt_ohm, max_current_a
        # the smallest PGA range that holds the largest shunt voltage
        v_max = max_current_a * shunt_ohm
        self.pga = next((i for i, fs in enumerate(reg.PG_FULL_SCALE_V) if v_max <= fs), 3)
        self.config = (reg.BRNG_32V | self.pga << reg.PG_SHIFT | reg.ADC_12BIT_8X << reg.BADC_SHIFT
                       | reg.ADC_12BIT_8X << reg.SADC_SHIFT | reg.MODE_SHUNT_BUS_CONTINUOUS)
        self.current_lsb = max_current_a / 32768.0
        cal = int(reg.CAL_NUMERATOR / (self.current_lsb * shunt_ohm))
        if cal > 0xFFFE:       # the shunt is so small that the LSB must grow to fit 16 bits
            cal = 0xFFFE
            self.current_lsb = reg.CAL_NUMERATOR / (cal * shunt_ohm)
        self.calibration = cal & 0xFFFE
        self.errors = 0        # failed reads so far
        self._bad = 0          # consecutive failed reads
        self._last = (math.nan, math.nan)

    def _where(self) -> str:
        return f"INA219 at 0x{self.address:02X} on {self.bus_name}"

    # --- register access -------------------------------------------------------------------
    def read_reg(self, register: int) -> int:
        msb, lsb = self.bus.read_i2c_block_data(self.address, register, 2)
        return (msb << 8) | lsb

    def write_reg(self, register: int, value: int) -> None:
        self.bus.write_i2c_block_data(self.address, register, [(value >> 8) & 0xFF, value & 0xFF])

    # --- lifecycle ---------------------------------------------------------------------------
    def start(self) -> None:
        try:
            self.write_reg(reg.CONFIG, reg.RST)
            after_reset = self.read_reg(reg.CONFIG)
            self.write_reg(reg.CONFIG, self.config)
            self.write_reg(reg.CALIBRATION, self.calibration)
            config, cal = self.read_reg(reg.CONFIG), self.read_reg(reg.CALIBRATION)
            bus = self.read_reg(reg.BUS_VOLTAGE)
        except OSError as e:
            raise PowerMonitorError(f"{self._where()}: no answer ({e}); check the wiring and the address") from None
        for name, value in (("CONFIG", config), ("BUS_VOLTAGE", bus)):
            if value in (0x0000, 0xFFFF) and not (name == "BUS_VOLTAGE" and value == 0):
                raise PowerMonitorError(f"{self._where()}: {name} reads 0x{value:04X} (a bus-error pattern); "
                                        "no INA219 answering")
        if after_reset != reg.CONFIG_RESET_VALUE:
            raise PowerMonitorError(f"{self._where()}: CONFIG reads 0x{after_reset:04X} after reset, expected "
                                    f"0x{reg.CONFIG_RESET_VALUE:04X}; wrong chip at this address?")
        if config != self.config or cal != self.calibration:
            raise PowerMonitorError(f"{self._where()}: CONFIG/CALIBRATION read back 0x{config:04X}/0x{cal:04X} "
                                    f"after writing 0x{self.config:04X}/0x{self.calibration:04X}")

    def read(self) -> tuple[float, float]:
        """Battery voltage in V and current in A (see the module notes for failures)."""
        try:
            bus = self.read_reg(reg.BUS_VOLTAGE)
            raw = self.read_reg(reg.SHUNT_VOLTAGE)
        except OSError:
            return self._failed()
        if bus & reg.BUS_OVF or (bus == 0 and raw == 0):   # math overflow (and 0xFFFF), or a dead bus
            return self._failed()
        shunt_v = (raw - 0x10000 if raw & 0x8000 else raw) * reg.SHUNT_LSB_V
        bus_v = (bus >> reg.BUS_SHIFT) * reg.BUS_LSB_V
        self._bad = 0
        self._last = (bus_v + shunt_v, shunt_v / self.shunt_ohm)
        return self._last

    def _failed(self) -> tuple[float, float]:
        self.errors += 1
        self._bad += 1
        return self._last if self._bad <= HOLD_READS else (math.nan, math.nan)

    def close(self) -> None:
        close = getattr(self.bus, "close", None)
        if close is not None:
            close()
