"""The rate setpoint of a Betaflight 3.1 log that does not log one (3.1 logs no setpoint[]; docs/steps.md):
computed from the logged rcCommand through the firmware's own rate curve, read in its source
(betaflight v3.1.5, src/main/fc/fc_rc.c:92-129 `calculateSetpointRate`, the same function from v3.1.4 to
v3.1.7; power3 is x^3, src/main/common/maths.h:23):

    rcRate = rcRate8 / 100 (rcYawRate8 on yaw), and above 2: rcRate += 14.54 (rcRate - 2)   fc_rc.c:98-108
    x = rcCommand / 500; with rcExpo8 e: x = x |x|^3 e/100 + x (1 - e/100)                fc_rc.c:110-118
    rate = 200 rcRate x, times 1 / clamp(1 - |rcCommand / 500| rates[axis] / 100, 0.01, 1)  fc_rc.c:120-124
    setpoint = clamp(rate, -1998, 1998) deg/s                                              fc_rc.c:128

The logged rcCommand is the one the curve takes: its deadband and yaw direction already applied
(fc_rc.c:266-287, updateRcCommands) and, with rc_interpolation on, interpolated in place between RC
frames (fc_rc.c:211-226) before the curve. The PID loop takes this setpoint less the filtered gyro
(flight/pid.c:228, 245 of v3.1.5). Not modelled: the acceleration limits (rateAccelLimit,
yawRateAccelLimit, pid.c:230-231) and the FPV camera-angle mix (fc_rc.c:243-244): named in the source line.
"""
from __future__ import annotations

import numpy as np

DEG = np.pi / 180.0
SETPOINT_RATE_LIMIT = 1998.0     # deg/s, fc_rc.c:92
RC_RATE_INCREMENTAL = 14.54      # fc_rc.c:93
FIRST, BEYOND = (3, 1, 4), (3, 2, 0)     # the versions whose fc_rc.c:95-129 this is


def applies(kind: str, ver: tuple[int, ...], h: dict) -> bool:
    """A Betaflight log whose rate curve this is, with the curve's settings in its header."""
    return (kind == "betaflight" and FIRST <= tuple(ver) < BEYOND
            and all(k in h for k in ("rcRate", "rcExpo", "rcYawRate", "rcYawExpo", "rates")))


def setpoint(h: dict, rc: np.ndarray) -> np.ndarray:
    """The rate setpoint (rad/s), rows (3, n), of rcCommand[0..2] as logged (counts, -500..500)."""
    out = np.empty(rc.shape, float)
    rates = list(h["rates"]) + [0, 0, 0]
    for axis in range(3):
        rate8, expo8 = (h["rcYawRate"], h["rcYawExpo"]) if axis == 2 else (h["rcRate"], h["rcExpo"])
        rc_rate = float(rate8) / 100.0
        if rc_rate > 2.0:
            rc_rate += RC_RATE_INCREMENTAL * (rc_rate - 2.0)
        x = rc[axis] / 500.0
        ax = np.abs(x)
        if expo8:
            e = float(expo8) / 100.0
            x = x * ax ** 3 * e + x * (1.0 - e)
        rate = 200.0 * rc_rate * x
        if rates[axis]:
            rate = rate / np.clip(1.0 - ax * (float(rates[axis]) / 100.0), 0.01, 1.0)
        out[axis] = np.clip(rate, -SETPOINT_RATE_LIMIT, SETPOINT_RATE_LIMIT) * DEG
    return out


def source(h: dict) -> str:
    return (f"rcCommand[0..2] through Betaflight 3.1's rate curve (src/main/fc/fc_rc.c:95-129 of v3.1.5): rcRate "
            f"{h['rcRate']}, rcExpo {h['rcExpo']}, rcYawRate {h['rcYawRate']}, rcYawExpo {h['rcYawExpo']}, rates "
            f"{list(h['rates'])}; not modelled: the acceleration limits (rateAccelLimit, yawRateAccelLimit)")
