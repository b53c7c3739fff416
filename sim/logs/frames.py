"""The multirotor layouts the firmwares declare, one table for every reader (docs/log-import.md,
"Frames"): where each motor is and which way it spins, read from the firmware's own mixer.

A layout is the motors in their output order: (x forward, y left) in arm lengths and the spin seen from
above, +1 counter-clockwise (docs/measured-data.md's s_i), the mixer's yaw factor beside it where the mixer
gives the motors unequal ones (ArduPilot's quad V: 0.7981 and 1). The `# rotors:` line a reader writes
is `layout.rotors()`; the report names `layout.source`.

- **ArduPilot** (FRAME_CLASS, FRAME_TYPE): libraries/AP_Motors/AP_MotorsMatrix.cpp,
  AP_MotorsMatrix::setup_motors, `case MOTOR_FRAME_QUAD` / `MOTOR_FRAME_HEXA` / `MOTOR_FRAME_OCTA` /
  `MOTOR_FRAME_OCTAQUAD` and their `MOTOR_FRAME_TYPE_*` cases. `add_motor(n, angle, yaw_factor, order)`
  puts motor n at `angle` from the nose, clockwise positive seen from above: its roll factor is
  cos(angle + 90) = -sin(angle) (our y, left positive) and its pitch factor cos(angle) (our x);
  `add_motor_raw(n, roll, pitch, yaw, order)` gives those factors directly (the octo V and H). The yaw
  factor's sign is the spin: AP_MOTORS_MATRIX_YAW_FACTOR_CCW = 1, _CW = -1 (AP_MotorsMatrix.h).
  ArduCopter 3.x's FRAME (orientation: 0 plus, 1 X, 2 V, 3 H) is today's FRAME_TYPE of the same number
  (AP_Motors_Class.h of 3.2; AP_MotorsQuad::setup_motors has these positions and spins).
- **PX4**: the CA_ROTOR_COUNT rotors at CA_ROTORn_PX/PY (m, FRD), KM > 0 counter-clockwise (the control
  allocation's parameters, src/modules/control_allocator/module.yaml), any count.
- **Betaflight and INAV**: their logs do not name the mixer (`mixerMode` is not in the blackbox header:
  its `mixer_type` is the mixing law, LEGACY/LINEAR/DYNAMIC/EZLANDING, and `features` holds no layout);
  the motor count chooses it: 4 quad X, 6 hexa X (src/main/flight/mixer_init.c, `mixerQuadX`,
  `mixerHex6X`: {throttle, roll, pitch, yaw} per motor, roll +1 on the left, pitch +1 at the rear, yaw -1
  clockwise with the props in). Six motors are also HEX6 (plus), HEX6H and Y6, which the header does not
  tell apart: hexa X is assumed and the report says so. Eight motors are four mixers as common as each
  other (OCTOX8, OCTOX8P, OCTOFLATP, OCTOFLATX: mixer_init.c's `mixers[]`, 266-268 and 282 at betaflight
  301d01abc4): refused by name. Another count, or a custom mixer (`mmix` is not logged), is refused.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

DEG = math.pi / 180.0
# The words of every refusal of a vehicle that is no multirotor (a plane, a VTOL, a helicopter, a rover): the
# corpus' headline counts such logs apart from the airborne multirotor flights (diagnose/corpus.py)
NOT_MULTIROTOR = "not a multirotor"
CCW, CW = 1.0, -1.0                       # AP_MOTORS_MATRIX_YAW_FACTOR_CCW / _CW (AP_MotorsMatrix.h)


@dataclass(frozen=True)
class Frame:
    """A layout: motors in output order, (x, y) in arm lengths (x forward, y left), spin +1 counter-clockwise,
    the mixer's yaw factor, and where it was read."""
    name: str
    x: tuple[float, ...]
    y: tuple[float, ...]
    spin: tuple[float, ...]
    yaw_factor: tuple[float, ...]
    source: str

    @property
    def count(self) -> int:
        return len(self.x)

    def rotors(self) -> str:
        """The `# rotors:` line (docs/measured-data.md): `x y spin` per motor, `;` between, in arm lengths."""
        return "; ".join(f"{round(x, 4) + 0.0:.4f} {round(y, 4) + 0.0:.4f} {s:+.0f}"
                         for x, y, s in zip(self.x, self.y, self.spin))


def _frame(name: str, motors, source: str) -> Frame:
    """A Frame of [(x, y, yaw factor)] scaled to arm lengths (the furthest motor at 1)."""
    arm = max(math.hypot(x, y) for x, y, _ in motors) or 1.0
    return Frame(name, tuple(x / arm for x, _, _ in motors), tuple(y / arm for _, y, _ in motors),
                 tuple(math.copysign(1.0, k) for _, _, k in motors), tuple(float(k) for _, _, k in motors), source)


