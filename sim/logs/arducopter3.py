"""ArduCopter before FRAME_CLASS (3.0 to 3.4, 2013-2016) as its DataFlash logs describe it
(docs/log-import.md, "ArduPilot"). Read from ArduPilot's source of those versions:

- One firmware per frame class (config.h's FRAME_CONFIG: quad, hexa, octa, heli, ...). From 3.2 the log
  says which (`Frame: QUAD` in a MSG and in the text dump's header); before, the log's own formats do:
  MOT has one field per motor (Mot1..Mot8 in the octocopter build) and the helicopter build adds GGain
  and its swashplate parameters (H_SV1_POS, H_SWASH_TYPE, ...).
- FRAME is the orientation (AP_Motors_Class.h): 0 plus, 1 X, 2 V, 3 H, 4 V-tail, 5 A-tail; the quad's
  motor positions and spins (AP_MotorsQuad::setup_motors) are those of today's FRAME_TYPE 0, 1 and 3, and
  any other value is taken as X there (10-13, the NEW_ frames, included).
- Motors 1-4 on outputs 1-4, driven over the throttle channel's range: RC3_MIN (+ THR_MIN when flying)
  to RC3_MAX (AP_MotorsMatrix::output_armed). Their pulses are in MOT (Mot1.., 3.0 and 3.1) or RCOU,
  whose fields were renamed twice: Chan1..8 from 3.1.1, Ch1.. in the 3.3 development builds of 2015
  (RCOU "Ihhhh": TimeMS, Ch1..Ch4), C1.. from 3.3 (TimeUS): the log's own FMT says which.
- LOG_BITMASK (defines.h): bit 7 IMU (logged in the 50 Hz loop), bit 10 MOTORS, RCOUT from 3.1 (the 10 Hz
  loop), whatever the main loop's rate; LOG_BITMASK's IMU_FAST (bit 18) came with 3.3.
- CURR's Volt and Curr are V x 100 and A x 100 in int16 fields (Log_Write_Current); CTUN's BarAlt is the
  barometer's altitude above the ground at boot (m).
"""
from __future__ import annotations

import re

import numpy as np

from flightctl.sim.logs.common import Imported
from flightctl.sim.logs.px4motors import MOVES      # an output moves when its spread is over 1 % of its range

FRAME_CONFIG = {"QUAD": 1, "HEXA": 2, "OCTA": 3, "OCTA_QUAD": 4, "Y6": 5, "HELI": 6, "TRI": 7, "SINGLE": 8,
                "COAX": 9}                    # FRAME_CONFIG_STRING to today's FRAME_CLASS
# MOT's motor fields to (FRAME_CLASS, what the count alone tells)
MOTOR_COUNTS = {3: (7, "a tricopter"), 4: (1, "a quadrotor"), 6: (2, "a hexacopter or a Y6"),
                8: (3, "an octocopter or an octo-quad")}
BUILDS = {1: "Quad", 2: "Hexa", 3: "Octa", 4: "OctaQuad"}   # FRAME_CLASS to the build's AP_Motors class
ORIENTATION = {0: 0, 1: 1, 2: 2, 3: 3}        # FRAME to today's FRAME_TYPE: plus, X, V, H (the same matrices)
UNTAKEN = {4: "V-tail", 5: "A-tail"}
LOG_IMU, LOG_MOTORS = 7, 10                   # LOG_BITMASK bits
RCOU_FIELDS = ("Chan", "Ch", "C")             # RCOU's output n is Chan<n> (3.1.1-3.2), Ch<n> (3.3-dev), C<n> (3.3)


def is_legacy(p: dict) -> bool:
    """A log of ArduCopter before FRAME_CLASS: FRAME is its orientation parameter."""
    return "FRAME_CLASS" not in p and "FRAME" in p


def frame_class(p: dict, formats: dict, texts: list[str]) -> tuple[int | None, str, str]:
    """(today's FRAME_CLASS or None when the log does not say, what the vehicle is, the evidence in words)."""
    for text in texts:
        m = re.search(r"Frame: (\w+)", text)
        if m and m[1] in FRAME_CONFIG:
            return FRAME_CONFIG[m[1]], "", f"'Frame: {m[1]}' in the log"
    heli = sorted(k for k in p if k.startswith(("H_SV", "H_SWASH", "H_COL_")))
    mot = formats.get("MOT")
    cols = list(getattr(mot, "columns", []) or [])
    if heli or "GGain" in cols:
        why = ", ".join(([f"its H_ parameters ({', '.join(heli[:3])}, ...)"] if heli else [])
                        + (["MOT's GGain field"] if "GGain" in cols else []))
        return 6, "a traditional helicopter", f"ArduCopter's helicopter build: {why}"
    n = sum(1 for c in cols if re.fullmatch(r"Mot\d+", c))
    if n:
        cls, name = MOTOR_COUNTS.get(n, (None, ""))
        return cls, name, f"the log's MOT message has {n} motor fields ({cols[0]}..{cols[n - 1]}): the {n}-motor build"
    return None, "", ""


