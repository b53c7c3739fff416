"""The figure at the end of `flightctl bench`, in the one plotting style (sim/plots.py): thrust and
speed against P per motor (eq. 26 and 27's data), the raw speed samples over time, and the step
responses with their fitted first-order curves. Imported only when a plot is asked for."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from flightctl.hil.bench import RAW_COLUMNS
from flightctl.logfile import BENCH_COLUMNS, read_table
from flightctl.sim.plots import empty_panel, figure, legend, save


def plot_bench(out: Path, raw_path: Path, step_fits, path) -> None:
    table = read_table(out, BENCH_COLUMNS) if out.stat().st_size else None
    raw = read_table(raw_path, RAW_COLUMNS, text_columns=("phase",))
    fig, ax = figure(2, 2, size=(11.0, 7.0))
    rows = table is not None and len(table) > 0
    for m in sorted(set(table["motor"].astype(int))) if rows else []:
        k = table["motor"] == m
        ax[0, 0].plot(table["P"][k], table["thrust"][k], "o-", label=f"motor {m}")
        ax[0, 1].plot(table["P"][k], table["omega"][k], "o-", label=f"motor {m}")
    for a, what, unit in ((ax[0, 0], "thrust", "N"), (ax[0, 1], "speed", "rad/s")):
        a.set_xlabel("P (command value, 0-255)")
        a.set_ylabel(f"steady {what} ({unit})")
        if rows:
            legend(a)
        else:
            empty_panel(a, "no steady point was measured")
    if len(raw):
        for m in sorted(set(raw["motor"].astype(int))):
            k = raw["motor"] == m
            ax[1, 0].plot(raw["t"][k], raw["omega"][k], ".", ms=1.5, label=f"motor {m}")
        legend(ax[1, 0])
    else:
        empty_panel(ax[1, 0], "the instruments sent no sample")
    ax[1, 0].set_xlabel("bench time (s)")
    ax[1, 0].set_ylabel("speed sample (rad/s)")
    for m, t0, samples, tau, w0, w1 in step_fits:
        t = np.array([s[0] for s in samples]) - t0
        w = np.array([s[1] for s in samples])
        dots, = ax[1, 1].plot(t * 1e3, w, ".", ms=2, label=f"motor {m}")
        ax[1, 1].plot(t * 1e3, w1 + (w0 - w1) * np.exp(-np.clip(t, 0, None) / tau), "-",  # its motor's colour
                      color=dots.get_color(), label=f"motor {m} fit, tau {tau * 1e3:.1f} ms")
    if step_fits:
        legend(ax[1, 1])
    else:
        empty_panel(ax[1, 1], "no step profile (--profile step or both)")
    ax[1, 1].set_xlabel("time after the step (ms)")
    ax[1, 1].set_ylabel("speed (rad/s)")
    fig.suptitle(f"flightctl bench: {out.name}")
    save(fig, path)
