"""The simulated devices, each at the lowest boundary it can emulate:

- `SimMpu9250`: answers SPI transfers like the chip (registers, 14-byte burst from 0x3B in big-endian
  int16 at the configured full scale, the AK8963 behind the I2C master);
- `SimGpio`: the pigpio calls the HC-SR04 driver makes, producing echo edges with 32-bit microsecond
  ticks (which wrap) and watchdog timeouts;
- `SimMotors`: takes PWM counts on the 0..40000 range;
- `SimBattery`: a discharging 4S LiPo behind the power monitor;
- `SimClock`: lock-step: waiting for the next tick advances the world by one loop period.

Noise and bias can be switched off (`SensorNoise.off()`); true values stay on `World`.
"""
from __future__ import annotations

import heapq
import math
import random
import struct
from dataclasses import dataclass

import numpy as np
import pigpio

from flightctl.drivers import mpu9250_regs as reg
from flightctl.drivers.hcsr04 import US_PER_M
from flightctl.hal import PWM_RANGE
from flightctl.params import Airframe
from flightctl.sim.model import Effect, Model, rotation
from flightctl.sim.plant import Plant

G = 9.80665
EARTH_FIELD_T = (20e-6, 0.0, -40e-6)  # North, West, Up: a mid-latitude field, dipping down


