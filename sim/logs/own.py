"""The project's own ULog (`flightctl log export`) read back as the flight log it was written from.

The export (sim/logs/export.py) writes PX4's topics for PX4's tools, and marks the file as
flightctl's own with four information messages: `sys_name` flightctl, `flightctl_columns` (the CSV's
header row), `flightctl_meta` (its `# key: value` lines, as JSON) and `flightctl_t0_us` (what its
timestamps add to `t`, us). Each column has one home (`HOMES`): a PX4 topic's field where the field
is the column up to a sign or a unit (PX4's frames: FRD and NED, y and z negated, flightctl/comms/
frames.py; Gauss to tesla), else the flightctl topic `flightctl_log`, which holds the column as the
CSV has it: the Euler angles (PX4 has the attitude as quaternions only, vehicle_attitude.q and
vehicle_attitude_setpoint.q_d, and the setpoint's Euler angles of PX4 before 1.14 with the yaw
wrapped), the sticks (input_rc holds whole microseconds) and any other column.

ULog stores these fields as float32: a column comes back to float32's precision (half a unit in
the last place: 2^-24 of the value), which, as the CSV writes 6 significant digits
(FlightLogWriter's %.6g, and float32 keeps any 6: FLT_DIG), is the value the CSV held; `t` is whole
microseconds in the timestamps, as the CSV writes it (%.6f), and comes back exactly.
"""
from __future__ import annotations

import json

import numpy as np

from flightctl.errors import InputError
from flightctl.logfile import FLIGHT_COLUMNS, IMU_COLUMNS

NAME = "flightctl"                     # the `sys_name` information message of the project's own ULog
OWN_TOPIC = "flightctl_log"            # the columns without a PX4 home, as the CSV has them
FRD = (1.0, -1.0, -1.0)                # ours to FRD / NED and back: y and z change sign (frames.py)
GAUSS_T = 1e-4                         # PX4's magnetometer is in Gauss (msg/VehicleMagnetometer.msg)

# column -> (PX4 topic, field, scale): column = field x scale. The topics' fields are PX4's (msg/*.msg of
# PX4-Autopilot: SensorCombined, ActuatorMotors, DistanceSensor, BatteryStatus, VehicleLocalPosition,
# VehicleLocalPositionSetpoint, VehicleMagnetometer, VehicleRatesSetpoint).
HOMES: dict[str, tuple[str, str, float]] = {
    **{f"P{i + 1}": ("actuator_motors", f"control[{i}]", 255.0) for i in range(4)},    # PX4's P / 255
    **{f"gyro_{a}": ("sensor_combined", f"gyro_rad[{i}]", s) for i, (a, s) in enumerate(zip("xyz", FRD))},
    **{f"acc_{a}": ("sensor_combined", f"accelerometer_m_s2[{i}]", s) for i, (a, s) in enumerate(zip("xyz", FRD))},
    "range": ("distance_sensor", "current_distance", 1.0),
    "battery_v": ("battery_status", "voltage_v", 1.0),
    "current": ("battery_status", "current_a", 1.0),
    "alt": ("vehicle_local_position", "z", -1.0),
    "alt_sp": ("vehicle_local_position_setpoint", "z", -1.0),
    **{f"mag_{a}": ("vehicle_magnetometer", f"magnetometer_ga[{i}]", s * GAUSS_T) for i, (a, s) in enumerate(zip("xyz", FRD))},
    **{f"true_{a}": ("vehicle_local_position_groundtruth", a, s) for a, s in zip("xyz", FRD)},
    **{f"setpoint_{a}": ("vehicle_rates_setpoint", k, s) for a, k, s in zip("xyz", ("roll", "pitch", "yaw"), FRD)},
}
# topics with a sample only on the rows where one of their columns has a value (an echo, a reading)
SPARSE = ("distance_sensor", "battery_status", "vehicle_magnetometer")


def own_columns(columns) -> list[str]:
    """The columns of a log that `flightctl_log` holds: those without a PX4 home, `t` apart."""
    return [c for c in columns if c != "t" and c not in HOMES]


def is_own(u) -> bool:
    """A ULog that `flightctl log export` wrote (and so can be read back whole)."""
    info = u.msg_info_dict
    return str(info.get("sys_name", "")) == NAME and "flightctl_columns" in info


def read(u, path: str, damaged: str | None, said: list[str]) -> tuple[dict[str, str], dict[str, np.ndarray], tuple[str, ...]]:
    """(the metadata, the columns, the extra columns in the CSV's order) of the project's own ULog.
    The rows are sensor_combined's samples; each column is taken from its home's samples at the rows'
    timestamps (a sparse topic's at its own rows). Rows that lost a sample a column needs (a damaged
    file whose data messages pyulog skipped: `damaged`, the damage already counted) are dropped and
    counted in `# damaged:` too."""
    from flightctl.sim.logs.ulog import topic
    info = u.msg_info_dict
    try:
        columns = str(info["flightctl_columns"]).split(",")
        meta = {str(k): str(v) for k, v in json.loads(str(info.get("flightctl_meta", "{}"))).items()}
        t0 = int(str(info.get("flightctl_t0_us", "0")))
    except (ValueError, AttributeError):
        raise InputError(f"{path}: its flightctl_columns, flightctl_meta or flightctl_t0_us information "
                         "message is damaged") from None
    base = topic(u, "sensor_combined")
    if base is None or columns[:1] != ["t"]:
        raise InputError(f"{path}: flightctl's ULog without sensor_combined or a 't' column: damaged")
    ts = base["timestamp"].astype(np.int64)
    n = ts.size
    cols = {"t": (ts - t0) * 1e-6}
    for c in columns[1:]:
        name, field, scale = HOMES.get(c, (OWN_TOPIC, c, 1.0))
        out = np.full(n, np.nan)
        d = topic(u, name)
        if d is not None and field in d and n:
            at = d["timestamp"].astype(np.int64)
            i = np.clip(np.searchsorted(ts, at), 0, n - 1)
            ok = ts[i] == at
            out[i[ok]] = d[field][ok].astype(float) * scale
        cols[c] = out
    needed = [c for c in ("P1", "P2", "P3", "P4") + (() if "imu" in meta else IMU_COLUMNS) if c in cols]
    keep = np.ones(n, bool)
    for c in needed:
        keep &= np.isfinite(cols[c])
    lost = int((~keep).sum())
    if lost or damaged:
        cols = {k: v[keep] for k, v in cols.items()}
        meta["damaged"] = "; ".join(filter(None, [damaged, lost and f"{lost} rows without a command or an IMU "
                                                                   "sample dropped"]))
    if said:
        meta["import_notes"] = "\n".join(filter(None, [meta.get("import_notes")] +
                                                [f"pyulog: {line}" for line in dict.fromkeys(said)]))
    extra = tuple(c for c in columns[1:] if c not in FLIGHT_COLUMNS)
    return meta, cols, extra
