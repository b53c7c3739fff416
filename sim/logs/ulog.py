"""PX4's ULog (`.ulg`) through pyulog (docs/log-import.md has each topic, unit and frame).

PX4's body frame is x forward, y right, z down (FRD), its earth frame North-East-Down: to ours (x
forward, y left, z up; North, West, Up) y and z change sign, and the accelerometer's specific force
reads -g on z at rest in FRD, +g in ours. `sensor_combined` is the time base (the gyro's).
"""
from __future__ import annotations

import math

import numpy as np

from flightctl.sim.logs.common import Imported, Stream

# PX4's quad X (the airframes without CA_ROTOR* parameters): motor 1 front right, 2 rear left, 3 front
# left, 4 rear right, in FRD (x, y); 1 and 2 counter-clockwise.
PX4_QUAD_X = ((1.0, 1.0, 1.0), (-1.0, -1.0, 1.0), (1.0, -1.0, -1.0), (-1.0, 1.0, -1.0))
QUADROTOR = 2                                    # MAV_TYPE


def _ulog(path: str):
    try:
        from pyulog import ULog
    except ImportError:
        from flightctl.errors import InputError
        raise InputError(f"{path}: reading a ULog needs the logs extra: pip install '.[logs]' (from the checkout)")
    from flightctl.errors import InputError
    try:
        return ULog(path)
    except Exception as e:             # pyulog raises what the bytes give it: a truncated or foreign file
        raise InputError(f"{path}: not a readable ULog ({type(e).__name__}: {e})") from None


def _topic(u, name: str):
    """The data of the first instance of a topic, or None."""
    sets = [d for d in u.data_list if d.name == name]
    return min(sets, key=lambda d: d.multi_id).data if sets else None


def _motor_rows(ao: dict) -> np.ndarray:
    """The rows of actuator_outputs that carry the motors: two publishers may share instance 0 (the
    main and the auxiliary outputs, told apart by `noutputs`); the motors' group is the one whose
    first four outputs vary most over the log."""
    groups = {int(k): ao["noutputs"] == k for k in np.unique(ao["noutputs"])}
    out = np.vstack([ao[f"output[{i}]"] for i in range(4)])
    return max(groups.values(), key=lambda rows: float(out[:, rows].std(axis=1).sum()) if rows.sum() > 1 else -1.0)


def _layout(u, imp: Imported) -> tuple[str, str]:
    """(`rotors` metadata, its source): CA_ROTOR* parameters, or the quad X of older airframes."""
    p = u.initial_parameters
    if "CA_ROTOR_COUNT" in p:
        count = int(p["CA_ROTOR_COUNT"])
        if count != 4:
            imp.fail(f"CA_ROTOR_COUNT = {count}: diagnose knows quadrotors (4)")
        rotors = []
        for i in range(4):
            x, y, km = (float(p.get(f"CA_ROTOR{i}_{k}", math.nan)) for k in ("PX", "PY", "KM"))
            if not all(math.isfinite(v) for v in (x, y, km)) or km == 0:
                imp.fail(f"CA_ROTOR{i}_PX/PY/KM missing or zero: the rotor layout is unknown")
            rotors.append((x, y, 1.0 if km > 0 else -1.0))      # KM > 0: counter-clockwise (PX4's control allocation)
        arm = max(math.hypot(x, y) for x, y, _ in rotors)
        source = "PX4's CA_ROTOR{0..3}_PX/PY/KM parameters (FRD positions, KM > 0 counter-clockwise)"
    else:
        mav = int(p.get("MAV_TYPE", -1))
        if mav != QUADROTOR:
            imp.fail(f"MAV_TYPE = {mav} and no CA_ROTOR* parameters: not a quadrotor this reader knows")
        rotors, arm = list(PX4_QUAD_X), math.sqrt(2.0)
        source = (f"PX4's quad X for SYS_AUTOSTART {int(p.get('SYS_AUTOSTART', 0))} (MAV_TYPE 2, no CA_ROTOR* "
                  "parameters): motor 1 front right, 2 rear left, 3 front left, 4 rear right; 1 and 2 counter-clockwise")
    text = "; ".join(f"{x / arm:.4f} {-y / arm:.4f} {s:+.0f}" for x, y, s in rotors)     # FRD y to our y
    return text, source


