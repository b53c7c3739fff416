"""`flightctl diagnose`: name what the base model gets wrong in flight logs, from the logs alone.

The method (docs/diagnose.md):

1. **Equation error, one loop period ahead.** The vehicle is open-loop unstable, so the model is not
   replayed over long horizons; it predicts, from the logged commands, what the sensors show over
   each loop period: the angular acceleration (the differenced gyro, eq. 7 with the torques of eq.
   25-28 and the yaw drag of eq. 6) and the specific force (accelerometer, sum f / M along z_b). The
   command logged on row k acts until row k+1 (zero-order hold), so it is paired with the gyro
   difference between rows k and k+1 and with the accelerometer on row k+1. Measured and predicted
   channels go through the same zero-phase low-pass (their difference is filtered once), which
   takes out sensor noise without moving one against the other in time.
2. **Candidates.** Each extension of measured-data.md changes the prediction; its parameters are
   fitted by a 1-D grid (motor_lag, actuation_delay, ground_effect, rotor_drag, each refined on the
   full data by a bounded scalar search) or by weighted linear least squares (battery_sag in
   1/v_nominal^2, linear_yaw_drag, com_offset, motor_weak per motor).
3. **Held-out score.** The airborne data are cut into `N_BLOCKS` contiguous blocks; for each block
   the parameters are fitted on the others and the block is predicted. `rmse_*` is the geometric
   mean over the channels of the held-out RMSE (so `1 - rmse_extended / rmse_base` is the geometric
   mean of the per-channel ratios, a Gaussian log-likelihood ratio with one variance per channel,
   which no choice of channel units can tilt).
4. **Significance.** A cause is named only if its held-out gain is at least `MIN_GAIN` and it beats
   the base model on the blocks by `T_CRIT` standard errors of the per-block log-likelihood gains
   (see `significance`); else `none`.

Accelerometer channels carry one constant offset each (the accelerometer bias is not calibrated
away in flight), fitted on the training blocks, for the base model and every candidate alike. The
angular channels carry none: a constant angular-acceleration offset is what com_offset explains.
"""
from __future__ import annotations

import math
import sys
from dataclasses import dataclass, field

import numpy as np
from scipy import optimize, signal

from flightctl.errors import InputError
from flightctl.logfile import Table
from flightctl.params import Airframe
from flightctl.sim.model import angular_acceleration, body_torques, rotor_torque, thrust_from_command, yaw_drag

CHANNELS = ("p_dot", "q_dot", "r_dot", "acc_x", "acc_y", "acc_z")
UNITS = ("rad/s^2", "rad/s^2", "rad/s^2", "m/s^2", "m/s^2", "m/s^2")
OFFSET = np.array([False, False, False, True, True, True])   # channels with a bias nuisance
C = len(CHANNELS)
CAUSES = ("motor_lag", "actuation_delay", "ground_effect", "battery_sag", "linear_yaw_drag",
          "rotor_drag", "com_offset", "motor_weak")

LOWPASS_HZ = 12.0        # zero-phase low-pass applied to every residual (2nd-order Butterworth, twice)
N_BLOCKS = 8             # blocked cross-validation
MIN_GAIN = 0.01          # effect-size floor on the held-out gain (docs/diagnose.md)
T_CRIT = 3.0             # Diebold-Mariano t on the held-out loss differential (docs/diagnose.md)
MIN_TIMING_PERIODS = 1.5  # lag or delay shorter than this many loop periods is not named
DM_WINDOW_S = 1.0        # s: windows of the loss differential for that test (at most; at least
DM_MIN_WINDOWS = 30      # this many windows, each no shorter than 0.1 s)
Z_AIRBORNE = 0.10        # m: below this the legs may touch and the range is near its 2 cm limit
EDGE_S = 0.1             # s trimmed at both ends of each airborne stretch
MIN_STRETCH_S = 0.5      # s: shorter airborne stretches are dropped
MIN_AIRBORNE_S = 1.0     # s of airborne data needed in total to judge anything
RANGE_GAP_S = 0.25       # s: a range older than this does not give the altitude
MOTOR_ON_MARGIN = 1.0    # P units above the dead zone h2 for a motor to count as running
GE_MAX_Z = 0.6           # m: ground effect is judged only with airborne time below this
GE_MIN_S = 1.0           # s of it
SAG_MIN_SPAN = 0.01      # battery_sag needs the voltage to vary by 1 % (5th to 95th percentile)
YAW_MIN_RATE = 0.2       # rad/s: linear_yaw_drag needs yaw rates at least this (95th percentile)


def say(*args) -> None:
    print("diagnose:", *args, file=sys.stderr, flush=True)


# --------------------------------------------------------------------------------------------
# Data: one file -> airborne stretches of paired input/measurement samples


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


def _stretches(mask):
    """(start, stop) index pairs of the runs of True in a boolean array."""
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1)))


