"""The data set of a diagnosis: every airborne stretch of every file, flattened into samples, with
the measured channels, the base model's prediction and their low-passed difference (the base
residual), and the contiguous blocks of the held-out scoring. Per-file arrays are kept for the
candidates that need history (a lag, a delay, a velocity filter).

The channels (docs/diagnose.md, "What is predicted"): row k pairs the command held from row k to
k+1 with the gyro difference k -> k+1 (angular acceleration) and the accelerometer on row k+1.

The base model is a `Vehicle`: this project's airframe with its known parameters, or, for a log of
another vehicle, the one `flightctl.sim.diagnose.basemodel` identifies from the flight (an
equivalent airframe per unit mass and inertia whose effectiveness on each channel is refitted on the
training blocks of every fold: the `free` columns of a prediction).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from flightctl.errors import InputError
from flightctl.params import Airframe
from flightctl.physics import rotor_speed, rotor_torque, thrust_from_command, yaw_drag
from flightctl.sim.diagnose.data import EDGE_S, FileData, Layout, stretches
from flightctl.sim.logs.columns import DYNAMIC_MIN_HZ, MOTION_HZ

CHANNELS = ("p_dot", "q_dot", "r_dot", "acc_x", "acc_y", "acc_z")
UNITS = ("rad/s^2", "rad/s^2", "rad/s^2", "m/s^2", "m/s^2", "m/s^2")
OFFSET = np.array([False, False, False, True, True, True])   # channels with a bias nuisance
C = len(CHANNELS)
GYRO, ACC = slice(0, 3), slice(3, 6)
THRUST_CHANNELS = (0, 1, 2, 5)   # the channels the rotors' thrust drives (roll, pitch, yaw torque; thrust)

LOWPASS_HZ = MOTION_HZ   # zero-phase low-pass applied to every residual (2nd-order Butterworth, twice)
# A lag or a delay of tens of milliseconds shows only in commands logged at several times the low-pass
# bandwidth (DYNAMIC_MIN_HZ, sim/logs/columns.py); a log whose motor outputs are slower is judged for its
# static effects only, low-passed at a quarter of its motor rate; one whose gyro and accelerometer are
# slower is not judged (verdict.py).
# After the low-pass the channels are kept at FLAT_PER_BAND times its bandwidth (every `step`-th row):
# the filter's response there is (1/8)^4 = 2.4e-4 of the pass band's, so nothing is aliased, and the
# fits, scores and tests see the same signal at a tenth of the samples of a 1 kHz log.
FLAT_PER_BAND = 8.0
N_BLOCKS = 8             # blocked cross-validation


@dataclass(frozen=True)
class Vehicle:
    """What the base model knows of the airframe: its parameters `a` (eq. 6-9, 26-28), the rotor
    `layout`, and eq. 7's inertia coupling per channel `coupling = (a_p, a_q, a_r)`:
    p_dot += a_p q r, q_dot += a_q p r, r_dot += a_r p q. For a known airframe these follow from its
    inertia; an `identified` vehicle has them fitted, and its `a` is an equivalent airframe (M = 1,
    Jzz = 1, arm lengths as unit) whose effectiveness the fits refine fold by fold."""
    a: Airframe
    layout: Layout
    coupling: tuple[float, float, float]
    identified: bool = False
    identification: dict = field(default_factory=dict, compare=False)   # the report of `basemodel.identify`
    gains: tuple[float, ...] = (1.0, 1.0, 1.0, 1.0)                     # each rotor's, of an identified vehicle

    @classmethod
    def known(cls, a: Airframe, layout: Layout) -> "Vehicle":
        Jxx, Jyy, Jzz = a.Jxx, a.Jyy, a.Jzz
        return cls(a, layout, ((Jyy - Jzz) / Jxx, (Jzz - Jxx) / Jyy, (Jxx - Jyy) / Jzz))


class Pred(NamedTuple):
    """A per-file prediction (C, n), and for an identified vehicle the thrust channels of each
    component of the drive at unit effectiveness (K, C, n), whose coefficients the fits refine, and
    the rest of the prediction (C, n): value = unit[0] + rest (the coupling, the yaw drag, a wrench)."""
    value: np.ndarray
    unit: np.ndarray | None = None
    rest: np.ndarray | None = None


class Change(NamedTuple):
    """A candidate's filtered change of the prediction (C, n) against the base model, and the free
    columns (K, C, n) its fit refits beside its own parameters: an identified vehicle's
    effectiveness at the candidate's thrusts (none for a known airframe)."""
    delta: np.ndarray
    free: np.ndarray


