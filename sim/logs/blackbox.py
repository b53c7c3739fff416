"""Betaflight's blackbox (`.bbl`, `.bfl`, `.BFL`; Betaflight, INDIflight) through orangebox 0.4.0
(docs/log-import.md has each field, unit and frame with its evidence).

Every main frame holds one gyro sample, the motor commands and the latest battery readings, so the
frame is the time base and nothing needs holding. Frames: Betaflight's sensors are x forward, y left,
z up, and the accelerometer reads +1 g up at rest: our body frame (conventions.md), so no axis
changes sign. INDIflight's quaternion `quat` is body (x forward, y right, z down) to North-East-Down;
its derivative gives the gyro's rates with y and z negated, which is that same frame turned about x.
"""
from __future__ import annotations

import math

import numpy as np

from flightctl.physics import G
from flightctl.sim.logs.common import Imported, Stream

QUAD_X = ((-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0))   # motors 1-4: rear right, front right,
QUAD_X_SPIN = (-1.0, 1.0, 1.0, -1.0)                               # rear left, front left; 1 and 4 clockwise
DEG = math.pi / 180.0
GYRO_SCALED = 6              # Betaflight 4.x debug_mode: debug[0..2] = the gyro before its filters, deg/s
LOWPASS_TYPES = {0: "pt1", 1: "biquad", 2: "pt2", 3: "pt3"}        # Betaflight's lowpass_type enum


def _parser(path: str, index: int | None):
    try:
        from orangebox import Parser
    except ImportError:
        raise_missing(path)
    import contextlib
    import io as _io
    with contextlib.redirect_stdout(_io.StringIO()), contextlib.redirect_stderr(_io.StringIO()):
        return Parser.load(path, index) if index is not None else Parser.load(path)


def raise_missing(path):
    from flightctl.errors import InputError
    raise InputError(f"{path}: reading a blackbox log needs the logs extra: pip install '.[logs]' (from the checkout)")


def count(path: str) -> int:
    return int(_parser(path, None).reader.log_count)


def _frames(parser) -> tuple[list[str], np.ndarray]:
    """The main frames as a float array (n, fields); a field with text (orangebox's flags) is NaN."""
    import contextlib
    import io as _io
    names = list(parser.field_names)
    rows = []
    with contextlib.redirect_stdout(_io.StringIO()), contextlib.redirect_stderr(_io.StringIO()):
        for frame in parser.frames():
            data = frame.data
            if len(data) == len(names):
                rows.append([v if isinstance(v, (int, float)) else math.nan for v in data])
    return names, np.array(rows, dtype=float).reshape(len(rows), len(names))


def _filters(h: dict, indiflight: bool) -> tuple[str, str]:
    """(the low-pass chain of the gyro field logged as gyroADC, in the project's syntax, a note)."""
    chain = []
    if indiflight:
        if h.get("gyro_lpf1_static_hz"):
            chain.append(f"{LOWPASS_TYPES.get(int(h.get('gyro_lpf1_type', 0)), 'pt1')} {h['gyro_lpf1_static_hz']:g}")
        if h.get("gyro_lpf2_static_hz"):
            chain.append(f"{LOWPASS_TYPES.get(int(h.get('gyro_lpf2_type', 0)), 'pt1')} {h['gyro_lpf2_static_hz']:g}")
        return "; ".join(chain) or "none", ""
    note = ""
    dyn = h.get("gyro_lowpass_dyn_hz")
    if isinstance(dyn, list) and dyn and dyn[0]:
        chain.append(f"{LOWPASS_TYPES.get(int(h.get('gyro_lowpass_type', 0)), 'pt1')} {dyn[0]:g}")
        note = f"gyro_lowpass_dyn_hz {dyn}: its lowest cut-off (at the lowest throttle) is used"
    elif h.get("gyro_lowpass_hz"):
        chain.append(f"{LOWPASS_TYPES.get(int(h.get('gyro_lowpass_type', 0)), 'pt1')} {h['gyro_lowpass_hz']:g}")
    if h.get("gyro_lowpass2_hz"):
        chain.append(f"{LOWPASS_TYPES.get(int(h.get('gyro_lowpass2_type', 0)), 'pt1')} {h['gyro_lowpass2_hz']:g}")
    return "; ".join(chain) or "none", note


