"""The data set of a diagnosis: every airborne stretch of every file, flattened into samples, with
the measured channels, the base model's prediction and their low-passed difference (the base
residual), and the contiguous blocks of the held-out scoring. Per-file arrays are kept for the
candidates that need history (a lag, a delay, a velocity filter).

The channels (docs/diagnose.md, "What is predicted"): row k pairs the command held from row k to
k+1 with the gyro difference k -> k+1 (angular acceleration) and the accelerometer on row k+1.
"""
from __future__ import annotations

import numpy as np

from flightctl.params import Airframe
from flightctl.physics import rotor_speed, rotor_torque, thrust_from_command, yaw_drag
from flightctl.sim.identify.diagnose.data import FileData, stretches
from flightctl.sim.model import angular_acceleration, body_torques

CHANNELS = ("p_dot", "q_dot", "r_dot", "acc_x", "acc_y", "acc_z")
UNITS = ("rad/s^2", "rad/s^2", "rad/s^2", "m/s^2", "m/s^2", "m/s^2")
OFFSET = np.array([False, False, False, True, True, True])   # channels with a bias nuisance
C = len(CHANNELS)

LOWPASS_HZ = 12.0        # zero-phase low-pass applied to every residual (2nd-order Butterworth, twice)
N_BLOCKS = 8             # blocked cross-validation


class DataSet:
    """`r_base` (C, n) is the low-passed base residual over the airborne samples; `block` gives each
    sample's block, `block_edges` the (start, stop) of each. The base model is the paper's until
    `carry` adds a parameter file's effects to it (docs/diagnose.md, "A base model with effects")."""

    def __init__(self, files: list[FileData], a: Airframe, lowpass_hz: float = LOWPASS_HZ):
        from scipy import signal   # here, not at the top: `flightctl sim` imports the causes for their effects
        self.files, self.a = files, a
        self.fs = 1.0 / float(np.median(np.concatenate([np.diff(f.t) for f in files])))
        self.sos = signal.butter(2, lowpass_hz, fs=self.fs, output="sos")
        # the stretches: (file index, start, stop) of input rows
        self.stretches = [(i, s0, s1) for i, f in enumerate(files) for s0, s1 in stretches(f.airborne)]
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
        self.carried: dict[str, np.ndarray] = {}     # cause -> its filtered term in the base prediction
        self.carried_parameters: dict[str, dict] = {}

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
        return np.concatenate([per_file[i][..., s0:s1] for i, s0, s1 in self.stretches], axis=-1)

    def flat_filtered(self, per_file):
        """The stretches of per-file (C, n) arrays, each stretch low-passed forward and backward."""
        from scipy import signal
        parts = []
        for i, s0, s1 in self.stretches:
            x = per_file[i][..., s0:s1]
            if x.ndim == 2:      # rows that are zero stay zero: filter only the others (speed)
                y = np.zeros_like(x)
                rows = np.flatnonzero(np.any(x != 0.0, axis=1))
                if rows.size:
                    y[rows] = signal.sosfiltfilt(self.sos, x[rows], axis=-1)
                parts.append(y)
            else:
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
        w = rotor_speed(F, a.c1)                                                # eq. 27
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