def _pt1(hz: float, fs: float):
    a = math.exp(-2.0 * math.pi * hz / fs)
    return [1.0 - a, 0.0], [1.0, -a]


def sensor_filters(chain, fs: float) -> list[tuple[list, list]]:
    """(b, a) stages of a log's declared low-pass chain at the log's rate (docs/real-flights.md):
    Betaflight's pt1, pt2 and pt3 (cascaded first-order stages, cut-off corrected so the chain's
    -3 dB point is the stated one) and biquad (2nd-order Butterworth). A biquad above 0.4 fs, which
    the log's rate cannot represent, becomes two first-order stages of the same low-frequency delay."""
    from scipy import signal
    out = []
    for kind, hz in chain:
        if kind == "biquad" and hz < 0.4 * fs:
            b, a = signal.butter(2, hz, fs=fs)
            out.append((list(b), list(a)))
            continue
        order = {"pt1": 1, "pt2": 2, "pt3": 3, "biquad": 2}[kind]
        corr = 1.0 / math.sqrt(2.0 ** (1.0 / order) - 1.0) if kind != "biquad" else math.sqrt(2.0)
        out += [_pt1(hz * corr, fs)] * order
    return out


def _sos(stages) -> np.ndarray | None:
    """The (b, a) stages of `sensor_filters` as one cascade of second-order sections, or None."""
    if not stages:
        return None
    rows = []
    for b, a in stages:
        b, a = list(b) + [0.0] * (3 - len(b)), list(a) + [0.0] * (3 - len(a))
        rows.append(b + a)
    return np.array(rows, float)


