"""Plots a pilot reads at a glance: a crash is marked and named in the title, every axis has its
unit, legends sit off the data, an empty panel says why it is empty."""
from __future__ import annotations

import math

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg

from flightctl.logfile import FLIGHT_COLUMNS, Table
from flightctl.sim.plots import crash_times, empty_panel, figure, flight_figure


def flight(t_end=6.0, crash_at=None, tilt_at=None):
    """A flight log: climb to 1 m; from `crash_at` a free fall (the floor hit at ~4.4 m/s); from
    `tilt_at` a roll that runs past 60 degrees."""
    t = np.arange(0.0, t_end, 1 / 450)
    cols = {c: np.zeros_like(t) for c in FLIGHT_COLUMNS}
    z = np.minimum(t, 1.0)
    if crash_at is not None:
        fall = np.clip(t - crash_at, 0, None)
        z = np.maximum(z - 0.5 * 9.81 * fall ** 2, 0.0)
    roll = np.zeros_like(t) if tilt_at is None else np.clip(t - tilt_at, 0, None) * 2.0
    cols.update(t=t, alt=z, alt_sp=np.ones_like(t), roll=roll, range=np.where(np.arange(len(t)) % 10, np.nan, z),
                battery_v=np.full_like(t, 15.8), true_z=z, true_roll=roll, true_pitch=0 * t, true_yaw=0 * t,
                **{f"P{i}": np.full_like(t, 170.0) for i in range(1, 5)})
    return Table("synthetic.csv", cols, {}, np.arange(len(t)))


def render(fig):
    """Draw (constrained layout runs) and give the renderer, so that extents are final."""
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    return canvas.get_renderer()


def test_a_clean_flight_is_not_marked():
    assert crash_times(flight()) == []
    fig = flight_figure(flight(), "hover")
    assert not fig.get_suptitle().startswith("CRASHED")


def test_a_hard_touchdown_is_marked_and_titled():
    log = flight(crash_at=3.0)
    (when, what), = crash_times(log)
    assert 3.4 < when < 3.5 and "hit the floor at 4." in what        # 1 m of free fall: 4.4 m/s
    fig = flight_figure(log, "step_alt")
    assert fig.get_suptitle().startswith(f"CRASHED at t = {when:.2f} s (hit the floor")
    for ax in fig.axes:
        assert any(abs(line.get_xdata()[0] - when) < 1e-9 for line in ax.get_lines() if line.get_linestyle() == ":")


def test_a_tilt_past_60_degrees_is_a_crash():
    (when, what), = crash_times(flight(tilt_at=2.0))
    assert when == np.float64(when) and abs(when - (2.0 + math.radians(60) / 2.0)) < 0.01
    assert what == "tilt past 60 deg"


def test_units_on_every_axis_and_legends_off_the_data():
    fig = flight_figure(flight(crash_at=3.0), "x")
    renderer = render(fig)
    for ax in fig.axes:
        assert "(" in ax.get_ylabel() and ")" in ax.get_ylabel(), ax.get_ylabel()
    assert "(s)" in fig.axes[-1].get_xlabel()
    boxes = [ax.get_window_extent(renderer) for ax in fig.axes]
    legends = list(fig.legends) + [ax.get_legend() for ax in fig.axes if ax.get_legend() is not None]
    assert len(legends) == 2
    for lg in legends:
        lb = lg.get_window_extent(renderer)
        assert not any(lb.overlaps(b) for b in boxes)


def test_an_empty_panel_says_why():
    fig, axes = figure()
    empty_panel(axes[0, 0], "Nothing to show: no candidate could be judged")
    texts = [t.get_text() for t in axes[0, 0].texts]
    assert texts == ["Nothing to show: no candidate could be judged"]
    assert len(axes[0, 0].get_xticks()) == 0
    render(fig)