def load_file(table: Table, a: Airframe) -> FileData:
    t = table["t"]
    n = t.size
    P = np.vstack([table[f"P{i}"] for i in range(1, 5)])
    gyro = np.vstack([table[c] for c in ("gyro_x", "gyro_y", "gyro_z")])
    acc = np.vstack([table[c] for c in ("acc_x", "acc_y", "acc_z")])
    notes = []
    on = (P > a.h2 + MOTOR_ON_MARGIN).any(axis=0)
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
    for i0, i1 in _stretches(pair):
        i0, i1 = i0 + edge, i1 - edge
        if (i1 - i0) * dt_nom >= MIN_STRETCH_S:
            keep[i0:i1] = True
    return FileData(table.path, t, P, gyro, acc, bv, z, Rm, keep, notes)


# --------------------------------------------------------------------------------------------
# The data set: every airborne stretch of every file, flattened; per-file arrays kept for the
# candidates that need history (lag, delay, the velocity filter of rotor_drag)


class DataSet:
    def __init__(self, files: list[FileData], a: Airframe, lowpass_hz: float = LOWPASS_HZ):
        self.files, self.a = files, a
        self.fs = 1.0 / float(np.median(np.concatenate([np.diff(f.t) for f in files])))
        self.sos = signal.butter(2, lowpass_hz, fs=self.fs, output="sos")
        # the stretches: (file index, start, stop) of input rows
        self.stretches = [(i, s0, s1) for i, f in enumerate(files) for s0, s1 in _stretches(f.airborne)]
        self.n = sum(s1 - s0 for _, s0, s1 in self.stretches)
        self.seconds = self.n / self.fs
        self.F = [thrust_from_command(f.P, a.h1, a.h2) for f in files]          # eq. 26, (4, n) each
        # measured channels per file (row k: gyro difference k -> k+1, accelerometer at k+1)
        self.meas, self.wmid = [], []
        for f in files:
            dt = np.diff(f.t)
            m = np.zeros((C, f.t.size))
            m[0:3, :-1] = np.diff(f.gyro, axis=1) / dt
            m[3:6, :-1] = f.acc[:, 1:]
            w = np.zeros((3, f.t.size))
            w[:, :-1] = 0.5 * (f.gyro[:, :-1] + f.gyro[:, 1:])
            self.meas.append(m)
            self.wmid.append(w)
        self.base_pred = [self.predict_file(i, self.F[i]) for i in range(len(files))]
        self.r_base = self.flat_filtered([m - p for m, p in zip(self.meas, self.base_pred)])
        self.V = self.flat([f.battery_v for f in files])
        self.z = self.flat([f.z for f in files])
        self.w = self.flat(self.wmid)
        self.thrust = self.flat(self.F)
        self.time = self.flat([f.t for f in files])
        self.file_index = np.concatenate([np.full(s1 - s0, i) for i, s0, s1 in self.stretches])
        edges = np.linspace(0, self.n, N_BLOCKS + 1).round().astype(int)
        self.block = np.zeros(self.n, int)
        for b in range(N_BLOCKS):
            self.block[edges[b]:edges[b + 1]] = b
        self.block_edges = list(zip(edges[:-1], edges[1:]))
        self.block_counts = np.diff(edges).astype(float)

    # -- helpers over stretches
    def flat(self, per_file):
        return np.concatenate([per_file[i][..., s0:s1] for i, s0, s1 in self.stretches], axis=-1)

    def flat_filtered(self, per_file):
        """The stretches of per-file (C, n) arrays, each stretch low-passed forward and backward."""
        parts = []
        for i, s0, s1 in self.stretches:
            x = per_file[i][..., s0:s1]
            parts.append(signal.sosfiltfilt(self.sos, x, axis=-1))
        return np.concatenate(parts, axis=-1)

    def predict_file(self, i, F, scale=None, torque_extra=None, force_extra=None):
        """The model's channels for file i from per-rotor thrusts F (4, n) (eq. 7, 25-28, 6, 9).
        `scale` (4, n) multiplies thrust and torque of each rotor; `torque_extra` (3, n) and
        `force_extra` (2, n) add a body wrench."""
        a = self.a
        tq = rotor_torque(F, a.g1, a.g2)                                       # eq. 28
        if scale is not None:
            F, tq = F * scale, tq * scale
        tphi, ttheta, tpsi = body_torques(*F, *tq, a.l)                        # "+" layout, eq. 25
        if torque_extra is not None:
            tphi, ttheta, tpsi = tphi + torque_extra[0], ttheta + torque_extra[1], tpsi + torque_extra[2]
        w = np.sqrt(F / a.c1)                                                   # eq. 27
        Omega = -w[0] + w[1] - w[2] + w[3]                                     # eq. 9
        p, q, r = self.wmid[i]
        tau_d = yaw_drag(r, a.gamma1, 0.0)                                      # eq. 6, gamma2 = 0 in flight
        out = np.zeros((C, F.shape[1]))
        out[0], out[1], out[2] = angular_acceleration(p, q, r, tphi, ttheta, tpsi, Omega, tau_d, a)  # eq. 7
        out[5] = F.sum(axis=0) / a.M
        if force_extra is not None:
            out[3], out[4] = force_extra[0] / a.M, force_extra[1] / a.M
        return out

    def delta_filtered(self, per_file_pred):
        """Filtered change of the prediction against the base model, flattened: D = L(pred - base)."""
        return self.flat_filtered([p - b for p, b in zip(per_file_pred, self.base_pred)])

    def thrust_columns(self, i, F=None):
        """Per-file (4, C, n): the part of the channels proportional to each rotor's thrust and torque."""
        a = self.a
        F = self.F[i] if F is None else F
        tq = rotor_torque(F, a.g1, a.g2)
        G = np.zeros((4, C, F.shape[1]))
        G[0, 1], G[2, 1] = -a.l * F[0] / a.Jyy, a.l * F[2] / a.Jyy
        G[1, 0], G[3, 0] = a.l * F[1] / a.Jxx, -a.l * F[3] / a.Jxx
        for m, sgn in enumerate((1.0, -1.0, 1.0, -1.0)):
            G[m, 2] = sgn * tq[m] / a.Jzz
            G[m, 5] = F[m] / a.M
        return G