def _angle(a: float, k: float) -> tuple[float, float, float]:
    """AP_MotorsMatrix::add_motor(n, a, k): pitch factor cos(a) (x), roll factor cos(a + 90) (y, left)."""
    return math.cos(a * DEG), math.cos((a + 90.0) * DEG), k


def _raw(roll: float, pitch: float, k: float) -> tuple[float, float, float]:
    """AP_MotorsMatrix::add_motor_raw(n, roll, pitch, k): the factors as they are."""
    return pitch, roll, k


# AP_MotorsMatrix::setup_motors: (FRAME_CLASS, FRAME_TYPE) -> (name, motors 1..N as (x, y, yaw factor))
_Q = lambda *m: [_angle(a, k) for a, k in m]
ARDUPILOT = {
    (1, 0): ("QUAD/PLUS", _Q((90, CCW), (-90, CCW), (0, CW), (180, CW))),
    (1, 1): ("QUAD/X", _Q((45, CCW), (-135, CCW), (-45, CW), (135, CW))),
    (1, 2): ("QUAD/V", _Q((45, 0.7981), (-135, 1.0), (-45, -0.7981), (135, -1.0))),
    (1, 3): ("QUAD/H", _Q((45, CW), (-135, CW), (-45, CCW), (135, CCW))),
    (1, 6): ("QUAD/PLUSREV", _Q((90, CW), (-90, CW), (0, CCW), (180, CCW))),
    (1, 12): ("QUAD/BF_X", _Q((135, CW), (45, CCW), (-135, CCW), (-45, CW))),
    (1, 13): ("QUAD/DJI_X", _Q((45, CCW), (-45, CW), (-135, CCW), (135, CW))),
    (1, 14): ("QUAD/CW_X", _Q((45, CCW), (135, CW), (-135, CCW), (-45, CW))),
    (1, 18): ("QUAD/BF_X_REV", _Q((135, CCW), (45, CW), (-135, CW), (-45, CCW))),
    (2, 0): ("HEXA/PLUS", _Q((0, CW), (180, CCW), (-120, CW), (60, CCW), (-60, CCW), (120, CW))),
    (2, 1): ("HEXA/X", _Q((90, CW), (-90, CCW), (-30, CW), (150, CCW), (30, CCW), (-150, CW))),
    (3, 0): ("OCTA/PLUS", _Q((0, CW), (180, CW), (45, CCW), (135, CCW), (-45, CCW), (-135, CCW), (-90, CW), (90, CW))),
    (3, 1): ("OCTA/X", _Q((22.5, CW), (-157.5, CW), (67.5, CCW), (157.5, CCW), (-22.5, CCW), (-112.5, CCW),
                          (-67.5, CW), (112.5, CW))),
    (3, 2): ("OCTA/V", [_raw(1.0, 0.34, CW), _raw(-1.0, -0.32, CW), _raw(1.0, -0.32, CCW), _raw(-0.5, -1.0, CCW),
                        _raw(1.0, 1.0, CCW), _raw(-1.0, 0.34, CCW), _raw(-1.0, 1.0, CW), _raw(0.5, -1.0, CW)]),
    (3, 3): ("OCTA/H", [_raw(-1.0, 1.0, CW), _raw(1.0, -1.0, CW), _raw(-1.0, 0.333, CCW), _raw(-1.0, -1.0, CCW),
                        _raw(1.0, 1.0, CCW), _raw(1.0, -0.333, CCW), _raw(1.0, 0.333, CW), _raw(-1.0, -0.333, CW)]),
    (4, 0): ("OCTAQUAD/PLUS", _Q((0, CCW), (-90, CW), (180, CCW), (90, CW), (-90, CCW), (0, CW), (90, CCW), (180, CW))),
    (4, 1): ("OCTAQUAD/X", _Q((45, CCW), (-45, CW), (-135, CCW), (135, CW), (-45, CCW), (45, CW), (135, CCW), (-135, CW))),
    (4, 3): ("OCTAQUAD/H", _Q((45, CW), (-45, CCW), (-135, CW), (135, CCW), (-45, CW), (45, CCW), (135, CW), (-135, CCW))),
}
AP_SOURCE = "libraries/AP_Motors/AP_MotorsMatrix.cpp, AP_MotorsMatrix::setup_motors"
AP_TYPES = {0: "PLUS", 1: "X", 2: "V", 3: "H", 4: "V-tail", 5: "A-tail", 6: "PLUSREV", 10: "Y6B", 11: "Y6F",
            12: "BF_X", 13: "DJI_X", 14: "CW_X", 15: "I", 16: "NYT_PLUS", 17: "NYT_X", 18: "BF_X_REV", 19: "Y4"}