def read(path: str) -> Imported:
    u = _ulog(path)
    imp = Imported(path, {}, {}, [])
    sc = _topic(u, "sensor_combined")
    if sc is None or "gyro_rad[0]" not in sc:
        imp.fail("no sensor_combined topic: the gyro was not logged")
    t = sc["timestamp"] * 1e-6
    g = np.vstack([sc[f"gyro_rad[{i}]"] for i in range(3)]).astype(float)
    a = np.vstack([sc[f"accelerometer_m_s2[{i}]"] for i in range(3)]).astype(float)
    imp.streams["gyro"] = Stream("sensor_combined gyro", t, g * np.array([[1.0], [-1.0], [-1.0]]))
    ta = t + sc.get("accelerometer_timestamp_relative", np.zeros(t.size)) * 1e-6
    imp.streams["acc"] = Stream("sensor_combined accelerometer", ta, a * np.array([[1.0], [-1.0], [-1.0]]))
    ao = _topic(u, "actuator_outputs")
    if ao is None:
        imp.fail("no actuator_outputs topic: the motor commands were not logged")
    rows = _motor_rows(ao)
    nout = np.vstack([ao[f"output[{i}]"] for i in range(8) if f"output[{i}]" in ao])
    if int(ao["noutputs"][rows].max()) > 4 or (nout.shape[0] > 4 and np.ptp(nout[4:, rows]) > 0):
        imp.fail("more than 4 motor outputs in use: diagnose knows quadrotors (4)")
    p = u.initial_parameters
    lo = [p.get(f"PWM_MAIN_MIN{i}", -1) for i in range(1, 5)]
    hi = [p.get(f"PWM_MAIN_MAX{i}", -1) for i in range(1, 5)]
    lo = np.array([v if v > 0 else p.get("PWM_MAIN_MIN", 1000) for v in lo], dtype=float)[:, None]
    hi = np.array([v if v > 0 else p.get("PWM_MAIN_MAX", 2000) for v in hi], dtype=float)[:, None]
    raw = np.vstack([ao[f"output[{i}]"][rows] for i in range(4)]).astype(float)
    P = 255.0 * (raw - lo) / (hi - lo)
    clipped = int(((P < 0) | (P > 255)).any(axis=0).sum())
    if clipped:
        imp.notes.append(f"{clipped} actuator_outputs samples outside PWM_MAIN_MIN..MAX (stopped or disarmed: 0) "
                         "clipped to 0-255")
    imp.streams["motors"] = Stream("actuator_outputs", ao["timestamp"][rows] * 1e-6, np.clip(P, 0.0, 255.0), held=True)
    bs = _topic(u, "battery_status")
    if bs is not None:
        tb = bs["timestamp"] * 1e-6
        imp.streams["battery_v"] = Stream("battery_status voltage", tb, bs["voltage_v"][None].astype(float))
        if np.any(bs["current_a"] > 0):
            imp.streams["current"] = Stream("battery_status current", tb, bs["current_a"][None].astype(float))
    air = _topic(u, "vehicle_air_data")
    height_source = "none"
    if air is not None:
        imp.streams["height"] = Stream("vehicle_air_data baro", air["timestamp"] * 1e-6,
                                       air["baro_alt_meter"][None].astype(float))
        height_source = "baro"
    lp = _topic(u, "vehicle_local_position")
    if lp is not None:
        imp.streams["alt"] = Stream("vehicle_local_position z", lp["timestamp"] * 1e-6, -lp["z"][None].astype(float))
    att = _topic(u, "vehicle_attitude")
    if att is not None:
        from flightctl.sim.logs.blackbox import _euler_from_frd_ned
        q = np.vstack([att[f"q[{i}]"] for i in range(4)]).astype(float)
        imp.streams["attitude"] = Stream("vehicle_attitude", att["timestamp"] * 1e-6, _euler_from_frd_ned(q))
    esc = _topic(u, "esc_status")
    if esc is not None and all(f"esc[{i}].esc_rpm" in esc for i in range(4)):
        rpm = np.vstack([esc[f"esc[{i}].esc_rpm"] for i in range(4)]).astype(float)
        if np.any(rpm != 0):
            imp.streams["omega"] = Stream("esc_status rpm", esc["timestamp"] * 1e-6, rpm * 2.0 * math.pi / 60.0)
        else:
            imp.notes.append("esc_status rpm are all zero: no rotor speeds")
    rotors, source = _layout(u, imp)
    cutoff = float(p.get("IMU_GYRO_CUTOFF", 0) or 0)
    info = u.msg_info_dict
    imp.meta.update({
        "vehicle": "foreign", "format": "px4 ulog", "source": path,
        "firmware": f"PX4 {info.get('ver_sw_release', '')} {str(info.get('ver_sw', ''))[:8]} {info.get('ver_hw', '')}".strip(),
        "craft": str(info.get("sys_name", "")),
        "rotors": rotors, "rotors_source": source,
        "command_range": f"{lo.min():g} {hi.max():g}",
        "command": "P = 255 (pwm - PWM_MAIN_MIN) / (PWM_MAIN_MAX - PWM_MAIN_MIN): actuator_outputs in us",
        "gyro_source": ("sensor_combined.gyro_rad: the integrated raw gyro (IMU_GYRO_CUTOFF "
                        f"{cutoff:g} Hz filters the controller's copy, not this one)"),
        "gyro_filter": "none", "acc_source": "sensor_combined.accelerometer_m_s2", "acc_filter": "none",
        "height_source": height_source,
    })
    return imp