def read(path: str, index: int) -> Imported:
    """Log `index` (from 1) of a blackbox file."""
    parser = _parser(path, index)
    h = dict(parser.headers)
    names, a = _frames(parser)
    name = f"{path}#{index}" if parser.reader.log_count > 1 else path
    imp = Imported(name, {}, {}, [])
    col = {n: i for i, n in enumerate(names)}
    motors = sorted((n for n in names if n.startswith("motor[")), key=lambda n: int(n[6:-1]))
    if not motors:
        imp.fail("no motor[] fields: the motor commands were not logged")
    if len(motors) != 4:
        imp.fail(f"{len(motors)} motors (motor[0..{len(motors) - 1}]): diagnose knows quadrotors (4)")
    for need in ("time", "gyroADC[0]", "accSmooth[0]"):
        if need not in col:
            imp.fail(f"no {need.split('[')[0]} field: {'the time' if need == 'time' else 'that sensor'} was not logged")
    if a.shape[0] < 10:
        imp.fail(f"{a.shape[0]} frames: empty or cut short")
    t = a[:, col["time"]] * 1e-6
    firmware = str(h.get("Firmware revision", ""))
    indiflight = firmware.lower().startswith("indiflight")
    hires = 10.0 if int(h.get("blackbox_high_resolution", 0) or 0) else 1.0   # gyro logged in 0.1 deg/s

    def field(prefix, k):
        return np.vstack([a[:, col[f"{prefix}[{i}]"]] for i in range(k)])

    # the gyro before its filters where the log has it: INDIflight's gyroADCafterRpm (after the rpm
    # notches, before the low-pass: it leads gyroADC by the low-pass's delay), Betaflight's debug[]
    # in GYRO_SCALED mode; else gyroADC with its filters declared
    filtered = field("gyroADC", 3) / hires * DEG
    chain, note = _filters(h, indiflight)
    if indiflight and "gyroADCafterRpm[0]" in col:
        gyro, source, gyro_filter = field("gyroADCafterRpm", 3) / hires * DEG, "gyroADCafterRpm (before the low-pass)", "none"
    elif int(h.get("debug_mode", 0) or 0) == GYRO_SCALED and "debug[0]" in col:
        gyro, source, gyro_filter = field("debug", 3) * DEG, "debug[0..2] (debug_mode GYRO_SCALED: before the filters)", "none"
    else:
        gyro, source, gyro_filter = filtered, "gyroADC (filtered)", chain
    if gyro_filter == "none":
        imp.streams["gyro_f"] = Stream("gyroADC", t, filtered)
    imp.streams["gyro"] = Stream("gyro", t, gyro)
    one_g = float(h.get("acc_1G", 2048) or 2048)
    if "accUnfiltered[0]" in col:
        acc, acc_source, acc_filter = field("accUnfiltered", 3), "accUnfiltered", "none"
    else:
        acc, acc_source = field("accSmooth", 3), "accSmooth"
        lpf = float(h.get("acc_lpf_hz", 0) or 0) / 100.0      # Betaflight keeps it in centi-Hz
        acc_filter = f"biquad {lpf:g}" if lpf > 0 else "none"
    imp.streams["acc"] = Stream("acc", t, acc / one_g * G)
    lo, hi = (float(v) for v in h.get("motorOutput", [0, 2047])[:2])
    raw = np.vstack([a[:, col[m]] for m in motors])
    P = 255.0 * (raw - lo) / (hi - lo)
    clipped = int(((P < 0) | (P > 255)).any(axis=0).sum())
    if clipped:
        imp.notes.append(f"{clipped} rows with a motor command outside motorOutput [{lo:g}, {hi:g}] "
                         "(stopped or disarmed: 0) clipped to 0-255")
    imp.streams["motors"] = Stream("motors", t, np.clip(P, 0.0, 255.0), held=True)
    if "vbatLatest" in col:
        v = a[:, col["vbatLatest"]] * 0.01
        ok = v > 0                       # 0 until the first reading after power-on
        if ok.any():
            imp.streams["battery_v"] = Stream("vbatLatest", t[ok], v[None, ok])
    if "amperageLatest" in col and np.any(a[:, col["amperageLatest"]] != 0):
        imp.streams["current"] = Stream("amperageLatest", t, a[None, :, col["amperageLatest"]] * 0.01)
    if "omegaUnfiltered[0]" in col and np.any(field("omegaUnfiltered", 4) != 0):
        imp.streams["omega"] = Stream("omegaUnfiltered", t, field("omegaUnfiltered", 4))
    height_source = "none"
    if "extPos[2]" in col and np.any(a[:, col["extPos[2]"]] != 0):
        imp.streams["height"] = Stream("extPos (motion capture)", t, -a[None, :, col["extPos[2]"]] * 1e-3)
        height_source = "mocap"
    elif "BaroAlt" in col:
        imp.streams["height"] = Stream("BaroAlt", t, a[None, :, col["BaroAlt"]] * 0.01)
        height_source = "baro"
    if "quat[0]" in col:
        imp.streams["attitude"] = Stream("quat", t, _euler_from_frd_ned(field("quat", 4)))
    reversed_ = h.get("yaw_motors_reversed")
    spins = tuple(-s for s in QUAD_X_SPIN) if reversed_ else QUAD_X_SPIN
    s2 = math.sqrt(0.5)
    imp.meta.update({
        "vehicle": "foreign", "format": "betaflight blackbox", "source": name, "firmware": firmware,
        "craft": str(h.get("Craft name", "")).strip(),
        "rotors": "; ".join(f"{x * s2:.4f} {y * s2:.4f} {s:+.0f}" for (x, y), s in zip(QUAD_X, spins)),
        "rotors_source": ("Betaflight's quad X (motor 1 rear right, 2 front right, 3 rear left, 4 front left), "
                          + (f"yaw_motors_reversed = {int(reversed_)}" if reversed_ is not None else
                             "yaw_motors_reversed not in the header: props in (motors 1 and 4 clockwise) assumed")),
        "command_range": f"{lo:g} {hi:g}",
        "command": f"P = 255 (motor - {lo:g}) / ({hi:g} - {lo:g}): the DShot command over motorOutput",
        "gyro_source": source + (f"; {note}" if note and gyro_filter != "none" else ""),
        "gyro_filter": gyro_filter,
        "acc_source": acc_source, "acc_filter": acc_filter,
        "height_source": height_source,
    })
    if "omega" in imp.streams:
        imp.meta["omega_source"] = "omegaUnfiltered (ESC telemetry, rad/s)"
    return imp


def _euler_from_frd_ned(q: np.ndarray) -> np.ndarray:
    """(roll, pitch, yaw) in our frames (conventions.md: body x forward, y left, z up; inertial North,
    West, Up) of quaternions (4, n; any scale) from body FRD to NED: the same rotation seen with y and
    z negated in both frames keeps the roll and negates the pitch and yaw."""
    w, x, y, z = q / np.linalg.norm(q, axis=0)
    roll = np.arctan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    pitch = np.arcsin(np.clip(2.0 * (w * y - z * x), -1.0, 1.0))
    yaw = np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return np.vstack([roll, -pitch, -yaw])
