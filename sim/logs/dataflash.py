"""ArduPilot's DataFlash log (`.bin`, and its text form `.log`) through pymavlink's DFReader
(docs/log-import.md has each message, unit and frame).

ArduPilot's body frame is x forward, y right, z down (FRD), its earth frame North-East-Down: to ours
(x forward, y left, z up) y and z change sign; the accelerometer reads -g on z at rest in FRD. The
gyro's messages are the time base: `GYR` (the raw high-rate samples, where logged) else `IMU`.

The vehicle: the firmware (ArduCopter, ArduPlane, ...), FRAME_CLASS and FRAME_TYPE with ArduPilot's
motor positions and spins (AP_MotorsMatrix: motor angle from the nose, clockwise positive seen from
above; its yaw factor is the spin). The motors: SERVOn_FUNCTION 33-36 are motors 1-4, their pulses
in RCOU's Cn, mapped onto 0-255 over MOT_PWM_MIN..MAX (RC3_MIN..MAX when those are 0, as ArduCopter does).
"""
from __future__ import annotations

import math
import re

import numpy as np

from flightctl.errors import InputError
from flightctl.sim.logs.common import Imported, Stream, rate_notes

FRD = np.array([[1.0], [-1.0], [-1.0]])
DEG = math.pi / 180.0
MOTOR_FUNCTION = 33                    # SERVOn_FUNCTION of motor 1 (33-44: motors 1-12)
FRAME_CLASSES = {0: "an undefined frame", 2: "a hexacopter", 3: "an octocopter", 4: "an octo-quad (coaxial)",
                 5: "a Y6", 6: "a helicopter", 7: "a tricopter", 8: "a single-rotor vehicle", 9: "a coaxial copter",
                 10: "a tailsitter", 11: "a dual helicopter", 12: "a dodeca-hexa", 13: "a quad helicopter",
                 14: "a decacopter", 15: "a scripted frame", 16: "a scripted 6DoF frame", 17: "a scripted frame"}
QUAD = 1
# AP_MotorsMatrix's quad frames (FRAME_TYPE): per motor 1-4 (angle from the nose in degrees, clockwise
# positive; spin +1 counter-clockwise)
QUAD_FRAMES = {
    0: ("PLUS", ((90, 1), (-90, 1), (0, -1), (180, -1))),
    1: ("X", ((45, 1), (-135, 1), (-45, -1), (135, -1))),
    3: ("H", ((45, -1), (-135, -1), (-45, 1), (135, 1))),
    6: ("PLUSREV", ((90, -1), (-90, -1), (0, 1), (180, 1))),
    12: ("BF_X", ((135, -1), (45, 1), (-135, 1), (-45, -1))),
    13: ("DJI_X", ((45, 1), (-45, -1), (-135, 1), (135, -1))),
    14: ("CW_X", ((45, 1), (135, -1), (-135, 1), (-45, -1))),
    18: ("BF_X_REV", ((135, 1), (45, -1), (-135, -1), (-45, 1))),
}
RATE_NOTE = ("set LOG_BITMASK's IMU_FAST (and RCOUT) bits, or INS_RAW_LOG_OPT for "
             "the raw gyro (GYR)")
WANTED = ["PARM", "MSG", "VER", "IMU", "GYR", "ACC", "RCOU", "RCO2", "RCO3", "BAT", "BARO", "RFND", "ATT", "RATE",
          "ESC", "ARM", "EV"]


def _read(path: str, text: bool):
    try:
        from pymavlink import DFReader
    except ImportError:
        raise InputError(f"{path}: reading an ArduPilot log needs the logs extra: pip install '.[logs]' "
                         "(from the checkout)") from None
    try:
        r = (DFReader.DFReader_text if text else DFReader.DFReader_binary)(path, zero_time_base=False)
    except Exception as e:
        raise InputError(f"{path}: not a readable DataFlash log ({type(e).__name__}: {e})") from None
    msgs: dict[str, list] = {k: [] for k in WANTED}
    while True:
        try:
            m = r.recv_match(type=WANTED)
        except Exception as e:          # DFReader raises what the bytes give it: read up to there
            msgs.setdefault("_damage", []).append(f"{type(e).__name__}: {e}")
            break
        if m is None:
            break
        msgs[m.get_type()].append(m)
    return r.params, msgs


