"""A check of the diagnosis against the log's own rotor speeds, where the log has them (ESC
telemetry, `omega1..omega4`; docs/real-flights.md).

The diagnosis measures the actuation from the gyro and the accelerometer alone. A log that also
measured each rotor's speed shows the same lag directly: the command P through a first-order lag of
time constant tau and a pure delay, against the measured speed, affine per rotor (Omega = a (P - h2)
by eq. 26 and 27: a scale and an offset for each rotor). Fitted by least squares over a grid, on the
airborne rows only.
"""
from __future__ import annotations


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

    def fit(tau, delay):
        """(RMSE per rotor, h2 per rotor) of Omega = a (x - h2), x the lagged command."""
        x, y = rows(tau, delay)
        xm, ym = x.mean(axis=1, keepdims=True), y.mean(axis=1, keepdims=True)
        k = np.einsum("mn,mn->m", x - xm, y - ym) / np.einsum("mn,mn->m", x - xm, x - xm)
        e = (y - ym) - k[:, None] * (x - xm)
        return np.sqrt(np.mean(e * e, axis=1)), (xm[:, 0] - ym[:, 0] / k)

    def err(tau, delay):
        return fit(tau, delay)[0]

    best = min(((float(err(t, d).mean()), t, d) for t in TAUS[::5] for d in DELAYS[::2]))
    _, t0, d0 = best
    fine = [(float(err(t, d).mean()), t, d) for t in TAUS[(TAUS >= t0 - 0.005) & (TAUS <= t0 + 0.005)]
            for d in DELAYS[(DELAYS >= d0 - 0.002) & (DELAYS <= d0 + 0.002)]]
    rmse, tau, delay = min(fine)
    errs = np.array([err(t, delay) for t in TAUS[::2]])        # (taus, 4)
    per_motor = [float(TAUS[::2][j]) for j in np.argmin(errs, axis=0)]
    h2 = fit(tau, delay)[1]
    return {"tau": round(float(tau), 4), "delay": round(float(delay), 4), "rmse": round(rmse, 2),
            "per_motor_tau": [round(t, 4) for t in per_motor], "h2": round(float(np.median(h2)), 1),
            "h2_spread": round(float(np.std(h2)), 1), "samples": int(sum(f.airborne.sum() for f in have)),
            "what": "first-order lag and pure delay from the command to the measured rotor speed, "
                    "Omega = a (P - h2) per rotor (eq. 26, 27), fitted on the airborne rows"}
