"""The simulated battery and its power monitor, at the lowest boundary: the INA219's registers behind
the smbus2 calls its driver makes, so that `flightctl.drivers.ina219.Ina219` runs in every simulation
(the sim board wires it like the Pi board does)."""
from __future__ import annotations

import errno
from typing import TYPE_CHECKING

from flightctl.drivers import ina219_regs as ina

if TYPE_CHECKING:
    from flightctl.sim.world.devices import World


class SimBattery:
    """A 4S 4000 mAh LiPo: open-circuit voltage linear in charge between 14.0 and 16.6 V, 25 mOhm of
    internal resistance; the current is the rotors' mechanical power (torque x speed, eq. 27-28)
    over the voltage at 75 % efficiency. Plausible values, not measured. `voltage` (at the terminals)
    and `current` are true values; the power monitor measures them through `SimIna219`."""
    CAPACITY_C = 4.0 * 3600
    R_INT = 0.025
    EFFICIENCY = 0.75

    def __init__(self, world: World, soc: float):
        self.world, self.soc = world, soc
        self.current = 0.0
        self.voltage = self._ocv()

    @staticmethod
    def open_circuit(soc):
        """The open-circuit voltage at the charge `soc` (0-1; a float or an array), V."""
        return 14.0 + 2.6 * soc

    def _ocv(self) -> float:
        return self.open_circuit(self.soc)

    def advance(self, dt: float) -> None:
        rotors = self.world.plant.forces()
        tau, w = rotors.tau, rotors.w
        power = (tau[0] * w[0] + tau[1] * w[1] + tau[2] * w[2] + tau[3] * w[3]) / self.EFFICIENCY
        self.current = power / self.voltage
        self.soc -= self.current * dt / self.CAPACITY_C
        self.voltage = self._ocv() - self.R_INT * self.current


def power_of_commands(P, a):
    """The power (W) SimBattery draws for the commands P (4, n) held steady: the rotors' torque times speed
    (eq. 26-28 through the airframe `a`) over EFFICIENCY; the pack's current is this over its voltage."""
    from flightctl.physics import rotor_speed, rotor_torque, thrust_from_command
    f = thrust_from_command(P, a.h1, a.h2)
    return (rotor_torque(f, a.g1, a.g2) * rotor_speed(f, a.c1) * (f > 0)).sum(axis=0) / SimBattery.EFFICIENCY


