"""The thrust curve the static tier reads the motor commands through: each rotor's thrust against its
full-command thrust, from the command P (0-255). Which curve is said in every finding that uses it.

- A log that declares one (`# thrust_curve: expo E spin A B`, ArduPilot's MOT_THST_EXPO, MOT_SPIN_MIN
  and MOT_SPIN_MAX as `flightctl.sim.logs.dataflash` writes them): the output u = (P/255 - A) / (B - A)
  of the spin range gives thrust (1 - E) u + E u^2 (AP_MotorsMulticopter::thrust_to_actuator inverted);
  E = 1 with A = h2/255, B = 1 is eq. 26.
- This project's own log: eq. 26, f = h1 (P - h2)^2, with the airframe's h2.
- A foreign log that declares none but measured its rotor speeds (ESC telemetry, eRPM): eq. 26 with the h2
  the speeds give (`SpeedCurve`: Omega = a (P - h2), eq. 27's thrust c1 Omega^2 making eq. 26's f = h1
  (P - h2)^2; fitted on the airborne rows, one h2 for the rotors), the same curve the rotors' speed
  per command is judged against (`hover.speed_gains`): one curve and so one centre of mass per flight.
- A foreign log that declares none and has no speeds: eq. 26's shape with h2 = 0 (thrust as the square of the command
  above the log's idle, which the readers map to P = 0), said as assumed: the sizes of the shares scale
  with the curve's slope (a linear curve halves them).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

P_FULL = 255.0


@dataclass(frozen=True)
class Curve:
    expo: float          # 0: thrust linear in the spin range's output; 1: quadratic (eq. 26)
    spin_min: float      # P / 255 at zero thrust
    spin_max: float      # P / 255 at full thrust
    source: str
    declared: bool

    def thrust(self, P: np.ndarray) -> np.ndarray:
        """Thrust against full thrust (0-1) at the commands P."""
        u = np.clip((np.asarray(P, float) / P_FULL - self.spin_min) / (self.spin_max - self.spin_min), 0.0, None)
        return (1.0 - self.expo) * u + self.expo * u * u

    def command(self, f: np.ndarray) -> np.ndarray:
        """The command P that gives thrust f (0 and above; the inverse of `thrust`)."""
        f = np.maximum(np.asarray(f, float), 0.0)
        e = self.expo
        u = f if e == 0 else ((e - 1.0) + np.sqrt((1.0 - e) ** 2 + 4.0 * e * f)) / (2.0 * e)
        return P_FULL * (self.spin_min + u * (self.spin_max - self.spin_min))

    def text(self) -> str:
        return f"expo {self.expo:g} spin {self.spin_min:g} {self.spin_max:g}"


def parse(text: str, source: str, fail) -> Curve:
    """`expo E spin A B` (a log's `# thrust_curve:` line)."""
    parts = text.split()
    try:
        if len(parts) != 5 or parts[0] != "expo" or parts[2] != "spin":
            raise ValueError
        e, a, b = float(parts[1]), float(parts[3]), float(parts[4])
    except ValueError:
        fail(f"# thrust_curve: {text!r} is not 'expo E spin MIN MAX'")
    if not (0.0 <= e <= 1.0 and 0.0 <= a < b <= 1.0):
        fail(f"# thrust_curve: {text!r}: expo in 0-1 and 0 <= spin MIN < MAX <= 1 needed")
    return Curve(e, a, b, source, True)


def declared(table) -> Curve | None:
    """The curve the log's `# thrust_curve:` line declares, None without one; InputError naming the
    file when the line is not a curve."""
    text = table.meta.get("thrust_curve", "").strip()
    if not text:
        return None
    return parse(text, table.meta.get("thrust_curve_source", f"the log's '# thrust_curve: {text}'"), table.fail)


@dataclass(frozen=True)
class SpeedCurve:
    """The rotors' common speed per command, Omega = slope (P - h2) (eq. 26 and 27), from the airborne rows
    of the logs with rotor speeds."""
    slope: float         # rad/s per unit of P
    h2: float            # P at zero speed (below 0: the ESC's idle turns the rotor at P = 0)

    def speed(self, P: np.ndarray) -> np.ndarray:
        return self.slope * (np.asarray(P, float) - self.h2)


def speed_curve(files) -> SpeedCurve | None:
    """The rotors' common speed-per-command line over the airborne rows (those with the four speeds finite)
    of the files whose rotor speeds are logged (no timing: the fit spans the flight's range of commands, a lag only spreads
    it): each rotor's own line Omega_i = k_i (P_i - h2_i) by least squares, h2 their median (a motor that
    gives less for its command has a lower k_i, not another h2; one line pooled over the four would mix
    the rotors' differences into its slope), the slope the rotors' mean k_i at that h2; or None (no
    speeds, or no positive slope, or an h2 at or above full command, which is no rotor's)."""
    xs, ys = [], []
    for f in files:
        if f.omega is None:
            continue
        m = f.airborne & np.isfinite(f.omega).all(axis=0)
        if not m.any() or np.abs(f.omega[:, m]).max() <= 0:
            continue
        xs.append(np.asarray(f.P, float)[:, m])
        ys.append(f.omega[:, m])
    if not xs:
        return None
    x, y = np.concatenate(xs, axis=1), np.concatenate(ys, axis=1)
    xm, ym = x.mean(axis=1, keepdims=True), y.mean(axis=1, keepdims=True)
    k = np.einsum("mn,mn->m", x - xm, y - ym) / np.maximum(np.einsum("mn,mn->m", x - xm, x - xm), 1e-300)
    if not (k > 0).all():
        return None
    h2 = float(np.median(xm[:, 0] - ym[:, 0] / k))
    slope = float(np.mean(np.einsum("mn,mn->m", y, x - h2) / np.einsum("mn,mn->m", x - h2, x - h2)))
    if not (slope > 0 and h2 < P_FULL):
        return None
    return SpeedCurve(slope, h2)


def of_log(table, a, foreign: bool, speeds: SpeedCurve | None = None) -> Curve:
    """The curve a log declares, else eq. 26: this project's airframe's h2, the h2 of the log's rotor speeds
    (`speeds`), or h2 = 0 assumed."""
    if (curve := declared(table)) is not None:
        return curve
    if not foreign:
        return Curve(1.0, a.h2 / P_FULL, 1.0, f"eq. 26 with the airframe's h2 = {a.h2:g}", True)
    if speeds is not None:
        return Curve(1.0, speeds.h2 / P_FULL, 1.0, f"eq. 26 with h2 = {speeds.h2:.1f} of the log's rotor speeds "
                     f"(Omega = a (P - h2) on the airborne rows, eq. 27; {100 * speeds.h2 / P_FULL:+.0f} % of the range)",
                     True)
    return Curve(1.0, 0.0, 1.0, "assumed: eq. 26's shape with h2 = 0 (thrust as the square of the command above "
                 "idle); the log declares no thrust curve", False)
