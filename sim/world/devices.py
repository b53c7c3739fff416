"""The simulated devices, each at the lowest boundary it can emulate:

- `SimMpu9250`: answers SPI transfers like the chip (registers, 14-byte burst from 0x3B in big-endian
  int16 at the configured full scale, the AK8963 behind the I2C master), with the chip's noise, wandering
  and temperature-driven offsets, warming die and the rotors' vibration through its DLPF;
- `SimGpio`: the pigpio calls the HC-SR04 driver makes, producing echo edges with 32-bit microsecond
  ticks (which wrap) and watchdog timeouts;
- `SimMotors`: takes PWM counts on the 0..40000 range;
- `SimBattery`, `SimIna219` on a `SimSMBus` (in `flightctl.sim.world.power`): a discharging 4S LiPo and the
  power monitor's registers behind the smbus2 calls of the INA219 driver;
- `SimClock`: lock-step: waiting for the next tick advances the world by one loop period.

Noise and bias can be switched off (`SensorNoise.off()`); true values stay on `World`.
"""
from __future__ import annotations

import functools
import heapq
import math
import random
import struct
from dataclasses import dataclass, fields, replace

import numpy as np

from flightctl.drivers import mpu9250_regs as reg
from flightctl.drivers.hcsr04 import US_PER_M
from flightctl.hal import LEVEL_TIMEOUT, PWM_RANGE
from flightctl.params import Airframe
from flightctl.physics import G
from flightctl.sim.world.model import Effect, Model, euler_rates, rotation
from flightctl.sim.world.plant import SUBSTEPS, Plant
from flightctl.sim.world.power import SimBattery

EARTH_FIELD_T = (20e-6, 0.0, -40e-6)  # North, West, Up: a mid-latitude field, dipping down


