"""Whether an ArduPilot DataFlash log shows its vehicle armed, and which of the log's sources say so
(sim/logs/dataflash.py reads the log; this is the evidence it weighs): ARM's ArmState, the EV ids
written only while armed, the motor outputs above their disarmed pulse, and the logged height's climb
and return (a flight); and where the sources that were logged disagree."""
from __future__ import annotations

import re

import numpy as np

from flightctl.sim.logs import arducopter3

MOTOR_FUNCTION = 33                    # SERVOn_FUNCTION of motor 1 (33-44: motors 1-12)
# EV's ids (ArduPilot's libraries/AP_Logger/AP_Logger.h, `enum class LogEvent`; DATA_* in
# ArduCopter 3.x's defines.h, the same numbers since 3.0) that are only written while armed: ARMED 10,
# DISARMED 11 (armed until then), AUTO_ARMED 15 (the throttle raised while armed), NOT_LANDED 28 (the
# landing detector's take-off). LAND_COMPLETE_MAYBE 17 and LAND_COMPLETE 18, the landing detector's
# landing, say the vehicle was in the air just before.
ARMED_EVENTS = {10: "ARMED", 11: "DISARMED", 15: "AUTO_ARMED", 28: "NOT_LANDED", 17: "LAND_COMPLETE_MAYBE",
                18: "LAND_COMPLETE"}
RAN_SHARE = 0.05                      # of the pulse range above its lowest: a motor output of an armed vehicle
# A flight in the logged height: up CLIMB_M from its level at the log's start and back down by CLIMB_M. A
# barometer on the ground drifts with the weather and the board's warming (ArduPilot's AP_Baro takes the
# ground pressure at boot and EKF3 fuses it with a 2 m noise by default, EK3_ALT_M_NSE 2) and the rotors'
# wash moves it by a few tenths of a metre: a round trip of 3 m each way is none of these, and a vehicle
# on its legs does not make it. The heights are taken as medians of HEIGHT_RUN samples (a single spike:
# ArduCopter 3.0's CTUN BarAlt reads -2.5 m for one sample in tests/data/ardupilot/underpowered.log).
CLIMB_M = 3.0
HEIGHT_RUN = 5
# (message, field) of the heights, the first the log has: the first barometer, the altitude controller's
# barometer (CTUN BAlt in 4.x, BarAlt in 3.x), the GPS's altitude above home (3.x RelAlt) or above the sea
HEIGHTS = (("BARO", "Alt"), ("CTUN", "BAlt"), ("CTUN", "BarAlt"), ("GPS", "RelAlt"), ("GPS", "Alt"))


def armed(p: dict, msgs) -> tuple[bool | None, str, str]:
    """(whether the log shows the vehicle armed, which of its sources say so, where the logged sources
    disagree or '': a climb and return with the motor outputs at their disarmed pulse throughout, a motor
    mapping or MOT_PWM_MIN that is not the vehicle's): ARM's ArmState, EV's ids that are only written
    while armed (ARMED_EVENTS: a log that opens armed, LOG_DISARMED 0, holds AUTO_ARMED or NOT_LANDED and
    no ARMED), the motor outputs above their
    disarmed pulse (`outputs_ran`) and the height's climb and return (`climbed`); None when none says
    armed and the log has no ARM or EV (outputs at their lowest in a log cut before its arming: the idle
    checks judge it). Armed when any source says so: a disarmed ArduCopter holds its motor outputs at
    their lowest pulse or 0 (AP_MotorsMulticopter's shut-down spool state: MOT_PWM_MIN, or 0 with
    MOT_SAFE_DISARM), writes no such event, logs ArmState 0, and does not fly."""
    said, against = [], []
    if any(getattr(m, "ArmState", 0) for m in msgs["ARM"]):     # (ArmState 0 alone: a log that opens armed
        said.append("ARM's ArmState")                           # logs its disarming only; no contradiction)
    ids = sorted({int(getattr(m, "Id", -1)) for m in msgs["EV"]} & set(ARMED_EVENTS))
    if ids:
        said.append("EV " + ", ".join(f"{i} {ARMED_EVENTS[i]}" for i in ids))
    ran = outputs_ran(p, msgs)
    if ran:
        said.append(ran)
    up = climbed(msgs)          # (no climb is no contradiction: a hover at 1 m is a flight)
    if up:
        said.append(up)
        if ran == "":           # a flight on motors that never left their disarmed pulse: not the vehicle's outputs
            against.append("the motor outputs at their disarmed pulse throughout")
    conflict = ("; ".join(against) + ", but " + "; ".join(said)) if said and against else ""
    if said:
        return True, "; ".join(said), conflict
    if msgs["ARM"] or msgs["EV"]:       # (outputs alone at their lowest: a short log before the arming)
        return False, ", ".join(k for k, v in (("ARM", msgs["ARM"]), ("EV", msgs["EV"]), ("motor outputs", ran is not None),
                                               ("height", up is not None)) if v) + " messages", ""
    return None, "", ""