class DataSet:
    """`r_base` (C, n) is the low-passed base residual over the airborne samples; `block` gives each
    sample's block, `block_edges` the (start, stop) of each; `base_free` (K, C, n) the identified
    vehicle's free columns at the base thrusts. The base model is `vehicle` until `carry` adds a
    parameter file's effects, or the causes of the chain, to it (docs/diagnose.md)."""

    def __init__(self, files: list[FileData], vehicle: Vehicle, lowpass_hz: float = LOWPASS_HZ):
        from scipy import signal   # here, not at the top: `flightctl sim` imports the causes for their effects
        self.files, self.vehicle, self.a = files, vehicle, vehicle.a
        self.fs = 1.0 / float(np.median(np.concatenate([np.diff(f.t) for f in files])))
        self.lowpass_hz = lowpass_hz
        self.sos = signal.butter(2, lowpass_hz, fs=self.fs, output="sos")
        self._zi = signal.sosfilt_zi(self.sos)          # (sections, 2): once, not per stretch
        self._sensor = [(_sos(sensor_filters(f.gyro_filter, self.fs)), _sos(sensor_filters(f.acc_filter, self.fs)))
                        for f in files]
        # the stretches: (file index, start, stop) of input rows
        self.stretches = [(i, s0, s1) for i, f in enumerate(files) for s0, s1 in stretches(f.airborne)]
        if not self.stretches:        # a log (or its half) that never flew long enough: a refusal, not a crash
            raise InputError("no stretch in the air to identify from (the log, or the part of it used, never flew)")
        self.step = max(1, int(self.fs / (FLAT_PER_BAND * lowpass_hz)))
        self.fs_flat = self.fs / self.step                # the rate of the flat (kept) samples
        self.n = sum(len(range(s0, s1, self.step)) for _, s0, s1 in self.stretches)
        # each stretch with the trimmed edges of its flight (data.EDGE_S) on either side, for the filter
        pads = [int(round(EDGE_S / float(np.median(np.diff(f.t))))) for f in files]
        self._padded = [(max(0, s0 - pads[i]), min(files[i].t.size - 1, s1 + pads[i])) for i, s0, s1 in self.stretches]
        self._last_row = {}
        for (i, _, _), (_, p1) in zip(self.stretches, self._padded):
            self._last_row[i] = max(self._last_row.get(i, 0), p1)
        self.seconds = sum(s1 - s0 for _, s0, s1 in self.stretches) / self.fs
        a = self.a
        self.D = [self.drive(thrust_from_command(f.P, a.h1, a.h2)) for f in files]   # eq. 26
        # each rotor's thrust and torque scale: an identified vehicle's rotor gains, then the chain's causes
        gains = np.asarray(vehicle.gains, float)[:, None]
        self.S: list[np.ndarray | float] = [gains if np.any(gains != 1.0) else 1.0] * len(files)
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
        self.V = self.flat([f.battery_v for f in files])
        self.z = self.flat([f.z for f in files])
        self.w = self.flat(self.wmid)
        self.time = self.flat([f.t for f in files])
        self.file_index = np.concatenate([np.full(len(range(s0, s1, self.step)), i) for i, s0, s1 in self.stretches])
        edges = np.linspace(0, self.n, N_BLOCKS + 1).round().astype(int)
        self.block = np.zeros(self.n, int)
        for b in range(N_BLOCKS):
            self.block[edges[b]:edges[b + 1]] = b
        self.block_edges = list(zip(edges[:-1], edges[1:]))
        self.block_counts = np.diff(edges).astype(float)
        self.measured = self.flat_filtered(self.meas, sensor=False)
        # what a candidate computes from the files and the accelerometer's sensing alone (rotor_drag's
        # filtered velocities at each drag): no model's, so every model of this data set and its copies
        # share it (`rebase` and `add_gyro_filter` change neither the files nor the accelerometer's filters)
        self.of_files: dict = {}
        self.carried: dict[str, np.ndarray] = {}     # cause -> its filtered term in the base prediction
        self.carried_parameters: dict[str, dict] = {}
        self.extra_free: list[np.ndarray] = []       # free columns a cause of the chain brought (C, n)
        self.rotor_speeds: dict | None = None        # the log's own rotor speeds' check (rotorspeed.py), if any
        self.rebase()

    def drive(self, F: np.ndarray, W: np.ndarray | None = None) -> np.ndarray:
        """The rotors' drive (K, 4, n) of thrusts F (4, n): the thrusts, and for an identified vehicle
        also the speeds W (eq. 27 from F unless given), whose columns free the thrust curve's shape in
        every fit (with both, the curve h1 (P - h2)^2 of each channel is linear in its coefficients)."""
        if not self.vehicle.identified:
            return F[None]
        return np.stack([F, rotor_speed(F, self.a.c1) if W is None else W])

    @property
    def F(self) -> list[np.ndarray]:
        """The per-file thrusts (4, n) of the base model's drive (before the chain's scales)."""
        return [d[0] for d in self.D]

    def thrust_of(self, i) -> np.ndarray:
        """File i's thrusts (4, n) as the base model has them, the chain's scales applied."""
        return self.D[i][0] * self.S[i]

    def rebase(self, D: list[np.ndarray] | None = None, S: list | None = None) -> None:
        """The base prediction and residual from the per-file drives `D` (default: eq. 26 of the
        commands; a cause of the chain that changes the thrusts passes them) and the scales `S` of
        each rotor's thrust and torque ((4, n), (n,) or a number per file), the carried terms kept."""
        if D is not None:
            self.D = D
        if S is not None:
            self.S = S
        # the grid candidates' changes of the prediction under this model (`GridCandidate.cached`): a
        # carried term changes none of them, so a copy that only carries more shares the store; a new
        # model (this method) gets a store of its own, the old one left to the copies that still have it
        self.changes: dict = {}
        self.thrust = self.flat([F * s for F, s in zip(self.F, self.S)])
        preds = [self.predict_file(i, self.D[i]) for i in range(len(self.files))]
        self.base_pred = [p.value for p in preds]
        self.base_rest = [p.rest for p in preds]
        self._base_unit0 = None
        if self.vehicle.identified:     # the prediction and its drive's unit channels filtered in one pass
            both = self.flat_filtered([np.concatenate([p.value[None], p.unit]) for p in preds])
            filtered, U = both[0], both[1:]
            self._base_unit0 = U[0]
            self.base_free = self._free(U)
        else:
            filtered = self.flat_filtered(self.base_pred)
            self.base_free = self._free(None)
        self.r_base = self.measured - filtered - sum(self.carried.values())

    def add_gyro_filter(self, b, a) -> None:
        """A first-order gyro filter (b, a), y_k = b0 x_k - a1 y_(k-1), that the log does not declare (a
        `gyro_lag`, folded into the model or tried): the model's gyro channels go through it as through
        the declared ones (`_sense`), and its rates (`wmid`, in the coupling, rotor-momentum and
        yaw-drag terms) are the logged gyro corrected by its exact inverse, x_k = (y_k + a1 y_(k-1)) / b0,
        the correction x - y low-passed (zero-phase, at twice the residual's low-pass: products of
        rates reach that band from there) so that the inverse's amplified noise stays out; the base
        is recomputed."""
        from scipy import signal
        stage = _sos([(b, a)])
        self._sensor = [(stage if g is None else np.vstack([g, stage]), acc) for g, acc in self._sensor]
        smooth = signal.butter(2, min(2.0 * self.lowpass_hz, 0.4 * self.fs), fs=self.fs, output="sos")
        wmid = []
        for w in self.wmid:
            x = np.zeros_like(w)
            x[:, 1:-1] = (w[:, 1:-1] + a[1] * w[:, :-2]) / b[0] - w[:, 1:-1]
            x = signal.sosfiltfilt(smooth, x, axis=1)
            x[:, -1] = 0.0
            wmid.append(w + x)
        self.wmid = wmid
        self.w = self.flat(wmid)
        self.rebase()

    def carry(self, cause: str, parameters: dict, delta: np.ndarray) -> None:
        """Add a carried effect's filtered prediction change `delta` (C, n) at `parameters` to the
        base model (a cause carried twice: both terms, the later parameters)."""
        self.r_base = self.r_base - delta
        self.carried[cause] = self.carried.get(cause, 0.0) + delta
        self.carried_parameters[cause] = dict(parameters)

    def base_without(self, cause: str) -> np.ndarray:
        """The base residual with `cause`'s carried term taken out again (the base a candidate of a
        carried cause is fitted on: its parameters replace the carried ones)."""
        d = self.carried.get(cause)
        return self.r_base if d is None else self.r_base + d

    # -- helpers over stretches
    def flat(self, per_file):
        """The kept samples (every `step`-th row of each stretch) of per-file (..., n) arrays."""
        return np.concatenate([per_file[i][..., s0:s1:self.step] for i, s0, s1 in self.stretches], axis=-1)

    def _sense(self, i, x):
        """What the sensors show of model-side (..., C, n) arrays of file i: the log's declared gyro
        and accelerometer filters, causal, over the whole file (the rows that are not all zero). A log
        without an accelerometer (`FileData.accel`) shows nothing of the model's accelerometer channels:
        they are zero, as its measurement is, so no fit or score is moved by them."""
        from scipy import signal
        gyro, acc = self._sensor[i]
        if not self.files[i].accel and x.shape[-2] == C:
            x = np.array(x, dtype=float)
            x[..., ACC, :] = 0.0
        if gyro is None and acc is None:
            return x
        x = np.array(x, dtype=float)
        for rows, sos in ((GYRO, gyro), (ACC, acc)):
            if sos is None:
                continue
            part = x[..., rows, :]
            flat = part.reshape(-1, part.shape[-1])
            live = np.flatnonzero(np.any(flat != 0.0, axis=1))
            if live.size:
                flat[live] = signal.sosfilt(sos, flat[live], axis=-1)
                x[..., rows, :] = flat.reshape(part.shape)
        return x

    def flat_filtered(self, per_file, sensor: bool = True):
        """The stretches of per-file (..., n) arrays, each stretch low-passed forward and backward, at
        the kept samples (`flat`).
        Each is filtered with the EDGE_S of flight on either side that the airborne mask trimmed off
        (`_padded`): the filter's start-up transient falls there, not on the data. `sensor`: the arrays
        are the model's channels (..., C, n), so they first go through the log's sensor filters (the
        measurements went through them on the vehicle)."""
        parts, jobs = [], []
        sensed = {}        # the sensor filters run once over each file, not once per stretch
        for (i, s0, s1), (p0, p1) in zip(self.stretches, self._padded):
            x = per_file[i]
            if sensor and x.ndim >= 2:
                if i not in sensed:
                    sensed[i] = self._sense(i, x[..., :self._last_row[i]])
                x = sensed[i]
            x = x[..., p0:p1]
            flat = x.reshape(-1, x.shape[-1])
            y = np.zeros((flat.shape[0], len(range(s0, s1, self.step))))
            # rows that are zero stay zero: filter only the others (speed)
            rows = np.flatnonzero(np.any(flat != 0.0, axis=1)) if x.ndim >= 2 else np.arange(1)
            if rows.size:
                jobs.append((flat[rows], y, rows, slice(s0 - p0, s1 - p0, self.step)))
            parts.append(y.reshape(x.shape[:-1] + y.shape[-1:]))
        for (_, y, rows, inner), out in zip(jobs, self._filtfilt_many([j[0] for j in jobs])):
            y[rows] = out[:, inner]
        return np.concatenate(parts, axis=-1)

    def _filtfilt_many(self, blocks: list[np.ndarray]) -> list[np.ndarray]:
        """`scipy.signal.sosfiltfilt(self.sos, x, axis=-1)` of each block x (rows, L) of rows (each
        stretch's), its odd extension and start-up states, as the function does them: the blocks of
        like length filtered together, each row's extension left-aligned in one array and its reverse
        gathered left-aligned for the backward pass (a causal filter's output at a sample does not
        depend on the samples after it, so the padding behind a shorter row changes none of its
        values). Row for row the same arithmetic as one call per block, in a few calls: a long log
        has dozens of stretches, and each call's overhead outweighed its work (docs/diagnose.md,
        "Speed")."""
        from scipy import signal
        pad = 3 * (2 * len(self.sos) + 1 - min((self.sos[:, 2] == 0).sum(), (self.sos[:, 5] == 0).sum()))
        out: list[np.ndarray | None] = [None] * len(blocks)
        todo = []
        for k, x in enumerate(blocks):
            if x.shape[-1] <= pad:
                out[k] = signal.sosfiltfilt(self.sos, x, axis=-1)
            else:
                todo.append(k)
        todo.sort(key=lambda k: -blocks[k].shape[-1])
        zi = self._zi[:, None, :]
        while todo:
            longest = blocks[todo[0]].shape[-1]
            group = [k for k in todo if 5 * blocks[k].shape[-1] >= 4 * longest]   # at most a quarter padded
            todo = todo[len(group):]
            lengths = np.concatenate([np.full(blocks[k].shape[0], blocks[k].shape[-1] + 2 * pad) for k in group])
            ext = np.zeros((lengths.size, longest + 2 * pad))
            r = 0
            for k in group:
                x = blocks[k]
                ext[r:r + x.shape[0], :x.shape[-1] + 2 * pad] = np.concatenate(
                    [2.0 * x[:, :1] - x[:, pad:0:-1], x, 2.0 * x[:, -1:] - x[:, -2:-pad - 2:-1]], axis=1)
                r += x.shape[0]
            y, _ = signal.sosfilt(self.sos, ext, axis=-1, zi=zi * ext[None, :, :1])
            back = np.maximum(lengths[:, None] - 1 - np.arange(ext.shape[-1])[None, :], 0)
            y = np.take_along_axis(y, back, axis=1)         # each row reversed, left-aligned
            y, _ = signal.sosfilt(self.sos, y, axis=-1, zi=zi * y[None, :, :1])
            r = 0
            for k in group:
                n, L = blocks[k].shape
                out[k] = y[r:r + n, :L + 2 * pad][:, ::-1][:, pad:-pad]
                r += n
        return out

    def predict_file(self, i, D, scale=None, torque_extra=None, force_extra=None, rates=None) -> Pred:
        """The model's channels for file i from the rotors' drive D (K, 4, n) (`drive`): eq. 7 with the
        torques of the rotor layout (eq. 25's structure), the rotor torque of eq. 28, the rotor
        momentum of eq. 9 (speed from eq. 27) and the yaw drag of eq. 6. `scale` (4, n) multiplies
        thrust and torque of each rotor; `torque_extra` (3, n) and `force_extra` (2, n) add a body wrench;
        `rates` (3, n) are the body rates of the period's middle in place of the logged gyro's (`wmid`)."""
        v = self.vehicle
        a, lay = v.a, v.layout
        F = D[0]
        tq = rotor_torque(F, a.g1, a.g2)                                       # eq. 28
        scale = self.S[i] if scale is None else scale * self.S[i]
        if not (isinstance(scale, float) and scale == 1.0):
            F, tq, D = F * scale, tq * scale, D * scale
        x, y, s = (np.asarray(c)[:, None] for c in (lay.x, lay.y, lay.spin))
        tphi, ttheta, tpsi = (y * F).sum(axis=0), -(x * F).sum(axis=0), -(s * tq).sum(axis=0)
        unit = None
        if v.identified:     # eq. 28 with g2 = 0 is linear in the drive: each component's channels
            unit = np.zeros((D.shape[0], C, F.shape[1]))
            for k, d in enumerate(D):
                unit[k, 0], unit[k, 1] = (y * d).sum(axis=0) / a.Jxx, -(x * d).sum(axis=0) / a.Jyy
                unit[k, 2], unit[k, 5] = -(s * a.g1 * d).sum(axis=0) / a.Jzz, d.sum(axis=0) / a.M
        if torque_extra is not None:
            tphi, ttheta, tpsi = tphi + torque_extra[0], ttheta + torque_extra[1], tpsi + torque_extra[2]
        p, q, r = self.wmid[i] if rates is None else rates
        hz = 0.0
        if a.Jp:
            w = rotor_speed(F, a.c1)                                            # eq. 27
            hz = a.Jp * (s * w).sum(axis=0)                                     # eq. 9: Jp Omega
        tau_d = yaw_drag(r, a.gamma1, 0.0)                                      # eq. 6, gamma2 = 0 in flight
        cp, cq, cr = v.coupling
        out = np.zeros((C, F.shape[1]))
        out[0] = (tphi - q * hz) / a.Jxx + cp * q * r                           # eq. 7, vector form
        out[1] = (ttheta + p * hz) / a.Jyy + cq * p * r
        out[2] = (tpsi - tau_d) / a.Jzz + cr * p * q
        out[5] = F.sum(axis=0) / a.M
        if force_extra is not None:
            out[3], out[4] = force_extra[0] / a.M, force_extra[1] / a.M
        rest = None
        if v.identified:     # the same terms without the drive's thrust part (Jp = 0: no rotor momentum)
            te = np.zeros((3, 1)) if torque_extra is None else torque_extra
            rest = np.zeros_like(out)
            rest[0] = te[0] / a.Jxx + cp * q * r
            rest[1] = te[1] / a.Jyy + cq * p * r
            rest[2] = (te[2] - tau_d) / a.Jzz + cr * p * q
            rest[3:5] = out[3:5]
        return Pred(out, unit, rest)

    def _free(self, U: np.ndarray | None) -> np.ndarray:
        """The free columns from the filtered unit channels U (K, C, n) of the drive's components: each
        thrust channel's effectiveness (its thrust part, channel by channel), and one shape of the
        curve for all of them (the speed part of every channel, one column: h2 is the rotors', so a
        trim torque, a centre of mass off the thrust centre, is not taken for a channel's curve)."""
        extra = np.stack(self.extra_free) if self.extra_free else np.zeros((0, C, self.n))
        if U is None:
            return extra
        cols = np.zeros((len(THRUST_CHANNELS) + 1, C, self.n))
        for j, c in enumerate(THRUST_CHANNELS):
            cols[j, c] = U[0, c]
            cols[-1, c] = U[1, c]
        return np.concatenate([cols, extra])

    def delta_filtered(self, per_file_pred: list[Pred]) -> Change:
        """Filtered change of the prediction against the base model, flattened: D = L(pred - base),
        with the free columns at the new thrusts (filtered together, in one pass)."""
        if not self.vehicle.identified:
            return Change(self.flat_filtered([p.value - b for p, b in zip(per_file_pred, self.base_pred)]),
                          self._free(None))
        # value = unit[0] + rest: the thrust part is filtered once, as a free column; what else changed
        # (a wrench, mostly nothing: zero rows are not filtered) is filtered on its own
        both = self.flat_filtered([np.concatenate([(p.rest - b)[None], p.unit])
                                   for p, b in zip(per_file_pred, self.base_rest)])
        return Change(both[0] + both[1] - self._base_unit0, self._free(both[1:]))

    def thrust_columns(self, i, F=None):
        """Per-file (4, C, n): the part of the channels proportional to each rotor's thrust and torque."""
        a, lay = self.a, self.vehicle.layout
        F = self.F[i] if F is None else F
        tq = rotor_torque(F, a.g1, a.g2)
        F, tq = F * self.S[i], tq * self.S[i]
        G = np.zeros((4, C, F.shape[1]))
        for m in range(4):
            G[m, 0] = lay.y[m] * F[m] / a.Jxx
            G[m, 1] = -lay.x[m] * F[m] / a.Jyy
            G[m, 2] = -lay.spin[m] * tq[m] / a.Jzz
            G[m, 5] = F[m] / a.M
        return G