@dataclass(frozen=True)
class SensorNoise:
    """What the simulated sensors add to the truth. MPU-9250 values from its Product Specification
    (PS-MPU-9250A-01 rev 1.1, section 3.1 gyroscope, 3.2 accelerometer) and Register Map (RM-MPU-9250A-00
    rev 1.6, registers 26 and 29: the DLPF bandwidths); where the datasheet is silent, a plausible value
    with its reason. `off()` gives the truth; `steady()` keeps white noise and a fixed offset only."""
    # MPU-9250 gyroscope
    gyro_density: float = math.radians(0.01)     # rad/s/rtHz: rate noise spectral density (PS 3.1)
    gyro_bias: float = 0.05            # rad/s, spread of the zero-rate offset per axis: initial ZRO tolerance
    #                                    +-5 deg/s (PS 3.1) taken as about 1.7 sigma
    gyro_bias_walk: float = 1.6e-5     # rad/s/rts, the bias random walk K. The datasheet is silent; MEMS gyros
    #   of this class show an in-run bias instability B (the Allan-deviation minimum) of a few to tens of
    #   deg/h (AirSim's MPU-6000 model, after Greenheck 2009: 4.6 deg/h). We take B = 10 deg/h and size K so
    #   that the Allan deviation of the white noise, N = density / sqrt 2 for a one-sided density, plus this
    #   walk, sqrt(N^2/tau + K^2 tau/3), has its minimum sqrt(2 N K / sqrt 3) at B: K = sqrt(3) B^2 / (2 N)
    #   = 1.6e-5 rad/s/rts, the minimum at tau = 13 s; the offset then wanders 0.016 deg/s in 5 minutes.
    gyro_temp_coeff: float = math.radians(0.02)  # rad/s/degC, spread per axis of the ZRO temperature slope.
    #   The datasheet bounds the ZRO variation by +-30 deg/s over -40..85 degC (PS 3.1), a worst case of
    #   0.24 deg/s/degC, and gives no typical slope: 0.02 deg/s/degC is a plausible typical value, an order
    #   of magnitude under that bound (the 5 degC warm-up below then moves each axis by ~0.1 deg/s).
    # MPU-9250 accelerometer
    accel_density: float = 300e-6 * G  # m/s^2/rtHz: noise power spectral density 300 ug/rtHz (PS 3.2)
    accel_bias: float = 0.05           # m/s^2 per axis (zero-g offset +-60 mg x, y and +-80 mg z, PS 3.2, are
    #                                    bounds; the paper's calibration removes the offset on the floor)
    accel_temp_coeff: float = 1.5e-3 * G   # m/s^2/degC per axis: zero-g change +-1.5 mg/degC (PS 3.2)
    # The die temperature after power-on: T = T_ambient + rise (1 - exp(-t / tau)). The datasheet gives no
    # figure. Plausible: the chip itself dissipates ~10 mW (a few mA at 3.3 V), a breakout board's regulator
    # and the Raspberry Pi beside it add more, and a board's thermal time constant is minutes: a rise of
    # 5 degC with a 2 min time constant.
    warmup_rise: float = 5.0           # degC
    warmup_tau: float = 120.0          # s
    # Vibration (the vehicle's, `Sensors` of its parameter file, flightctl/params.py: `vehicle_noise` puts them
    # here). Each rotor's residual imbalance U (kg m) is a force U w^2 rotating at its speed w (1/rev):
    # proportional to its thrust, since f = c1 w^2 (eq. 27). `vibration` is the specific force per rotor and
    # axis at hover thrust, before the DLPF. A balanced 12-inch propeller with its motor bell keeps U near 3 g mm;
    # at hover (w = 524 rad/s) that is U w^2 / M = 0.5 m/s^2 on the 1.645 kg frame, about 0.7 m/s^2 rms per
    # axis from four rotors of random phase. The arms bend under the rotating load and couple it into z;
    # multirotor logs show z vibration of the same order as x and y, so z gets the same amplitude.
    vibration: float = 0.5             # m/s^2, the accelerometer's 1/rev per rotor at hover thrust
    gyro_vibration: float = 0.0        # rad/s, the roll and pitch rates' 1/rev per rotor at hover thrust
    harmonic2: float = 0.0             # the 2/rev and 3/rev lines over the 1/rev, both sensors
    harmonic3: float = 0.0
    gyro_broadband: float = 0.0        # rad/s rms per read at hover thrust, roll and pitch (frame and airflow)
    yaw_share: float = 0.6             # the yaw rate's vibration and broadband over roll's and pitch's
    from_vehicle: bool = True          # `vehicle_noise` replaces the vibration terms by the vehicle file's
    mag_sigma: float = 0.3e-6          # T
    sonar_sigma_us: float = 15.0       # echo width jitter
    sonar_dropout: float = 0.0         # probability that an echo does not come back
    battery_sigma: float = 0.01        # V

    @staticmethod
    def off() -> "SensorNoise":
        return SensorNoise(**{f.name: 0.0 for f in fields(SensorNoise)})

    def steady(self) -> "SensorNoise":
        """Without what wanders: no bias random walk, no warm-up drift, no vibration."""
        return replace(self, gyro_bias_walk=0.0, warmup_rise=0.0, vibration=0.0, gyro_vibration=0.0,
                       gyro_broadband=0.0, from_vehicle=False)


def vehicle_noise(noise: SensorNoise, sensors) -> SensorNoise:
    """The chip's noise with the vehicle's vibration (`flightctl.params.Sensors`: a parameter file's
    [sensors]), unless the noise was set term by term (`off`, `steady`, or `from_vehicle=False`)."""
    if not noise.from_vehicle:
        return noise
    return replace(noise, vibration=sensors.accel_vibration, gyro_vibration=sensors.gyro_vibration,
                   harmonic2=sensors.harmonic2, harmonic3=sensors.harmonic3,
                   gyro_broadband=sensors.gyro_broadband, yaw_share=sensors.yaw_share)


class NoisePool:
    """Standard normal numbers drawn in blocks by numpy: the per-sample cost of `next()` is an index."""

    def __init__(self, seed: int, block: int = 1 << 16):
        self._gen = np.random.default_rng(seed)
        self._block = block
        self._refill()

    def _refill(self) -> None:
        self.array = self._gen.standard_normal(self._block)
        self.values = self.array.tolist()
        self._i = 0

    def take(self, n: int) -> list[float]:
        i = self.index(n)
        return self.values[i:i + n]

    def index(self, n: int) -> int:
        """Where the next n numbers start in the block (`array`, the list `values`), taken."""
        if self._i + n > self._block:
            self._refill()
        i = self._i
        self._i = i + n
        return i