def _col(ms: list, name: str, instance: int | None = None, key: str = "I") -> np.ndarray:
    ms = [m for m in ms if instance is None or getattr(m, key, 0) == instance]
    return np.array([getattr(m, name) for m in ms], dtype=float)


def _pick(ms: list, key: str) -> list:
    """The messages of instance 0 (or the lowest logged) of a multi-instance message."""
    if not ms or not hasattr(ms[0], key):
        return ms
    first = min(getattr(m, key) for m in ms)
    return [m for m in ms if getattr(m, key) == first]


def _firmware(msgs) -> str:
    for m in msgs["VER"]:
        fws = getattr(m, "FWS", "")
        if fws:
            return str(fws)
    for m in msgs["MSG"]:
        text = str(getattr(m, "Message", ""))
        if re.match(r"Ardu\w+ V\d", text) or text.startswith(("ArduCopter", "ArduPlane", "ArduRover", "ArduSub", "Rover")):
            return text
    return ""


def _vehicle(p: dict, firmware: str, imp: Imported) -> tuple[str, str]:
    """(`rotors` metadata, its source) of a quadrotor; InputError naming what it is otherwise."""
    low = firmware.lower()
    if "plane" in low:
        imp.fail(f"{firmware}: " + ("a QuadPlane (VTOL, Q_ENABLE = 1)" if p.get("Q_ENABLE") else "a fixed wing")
                 + ", not a quadrotor: diagnose knows quadrotors (4)")
    if low.startswith(("rover", "ardurover", "ardusub", "antennatracker", "blimp")):
        imp.fail(f"{firmware}: not a multirotor: diagnose knows quadrotors (4)")
    cls = int(p.get("FRAME_CLASS", QUAD))
    if cls != QUAD:
        imp.fail(f"FRAME_CLASS = {cls}: {FRAME_CLASSES.get(cls, 'not a quadrotor')}, not a quadrotor: diagnose "
                 "knows quadrotors (4)")
    ftype = int(p.get("FRAME_TYPE", 1))
    if ftype not in QUAD_FRAMES:
        imp.fail(f"FRAME_TYPE = {ftype}: a quad frame whose geometry (V, V-tail, A-tail, Y4, no-yaw-torque) this "
                 "reader does not take")
    name, motors = QUAD_FRAMES[ftype]
    rotors = "; ".join(f"{math.cos(a * DEG):.4f} {-math.sin(a * DEG):.4f} {s:+d}" for a, s in motors)
    source = (f"ArduPilot's QUAD/{name} (FRAME_CLASS 1, FRAME_TYPE {ftype}; AP_MotorsMatrix): motors 1-4 at "
              + ", ".join(f"{a:+d} deg {'CCW' if s > 0 else 'CW'}" for a, s in motors) + " from the nose, clockwise positive")
    return rotors, source