def frame_type(p: dict, imp: Imported) -> int:
    """Today's FRAME_TYPE of FRAME (the orientation); InputError for a geometry not taken."""
    f = int(p.get("FRAME", 1))
    if f in UNTAKEN:
        imp.fail(f"FRAME = {f}: ArduCopter's quad {UNTAKEN[f]} frame, a geometry (front motors without a yaw factor, "
                 "so no spin to read their shares by) this reader does not take")
    if f not in ORIENTATION:
        imp.notes.append(f"FRAME = {f}: taken as X, as ArduCopter 3.x's AP_MotorsQuad takes any value but 0-5")
    return ORIENTATION.get(f, 1)


def log_bitmask(p: dict) -> int:
    """LOG_BITMASK as its bits (a 16-bit parameter before 3.3, logged signed: -22530 is 43006)."""
    v = int(p.get("LOG_BITMASK", 0) or 0)
    return v + 65536 if v < 0 else v


def unlogged(p: dict, gyro: bool, motors: bool) -> str:
    """'the gyro (IMU) and the motor outputs were not logged: LOG_BITMASK 830 lacks ...' for what is missing."""
    missing = ([("the gyro (IMU)", LOG_IMU, "IMU")] if not gyro else []) + \
              ([("the motor outputs", LOG_MOTORS, "MOTORS, named RCOUT from 3.1")] if not motors else [])
    if not missing:
        return ""
    what = " and ".join(m[0] for m in missing)
    were = f"{what} {'were' if len(missing) > 1 else 'was'} not logged"
    if "LOG_BITMASK" not in p:
        return were + ": LOG_BITMASK's " + " and ".join(f"bit {b} ({name}, {1 << b})" for _, b, name in missing) + \
            " log them (the parameter is not in this log)"
    mask = log_bitmask(p)
    lacks = [(b, name) for _, b, name in missing if not mask >> b & 1]
    if not lacks:
        return were
    return (were + f": LOG_BITMASK {mask} lacks " + ", ".join(f"bit {b} ({name}, {1 << b})" for b, name in lacks)
            + f"; add {sum(1 << b for b, _ in lacks)}")


def outputs(p: dict, msgs: dict, n: int, imp: Imported) -> tuple[str, list[str]]:
    """(the message of the motor pulses, its fields for motors 1-n): MOT's Mot1..n, else RCOU's first n
    pulse fields (Chan, Ch or C and the output's number, as its FMT names them); InputError when the
    outputs after the n-th move while armed with no auxiliary function (RCn_FUNCTION 0): more motors than
    the frame's."""
    if msgs["MOT"]:
        return "MOT", [f"Mot{m}" for m in range(1, n + 1)]
    rc = msgs["RCOU"]
    if not rc:
        return "", []
    chan = next((pre for pre in RCOU_FIELDS if f"{pre}1" in rc[0].fmt.columns), None)
    if chan is None:
        imp.fail(f"RCOU's fields ({', '.join(rc[0].fmt.columns)}) name no output pulses (Chan1, Ch1 or C1): the "
                 "motor commands are not in this log")
    if not hasattr(rc[0], f"{chan}{n}"):
        imp.fail(f"RCOU has no {chan}{n}: the {n} motors' commands are not all in this log")
    lo, hi = float(p.get("RC3_MIN", 1000)), float(p.get("RC3_MAX", 2000))
    moving = []
    for c in range(n + 1, 9):
        if not hasattr(rc[0], f"{chan}{c}") or int(p.get(f"RC{c}_FUNCTION", 0) or 0) != 0:
            continue
        v = np.array([getattr(m, f"{chan}{c}") for m in rc], dtype=float)
        if np.ptp(v) > MOVES * (hi - lo):
            moving.append(c)
    if moving:
        imp.fail(f"outputs {', '.join(map(str, moving))} move with motors 1-{n} and have no auxiliary function "
                 f"(RC{moving[0]}_FUNCTION = 0): more motors than the frame's {n}")
    return "RCOU", [f"{chan}{m}" for m in range(1, n + 1)]
