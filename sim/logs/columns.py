"""The flight-log table's columns beyond the contract's (docs/measured-data.md), which every reader of
another autopilot's log writes and diagnose reads: the commands of motors 5.. (P5..), each motor's
measured speed (omega1..), the height, current and landing detector; which motors run; and the band of a
quadrotor's motion under control that a log must be fast enough to follow. The readers (sim/logs/) sit
below diagnose: they import this, never diagnose."""
from __future__ import annotations

import numpy as np

MIN_ROTORS, MAX_ROTORS = 4, 12      # the static tier's layouts (sim/logs/frames.py); the dynamic tier's model is the quad's
MOTOR_COLUMNS = tuple(f"P{i}" for i in range(5, MAX_ROTORS + 1))   # motors 5.. beside the contract's P1-P4
OMEGA_COLUMNS = tuple(f"omega{i}" for i in range(1, MAX_ROTORS + 1))   # each motor's measured speed (rad/s)
FOREIGN_COLUMNS = ("height", "current", "landed") + OMEGA_COLUMNS + MOTOR_COLUMNS
# The command is the ESC's range mapped onto 0-255 (docs/real-flights.md), so a motor runs above 1 % of it.
IDLE_P = 2.55
# The motion diagnose follows: its residuals are low-passed at MOTION_HZ (sim/diagnose/dataset.py LOWPASS_HZ);
# a lag or a delay of tens of milliseconds shows only in commands logged at several times that bandwidth.
MOTION_HZ = 12.0
DYNAMIC_MIN_HZ = 4.0 * MOTION_HZ


def motor_columns(table) -> tuple[str, ...]:
    """The commands' columns: the contract's P1-P4 and, for a vehicle of more motors, P5.. in order while
    they hold a command (MOTOR_COLUMNS; the `# rotors:` line says how many there are)."""
    out = [f"P{i}" for i in range(1, 5)]
    for c in MOTOR_COLUMNS:
        if c not in table or not np.isfinite(table[c]).any():
            break
        out.append(c)
    return tuple(out)


def all_running(P: np.ndarray) -> np.ndarray:
    """(n,) bool: the rows of a foreign log's commands P (N, n) where all its motors run (above IDLE_P)."""
    return (P > IDLE_P).all(axis=0)