def climbed(msgs) -> str | None:
    """Where the log's first height (HEIGHTS) rose CLIMB_M above its level at the log's start and came
    back down by CLIMB_M after its highest: a flight's climb and return, in words ('' when it did not;
    None without a height). Heights as medians of HEIGHT_RUN samples."""
    for name, field in HEIGHTS:
        ms = [m for m in msgs.get(name, ()) if getattr(m, "I", getattr(m, "Instance", 0)) == 0
              and (name != "GPS" or getattr(m, "Status", 3) >= 3)]          # a 3D fix, for a GPS
        if len(ms) < 3 * HEIGHT_RUN or not hasattr(ms[0], field):
            continue
        h = np.array([float(getattr(m, field)) for m in ms])
        n = h.size // HEIGHT_RUN
        h = np.median(h[:n * HEIGHT_RUN].reshape(n, HEIGHT_RUN), axis=1)
        h = h[np.isfinite(h)]
        if h.size < 3:
            continue
        top = int(np.argmax(h))
        rise, fall = float(h[top] - h[0]), float(h[top] - h[top:].min())
        if rise >= CLIMB_M and fall >= CLIMB_M:
            return (f"{name} {field} {rise:.1f} m above its start and {fall:.1f} m back down (a climb and a return "
                    f"of {CLIMB_M:g} m or more: a flight)")
        return ""
    return None


def outputs_ran(p: dict, msgs) -> str | None:
    """Which motor outputs rose above their lowest pulse by RAN_SHARE of their range ('' when none
    did; None without RCOU or MOT): the motors' outputs of SERVOn_FUNCTION 33-44, else (ArduCopter 3.x,
    or no such parameter) outputs 1-4, over MOT_PWM_MIN/MAX else RC3_MIN/MAX."""
    if msgs["MOT"]:                    # ArduCopter 3.0-3.1's pulses (arducopter3.outputs)
        ms, fields = msgs["MOT"], [c for c in msgs["MOT"][0].fmt.columns if re.fullmatch(r"Mot\d+", c)]
    elif msgs["RCOU"]:
        ms = msgs["RCOU"]
        pre = next((k for k in arducopter3.RCOU_FIELDS if f"{k}1" in ms[0].fmt.columns), None)
        if pre is None:
            return None
        chans = sorted(int(m[1]) for name, v in p.items() if (m := re.fullmatch(r"SERVO(\d+)_FUNCTION", name))
                       and MOTOR_FUNCTION <= int(v) <= MOTOR_FUNCTION + 11 and int(m[1]) <= 14) or [1, 2, 3, 4]
        fields = [f"{pre}{c}" for c in chans if f"{pre}{c}" in ms[0].fmt.columns]
    else:
        return None
    lo, hi = float(p.get("MOT_PWM_MIN", 0) or 0), float(p.get("MOT_PWM_MAX", 0) or 0)
    if not 0 < lo < hi:
        lo, hi = float(p.get("RC3_MIN", 1000) or 1000), float(p.get("RC3_MAX", 2000) or 2000)
    up = [f for f in fields if max(float(getattr(m, f)) for m in ms) > lo + RAN_SHARE * (hi - lo)]
    if not up:
        return ""
    top = max(max(float(getattr(m, f)) for m in ms) for f in up)
    return f"{ms[0].get_type()} {', '.join(up)} up to {top:g} (above {lo:g}, the disarmed output)"
