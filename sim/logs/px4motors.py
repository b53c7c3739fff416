"""What a PX4 vehicle is and which of its outputs are the motors, from the log's own description
(docs/log-import.md, "PX4 as it is flown").

PX4 logs 8 or 16 outputs per group whatever the motor count (unused ones at 0 or their disarmed
value), one `actuator_outputs` instance per output driver (main PWM, auxiliary PWM, UAVCAN/DroneCAN),
and since 1.13 the normalised motor commands `actuator_motors`. The vehicle: MAV_TYPE, CA_AIRFRAME,
SYS_AUTOSTART and the rotors CA_ROTOR*. The motors: the output functions (`<GROUP>_FUNCn`, 101-104 are
motors 1-4) with each group's own MIN/MAX/DIS, and the outputs that move while armed; logs before the
output functions (PX4 1.12 and older) put motors 1-4 on the first four outputs of the group that moves.
"""
from __future__ import annotations

import math
import re

import numpy as np

from flightctl.sim.logs.columns import MAX_ROTORS, MIN_ROTORS
from flightctl.sim.logs import frames
from flightctl.sim.logs.common import Imported, Stream, command_p

MAV_TYPES = {0: "a generic vehicle", 1: "a fixed wing", 3: "a coaxial helicopter", 4: "a helicopter",
             10: "a ground rover", 11: "a boat", 12: "a submarine", 13: "a hexacopter", 14: "an octocopter",
             15: "a tricopter", 19: "a VTOL (duo tailsitter)", 20: "a VTOL (quad tailsitter)", 21: "a VTOL (tiltrotor)",
             22: "a VTOL (standard: lift rotors and a pusher)", 23: "a VTOL (tailsitter)", 24: "a VTOL (tiltwing)",
             29: "a dodecacopter"}
QUADROTOR = 2
CA_AIRFRAMES = {1: "a fixed wing", 2: "a VTOL (standard)", 3: "a VTOL (tiltrotor)", 4: "a VTOL (tailsitter)",
                5: "a rover", 6: "a motor-only vehicle", 7: "a helicopter", 8: "a helicopter (coaxial)",
                9: "a spacecraft", 10: "a multirotor with tilt", 11: "a rover"}
ROTOR_COUNTS = {1: "a single rotor", 2: "a bicopter", 3: "a tricopter", 6: "a hexacopter", 8: "an octocopter",
                12: "a dodecacopter"}
AUTOSTART_RANGES = ((2000, 3999, "a fixed wing"), (6000, 7999, "a hexacopter"), (8000, 9999, "an octocopter"),
                    (11000, 11999, "a hexacopter (coaxial)"), (12000, 12999, "an octocopter (coaxial)"),
                    (13000, 13999, "a VTOL"), (14000, 14999, "a multirotor with tilt"), (16000, 16999, "a helicopter"),
                    (17000, 17999, "an autogyro"), (50000, 69999, "a ground or water vehicle"))
MOTOR_FUNCTION = 101                 # output function of motor 1 (PX4's OutputFunction: 101-112 motors 1-12)
UAVCAN_RAW_MAX = 8191.0              # UAVCAN ESC raw command (PX4 before the output functions: (u + 1) / 2 x 8191)
MOVES = 0.01                         # an output moves while armed when its spread is over 1 % of its range


def _refuse(imp: Imported, what: str, why: str, rotorcraft: bool = False):
    """InputError naming the vehicle; `rotorcraft`: a multirotor of a layout not taken, else no multirotor."""
    kind = "a multirotor this reader does not take" if rotorcraft else frames.NOT_MULTIROTOR
    imp.fail(f"{why}: {what}, {kind}: {TAKES}")


TAKES = "diagnose knows multirotors of CA_ROTOR_COUNT 4 to 12 rotors, and PX4's quad X and + before them"
MULTIROTORS = (QUADROTOR, 13, 14)            # MAV_TYPE quadrotor, hexarotor, octorotor


