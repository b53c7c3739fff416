"""MPU-9250 over SPI (spidev), with the AK8963 magnetometer read through the MPU's I2C master.

Frames: the chip is mounted with its x toward motor 1 and z up, so accelerometer and gyro axes are
the body axes. The AK8963 axes are (x_mpu = y_ak, y_mpu = x_ak, z_mpu = -z_ak); the driver converts
once, here, and reports the field in the body frame (x forward, y left, z up) in tesla.

Frame checks (docs/safety.md). `read` refuses a frame, leaving the sample as it
was (the loop flies on the last good sample), when it is
- a bus-error pattern: the 14 data bytes all 0x00 or all 0xFF (MISO stuck low or high);
- frozen: the same 14 bytes as the FROZEN_FRAMES frames before it. A live chip never repeats a
  frame: its accelerometer noise alone is ~20 LSB rms (300 ug/rtHz, PS 3.2, at 4096 LSB/g), so
  FROZEN_FRAMES + 1 identical frames are a stale bus or a hung chip (refused from the 5th);
- a temperature outside the chip's operating range, TEMP_RANGE_C (PS 3.4: -40 to 85 degC);
- an impossible jump from the last accepted frame: more than JUMP_ACCEL in one axis's specific force,
  JUMP_GYRO in one rate, or JUMP_TEMP_C in the die temperature between two frames; unless the frame
  before it (refused or not) is within those limits of it, i.e. a real step confirmed by the next frame.
  Random bytes fail one of these at once (the die temperature alone moves ~0.01 degC a second);
  JUMP_GYRO is 3 rad/s in 2.2 ms, ~1400 rad/s^2, ten times what the rotors' torque can give the
  frame, and JUMP_ACCEL 30 m/s^2, forty times the rotors' vibration (sim/world/imu.py).
- a dead accelerometer: the three accelerometer words exactly 0 in ZERO_ACCEL_FRAMES frames in a row
  (its ~20 LSB of noise make one such frame about 1 in 10^5 even in free fall, three never), while
  the rest of the frame lives; off with the frozen check (`frozen_frames` = 0: a noise-free chip).
`rejected` counts the refused frames by reason; `why` names the last one. A saturated frame (an
accelerometer or gyro word at the int16 limit, -32768 or 32767: the true value is beyond the full
scale) is not refused, since a real manoeuvre can saturate it too: it is decoded as the full scale,
`saturated` is set and counted in `rejected["saturated"]`; the loop names it (docs/safety.md).
"""
from __future__ import annotations

import math
import struct
import time

from flightctl.drivers import mpu9250_regs as reg
from flightctl.hal import ImuSample, SpiDevice
from flightctl.physics import G
_HEAD = struct.Struct(">7h")    # accel x y z, temperature, gyro x y z: big-endian int16
_MAG = struct.Struct("<3hB")     # then the AK8963 data, little-endian int16, and ST2
FROZEN_FRAMES = 4                # identical frames accepted after a frame; the next one is refused
ZERO_ACCEL_FRAMES = 3            # frames in a row with the accelerometer at exactly (0, 0, 0): a dead sensor
TEMP_RANGE_C = (-40.0, 85.0)     # degC, the operating range (PS-MPU-9250A-01 section 3.4)
JUMP_ACCEL = 30.0                # m/s^2 per frame and axis
JUMP_GYRO = 3.0                  # rad/s per frame and axis
JUMP_TEMP_C = 1.0                # degC per frame
_BUS_ZEROS, _BUS_ONES = b"\x00" * 14, b"\xff" * 14


class ImuError(Exception):
    """The IMU is absent, the wrong chip, or not answering."""


DLPF = 1   # DLPF_CFG and A_DLPF_CFG the driver configures by default: 184 Hz gyro, 218 Hz accelerometer


def dlpf_delays(dlpf: int = DLPF) -> tuple[float, float]:
    """s: the register map's delay of the gyro's and the accelerometer's DLPF at configuration `dlpf`."""
    return reg.GYRO_DLPF[dlpf][1], reg.ACCEL_DLPF[dlpf][1]


