"""A motor at full command while the vehicle rolls away, in the static tier (docs/diagnose.md, "A motor at
full command"): a rotor that gives no thrust (a motor or ESC that stopped, a propeller lost) tips the frame
toward itself, and the attitude loop, which still believes in it, asks it for all it has and its opposite for
the least. So: spans where one motor's command sits at the log's ceiling while the others' mean is well
below it (a punch-out has them all there), and the attitude departs from its setpoint (from the attitude at
the span's start where no setpoint is logged) toward that motor, on the layout's own rotor positions.

A rotor at r_i = (x_i, y_i) (x forward, y left) gives the torques tau_phi = y_i f_i and tau_theta = -x_i f_i
(docs/conventions.md, eq. 25: tau_phi = l (f_2 - f_4), tau_theta = l (f_3 - f_1)); its lost thrust leaves
(-y_i, x_i) f_i, so roll and pitch accelerate along (-y_i, x_i): the frame's side at motor i goes down.
No yaw factor enters, so the check holds for any layout the reader declares.

A span starts in the air (or within START_S of it) and may go on after (the fall that the airborne test cuts).
The ceiling is the highest command the log holds from the first take-off on, where a firmware's output limit piles its
commands up (ArduCopter's MOT_PWM_MAX and MOT_SPIN_MAX, or ArduCopter 3.x's 1950 us; Betaflight's motorOutput
top; this project's P = 255), counted only when it is at least CEILING_MIN of the range; the floor is the
lowest command of a running motor from then on (a firmware's spin minimum). A span that starts within BEFORE_S
of a tilt past TUMBLE_RAD is the loop's recovery of a vehicle already tumbling, which a loss cannot be told
from: it is listed, never named. Below SLOW_HZ a motor output is one sample in several of the loop's, so how
long a motor stayed at full command is not seen: spans of two samples or more are then kept and said so.
"""
from __future__ import annotations

import math

import numpy as np

from flightctl.sim.diagnose.static.curve import P_FULL

MIN_PINNED_S = 0.5        # s: a loop's saturation in a manoeuvre (a flip, a punch-out's start) is shorter
PIN_TOL = 0.015           # of the range: a command this near the ceiling (or the floor) sits there (4 of 255: a
#                           loop at its limit, sampled at a log's rate, is caught at it or just off it)
CEILING_MIN = 0.75        # of the range: a highest command below this is no output limit
UNEVEN = 0.10             # of the range: the others' mean at least this far below the pinned motor
GAP_S = 0.1               # s: samples at the ceiling this close (or 2.5 motor samples) are one span
DEPART_RAD = math.radians(10.0)   # the attitude's departure toward the motor named ...
COS_TOWARD = math.cos(math.radians(45.0))   # ... within 45 degrees of that motor's direction
STOP_RAD = math.radians(90.0)     # the departure followed until it reaches this (Euler angles past it mean little)
TUMBLE_RAD = math.radians(60.0)   # a tilt from level past this ...
BEFORE_S = 2.0                    # ... within this before a span: a vehicle already tumbling
START_S = 0.5                     # s: a span starts in the air, or this near it (data.SMOOTH_S: a loss ends the
#                                   airborne test's mean command there), and may go on past it (the fall)
SLOW_HZ = 20.0                    # Hz: below, MIN_PINNED_S holds fewer than 10 motor samples
WHAT = ("spans where one motor's command sits at the log's ceiling (the others' mean at least 10 % of the range below "
        "it) for 0.5 s or more while the attitude departs from its setpoint toward that motor by 10 degrees or more: "
        "its thrust lost, or its propeller or ESC failed")


def _wrap(a: np.ndarray) -> np.ndarray:
    return (a + np.pi) % (2.0 * np.pi) - np.pi


