"""Figures like the paper's 6-9: data, fit, and the residuals underneath.

Imported only when a plot is asked for (matplotlib is slow to import). Figures are built with
`matplotlib.figure.Figure` and rendered by the Agg backend, without pyplot's global state.
"""
from __future__ import annotations

import io

import numpy as np
from matplotlib.figure import Figure

from flightctl.sim.identify.propeller import FITS, predict
from flightctl.sim.identify.yaw_drag import drag_torque

AVERAGE = "goldenrod"  # the paper draws its averaged model in yellow


def png(fig: Figure, dpi: int = 90) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    return buf.getvalue()


def _with_residuals(ncols: int, width: float = 4.2, height: float = 4.6):
    fig = Figure(figsize=(width * ncols, height), layout="constrained")
    axes = fig.subplots(2, ncols, squeeze=False, sharex="col", gridspec_kw={"height_ratios": [3, 1]})
    for ax in axes[1]:
        ax.axhline(0, color="k", lw=0.6)
        ax.set_ylabel("residual")
    return fig, axes


BENCH_AXES = {"thrust_P": ("Fig. 6: thrust vs command (eq. 26)", "P (0-255)", "thrust (N)"),
              "thrust_omega": ("Fig. 7: thrust vs speed (eq. 27)", "omega (rad/s)", "thrust (N)"),
              "torque": ("Fig. 8: torque vs thrust (eq. 28)", "thrust (N)", "V I / omega (N m)")}


def bench(result) -> Figure:
    fig, axes = _with_residuals(3)
    for col, fit in enumerate(FITS):
        title, xlabel, ylabel = BENCH_AXES[fit]
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
        top.set(title=title, ylabel=ylabel)
        bottom.set_xlabel(xlabel)
    axes[0, 0].legend(fontsize="small")
    return fig


def yaw_drag(r, tau, fit) -> Figure:
    fig, axes = _with_residuals(1, width=5.5)
    grid = np.linspace(r.min(), r.max(), 400)
    axes[0, 0].plot(r, tau, ".", label="steady spins")
    axes[0, 0].plot(grid, drag_torque(grid, fit["gamma1"], fit["gamma2"]), "-", color=AVERAGE, lw=2, label="eq. 6 fit")
    axes[0, 0].set(title="Fig. 9: yaw drag torque vs steady yaw rate", ylabel="torque (N m)")
    axes[0, 0].legend(fontsize="small")
    axes[1, 0].plot(r, fit.residuals, ".")
    axes[1, 0].set_xlabel("yaw rate (rad/s)")
    return fig


def per_group(title: str, ylabel: str, groups: dict[str, np.ndarray], params: dict, labels=None) -> Figure:
    """Repeated measurements per group (axis, or all rotors), with their mean ± stderr."""
    fig, axes = _with_residuals(1, width=5.5)
    top, bottom = axes[0, 0], axes[1, 0]
    for i, (name, values) in enumerate(groups.items()):
        x = i + np.linspace(-0.15, 0.15, len(values))
        mean, err = params[name]["value"], params[name]["stderr"]
        top.plot(x, values, "o", color=f"C{i}", label=name)
        top.errorbar([i + 0.3], [mean], yerr=[err], fmt="s", color=AVERAGE, capsize=4)
        bottom.plot(x, values - mean, "o", color=f"C{i}")
        if labels:
            for xi, yi, text in zip(x, values, labels):
                top.annotate(text, (xi, yi), fontsize="x-small", xytext=(3, 3), textcoords="offset points")
    bottom.set_xticks(range(len(groups)), list(groups))
    top.set(title=title, ylabel=ylabel)
    return fig
