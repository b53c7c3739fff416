"""What a crash is: one definition for the loop (which cuts the motors on it), the simulator's verdict
(`flightctl sim`, its exit status), the fault matrix and the comparison scripts.

A crash is a tilt past CRASH_TILT (the vehicle is going over: nothing is left to save, so the motors
are cut at once) or a touchdown faster than CRASH_TOUCHDOWN_SPEED (a fall: a 1.5 m drop lands at
5.4 m/s; a commanded landing at 0.3 m/s). Anything else that goes wrong in the air is answered by a
controlled landing (flightctl/loop.py), never by cutting the motors.
"""
from __future__ import annotations

import math

import numpy as np

CRASH_TILT = math.radians(60)       # rad, roll or pitch
CRASH_TOUCHDOWN_SPEED = 1.0         # m/s, vertical speed at contact with the floor
LEFT_GROUND_ALT = 0.10              # m: below this the vehicle never flew


def crash_reason(tilt: float, touchdown_speed: float) -> str | None:
    """None, or why this is a crash; `tilt` (rad, largest |roll| or |pitch|), `touchdown_speed` (m/s,
    largest |vz| at contact; 0 for none). NaN counts as a crash."""
    if not abs(touchdown_speed) <= CRASH_TOUCHDOWN_SPEED:
        return f"hit the floor at {abs(touchdown_speed):.1f} m/s"
    if not abs(tilt) <= CRASH_TILT:
        return f"tilted {math.degrees(abs(tilt)):.0f} deg (past {math.degrees(CRASH_TILT):.0f} deg)"
    return None


def first_tilt_past(roll, pitch, limit: float = CRASH_TILT) -> int | None:
    """The index of a log's first row whose roll or pitch (arrays, rad) is past `limit` (a NaN is not), or None:
    where a logged crash begins (sim/plots.py `crash_times`, sim/diagnose/predict.py `before_crash`)."""
    with np.errstate(invalid="ignore"):
        over = np.flatnonzero(np.maximum(np.abs(np.asarray(roll, float)), np.abs(np.asarray(pitch, float))) > limit)
    return int(over[0]) if over.size else None