# --------------------------------------------------------------------------------------------
# Scoring


def _rss(res, mask, offsets=None):
    """Per-channel residual sum of squares over `mask`; offset channels centred by `offsets`."""
    r = res[:, mask]
    if offsets is not None:
        r = r - offsets[:, None]
    return np.einsum("cn,cn->c", r, r)


def _offsets(res, mask):
    m = np.zeros(C)
    m[OFFSET] = res[OFFSET][:, mask].mean(axis=1)
    return m


def block_stats(ds: "DataSet", res):
    """(2, B, C): per block and channel, the sum and the sum of squares of a residual."""
    out = np.zeros((2, N_BLOCKS, C))
    for b, (i0, i1) in enumerate(ds.block_edges):
        r = res[:, i0:i1]
        out[0, b] = r.sum(axis=1)
        out[1, b] = np.einsum("cn,cn->c", r, r)
    return out


def stats_objective(st, test_block, counts):
    """`objective` on all blocks but one, from `block_stats` and the samples per block."""
    keep = np.arange(N_BLOCKS) != test_block
    n = counts[keep].sum()
    s1, s2 = st[0, keep].sum(axis=0), st[1, keep].sum(axis=0)
    rss = s2 - np.where(OFFSET, s1 * s1 / n, 0.0)
    return float(np.log(np.maximum(rss, 1e-300)).sum())



def objective(res, mask):
    """Gaussian log-likelihood with one variance per channel (up to constants): sum_c log RSS_c."""
    return float(np.log(_rss(res, mask, _offsets(res, mask)) + 1e-300).sum())


@dataclass
class Score:
    rss: np.ndarray          # (N_BLOCKS, C) held-out residual sums of squares
    count: np.ndarray        # (N_BLOCKS,) samples per block
    residual: np.ndarray     # (C, n) held-out residual (each block predicted by the fit on the others)

    def rmse(self):
        return np.sqrt(self.rss.sum(axis=0) / self.count.sum())


def heldout(ds: DataSet, residual_for_fold) -> Score:
    """`residual_for_fold(train_mask) -> (C, n) residual` of the model fitted on train_mask."""
    rss = np.zeros((N_BLOCKS, C))
    count = np.zeros(N_BLOCKS)
    out = np.empty((C, ds.n))
    for b in range(N_BLOCKS):
        test = ds.block == b
        res = residual_for_fold(~test)
        out[:, test] = res[:, test] - _offsets(res, ~test)[:, None]
        rss[b] = np.einsum("cn,cn->c", out[:, test], out[:, test])
        count[b] = test.sum()
    return Score(rss, count, out)


def _num(x, digits=5):
    """A JSON-safe number: non-finite values become None."""
    x = float(x)
    return round(x, digits) if math.isfinite(x) else None


def geomean(x):
    return float(np.exp(np.mean(np.log(x))))


# --------------------------------------------------------------------------------------------
# Candidates


@dataclass
class Result:
    cause: str
    parameters: dict
    score: Score | None = None
    residual: np.ndarray | None = None     # fitted on all data, for the report
    gain: float = float("nan")
    block_gain: np.ndarray | None = None
    t_stat: float = float("nan")
    explains: str = ""                     # the variable that explains the residual
    explanatory: np.ndarray | None = None
    folds: list = field(default_factory=list)


class Candidate:
    cause = ""
    explains = ""

    def __init__(self, ds: DataSet):
        self.ds = ds

    def why_not(self) -> str | None:
        """A reason the data cannot judge this candidate, or None."""
        return None

    def run(self) -> Result:
        raise NotImplementedError

    def explanatory(self) -> np.ndarray | None:
        return None


