"""Figures of the real-data report (realdata.py): small PNGs, committed in docs/, in the style of
`flightctl.sim.plots`. `images(res)` draws them all under the file names the report links to."""
from __future__ import annotations

import numpy as np

from flightctl.sim.identify.propeller import torque_from_power
from flightctl.sim.identify.realdata import (BASE_THRUST, BASE_TORQUE, EXT_THRUST, EXT_TORQUE, FIGURE_FILES, RPM,
                                             SPLITS, efficiency)
from flightctl.sim.plots import figure, legend, png

DPI = 80
SIZE = (11, 4.2)


def _label(name: str) -> str:
    return name.removeprefix("StepsTest_").removesuffix(".csv")


def torque(res):
    fig, ((left, right),) = figure(1, 2, size=SIZE)
    for i, run in enumerate(res["run_data"]):
        color = f"C{i % 10}"
        marker = "o" if i < 10 else "s"
        tau_e = torque_from_power(run.voltage, run.current, run.omega)
        left.loglog(run.torque * 1e3, tau_e * 1e3, marker, color=color, ms=3, label=_label(run.name))
        right.plot(run.omega / RPM, efficiency(run), marker + "-", color=color, ms=3, lw=0.8)
    lim = np.array(left.get_xlim())
    left.plot(lim, lim, "k--", lw=0.8, label="V I / w = measured")
    left.set(title="(a) V I / w (eq. 13-16) vs the torque sensor", xlabel="measured torque (mN m)",
             ylabel="V I / w (mN m)")
    right.axhline(1, color="k", ls="--", lw=0.8)
    right.set(title="efficiency tau w / (V I) over speed", xlabel="speed (RPM)",
              ylabel="efficiency tau w / (V I) (no unit)", ylim=(0, 1.05))
    legend(right, handles=left.get_legend_handles_labels()[0], fontsize=6, ncol=2)
    return fig


def ct(res):
    fig, ((left, right),) = figure(1, 2, size=SIZE)
    for rpm, c, _diameter in res["uiuc"]["curves"].values():
        left.plot(rpm, c / c.mean(), "-", color="0.4", lw=0.4, alpha=0.5)
    left.axhline(1, color="goldenrod", lw=2, label="eq. 27: constant")
    left.set(title=f"(b) UIUC static tests: CT / mean, {len(res['uiuc']['curves'])} propellers",
             xlabel="speed (RPM)", ylabel="CT / mean CT (no unit)", ylim=(0.6, 1.4))
    for i, run in enumerate(res["run_data"]):
        k = run.thrust / run.omega ** 2
        right.plot(run.omega / RPM, k / k.mean(), ("o" if i < 10 else "s") + "-", color=f"C{i % 10}", ms=3, lw=0.8,
                   label=_label(run.name))
    right.axhline(1, color="goldenrod", lw=2, label="eq. 27: constant")
    right.set(title="RCbenchmark: (f / w^2) / mean", xlabel="speed (RPM)", ylabel="(f / w^2) / mean (no unit)",
              ylim=(0, 2))
    legend(right, fontsize=6, ncol=2)
    return fig


def held_out(res):
    fig, axes = figure(1, 2, size=SIZE)
    names = list(res["runs"])
    x = np.arange(len(names))
    for ax, (base, ext, unit) in zip(axes[0], ((BASE_THRUST, EXT_THRUST, "mN"), (BASE_TORQUE, EXT_TORQUE, "mN m"))):
        for split, fill in zip(SPLITS, ("full", "none")):
            for model, color, dx in ((base, "C3", -0.12), (ext, "C0", 0.12)):
                y = [1e3 * res["runs"][n]["rmse"][split][model] for n in names]
                ax.semilogy(x + dx, y, "o", color=color, fillstyle=fill, label=f"{model}, {split}")
        ax.set_xticks(x, [_label(n) for n in names], rotation=60, fontsize=7)
        ax.set(xlabel="RCbenchmark file", ylabel=f"held-out RMSE ({unit})")
        legend(ax, fontsize=6)
    axes[0, 0].set_title("(c) thrust: held-out RMSE per file")
    axes[0, 1].set_title("(c) torque: held-out RMSE per file")
    return fig


def images(res) -> dict[str, bytes]:
    """File name -> PNG of every figure of the report."""
    figures = {"torque": torque, "ct": ct, "held_out": held_out}
    return {FIGURE_FILES[name]: png(draw(res), DPI) for name, draw in figures.items()}
