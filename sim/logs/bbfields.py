"""One blackbox log's frames and header as this project's streams (docs/log-import.md): Betaflight
3.x to 4.5, INDIflight, INAV; each field, unit and frame with its evidence there.

Every main frame holds one gyro sample, the motor commands and the latest battery readings, so the
frame is the time base. Frames: the sensors are x forward, y left, z up and the accelerometer reads
+1 g up at rest: our body frame (conventions.md), no axis changes sign. INDIflight's quaternion `quat`
is body (x forward, y right, z down) to North-East-Down.
"""
from __future__ import annotations

import math
import re
import struct

import numpy as np

from flightctl.sim.logs import bfrates, controller
from flightctl.physics import G
from flightctl.sim.logs import frames, identity
from flightctl.sim.logs.common import DEG, Imported, Stream, backward_note, command_p, euler_from_frd_ned, forward

RPM = 2.0 * math.pi / 60.0
LOWPASS_TYPES = {0: "pt1", 1: "biquad", 2: "pt2", 3: "pt3"}        # Betaflight's lowpass_type enum
# Betaflight's debug modes (debugType_e): GYRO_SCALED holds the gyro before its filters (deg/s) up to
# 4.2 (the enum changed after); DSHOT_RPM_TELEMETRY the ESCs' eRPM / 100, RPM_FILTER the rotation
# frequency in Hz after a pt1 (rpm_notch_lpf) - both numbers unchanged from 4.1 to 4.5.
GYRO_SCALED, DSHOT_RPM_TELEMETRY, RPM_FILTER = 6, 45, 46
DEFAULT_POLES = 14                 # Betaflight's motor_poles default (a 12N14P motor)


def version(firmware: str) -> tuple[int, ...]:
    """(major, minor, patch) of 'Betaflight 4.2.0 (8f2d21460) STM32F745'; () when not found."""
    m = re.search(r"(\d+)\.(\d+)\.(\d+)", firmware)
    return tuple(int(x) for x in m.groups()) if m else ()


def kind_of(firmware: str) -> str:
    low = firmware.lower()
    for k in ("indiflight", "inav", "betaflight", "cleanflight", "emuflight"):
        if low.startswith(k):
            return k
    return "unknown"


def _lowpass(h: dict, stem: str, dyn_note: list[str], static: str = "_static_hz") -> str | None:
    """One low-pass stage: its cut-off `<stem><static>` (Betaflight 4.3+ and INDIflight `gyro_lpf1_static_hz`,
    before 4.3 `gyro_lowpass_hz`), its dynamic range `<stem>_dyn_hz` [min, max] (its lowest cut-off, at
    the lowest throttle, is declared), its type `<stem>_type`."""
    kind = LOWPASS_TYPES.get(int(h.get(f"{stem}_type", 0) or 0), "pt1")
    dyn = h.get(f"{stem}_dyn_hz")
    if isinstance(dyn, list) and dyn and dyn[0]:
        dyn_note.append(f"{stem}_dyn_hz {dyn}: its lowest cut-off {dyn[0]} Hz (at the lowest throttle) declared")
        return f"{kind} {dyn[0]:g}"
    hz = h.get(f"{stem}{static}")
    return f"{kind} {hz:g}" if hz else None


def filters(h: dict) -> tuple[str, str, str]:
    """(the low-pass chain of `gyroADC` in the project's syntax, a note, the notches): Betaflight up to
    4.2 (`gyro_lowpass_hz`, `gyro_lowpass2_hz`), 4.3+ and INDIflight (`gyro_lpf1_static_hz`, ...), INAV
    (`gyro_lpf_hz`). Notches (dynamic, rpm) are named, not declared: away from their frequencies (the
    motors', hundreds of Hz) they hardly delay."""
    notes: list[str] = []
    if "gyro_lpf1_static_hz" in h or "gyro_lpf1_dyn_hz" in h:
        chain = [s for s in (_lowpass(h, "gyro_lpf1", notes), _lowpass(h, "gyro_lpf2", notes)) if s]
    elif "gyro_lowpass_hz" in h:
        chain = [s for s in (_lowpass(h, "gyro_lowpass", notes, "_hz"), _lowpass(h, "gyro_lowpass2", notes, "_hz")) if s]
    else:                                                  # INAV: gyro_lpf_hz, its type not in the header
        chain = [f"pt1 {h['gyro_lpf_hz']:g}"] if h.get("gyro_lpf_hz") else []
        if chain:
            notes.append("INAV's gyro_lpf_hz, taken as its default pt1 (the type is not in the header)")
    notches = []
    if int(h.get("dyn_notch_count", 1) or 0) and h.get("dyn_notch_max_hz"):
        notches.append(f"dynamic notch {h.get('dyn_notch_min_hz', '?')}-{h['dyn_notch_max_hz']} Hz, "
                       f"q {h.get('dyn_notch_q', '?')}, count {h.get('dyn_notch_count', 'one per axis')}")
    harmonics = h.get("rpm_filter_harmonics", h.get("gyro_rpm_notch_harmonics"))
    if int(h.get("dshot_bidir", 0) or 0) and harmonics:
        notches.append(f"rpm filter {harmonics} harmonics from "
                       f"{h.get('rpm_filter_min_hz', h.get('gyro_rpm_notch_min', '?'))} Hz, "
                       f"q {h.get('rpm_filter_q', h.get('gyro_rpm_notch_q', '?'))}")
    return "; ".join(chain) or "none", "; ".join(notes), "; ".join(notches) or "none"