class SimIna219:
    """The INA219 on the battery lead (TI SBOS448), answering register reads and writes from the
    battery's true voltage and current. The shunt (`shunt_ohm`) is on the high side: the chip measures
    the shunt voltage I R (signed, 10 uV LSB, clipped to the range of the PGA gain in CONFIG) and the
    bus voltage on IN-, V - I R (4 mV LSB in bits 15..3, clipped to the 16 or 32 V range; bit 1 CNVR,
    bit 0 OVF). CURRENT = shunt * CALIBRATION / 4096 and POWER = CURRENT * bus / 5000 (datasheet
    eq. 4 and 5), both 0 until CALIBRATION is written; OVF is set when they overflow 16 bits.

    Conversions: in a continuous mode (CONFIG bits 2..0) a read of SHUNT_VOLTAGE or BUS_VOLTAGE gets a
    fresh conversion (the 8.5 ms conversion cycle is short against the loop's 10 Hz reads); a triggered
    mode converts once when CONFIG is written; power-down and ADC-off hold the registers. A read of
    POWER clears CNVR. Measurement noise: `battery_sigma` volts on the bus voltage, and as many LSBs on
    the shunt voltage (one ADC behind a multiplexer): 0.01 V is 2.5 LSB, 25 uV, 12.5 mA on 2 mOhm.
    `ignore_writes` makes a chip that takes no write (a wrong device at the address)."""
    CAL_DIVISOR, POWER_DIVISOR = 4096, 5000

    def __init__(self, world: World, shunt_ohm: float = 0.002, address: int = ina.DEFAULT_ADDRESS):
        self.world = world
        self.shunt_ohm, self.address = shunt_ohm, address
        self.ignore_writes = False
        self._reset()

    def _reset(self) -> None:
        self.regs = {r: 0 for r in (ina.CONFIG, ina.SHUNT_VOLTAGE, ina.BUS_VOLTAGE, ina.POWER, ina.CURRENT,
                                    ina.CALIBRATION)}
        self.regs[ina.CONFIG] = ina.CONFIG_RESET_VALUE
        self._shunt = self._bus = 0   # the last conversions, signed shunt LSBs and bus LSBs

    def write(self, register: int, value: int) -> None:
        if self.ignore_writes or register not in (ina.CONFIG, ina.CALIBRATION):
            return
        if register == ina.CONFIG:
            if value & ina.RST:
                self._reset()
                return
            self.regs[ina.CONFIG] = value
            self.regs[ina.BUS_VOLTAGE] &= ~ina.BUS_CNVR & 0xFFFF
            mode = value & 7
            if mode & 1 and mode < 4:   # triggered: one conversion now
                self._convert_shunt()
            if mode & 2 and mode < 4:
                self._convert_bus()
            return
        self.regs[ina.CALIBRATION] = value & 0xFFFE   # bit 0 is not writable
        self._calculate()

    def read(self, register: int) -> int:
        mode = self.regs[ina.CONFIG] & 7
        if register == ina.SHUNT_VOLTAGE and mode in (5, 7):
            self._convert_shunt()
        elif register == ina.BUS_VOLTAGE and mode in (6, 7):
            self._convert_bus()
        value = self.regs.get(register, 0)
        if register == ina.POWER:
            self.regs[ina.BUS_VOLTAGE] &= ~ina.BUS_CNVR & 0xFFFF
        return value

    def _convert_shunt(self) -> None:
        w, s = self.world, self.world.noise.battery_sigma
        volts = w.battery.current * self.shunt_ohm + w.rng.gauss(0.0, s * ina.SHUNT_LSB_V / ina.BUS_LSB_V)
        full = round(ina.PG_FULL_SCALE_V[(self.regs[ina.CONFIG] >> ina.PG_SHIFT) & 3] / ina.SHUNT_LSB_V)
        self._shunt = max(-full, min(full, round(volts / ina.SHUNT_LSB_V)))
        self.regs[ina.SHUNT_VOLTAGE] = self._shunt & 0xFFFF
        self._calculate()

    def _convert_bus(self) -> None:
        w, s = self.world, self.world.noise.battery_sigma
        volts = w.battery.voltage - w.battery.current * self.shunt_ohm + w.rng.gauss(0.0, s)
        full = round((32.0 if self.regs[ina.CONFIG] & ina.BRNG_32V else 16.0) / ina.BUS_LSB_V)
        self._bus = max(0, min(full, round(volts / ina.BUS_LSB_V)))
        self.regs[ina.BUS_VOLTAGE] = self._bus << ina.BUS_SHIFT | ina.BUS_CNVR
        self._calculate()

    def _calculate(self) -> None:
        """CURRENT and POWER from the last conversions and CALIBRATION (datasheet eq. 4, 5), and OVF."""
        current = int(self._shunt * self.regs[ina.CALIBRATION] / self.CAL_DIVISOR)
        power = int(abs(current) * self._bus / self.POWER_DIVISOR)
        overflow = not -0x8000 <= current <= 0x7FFF or power > 0xFFFF
        current = max(-0x8000, min(0x7FFF, current))
        self.regs[ina.CURRENT] = current & 0xFFFF
        self.regs[ina.POWER] = min(power, 0xFFFF)
        bus = self.regs[ina.BUS_VOLTAGE] & ~ina.BUS_OVF & 0xFFFF
        self.regs[ina.BUS_VOLTAGE] = bus | ina.BUS_OVF if overflow else bus


class SimSMBus:
    """An I2C bus with chips at their `address`, answering the calls of `smbus2.SMBus` that drivers
    make. Registers are 16-bit, most significant byte first on the wire: the block calls carry the
    wire order; the word calls return (and take) the SMBus little-endian interpretation, the bytes
    swapped, as the real bus does. `fault` = "nack" (OSError 121 on every transfer, like a missing
    device), "zeros" or "ones" (every byte read is 0x00 / 0xFF) makes the bus misbehave."""

    def __init__(self, *chips: SimIna219):
        self.devices = {chip.address: chip for chip in chips}
        self.fault: str | None = None
        self.transfers = 0
        self.closed = False

    def _device(self, addr: int) -> SimIna219:
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
        out: list[int] = []
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