def _motors(p: dict, msgs, imp: Imported) -> Stream:
    chan = {}
    for name, value in p.items():
        m = re.fullmatch(r"SERVO(\d+)_FUNCTION", name)
        if m and MOTOR_FUNCTION <= int(value) <= MOTOR_FUNCTION + 11:
            chan[int(value) - MOTOR_FUNCTION + 1] = int(m[1])
    if not chan:
        chan = {k: k for k in range(1, 5)}
        imp.notes.append("no SERVOn_FUNCTION parameters: motors 1-4 taken on outputs 1-4")
    if max(chan) > 4:
        imp.fail(f"motors {sorted(chan)} assigned (SERVOn_FUNCTION 33-{MOTOR_FUNCTION + max(chan) - 1}): more than "
                 "four motors: diagnose knows quadrotors (4)")
    if sorted(chan) != [1, 2, 3, 4]:
        imp.fail(f"SERVOn_FUNCTION assigns motors {sorted(chan)}: motors 1-4 are needed")
    rows = []
    for m in range(1, 5):
        c = chan[m]
        msg = "RCOU" if c <= 14 else "RCO2" if c <= 18 else "RCO3"
        ms = msgs[msg]
        if not ms or not hasattr(ms[0], f"C{c}"):
            imp.fail(f"no {msg}.C{c} (motor {m} on SERVO{c}): the motor commands were not logged")
        rows.append((_col(ms, "TimeUS") * 1e-6, _col(ms, f"C{c}")))
    t = rows[0][0]
    raw = np.vstack([np.interp(t, tr, v) if tr.size != t.size else v for tr, v in rows])
    lo, hi = float(p.get("MOT_PWM_MIN", 0) or 0), float(p.get("MOT_PWM_MAX", 0) or 0)
    source = "MOT_PWM_MIN/MAX"
    if not 0 < lo < hi:
        lo, hi = float(p.get("RC3_MIN", 1000) or 1000), float(p.get("RC3_MAX", 2000) or 2000)
        source = "RC3_MIN/MAX (MOT_PWM_MIN/MAX are 0: ArduCopter then uses the throttle channel's range)"
    P = 255.0 * (raw - lo) / (hi - lo)
    clipped = int(((P < 0) | (P > 255)).any(axis=0).sum())
    if clipped:
        imp.notes.append(f"{clipped} RCOU samples outside {source.split(' ')[0]} (stopped or disarmed) clipped to 0-255")
    outputs = ", ".join(f"SERVO{chan[m]}" for m in range(1, 5))
    imp.meta["motor_outputs"] = f"RCOU {outputs} (SERVOn_FUNCTION 33-36 = motors 1-4); {source} {lo:g}-{hi:g} us"
    imp.meta["command_range"] = f"{lo:g} {hi:g}"
    imp.meta["command"] = f"P = 255 (pwm - {lo:g}) / ({hi:g} - {lo:g}): RCOU {outputs} over {source.split(' ')[0]}"
    imp.meta["esc_order"] = " ".join(str(chan[m] - 1) for m in range(1, 5))
    return Stream("RCOU", t, np.clip(P, 0.0, 255.0), held=True)


def read(path: str, text: bool = False) -> Imported:
    p, msgs = _read(path, text)
    imp = Imported(path, {}, {}, [])
    if "_damage" in msgs:
        imp.notes.append(f"damaged: read up to {msgs['_damage'][0]}")
    firmware = _firmware(msgs)
    rotors, source = _vehicle(p, firmware, imp)
    if msgs["ARM"] and not any(getattr(m, "ArmState", 0) for m in msgs["ARM"]):
        imp.fail("never armed: the motors did not run in this log (ARM messages)")
    gyr = _pick(msgs["GYR"], "I")
    imu = _pick(msgs["IMU"], "I")
    if len(gyr) >= 10 and len(_pick(msgs["ACC"], "I")) >= 10:
        acc = _pick(msgs["ACC"], "I")
        tg = _col(gyr, "SampleUS") * 1e-6
        ta = _col(acc, "SampleUS") * 1e-6
        g = np.vstack([_col(gyr, f"Gyr{a}") for a in "XYZ"])
        a = np.vstack([_col(acc, f"Acc{a}") for a in "XYZ"])
        post = int(p.get("INS_RAW_LOG_OPT", 0) or 0) & 4
        gsource = "GYR (the raw high-rate gyro samples" + (", after the filters: INS_RAW_LOG_OPT bit 2)" if post else ")")
        asource, filtered = "ACC", bool(post)
    elif imu:
        tg = ta = _col(imu, "TimeUS") * 1e-6
        g = np.vstack([_col(imu, f"Gyr{a}") for a in "XYZ"])
        a = np.vstack([_col(imu, f"Acc{a}") for a in "XYZ"])
        gsource, asource, filtered = "IMU (the filtered gyro the controller uses)", "IMU", True
    else:
        imp.fail("no IMU or GYR messages: the gyro was not logged")
    imp.streams["gyro"] = Stream(gsource.split(" ")[0], tg, g * FRD)
    imp.streams["acc"] = Stream("accelerometer", ta, a * FRD)
    imp.streams["motors"] = _motors(p, msgs, imp)
    rate_notes(imp, "motor commands (RCOU)", RATE_NOTE)
    _measurements(p, msgs, imp)
    gf, af = float(p.get("INS_GYRO_FILTER", 0) or 0), float(p.get("INS_ACCEL_FILTER", 0) or 0)
    notches = "harmonic notch (INS_HNTCH_ENABLE)" if p.get("INS_HNTCH_ENABLE") else "none"
    imp.meta.update({
        "vehicle": "foreign", "format": "ardupilot dataflash", "source": path, "firmware": firmware,
        "craft": "", "rotors": rotors, "rotors_source": source,
        "gyro_source": gsource, "gyro_filter": f"biquad {gf:g}" if filtered and gf > 0 else "none",
        "gyro_notches": notches, "acc_source": asource,
        "acc_filter": f"biquad {af:g}" if filtered and af > 0 else "none",
    })
    return imp