class World:
    """The plant, its environment and the true sensor values."""

    def __init__(self, airframe: Airframe, effects: tuple[Effect, ...] = (), noise: SensorNoise = SensorNoise(),
                 seed: int = 0, substeps: int | None = None, battery_soc: float = 0.9):
        self.a = airframe
        self.dt = airframe.dt
        self.rng = random.Random(seed)
        self.normal = NoisePool(seed)
        self.noise = noise
        self.battery = SimBattery(self, battery_soc)
        self.plant = Plant(Model(airframe, effects), self.dt, substeps or SUBSTEPS, self.battery.voltage)
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


AMBIENT_C = 25.0   # degC: the room at power-on; the datasheet's typical values are at 25 degC (PS 3.1)
SPIN = (-1.0, 1.0, -1.0, 1.0)   # rotors 1 and 3 turn clockwise seen from above (eq. 9)
_CONFIG_REGS = frozenset((reg.SMPLRT_DIV, reg.CONFIG, reg.GYRO_CONFIG, reg.ACCEL_CONFIG, reg.ACCEL_CONFIG2))
_TAU = 2.0 * math.pi


class SimMpu9250:
    """The chip behind `spidev.SpiDev.xfer2`. `fault` = 'zeros' or 'ones' makes every read a bus-error frame.

    What a real MPU-9250 adds to the truth (sized by `SensorNoise`): white noise of the datasheet's density
    through the configured DLPF; a zero-rate offset that wanders (random walk) and follows the die
    temperature, which warms after power-on and is in the burst's temperature word; the accelerometer's
    offset that follows the temperature too; and the rotors' 1/rev vibration in the specific force, seen
    through the DLPF and the output sample rate (SMPLRT_DIV), so that it aliases as on the chip.
    The DLPF delays the rigid-body signals too: they pass a first-order low-pass whose time constant
    is the register map's delay of the configured filter (2.9 ms for the gyro at DLPF_CFG = 1, 1.88 ms
    for the accelerometer at A_DLPF_CFG = 1), updated at each read; the driver declares the same
    stages in the flight log (`Mpu9250.filters`), so that diagnose models what the chip did."""
    _HEAD = struct.Struct(">7h")
    _MAG = struct.Struct("<3hB")
    MAG_EVERY = 4   # burst reads per magnetometer sample: 450 Hz / 4, near the AK8963's 100 Hz
    AMBIENT_C = AMBIENT_C

    def __init__(self, world: World, who_am_i: int = reg.WHO_AM_I_MPU9250, has_mag: bool = True):
        self.world = world
        self.max_speed_hz = 0
        self.fault = None
        self.who_am_i = who_am_i
        self.has_mag = has_mag
        self._s, self._c = chip_die(world.noise, world.a, world.rng)   # `chip_frame`'s state and constants
        c = self._c
        self.accel_bias, self.gyro_bias = tuple(c[_C_A0:_C_A0 + 3]), tuple(c[_C_G0:_C_G0 + 3])
        self._t_on = self._t_last = world.t
        self._started = False             # the DLPF stage has its first read
        compiled = chip_frame_compiled()
        self._frame, self._arrays = compiled or chip_frame, compiled is not None
        # sensor effects that change what the gyro reports (`Effect.gyro`: an undeclared filter)
        self._gyro_effects = tuple(e for e in world.plant.model.effects if e.uses_gyro)
        if self._arrays:                             # compiled, it takes arrays (the same values)
            self._s, self._c = np.array(self._s), np.array(self._c)
        self._reset()

    def die_temperature(self, t: float) -> float:
        """degC: the die warms from the room toward a steady rise after power-on (first order)."""
        n = self.world.noise
        if n.warmup_rise == 0.0:
            return self.AMBIENT_C
        return self.AMBIENT_C + n.warmup_rise * (1.0 - math.exp((self._t_on - t) / n.warmup_tau))

    def _reset(self) -> None:
        self.regs = bytearray(128)
        self._regs = np.frombuffer(self.regs, dtype=np.uint8) if self._arrays else self.regs
        self.regs[reg.WHO_AM_I] = self.who_am_i
        self.regs[reg.PWR_MGMT_1] = 0x01
        self.ak = bytearray(0x13)
        self.ak[reg.AK_WIA] = reg.AK_WIA_VALUE if self.has_mag else 0x00
        self._slv0_read = 0   # bytes the I2C master copies from the AK8963 on every sample
        self._mag_count = self.MAG_EVERY
        self._configure()

    def _configure(self) -> None:
        """What the configuration registers set: scales, noise per sample, DLPF, output sample period."""
        rg, n = self.regs, self.world.noise
        self._a_lsb = reg.ACCEL_LSB_PER_G[(rg[reg.ACCEL_CONFIG] >> 3) & 3] / G
        self._g_lsb = reg.GYRO_LSB_PER_DPS[(rg[reg.GYRO_CONFIG] >> 3) & 3] * (180.0 / math.pi)
        cfg = rg[reg.CONFIG] & 7
        g_bw = reg.GYRO_DLPF[cfg][0]
        a_bw, self._a_delay = reg.ACCEL_DLPF[rg[reg.ACCEL_CONFIG2] & 7]
        # white noise of one-sided density d through a first-order low-pass of 3-dB bandwidth B: its
        # noise-equivalent bandwidth is pi/2 B, so sigma = d sqrt(pi/2 B) (at B = 92 Hz: 0.12 deg/s,
        # against the datasheet's 0.1 deg/s rms total noise there, PS 3.1)
        c = self._c
        c[_C_SG] = n.gyro_density * math.sqrt(0.5 * math.pi * g_bw)
        c[_C_SA] = n.accel_density * math.sqrt(0.5 * math.pi * a_bw)
        a_tc = 1.0 / (_TAU * a_bw)   # time constant of the accelerometer's DLPF as a first-order lag
        c[_C_A_LSB], c[_C_G_LSB], c[_C_TC2], c[_C_A_DELAY] = self._a_lsb, self._g_lsb, a_tc * a_tc, self._a_delay
        self._g_delay = reg.GYRO_DLPF[cfg][1]
        g_tc = 1.0 / (_TAU * g_bw)
        c[_C_TCG2], c[_C_G_DELAY] = g_tc * g_tc, self._g_delay
        self._k_dt = None   # the read interval of the DLPF stage's gains (c[_C_KA], c[_C_KG])
        # SAMPLE_RATE = 1 kHz / (1 + SMPLRT_DIV) when 0 < DLPF_CFG < 7, else the gyro's 8 kHz (RM, register 25)
        c[_C_PERIOD] = (1 + rg[reg.SMPLRT_DIV]) / 1000.0 if 0 < cfg < 7 else 1.0 / 8000.0

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
        if r in _CONFIG_REGS:
            self._configure()
        if r == reg.I2C_SLV0_CTRL and value & reg.SLV_EN:
            addr, ak_reg, n = self.regs[reg.I2C_SLV0_ADDR], self.regs[reg.I2C_SLV0_REG], value & 0x0F
            if addr & 0x7F != reg.AK8963_ADDR:
                return
            if addr & reg.READ:
                self._slv0_read = n
                self._copy_ext()
            elif ak_reg < len(self.ak) and ak_reg != reg.AK_WIA:
                self.ak[ak_reg] = self.regs[reg.I2C_SLV0_DO]

    def _gyro_effect(self, dt: float) -> None:
        """The gyro's output registers through each sensor effect (`Effect.gyro`), in rad/s."""
        lsb = self._g_lsb
        rates = [v / lsb for v in _GYRO_WORDS.unpack_from(self.regs, _BURST + 8)]
        for e in self._gyro_effects:
            rates = e.gyro(dt, *rates)
        for k, v in enumerate(rates):
            put16(self.regs, _BURST + 8 + 2 * k, v * lsb)

    def _copy_ext(self) -> None:
        start, n = self.regs[reg.I2C_SLV0_REG], self._slv0_read
        self.regs[reg.EXT_SENS_DATA_00:reg.EXT_SENS_DATA_00 + n] = self.ak[start:start + n]

    def _sample(self) -> None:
        """The burst's registers now (`chip_frame`), and the magnetometer's at its own rate."""
        w = self.world
        t = w.t
        plant = w.plant
        fx, fy, fz = plant.specific_force()
        p, q, r = plant.rates
        dt, self._t_last = t - self._t_last, t
        if dt > 0.0 and dt != self._k_dt:   # the DLPF stage's gains for this read interval (the loop period)
            self._k_dt = dt
            self._c[_C_KA], self._c[_C_KG] = 1.0 - math.exp(-dt / self._a_delay), 1.0 - math.exp(-dt / self._g_delay)
        (f1, f2, f3, f4), (w1, w2, w3, w4) = (rotors := plant.forces()).f, rotors.w
        normal = w.normal
        i = normal.index(9)
        self._frame(self._regs, self._s, self._c, normal.array if self._arrays else normal.values, i,
                    fx, fy, fz, p, q, r, f1, f2, f3, f4, w1, w2, w3, w4, t, dt, self.die_temperature(t), self._started)
        self._started = True
        if self._gyro_effects:
            self._gyro_effect(dt)
        self._mag_count += 1
        if self._slv0_read and self.ak[reg.AK_CNTL1] and self._mag_count >= self.MAG_EVERY:
            self._mag_count = 0   # the AK8963 measures at 100 Hz (continuous mode 2)
            bx, by, bz = w.magnetic_field_body()
            sm, lsb = w.noise.mag_sigma, 1.0 / reg.AK_TESLA_PER_LSB
            e = normal.take(3)
            # body (x fwd, y left, z up) -> AK8963 axes (x_ak = y_mpu, y_ak = x_mpu, z_ak = -z_mpu)
            self._MAG.pack_into(self.ak, reg.AK_HXL, _i16((by + sm * e[0]) * lsb),
                                _i16((bx + sm * e[1]) * lsb), _i16(-(bz + sm * e[2]) * lsb), 0x10)
            self._copy_ext()


