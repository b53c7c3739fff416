"""PX4's ULog (`.ulg`) through pyulog (docs/log-import.md has each topic, unit and frame).

PX4's body frame is x forward, y right, z down (FRD), its earth frame North-East-Down: to ours (x
forward, y left, z up; North, West, Up) y and z change sign, and the accelerometer's specific force
reads -g on z at rest in FRD, +g in ours. `sensor_combined` is the time base (the gyro's).

What the vehicle is comes from the log's own description (`px4motors`): the airframe (MAV_TYPE,
CA_AIRFRAME, SYS_AUTOSTART), the rotors (CA_ROTOR*), the output functions and their ranges, and
which outputs move while armed.
"""
from __future__ import annotations

import contextlib
import io
import math
import re
import struct
from collections import Counter

import numpy as np

from flightctl.errors import InputError

from flightctl.files import read_bytes
from flightctl.sim.logs import controller
from flightctl.sim.logs import identity
from flightctl.sim.logs.common import (FRD, Imported, Stream, euler_from_frd_ned, log_text, parser_said,
                                      rate_notes)

ARMED = 2                                    # vehicle_status.arming_state ARMED (every PX4 version)
RANGE_MAX_M = 10.0                           # the contract's rangefinder range
DOWNWARD = 25                                # distance_sensor.orientation ROTATION_DOWNWARD_FACING
PROFILE_NOTE = ("set SDLOG_PROFILE bit 4 (High rate: add 16, e.g. 17) or bit 3 "
                "(System identification: add 8) and reboot")


def _ulog(path: str):
    """(pyulog's ULog of `path`, the lines pyulog printed while reading it). pyulog prints its warnings
    on stdout (pyulog/core.py: `print('Warning: no subscription found for message id ...')`, "File
    corruption detected while reading file data!"): they are taken here, never left on our stdout, and
    said in the import's notes (`pyulog: ...` in `# import_notes`)."""
    try:
        from pyulog import ULog
    except ImportError:
        raise InputError(f"{path}: reading a ULog needs the logs extra: pip install '.[logs]' (from the checkout)") from None
    said = io.StringIO()
    try:
        with contextlib.redirect_stdout(said):
            u = ULog(path)
    except Exception as e:             # pyulog raises what the bytes give it: a truncated or foreign file
        raise InputError(f"{path}: not a readable ULog ({parser_said(e)})") from None
    return u, [line.strip() for line in said.getvalue().splitlines() if line.strip()]


def topic(u, name: str, instance: int | None = None):
    """The data of a topic's instance (the lowest when None), or None."""
    sets = [d for d in u.data_list if d.name == name and (instance is None or d.multi_id == instance)]
    return min(sets, key=lambda d: d.multi_id).data if sets else None


def armed_times(u) -> tuple[np.ndarray, np.ndarray] | None:
    """(times, armed 0/1) from actuator_armed, else vehicle_status.arming_state; None when neither."""
    aa = topic(u, "actuator_armed")
    if aa is not None and "armed" in aa:
        return aa["timestamp"] * 1e-6, aa["armed"].astype(bool)
    vs = topic(u, "vehicle_status")
    if vs is not None and "arming_state" in vs:
        return vs["timestamp"] * 1e-6, vs["arming_state"] == ARMED
    return None