class GridCandidate(Candidate):
    """One nonlinear parameter: predictions on a grid, folds choose the best grid point (parabolic
    interpolation), the full-data fit is refined by a bounded scalar search."""
    name = ""
    grid: np.ndarray = np.array([])
    round_to = 4

    def residual(self, theta) -> np.ndarray:
        return self.ds.r_base - self.delta(theta)

    def delta(self, theta) -> np.ndarray:
        raise NotImplementedError

    def _best(self, objs):
        j = int(np.argmin(objs))
        g = self.grid
        if 0 < j < len(g) - 1:
            lo, hi = g[j - 1], g[j + 1]
            try:
                res = optimize.minimize_scalar(lambda th: objective(self.residual(th), self._mask),
                                               bounds=(lo, hi), method="bounded",
                                               options={"xatol": (hi - lo) * 1e-3})
                return float(res.x)
            except ValueError:
                return float(g[j])
        return float(g[j])

    def run(self) -> Result:
        ds = self.ds
        deltas = [self.delta(th) for th in self.grid]
        stats = np.stack([block_stats(ds, ds.r_base - d) for d in deltas])    # (J, 2, B, C)
        folds = []

        def fold(train):
            test_block = int(ds.block[~train][0])
            objs = [stats_objective(st, test_block, ds.block_counts) for st in stats]
            j = int(np.argmin(objs))
            folds.append(float(self.grid[j]))
            return ds.r_base - deltas[j]

        score = heldout(ds, fold)
        self._mask = np.ones(ds.n, bool)
        objs = [objective(ds.r_base - d, self._mask) for d in deltas]
        theta = self._best(objs)
        return Result(self.cause, {self.name: round(theta, self.round_to)}, score, self.residual(theta),
                      explains=self.explains, folds=folds)


class AffineCandidate(Candidate):
    """Prediction change D = G0 + sum_p theta_p G_p with filtered columns: weighted least squares,
    each channel weighted by the inverse of its residual variance (two reweighting passes), with
    the offset channels centred on the training data."""
    names: tuple[str, ...] = ()

    def columns(self):
        """(G0 (C, n) or None, [G_p (C, n)])"""
        raise NotImplementedError

    def to_parameters(self, theta) -> dict:
        return {n: float(v) for n, v in zip(self.names, theta)}

    def fit(self, G0, Gs, mask):
        ds = self.ds
        r = ds.r_base[:, mask] - (G0[:, mask] if G0 is not None else 0.0)
        A = np.stack([g[:, mask] for g in Gs], axis=-1)          # (C, n, P)
        r = r - np.where(OFFSET, r.mean(axis=1), 0.0)[:, None]
        A = A - np.where(OFFSET[:, None], A.mean(axis=1), 0.0)[:, None, :]
        w = 1.0 / np.maximum(np.einsum("cn,cn->c", r, r), 1e-300)
        theta = np.zeros(len(Gs))
        for _ in range(3):
            M = np.einsum("c,cnp,cnq->pq", w, A, A)
            h = np.einsum("c,cnp,cn->p", w, A, r)
            theta = np.linalg.lstsq(M, h, rcond=None)[0]
            e = r - A @ theta
            w = 1.0 / np.maximum(np.einsum("cn,cn->c", e, e), 1e-300)
        return theta

    def residual_at(self, G0, Gs, theta):
        res = self.ds.r_base - (G0 if G0 is not None else 0.0)
        for g, th in zip(Gs, theta):
            res = res - th * g
        return res

    def run(self) -> Result:
        ds = self.ds
        G0, Gs = self.columns()
        folds = []

        def fold(train):
            th = self.fit(G0, Gs, train)
            folds.append(self.to_parameters(th))
            return self.residual_at(G0, Gs, th)

        score = heldout(ds, fold)
        theta = self.fit(G0, Gs, np.ones(ds.n, bool))
        return Result(self.cause, self.to_parameters(theta), score, self.residual_at(G0, Gs, theta),
                      explains=self.explains, folds=folds)


class MotorLag(GridCandidate):
    cause, name = "motor_lag", "tau"
    explains = "rate of change of the commanded total |thrust differences| (N/s)"
    grid = np.concatenate([[0.0], np.geomspace(0.002, 0.3, 40)])

    def delta(self, tau):
        ds = self.ds
        preds = []
        for i, f in enumerate(ds.files):
            F = ds.F[i]
            if tau > 0:
                # first-order lag of a zero-order-held input, averaged over each loop period (exact)
                dt = 1.0 / ds.fs
                a = math.exp(-dt / tau)
                b_, a_ = [0.0, 1.0 - a], [1.0, -a]
                y, _ = signal.lfilter(b_, a_, F, axis=1, zi=signal.lfilter_zi(b_, a_)[None, :] * F[:, :1])
                F = F + (y - F) * (tau / dt) * (1.0 - a)
            preds.append(ds.predict_file(i, F))
        return ds.delta_filtered(preds)


class ActuationDelay(GridCandidate):
    cause, name = "actuation_delay", "delay"
    explains = MotorLag.explains
    grid = np.linspace(0.0, 0.12, 49)

    def delta(self, d):
        ds = self.ds
        preds = []
        for i, f in enumerate(ds.files):
            F = ds.F[i]
            if d > 0:
                s = d * ds.fs                      # delay in loop periods; average over the period
                m, frac = int(math.floor(s)), s - math.floor(s)
                F0 = _shift(F, m)
                F = (1.0 - frac) * F0 + frac * _shift(F, m + 1)
            preds.append(ds.predict_file(i, F))
        return ds.delta_filtered(preds)