class Mpu9250:
    """`start()` configures the chip; `read(sample)` does one burst read and fills the sample in SI."""

    def __init__(self, spi: SpiDevice, accel_fs: int = 2, gyro_fs: int = 3, dlpf: int = DLPF,
                 sleep=time.sleep, frozen_frames: int = FROZEN_FRAMES):
        """`frozen_frames` = 0 switches the frozen check off: only for an ideal, noise-free simulated
        chip, whose frames do repeat."""
        if accel_fs not in range(4) or gyro_fs not in range(4):
            raise ValueError("full-scale selections are 0..3")
        self.spi = spi
        self.accel_fs, self.gyro_fs, self.dlpf = accel_fs, gyro_fs, dlpf
        self._sleep = sleep
        self._a = G / reg.ACCEL_LSB_PER_G[accel_fs]                  # m/s^2 per LSB
        self._g = math.radians(1.0) / reg.GYRO_LSB_PER_DPS[gyro_fs]   # rad/s per LSB
        self._tx = [reg.READ | reg.ACCEL_XOUT_H] + [0] * reg.BURST_LEN
        self.has_mag = False
        self.temperature = 0.0
        self.frozen_frames = frozen_frames
        self._jump = (round(JUMP_ACCEL / self._a),) * 3 + (round(JUMP_TEMP_C * reg.TEMP_LSB_PER_C),) \
            + (round(JUMP_GYRO / self._g),) * 3
        lo, hi = ((c - reg.TEMP_OFFSET_C) * reg.TEMP_LSB_PER_C for c in TEMP_RANGE_C)
        self._temp_lsb = (lo, hi)
        self._prev_head = b""     # the last frame read (refused or not), raw
        self._zero_accel = 0      # frames in a row with the accelerometer words all 0
        self._prev = None         # its seven words
        self._good = None         # the words of the last accepted frame
        self._repeats = 0         # how many times the last frame repeated the one before it
        self.rejected: dict[str, int] = {}
        self.why = ""
        self.saturated = False    # the last accepted frame had a word at the int16 limit

    # --- register access -------------------------------------------------------------------
    def write(self, register: int, value: int) -> None:
        self.spi.xfer2([register & 0x7F, value & 0xFF])

    def read_reg(self, register: int) -> int:
        return self.spi.xfer2([reg.READ | register, 0])[1]

    def _ak_write(self, register: int, value: int) -> None:
        self.write(reg.I2C_SLV0_ADDR, reg.AK8963_ADDR)
        self.write(reg.I2C_SLV0_REG, register)
        self.write(reg.I2C_SLV0_DO, value)
        self.write(reg.I2C_SLV0_CTRL, reg.SLV_EN | 1)
        self._sleep(0.01)

    def _ak_read(self, register: int) -> int:
        self.write(reg.I2C_SLV0_ADDR, reg.READ | reg.AK8963_ADDR)
        self.write(reg.I2C_SLV0_REG, register)
        self.write(reg.I2C_SLV0_CTRL, reg.SLV_EN | 1)
        self._sleep(0.01)
        return self.read_reg(reg.EXT_SENS_DATA_00)

    # --- lifecycle ---------------------------------------------------------------------------
    def filters(self) -> dict[str, str]:
        """The chip's own low-pass filters as a flight log declares them (`# gyro_filter:`,
        `# acc_filter:`, read by `flightctl diagnose`): each configured DLPF as the first-order stage
        of the register map's delay, 1 / (2 pi delay) Hz (2.9 ms for the gyro at DLPF_CFG = 1)."""
        gyro, acc = dlpf_delays(self.dlpf)
        return {"gyro_filter": "pt1 %.4g" % (1.0 / (2.0 * math.pi * gyro)),
                "acc_filter": "pt1 %.4g" % (1.0 / (2.0 * math.pi * acc))}

    def start(self) -> None:
        self.spi.max_speed_hz = reg.SETUP_SPI_HZ
        self.write(reg.PWR_MGMT_1, reg.H_RESET)
        self._sleep(0.1)
        self.write(reg.PWR_MGMT_1, reg.CLKSEL_PLL)
        who = self.read_reg(reg.WHO_AM_I)
        if who != reg.WHO_AM_I_MPU9250:
            raise ImuError(f"IMU: WHO_AM_I returned 0x{who:02X}, expected 0x{reg.WHO_AM_I_MPU9250:02X} "
                           "(MPU-9250); wrong chip or no chip on the SPI bus")
        self.write(reg.USER_CTRL, reg.I2C_IF_DIS | reg.I2C_MST_EN)
        self.write(reg.PWR_MGMT_2, 0x00)
        self.write(reg.SMPLRT_DIV, 0)
        self.write(reg.CONFIG, self.dlpf)
        self.write(reg.GYRO_CONFIG, self.gyro_fs << 3)
        self.write(reg.ACCEL_CONFIG, self.accel_fs << 3)
        self.write(reg.ACCEL_CONFIG2, self.dlpf)
        for r, v in ((reg.GYRO_CONFIG, self.gyro_fs << 3), (reg.ACCEL_CONFIG, self.accel_fs << 3)):
            if self.read_reg(r) != v:
                raise ImuError(f"IMU: register 0x{r:02X} reads back 0x{self.read_reg(r):02X} after writing 0x{v:02X}")
        self.write(reg.I2C_MST_CTRL, reg.I2C_MST_400KHZ)
        self._ak_write(reg.AK_CNTL2, 0x01)
        self.has_mag = self._ak_read(reg.AK_WIA) == reg.AK_WIA_VALUE
        if self.has_mag:
            self._ak_write(reg.AK_CNTL1, reg.AK_CNTL1_16BIT_100HZ)
            self.write(reg.I2C_SLV0_ADDR, reg.READ | reg.AK8963_ADDR)   # from now on, every sample
            self.write(reg.I2C_SLV0_REG, reg.AK_HXL)
            self.write(reg.I2C_SLV0_CTRL, reg.SLV_EN | reg.MAG_READ_LEN)
        self.spi.max_speed_hz = reg.READ_SPI_HZ

    def read(self, out: ImuSample) -> bool:
        """One burst read from ACCEL_XOUT_H; False (sample untouched) on a refused frame (the checks
        of the module docstring; `why` names the reason)."""
        rx = self.spi.xfer2(self._tx)
        data = bytes(rx)
        head = data[1:15]
        if head == _BUS_ZEROS or head == _BUS_ONES:
            return self._refuse("bus error pattern")
        if head == self._prev_head:
            self._repeats += 1
            if self.frozen_frames and self._repeats >= self.frozen_frames:
                return self._refuse("frozen")
        else:
            self._repeats = 0
        self._prev_head = head
        words = _HEAD.unpack_from(data, 1)
        prev, self._prev = self._prev, words
        ax, ay, az, temp, gx, gy, gz = words
        if not self._temp_lsb[0] <= temp <= self._temp_lsb[1]:
            return self._refuse("temperature out of range")
        if ax == 0 and ay == 0 and az == 0 and self.frozen_frames:   # (a noise-free chip reads 0 in free fall)
            self._zero_accel += 1
            if self._zero_accel >= ZERO_ACCEL_FRAMES:
                return self._refuse("accelerometer reads zero")
        else:
            self._zero_accel = 0
        good = self._good
        if good is not None and self._jumps(good, words) and (prev is None or self._jumps(prev, words)):
            return self._refuse("impossible jump")
        self._good = words
        self.saturated = sat = -32768 in words or 32767 in (ax, ay, az, gx, gy, gz)
        if sat:
            self.rejected["saturated"] = self.rejected.get("saturated", 0) + 1
        mx, my, mz, st2 = _MAG.unpack_from(data, 15)
        a, g = self._a, self._g
        out.ax, out.ay, out.az = ax * a, ay * a, az * a
        out.gx, out.gy, out.gz = gx * g, gy * g, gz * g
        self.temperature = temp / reg.TEMP_LSB_PER_C + reg.TEMP_OFFSET_C
        if self.has_mag and not st2 & reg.AK_ST2_HOFL:
            m = reg.AK_TESLA_PER_LSB
            out.mx, out.my, out.mz = my * m, mx * m, -mz * m   # AK8963 axes -> body axes
            out.mag_fresh = True
        else:
            out.mag_fresh = False
        return True

    def _jumps(self, a: tuple, b: tuple) -> bool:
        """True if any word moves more than its limit between frames `a` and `b`."""
        m = self._jump
        return (abs(a[0] - b[0]) > m[0] or abs(a[1] - b[1]) > m[1] or abs(a[2] - b[2]) > m[2] or abs(a[3] - b[3]) > m[3]
                or abs(a[4] - b[4]) > m[4] or abs(a[5] - b[5]) > m[5] or abs(a[6] - b[6]) > m[6])

    def _refuse(self, why: str) -> bool:
        self.why = why
        self.rejected[why] = self.rejected.get(why, 0) + 1
        return False