def read(path: str) -> Imported | str:
    """A PX4 ULog as an `Imported`; the project's own ULog (`flightctl log export`) as the flight-log
    text it was written from, column for column (sim/logs/own.py)."""
    from flightctl.sim.logs import own, px4motors
    u, said = _ulog(path)
    if own.is_own(u):
        return log_text(*own.read(u, path, damaged(u, path), said))
    imp = Imported(path, {}, {}, [])
    p = u.initial_parameters
    # never armed is said first: a log of a board on the bench says nothing of its vehicle's flight, and
    # its layout is often not set up yet (CA_ROTOR* missing would be refused as an unknown layout)
    armed = armed_times(u)
    if armed is not None and not armed[1].any():
        imp.fail("never armed: the motors did not run in this log (actuator_armed / vehicle_status.arming_state)")
    rotors, source, count = px4motors.vehicle(u, p, imp)   # refuses what is no multirotor it takes, names why
    sc = topic(u, "sensor_combined")
    if sc is None or "gyro_rad[0]" not in sc:
        imp.fail("no sensor_combined topic: the gyro was not logged")
    t = sc["timestamp"] * 1e-6
    g = np.vstack([sc[f"gyro_rad[{i}]"] for i in range(3)]).astype(float)
    a = np.vstack([sc[f"accelerometer_m_s2[{i}]"] for i in range(3)]).astype(float)
    imp.streams["gyro"] = Stream("sensor_combined gyro", t, g * FRD)
    imp.notes += [f"pyulog: {line}" for line in dict.fromkeys(said)]
    if (damage := damaged(u, path)) is not None:
        imp.meta["damaged"] = damage
        imp.notes.append(f"damaged: {damage}")
    ta = t + sc.get("accelerometer_timestamp_relative", np.zeros(t.size)) * 1e-6
    imp.streams["acc"] = Stream("sensor_combined accelerometer", ta, a * FRD)
    imp.streams["motors"] = px4motors.motors(u, p, imp, armed, count)
    rate_notes(imp, "motor commands", PROFILE_NOTE)
    _measurements(u, p, imp)
    cutoff = float(p.get("IMU_GYRO_CUTOFF", 0) or 0)
    info = u.msg_info_dict
    imp.meta.update({
        "vehicle": "foreign", "format": "px4 ulog", "source": path,
        "firmware": f"PX4 {info.get('ver_sw_release', '')} {str(info.get('ver_sw', ''))[:8]} {info.get('ver_hw', '')}".strip(),
        "craft": str(info.get("sys_name", "")),
        "rotors": rotors, "rotors_source": source,
        "gyro_source": ("sensor_combined.gyro_rad: the integrated raw gyro (IMU_GYRO_CUTOFF "
                        f"{cutoff:g} Hz filters the controller's copy, not this one)"),
        "gyro_filter": "none", "acc_source": "sensor_combined.accelerometer_m_s2", "acc_filter": "none",
    })
    imp.meta["controller"] = controller.encode(controller.px4(p))
    gps = topic(u, "vehicle_gps_position")
    imp.meta.update(identity.px4(info, gps if gps is not None else topic(u, "sensor_gps")))
    return imp


def _in_file(raw: bytes, msg_id: int) -> int:
    """How many data messages of subscription `msg_id` the file holds: the 5 bytes that open each one
    (its size, 'D', the id: ULog's message header and data message, docs.px4.io's ulog_file_format),
    counted over the whole file, so that the messages after a damaged one are found where pyulog's
    reading lost its place. The size is the one most of the id's headers have."""
    key = b"D" + struct.pack("<H", msg_id)
    sizes = Counter(raw[m.start() - 2:m.start()] for m in re.finditer(re.escape(key), raw) if m.start() >= 2)
    return raw.count(sizes.most_common(1)[0][0] + key) if sizes else 0


def damaged(u, path: str) -> str | None:
    """What pyulog found damaged (None when nothing), for `# damaged:` (diagnose's report says it too).
    pyulog skips a data message it cannot place (an unknown message id, a size that does not fit its
    format) and, having lost its place, what follows until a message fits again, raising only
    `file_corruption` (pyulog/core.py: `_file_corrupt`, set in `_read_file_data`,
    `_MessageData.initialize` and `_check_packet_corruption`), without a count: the messages it skipped
    are counted here, each topic's in the file (`_in_file`) less those pyulog read."""
    if not u.file_corruption:
        return None
    raw = read_bytes(path)
    skipped = {d.name: max(0, _in_file(raw, d.msg_id) - len(d.data["timestamp"])) for d in u.data_list}
    rows = skipped.get("sensor_combined", 0)
    return (f"pyulog found corrupt data and skipped {sum(skipped.values())} whole data messages after it, "
            f"{rows} of them sensor_combined's: {rows} rows lost (its file_corruption flag)")