def _shift(F, m):
    if m <= 0:
        return F
    out = np.empty_like(F)
    out[:, m:] = F[:, :-m]
    out[:, :m] = F[:, :1]
    return out


class GroundEffect(GridCandidate):
    cause, name = "ground_effect", "rotor_radius"
    explains = "altitude from the range (m)"
    grid = np.linspace(0.0, 0.45, 46)

    def why_not(self):
        z = self.ds.z
        if not np.isfinite(z).any():
            return "no range readings in flight: the altitude near the ground is unknown"
        low = np.isfinite(z) & (z < GE_MAX_Z)
        if low.sum() / self.ds.fs < GE_MIN_S:
            return (f"only {low.sum() / self.ds.fs:.1f} s airborne below {GE_MAX_Z:g} m "
                    f"({GE_MIN_S:g} s needed) to see the thrust rise near the ground")
        return None

    @staticmethod
    def factor(z, R):
        """f / f_inf = 1 / (1 - (R / 4 z)^2), held at its z = R / 2 value (4/3) below R / 2."""
        zz = np.maximum(np.nan_to_num(z, nan=10.0), 0.5 * R)
        return 1.0 / (1.0 - (R / (4.0 * zz)) ** 2)

    def delta(self, R):
        ds = self.ds
        if R <= 0:
            return np.zeros((C, ds.n))
        preds = []
        for i, f in enumerate(ds.files):
            s = self.factor(f.z, R)
            preds.append(ds.predict_file(i, ds.F[i], scale=np.broadcast_to(s, ds.F[i].shape)))
        return ds.delta_filtered(preds)

    def explanatory(self):
        return self.ds.z


class RotorDrag(Candidate):
    """Horizontal drag -k (u, v) in the body frame. The body velocity is not logged; it is
    reconstructed by the model itself: the horizontal inertial acceleration is the horizontal part
    of R (0, 0, a_z) (a_z the measured specific force along z_b, R the integrated gyro) minus
    k v / M, so the horizontal velocity is that acceleration through a first-order filter with pole
    k / M, started at rest at take-off (small-tilt approximation for the drag direction). Its
    body-frame (u, v) gives the predicted accelerometer x, y: -k (u, v) / M. The initial tilt is
    known only to the accelerometer's bias, which leaks g times the tilt error into the horizontal
    acceleration as an unknown constant in the inertial frame: two nuisance parameters (b_x, b_y),
    fitted with the offsets by least squares for each k on the training blocks."""
    cause, name = "rotor_drag", "k"
    explains = "reconstructed body velocity u (m/s)"
    grid = np.concatenate([[0.0], np.geomspace(0.01, 3.0, 36)])

    def _filtered(self, k, inputs):
        """Per file: the body-frame (2, n) response -k/M R^T LPF_k(x) of inertial horizontal x (2, n)."""
        ds, M = self.ds, self.ds.a.M
        out = []
        for f, x in zip(ds.files, inputs):
            v = np.zeros_like(x)
            flying = (f.P > ds.a.h2 + MOTOR_ON_MARGIN).any(axis=0)
            a = math.exp(-k / M / ds.fs)
            g = (1.0 - a) * M / k if k > 0 else 1.0 / ds.fs
            for s0, s1 in _stretches(flying):
                v[:, s0:s1] = signal.lfilter([0.0, g], [1.0, -a], x[:, s0:s1], axis=1)
            u = f.Rm[0] * v[0] + f.Rm[3] * v[1]     # R^T v, body x (horizontal v)
            w = f.Rm[1] * v[0] + f.Rm[4] * v[1]     # body y
            d = np.zeros((2, x.shape[1]))
            d[:, :-1] = -k / M * np.vstack([u, w])[:, 1:]     # the accelerometer row k + 1
            out.append(d)
        return out

    def columns(self, k):
        """Filtered (3, 2, n): the drag prediction and the responses to unit inertial biases."""
        ds = self.ds
        ah = [np.vstack([f.Rm[2] * f.acc[2], f.Rm[5] * f.acc[2]]) for f in ds.files]
        ones = [np.ones(f.t.size) for f in ds.files]
        zero = [np.zeros(f.t.size) for f in ds.files]
        cols = []
        for x in (ah, [np.vstack([o, z]) for o, z in zip(ones, zero)], [np.vstack([z, o]) for o, z in zip(ones, zero)]):
            cols.append(ds.flat_filtered(self._filtered(k, x)))
        return np.stack(cols)

    def _stats(self, cols):
        """Per block: sums and cross-products of e = r - drag prediction and the bias columns, x and y."""
        ds = self.ds
        e = ds.r_base[3:5] - cols[0]
        A = np.stack([cols[1], cols[2]], axis=-1)          # (2, n, 2)
        st = []
        for i0, i1 in ds.block_edges:
            eb, Ab = e[:, i0:i1], A[:, i0:i1]
            st.append((eb.sum(axis=1), Ab.sum(axis=1), np.einsum("cn,cn->c", eb, eb),
                       np.einsum("cnp,cn->cp", Ab, eb), np.einsum("cnp,cnq->cpq", Ab, Ab)))
        return st

    @staticmethod
    def _solve(st, keep, n):
        """Weighted LSQ of the two inertial biases from the training blocks' statistics (offsets
        centred); returns (sum_c log RSS_c of x and y, b)."""
        se = sum(st[b][0] for b in keep)
        sA = sum(st[b][1] for b in keep)
        ee = sum(st[b][2] for b in keep) - se * se / n
        Ae = sum(st[b][3] for b in keep) - sA * se[:, None] / n
        AA = sum(st[b][4] for b in keep) - sA[:, :, None] * sA[:, None, :] / n
        w = 1.0 / np.maximum(ee, 1e-300)
        b = np.zeros(2)
        for _ in range(3):
            M = np.einsum("c,cpq->pq", w, AA)
            h = np.einsum("c,cp->p", w, Ae)
            b = np.linalg.lstsq(M + 1e-12 * np.trace(M) * np.eye(2), h, rcond=None)[0]
            rss = ee - 2.0 * Ae @ b + np.einsum("p,cpq,q->c", b, AA, b)
            w = 1.0 / np.maximum(rss, 1e-300)
        return float(np.log(np.maximum(rss, 1e-300)).sum()), b

    def _residual(self, cols, b):
        res = self.ds.r_base.copy()
        res[3:5] = res[3:5] - cols[0] - b[0] * cols[1] - b[1] * cols[2]
        return res

    def run(self) -> Result:
        ds = self.ds
        counts = ds.block_counts
        zero = np.zeros((3, 2, ds.n))
        table = [self.columns(k) if k > 0 else zero for k in self.grid]
        stats = [self._stats(cols) for cols in table]

        def best(keep):
            n = counts[keep].sum()
            out = [self._solve(st, keep, n) for st in stats]
            j = int(np.argmin([o[0] for o in out]))
            return j, out[j][1]

        folds = []

        def fold(train):
            test_block = int(ds.block[~train][0])
            j, b = best([x for x in range(N_BLOCKS) if x != test_block])
            folds.append(float(self.grid[j]))
            return self._residual(table[j], b)

        score = heldout(ds, fold)
        allb = list(range(N_BLOCKS))
        j, b = best(allb)
        k = float(self.grid[j])
        if 0 < j < len(self.grid) - 1:     # refine between the neighbours
            lo, hi = self.grid[j - 1], self.grid[j + 1]
            opt = optimize.minimize_scalar(lambda kk: self._solve(self._stats(self.columns(kk)), allb, ds.n)[0],
                                           bounds=(lo, hi), method="bounded", options={"xatol": 1e-3})
            k = float(opt.x)
        cols = self.columns(k) if k > 0 else zero
        b = self._solve(self._stats(cols), allb, ds.n)[1]
        self._k = k
        return Result(self.cause, {"k": round(k, 3)}, score, self._residual(cols, b), explains=self.explains,
                      folds=folds)

    def explanatory(self):
        k = max(getattr(self, "_k", 0.0), 1e-3)
        ds = self.ds
        ah = [np.vstack([f.Rm[2] * f.acc[2], f.Rm[5] * f.acc[2]]) for f in ds.files]
        d = self._filtered(k, ah)
        return ds.flat([x[0] * (-ds.a.M / k) for x in d])


