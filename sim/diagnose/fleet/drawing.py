"""A vehicle's figure of the fleet report: each series against its flights' order with its standard
errors as bars (the four motors' shares in one panel, the battery's resistance, the vibration, the
timing where the dynamic tier gave one), a named change marked: a line at its onset flight, its 95 %
onset set shaded, and the fitted levels (or the hinge) drawn over it."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from flightctl.sim.plots import figure, legend, save

PANELS = (("shares", ("share_1", "share_2", "share_3", "share_4"), "share of the hover thrust", 1.0),
          ("battery", ("battery_ohm",), "internal resistance (mOhm)", 1e3),
          ("vibration", ("vibration",), "vibration (m/s^2)", 1.0),
          ("timing", ("timing_s",), "timing (ms)", 1e3))


def draw(v: dict, changes: list[dict], path: Path) -> None:
    """The figure of one vehicle of the report's JSON (`report.build`) into `path` (PNG)."""
    fig, axes = figure(len(PANELS), 1, size=(8.0, 9.0), sharex=True)
    n = len(v["flights"])
    for ax, (panel, names, unit, k) in zip(axes[:, 0], PANELS):
        drawn = False
        for name in names:
            s = v["series"].get(name)
            if not s:
                continue
            err = [0.0 if e is None else k * e for e in s["stderr"]]
            label = f"motor {name[-1]}" if name.startswith("share_") else None
            ax.errorbar(np.asarray(s["flight"]) + 1, k * np.asarray(s["value"]), yerr=err, fmt="o", ms=3, capsize=2, label=label)
            drawn = True
        for c in changes:
            if c["series"] not in names:
                continue
            lo, hi = c["onset_set_flights"]
            ax.axvspan(lo + 0.5, hi + 1.5, color="tab:red", alpha=0.12)
            ax.axvline(c["onset_flight"] + 0.5, color="tab:red", lw=1.2)
            x0, x1 = c["onset_flight"] + 1, n          # counted from 1, as fleet.md counts them
            if c["shape"] == "step":
                ax.plot([1, x0 - 0.5], [k * c["before"]] * 2, color="tab:red", lw=1)
                ax.plot([x0 - 0.5, x1], [k * c["after"]] * 2, color="tab:red", lw=1)
            else:
                ax.plot([1, x0 - 1, x1], [k * c["before"], k * c["before"], k * c["after"]], color="tab:red", lw=1)
            ax.text(x0, ax.get_ylim()[1], f" {c['what']}: from flight {x0}", color="tab:red", va="top", fontsize=8)
        if not drawn:
            why = v["timing"] if panel == "timing" and v["timing"] else f"no {panel} figure in these logs"
            ax.text(0.5, 0.5, why, ha="center", va="center", wrap=True, fontsize=9, transform=ax.transAxes)
            ax.set_yticks([])          # (not sim.plots.empty_panel: its x ticks are the shared axis')
        else:
            ax.set_ylabel(unit)
            if panel == "shares":
                legend(ax)
    from matplotlib.ticker import MaxNLocator
    axes[-1, 0].xaxis.set_major_locator(MaxNLocator(integer=True))
    axes[-1, 0].set_xlabel(f"flight, from 1 (in order: {v['order'][:60]})")
    axes[0, 0].set_title(f"{v['vehicle']}: {n} flights")
    save(fig, path)