# The header's scales, as Betaflight's Blackbox Explorer applies them (betaflight/blackbox-log-viewer:
# src/flightlog_parser.js reads `gyro.scale`/`gyro_scale` as a hex float, deg/s per count for Cleanflight,
# Betaflight and INAV and rad/us per count for Baseflight; src/flightlog.js converts ADC counts,
# vbatADCToMillivolts = counts x 33 x 10 x vbatscale / 4095 and amperageADCToMillivolts = (counts x 33 x
# 100 / 4095 - currentMeter offset) x 10000 / currentMeter scale, in mA; src/flightlog_fields_presenter.js
# says which firmware logs volts and amps instead, `battery_scale` and `current_scale` below).
ADC_FULL = 4095.0                  # a 12-bit ADC
ADC_VREF_V = 3.3


def gyro_scale(h: dict) -> tuple[float, str]:
    """(deg/s per count of the gyro fields, its source): the header's `gyro_scale` (`gyro.scale` in
    Cleanflight and Betaflight before 3.1), a float written as its bits in hex: 1.0 when the gyro is
    logged in deg/s (Betaflight 3.1+), 1 / 16.4 for an MPU-6050's raw counts at 2000 deg/s in a 2016
    Cleanflight log. Baseflight's is in rad/us per count."""
    text = h.get("gyro_scale", h.get("gyro.scale"))
    if text is None:
        return 1.0, "no gyro_scale in the header: deg/s taken"
    try:       # (orangebox gives the header's 0x... as its int; a text header as written)
        bits = text if isinstance(text, int) else int(str(text), 16)
        raw = struct.unpack("<f", struct.pack("<I", bits))[0]
        text = f"0x{bits:08x}"
    except (ValueError, struct.error):
        return 1.0, f"gyro_scale {text!r} is not a hex float: deg/s taken"
    if not (math.isfinite(raw) and raw > 0):
        return 1.0, f"gyro_scale {text} is not a positive scale: deg/s taken"
    if str(h.get("Firmware type", "")).lower() == "baseflight":
        return raw * 1e6 / DEG, f"gyro_scale {text} ({raw:.4g} rad/us per count, Baseflight)"
    return raw, f"gyro_scale {text} ({raw:.6g} deg/s per count)"


def battery_scale(kind: str, ver: tuple[int, ...]) -> tuple[float | None, str]:
    """Volts per count of `vbatLatest` (Blackbox Explorer's reading by firmware): Betaflight 4.0+,
    INDIflight and INAV 0.01 V; Betaflight 3.1-3.5 and Cleanflight 2 0.1 V; older logs ADC counts (None)."""
    if kind in ("inav", "indiflight", "emuflight") or (kind == "betaflight" and ver >= (4, 0, 0)):
        return 0.01, "0.01 V"
    if (kind == "betaflight" and ver >= (3, 1, 0)) or (kind == "cleanflight" and ver >= (2, 0, 0)):
        return 0.1, "0.1 V (before Betaflight 4.0)"
    return None, "ADC counts"


def vbat_volts(raw, h: dict, scale: float | None):
    """`vbatLatest` (or `vbatref`) in volts: counts x scale, or ADC counts through the divider the header's
    `vbatscale` (`vbat_scale`; 110 by default: 11.0 to 1) declares."""
    if scale is not None:
        return raw * scale
    div = float(h.get("vbat_scale", h.get("vbatscale", 110)) or 110)
    return raw * ADC_VREF_V * div / 10.0 / ADC_FULL


