"""The simulated MPU-9250 behind `spidev.SpiDev.xfer2` (`SimMpu9250`): its registers, the 14-byte burst
from 0x3B in big-endian int16 at the configured full scale, the AK8963 behind its I2C master, and what a
real chip adds to the truth (sized by `devices.SensorNoise`): white noise through the configured DLPF,
the wandering and temperature-driven offsets, the warming die and the rotors' vibration.

The burst's registers are written by one plain function, `chip_frame` (with `vibration`, `put16`),
which sim/world/compiled.py compiles (`chip_frame_compiled`) and the batched simulator
(sim/sweeps/batch.py) runs for each of its vehicles; `chip_die` makes one chip's offsets and phases.
"""
from __future__ import annotations

import functools
import math
import struct

import numpy as np

from flightctl.drivers import mpu9250_regs as reg
from flightctl.physics import G
from flightctl.sim.world.model import remainder

TYPE_CHECKING = False
if TYPE_CHECKING:
    from flightctl.sim.world.devices import SensorNoise, World

AMBIENT_C = 25.0   # degC: the room at power-on; the datasheet's typical values are at 25 degC (PS 3.1)
SPIN = (-1.0, 1.0, -1.0, 1.0)   # rotors 1 and 3 turn clockwise seen from above (eq. 9)
# Hz: the gyro's broadband (frame and airflow) noise passes a first-order high-pass at this corner. It is
# vibration, not motion: what moves the frame below its structural modes moves the rigid body, which the
# plant flies; a multirotor's vibration sits at 40-300 Hz (its rotors' 1/rev and blade passing, the frame's
# resonances: ArduPilot's forum, "Frames and frame resonances and vibrations", frame peaks above 100 Hz;
# diydrones.com, "Vibration analysis", an MPU-9250 on a Raspberry Pi: noise at 40-300 Hz, the vehicle's
# useful band under 10 Hz). The corner lies between the two; white down to DC the noise made an attitude
# random walk (12.6-26 deg/sqrt(h)) that the chip's own 0.6 does not (issue 37)
BROADBAND_HP_HZ = 20.0
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
        self._k_dt = None   # the read interval of `read_gains`
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
        if dt > 0.0 and dt != self._k_dt:   # the gains for this read interval (the loop period)
            self._k_dt = dt
            c = self._c
            c[_C_KA], c[_C_KG], c[_C_BBA], c[_C_BBQ] = read_gains(c, dt)
        (f1, f2, f3, f4), (w1, w2, w3, w4) = (rotors := plant.forces()).f, rotors.w
        normal = w.normal
        i = normal.index(normals_per_read(self._c))
        self._frame(self._regs, self._s, self._c, normal.array if self._arrays else normal.values, i,
                    fx, fy, fz, p, q, r, f1, f2, f3, f4, w1, w2, w3, w4, t % float(self._c[_C_PERIOD]), dt,
                    self.die_temperature(t), self._started)
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
# random walk (_S_WALK, 3), each rotor's angle (_S_PHASE, 4), the broadband noise's high-pass (_S_BB, 3:
# its low-pass part, which the high-pass takes away, in the units of the read's rms gain, _S_BBG)
_S_WALK, _S_PHASE, _S_BB, _S_BBG, N_CHIP_STATE = 6, 9, 13, 16, 17
# its constants c, by index: the DLPF stage's gains for the read interval, the LSBs per unit, the white
# noise per sample, the bias walk K, the vibration per newton, the accelerometer DLPF's time constant
# squared, the output sample period, the accelerometer's DLPF delay; then per axis the zero-g offset and
# its temperature slope, the zero-rate offset and its slope; per arm the cosine and sine of its bending;
# then the gyro's vibration per newton, its DLPF's time constant squared and delay, the 2/rev and 3/rev
# lines over the 1/rev, the gyro's broadband noise per newton of the total thrust, its yaw share, the
# yaw share of the rotor lines; then the broadband high-pass's pole a and sqrt((1 + a) / 2) for the read interval
(_C_KA, _C_KG, _C_A_LSB, _C_G_LSB, _C_SA, _C_SG, _C_WALK, _C_KV, _C_TC2, _C_PERIOD, _C_A_DELAY,
 _C_A0, _C_AC, _C_G0, _C_GC, _C_ZC, _C_ZS, _C_KVG, _C_TCG2, _C_G_DELAY, _C_H2, _C_H3, _C_BB, _C_YAW,
 _C_YAWL, _C_BBA, _C_BBQ, N_CHIP_CONST) = (0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 14, 17, 20, 23, 27, 31, 32, 33, 34, 35,
                                          36, 37, 38, 39, 40, 41)