@dataclass(frozen=True)
class SensorNoise:
    """Defaults from the MPU-9250 datasheet at a 184 Hz bandwidth (noise densities 0.01 deg/s/rtHz and
    300 ug/rtHz), its +-5 deg/s zero-rate offset, and an HC-SR04 echo jitter of a few millimetres."""
    gyro_sigma: float = 0.003          # rad/s
    gyro_bias: float = 0.05            # rad/s, the spread of the zero-rate offset per axis
    accel_sigma: float = 0.05          # m/s^2
    accel_bias: float = 0.05           # m/s^2
    mag_sigma: float = 0.3e-6          # T
    sonar_sigma_us: float = 15.0       # echo width jitter
    sonar_dropout: float = 0.0         # probability that an echo does not come back
    battery_sigma: float = 0.01        # V

    @staticmethod
    def off() -> "SensorNoise":
        return SensorNoise(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


class NoisePool:
    """Standard normal numbers drawn in blocks by numpy: the per-sample cost of `next()` is an index."""

    def __init__(self, seed: int, block: int = 1 << 16):
        self._gen = np.random.default_rng(seed)
        self._block = block
        self._refill()

    def _refill(self) -> None:
        self._values = self._gen.standard_normal(self._block).tolist()
        self._i = 0

    def take(self, n: int) -> list[float]:
        if self._i + n > self._block:
            self._refill()
        i = self._i
        self._i = i + n
        return self._values[i:i + n]


class World:
    """The plant, its environment and the true sensor values."""

    def __init__(self, airframe: Airframe, effects: tuple[Effect, ...] = (), noise: SensorNoise = SensorNoise(),
                 seed: int = 0, substeps: int = 2, battery_soc: float = 0.9):
        self.a = airframe
        self.dt = airframe.dt
        self.rng = random.Random(seed)
        self.normal = NoisePool(seed)
        self.noise = noise
        self.battery = SimBattery(self, battery_soc)
        self.plant = Plant(Model(airframe, effects), self.dt, substeps, self.battery.voltage)
        self.gpio = SimGpio(self)

    @property
    def t(self) -> float:
        return self.plant.t

    def advance(self, dt: float) -> None:
        self.plant.advance(dt)
        self.battery.advance(dt)
        self.gpio.advance_to(self.plant.t)

    def range_along_body_z(self) -> float:
        """Distance from the sonar along -z_b to the floor plane (infinite if tilted past 60 deg)."""
        x = self.plant.x
        c = math.cos(x[6]) * math.cos(x[7])
        return x[2] / c if c > 0.5 else math.inf

    def magnetic_field_body(self) -> tuple[float, float, float]:
        Rm = rotation(*self.plant.attitude)
        bn, bw, bu = EARTH_FIELD_T
        return (Rm[0] * bn + Rm[3] * bw + Rm[6] * bu, Rm[1] * bn + Rm[4] * bw + Rm[7] * bu,
                Rm[2] * bn + Rm[5] * bw + Rm[8] * bu)


class SimMpu9250:
    """The chip behind `spidev.SpiDev.xfer2`. `fault` = 'zeros' or 'ones' makes every read a bus-error frame."""
    _HEAD = struct.Struct(">7h")
    _MAG = struct.Struct("<3hB")
    MAG_EVERY = 4   # burst reads per magnetometer sample: 450 Hz / 4, near the AK8963's 100 Hz

    def __init__(self, world: World, who_am_i: int = reg.WHO_AM_I_MPU9250, has_mag: bool = True):
        self.world = world
        self.max_speed_hz = 0
        self.fault = None
        self.who_am_i = who_am_i
        self.has_mag = has_mag
        n = world.noise
        g = world.rng.gauss
        self.gyro_bias = (g(0, n.gyro_bias), g(0, n.gyro_bias), g(0, n.gyro_bias))
        self.accel_bias = (g(0, n.accel_bias), g(0, n.accel_bias), g(0, n.accel_bias))
        self._reset()

    def _reset(self) -> None:
        self.regs = bytearray(128)
        self.regs[reg.WHO_AM_I] = self.who_am_i
        self.regs[reg.PWR_MGMT_1] = 0x01
        self.ak = bytearray(0x13)
        self.ak[reg.AK_WIA] = reg.AK_WIA_VALUE if self.has_mag else 0x00
        self._slv0_read = 0   # bytes the I2C master copies from the AK8963 on every sample
        self._mag_count = self.MAG_EVERY

    def xfer2(self, data: list[int]) -> list[int]:
        r = data[0] & 0x7F
        if data[0] & reg.READ:
            if self.fault:
                return [0] + [0x00 if self.fault == "zeros" else 0xFF] * (len(data) - 1)
            if r == reg.ACCEL_XOUT_H:
                self._sample()
            return [0] + list(self.regs[r:r + len(data) - 1])
        for i, value in enumerate(data[1:]):
            self._write(r + i, value)
        return [0] * len(data)

    def _write(self, r: int, value: int) -> None:
        if r == reg.PWR_MGMT_1 and value & reg.H_RESET:
            self._reset()
            return
        self.regs[r] = value
        if r == reg.I2C_SLV0_CTRL and value & reg.SLV_EN:
            addr, ak_reg, n = self.regs[reg.I2C_SLV0_ADDR], self.regs[reg.I2C_SLV0_REG], value & 0x0F
            if addr & 0x7F != reg.AK8963_ADDR:
                return
            if addr & reg.READ:
                self._slv0_read = n
                self._copy_ext()
            elif ak_reg < len(self.ak) and ak_reg != reg.AK_WIA:
                self.ak[ak_reg] = self.regs[reg.I2C_SLV0_DO]

    def _copy_ext(self) -> None:
        start, n = self.regs[reg.I2C_SLV0_REG], self._slv0_read
        self.regs[reg.EXT_SENS_DATA_00:reg.EXT_SENS_DATA_00 + n] = self.ak[start:start + n]

    def _sample(self) -> None:
        w = self.world
        n = w.noise
        fx, fy, fz = w.plant.specific_force()
        p, q, r = w.plant.rates
        ab, gb = self.accel_bias, self.gyro_bias
        a_lsb = reg.ACCEL_LSB_PER_G[(self.regs[reg.ACCEL_CONFIG] >> 3) & 3] / G
        g_lsb = reg.GYRO_LSB_PER_DPS[(self.regs[reg.GYRO_CONFIG] >> 3) & 3] * (180.0 / math.pi)
        sa, sg = n.accel_sigma, n.gyro_sigma
        e = w.normal.take(6)
        self._HEAD.pack_into(self.regs, reg.ACCEL_XOUT_H,
                             _i16((fx + ab[0] + sa * e[0]) * a_lsb), _i16((fy + ab[1] + sa * e[1]) * a_lsb),
                             _i16((fz + ab[2] + sa * e[2]) * a_lsb), _i16(10.0 * reg.TEMP_LSB_PER_C),
                             _i16((p + gb[0] + sg * e[3]) * g_lsb), _i16((q + gb[1] + sg * e[4]) * g_lsb),
                             _i16((r + gb[2] + sg * e[5]) * g_lsb))
        self._mag_count += 1
        if self._slv0_read and self.ak[reg.AK_CNTL1] and self._mag_count >= self.MAG_EVERY:
            self._mag_count = 0   # the AK8963 measures at 100 Hz (continuous mode 2)
            bx, by, bz = w.magnetic_field_body()
            sm, lsb = n.mag_sigma, 1.0 / reg.AK_TESLA_PER_LSB
            e = w.normal.take(3)
            # body (x fwd, y left, z up) -> AK8963 axes (x_ak = y_mpu, y_ak = x_mpu, z_ak = -z_mpu)
            self._MAG.pack_into(self.ak, reg.AK_HXL, _i16((by + sm * e[0]) * lsb),
                                _i16((bx + sm * e[1]) * lsb), _i16(-(bz + sm * e[2]) * lsb), 0x10)
            self._copy_ext()


def _i16(v: float) -> int:
    v = int(v + 0.5) if v >= 0.0 else -int(0.5 - v)
    return 32767 if v > 32767 else -32768 if v < -32768 else v


class _Callback:
    def __init__(self, gpio: "SimGpio", pin: int, func):
        self._gpio, self.pin, self.func = gpio, pin, func

    def cancel(self) -> None:
        self._gpio.callbacks.get(self.pin, []).remove(self)


class SimGpio:
    """The pigpio calls of the HC-SR04 driver. A trigger schedules the echo edges the module would
    produce for the true distance: the echo rises about 450 us after the trigger and stays high for
    distance * 5831 us; with no echo (out of range, dropout) a module holds it high for 38 ms."""
    ECHO_DELAY_S = 450e-6
    NO_ECHO_S = 0.038

    def __init__(self, world: World, tick0: int | None = None):
        self.world = world
        # start the 32-bit microsecond counter at a random place, so the wrap is met in long runs
        self.tick0 = world.rng.randrange(1 << 32) if tick0 is None else tick0
        self.callbacks: dict[int, list[_Callback]] = {}
        self.watchdogs: dict[int, float] = {}
        self.last_edge: dict[int, float] = {}
        self.stuck_high = False
        self._events: list[tuple[float, int, int]] = []
        self._echo_pin = None

    def tick(self, t: float) -> int:
        return (self.tick0 + int(round(t * 1e6))) & 0xFFFFFFFF

    def get_current_tick(self) -> int:
        return self.tick(self.world.t)

    def set_mode(self, gpio: int, mode: int) -> int:
        return 0

    def callback(self, user_gpio: int, edge: int, func) -> _Callback:
        cb = _Callback(self, user_gpio, func)
        self.callbacks.setdefault(user_gpio, []).append(cb)
        self._echo_pin = user_gpio
        return cb

    def set_watchdog(self, user_gpio: int, wdog_timeout: int) -> int:
        if wdog_timeout:
            self.watchdogs[user_gpio] = wdog_timeout / 1000.0
            self.last_edge[user_gpio] = self.world.t
        else:
            self.watchdogs.pop(user_gpio, None)
        return 0

    def gpio_trigger(self, user_gpio: int, pulse_len: int = 10, level: int = 1) -> int:
        w, pin = self.world, self._echo_pin
        if pin is None or self.stuck_high:
            return 0
        t = w.t + pulse_len * 1e-6 + self.ECHO_DELAY_S
        d = w.range_along_body_z()
        n = w.noise
        if d > 4.5 or (n.sonar_dropout and w.rng.random() < n.sonar_dropout):
            width = self.NO_ECHO_S
        else:
            width = max(d * US_PER_M + w.rng.gauss(0.0, n.sonar_sigma_us), 0.0) * 1e-6
        heapq.heappush(self._events, (t, pin, 1))
        heapq.heappush(self._events, (t + width, pin, 0))
        return 0

    def stick_echo_high(self) -> None:
        """A fault seen in clones: the echo line goes high and stays there."""
        self._events.clear()
        self._fire(self._echo_pin, 1, self.world.t)
        self.stuck_high = True

    def advance_to(self, t: float) -> None:
        events = self._events
        while events and events[0][0] <= t:
            te, pin, level = heapq.heappop(events)
            self._fire(pin, level, te)
        for pin, timeout in self.watchdogs.items():
            last = self.last_edge.get(pin, 0.0)
            while t - last >= timeout:   # pigpio repeats the timeout report while no edge comes
                last += timeout
                self._fire(pin, pigpio.TIMEOUT, last)

    def _fire(self, pin: int, level: int, t: float) -> None:
        self.last_edge[pin] = t
        tick = self.tick(t)
        for cb in list(self.callbacks.get(pin, ())):
            cb.func(pin, level, tick)


class SimMotors:
    """Four ESC outputs taking PWM counts; the command value P = counts / 40000 * 255 drives eq. 26."""

    def __init__(self, world: World):
        self.world = world
        self.armed = False
        self.counts = [0, 0, 0, 0]

    def arm(self) -> None:
        self.armed = True   # the simulated output runs at exactly the configured ESC frequency

    def write(self, counts: list[int]) -> None:
        c = self.counts
        c[0], c[1], c[2], c[3] = counts
        k = 255.0 / PWM_RANGE
        self.world.plant.command(c[0] * k, c[1] * k, c[2] * k, c[3] * k, self.world.battery.voltage)

    def stop(self) -> None:
        self.write([0, 0, 0, 0])
        self.armed = False


class SimBattery:
    """A 4S 4000 mAh LiPo: open-circuit voltage linear in charge between 14.0 and 16.6 V, 25 mOhm of
    internal resistance; the current is the rotors' mechanical power (torque x speed, eq. 27-28)
    over the voltage at 75 % efficiency. Plausible values, not measured."""
    CAPACITY_C = 4.0 * 3600
    R_INT = 0.025
    EFFICIENCY = 0.75

    def __init__(self, world: World, soc: float):
        self.world, self.soc = world, soc
        self.current = 0.0
        self.voltage = self._ocv()

    def _ocv(self) -> float:
        return 14.0 + 2.6 * self.soc

    def advance(self, dt: float) -> None:
        plant = self.world.plant
        a = self.world.a
        f, tau, _, _ = plant.model.forces(plant.t, plant.x, plant.u)
        power = sum(tau[i] * math.sqrt(f[i] / a.c1) for i in range(4)) / self.EFFICIENCY
        self.current = power / self.voltage
        self.soc -= self.current * dt / self.CAPACITY_C
        self.voltage = self._ocv() - self.R_INT * self.current

    def read(self) -> tuple[float, float]:
        s = self.world.noise.battery_sigma
        g = self.world.rng.gauss
        return self.voltage + g(0.0, s), self.current + g(0.0, 10 * s)


class SimClock:
    """Lock-step with the plant: no sleeping."""

    def __init__(self, world: World):
        self.world = world
        self.period = world.dt

    def now(self) -> float:
        return self.world.t

    def wait_next(self) -> float:
        self.world.advance(self.period)
        return self.world.t


class TruthEstimator:
    """Perfect state feedback: the controller sees the true attitude (for the paper's comparison)."""
    __slots__ = ("plant", "roll", "pitch", "yaw", "droll", "dpitch", "dyaw", "in_flight")

    def __init__(self, world: World):
        self.plant = world.plant
        self.roll = self.pitch = self.yaw = self.droll = self.dpitch = self.dyaw = 0.0
        self.in_flight = False

    def set_reference(self, tilt_bias, yaw_bias, use_mag) -> None:
        pass

    def update(self, s, dt: float) -> None:
        x = self.plant.x
        self.roll, self.pitch = x[6], x[7]
        self.yaw = (x[8] + math.pi) % (2 * math.pi) - math.pi
        xdot = self.plant.model.f(self.plant.t, x, self.plant.u)
        self.droll, self.dpitch, self.dyaw = xdot[6], xdot[7], xdot[8]


class TruthRangefinder:
    """Perfect altitude at every loop iteration (the altitude task then runs at the loop rate)."""

    def __init__(self, world: World):
        self.world = world

    def trigger(self) -> None:
        pass

    def poll(self) -> float:
        return self.world.range_along_body_z()