def vehicle(u, p: dict, imp: Imported) -> tuple[str, str, int]:
    """(`rotors` metadata, its source, the motor count) of a multirotor (`frames.px4` for CA_ROTOR*, else
    PX4's quad X or +); InputError naming what the vehicle is otherwise."""
    from flightctl.sim.logs.ulog import topic
    mav = int(p.get("MAV_TYPE", -1))
    if mav not in MULTIROTORS and mav in MAV_TYPES:
        _refuse(imp, MAV_TYPES[mav], f"MAV_TYPE = {mav}", mav in (15, 29))      # a tricopter, a dodecacopter
    frame = int(p.get("CA_AIRFRAME", 0) or 0)
    if frame in CA_AIRFRAMES:
        _refuse(imp, CA_AIRFRAMES[frame], f"CA_AIRFRAME = {frame}", frame == 10)      # 10: a multirotor with tilt
    vs = topic(u, "vehicle_status")
    if vs is not None and "is_vtol" in vs and np.any(vs["is_vtol"]):
        _refuse(imp, "a VTOL", "vehicle_status.is_vtol")
    auto = int(p.get("SYS_AUTOSTART", 0) or 0)
    placed = "CA_ROTOR_COUNT" in p
    for lo, hi, what in AUTOSTART_RANGES:
        rotorcraft = what.startswith(("a hexa", "an octo"))
        if lo <= auto <= hi and not (rotorcraft and placed):      # a hexa or octo is read by its CA_ROTOR*
            _refuse(imp, what + (" (no CA_ROTOR* parameters to place its rotors)" if rotorcraft else ""),
                    f"SYS_AUTOSTART = {auto}", rotorcraft)
    if placed:
        count = int(p["CA_ROTOR_COUNT"])
        if not MIN_ROTORS <= count <= MAX_ROTORS:
            _refuse(imp, ROTOR_COUNTS.get(count, f"{count} rotors"), f"CA_ROTOR_COUNT = {count}", count >= 3)
        f = frames.px4(p, imp.fail)
        return f.rotors(), f.source, f.count
    if mav != QUADROTOR:
        imp.fail(f"MAV_TYPE = {mav} and no CA_ROTOR* parameters: a rotor layout this reader does not know")
    f = frames.px4_quad(auto)
    return f.rotors(), f.source, f.count


def functions(p: dict) -> dict[str, dict[int, int]]:
    """The motor outputs by group: {group: {motor (1-4): channel (1-based)}}, from `<GROUP>_FUNCn`."""
    out: dict[str, dict[int, int]] = {}
    for name, value in p.items():
        m = re.fullmatch(r"(.+)_FUNC(\d+)", name)
        if m and MOTOR_FUNCTION <= int(value) <= MOTOR_FUNCTION + 11:
            out.setdefault(m[1], {})[int(value) - MOTOR_FUNCTION + 1] = int(m[2])
    return out


def _armed_rows(t: np.ndarray, armed) -> np.ndarray:
    if armed is None:
        return np.ones(t.size, bool)
    ta, a = armed
    i = np.searchsorted(ta, t, side="right") - 1
    return np.where(i >= 0, a[np.clip(i, 0, None)], False)


def _candidates(u, armed):
    """Every actuator_outputs publisher: (instance, noutputs, times, outputs (k, n), armed rows). Two
    publishers may share an instance, told apart by `noutputs`."""
    for d in sorted((d for d in u.data_list if d.name == "actuator_outputs"), key=lambda d: d.multi_id):
        ao = d.data
        k = sum(1 for key in ao if key.startswith("output["))
        out = np.vstack([ao[f"output[{i}]"] for i in range(k)]).astype(float)
        for n in np.unique(ao["noutputs"]):
            rows = ao["noutputs"] == n
            if rows.sum() < 2:
                continue
            t = ao["timestamp"][rows] * 1e-6
            yield d.multi_id, int(n), t, out[:, rows], _armed_rows(t, armed)


def _spread(x: np.ndarray, on: np.ndarray) -> np.ndarray:
    x = x[:, on] if on.sum() > 1 else x
    return x.std(axis=1)