_BURST = reg.ACCEL_XOUT_H
_GYRO_WORDS = struct.Struct(">3h")   # the gyro's three words in the burst, from _BURST + 8


def chip_die(noise: SensorNoise, airframe, rng) -> tuple[list, list]:
    """One chip's `chip_frame` state and constants as it leaves the factory and sits on the vehicle:
    its zero-rate and zero-g offsets and their temperature slopes (drawn with the spreads of `noise`),
    each rotor's angle and each arm's bending phase (uniform), and the vehicle's vibration and
    broadband noise per newton of thrust. `rng` is a `random.Random`; the constants the driver's
    register writes set (`SimMpu9250._configure`) are left at 0. The batched simulator
    (sim/sweeps/batch.py) builds its chips with this too."""
    n, g, a = noise, rng.gauss, airframe
    gyro_bias = (g(0, n.gyro_bias), g(0, n.gyro_bias), g(0, n.gyro_bias))
    accel_bias = (g(0, n.accel_bias), g(0, n.accel_bias), g(0, n.accel_bias))
    gyro_temp_coeff = (g(0, n.gyro_temp_coeff), g(0, n.gyro_temp_coeff), g(0, n.gyro_temp_coeff))
    accel_temp_coeff = (g(0, n.accel_temp_coeff), g(0, n.accel_temp_coeff), g(0, n.accel_temp_coeff))
    s = [0.0] * N_CHIP_STATE
    s[_S_PHASE:_S_PHASE + 4] = [rng.uniform(0.0, _TAU) for _ in range(4)]
    z = [rng.uniform(0.0, _TAU) for _ in range(4)]   # phase of each arm's bending
    c = [0.0] * N_CHIP_CONST
    c[_C_A0:_C_A0 + 3], c[_C_AC:_C_AC + 3] = accel_bias, accel_temp_coeff
    c[_C_G0:_C_G0 + 3], c[_C_GC:_C_GC + 3] = gyro_bias, gyro_temp_coeff
    c[_C_ZC:_C_ZC + 4], c[_C_ZS:_C_ZS + 4] = [math.cos(v) for v in z], [math.sin(v) for v in z]
    c[_C_WALK] = n.gyro_bias_walk
    vibration_constants(c, n, a)
    return s, c


def vibration_constants(c, noise: SensorNoise, airframe) -> None:
    """The vehicle's vibration and broadband noise per newton of thrust into a chip's constants c
    (`chip_die`); with the vehicle's values as arrays, into c's rows of arrays (the batched simulator's
    chips, a column per constant: nothing here is drawn)."""
    n, a = noise, airframe
    B = a.M * a.g / 4.0                          # hover thrust per rotor
    c[_C_KV] = n.vibration / B                   # m/s^2 per newton of the rotor's thrust
    c[_C_KVG] = n.gyro_vibration / B             # rad/s per newton
    c[_C_H2], c[_C_H3], c[_C_YAW], c[_C_YAWL] = n.harmonic2, n.harmonic3, n.yaw_share, n.yaw_lines
    c[_C_BB] = n.gyro_broadband / (4.0 * B)      # rad/s rms per newton of the four rotors' thrust