def _attitude(f, table) -> tuple[np.ndarray, np.ndarray, str]:
    """((2, n) roll and pitch off their setpoints, rad; (n,) the tilt from level; what they are): the logged attitude (the autopilot's
    estimate) where the log has it, else the gyro integrated (`FileData.Rm`); minus the logged setpoint where
    it has one (NaN rows held from the last one), else minus nothing (the departure is then from the attitude
    at the span's start)."""
    if all(c in table and np.isfinite(table[c]).any() for c in ("roll", "pitch")):
        att, what = np.vstack([table["roll"], table["pitch"]]), "the logged attitude"
    else:
        R = f.Rm
        att = np.vstack([np.arctan2(R[7], R[8]), -np.arcsin(np.clip(R[6], -1.0, 1.0))])
        what = "the attitude of the integrated gyro"
    tilt = np.arccos(np.clip(np.cos(att[0]) * np.cos(att[1]), -1.0, 1.0))
    if all(c in table and np.isfinite(table[c]).any() for c in ("roll_sp", "pitch_sp")):
        sp = np.vstack([_held(table["roll_sp"]), _held(table["pitch_sp"])])
        return _wrap(att - np.nan_to_num(sp)), tilt, what + " off its logged setpoint"
    return att, tilt, what + " (no setpoint logged: its change from the span's start)"


def _held(x: np.ndarray) -> np.ndarray:
    """x with each NaN row given the last finite value before it (NaN before the first)."""
    ok = np.isfinite(x)
    idx = np.where(ok, np.arange(x.size), 0)
    np.maximum.accumulate(idx, out=idx)
    out = x[idx]
    out[~ok & (np.cumsum(ok) == 0)] = np.nan
    return out


def _words(u: np.ndarray) -> str:
    roll, pitch = abs(u[0]) > 0.38, abs(u[1]) > 0.38       # more than 22.5 degrees toward each axis
    return "rolled and pitched" if roll and pitch else "rolled" if roll else "pitched"


def spans(f, table, motor_hz: float) -> tuple[list[dict], dict]:
    """(the spans of `f` (a `FileData`) and its `table` where a motor sat at the ceiling while the vehicle tipped
    toward it, in time order; the ceiling and floor) (the module's docstring)."""
    P = f.P
    N = P.shape[0]
    level = {"ceiling": None, "floor": None}
    if not f.airborne.any():
        return [], level
    ok = np.isfinite(P).all(axis=0) & (f.t >= f.t[f.airborne][0])
    air = f.t[f.airborne]
    j = np.searchsorted(air, f.t)          # each row's distance to the nearest airborne row's time
    near = np.minimum(np.abs(f.t - air[np.minimum(j, air.size - 1)]), np.abs(f.t - air[np.maximum(j - 1, 0)])) <= START_S
    hi = float(P[:, ok].max())
    running = ok & f.running
    lo = float(P[:, running].min()) if running.any() else 0.0
    level = {"ceiling": round(hi, 2), "floor": round(lo, 2)}
    if hi < CEILING_MIN * P_FULL:
        return [], level
    tol = PIN_TOL * P_FULL
    others = (P.sum(axis=0) - P) / (N - 1)
    top = ok & f.running & (P >= hi - tol) & (P - others >= UNEVEN * P_FULL)
    err, tilt, what = _attitude(f, table)
    r = np.column_stack([f.layout.x, f.layout.y])
    u = np.column_stack([-r[:, 1], r[:, 0]]) / np.linalg.norm(r, axis=1)[:, None]
    dt_m = 1.0 / motor_hz
    gap = max(GAP_S, 2.5 * dt_m)
    slow = motor_hz < SLOW_HZ
    found = []
    for i in range(N):
        idx = np.flatnonzero(top[i])
        if idx.size == 0:
            continue
        for run in np.split(idx, np.flatnonzero(np.diff(f.t[idx]) > gap) + 1):
            k0, k1 = int(run[0]), int(run[-1])
            if not near[k0]:
                continue
            held = float(f.t[k1] - f.t[k0]) + dt_m
            samples = int(round((f.t[k1] - f.t[k0]) * motor_hz)) + 1
            if held < MIN_PINNED_S and not (slow and samples >= 2):
                continue
            end = min(int(np.searchsorted(f.t, f.t[k1] + dt_m, side="right")), f.t.size)
            d = _wrap(err[:, k0:end] - err[:, k0:k0 + 1])
            d = np.where(np.isfinite(d), d, 0.0)
            size = np.hypot(d[0], d[1])
            past = np.flatnonzero(size > STOP_RAD)
            if past.size:
                d, size = d[:, :past[0] + 1], size[:past[0] + 1]
            along = u[i] @ d
            j = int(np.argmax(along))
            toward = float(along[j])
            if toward < DEPART_RAD or toward < COS_TOWARD * float(size[j]):
                continue
            before = (f.t >= f.t[k0] - BEFORE_S) & (f.t < f.t[k0])
            opposite = int(np.argmin(u @ u[i]))
            window = ok[k0:k1 + 1]
            at_floor = float(np.mean(P[opposite, k0:k1 + 1][window] <= lo + tol))
            found.append({"motor": i + 1, "start_s": round(float(f.t[k0]), 2), "end_s": round(float(f.t[k1]) + dt_m, 2),
                          "held_s": round(held, 2), "samples": samples, "ceiling": level["ceiling"],
                          "share_at_ceiling": round(float(np.mean(top[i, k0:k1 + 1][window])), 2),
                          "toward_deg": round(math.degrees(toward), 1), "words": _words(u[i]),
                          "opposite": opposite + 1, "opposite_at_floor": round(at_floor, 2),
                          "tumbling": bool(np.any(tilt[before] > TUMBLE_RAD)),
                          "long": held >= MIN_PINNED_S, "attitude": what})
    found.sort(key=lambda s: s["start_s"])
    return found, level


