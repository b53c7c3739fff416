"""The figure of what was read from a log (`flightctl log import --plot`, `flightctl diagnose --plot`):
each stream's rate of distinct samples with its gaps, then the channels the diagnosis uses over time,
the rate setpoint dashed beside the gyro where the log has one. Lines break across gaps in the rows
(no line is drawn through time nothing was logged); a barometer's height is drawn from its first
reading (an absolute altitude would sit metres away from the estimate's). Drawn from the table and its
metadata only, so a foreign log and the CSV imported from it give the same figure."""
from __future__ import annotations

import re

import numpy as np

from flightctl.logfile import Table
from flightctl.sim.logs.columns import MAX_ROTORS   # P1..PN and omega1..omegaN, as many as the log's motors
from flightctl.sim.logs.common import GAP_PERIODS   # a line breaks across a gap in the rows as a stream's does
from flightctl.sim.plots import empty_panel, figure, legend

STREAM = re.compile(r"(.+?) rate_hz=([\d.]+) samples=(\d+) gaps=(\d+) longest_gap_s=([\d.]+)")
STRIPS = (("commands P (0-255)", tuple(f"P{i}" for i in range(1, MAX_ROTORS + 1))),
          ("gyro, setpoint dashed (rad/s)", ("gyro_x", "gyro_y", "gyro_z")),
          ("specific force (m/s^2)", ("acc_x", "acc_y", "acc_z")),
          ("battery (V, A)", ("battery_v", "current")),
          ("height (m; baro from its first reading)", ("height", "alt", "range")),
          ("rotor speed (rad/s)", tuple(f"omega{i}" for i in range(1, MAX_ROTORS + 1))))


def streams(table: Table) -> list[tuple[str, float, int, int, float]]:
    """(name, rate in Hz, samples, gaps, longest interval in s) of each stream the metadata lists."""
    out = []
    for line in table.meta.get("stream", "").splitlines():
        m = STREAM.match(line.strip())
        if m:
            out.append((m[1], float(m[2]), int(m[3]), int(m[4]), float(m[5])))
    return out


def read_figure(table: Table):
    t = table["t"]
    fig, axes = figure(1 + len(STRIPS), 1, size=(9.5, 13),
                       gridspec_kw={"height_ratios": [1.4] + [1.0] * len(STRIPS)})
    axes = axes[:, 0]
    ax = axes[0]
    info = streams(table)
    if info:
        y = np.arange(len(info))
        ax.barh(y, [s[1] for s in info], color="tab:blue")
        ax.set_yticks(y, [s[0] for s in info], fontsize=7)
        ax.set_xscale("log")
        ax.set_xlabel("rate of distinct samples [Hz] (log scale)")
        for k, (_, rate, n, gaps, longest) in enumerate(info):
            ax.text(rate, k, f"  {n} samples, {gaps} gaps, longest {1e3 * longest:.0f} ms", va="center", fontsize=7)
    else:
        empty_panel(ax, "This log lists no streams: it was not imported from another autopilot.")
    meta = table.meta
    ax.set_title(f"{meta.get('source', table.path)}: {meta.get('format', 'flightctl log')}, "
                 f"{t[-1] - t[0]:.1f} s, rows at {meta.get('rate_hz', '?')} Hz, motors at "
                 f"{meta.get('motor_rate_hz', '?')} Hz", fontsize=9)
    step = max(1, t.size // 6000)
    gap = np.flatnonzero(np.diff(t) > GAP_PERIODS * np.median(np.diff(t))) + 1 if t.size > 2 else np.array([], int)
    tt = np.insert(t, gap, np.nan)[::step]

    def line(x):
        """x with NaN at the gaps (a line breaks there), decimated; a value missing inside a stream's
        own span is bridged (its samples are sparser than the rows), not outside it."""
        ok = np.isfinite(x)
        if ok.sum() >= 2:
            inside = (np.arange(x.size) >= np.argmax(ok)) & (np.arange(x.size) <= x.size - 1 - np.argmax(ok[::-1]))
            x = np.where(inside & ~ok, np.interp(t, t[ok], x[ok]), x)
        return np.insert(x, gap, np.nan)[::step]

    for ax, (label, names) in zip(axes[1:], STRIPS):
        shown = [n for n in names if n in table and np.isfinite(table[n]).any()]
        for n in shown:
            x = table[n]
            if n == "height" and table.meta.get("height_source") == "baro":
                x = x - x[np.isfinite(x)][0]
            drawn = ax.plot(tt, line(x), lw=0.6, label=n)
            sp = n.replace("gyro_", "setpoint_")
            if sp != n and sp in table and np.isfinite(table[sp]).any():
                ax.plot(tt, line(table[sp]), lw=0.6, ls="--", color=drawn[0].get_color(), label=sp)
        if shown:
            legend(ax, fontsize=7)
        else:
            empty_panel(ax, f"not in this log: {', '.join(names[:4])}{'..' if len(names) > 4 else ''}")
        ax.set_ylabel(label, fontsize=8)
        ax.tick_params(labelsize=7)
    axes[-1].set_xlabel("time since the log's first row [s]")
    return fig