def normals_per_read(c) -> int:
    """The standard normal numbers a read of `chip_frame` takes: nine, and three more for the gyro's
    broadband noise where the vehicle has it (so that a chip without it draws as it always did)."""
    return 12 if c[_C_BB] != 0.0 else 9


def read_gains(c, dt: float) -> tuple[float, float, float, float]:
    """`chip_frame`'s gains for a read interval dt, with the chip's constants c: the DLPF stage's, 1 - exp(-dt /
    delay) of the accelerometer and of the gyro (c[_C_KA], c[_C_KG]), the broadband noise's high-pass pole a =
    exp(-2 pi BROADBAND_HP_HZ dt) and sqrt((1 + a) / 2) (c[_C_BBA], c[_C_BBQ]). Its caller finds them once for
    each interval (a loop's reads share one or two): their exponentials cost more than the rest of the frame's
    noise."""
    a, root = broadband_gains(dt)
    return 1.0 - math.exp(-dt / c[_C_A_DELAY]), 1.0 - math.exp(-dt / c[_C_G_DELAY]), a, root


def broadband_gains(dt: float) -> tuple[float, float]:
    """The broadband noise's high-pass over a read interval dt: its pole a = exp(-2 pi BROADBAND_HP_HZ dt) and
    sqrt((1 + a) / 2) (`read_gains`' last two)."""
    a = math.exp(-_TAU * BROADBAND_HP_HZ * dt)
    return a, math.sqrt(0.5 * (1.0 + a))