# `chip_frame`'s state s, by index: the DLPF stage's outputs fx, fy, fz, p, q, r (0-5), the gyro's
# random walk (_S_WALK, 3), each rotor's angle (_S_PHASE, 4)
_S_WALK, _S_PHASE, N_CHIP_STATE = 6, 9, 13
# its constants c, by index: the DLPF stage's gains for the read interval, the LSBs per unit, the white
# noise per sample, the bias walk K, the vibration per newton, the accelerometer DLPF's time constant
# squared, the output sample period, the accelerometer's DLPF delay; then per axis the zero-g offset and
# its temperature slope, the zero-rate offset and its slope; per arm the cosine and sine of its bending;
# then the gyro's vibration per newton, its DLPF's time constant squared and delay, the 2/rev and 3/rev
# lines over the 1/rev, the gyro's broadband noise per newton of the total thrust, the yaw share
(_C_KA, _C_KG, _C_A_LSB, _C_G_LSB, _C_SA, _C_SG, _C_WALK, _C_KV, _C_TC2, _C_PERIOD, _C_A_DELAY,
 _C_A0, _C_AC, _C_G0, _C_GC, _C_ZC, _C_ZS, _C_KVG, _C_TCG2, _C_G_DELAY, _C_H2, _C_H3, _C_BB, _C_YAW,
 N_CHIP_CONST) = (0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 14, 17, 20, 23, 27, 31, 32, 33, 34, 35, 36, 37, 38)