class BatterySag(AffineCandidate):
    """Thrust times (V / v_nominal)^2: D = (c V^2 - 1) G with G the thrust-proportional part of the
    prediction, affine in c = 1 / v_nominal^2."""
    cause, names = "battery_sag", ("v_nominal",)
    explains = "battery voltage (V)"

    def why_not(self):
        V = self.ds.V
        if not np.isfinite(V).all():
            return "battery_v is missing in flight"
        lo, hi = np.percentile(V, [5, 95])
        span = (hi - lo) / np.median(V)
        if span < SAG_MIN_SPAN:
            return (f"battery_v hardly varies in flight ({100 * span:.2f} % from the 5th to the 95th "
                    f"percentile, {100 * SAG_MIN_SPAN:g} % needed): a constant voltage only rescales the thrust")
        return None

    def columns(self):
        ds = self.ds
        G = [ds.thrust_columns(i).sum(axis=0) for i in range(len(ds.files))]
        G0 = -ds.flat_filtered(G)
        G1 = ds.flat_filtered([g * f.battery_v ** 2 for g, f in zip(G, ds.files)])
        return G0, [G1]

    def to_parameters(self, theta):
        c = float(theta[0])
        return {"v_nominal": round(1.0 / math.sqrt(c), 3) if c > 0 else None}

    def explanatory(self):
        return self.ds.V


