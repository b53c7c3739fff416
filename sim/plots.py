"""Plots of a flight like the paper's figures 13-20: for each channel the setpoint (red), the
controller's estimate (blue) and, in simulation, the true value (green); and the four commands."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from flightctl.logfile import Table


def plot_flight(log: Table, path: str | Path, title: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = log["t"]
    deg = 180 / math.pi
    panels = [("alt", "altitude (m)", 1.0, "true_z"), ("roll", "roll (deg)", deg, "true_roll"),
              ("pitch", "pitch (deg)", deg, "true_pitch"), ("yaw", "yaw (deg)", deg, "true_yaw")]
    fig, axes = plt.subplots(5, 1, figsize=(10, 11), sharex=True)
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
    axes[0].legend(loc="upper right", fontsize=8, ncol=4)
    for i in range(1, 5):
        axes[4].plot(t, log[f"P{i}"], lw=0.6, label=f"P{i}")
    axes[4].set_ylabel("command P (0-255)")
    axes[4].set_xlabel("time (s)")
    axes[4].legend(loc="upper right", fontsize=8, ncol=4)
    axes[4].grid(alpha=0.3)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)