def current_scale(kind: str, ver: tuple[int, ...]) -> float | None:
    """Amps per count of `amperageLatest`: 0.01 A from Betaflight 3.1 and Cleanflight 2 (and INAV,
    INDIflight), before them ADC counts (None: `amps`)."""
    if kind in ("inav", "indiflight", "emuflight") or (kind == "betaflight" and ver >= (3, 1, 0)) \
            or (kind == "cleanflight" and ver >= (2, 0, 0)):
        return 0.01
    return None


def amps(raw, h: dict):
    """ADC counts of the current sensor in amps: its millivolts less the header's `currentMeter` offset
    (mV), over its scale (mV per 10 A)."""
    meter = h.get("currentMeter", h.get("currentSensor", [0, 400]))
    offset, scale = (float(v) for v in (meter if isinstance(meter, list) and len(meter) >= 2 else [0, 400])[:2])
    mv = raw * ADC_VREF_V * 1000.0 / ADC_FULL
    return (mv - offset) * 10.0 / (scale or 400.0)


def cells(h: dict, scale: float | None) -> tuple[str, str] | None:
    """(cell count, its source) from the header, as Blackbox Explorer estimates it: the voltage at
    power-on `vbatref` over the cell's full voltage `vbatcellvoltage` [min, warning, max]."""
    ref, cell = h.get("vbatref"), h.get("vbatcellvoltage")
    if not ref or not isinstance(cell, list) or len(cell) < 3 or not cell[2]:
        return None
    full = cell[2] / (100.0 if cell[2] > 100 else 10.0)           # 0.01 V (Betaflight 4) or 0.1 V
    v = float(vbat_volts(ref, h, scale))
    n = max(1, math.ceil(v / full - 1e-9))
    return str(n), f"header: vbatref {v:.2f} V at power-on over vbatcellvoltage's full cell {full:.2f} V"


