"""The hover segments of a flight and their blocks: the rows where the vehicle holds itself (airborne by
`flightctl.sim.diagnose.data`'s mask, all four motors running and none at full command, body
rates and specific force near rest), cut into contiguous blocks of equal length over the flight, for
block-jackknife standard errors (a statistic of the block means, recomputed with each block left out:
the rows of one block are correlated, the blocks nearly not) and for the drift of a block statistic over
the flight (a regression on the blocks' times)."""
from __future__ import annotations

import math

import numpy as np

from flightctl.sim.diagnose.data import FileData, all_running

G = 9.80665
HOVER_RATE = 0.5        # rad/s: body rates below this (a quadrotor holding its attitude)
HOVER_ACC = 0.25        # the specific force within this share of g (not climbing hard, not falling)
FULL_P = 250.0          # a motor at or above this command is saturated: the torques are not balanced there
SMOOTH_S = 0.2          # s: the rates and the specific force averaged over this for the hover test
STEADY_S = 1.0          # s: without an IMU, the logged height's climb rate averaged over this ...
STEADY_CLIMB = 0.5      # m/s: ... below this is a steady altitude (in place of the specific force's test)
MIN_HOVER_S = 2.5       # s of hover needed for the hover findings
BLOCK_S = 0.5           # s: blocks at least this long ...
MAX_BLOCKS, MIN_BLOCKS = 20, 5   # ... and this many of them


def moving_mean(t: np.ndarray, x: np.ndarray, seconds: float) -> np.ndarray:
    """Each row of x (k, n) averaged over `seconds` centred on it (at least 3 rows; over the finite
    values in the window, fewer at the ends)."""
    width = max(3, int(round(seconds / float(np.median(np.diff(t))))))
    k = np.ones(width)
    out = []
    for v in np.atleast_2d(x):
        ok = np.isfinite(v)
        n = np.convolve(ok.astype(float), k, mode="same")
        with np.errstate(invalid="ignore", divide="ignore"):
            out.append(np.convolve(np.where(ok, v, 0.0), k, mode="same") / n)
    return np.vstack(out)


def hover_mask(f: FileData) -> np.ndarray:
    """(n,) bool: the rows of `f` in hover (the module's docstring), on the body rates and the specific
    force averaged over SMOOTH_S (a small vehicle's accelerometer shakes by g with its motors). Without an
    IMU the rates are the logged attitude's (`data.attitude_rates`) and the specific force's test is
    `steady` on the logged height."""
    rate = np.linalg.norm(moving_mean(f.t, f.rates, SMOOTH_S), axis=0)
    if f.imu:
        acc = np.linalg.norm(moving_mean(f.t, f.acc, SMOOTH_S), axis=0)
        level = np.abs(acc / G - 1.0) < HOVER_ACC
    else:
        level = steady(f)
    return f.airborne & all_running(f.P) & (f.P < FULL_P).all(axis=0) & (rate < HOVER_RATE) & level


def steady(f: FileData) -> np.ndarray:
    """(n,) bool, for a log without an IMU: the rows at a steady altitude, the logged height's climb rate
    (averaged over STEADY_S) under STEADY_CLIMB: no climb or descent under way, so no vertical acceleration
    held for long (HOVER_ACC g for STEADY_S would change the climb rate by 2.5 m/s); False on every row
    when no height was logged."""
    if f.height is None or not np.isfinite(f.height).any():
        return np.zeros(f.t.size, bool)
    h = moving_mean(f.t, f.height, STEADY_S / 2)[0]
    climb = np.gradient(h, f.t)
    return np.abs(moving_mean(f.t, climb, STEADY_S)[0]) < STEADY_CLIMB


class Blocks:
    """Rows of several files (selected by a mask each) in order of time, cut into contiguous blocks."""

    def __init__(self, files: list[FileData], masks: list[np.ndarray]):
        self.files, self.masks = files, masks
        offset, times = 0.0, []
        for f, m in zip(files, masks):
            times.append(f.t[m] - f.t[0] + offset)
            offset += f.t[-1] - f.t[0]
        self.t = np.concatenate(times)
        self.dt = float(np.median(np.concatenate([np.diff(f.t) for f in files])))
        self.seconds = self.t.size * self.dt
        self.n_blocks = int(min(MAX_BLOCKS, math.floor(self.seconds / BLOCK_S)))
        self.index = (np.arange(self.t.size) * max(self.n_blocks, 1)) // max(self.t.size, 1)

    @property
    def enough(self) -> bool:
        return self.n_blocks >= MIN_BLOCKS

    def rows(self, values) -> np.ndarray:
        """(k, rows) of per-file arrays (k, n) (or (n,)) on the selected rows, concatenated."""
        return np.concatenate([np.atleast_2d(v)[:, m] for v, m in zip(values, self.masks)], axis=1)

    def means(self, x: np.ndarray) -> np.ndarray:
        """(blocks, k): the mean of each block of x (k, rows)."""
        x = np.atleast_2d(x)
        out = np.empty((self.n_blocks, x.shape[0]))
        for b in range(self.n_blocks):
            out[b] = np.nanmean(x[:, self.index == b], axis=1)
        return out

    def times(self) -> np.ndarray:
        """(blocks,): each block's mean time (s from the start of the first file)."""
        return self.means(self.t)[:, 0]

    def jackknife(self, means: np.ndarray, stat) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(the statistic on all blocks, its jackknife standard error, the leave-one-out values) of
        `stat`, a function of the (k,) mean of the block means kept."""
        full = np.asarray(stat(means.mean(axis=0)), float)
        keep = ~np.eye(self.n_blocks, dtype=bool)
        jack = np.array([np.asarray(stat(means[k].mean(axis=0)), float) for k in keep])
        B = self.n_blocks
        sd = np.sqrt((B - 1) / B * ((jack - jack.mean(axis=0)) ** 2).sum(axis=0))
        return full, sd, jack


def drift(t: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(slope, standard error) per column of y (blocks, k) regressed on t (blocks,) by least squares
    (the regression's own standard error: the blocks' residuals are taken as independent)."""
    tc = t - t.mean()
    sxx = float(tc @ tc)
    slope = tc @ (y - y.mean(axis=0)) / sxx
    r = (y - y.mean(axis=0)) - np.outer(tc, slope)
    se = np.sqrt((r * r).sum(axis=0) / max(t.size - 2, 1) / sxx)
    return slope, se


def body_z_force(f: FileData) -> tuple[np.ndarray, str]:
    """((n,) the body-z specific force, what it is): the accelerometer's acc_z; without an IMU, at a steady
    altitude (`steady`), the force that holds the weight through the logged tilt, g / (cos(roll) cos(pitch))
    (Rm's z-z entry, eq. 7 with no vertical acceleration)."""
    if f.imu:
        return f.acc[2], "the accelerometer's acc_z"
    return G / np.maximum(f.Rm[8], 0.1), "g / (cos(roll) cos(pitch)) of the logged attitude at a steady altitude (no IMU)"
