"""A fake SMBus (the methods of `smbus2.SMBus` the drivers use) with an INA219 behind it.

The INA219 model: 16-bit registers, most significant byte first on the wire; `read_word_data`
returns the SMBus (little-endian) interpretation, i.e. the bytes swapped, as the real bus does.
Set `battery_v` and `current_a`; the shunt and bus registers follow. `fault` = "nack" (OSError 121
as from a missing device), "zeros" or "ones" (every byte 0x00 / 0xFF) makes the bus misbehave.
"""
from __future__ import annotations

import errno

from flightctl.drivers import ina219_regs as reg


class FakeIna219:
    def __init__(self, shunt_ohm: float = 0.002, battery_v: float = 16.0, current_a: float = 0.0):
        self.shunt_ohm = shunt_ohm
        self.battery_v, self.current_a = battery_v, current_a
        self.regs = {reg.CONFIG: reg.CONFIG_RESET_VALUE, reg.CALIBRATION: 0}
        self.ignore_writes = False

    def write(self, register: int, value: int) -> None:
        if self.ignore_writes:
            return
        if register == reg.CONFIG and value & reg.RST:
            self.regs = {reg.CONFIG: reg.CONFIG_RESET_VALUE, reg.CALIBRATION: 0}
            return
        if register == reg.CALIBRATION:
            value &= 0xFFFE
        if register in (reg.CONFIG, reg.CALIBRATION):
            self.regs[register] = value

    def read(self, register: int) -> int:
        shunt_v = self.current_a * self.shunt_ohm
        if register == reg.SHUNT_VOLTAGE:
            return int(round(shunt_v / reg.SHUNT_LSB_V)) & 0xFFFF
        if register == reg.BUS_VOLTAGE:
            bus = int(round((self.battery_v - shunt_v) / reg.BUS_LSB_V))
            return (bus << reg.BUS_SHIFT | reg.BUS_CNVR) & 0xFFFF
        if register == reg.CURRENT:
            cal = self.regs[reg.CALIBRATION]
            return int(round(shunt_v / reg.SHUNT_LSB_V * cal / 4096)) & 0xFFFF
        return self.regs.get(register, 0)


class FakeSMBus:
    def __init__(self, devices: dict[int, FakeIna219] | None = None):
        self.devices = devices if devices is not None else {reg.DEFAULT_ADDRESS: FakeIna219()}
        self.fault: str | None = None
        self.transfers = 0
        self.closed = False

    def _device(self, addr: int) -> FakeIna219:
        self.transfers += 1
        if self.fault == "nack" or addr not in self.devices:
            raise OSError(errno.EREMOTEIO, "Remote I/O error")
        return self.devices[addr]

    def _bytes(self, word: int) -> list[int]:
        if self.fault == "zeros":
            return [0x00, 0x00]
        if self.fault == "ones":
            return [0xFF, 0xFF]
        return [word >> 8 & 0xFF, word & 0xFF]

    def read_i2c_block_data(self, i2c_addr: int, register: int, length: int, force=None) -> list[int]:
        dev = self._device(i2c_addr)
        out = []
        while len(out) < length:
            out += self._bytes(dev.read(register))
            register += 1
        return out[:length]

    def write_i2c_block_data(self, i2c_addr: int, register: int, data: list[int], force=None) -> None:
        dev = self._device(i2c_addr)
        if len(data) != 2:
            raise OSError(errno.EINVAL, "INA219 registers take two bytes")
        dev.write(register, data[0] << 8 | data[1])

    def read_word_data(self, i2c_addr: int, register: int, force=None) -> int:
        msb, lsb = self._bytes(self._device(i2c_addr).read(register))
        return lsb << 8 | msb

    def write_word_data(self, i2c_addr: int, register: int, value: int, force=None) -> None:
        self._device(i2c_addr).write(register, (value & 0xFF) << 8 | value >> 8)

    def close(self) -> None:
        self.closed = True
