"""Least squares with standard errors: the one fitting engine behind every identification.

Standard errors come from the covariance of the fit, `s^2 (J^T J)^-1` with `s^2 = SSR / (n - p)`
(J the Jacobian of the model, the design matrix for a linear fit). A fit that cannot be made raises
`FitError` with what is wrong; the caller adds the file name and turns it into an `InputError`.
"""
from __future__ import annotations

from dataclasses import dataclass

import dataclasses
import math

import numpy as np

from flightctl.params import Airframe

MIN_DOF = 2  # points beyond the number of parameters, so that a fit can estimate its own error


class FitError(ValueError):
    """A fit that cannot be made from the data given (too few points, degenerate, no convergence)."""


@dataclass(frozen=True)
class Identified:
    """What one identification gives the command line: the JSON report, a few lines for a human,
    the fitted values under the names of conventions.md (for a parameter file), and what its figure
    draws: the arguments of `plots.FIGURES[kind]`, drawn only when a plot is asked for (the fits
    never import the figures)."""
    report: dict
    summary: list[str]
    values: dict[str, float]
    figure_data: tuple


@dataclass(frozen=True)
class Fit:
    names: tuple[str, ...]
    value: np.ndarray
    stderr: np.ndarray
    y: np.ndarray          # the measured values fitted
    residuals: np.ndarray  # y - model

    def __getitem__(self, name: str) -> float:
        return float(self.value[self.names.index(name)])

    def error(self, name: str) -> float:
        return float(self.stderr[self.names.index(name)])

    @property
    def rms(self) -> float:
        return rms(self.residuals)

    @property
    def r2(self) -> float:
        return r_squared(self.y, self.residuals)

    def params(self) -> dict[str, dict[str, float]]:
        return {n: {"value": float(v), "stderr": float(e)} for n, v, e in zip(self.names, self.value, self.stderr)}


def rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x))))


def r_squared(y: np.ndarray, residuals: np.ndarray) -> float:
    total = float(np.sum((y - np.mean(y)) ** 2))
    return 1.0 - float(np.sum(residuals ** 2)) / total if total > 0 else float("nan")


def check_count(n: int, names: tuple[str, ...]) -> None:
    need = len(names) + MIN_DOF
    if n < need:
        raise FitError(f"too few points to fit {', '.join(names)}: {n}, at least {need} needed")


def _covariance(jac: np.ndarray, residuals: np.ndarray, names: tuple[str, ...]) -> np.ndarray:
    n, p = jac.shape
    if np.linalg.matrix_rank(jac) < p:
        raise FitError(f"the points do not determine {', '.join(names)} (degenerate design: "
                       "too few distinct values)")
    s2 = float(residuals @ residuals) / (n - p)
    return s2 * np.linalg.inv(jac.T @ jac)


def linear_fit(A: np.ndarray, y: np.ndarray, names: tuple[str, ...]) -> Fit:
    """Ordinary least squares of y = A @ theta."""
    check_count(len(y), names)
    theta = np.linalg.lstsq(A, y, rcond=None)[0]
    residuals = y - A @ theta
    cov = _covariance(A, residuals, names)
    return Fit(names, theta, np.sqrt(np.diag(cov)), y, residuals)


def nonlinear_fit(model, x0: np.ndarray, y: np.ndarray, names: tuple[str, ...]) -> Fit:
    """Nonlinear least squares of y = model(theta), started at x0 (scipy `least_squares`)."""
    from scipy.optimize import least_squares   # here: a command's arguments are checked before this import
    check_count(len(y), names)
    result = least_squares(lambda theta: model(theta) - y, x0, x_scale="jac", max_nfev=2000)
    if not result.success or not np.all(np.isfinite(result.x)):
        raise FitError(f"the fit of {', '.join(names)} did not converge ({result.message})")
    residuals = y - model(result.x)
    cov = _covariance(result.jac, residuals, names)
    stderr = np.sqrt(np.diag(cov))
    if not np.all(np.isfinite(stderr)):
        raise FitError(f"the fit of {', '.join(names)} did not converge (no finite covariance)")
    return Fit(names, result.x, stderr, y, residuals)


def require(table, column: str, ok: np.ndarray, what: str) -> None:
    """Fail on the first row of `table` where `ok` is false, naming the row and column."""
    bad = np.flatnonzero(~ok)
    if bad.size:
        k = int(bad[0])
        value = table[column][k]
        shown = f"{value:g}" if isinstance(value, (float, np.floating)) else repr(str(value))
        table.fail(f"{what}, got {shown}", row=k, column=column)


def within(table, column: str, lo: float, hi: float, unit: str) -> np.ndarray:
    """A measured column whose values must lie in [lo, hi]: beyond it a row is not a measurement of
    this rig (and the fits would overflow)."""
    x = table[column]
    require(table, column, (x >= lo) & (x <= hi), f"must be {lo:g} to {hi:g} {unit}")
    return x


def check_result(result: Identified) -> None:
    """Refuse (FitError naming it) a fitted value outside the parameter schema's physical range
    (flightctl.params, conventions.md) and any non-finite number in the report."""
    fields = {f.name: f.metadata for f in dataclasses.fields(Airframe)}
    for name, value in result.values.items():
        meta = fields[name]
        if not (math.isfinite(value) and meta["lo"] <= value <= meta["hi"]):
            raise FitError(f"the fit gives {name} = {value:.4g} {meta['unit']}, outside its physical range "
                           f"[{meta['lo']:g}, {meta['hi']:g}] (check the signs and units of the data)")
    _check_finite(result.report, "")


def _check_finite(value, where: str) -> None:
    if isinstance(value, dict):
        for k, v in value.items():
            _check_finite(v, f"{where}.{k}" if where else str(k))
    elif isinstance(value, (list, tuple)):
        for k, v in enumerate(value):
            _check_finite(v, f"{where}[{k}]")
    elif isinstance(value, (float, np.floating)) and not math.isfinite(value):
        raise FitError(f"the fit gives {where} = {value}: the data do not determine it")


def whole_numbers(table, column: str, lo: int, hi: int) -> np.ndarray:
    """An integer label column (motor, rotor) whose values must be lo..hi."""
    x = table[column]
    require(table, column, (x == np.round(x)) & (x >= lo) & (x <= hi), f"must be a whole number {lo} to {hi}")
    return x.astype(int)