class LinearYawDrag(AffineCandidate):
    cause, names = "linear_yaw_drag", ("gamma0",)
    explains = "yaw rate r (rad/s)"

    def why_not(self):
        r95 = np.percentile(np.abs(self.ds.w[2]), 95)
        if r95 < YAW_MIN_RATE:
            return f"no yaw motion to judge it (95th percentile |r| = {r95:.3f} rad/s, {YAW_MIN_RATE:g} needed)"
        return None

    def columns(self):
        ds = self.ds
        G = []
        for i in range(len(ds.files)):
            x = np.zeros((C, ds.files[i].t.size))
            x[2] = -ds.wmid[i][2] / ds.a.Jzz
            G.append(x)
        return None, [ds.flat_filtered(G)]

    def to_parameters(self, theta):
        return {"gamma0": float(f"{theta[0]:.4g}")}

    def explanatory(self):
        return self.ds.w[2]


class ComOffset(AffineCandidate):
    """Thrust acting at (x_i - dx, y_i - dy): torques (-dy, +dx) times the total thrust."""
    cause, names = "com_offset", ("dx", "dy")
    explains = "total thrust (N)"

    def columns(self):
        ds = self.ds
        Gx, Gy = [], []
        for i in range(len(ds.files)):
            T = ds.F[i].sum(axis=0)
            x = np.zeros((C, T.size))
            y = np.zeros((C, T.size))
            x[1] = T / ds.a.Jyy
            y[0] = -T / ds.a.Jxx
            Gx.append(x)
            Gy.append(y)
        return None, [ds.flat_filtered(Gx), ds.flat_filtered(Gy)]

    def to_parameters(self, theta):
        return {"dx": round(float(theta[0]), 5), "dy": round(float(theta[1]), 5)}

    def explanatory(self):
        return self.ds.thrust.sum(axis=0)


class MotorWeak(AffineCandidate):
    """One motor m at a fraction `scale`: D = (scale - 1) G_m. Each fold picks the motor whose
    fit is best on its training blocks."""
    cause = "motor_weak"
    explains = "thrust of the weak motor (N)"

    def run(self):
        ds = self.ds
        Gm = [ds.flat_filtered([ds.thrust_columns(i)[m] for i in range(len(ds.files))]) for m in range(4)]
        folds = []

        def best(train):
            out = []
            for m in range(4):
                th = self.fit(None, [Gm[m]], train)
                out.append((objective(self.residual_at(None, [Gm[m]], th), train), m, float(th[0])))
            return min(out)

        def fold(train):
            _, m, th = best(train)
            folds.append({"motor": m + 1, "scale": 1.0 + th})
            return self.residual_at(None, [Gm[m]], [th])

        score = heldout(ds, fold)
        _, m, th = best(np.ones(ds.n, bool))
        self._m = m
        return Result(self.cause, {"motor": m + 1, "scale": round(1.0 + th, 4)}, score,
                      self.residual_at(None, [Gm[m]], [th]), explains=self.explains, folds=folds)

    def explanatory(self):
        return self.ds.thrust[getattr(self, "_m", 0)]


CANDIDATES = (MotorLag, ActuationDelay, GroundEffect, BatterySag, LinearYawDrag, RotorDrag, ComOffset,
              MotorWeak)


# --------------------------------------------------------------------------------------------
# The diagnosis


@dataclass
class Diagnosis:
    cause: str
    parameters: dict
    rmse_base: float
    rmse_extended: float
    gain: float
    metric: str
    results: list[Result]            # judged candidates, best first
    not_judged: list[dict]
    base: Result
    ds: DataSet
    notes: list[str]
    significant: list[str]

    def report(self) -> dict:
        cands = []
        for r in self.results:
            cands.append({"cause": r.cause, "parameters": r.parameters, "gain": _num(r.gain),
                          "rmse_extended": _num(geomean(r.score.rmse()), 6),
                          "t_stat": _num(r.t_stat, 2), "significant": r.cause in self.significant,
                          "block_gains": [_num(g, 4) for g in r.block_gain]})
        base_rmse = self.base.score.rmse()
        best = next((r for r in self.results if r.cause == self.cause), None)
        ext_rmse = best.score.rmse() if best is not None else base_rmse
        return {
            "cause": self.cause,
            "parameters": self.parameters,
            "rmse_base": _num(self.rmse_base, 6),
            "rmse_extended": _num(self.rmse_extended, 6),
            "gain": _num(self.gain),
            "metric": self.metric,
            "candidates": cands,
            "not_judged": self.not_judged,
            "channels": {c: {"unit": u, "rmse_base": _num(b, 6), "rmse_extended": _num(e, 6)}
                         for c, u, b, e in zip(CHANNELS, UNITS, base_rmse, ext_rmse)},
            "significance": {"min_gain": MIN_GAIN, "t_crit": T_CRIT, "blocks": N_BLOCKS},
            "data": {"files": [f.path for f in self.ds.files], "airborne_s": round(self.ds.seconds, 2),
                     "lowpass_hz": LOWPASS_HZ},
            "notes": self.notes,
        }


METRIC = ("geometric mean over 6 channels of the held-out RMSE of the one-loop-period equation error: "
          "angular acceleration p, q, r (rad/s^2, differenced gyro) and specific force x, y, z (m/s^2, "
          f"accelerometer, one bias each), both sides low-passed at {LOWPASS_HZ:g} Hz; held out by "
          f"{N_BLOCKS}-block cross-validation over the airborne data")