def _line(s: dict) -> str:
    held = (f"for {s['held_s']:.1f} s" if s["long"] else
            f"in {s['samples']} samples over {s['held_s']:.1f} s (its time there between samples not seen)")
    out = (f"motor {s['motor']} at full command (P {s['ceiling']:.1f} of 255) {held} from {s['start_s']:.2f} s while the "
           f"vehicle {s['words']} toward it by {s['toward_deg']:.0f} deg")
    if s["opposite_at_floor"] > 0.0:
        out += f", motor {s['opposite']} across it at its minimum for {100 * s['opposite_at_floor']:.0f} % of the span"
    return out


def motor_at_full(files, tables, motor_hz: float, faster: str) -> dict:
    """The finding over the logs `files` (their `tables`, motor outputs at `motor_hz`; `faster`: how the log's
    autopilot logs them faster, `rates.faster`): {what, motor_hz, ceiling_floor, spans, named, verdict, rate}."""
    found, levels = [], []
    for k, (f, t) in enumerate(zip(files, tables)):
        s, level = spans(f, t, motor_hz)
        found += [dict(x, log=k) for x in s]       # `log`: which of the logs (0 the first), its own times
        levels.append(level)
    named = next((s for s in found if not s["tumbling"]), None)
    rate = None
    if motor_hz < SLOW_HZ:
        rate = (f"the motor outputs were logged at {motor_hz:.0f} Hz: each a single sample of the loop's, so how long a motor "
                f"stayed at full command between them is not seen (a span of {MIN_PINNED_S:g} s is told from "
                f"{SLOW_HZ:g} Hz on){faster}")
    if named is None:
        verdict = ("none: no motor sat at full command while the vehicle tipped toward it" if not found else
                   "none named: every span starts while the vehicle was already tumbling (its loop's recovery, not told "
                   "from a loss)")
    else:
        verdict = (_line(named) + f": motor {named['motor']}'s thrust lost, or its propeller or ESC failed")
        later = [s for s in found if s is not named]
        if later:
            verdict += (f"; then {len(later)} more span{'s' if len(later) > 1 else ''} ("
                        + ", ".join(f"motor {s['motor']} from {s['start_s']:.2f} s" for s in later[:3])
                        + (", ..." if len(later) > 3 else "")
                        + (f"), {sum(s['tumbling'] for s in later)} of them while it tumbled" if any(s["tumbling"] for s in later)
                           else ")"))
    return {"what": WHAT, "motor_hz": motor_hz, "ceiling_floor": levels, "spans": found, "named": None if named is None else named["motor"],
            "verdict": verdict, "rate": rate}