def ardupilot(cls: int, ftype: int, fail, what: str = "") -> Frame:
    """The layout of ArduPilot's FRAME_CLASS `cls` and FRAME_TYPE `ftype`; `fail` (one line) for a pair
    AP_MotorsMatrix has no matrix for here (V-tail and A-tail: front motors without a yaw factor, so no
    spin the static tier can use; Y6 and the NYT frames)."""
    if (cls, ftype) not in ARDUPILOT:
        fail(f"FRAME_CLASS {cls}, FRAME_TYPE {ftype} ({AP_TYPES.get(ftype, 'unknown type')}): a frame whose matrix "
             f"this reader does not take (it takes {', '.join(n for n, _ in ARDUPILOT.values())})")
    name, motors = ARDUPILOT[(cls, ftype)]
    f = _frame(name, motors, "")
    unequal = len({abs(k) for k in f.yaw_factor}) > 1
    spins = ", ".join(f"{i + 1} {'CCW' if s > 0 else 'CW'}" for i, s in enumerate(f.spin))
    source = (f"ArduPilot's {name} ({what or f'FRAME_CLASS {cls}, FRAME_TYPE {ftype}'}; {AP_SOURCE}): {f.count} "
              f"motors, {spins}" + (f"; the mixer's yaw factors {', '.join(f'{k:+g}' for k in f.yaw_factor)} "
                                     "(unequal: the spins are their signs)" if unequal else ""))
    return Frame(f.name, f.x, f.y, f.spin, f.yaw_factor, source)


def px4(p: dict, fail) -> Frame:
    """The CA_ROTOR_COUNT rotors of PX4's control allocation (FRD metres to ours: y changes sign)."""
    count = int(p["CA_ROTOR_COUNT"])
    if count < 3:
        fail(f"CA_ROTOR_COUNT = {count}: not a multirotor the static tier can read (three rotors or more)")
    motors = []
    for i in range(count):
        x, y, km = (float(p.get(f"CA_ROTOR{i}_{k}", math.nan)) for k in ("PX", "PY", "KM"))
        if not all(math.isfinite(v) for v in (x, y, km)) or km == 0:
            fail(f"CA_ROTOR{i}_PX/PY/KM missing or zero: the rotor layout is unknown")
        motors.append((x, -y, km))
    if any(abs(float(p.get(f"CA_ROTOR{i}_AZ", -1.0))) < 0.95 for i in range(count)):      # FRD: -1 is up
        fail("CA_ROTORn_AX/AY/AZ tilt a rotor out of the body's z: a tilted-rotor layout this reader does not take")
    arm = max(math.hypot(x, y) for x, y, _ in motors)
    f = _frame(f"{count} rotors", motors, "")
    return Frame(f.name, f.x, f.y, f.spin, f.yaw_factor,
                 f"PX4's CA_ROTOR0..{count - 1}_PX/PY/KM (CA_ROTOR_COUNT {count}; FRD positions, KM > 0 counter-"
                 f"clockwise; arm {arm:.3g} m)")


# PX4 before the control allocation (no CA_ROTOR*): the quad X (SYS_AUTOSTART 4000-4999): motor 1 front right,
# 2 rear left, 3 front left, 4 rear right; the quad + (5000-5999): 1 right, 2 left, 3 front, 4 rear; 1 and 2
# counter-clockwise in both. FRD (x, y, spin +1 counter-clockwise), arm length 1.
PX4_QUAD_X = ((1.0, 1.0, 1.0), (-1.0, -1.0, 1.0), (1.0, -1.0, -1.0), (-1.0, 1.0, -1.0))
PX4_QUAD_PLUS = ((0.0, 1.0, 1.0), (0.0, -1.0, 1.0), (1.0, 0.0, -1.0), (-1.0, 0.0, -1.0))