def significance(res: Result, base: Score, ds: DataSet):
    """Per-block held-out gains, and a Diebold-Mariano-type test of equal predictive accuracy on
    the held-out residuals. The held-out data are cut into windows of DM_WINDOW_S (much longer than
    the correlation time of the low-passed residual, so that windows are close to independent); in
    each window the loss differential is the metric's own, mean_c log(RSS_base,c / RSS_ext,c) (a
    log ratio, so that a few violent windows, a touchdown or a crash, cannot swamp the others). t is
    its mean over the windows in standard errors; when the candidate predicts no better than the
    base model, t is about N(0, 1) or below, and T_CRIT = 3 is a one-sided 0.1 % level."""
    ratio = res.score.rss / base.rss                       # (B, C)
    res.block_gain = 1.0 - np.exp(0.5 * np.log(ratio).mean(axis=1))
    res.gain = 1.0 - geomean(res.score.rmse()) / geomean(base.rmse())
    win = min(DM_WINDOW_S, max(0.1, ds.seconds / DM_MIN_WINDOWS))
    per = max(2, int(round(win * ds.fs)))
    m = ds.n // per
    if m < 2:
        res.t_stat = 0.0
        return
    eb = (base.residual[:, :m * per] ** 2).reshape(C, m, per).sum(axis=2)
    ee = (res.score.residual[:, :m * per] ** 2).reshape(C, m, per).sum(axis=2)
    w = np.log((eb + 1e-300) / (ee + 1e-300)).mean(axis=0)
    se = w.std(ddof=1) / math.sqrt(m)
    res.t_stat = float(w.mean() / se) if se > 0 else (math.inf if w.mean() > 0 else 0.0)


def _too_small(r: Result, ds: DataSet) -> str | None:
    """Sizes the data cannot tell from the log's own timing or from nothing (not significant)."""
    if r.cause in ("motor_lag", "actuation_delay"):
        v = next(iter(r.parameters.values()))
        if v < MIN_TIMING_PERIODS / ds.fs and r.gain >= MIN_GAIN:
            return (f"{r.cause}: {v * 1e3:.1f} ms is within {MIN_TIMING_PERIODS:g} loop periods, the timing "
                    f"uncertainty of a log (sensor filters, when in the period the sample is taken): not named")
    if r.cause == "battery_sag" and r.parameters.get("v_nominal") is None:
        return "battery_sag: the fit wants no voltage dependence (1/v_nominal^2 <= 0): not named"
    return None


def diagnose(tables: list[Table], a: Airframe, progress=say) -> Diagnosis:
    files, notes = [], []
    for tab in tables:
        fd = load_file(tab, a)
        sec = fd.airborne.sum() / (1.0 / float(np.median(np.diff(fd.t))))
        progress(f"{tab.path}: {fd.t[-1] - fd.t[0]:.1f} s logged, {sec:.1f} s airborne")
        notes += [f"{tab.path}: {n}" for n in fd.notes]
        if sec < MIN_STRETCH_S:
            notes.append(f"{tab.path}: no usable airborne data (motors off or on the ground): not used")
            continue
        files.append(fd)
    total = sum(f.airborne.sum() * float(np.median(np.diff(f.t))) for f in files)
    if total < MIN_AIRBORNE_S:
        where = tables[0] if len(tables) == 1 else None
        what = (f"too short to judge: {total:.1f} s of airborne data (motors running, above "
                f"{Z_AIRBORNE:g} m), at least {MIN_AIRBORNE_S:g} s needed")
        if where is not None:
            where.fail(what)
        raise InputError(f"{', '.join(t.path for t in tables)}: {what}")
    ds = DataSet(files, a)
    progress(f"{ds.n} samples airborne ({ds.seconds:.1f} s), {N_BLOCKS} blocks")
    base = Result("none", {}, heldout(ds, lambda train: ds.r_base), ds.r_base)
    results, not_judged = [], []
    for cls in CANDIDATES:
        cand = cls(ds)
        why = cand.why_not()
        if why is not None:
            not_judged.append({"cause": cand.cause, "why": why})
            progress(f"{cand.cause}: not judged ({why})")
            continue
        r = cand.run()
        significance(r, base.score, ds)
        r.explanatory = cand.explanatory()
        results.append(r)
        progress(f"{cand.cause}: {r.parameters} held-out gain {r.gain:+.4f} (t = {r.t_stat:.1f})")
    results.sort(key=lambda r: -r.gain)
    significant = []
    for r in results:
        why = _too_small(r, ds)
        if why:
            notes.append(why)
        elif r.gain >= MIN_GAIN and r.t_stat >= T_CRIT:
            significant.append(r.cause)
    rb = geomean(base.score.rmse())
    best = next((r for r in results if r.cause in significant), None)
    if best is None:
        cause, params, re, gain = "none", {}, rb, 0.0
    else:
        cause, params, re, gain = best.cause, best.parameters, geomean(best.score.rmse()), best.gain
    return Diagnosis(cause, params, rb, re, gain, METRIC, results, not_judged, base, ds, notes, significant)