_BURST = reg.ACCEL_XOUT_H
_GYRO_WORDS = struct.Struct(">3h")   # the gyro's three words in the burst, from _BURST + 8


def chip_die(noise: SensorNoise, airframe, rng) -> tuple[list, list]:
    """One chip's `chip_frame` state and constants as it leaves the factory and sits on the vehicle:
    its zero-rate and zero-g offsets and their temperature slopes (drawn with the spreads of `noise`),
    each rotor's angle and each arm's bending phase (uniform), and the vehicle's vibration and
    broadband noise per newton of thrust. `rng` is a `random.Random`; the constants the driver's
    register writes set (`SimMpu9250._configure`) are left at 0. The batched simulator
    (sim/sweeps/batch_imu.py) builds its chips with this too."""
    n, g, a = noise, rng.gauss, airframe
    gyro_bias = (g(0, n.gyro_bias), g(0, n.gyro_bias), g(0, n.gyro_bias))
    accel_bias = (g(0, n.accel_bias), g(0, n.accel_bias), g(0, n.accel_bias))
    gyro_temp_coeff = (g(0, n.gyro_temp_coeff), g(0, n.gyro_temp_coeff), g(0, n.gyro_temp_coeff))
    accel_temp_coeff = (g(0, n.accel_temp_coeff), g(0, n.accel_temp_coeff), g(0, n.accel_temp_coeff))
    s = [0.0] * N_CHIP_STATE
    s[_S_PHASE:] = [rng.uniform(0.0, _TAU) for _ in range(4)]
    z = [rng.uniform(0.0, _TAU) for _ in range(4)]   # phase of each arm's bending
    c = [0.0] * N_CHIP_CONST
    c[_C_A0:_C_A0 + 3], c[_C_AC:_C_AC + 3] = accel_bias, accel_temp_coeff
    c[_C_G0:_C_G0 + 3], c[_C_GC:_C_GC + 3] = gyro_bias, gyro_temp_coeff
    c[_C_ZC:_C_ZC + 4], c[_C_ZS:_C_ZS + 4] = [math.cos(v) for v in z], [math.sin(v) for v in z]
    c[_C_WALK] = n.gyro_bias_walk
    B = a.M * a.g / 4.0                          # hover thrust per rotor
    c[_C_KV] = n.vibration / B                   # m/s^2 per newton of the rotor's thrust
    c[_C_KVG] = n.gyro_vibration / B             # rad/s per newton
    c[_C_H2], c[_C_H3], c[_C_YAW] = n.harmonic2, n.harmonic3, n.yaw_share
    c[_C_BB] = n.gyro_broadband / (4.0 * B)      # rad/s rms per newton of the four rotors' thrust
    return s, c