def px4_quad(auto: int) -> Frame:
    """PX4's quad X or + by SYS_AUTOSTART, for a log without CA_ROTOR* (MAV_TYPE 2)."""
    plus = 5000 <= auto <= 5999
    f = _frame("quad +" if plus else "quad X", [(x, -y, s) for x, y, s in (PX4_QUAD_PLUS if plus else PX4_QUAD_X)], "")
    if plus:
        source = (f"PX4's quad + for SYS_AUTOSTART {auto} (no CA_ROTOR* parameters): motor 1 right, 2 left, "
                  "3 front, 4 rear; 1 and 2 counter-clockwise")
    else:
        known = "" if 4000 <= auto <= 4999 else " (not in PX4's quad X range 4000-4999: assumed)"
        source = (f"PX4's quad X for SYS_AUTOSTART {auto}{known} (MAV_TYPE 2, no CA_ROTOR* parameters): motor 1 "
                  "front right, 2 rear left, 3 front left, 4 rear right; 1 and 2 counter-clockwise")
    return Frame(f.name, f.x, f.y, f.spin, f.yaw_factor, source)


# Betaflight's src/main/flight/mixer_init.c (mixer.c before 4.3; INAV's mixer.c): {roll, pitch, yaw} per motor (throttle 1 left out)
BETAFLIGHT = {4: ("mixerQuadX", ((-1.0, 1.0, -1.0), (-1.0, -1.0, 1.0), (1.0, 1.0, 1.0), (1.0, -1.0, -1.0))),
              6: ("mixerHex6X", ((-0.5, 0.866025, 1.0), (-0.5, -0.866025, 1.0), (0.5, 0.866025, -1.0),
                            (0.5, -0.866025, -1.0), (-1.0, 0.0, -1.0), (1.0, 0.0, 1.0)))}
BF_NAMES = {4: "motor 1 rear right, 2 front right, 3 rear left, 4 front left",
            6: "motor 1 rear right, 2 front right, 3 rear left, 4 front left, 5 right, 6 left"}
ROTOR_NAMES = {1: "a single rotor", 2: "a bicopter", 3: "a tricopter", 6: "a hexacopter", 8: "an octocopter"}
# The other mixers of a count (mixer_init.c's `mixers[]`, betaflight 301d01abc4, all compiled: USE_UNCOMMON_MIXERS
# is defined in src/main/target/common_pre.h:422): six motors HEX6 (mixerHex6P, plus), HEX6H, Y6 (coaxial) beside
# HEX6X; eight motors OCTOX8 (coaxial X, mixer_init.c:166), OCTOX8P (coaxial plus, :177), OCTOFLATP (:188) and
# OCTOFLATX (:199), none the default of its count
OTHER_MIXERS = {6: "HEX6 (plus), HEX6H and Y6 (coaxial)"}
BF_OCTO = "OCTOX8 (coaxial X), OCTOX8P (coaxial plus), OCTOFLATP (flat plus) or OCTOFLATX (flat X)"


def betaflight(count: int, firmware: str, reversed_, fail) -> Frame:
    """Betaflight's or INAV's mixer for `count` motors (the header does not name it); `reversed_`:
    yaw_motors_reversed / motor_direction_inverted from the header, None when it is not there."""
    if count <= 2:
        fail(f"{count} motor{'s' if count > 1 else ''} (motor[0..{count - 1}]): a plane or a flying wing, "
             f"{NOT_MULTIROTOR} (its mixer is not in the blackbox header)")
    if count == 8:
        fail(f"8 motors (motor[0..7]): an octocopter, whose mixer {firmware}'s blackbox header does not name: "
             f"{BF_OCTO} (src/main/flight/mixer_init.c, mixers[]: eight motors each, with other positions and spins; "
             "the header's mixer_type is the mixing law, not the layout), not told apart by the log")
    if count not in BETAFLIGHT:
        fail(f"{count} motors (motor[0..{count - 1}]): {ROTOR_NAMES.get(count, f'{count} motors')} whose mixer the "
             f"blackbox header does not name (it takes {' and '.join(f'{n} ({m})' for n, (m, _) in BETAFLIGHT.items())} "
             "motors, by their count)")
    name, mix = BETAFLIGHT[count]
    sign = -1.0 if reversed_ else 1.0
    # the yaw factor: -1 on the clockwise rotors with the props in (the default), all reversed by the header's flag
    f = _frame(name, [(-pitch, roll, sign * yaw) for roll, pitch, yaw in mix], "")
    return Frame(f.name, f.x, f.y, f.spin, f.yaw_factor,
                 f"{firmware}'s {name} (src/main/flight/mixer_init.c, chosen by the "
                 f"{count} motors: the header does not name the mixer"
                 + (f", and {OTHER_MIXERS[count]} have {count} motors too: {name} assumed" if count in OTHER_MIXERS else "")
                 + f"; {BF_NAMES[count]}), "
                 + (f"yaw_motors_reversed = {int(reversed_)}" if reversed_ is not None else
                    "the motor direction not in the header: props in assumed"))
