"""An independent check of the base model's roll and pitch (issue 42, docs/real-flights.md, "Refused when
the data contradict the layout, or do not show it"): the angular acceleration regressed on the commanded
torque, with none of the identification's structure (no thrust curve, rotor gains, centre of mass, timing
search or channel weighting). Per axis over the airborne rows of the logs (`FileData.airborne`): the gyro's
difference and the torque the layout gives the commands, sum_i y_i P_i^2 for roll and -sum_i x_i P_i^2 for
pitch (eq. 26 with h2 = 0 through eq. 25's structure), the commands DELAY_S late, both low-passed at the
diagnosis' 12 Hz (2nd-order Butterworth forward and back, per airborne stretch), cut into the scoring's
N_BLOCKS contiguous blocks with an intercept each (a trim torque that drifts between blocks is not the
axis' effectiveness). Reported: the slope's t over its delete-one-block jackknife error, in how many blocks
alone the slope has the layout's sign, and R^2. A refusal that says a log does not show an axis gives these
figures (basemodel._refuse); scripts/axis_regression.py sets them beside the tool's t on every shipped log."""
from __future__ import annotations

import numpy as np

from flightctl.sim.diagnose.data import FileData, stretches
from flightctl.sim.diagnose.dataset import LOWPASS_HZ, N_BLOCKS

DELAY_S = 0.025       # s: the issue's; the motors' lag and the loop's delay of a small quad are 10-30 ms
MIN_ROWS = 30         # rows: a shorter stretch is left out (the filter's transient would be all of it)
AXES = ("roll", "pitch")


def regression(files: list[FileData], axis: int, delay_s: float = DELAY_S, lowpass_hz: float = LOWPASS_HZ) -> dict:
    """{"slope", "t", "r2", "signs"} of axis 0 (roll) or 1 (pitch) (module docstring)."""
    from scipy import signal
    ys, xs = [], []
    for fd in files:
        fs = 1.0 / float(np.median(np.diff(fd.t)))
        sos = signal.butter(2, lowpass_hz, fs=fs, output="sos")
        lay = fd.layout
        arm = (np.asarray(lay.y, float) if axis == 0 else -np.asarray(lay.x, float))[:, None]
        P = np.nan_to_num(fd.P[:4])
        k = int(round(delay_s * fs))
        if k:
            P = np.concatenate([np.repeat(P[:, :1], k, axis=1), P[:, :P.shape[1] - k]], axis=1)
        torque = (arm * P * P).sum(axis=0)
        acc = np.zeros(fd.t.size)
        acc[:-1] = np.diff(np.nan_to_num(fd.gyro[axis])) / np.diff(fd.t)
        for s0, s1 in stretches(fd.airborne):
            if s1 - s0 >= MIN_ROWS:
                ys.append(signal.sosfiltfilt(sos, acc[s0:s1]))
                xs.append(signal.sosfiltfilt(sos, torque[s0:s1]))
    if not ys:
        return {"slope": 0.0, "t": 0.0, "r2": 0.0, "signs": 0}
    y, x = np.concatenate(ys), np.concatenate(xs)
    edges = np.linspace(0, y.size, N_BLOCKS + 1).round().astype(int)
    # per block: the centred sums, so that any set of blocks is fitted from them
    sxx, sxy, syy = (np.zeros(N_BLOCKS) for _ in range(3))
    for b in range(N_BLOCKS):
        xb, yb = x[edges[b]:edges[b + 1]], y[edges[b]:edges[b + 1]]
        if xb.size:
            xb, yb = xb - xb.mean(), yb - yb.mean()
            sxx[b], sxy[b], syy[b] = xb @ xb, xb @ yb, yb @ yb

    def fit(keep):
        return float(sxy[keep].sum() / sxx[keep].sum()) if sxx[keep].sum() > 0 else 0.0

    allb = np.ones(N_BLOCKS, bool)
    slope = fit(allb)
    r2 = slope * float(sxy.sum()) / float(syy.sum()) if syy.sum() > 0 else 0.0
    jack = np.array([fit(np.arange(N_BLOCKS) != b) for b in range(N_BLOCKS)])
    sd = float(np.sqrt((N_BLOCKS - 1) / N_BLOCKS * ((jack - jack.mean()) ** 2).sum()))
    signs = int(sum(sxy[b] > 0 for b in range(N_BLOCKS)))
    return {"slope": slope, "t": slope / sd if sd > 0 else 0.0, "r2": r2, "signs": signs}


def said(files: list[FileData], axes: list[str]) -> str:
    """The regression's figures for the named axes (of AXES), in words for a refusal."""
    parts = []
    for name in axes:
        if name not in AXES:
            continue
        r = regression(files, AXES.index(name))
        parts.append(f"{name} t = {r['t']:.1f}, the layout's sign in {r['signs']} of {N_BLOCKS} blocks, "
                     f"R^2 {r['r2']:.2f}")
    if not parts:
        return ""
    return (f"an independent regression of the angular acceleration on the commanded torque ({LOWPASS_HZ:g} Hz, "
            f"{1e3 * DELAY_S:.0f} ms late, an intercept per block) finds {'; '.join(parts)}")
