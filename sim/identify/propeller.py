"""Propeller bench fits of section 4.1, per motor and averaged over the motors as the paper does.

- eq. 26 `f = h1 (P - h2)^2` above the dead zone (nonlinear least squares),
- eq. 27 `f = c1 w^2` (linear least squares),
- eq. 28 `tau = g1 f + g2` with the torque from electrical power, `tau = V I / w` (eq. 13-16).

The paper's final model is "the average of those of the obtained models for the four propellers":
the top-level values are the means of the per-motor values. Their standard error is propagated from
the per-motor fits, `sqrt(sum stderr_i^2) / n`; the spread of the motors, `std(values) / sqrt(n)`,
is reported beside it as `motor_spread` because real motors differ by more than their fit errors.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from flightctl.physics import thrust_from_command, thrust_from_speed
from flightctl.sim.identify.fits import (Fit, FitError, Identified, check_count, linear_fit, nonlinear_fit, r_squared,
                                         require, rms, whole_numbers, within)

FITS = {"thrust_P": ("h1", "h2"), "thrust_omega": ("c1",), "torque": ("g1", "g2")}
NAMES = tuple(n for names in FITS.values() for n in names)
STDERR_METHOD = ("top-level stderr propagated from the per-motor fits, sqrt(sum of stderr^2) / n; "
                 "motor_spread is the standard deviation of the per-motor values / sqrt(n)")


def torque_from_power(voltage, current, omega):
    """Eq. 13-16: steady state, electrical torque = reaction torque, every loss ignored."""
    return voltage * current / omega


def predict(fit: str, x, v: dict[str, float]):
    """The model of one fit with parameter values v: thrust_P(P), thrust_omega(w), torque(f)."""
    if fit == "thrust_P":
        return thrust_from_command(x, v["h1"], v["h2"])   # eq. 26
    if fit == "thrust_omega":
        return thrust_from_speed(x, v["c1"])              # eq. 27
    return v["g1"] * x + v["g2"]   # eq. 28 as fitted: the straight line through the bench points (f > 0)


def motor_points(P, thrust, omega, voltage, current) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """The (x, y) points each fit uses. Eq. 26 takes the points above the dead zone: P above the
    highest P at which the thrust is not positive. Eq. 28 takes the points where the propeller turns."""
    dead = thrust <= 0
    above = P > P[dead].max() if dead.any() else np.ones(len(P), bool)
    t = omega > 0
    return {"thrust_P": (P[above], thrust[above]),
            "thrust_omega": (omega, thrust),
            "torque": (thrust[t], torque_from_power(voltage[t], current[t], omega[t]))}


def fit_motor(points) -> dict[str, Fit]:
    P, f = points["thrust_P"]
    check_count(len(P), FITS["thrust_P"])
    if len(np.unique(P)) < 3:
        raise FitError(f"the points do not determine h1, h2: {len(np.unique(P))} distinct P values above "
                       "the dead zone, at least 3 needed")
    slope, intercept = np.polyfit(P, np.sqrt(f), 1)  # start: sqrt(f) = sqrt(h1) (P - h2)
    if not slope > 0:
        raise FitError("thrust does not rise with P above the dead zone: eq. 26 cannot be fitted")
    thrust_P = nonlinear_fit(lambda th: thrust_from_command(P, *th), np.array([slope ** 2, -intercept / slope]),
                             f, FITS["thrust_P"])
    w, f = points["thrust_omega"]
    thrust_omega = linear_fit(w[:, None] ** 2, f, FITS["thrust_omega"])
    f, tau = points["torque"]
    torque = linear_fit(np.column_stack([f, np.ones_like(f)]), tau, FITS["torque"])
    return {"thrust_P": thrust_P, "thrust_omega": thrust_omega, "torque": torque}


@dataclass(frozen=True)
class BenchResult:
    path: str
    points: dict[int, dict[str, tuple[np.ndarray, np.ndarray]]]  # motor -> fit -> (x, y)
    fits: dict[int, dict[str, Fit]]                               # motor -> fit -> Fit
    value: dict[str, float]   # averaged over motors
    stderr: dict[str, float]
    spread: dict[str, float]  # empty with one motor

    def motor_values(self, motor: int) -> dict[str, float]:
        return {n: fit[n] for fit in self.fits[motor].values() for n in fit.names}

    def residuals(self, fit: str) -> tuple[np.ndarray, np.ndarray]:
        """(y, y - averaged model) over the points of every motor."""
        y = np.concatenate([self.points[m][fit][1] for m in self.points])
        model = np.concatenate([predict(fit, self.points[m][fit][0], self.value) for m in self.points])
        return y, y - model

    def report(self) -> dict:
        out: dict = {"kind": "bench", "file": self.path, "motors": sorted(self.fits)}
        out.update({n: {"value": self.value[n], "stderr": self.stderr[n]} for n in NAMES})
        out["residual_rms"] = {fit: rms(self.residuals(fit)[1]) for fit in FITS}
        out["r2"] = {fit: r_squared(*self.residuals(fit)) for fit in FITS}
        out["stderr_method"] = STDERR_METHOD
        if self.spread:
            out["motor_spread"] = self.spread
        out["per_motor"] = {
            str(m): {**{n: p for fit in fits.values() for n, p in fit.params().items()},
                     "residual_rms": {k: fit.rms for k, fit in fits.items()},
                     "r2": {k: fit.r2 for k, fit in fits.items()},
                     "points": {k: len(fit.y) for k, fit in fits.items()}}
            for m, fits in self.fits.items()}
        return out


def fit_bench(table) -> BenchResult:
    motor = whole_numbers(table, "motor", 1, 4)
    P, f, w, V, I = (table[c] for c in ("P", "thrust", "omega", "voltage", "current"))
    require(table, "P", (P >= 0) & (P <= 255), "the command value P must be 0 to 255")
    within(table, "thrust", -1e3, 1e3, "N")
    within(table, "omega", 0.0, 1e4, "rad/s (the speed must not be negative)")
    require(table, "voltage", V > 0, "the voltage must be positive")
    within(table, "voltage", 0.0, 100.0, "V")
    within(table, "current", 0.0, 1e3, "A (the current must not be negative)")
    points, fits = {}, {}
    for m in map(int, np.unique(motor)):
        k = motor == m
        points[m] = motor_points(P[k], f[k], w[k], V[k], I[k])
        try:
            fits[m] = fit_motor(points[m])
        except FitError as e:
            table.fail(f"motor {m}: {e}")
    n = len(fits)
    per = {name: np.array([fits[m][fit][name] for m in fits]) for fit, names in FITS.items() for name in names}
    err = {name: np.array([fits[m][fit].error(name) for m in fits]) for fit, names in FITS.items() for name in names}
    return BenchResult(
        table.path, points, fits,
        value={k: float(v.mean()) for k, v in per.items()},
        stderr={k: float(np.sqrt(np.sum(e ** 2)) / n) for k, e in err.items()},
        spread={k: float(v.std(ddof=1) / np.sqrt(n)) for k, v in per.items()} if n > 1 else {})


def identify(table, airframe) -> Identified:
    result = fit_bench(table)
    report = result.report()
    lines = [f"bench {table.path}: motors {', '.join(map(str, result.fits))}, averaged as in the paper (sec. 4.1)"]
    units = {"h1": "N", "h2": "P units", "c1": "N/(rad/s)^2", "g1": "N m/N", "g2": "N m"}
    for fit, names in FITS.items():
        params = ", ".join(f"{n} = {result.value[n]:.4g} ± {result.stderr[n]:.2g} {units[n]}" for n in names)
        lines.append(f"  {fit:<12} {params}; rms {report['residual_rms'][fit]:.3g}, R^2 {report['r2'][fit]:.4f}")
    return Identified(report, lines, dict(result.value), (result,))