def _measurements(u, p: dict, imp: Imported) -> None:
    """Battery, heights, attitude, rotor speeds, the rate setpoint, the battery's cells."""
    bs = topic(u, "battery_status")
    if bs is not None:
        tb = bs["timestamp"] * 1e-6
        v = bs["voltage_v"].astype(float)
        ok = v > 0.5                     # 0 until the first reading
        imp.streams["battery_v"] = Stream("battery_status voltage", tb[ok], v[None, ok])
        if "current_a" in bs and np.any(bs["current_a"] > 0):
            imp.streams["current"] = Stream("battery_status current", tb, bs["current_a"][None].astype(float))
    for name in ("BAT1_N_CELLS", "BAT_N_CELLS"):
        if int(p.get(name, 0) or 0) > 0:
            imp.meta["battery_cells"] = str(int(p[name]))
            imp.meta["battery_cells_source"] = f"PX4 parameter {name}"
            break
    air = topic(u, "vehicle_air_data")
    imp.meta["height_source"] = "none"
    if air is not None and "baro_alt_meter" in air:
        imp.streams["height"] = Stream("vehicle_air_data baro (above sea level)", air["timestamp"] * 1e-6,
                                       air["baro_alt_meter"][None].astype(float))
        imp.meta["height_source"] = "baro"
    ds = topic(u, "distance_sensor")
    if ds is not None and "current_distance" in ds:
        down = ds["orientation"] == DOWNWARD if "orientation" in ds else np.ones(len(ds["timestamp"]), bool)
        d = ds["current_distance"]
        lo, hi = ds.get("min_distance", np.zeros(d.size)), ds.get("max_distance", np.full(d.size, RANGE_MAX_M))
        down &= (d > lo) & (d < np.minimum(hi, RANGE_MAX_M))      # out of range: no echo (docs/measured-data.md: 0-10 m)
        if down.any():
            imp.streams["range"] = Stream("distance_sensor (downward)", ds["timestamp"][down] * 1e-6,
                                          ds["current_distance"][None, down].astype(float))
    lp = topic(u, "vehicle_local_position")
    if lp is not None and "z" in lp:
        imp.streams["alt"] = Stream("vehicle_local_position z", lp["timestamp"] * 1e-6, -lp["z"][None].astype(float))
    att = topic(u, "vehicle_attitude")
    if att is not None:
        q = np.vstack([att[f"q[{i}]"] for i in range(4)]).astype(float)
        imp.streams["attitude"] = Stream("vehicle_attitude", att["timestamp"] * 1e-6, euler_from_frd_ned(q))
    asp = topic(u, "vehicle_attitude_setpoint")
    if asp is not None and all(f"q_d[{i}]" in asp for i in range(4)):
        q = np.vstack([asp[f"q_d[{i}]"] for i in range(4)]).astype(float)
        e = euler_from_frd_ned(q)
        e[2] = np.unwrap(e[2])
        imp.streams["attitude_sp"] = Stream("vehicle_attitude_setpoint q_d", asp["timestamp"] * 1e-6, e)
    rs = topic(u, "vehicle_rates_setpoint")
    if rs is not None and all(k in rs for k in ("roll", "pitch", "yaw")):
        sp = np.vstack([rs[k] for k in ("roll", "pitch", "yaw")]).astype(float)
        imp.streams["setpoint"] = Stream("vehicle_rates_setpoint", rs["timestamp"] * 1e-6, sp * FRD)
    land = topic(u, "vehicle_land_detected")
    if land is not None and "landed" in land:
        ok = land["timestamp"] >= u.start_timestamp                  # (a first sample stamped 0 is none)
        if ok.any():
            imp.streams["landed"] = Stream("vehicle_land_detected landed", land["timestamp"][ok] * 1e-6,
                                           land["landed"][ok][None].astype(float), held=True)
            imp.meta["landed_source"] = "PX4's vehicle_land_detected.landed"
    esc = topic(u, "esc_status")
    n = imp.streams["motors"].values.shape[0]
    order = imp.meta.pop("esc_order", None)
    idx = [int(k) for k in order.split()] if order else list(range(n))
    if esc is not None and not all(f"esc[{i}].esc_rpm" in esc for i in idx):
        imp.notes.append(f"esc_status holds no esc_rpm for esc[{','.join(map(str, idx))}] (the {n} motors' ESCs): "
                         "no rotor speeds")
    elif esc is not None:
        rpm = np.vstack([esc[f"esc[{i}].esc_rpm"] for i in idx]).astype(float)
        if np.any(rpm != 0):
            imp.streams["omega"] = Stream("esc_status rpm", esc["timestamp"] * 1e-6, np.abs(rpm) * 2.0 * math.pi / 60.0)
            imp.meta["omega_source"] = (f"esc_status esc[{','.join(map(str, idx))}].esc_rpm (the ESCs' telemetry, "
                                        f"rpm) for motors 1-{n}")
        else:
            imp.notes.append("esc_status rpm are all zero: no rotor speeds")