def imported(name: str, h: dict, names: list[str], a: np.ndarray, notes: list[str]) -> Imported:
    imp = Imported(name, {}, {}, list(notes))
    col = {n: i for i, n in enumerate(names)}
    firmware = str(h.get("Firmware revision", ""))
    kind, ver = kind_of(firmware), version(firmware)
    motors = sorted((n for n in names if n.startswith("motor[")), key=lambda n: int(n[6:-1]))
    if not motors:
        imp.fail("no motor[] fields: the motor commands were not logged")
    reversed_ = h.get("yaw_motors_reversed", h.get("motor_direction_inverted"))
    mixer = "INAV" if kind == "inav" else "Betaflight"
    frame = frames.betaflight(len(motors), mixer, reversed_, imp.fail)
    for need in ("time", "gyroADC[0]"):
        if need not in col:
            imp.fail(f"no {need.split('[')[0]} field: {'the time' if need == 'time' else 'that sensor'} was not logged")
    t = a[:, col["time"]] * 1e-6
    keep = forward(t)
    if not keep.all():      # a time that jumps back (Betaflight 3.0's clock): its rows dropped, counted
        loop = a[:, col["loopIteration"]] if "loopIteration" in col else None
        steady = "" if loop is None else ("; loopIteration continuous across it" if np.all(np.diff(loop) > 0)
                                          else "; loopIteration restarts too")
        imp.notes.append(backward_note(t, keep, "frames") + steady)
        a, t = a[keep], t[keep]
    hires = 10.0 if int(h.get("blackbox_high_resolution", 0) or 0) else 1.0   # gyro logged in 0.1 deg/s
    per_count, scale_source = gyro_scale(h)
    counts = hires / per_count                                             # the gyro fields' counts per deg/s

    def field(prefix, k, cols=None):
        return np.vstack([a[:, col[f"{prefix}[{i}]"]] if f"{prefix}[{i}]" in col else np.full(len(t), np.nan)
                          for i in (cols or range(k))])

    # the gyro before its filters where the log has it; else gyroADC with its low-pass declared
    filtered = field("gyroADC", 3) / counts * DEG
    chain, note, notches = filters(h)
    debug = int(h.get("debug_mode", 0) or 0)
    if kind == "indiflight" and "gyroADCafterRpm[0]" in col:
        gyro, source = field("gyroADCafterRpm", 3) / counts * DEG, "gyroADCafterRpm (after the rpm notches, before the low-pass)"
    elif "gyroUnfilt[0]" in col:
        gyro, source = field("gyroUnfilt", 3) / counts * DEG, "gyroUnfilt (before the filters)"
    elif kind == "inav" and "gyroRaw[0]" in col:
        gyro, source = field("gyroRaw", 3) * DEG, "gyroRaw (INAV's gyro before its filters)"
    elif debug == GYRO_SCALED and "debug[0]" in col and kind == "betaflight" and ver < (4, 3, 0):
        gyro, source = field("debug", 3) * per_count * DEG, "debug[0..2] (debug_mode GYRO_SCALED: before the filters)"
    else:
        gyro, source = filtered, "gyroADC (filtered)"
    if per_count != 1.0:
        source += f"; {scale_source}"
    gyro_filter = chain if gyro is filtered else "none"
    if gyro is not filtered:
        imp.streams["gyro_f"] = Stream("gyroADC", t, filtered)
    imp.streams["gyro"] = Stream("gyro", t, gyro)
    one_g = float(h.get("acc_1G", 2048) or 2048)
    if "accUnfiltered[0]" in col:
        acc, acc_source, acc_filter = field("accUnfiltered", 3), "accUnfiltered", "none"
    elif "accSmooth[0]" not in col:
        # the accelerometer switched off (Betaflight 3.x racers: `feature -ACC`): no acc fields at all; the
        # columns stay empty and diagnose judges the gyro and the motors (data.NO_ACCELEROMETER)
        acc, acc_source, acc_filter = field("accSmooth", 3), "none (no accSmooth field: the accelerometer off)", "none"
        imp.notes.append("no accSmooth field: the accelerometer was switched off; its columns are empty")
    else:
        acc, acc_source = field("accSmooth", 3), "accSmooth"
        lpf = float(h.get("acc_lpf_hz", 0) or 0) / (1.0 if kind == "inav" else 100.0)   # Betaflight: centi-Hz
        acc_filter = f"biquad {lpf:g}" if lpf > 0 else "none"
    imp.streams["acc"] = Stream("acc", t, acc / one_g * G)
    lo, hi = (float(v) for v in h.get("motorOutput", [0, 2047])[:2])
    raw = np.vstack([a[:, col[m]] for m in motors])
    P = command_p(imp, raw, lo, hi, f"rows with a motor command outside motorOutput [{lo:g}, {hi:g}] (stopped or "
                  "disarmed: 0)")
    imp.streams["motors"] = Stream("motors", t, P, held=True)
    _battery(imp, h, a, col, t, kind, ver)
    _rotor_speeds(imp, h, a, col, t, field, debug, kind)
    _tracking(imp, a, col, t, field, hires, kind, h if bfrates.applies(kind, ver, h) else None)
    height_source = "none"
    if "extPos[2]" in col and np.any(a[:, col["extPos[2]"]] != 0):
        imp.streams["height"] = Stream("extPos (motion capture)", t, -a[None, :, col["extPos[2]"]] * 1e-3)
        height_source = "mocap"
    elif "BaroAlt" in col:
        imp.streams["height"] = Stream("BaroAlt", t, a[None, :, col["BaroAlt"]] * 0.01)
        height_source = "baro"
    if "quat[0]" in col:
        imp.streams["attitude"] = Stream("quat", t, euler_from_frd_ned(field("quat", 4)))
    imp.meta.update({
        "vehicle": "foreign", "format": ("inav" if kind == "inav" else "betaflight") + " blackbox", "source": name,
        "firmware": firmware, "craft": str(h.get("Craft name", "")).strip(),
        "rotors": frame.rotors(), "rotors_source": frame.source,
        "command_range": f"{lo:g} {hi:g}",
        "command": f"P = 255 (motor - {lo:g}) / ({hi:g} - {lo:g}): the command over motorOutput",
        "gyro_source": source + (f"; {note}" if note and gyro_filter != "none" else ""),
        "gyro_filter": gyro_filter, "gyro_notches": notches,
        "gyro_loop_filter": chain,            # the low-passes of the gyro the PID loop flies on (predict.py)
        "acc_source": acc_source, "acc_filter": acc_filter,
        "height_source": height_source,
    })
    imp.meta.update(identity.blackbox(h))
    imp.meta["controller"] = controller.encode(controller.blackbox(h, kind, kind == "betaflight" and ver >= (3, 1, 0)))
    return imp


def _battery(imp, h, a, col, t, kind, ver):
    name = "vbat" if kind == "inav" and "vbat" in col else "vbatLatest"
    if name in col:
        scale, unit = battery_scale(kind, ver)
        v = vbat_volts(a[:, col[name]], h, scale)
        if scale is None:
            unit += f" through vbatscale {float(h.get('vbat_scale', h.get('vbatscale', 110)) or 110):g}"
        ok = v > 0.5                    # 0 (or a few counts) until the first reading after power-on
        if ok.any():
            imp.streams["battery_v"] = Stream(f"{name} ({unit})", t[ok], v[None, ok])
        found = cells(h, scale)
        if found:
            imp.meta["battery_cells"], imp.meta["battery_cells_source"] = found
    name_a = "amperage" if kind == "inav" and "amperage" in col else "amperageLatest"
    if name_a in col and np.any(a[:, col[name_a]] != 0):
        per = current_scale(kind, ver)
        raw = a[None, :, col[name_a]]
        if per is not None:
            imp.streams["current"] = Stream(f"{name_a} (0.01 A)", t, raw * per)
        else:
            imp.streams["current"] = Stream(f"{name_a} (ADC counts through currentMeter "
                                            f"{h.get('currentMeter', h.get('currentSensor', '0,400'))})", t, amps(raw, h))