def chip_frame(regs, s, c, e, i, fx, fy, fz, p, q, r, f1, f2, f3, f4, w1, w2, w3, w4, held, dt, temp, started):
    """The MPU-9250's burst registers (ACCEL_XOUT_H on, big-endian int16) for the true specific force
    (fx, fy, fz) and rates (p, q, r) at time t, dt after the last read, `held` = t % c[_C_PERIOD] s after
    the chip's last output sample (the caller's: the batch finds it once a period for all its vehicles),
    the rotors' thrusts f and speeds w, the die at temp (degC), with the chip's state s and constants c
    (`SimMpu9250`; `started`: not the first read) and `normals_per_read(c)` standard normal numbers
    from e[i]:

    - the DLPF's first-order stage on the rigid-body signals (gains c[_C_KA], c[_C_KG] for dt: the caller's
      `read_gains`, as the broadband high-pass's c[_C_BBA], c[_C_BBQ]);
    - the zero-rate offset's random walk, variance K^2 dt over the time since the last sample;
    - the offsets and their temperature slopes, the chip's white noise per sample, the rotors'
      vibration, and on the gyro the frame's broadband noise in proportion to the rotors' thrust,
      through a first-order high-pass at BROADBAND_HP_HZ (its rms per read kept: the gain
      sqrt((1 + a) / 2) / a undoes the filter's a^2 2 / (1 + a) on white noise).

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
        vx, vy, vz, vp, vq, vr = vibration(s, c, f1, f2, f3, f4, w1, w2, w3, w4, held, dt)
        fx, fy, fz, p, q, r = fx + vx, fy + vy, fz + vz, p + vp, q + vq, r + vr
    a_lsb, g_lsb, sa, sg = c[_C_A_LSB], c[_C_G_LSB], c[_C_SA], c[_C_SG]
    if c[_C_BB] != 0.0 and dt > 0.0:          # the frame's broadband rate noise, rms per read, high-passed
        a, root = c[_C_BBA], c[_C_BBQ]       # (`read_gains` of dt)
        gain = root / a
        if gain != s[_S_BBG]:   # another read interval (a late or stalled loop): the low-pass part held
            if s[_S_BBG] != 0.0:    # in the new gain's units, or a gap of many periods (gain ~ 1/a) would
                k = gain / s[_S_BBG]   # leave it 1/a too large, and the next read's noise at full scale
                s[_S_BB] *= k
                s[_S_BB + 1] *= k
                s[_S_BB + 2] *= k
            s[_S_BBG] = gain
        bb = c[_C_BB] * (f1 + f2 + f3 + f4) * root / a
        b = 1.0 - a
        x = bb * e[i + 9]
        s[_S_BB] = a * s[_S_BB] + b * x
        p += x - s[_S_BB]
        x = bb * e[i + 10]
        s[_S_BB + 1] = a * s[_S_BB + 1] + b * x
        q += x - s[_S_BB + 1]
        x = c[_C_YAW] * bb * e[i + 11]
        s[_S_BB + 2] = a * s[_S_BB + 2] + b * x
        r += x - s[_S_BB + 2]
    put16(regs, _BURST, (fx + c[_C_A0] + c[_C_AC] * d + sa * e[i]) * a_lsb)
    put16(regs, _BURST + 2, (fy + c[_C_A0 + 1] + c[_C_AC + 1] * d + sa * e[i + 1]) * a_lsb)
    put16(regs, _BURST + 4, (fz + c[_C_A0 + 2] + c[_C_AC + 2] * d + sa * e[i + 2]) * a_lsb)
    put16(regs, _BURST + 6, (temp - reg.TEMP_OFFSET_C) * reg.TEMP_LSB_PER_C)
    put16(regs, _BURST + 8, (p + c[_C_G0] + s[_S_WALK] + c[_C_GC] * d + sg * e[i + 3]) * g_lsb)
    put16(regs, _BURST + 10, (q + c[_C_G0 + 1] + s[_S_WALK + 1] + c[_C_GC + 1] * d + sg * e[i + 4]) * g_lsb)
    put16(regs, _BURST + 12, (r + c[_C_G0 + 2] + s[_S_WALK + 2] + c[_C_GC + 2] * d + sg * e[i + 5]) * g_lsb)


def vibration(s, c, f1, f2, f3, f4, w1, w2, w3, w4, held, dt):
    """The rotors' vibration in the output registers: (ax, ay, az) m/s^2 and (p, q, r) rad/s. Each
    rotor's speed from its thrust (eq. 27, so a rotor lag is followed), lines at 1, 2 and 3 times it
    (c[_C_H2], c[_C_H3] of the 1/rev), the amplitude in proportion to the thrust, taken at the chip's
    last output sample (SMPLRT_DIV) and through each sensor's DLPF as a first-order low-pass with the
    register map's bandwidth and delay; each rotor's angle advances in s. On the accelerometer the
    imbalance force turns with the rotor in x-y (eq. 9's sense) and bends its arm in z; on the gyro
    the bending arm rocks the frame in roll and pitch (and yaw, by c[_C_YAWL]), with each arm's phase;
    `held`: s since the last output sample."""
    kv, kg, tc2, tg2 = c[_C_KV], c[_C_KVG], c[_C_TC2], c[_C_TCG2]
    h2, h3, yaw = c[_C_H2], c[_C_H3], c[_C_YAWL]
    back_a, back_g = held + c[_C_A_DELAY], held + c[_C_G_DELAY]   # how long ago each entered its register
    vx = vy = vz = vp = vq = vr = 0.0
    thrusts, speeds = (f1, f2, f3, f4), (w1, w2, w3, w4)
    for j in range(4):
        fi, om = thrusts[j], speeds[j]
        if fi > 0.0:
            th = s[_S_PHASE + j] = remainder(s[_S_PHASE + j] + om * dt, _TAU)
            zc, zs, spin = c[_C_ZC + j], c[_C_ZS + j], SPIN[j]
            for sensor in range(2):
                k0, t2 = (kv, tc2) if sensor == 0 else (kg, tg2)
                if k0 == 0.0:
                    continue
                a = th - om * (back_a if sensor == 0 else back_g)
                s1, c1 = sincos(a)
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


# `sincos`'s constants, fdlibm's (Sun Microsystems, 1993: "permission to use, copy, modify, and distribute this
# software is freely granted"; as in musl's src/math/__sin.c, __cos.c, __rem_pio2.c): the minimax polynomials of
# sin and cos on [-pi/4, pi/4]; 2/pi; pi/2 in two parts, its first 33 bits (n pi/2 exact for |n| < 2^20) and the rest
_S1, _S2, _S3, _S4, _S5, _S6 = (-1.66666666666666324348e-01, 8.33333333332248946124e-03, -1.98412698298579493134e-04,
                                2.75573137070700676789e-06, -2.50507602534068634195e-08, 1.58969099521155010221e-10)
_K1, _K2, _K3, _K4, _K5, _K6 = (4.16666666666666019037e-02, -1.38888888888741095749e-03, 2.48015872894767294178e-05,
                                -2.75573143513906633035e-07, 2.08757232129817482790e-09, -1.13596475577881948265e-11)
_INV_PIO2, _PIO2_HI, _PIO2_LO = 6.36619772367581382433e-01, 1.57079632673412561417e+00, 6.07710050650619224932e-11


def sincos(x: float) -> tuple[float, float]:
    """(sin x, cos x) of a rotor line's angle, within 2^-52 of libm's for |x| < 1e5 (tests/sim/world/test_compiled.py),
    in arithmetic alone: fdlibm's scheme, x less the nearest multiple n of pi/2 (Cody and Waite), the
    polynomials there, n's quadrant choosing and signing them without a branch. The vibration's eight
    angles a read (up to tens of radians, each quadrant a coin toss for a branch predictor) took a fifth of
    the batched simulator's time through libm's calls (docs/batch.md); the plant's attitude, small
    angles, keeps libm's."""
    if not abs(x) < 1e5:                  # (n pi/2's parts no longer exact; an infinity, a NaN): libm's
        return math.sin(x), math.cos(x)
    n = math.floor(x * _INV_PIO2 + 0.5)
    y = (x - n * _PIO2_HI) - n * _PIO2_LO
    z = y * y
    s = y + z * y * (_S1 + z * (_S2 + z * (_S3 + z * (_S4 + z * (_S5 + z * _S6)))))
    hz = 0.5 * z
    w = 1.0 - hz
    c = w + (((1.0 - w) - hz) + z * z * (_K1 + z * (_K2 + z * (_K3 + z * (_K4 + z * (_K5 + z * _K6))))))
    q = int(n) & 3
    o = float(q & 1)                      # an odd quadrant swaps the two (a product by 0 or 1 is exact)
    e = 1.0 - o
    return (1.0 - 2.0 * (q >> 1)) * (s * e + c * o), (1.0 - 2.0 * (((q + 1) >> 1) & 1)) * (c * e + s * o)


def put16(regs, at: int, v: float) -> None:
    """v rounded to a big-endian int16 (`_i16`) at regs[at], regs[at + 1]."""
    v = _i16(v) & 0xFFFF
    regs[at] = v >> 8
    regs[at + 1] = v & 0xFF


@functools.cache
def chip_frame_compiled(put=None):
    """`chip_frame` compiled (sim/world/compiled.py), or None. `put`: a plain function in place of
    `put16` (the batched simulator's `flight.put_word`, into a float array: a signature of its own,
    so that numba's cache, which keys a function's copies by their argument types, keeps both)."""
    from flightctl.sim.world import compiled
    if not compiled.enabled():
        return None
    c = compiled.compiled_copy
    frame = c(chip_frame, vibration=c(vibration, remainder=c(remainder), sincos=c(sincos)), put16=c(put or put16, _i16=c(_i16)))
    if put is not None:
        return frame
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
    r = int(abs(v) + 0.5)                 # (|v| + 0.5 is 0.5 - v below zero, to the bit: no branch on the sign's
    return r if v >= 0.0 else -r          # rounding, which noise around zero would mispredict)
