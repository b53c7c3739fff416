"""A check of the diagnosis against the log's own rotor speeds, where the log has them (ESC
telemetry, `omega1..omega4`; docs/real-flights.md).

The diagnosis measures the actuation from the gyro and the accelerometer alone. A log that also
measured each rotor's speed shows the same lag directly: the command P through a first-order lag of
time constant tau and a pure delay, against the measured speed, affine per rotor (Omega = a (P - h2)
by eq. 26 and 27: a scale and an offset for each rotor). Fitted by least squares over a grid, on the
airborne rows only.
"""
from __future__ import annotations

import math

import numpy as np

from flightctl.sim.causes.actuation_delay import shift
from flightctl.sim.causes.motor_lag import lag_held
from flightctl.sim.identify.diagnose.data import FileData

TAUS = np.arange(0.0, 0.1005, 0.001)        # s
DELAYS = np.arange(0.0, 0.0105, 0.001)      # s


def rotor_speed_lag(files: list[FileData]) -> dict | None:
    """{tau, delay, rmse, per_motor_tau, samples} of the lag from commanded to measured rotor speed,
    or None when no log has rotor speeds."""
    have = [f for f in files if f.omega is not None and np.isfinite(f.omega[:, f.airborne]).all()
            and f.airborne.any() and np.abs(f.omega[:, f.airborne]).max() > 0]
    if not have:
        return None
    fs = 1.0 / float(np.median(np.concatenate([np.diff(f.t) for f in have])))

    def rows(tau, delay):
        """(commanded speed through the lag and delay, measured speed) on the airborne rows, (4, n)."""
        xs, ys = [], []
        for f in have:
            U = shift(f.P, delay * fs)
            if tau > 0:
                U = lag_held(U, tau, fs)[0]
            xs.append(U[:, f.airborne])
            ys.append(f.omega[:, f.airborne])
        return np.concatenate(xs, axis=1), np.concatenate(ys, axis=1)

    def err(tau, delay):
        x, y = rows(tau, delay)
        x = x - x.mean(axis=1, keepdims=True)                               # an offset per rotor
        y = y - y.mean(axis=1, keepdims=True)
        k = np.einsum("mn,mn->m", x, y) / np.einsum("mn,mn->m", x, x)      # and a scale
        e = y - k[:, None] * x
        return np.sqrt(np.mean(e * e, axis=1))

    best = min(((float(err(t, d).mean()), t, d) for t in TAUS[::5] for d in DELAYS[::2]))
    _, t0, d0 = best
    fine = [(float(err(t, d).mean()), t, d) for t in TAUS[(TAUS >= t0 - 0.005) & (TAUS <= t0 + 0.005)]
            for d in DELAYS[(DELAYS >= d0 - 0.002) & (DELAYS <= d0 + 0.002)]]
    rmse, tau, delay = min(fine)
    per_motor = []
    for m in range(4):
        per_motor.append(float(TAUS[int(np.argmin([err(t, delay)[m] for t in TAUS]))]))
    return {"tau": round(float(tau), 4), "delay": round(float(delay), 4), "rmse": round(rmse, 2),
            "per_motor_tau": [round(t, 4) for t in per_motor], "samples": int(sum(f.airborne.sum() for f in have)),
            "what": "first-order lag and pure delay from the commanded rotor speed (P - h2) to the measured "
                    "rotor speed, fitted on the airborne rows"}