def motors(u, p: dict, imp: Imported, armed, count: int = 4) -> Stream:
    """The `count` motors' commands as P on 0-255 (held between samples), with `command_range`, `command`
    and `motor_outputs` in the metadata; InputError naming why the motors cannot be found."""
    from flightctl.sim.logs.ulog import topic
    by_group = functions(p)
    if len(by_group) > 1 or any(max(m) > count for m in by_group.values()):
        assigned = ", ".join(f"{g} motors {sorted(m)}" for g, m in by_group.items())
        if any(max(m) > count for m in by_group.values()):
            imp.fail(f"more motors assigned ({assigned}) than the layout's {count}")
        imp.fail(f"the motors are split over output groups ({assigned}): not read")
    group, chan = next(iter(by_group.items())) if by_group else (None, {m: m for m in range(1, count + 1)})
    if by_group and sorted(chan) != list(range(1, count + 1)):
        imp.fail(f"{group}_FUNCn assign motors {sorted(chan)}: motors 1-{count} are needed")
    channels = [chan[m] - 1 for m in range(1, count + 1)]
    best = None
    for inst, n, t, out, on in _candidates(u, armed):
        if max(channels) >= out.shape[0]:
            continue
        spread = _spread(out, on)
        span = max(float(np.ptp(out[channels])), 1.0)
        moving = spread > MOVES * span
        score = float(spread[channels].sum()) if moving[channels].all() else -1.0
        if best is None or score > best[0]:
            best = (score, inst, n, t, out, on, moving)
    if best is None or best[0] < 0:
        imp.fail("no actuator_outputs group whose motor outputs move while armed: the motor commands were not "
                 "logged (or the vehicle never flew)")
    _, inst, n, t, out, on, moving = best
    others = [i for i in np.flatnonzero(moving) if i not in channels and i < n]
    if not by_group and others:
        imp.fail(f"actuator_outputs[{inst}] outputs {', '.join(str(i + 1) for i in others)} move with the motors: "
                 f"more motors ({int(len(others)) + count}) than the layout's {count}")
    raw = out[channels]
    lo, hi, what = _range(p, group, chan, raw)
    where = (f"actuator_outputs[{inst}] outputs {', '.join(str(c + 1) for c in channels)}"
             + (f" ({group}_FUNC{', '.join(str(chan[m]) for m in range(1, count + 1))} = 101-{100 + count})" if group
                else f" (no output functions in this PX4: motors 1-{count} on the first outputs of the group that moves)"))
    imp.meta["motor_outputs"] = f"{where}; {what}"
    am = topic(u, "actuator_motors")
    if am is not None and all(f"control[{i}]" in am for i in range(count)):
        c = np.vstack([am[f"control[{i}]"] for i in range(count)]).astype(float)
        if np.isfinite(c).any() and np.nanmax(c) > 0:
            stopped = int((~np.isfinite(c)).any(axis=0).sum())
            if stopped:
                imp.notes.append(f"{stopped} actuator_motors samples without a command (NaN: stopped) read as 0")
            imp.meta["command_range"] = "0 1"
            imp.meta["command"] = (f"P = 255 actuator_motors.control[0..{count - 1}] (PX4's normalised motor commands, "
                                   "0-1)")
            return Stream("actuator_motors", am["timestamp"] * 1e-6, np.clip(np.nan_to_num(c) * 255.0, 0.0, 255.0),
                          held=True)
    P = command_p(imp, raw, lo[:, None], hi[:, None], "actuator_outputs samples outside their MIN..MAX (stopped or "
                  "disarmed: their disarmed value)")
    imp.meta["command_range"] = f"{lo.min():g} {hi.max():g}"
    imp.meta["command"] = f"P = 255 (output - MIN) / (MAX - MIN) of {where}"
    if group == "UAVCAN_EC" or what.startswith("UAVCAN"):
        imp.meta["esc_order"] = " ".join(str(c) for c in channels)
    return Stream(f"actuator_outputs[{inst}]", t, P, held=True)


def _range(p: dict, group: str | None, chan: dict[int, int], raw: np.ndarray):
    """(MIN per motor, MAX per motor, their description) of the motors' outputs."""
    if group is not None:
        lo = np.array([float(p.get(f"{group}_MIN{chan[m]}", math.nan)) for m in sorted(chan)])
        hi = np.array([float(p.get(f"{group}_MAX{chan[m]}", math.nan)) for m in sorted(chan)])
        dis = [p.get(f"{group}_DIS{chan[m]}") for m in sorted(chan)]
        if np.isfinite(lo).all() and np.isfinite(hi).all() and (hi > lo).all():
            return lo, hi, (f"{group}_MIN/MAX {lo.min():g}-{hi.max():g}"
                            + (f", disarmed {dis[0]}" if dis[0] is not None else ""))
    if np.nanmax(raw) > 2500 and int(p.get("UAVCAN_ENABLE", 0) or 0) >= 3:
        return (np.zeros(len(chan)), np.full(len(chan), UAVCAN_RAW_MAX),
                f"UAVCAN ESC raw commands 0-{UAVCAN_RAW_MAX:g} ((u + 1) / 2 x {UAVCAN_RAW_MAX:g}, PX4 before 1.13)")
    lo = [p.get(f"PWM_MAIN_MIN{i}", -1) for i in range(1, len(chan) + 1)]
    hi = [p.get(f"PWM_MAIN_MAX{i}", -1) for i in range(1, len(chan) + 1)]
    lo = np.array([v if v > 0 else p.get("PWM_MAIN_MIN", p.get("PWM_MIN", 1000)) for v in lo], dtype=float)
    hi = np.array([v if v > 0 else p.get("PWM_MAIN_MAX", p.get("PWM_MAX", 2000)) for v in hi], dtype=float)
    return lo, hi, f"PWM_MAIN_MIN/MAX {lo.min():g}-{hi.max():g} us"