def chip_frame(regs, s, c, e, i, fx, fy, fz, p, q, r, f1, f2, f3, f4, w1, w2, w3, w4, t, dt, temp, started):
    """The MPU-9250's burst registers (ACCEL_XOUT_H on, big-endian int16) for the true specific force
    (fx, fy, fz) and rates (p, q, r) at time t, dt after the last read, the rotors' thrusts f and speeds
    w, the die at temp (degC), with the chip's state s and constants c (`SimMpu9250`; `started`: not
    the first read) and nine standard normal numbers e[i:i + 9]:

    - the DLPF's first-order stage on the rigid-body signals (gains c[_C_KA], c[_C_KG] for dt);
    - the zero-rate offset's random walk, variance K^2 dt over the time since the last sample;
    - the offsets and their temperature slopes, white noise per sample (the chip's, and on the gyro
      the frame's broadband part, in proportion to the rotors' thrust), the rotors' vibration.

    Plain arithmetic on indexable values: lists in plain Python, arrays compiled (`chip_frame_compiled`)."""
    if not started:
        s[0], s[1], s[2], s[3], s[4], s[5] = fx, fy, fz, p, q, r
    elif dt > 0.0:
        ka, kg = c[_C_KA], c[_C_KG]
        s[0] += ka * (fx - s[0])
        s[1] += ka * (fy - s[1])
        s[2] += ka * (fz - s[2])
        s[3] += kg * (p - s[3])
        s[4] += kg * (q - s[4])
        s[5] += kg * (r - s[5])
    fx, fy, fz, p, q, r = s[0], s[1], s[2], s[3], s[4], s[5]
    if c[_C_WALK] != 0.0 and dt > 0.0:
        k = c[_C_WALK] * math.sqrt(dt)
        s[_S_WALK] += k * e[i + 6]
        s[_S_WALK + 1] += k * e[i + 7]
        s[_S_WALK + 2] += k * e[i + 8]
    d = temp - AMBIENT_C
    if c[_C_KV] != 0.0 or c[_C_KVG] != 0.0:
        vx, vy, vz, vp, vq, vr = vibration(s, c, f1, f2, f3, f4, w1, w2, w3, w4, t, dt)
        fx, fy, fz, p, q, r = fx + vx, fy + vy, fz + vz, p + vp, q + vq, r + vr
    a_lsb, g_lsb, sa, sg = c[_C_A_LSB], c[_C_G_LSB], c[_C_SA], c[_C_SG]
    bb = c[_C_BB] * (f1 + f2 + f3 + f4)       # the frame's broadband rate noise, rms per read
    sp, sr = math.sqrt(sg * sg + bb * bb), math.sqrt(sg * sg + c[_C_YAW] * c[_C_YAW] * bb * bb)
    put16(regs, _BURST, (fx + c[_C_A0] + c[_C_AC] * d + sa * e[i]) * a_lsb)
    put16(regs, _BURST + 2, (fy + c[_C_A0 + 1] + c[_C_AC + 1] * d + sa * e[i + 1]) * a_lsb)
    put16(regs, _BURST + 4, (fz + c[_C_A0 + 2] + c[_C_AC + 2] * d + sa * e[i + 2]) * a_lsb)
    put16(regs, _BURST + 6, (temp - reg.TEMP_OFFSET_C) * reg.TEMP_LSB_PER_C)
    put16(regs, _BURST + 8, (p + c[_C_G0] + s[_S_WALK] + c[_C_GC] * d + sp * e[i + 3]) * g_lsb)
    put16(regs, _BURST + 10, (q + c[_C_G0 + 1] + s[_S_WALK + 1] + c[_C_GC + 1] * d + sp * e[i + 4]) * g_lsb)
    put16(regs, _BURST + 12, (r + c[_C_G0 + 2] + s[_S_WALK + 2] + c[_C_GC + 2] * d + sr * e[i + 5]) * g_lsb)


