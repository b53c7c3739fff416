"""Figures like the paper's 6-9: data, fit, and the residuals underneath, in the style of
`flightctl.sim.plots`. The figures import the fits, never the other way round: `flightctl identify`
fits, then draws `FIGURES[kind](*identified.figure_data)` when a plot is asked for.
"""
from __future__ import annotations

import numpy as np

from flightctl import physics
from flightctl.sim.identify.propeller import FITS, predict
from flightctl.sim.plots import figure, legend

AVERAGE = "goldenrod"  # the paper draws its averaged model in yellow


def _with_residuals(ylabels: list[str], width: float = 4.2, height: float = 4.6):
    """Data above, residuals below, one column per y label (the residual has the unit of the data)."""
    n = len(ylabels)
    fig, axes = figure(2, n, size=(width * n, height), sharex="col", gridspec_kw={"height_ratios": [3, 1]})
    for col, ylabel in enumerate(ylabels):
        axes[0, col].set_ylabel(ylabel)
        axes[1, col].axhline(0, color="k", lw=0.6)
        axes[1, col].set_ylabel("residual " + ylabel[ylabel.index("("):])
    return fig, axes


BENCH_AXES = {"thrust_P": ("Fig. 6: thrust vs command (eq. 26)", "P (0-255, no unit)", "thrust (N)"),
              "thrust_omega": ("Fig. 7: thrust vs speed (eq. 27)", "omega (rad/s)", "thrust (N)"),
              "torque": ("Fig. 8: torque vs thrust (eq. 28)", "thrust (N)", "V I / omega (N m)")}


def bench(result):
    fig, axes = _with_residuals([BENCH_AXES[fit][2] for fit in FITS])
    for col, fit in enumerate(FITS):
        title, xlabel, _ = BENCH_AXES[fit]
        top, bottom = axes[0, col], axes[1, col]
        xs = np.concatenate([result.points[m][fit][0] for m in result.points])
        grid = np.linspace(xs.min() if fit == "thrust_P" else 0.0, xs.max(), 200)
        for i, m in enumerate(result.points):
            x, y = result.points[m][fit]
            color = f"C{i}"
            top.plot(x, y, ".", color=color, ms=4, label=f"motor {m}")
            top.plot(grid, predict(fit, grid, result.motor_values(m)), "-", color=color, lw=0.8)
            bottom.plot(x, y - predict(fit, x, result.value), ".", color=color, ms=4)
        top.plot(grid, predict(fit, grid, result.value), "-", color=AVERAGE, lw=2.5, label="average")
        top.set_title(title)
        bottom.set_xlabel(xlabel)
    legend(axes[0, -1])
    return fig


def yaw_drag(r, tau, fit):
    fig, axes = _with_residuals(["torque (N m)"], width=6.5)
    grid = np.linspace(r.min(), r.max(), 400)
    axes[0, 0].plot(r, tau, ".", label="steady spins")
    axes[0, 0].plot(grid, physics.yaw_drag(grid, fit["gamma1"], fit["gamma2"]), "-", color=AVERAGE, lw=2,
                    label="eq. 6 fit")
    axes[0, 0].set_title("Fig. 9: yaw drag torque vs steady yaw rate")
    legend(axes[0, 0])
    axes[1, 0].plot(r, fit.residuals, ".")
    axes[1, 0].set_xlabel("yaw rate (rad/s)")
    return fig


def per_group(title: str, ylabel: str, groups: dict[str, np.ndarray], params: dict, labels=None):
    """Repeated measurements per group (axis, or all rotors), with their mean ± stderr."""
    fig, axes = _with_residuals([ylabel], width=5.5)
    top, bottom = axes[0, 0], axes[1, 0]
    for i, (name, values) in enumerate(groups.items()):
        x = i + np.linspace(-0.15, 0.15, len(values))
        mean, err = params[name]["value"], params[name]["stderr"]
        top.plot(x, values, "o", color=f"C{i}", label=name)
        top.errorbar([i + 0.3], [mean], yerr=[err], fmt="s", color=AVERAGE, capsize=4,
                     label="mean ± stderr" if i == 0 else None)
        bottom.plot(x, values - mean, "o", color=f"C{i}")
        if labels:
            for xi, yi, text in zip(x, values, labels):
                top.annotate(text, (xi, yi), fontsize="x-small", xytext=(3, 3), textcoords="offset points")
    bottom.set_xticks(range(len(groups)), list(groups))
    top.set_title(title)
    legend(top)
    return fig


def pendulum(groups: dict[str, np.ndarray], params: dict):
    return per_group("Pendulum inertia per trial (eq. 17-18)", "J_C (kg m^2)", groups, params)


def rotor(groups: dict[str, np.ndarray], params: dict, labels: list[str]):
    return per_group("Rotor inertia per rotor (eq. 19-21)", "Jp (kg m^2)", groups, params, labels)


FIGURES = {"bench": bench, "yaw-drag": yaw_drag, "pendulum": pendulum, "rotor": rotor}  # kind -> figure
