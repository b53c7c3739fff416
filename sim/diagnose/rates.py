"""The rates a log was written at, against what the dynamic tier needs (dataset.DYNAMIC_MIN_HZ), and
what its autopilot's logger needs to log faster (the reader's `# log_faster:` line)."""
from __future__ import annotations

import numpy as np

from flightctl.errors import InputError
from flightctl.logfile import Table
from flightctl.sim.diagnose.dataset import DYNAMIC_MIN_HZ


def motor_rate(tables: list[Table]) -> float | None:
    """The slowest motor-output rate any log declares (`# motor_rate_hz:`), or None."""
    rates = []
    for t in tables:
        try:
            rates.append(float(t.meta["motor_rate_hz"]))
        except (KeyError, ValueError):
            pass
    return min(rates) if rates else None


def faster(tables: list[Table]) -> str:
    """'; to log them faster: ...' from a log's `# log_faster:` line (what its autopilot's logger needs), or ''."""
    how = next((t.meta["log_faster"] for t in tables if t.meta.get("log_faster")), "")
    return f"; to log them faster: {how}" if how else ""


def sensor_rate(tables: list[Table], files) -> None:
    """InputError when the gyro and accelerometer were not logged (`# imu: none: why`), or slower than
    DYNAMIC_MIN_HZ: a quadrotor's motion under control has tens of Hz, and samples this sparse, each one
    reading and not an average over its period, alias it (and the motors' vibration) into what is left
    (docs/real-flights.md)."""
    if blind := [t for t, f in zip(tables, files) if not f.imu]:
        raise InputError(f"{blind[0].path}: no gyro or accelerometer logged ({blind[0].meta['imu'][6:]}): not judged")
    rate = min(1.0 / float(np.median(np.diff(f.t))) for f in files)
    if rate < DYNAMIC_MIN_HZ:
        raise InputError(f"{', '.join(t.path for t in tables)}: its gyro and accelerometer were logged at {rate:.1f} Hz: "
                         f"too slow to follow the vehicle's motion, which needs them at {DYNAMIC_MIN_HZ:g} Hz or more"
                         + faster(tables) + "; not judged")
