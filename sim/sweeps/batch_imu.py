"""The batched simulator's IMU: one simulated MPU-9250 per vehicle, each the single simulator's own chip
(`sim/world/imu.py`: `chip_die` builds it, `chip_frame` writes its burst registers: the DLPF stage,
the bias walk, the offsets and their temperature slopes, the white and broadband noise, the rotors'
vibration lines, aliased at the chip's output rate), configured by the real driver's register writes
(a template chip), read as the driver decodes a burst (each int16 word times its LSB), and the
calibration of section 4.4.4 on the floor before the flight (`calibrate`: the loop's `Calibration`).

One equation, one copy: `chip_frame` runs here as in the single simulator, compiled (numba, the `fast`
extra: `chip_frame_compiled`, looped over the vehicles in `read_all`, itself compiled with its call
bound to the compiled chip) or, without numba, in plain Python over the vehicles (slow; correct).
"""
from __future__ import annotations

import dataclasses
import functools
import random

import numpy as np

from flightctl.drivers import mpu9250_regs as reg
from flightctl.drivers.mpu9250 import Mpu9250
from flightctl.sim.world import imu
from flightctl.sim.world.devices import SensorNoise, World, vehicle_noise
from flightctl.sim.world.imu import N_CHIP_CONST, N_CHIP_STATE, SimMpu9250, chip_die, chip_frame

_BURST = reg.ACCEL_XOUT_H
# the constants the driver's register writes set (`SimMpu9250._configure`): taken from the template chip
_REGISTERED = (imu._C_A_LSB, imu._C_G_LSB, imu._C_SA, imu._C_SG, imu._C_TC2, imu._C_PERIOD,
               imu._C_A_DELAY, imu._C_TCG2, imu._C_G_DELAY)


def _word(regs, at: int) -> float:
    """The big-endian int16 at regs[at] (the driver's `>h`)."""
    v = regs[at] * 256 + regs[at + 1]
    return float(v - 65536 if v >= 32768 else v)


def read_all(regs, s, c, e, fx, fy, fz, p, q, r, f, w, t, dt, temp, started, out):
    """Every vehicle's chip read once: `chip_frame` on its registers regs[k], state s[k], constants
    c[k] and nine normals e[k], then its six words decoded into out[:, k] (ax, ay, az, gx, gy, gz in
    SI: the word over the chip's LSB per unit, as the driver's scale). f, w: (4, N) thrusts, speeds."""
    for k in range(s.shape[0]):
        chip_frame(regs[k], s[k], c[k], e[k], 0, fx[k], fy[k], fz[k], p[k], q[k], r[k], f[0, k], f[1, k], f[2, k],
                   f[3, k], w[0, k], w[1, k], w[2, k], w[3, k], t, dt, temp, started)
        ck, rk = c[k], regs[k]
        a_lsb, g_lsb = ck[imu._C_A_LSB], ck[imu._C_G_LSB]
        out[0, k] = _word(rk, _BURST) / a_lsb
        out[1, k] = _word(rk, _BURST + 2) / a_lsb
        out[2, k] = _word(rk, _BURST + 4) / a_lsb
        out[3, k] = _word(rk, _BURST + 8) / g_lsb
        out[4, k] = _word(rk, _BURST + 10) / g_lsb
        out[5, k] = _word(rk, _BURST + 12) / g_lsb


@functools.cache
def _compiled_read_all():
    """`read_all` compiled with `chip_frame`'s compiled copy, or None without numba."""
    from flightctl.sim.world import compiled
    frame = imu.chip_frame_compiled()
    if frame is None:
        return None
    return compiled.compiled_copy(read_all, chip_frame=frame, _word=compiled.compiled_copy(_word))