def _measurements(p: dict, msgs, imp: Imported) -> None:
    bat = _pick(msgs["BAT"], "Inst")
    if bat:
        tb = _col(bat, "TimeUS") * 1e-6
        v = _col(bat, "Volt")
        ok = v > 0.5
        imp.streams["battery_v"] = Stream("BAT Volt", tb[ok], v[None, ok])
        cur = _col(bat, "Curr")
        if np.any(cur > 0):
            imp.streams["current"] = Stream("BAT Curr", tb, cur[None])
    vmax = float(p.get("MOT_BAT_VOLT_MAX", 0) or 0)
    if vmax > 0:
        imp.meta["battery_cells"] = str(max(1, round(vmax / 4.2)))
        imp.meta["battery_cells_source"] = f"MOT_BAT_VOLT_MAX {vmax:g} V over 4.2 V a cell"
    baro = _pick(msgs["BARO"], "I")
    imp.meta["height_source"] = "none"
    if baro:
        imp.streams["height"] = Stream("BARO Alt (above the ground at boot)", _col(baro, "TimeUS") * 1e-6,
                                       _col(baro, "Alt")[None])
        imp.meta["height_source"] = "baro"
    rf = [m for m in msgs["RFND"] if getattr(m, "Orient", 25) == 25 and getattr(m, "Stat", 4) == 4]
    if rf:
        dist = _col(rf, "Dist")
        imp.streams["range"] = Stream("RFND Dist (downward)", _col(rf, "TimeUS") * 1e-6, dist[None])
    att = msgs["ATT"]
    if att:
        e = np.vstack([_col(att, k) for k in ("Roll", "Pitch", "Yaw")]) * DEG
        e[2] = np.unwrap(e[2])
        imp.streams["attitude"] = Stream("ATT", _col(att, "TimeUS") * 1e-6, e * FRD)
    rate = msgs["RATE"]
    if rate:
        sp = np.vstack([_col(rate, k) for k in ("RDes", "PDes", "YDes")]) * DEG
        imp.streams["setpoint"] = Stream("RATE RDes/PDes/YDes", _col(rate, "TimeUS") * 1e-6, sp * FRD)
    order = [int(k) for k in imp.meta.pop("esc_order").split()]
    esc = msgs["ESC"]
    if esc and hasattr(esc[0], "RPM"):
        inst = {i: [m for m in esc if getattr(m, "Instance", -1) == i] for i in order}
        if all(inst[i] for i in order):
            t = _col(inst[order[0]], "TimeUS") * 1e-6
            w = np.vstack([np.interp(t, _col(inst[i], "TimeUS") * 1e-6, _col(inst[i], "RPM")) for i in order])
            if np.any(w != 0):
                imp.streams["omega"] = Stream("ESC RPM", t, np.abs(w) * 2.0 * math.pi / 60.0)
                imp.meta["omega_source"] = (f"ESC telemetry RPM of instances {', '.join(map(str, order))} (the motors' "
                                            "output channels) for motors 1-4")