def _rotor_speeds(imp, h, a, col, t, field, debug, kind):
    """omega1..N (rad/s), one per motor: INDIflight's ESC telemetry; Betaflight 4.3+'s eRPM[0..N-1]
    (bidirectional DShot, eRPM / 100; blackbox.c logs one per motor, up to 8); the debug modes
    DSHOT_RPM_TELEMETRY and RPM_FILTER (debug[0..3]: four values, so a quad's only)."""
    n = imp.streams["motors"].values.shape[0]
    poles = h.get("motor_poles")
    pole_note = "" if poles else f" (motor_poles not in the header: Betaflight's default {DEFAULT_POLES} assumed)"
    poles = float(poles or DEFAULT_POLES)
    has = lambda name: all(f"{name}[{i}]" in col for i in range(n))
    if has("omegaUnfiltered") and np.any(field("omegaUnfiltered", n) != 0):
        w, source = field("omegaUnfiltered", n), f"omegaUnfiltered[0..{n - 1}] (ESC telemetry, rad/s)"
    elif has("eRPM") and np.any(field("eRPM", n) > 0):
        w = field("eRPM", n) * 100.0 / (poles / 2.0) * RPM
        source = (f"eRPM[0..{n - 1}] (bidirectional DShot, eRPM / 100): rpm = 100 eRPM / (motor_poles / 2), "
                  f"motor_poles {poles:g}")
    elif n != 4 and debug in (DSHOT_RPM_TELEMETRY, RPM_FILTER) and kind != "inav":
        imp.notes.append(f"rotor speeds not read: debug[0..3] holds four motors' speeds, the log has {n} motors")
        return
    elif kind != "inav" and debug == DSHOT_RPM_TELEMETRY and "debug[3]" in col:
        w = field("debug", 4) * 100.0 / (poles / 2.0) * RPM
        source = f"debug[0..3] (debug_mode DSHOT_RPM_TELEMETRY, eRPM / 100), motor_poles {poles:g}"
    elif kind != "inav" and debug == RPM_FILTER and "debug[3]" in col:
        w = field("debug", 4) * 2.0 * math.pi
        lpf = h.get('rpm_notch_lpf', h.get('rpm_filter_lpf_hz', '?'))
        source = f"debug[0..3] (debug_mode RPM_FILTER: rotation in Hz after a pt1 at rpm_notch_lpf {lpf} Hz)"
        pole_note = ""
    else:
        return
    imp.streams["omega"] = Stream("rotor speeds", t, w)
    imp.meta["omega_source"] = source + pole_note
    imp.meta["motor_poles"] = f"{poles:g}"


def _tracking(imp, a, col, t, field, hires, kind, curve_h=None):
    """What draws rate tracking: the rate setpoint (Betaflight setpoint[0..2], INAV axisRate[0..2];
    deg/s, the gyro's frame; a Betaflight 3.1 log's from rcCommand through its rate curve, `curve_h` its
    header: sim/logs/bfrates.py), the sticks (rcCommand, normalised) and the PID terms (axisP/I/D/F, in
    the mixer's units: 1000 is its full range)."""
    sp = "axisRate" if kind == "inav" else "setpoint"
    if f"{sp}[0]" in col:
        imp.streams["setpoint"] = Stream(f"{sp}[0..2]", t, field(sp, 3) / hires * DEG)
    if "rcCommand[0]" in col:
        rc = field("rcCommand", 4)
        rc = np.where(rc >= 2.0 ** 31, rc - 2.0 ** 32, rc)      # orangebox reads some of INAV's as unsigned
        if "setpoint" not in imp.streams and curve_h is not None:
            imp.streams["setpoint"] = Stream(bfrates.source(curve_h), t, bfrates.setpoint(curve_h, rc[:3]))
        rc[:3] /= 500.0
        rc[3] = (rc[3] - 1000.0) / 1000.0
        imp.streams["rc"] = Stream("rcCommand", t, rc)
    if "axisP[0]" in col:
        imp.streams["pid"] = Stream("axisP/I/D/F", t, np.vstack([field(f"axis{k}", 3) for k in "PIDF"]) / 1000.0)
