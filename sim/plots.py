"""The one plotting style of flightctl, and the flight figure.

Every figure is a `matplotlib.figure.Figure` made by `figure()` and rendered by `png()` or `save()`
through the Agg canvas: no pyplot, so no global state (safe in threads and tests) and no backend to
select. The style: constrained layout, a unit on every axis (a ratio or count says so), legends
outside the data (`legend()` puts one beside its axes, `figure_legend()` one under all of them), an
empty axes says why (`empty_panel()`), a crash is marked and named in the title (`plot_flight`).
Imported only when a plot is asked for (matplotlib is slow to import).

The flight figure is like the paper's figures 13-20: for each channel the setpoint (red), the
controller's estimate (blue) and, in simulation, the true value (green); and the four commands.
"""
from __future__ import annotations

import io
import math
from pathlib import Path

import numpy as np

from flightctl.cli import matplotlib_home


matplotlib_home()
from matplotlib.figure import Figure  # noqa: E402  (after its folders are set)

from flightctl.logfile import Table
from flightctl.safety import CRASH_TILT, CRASH_TOUCHDOWN_SPEED, first_tilt_past

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


def empty_panel(ax, why: str) -> None:
    """An axes with nothing to plot says why, in its middle, instead of a blank frame."""
    ax.text(0.5, 0.5, why, ha="center", va="center", wrap=True, fontsize=9, transform=ax.transAxes)
    ax.set_xticks([])
    ax.set_yticks([])


def png(fig: Figure, dpi: int = DPI) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    return buf.getvalue()


def save(fig: Figure, path: str | Path, dpi: int = DPI) -> None:
    """The figure as a PNG, written whole (a reader never sees half an image)."""
    from flightctl.files import write_atomic
    write_atomic(path, png(fig, dpi))


def crash_times(log: Table, crash_tilt: float = CRASH_TILT, hard_touchdown: float = CRASH_TOUCHDOWN_SPEED) -> list[tuple[float, str]]:
    """(time, what) of each crash in a log (flightctl/safety.py): the first tilt past `crash_tilt` (rad; the true attitude
    where the log has it, else the estimate), and touchdowns faster than `hard_touchdown` (m/s) where
    the log has the true altitude."""
    t = log["t"]
    roll, pitch = ((log["true_roll"], log["true_pitch"]) if "true_roll" in log else (log["roll"], log["pitch"]))
    out = []
    first = first_tilt_past(roll, pitch, crash_tilt)
    if first is not None:
        out.append((float(t[first]), f"tilt past {math.degrees(crash_tilt):.0f} deg"))
    if "true_z" in log and len(t) > 2:
        z = log["true_z"]
        vz = np.gradient(z, t)
        down = np.flatnonzero((z[1:] <= 0.01) & (z[:-1] > 0.01)) + 1     # each arrival on the floor
        for k in down:
            speed = float(np.max(np.abs(vz[max(k - 5, 0):k + 1])))
            if speed > hard_touchdown:
                out.append((float(t[k]), f"hit the floor at {speed:.1f} m/s"))
    return sorted(out)


def plot_flight(log: Table, path: str | Path, title: str) -> None:
    save(flight_figure(log, title), path, dpi=80)


def flight_figure(log: Table, title: str) -> Figure:
    """The flight figure; a crash is marked on every panel and the title says so."""
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
    for i in range(1, 5):
        axes[4].plot(t, log[f"P{i}"], lw=0.6, label=f"P{i}")
    axes[4].set_ylabel("command P (0-255, no unit)")
    axes[4].set_xlabel("time (s)")
    legend(axes[4])
    axes[4].grid(alpha=0.3)
    crashes = crash_times(log)
    for tc, _ in crashes:
        for ax in axes:
            ax.axvline(tc, color="k", lw=1.5, ls=":", label="crash" if ax is axes[0] and tc == crashes[0][0] else None)
    figure_legend(fig, axes[0], ncol=5 if crashes else 4)
    if crashes:
        title = f"CRASHED at t = {crashes[0][0]:.2f} s ({crashes[0][1]}): {title}"
    fig.suptitle(title, color="tab:red" if crashes else "black")
    return fig