def vibration(s, c, f1, f2, f3, f4, w1, w2, w3, w4, t, dt):
    """The rotors' vibration in the output registers: (ax, ay, az) m/s^2 and (p, q, r) rad/s. Each
    rotor's speed from its thrust (eq. 27, so a rotor lag is followed), lines at 1, 2 and 3 times it
    (c[_C_H2], c[_C_H3] of the 1/rev), the amplitude in proportion to the thrust, taken at the chip's
    last output sample (SMPLRT_DIV) and through each sensor's DLPF as a first-order low-pass with the
    register map's bandwidth and delay; each rotor's angle advances in s. On the accelerometer the
    imbalance force turns with the rotor in x-y (eq. 9's sense) and bends its arm in z; on the gyro
    the bending arm rocks the frame in roll and pitch (and yaw, by c[_C_YAW]), with each arm's phase."""
    kv, kg, tc2, tg2 = c[_C_KV], c[_C_KVG], c[_C_TC2], c[_C_TCG2]
    h2, h3, yaw = c[_C_H2], c[_C_H3], c[_C_YAW]
    held = t % c[_C_PERIOD]
    back_a, back_g = held + c[_C_A_DELAY], held + c[_C_G_DELAY]   # how long ago each entered its register
    vx = vy = vz = vp = vq = vr = 0.0
    thrusts, speeds = (f1, f2, f3, f4), (w1, w2, w3, w4)
    for j in range(4):
        fi, om = thrusts[j], speeds[j]
        if fi > 0.0:
            th = s[_S_PHASE + j] = (s[_S_PHASE + j] + om * dt) % _TAU
            zc, zs, spin = c[_C_ZC + j], c[_C_ZS + j], SPIN[j]
            for sensor in range(2):
                k0, t2 = (kv, tc2) if sensor == 0 else (kg, tg2)
                if k0 == 0.0:
                    continue
                a = th - om * (back_a if sensor == 0 else back_g)
                c1, s1 = math.cos(a), math.sin(a)
                c2, s2 = 2.0 * c1 * c1 - 1.0, 2.0 * s1 * c1          # the 2/rev and 3/rev angles
                c3, s3 = c1 * c2 - s1 * s2, s1 * c2 + c1 * s2
                wt = om * om * t2
                g1 = k0 * fi / math.sqrt(1.0 + wt)                    # first-order DLPF gain at each line
                g2 = k0 * fi * h2 / math.sqrt(1.0 + 4.0 * wt)
                g3 = k0 * fi * h3 / math.sqrt(1.0 + 9.0 * wt)
                cs = g1 * c1 + g2 * c2 + g3 * c3
                sn = g1 * s1 + g2 * s2 + g3 * s3
                bent = cs * zc - sn * zs                              # the arm's phase
                if sensor == 0:
                    vx += cs
                    vy += spin * sn
                    vz += bent
                else:
                    vp += bent
                    vq += spin * (sn * zc + cs * zs)
                    vr += yaw * (cs * zc + sn * zs)
    return vx, vy, vz, vp, vq, vr


