"""Reading a flight log for diagnose: one file reduced to per-row arrays (commands, gyro,
accelerometer, battery, levelled range altitude, the attitude from the integrated gyro) and the mask
of its usable airborne rows (docs/diagnose.md, "Only airborne data are used")."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from flightctl.logfile import Table
from flightctl.params import Airframe
from flightctl.physics import thrust_from_command

Z_AIRBORNE = 0.10        # m: below this the legs may touch and the range is near its 2 cm limit
EDGE_S = 0.1             # s trimmed at both ends of each airborne stretch
MIN_STRETCH_S = 0.5      # s: shorter airborne stretches are dropped
RANGE_GAP_S = 0.25       # s: a range older than this does not give the altitude
MOTOR_ON_MARGIN = 1.0    # P units above the dead zone h2 for a motor to count as running
IMU_COLUMNS = ("gyro_x", "gyro_y", "gyro_z", "acc_x", "acc_y", "acc_z")


@dataclass
class FileData:
    """One flight log reduced to what the fits need, every array over rows of the file."""
    path: str
    t: np.ndarray
    P: np.ndarray           # (4, n) commands
    gyro: np.ndarray        # (3, n)
    acc: np.ndarray         # (3, n)
    battery_v: np.ndarray   # (n,), NaN where unknown
    z: np.ndarray           # (n,) altitude from the range, NaN where unknown
    Rm: np.ndarray          # (9, n) attitude from the integrated gyro
    airborne: np.ndarray    # (n,) bool, for input rows k whose pair (k, k+1) is usable
    notes: list[str] = field(default_factory=list)


def _rotations(t, gyro, R0):
    """Integrate the gyro (body rates) into body-to-inertial rotations: R_{k+1} = R_k exp([w_k dt]x)."""
    n = t.size
    out = np.empty((9, n))
    r = [float(v) for v in R0.ravel()]
    dts = np.diff(t, append=t[-1])
    gx, gy, gz = gyro.tolist()
    dl = dts.tolist()
    o0, o1, o2, o3, o4, o5, o6, o7, o8 = ([0.0] * n for _ in range(9))
    cols = (o0, o1, o2, o3, o4, o5, o6, o7, o8)
    for k in range(n):
        for j in range(9):
            cols[j][k] = r[j]
        wx, wy, wz = gx[k] * dl[k], gy[k] * dl[k], gz[k] * dl[k]
        a2 = wx * wx + wy * wy + wz * wz
        if a2 < 1e-8:
            s, c = 1.0 - a2 / 6.0, 0.5 - a2 / 24.0
        else:
            a = math.sqrt(a2)
            s, c = math.sin(a) / a, (1.0 - math.cos(a)) / a2
        # Rodrigues: E = I + s W + c W^2, W = [w]x
        e00 = 1.0 - c * (wy * wy + wz * wz)
        e11 = 1.0 - c * (wx * wx + wz * wz)
        e22 = 1.0 - c * (wx * wx + wy * wy)
        e01 = -s * wz + c * wx * wy
        e10 = s * wz + c * wx * wy
        e02 = s * wy + c * wx * wz
        e20 = -s * wy + c * wx * wz
        e12 = -s * wx + c * wy * wz
        e21 = s * wx + c * wy * wz
        r = [r[0] * e00 + r[1] * e10 + r[2] * e20, r[0] * e01 + r[1] * e11 + r[2] * e21,
             r[0] * e02 + r[1] * e12 + r[2] * e22,
             r[3] * e00 + r[4] * e10 + r[5] * e20, r[3] * e01 + r[4] * e11 + r[5] * e21,
             r[3] * e02 + r[4] * e12 + r[5] * e22,
             r[6] * e00 + r[7] * e10 + r[8] * e20, r[6] * e01 + r[7] * e11 + r[8] * e21,
             r[6] * e02 + r[7] * e12 + r[8] * e22]
    for j in range(9):
        out[j] = cols[j]
    return out


def _tilt_rotation(acc_mean):
    """R = Ry(theta) Rx(phi) from the accelerometer at rest (eq. 30-31), yaw 0."""
    ax, ay, az = acc_mean
    phi, theta = math.atan2(ay, az), math.atan2(-ax, math.hypot(ay, az))
    cf, sf, ct, st = math.cos(phi), math.sin(phi), math.cos(theta), math.sin(theta)
    return np.array([[ct, st * sf, st * cf], [0.0, cf, -sf], [-st, ct * sf, ct * cf]])


def stretches(mask):
    """(start, stop) index pairs of the runs of True in a boolean array."""
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1)))


def motors_on(P: np.ndarray, a: Airframe) -> np.ndarray:
    """(n,) bool: some motor runs above its dead zone (eq. 26) on that row."""
    return (P > a.h2 + MOTOR_ON_MARGIN).any(axis=0)


def _check_columns(table: Table, P: np.ndarray, a: Airframe) -> None:
    """Refuse what would give a confident verdict from no measurement: a sensor column that never
    changes (a dead or unlogged sensor; a real IMU always reads noise), and a motor whose command
    never leaves the dead zone while the others fly (the quadcopter cannot fly so: not logged)."""
    for name in IMU_COLUMNS:
        x = table[name]
        if np.ptp(x) == 0:
            table.fail(f"{x[0]:g} on every row: a dead or unlogged sensor cannot be judged", column=name)
    running = P > a.h2 + MOTOR_ON_MARGIN
    if running.any():
        for i in np.flatnonzero(~running.any(axis=1)):
            table.fail(f"motor {i + 1} never runs (P at most {P[i].max():g}, its dead zone h2 = {a.h2:g}) "
                       "while the others do: its command was not logged", column=f"P{i + 1}")


def load_file(table: Table, a: Airframe) -> FileData:
    """The arrays of one flight log (already read and checked by `flightctl.logfile`)."""
    t = table["t"]
    n = t.size
    P = np.vstack([table[f"P{i}"] for i in range(1, 5)])
    gyro = np.vstack([table[c] for c in ("gyro_x", "gyro_y", "gyro_z")])
    acc = np.vstack([table[c] for c in ("acc_x", "acc_y", "acc_z")])
    notes = []
    on = motors_on(P, a)
    _check_columns(table, P, a)
    # at rest before the first take-off: the initial tilt
    first_on = int(np.argmax(on)) if on.any() else n
    still = slice(0, first_on)
    if first_on >= 20:
        # the gyro is calibrated by contract (bias removed): only the initial tilt is taken here
        R0 = _tilt_rotation(acc[:, still].mean(axis=1))
    else:
        notes.append("no rest before the motors start: initial tilt taken as zero")
        R0 = np.eye(3)
    # attitude: the gyro integrated from the first motor start (at rest before it: R0)
    Rm = np.empty((9, n))
    Rm[:, :first_on] = R0.reshape(9, 1)
    if first_on < n:
        Rm[:, first_on:] = _rotations(t[first_on:], gyro[:, first_on:], R0)
    rng = table["range"]
    have = np.isfinite(rng)
    z = np.full(n, np.nan)
    if have.sum() >= 2:
        tr = t[have]
        zr = rng[have] * Rm[8, have]          # along -z_b, levelled by cos(phi) cos(theta)
        z = np.interp(t, tr, zr)
        idx = np.clip(np.searchsorted(tr, t), 1, tr.size - 1)
        gap = np.minimum(np.abs(t - tr[idx - 1]), np.abs(tr[idx] - t))
        z[gap > RANGE_GAP_S] = np.nan
    bv = table["battery_v"].copy()
    if np.isfinite(bv).sum() >= 2:
        ok = np.isfinite(bv)
        bv = np.interp(t, t[ok], bv[ok])
    if np.isfinite(z).any():
        up = on & (np.nan_to_num(z, nan=-1.0) > Z_AIRBORNE)
    else:
        notes.append("no range readings: airborne taken as motors running with thrust above 90 % of the weight")
        f = thrust_from_command(P, a.h1, a.h2).sum(axis=0)
        up = on & (f > 0.9 * a.M * a.g)
    # a usable input row k needs rows k and k+1 airborne; trim the stretch edges; drop short ones
    pair = np.zeros(n, bool)
    pair[:-1] = up[:-1] & up[1:]
    dt_nom = float(np.median(np.diff(t)))
    edge = int(round(EDGE_S / dt_nom))
    keep = np.zeros(n, bool)
    for i0, i1 in stretches(pair):
        i0, i1 = i0 + edge, i1 - edge
        if (i1 - i0) * dt_nom >= MIN_STRETCH_S:
            keep[i0:i1] = True
    return FileData(table.path, t, P, gyro, acc, bv, z, Rm, keep, notes)


