"""Figures of the real-data report (see realdata.py). Small PNGs: they are committed in docs/."""
from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from flightctl.sim.identify.plots import png
from flightctl.sim.identify.propeller import torque_from_power
from flightctl.sim.identify.realdata import (BASE_THRUST, BASE_TORQUE, EXT_THRUST, EXT_TORQUE, RPM, SPLITS,
                                   efficiency)

DPI = 80


def _label(run) -> str:
    return run.name.removeprefix("StepsTest_").removesuffix(".csv")


def torque(res) -> bytes:
    fig = Figure(figsize=(10, 4.2), layout="constrained")
    left, right = fig.subplots(1, 2)
    for i, run in enumerate(res["run_data"]):
        color = f"C{i % 10}"
        marker = "o" if i < 10 else "s"
        tau_e = torque_from_power(run.voltage, run.current, run.omega)
        left.loglog(run.torque * 1e3, tau_e * 1e3, marker, color=color, ms=3, label=_label(run))
        right.plot(run.omega / RPM, efficiency(run), marker + "-", color=color, ms=3, lw=0.8)
    lim = np.array(left.get_xlim())
    left.plot(lim, lim, "k--", lw=0.8, label="V I / w = measured")
    left.set(title="(a) V I / w (eq. 13-16) vs the torque sensor", xlabel="measured torque (mN m)",
             ylabel="V I / w (mN m)")
    left.legend(fontsize=6, ncol=2)
    right.axhline(1, color="k", ls="--", lw=0.8)
    right.set(title="efficiency tau w / (V I) over speed", xlabel="speed (RPM)", ylabel="eta", ylim=(0, 1.05))
    return png(fig, DPI)


def ct(res) -> bytes:
    fig = Figure(figsize=(10, 4.2), layout="constrained")
    left, right = fig.subplots(1, 2)
    for rpm, c, _diameter in res["uiuc"]["curves"].values():
        left.plot(rpm, c / c.mean(), "-", color="0.4", lw=0.4, alpha=0.5)
    left.axhline(1, color="goldenrod", lw=2, label="eq. 27: CT constant")
    left.set(title=f"(b) UIUC static tests: CT / mean, {len(res['uiuc']['curves'])} propellers",
             xlabel="speed (RPM)", ylabel="CT / mean CT", ylim=(0.6, 1.4))
    left.legend(fontsize="small")
    for i, run in enumerate(res["run_data"]):
        k = run.thrust / run.omega ** 2
        right.plot(run.omega / RPM, k / k.mean(), ("o" if i < 10 else "s") + "-", color=f"C{i % 10}", ms=3, lw=0.8,
                   label=_label(run))
    right.axhline(1, color="goldenrod", lw=2)
    right.set(title="RCbenchmark: (f / w^2) / mean", xlabel="speed (RPM)", ylabel="(f / w^2) / mean", ylim=(0, 2))
    right.legend(fontsize=6, ncol=2)
    return png(fig, DPI)


def held_out(res) -> bytes:
    fig = Figure(figsize=(10, 4.2), layout="constrained")
    axes = fig.subplots(1, 2)
    names = list(res["runs"])
    x = np.arange(len(names))
    for ax, (base, ext, unit) in zip(axes, ((BASE_THRUST, EXT_THRUST, "mN"), (BASE_TORQUE, EXT_TORQUE, "mN m"))):
        for split, fill in zip(SPLITS, ("full", "none")):
            for model, color, dx in ((base, "C3", -0.12), (ext, "C0", 0.12)):
                y = [1e3 * res["runs"][n]["rmse"][split][model] for n in names]
                ax.semilogy(x + dx, y, "o", color=color, fillstyle=fill, label=f"{model}, {split}")
        ax.set_xticks(x, [n.removeprefix("StepsTest_").removesuffix(".csv") for n in names], rotation=60, fontsize=7)
        low, high = ax.get_ylim()
        ax.set(ylabel=f"held-out RMSE ({unit})", ylim=(low, high * (high / low) ** 0.6))  # room for the legend
        ax.legend(fontsize=7, loc="upper center", ncol=2)
    axes[0].set_title("(c) thrust: held-out RMSE per file")
    axes[1].set_title("(c) torque: held-out RMSE per file")
    return png(fig, DPI)