def put16(regs, at: int, v: float) -> None:
    """v rounded to a big-endian int16 (`_i16`) at regs[at], regs[at + 1]."""
    v = _i16(v) & 0xFFFF
    regs[at] = v >> 8
    regs[at + 1] = v & 0xFF


@functools.cache
def chip_frame_compiled():
    """`chip_frame` compiled (sim/world/compiled.py), or None."""
    from flightctl.sim.world import compiled
    if not compiled.enabled():
        return None
    c = compiled.compiled_copy
    frame = c(chip_frame, vibration=c(vibration), put16=c(put16, _i16=c(_i16)))
    # compiled (or loaded from the cache) now, not at a first read that a simulation paced by the wall
    # clock would see as a stall
    zeros = np.zeros(N_CHIP_CONST)
    frame(np.frombuffer(bytearray(128), dtype=np.uint8), zeros.copy(), zeros, zeros, 0, *[0.0] * 17, True)
    return frame


def _i16(v: float) -> int:
    """v rounded half away from zero to an int16, clipped at its ends as the chip's registers saturate
    (before the rounding: compiled, a float beyond the int64 range has no integer)."""
    if v >= 32767.0:
        return 32767
    if v <= -32768.0:
        return -32768
    if v != v:
        raise ValueError("a NaN register value")
    return int(v + 0.5) if v >= 0.0 else -int(0.5 - v)


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
        self._quiet_until = -math.inf   # before this time no edge is due and no watchdog can time out

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
        self._quiet_until = -math.inf
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
        self._quiet_until = -math.inf
        return 0

    def stick_echo_high(self) -> None:
        """A fault seen in clones: the echo line goes high and stays there."""
        self._events.clear()
        self._fire(self._echo_pin, 1, self.world.t)
        self.stuck_high = True
        self._quiet_until = -math.inf

    def advance_to(self, t: float) -> None:
        if t < self._quiet_until:       # (most loop periods)
            return
        events = self._events
        while events and events[0][0] <= t:
            te, pin, level = heapq.heappop(events)
            self._fire(pin, level, te)
        quiet = events[0][0] if events else math.inf
        for pin, timeout in self.watchdogs.items():
            last = self.last_edge.get(pin, 0.0)
            while t - last >= timeout:   # pigpio repeats the timeout report while no edge comes
                last += timeout
                self._fire(pin, LEVEL_TIMEOUT, last)
            quiet = min(quiet, self.last_edge.get(pin, 0.0) + timeout - 1e-9)   # (short of the rounding)
        self._quiet_until = quiet

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


class SimClock:
    """Lock-step with the plant: no sleeping. Its time is the plant's whole loop periods times the
    period (`Plant.periods`, an integer), never a sum: the same at any substep count."""

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
        self.roll, self.pitch = phi, theta = x[6], x[7]
        self.yaw = (x[8] + math.pi) % (2 * math.pi) - math.pi
        self.droll, self.dpitch, self.dyaw = euler_rates(math.sin(phi), math.cos(phi), math.sin(theta), math.cos(theta),
                                                         x[9], x[10], x[11])


class TruthRangefinder:
    """Perfect altitude at every loop iteration (the altitude task then runs at the loop rate)."""

    def __init__(self, world: World):
        self.world = world

    def trigger(self) -> None:
        pass

    def poll(self) -> float:
        return self.world.range_along_body_z()