class BatchImu:
    """N chips, one per vehicle: each vehicle's own die (`chip_die` with its own seeded generator) and
    its own vibration (`sensors`: the parameter file's [sensors]; `drawn`: name -> (N,) array of the
    values drawn per vehicle)."""

    def __init__(self, airframe, sensors, n: int, drawn: dict | None = None, seed: int = 0,
                 noise: SensorNoise | None = None):
        noise = noise if noise is not None else SensorNoise()
        template = World(airframe, noise=noise, seed=seed)
        chip = SimMpu9250(template)
        Mpu9250(chip, sleep=lambda s: None, frozen_frames=0).start()   # the driver's configuration
        self.die_temperature = chip.die_temperature
        c0 = np.asarray(chip._c, dtype=float)
        self.n = n
        self.s = np.zeros((n, N_CHIP_STATE))
        self.c = np.zeros((n, N_CHIP_CONST))
        B = airframe.M * airframe.g / 4.0
        for k in range(n):
            row = {name: float(np.broadcast_to(v, (n,))[k]) for name, v in (drawn or {}).items()}
            vib = vehicle_noise(noise, dataclasses.replace(sensors, **row))
            s, c = chip_die(vib, airframe, random.Random(seed * 1000003 + k))
            self.s[k], self.c[k] = s, c
        self.c[:, _REGISTERED] = c0[list(_REGISTERED)]
        self.B = B
        self.regs = np.zeros((n, 128), dtype=np.uint8)
        self.out = np.zeros((6, n))
        self.rng = np.random.default_rng(seed)
        self._dt = None
        self._started = False
        self._t_last = 0.0
        fast = _compiled_read_all()
        self._read = fast if fast is not None else read_all
        self.gyro_bias = np.zeros((3, n))
        self.tilt_bias = (np.zeros(n), np.zeros(n))

    def read(self, t: float, fx, fy, fz, p, q, r, f, w) -> np.ndarray:
        """The decoded (6, N) readings at time t (s since power-on) of the true specific force and
        rates and the rotors' thrusts and speeds (4, N), the gyro less the calibration's bias."""
        dt, self._t_last = t - self._t_last, t
        c = self.c
        if dt > 0.0 and dt != self._dt:   # the DLPF stage's gains for this read interval
            self._dt = dt
            c[:, imu._C_KA] = 1.0 - np.exp(-dt / c[:, imu._C_A_DELAY])
            c[:, imu._C_KG] = 1.0 - np.exp(-dt / c[:, imu._C_G_DELAY])
        e = self.rng.standard_normal((self.n, 9))
        col = lambda v: np.ascontiguousarray(np.broadcast_to(np.asarray(v, dtype=float), (self.n,)))   # noqa: E731
        self._read(self.regs, self.s, c, e, col(fx), col(fy), col(fz), col(p), col(q), col(r),
                   np.ascontiguousarray(f, dtype=float), np.ascontiguousarray(w, dtype=float), t, dt,
                   self.die_temperature(t), self._started, self.out)
        self._started = True
        out = self.out.copy()
        out[3:] -= self.gyro_bias
        return out

    def calibrate(self, seconds: float, dt: float, g: float) -> None:
        """Section 4.4.4 on the floor, motors stopped (the loop's `Calibration`): `seconds` of reads at
        rest, their mean gyro the bias subtracted from now on, their mean accelerometer angles the
        estimator's tilt biases."""
        n, zero = self.n, np.zeros(self.n)
        rotors = np.zeros((4, n))
        sums, count = np.zeros((5, n)), 0
        for k in range(1, int(round(seconds / dt)) + 1):
            out = self.read(k * dt, zero, zero, g, zero, zero, zero, rotors, rotors)
            roll, pitch = _tilt(out[0], out[1], out[2])
            sums += np.array([out[3], out[4], out[5], roll, pitch])
            count += 1
        self.gyro_bias = sums[:3] / count
        self.tilt_bias = (sums[3] / count, sums[4] / count)


def _tilt(ax, ay, az):
    """Eq. 30-31 (`flightctl.control.estimator.tilt_from_accel`) on arrays."""
    return np.arctan2(ay, az), np.arctan2(-ax, np.sqrt(ay * ay + az * az))
