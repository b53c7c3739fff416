"""The one plotting style of flightctl, and the flight figure.

Every figure is a `matplotlib.figure.Figure` made by `figure()` and rendered by `png()` or `save()`
through the Agg canvas: no pyplot, so no global state (safe in threads and tests) and no backend to
select. The style: constrained layout, a unit on every axis (a ratio or count says so), legends
outside the data (`legend()` puts one beside its axes, `figure_legend()` one under all of them).
Imported only when a plot is asked for (matplotlib is slow to import).

The flight figure is like the paper's figures 13-20: for each channel the setpoint (red), the
controller's estimate (blue) and, in simulation, the true value (green); and the four commands.
"""
from __future__ import annotations

import io
import math
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from flightctl.logfile import Table

DPI = 90


def figure(nrows: int = 1, ncols: int = 1, size: tuple[float, float] = (6.4, 4.8), **subplots):
    """A figure and its grid of axes (always 2-D: `axes[row, col]`); `subplots` go to `Figure.subplots`
    (sharex, gridspec_kw, ...)."""
    fig = Figure(figsize=size, layout="constrained")
    return fig, fig.subplots(nrows, ncols, squeeze=False, **subplots)


def legend(ax, **kw) -> None:
    """The legend of `ax` beside it, outside the data."""
    ax.legend(**{"loc": "upper left", "bbox_to_anchor": (1.01, 1.0), "borderaxespad": 0.0, "fontsize": "small", **kw})


def figure_legend(fig: Figure, ax, ncol: int) -> None:
    """One legend for the whole figure from the lines of `ax`, under the axes (the title is above)."""
    fig.legend(*ax.get_legend_handles_labels(), loc="outside lower center", ncol=ncol, fontsize="small")


def png(fig: Figure, dpi: int = DPI) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    return buf.getvalue()


def save(fig: Figure, path: str | Path, dpi: int = DPI) -> None:
    Path(path).write_bytes(png(fig, dpi))


def plot_flight(log: Table, path: str | Path, title: str) -> None:
    t = log["t"]
    deg = 180 / math.pi
    panels = [("alt", "altitude (m)", 1.0, "true_z"), ("roll", "roll (deg)", deg, "true_roll"),
              ("pitch", "pitch (deg)", deg, "true_pitch"), ("yaw", "yaw (deg)", deg, "true_yaw")]
    fig, axes = figure(5, 1, size=(10, 11), sharex="col")
    axes = axes[:, 0]
    for ax, (name, label, k, true) in zip(axes, panels):
        ax.plot(t, log[f"{name}_sp"] * k, color="tab:red", lw=1.2, label="setpoint")
        ax.plot(t, log[name] * k, color="tab:blue", lw=0.8, label="estimate")
        if true in log:
            ax.plot(t, log[true] * k, color="tab:green", lw=0.8, ls="--", label="true")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    rng = log["range"]
    ok = ~np.isnan(rng)
    axes[0].plot(t[ok], rng[ok], ".", ms=1.5, color="0.5", label="sonar range")
    figure_legend(fig, axes[0], ncol=4)
    for i in range(1, 5):
        axes[4].plot(t, log[f"P{i}"], lw=0.6, label=f"P{i}")
    axes[4].set_ylabel("command P (0-255, no unit)")
    axes[4].set_xlabel("time (s)")
    legend(axes[4])
    axes[4].grid(alpha=0.3)
    fig.suptitle(title)
    save(fig, path, dpi=80)
