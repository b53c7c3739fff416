"""The battery in the static tier: its sag under load and, where the log has the current, its internal
resistance.

The pack is an open-circuit voltage E that falls as charge q is drawn, behind a resistance R:
V = E0 - k q - R I (the battery_sag cause's model, flightctl.sim.causes.battery_sag, with E linear in the
charge over one flight), fitted by least squares over the rows with the motors running, the current
taken a lag L earlier (0-MAX_LAG_S, the one that fits best: a logger's voltage filter lags its current),
both averaged over SMOOTH_S first (a logger that holds its voltage between reads, or filters it).
The standard errors are the block jackknife's (the rows of a block are correlated). Physical checks: R
above zero and within R_CELL (per cell, a LiPo's and its wiring's) times the cell count; E0 per cell
within a LiPo's range and inside the voltages the pack showed (from its lowest under load to its highest,
at rest before the motors start where the log has that); the open-circuit voltage not rising with the charge drawn (k >= 0).
"""
from __future__ import annotations

import math

import numpy as np

from flightctl.battery import CELL_V as E_CELL   # a lithium-polymer cell, discharged to charged
from flightctl.sim.diagnose.data import FileData, all_running
from flightctl.sim.diagnose.static.blocks import moving_mean

R_CELL = (0.0003, 0.1)      # ohm per cell: a new high-rate LiPo's 1-3 mOhm to a worn one's tens, and its leads
R_T = 3.0                   # R named when above this many of its standard errors
E_TOL = 0.02                # V a cell: E0 may exceed the highest voltage logged by this (the logger's resolution)
SMOOTH_S = 0.5              # s: V and I both averaged over this (a logger holds or filters its voltage)
MAX_LAG_S, LAG_STEP_S = 0.5, 0.02
N_BLOCKS = 10
MIN_ROWS = 50
# A logged current is no sensor when less than MIN_CURRENT_A of its spread follows the throttle or its
# correlation with it is under MIN_CURRENT_R (a constant 0.27-0.40 A, or a noise: what boards without a sensor
# log): the shipped logs' sensors 0.71-0.90 and 2.9-7.9 A, the simulator's hover-heavy test flight -0.38 and 0.29 A
MIN_CURRENT_A, MIN_CURRENT_R = 0.1, 0.25


def _lagged(t: np.ndarray, x: np.ndarray, lag: float) -> np.ndarray:
    return np.interp(t - lag, t, x)


def battery(files: list[FileData], currents: list[np.ndarray | None]) -> dict | None:
    """{sag, resistance}: the battery findings (the module's docstring), None when no voltage was logged."""
    rows = []
    for f, cur in zip(files, currents):
        on = all_running(f.P) if f.foreign else f.running
        ok = on & np.isfinite(f.battery_v) & (f.battery_v > 0)
        if cur is not None:
            c = np.where(np.isfinite(cur), cur, np.nan)
            good = np.isfinite(c)
            if good.sum() >= 2:
                cur = np.interp(f.t, f.t[good], c[good])
                q = np.concatenate([[0.0], np.cumsum(0.5 * (cur[1:] + cur[:-1]) * np.diff(f.t))]) / 3600.0
            else:
                cur = None
        V = moving_mean(f.t, np.where(np.isfinite(f.battery_v), f.battery_v, np.nan), SMOOTH_S)[0]
        if cur is not None:
            cur = moving_mean(f.t, cur, SMOOTH_S)[0]
        rows.append((f, ok, V, cur, q if cur is not None else None))
    if not any(ok.sum() >= MIN_ROWS for _, ok, _, _, _ in rows):
        return None
    V = np.concatenate([f.battery_v[ok] for f, ok, _, _, _ in rows])
    rest = max(float(np.nanmax(f.battery_v)) for f in files if np.isfinite(f.battery_v).any())
    cells = next((f.battery_cells for f in files if f.battery_cells), None)
    out = {"cells": cells, "v_range": [round(float(V.min()), 2), round(float(V.max()), 2)],
           "v_min_per_cell": round(float(V.min()) / cells, 3) if cells else None,
           "what": "the pack's voltage over the rows with the motors running (V); per cell from the log's cell count"}
    if any(cur is None for _, _, _, cur, _ in rows):
        out["resistance"] = None
        out["without_current"] = ("no current in the log: the sag is the voltage's range; the internal resistance needs "
                                  "a current sensor logged (ArduPilot BAT.Curr, Betaflight amperage)")
        return out
    r, amps = throttle_current(rows)
    out["current_throttle"] = {"r": round(r, 3), "amps": round(amps, 3),
                               "what": "the current's correlation with the mean motor command and its spread that "
                                       "follows it (|r| times its standard deviation, A)"}
    if not (amps >= MIN_CURRENT_A and abs(r) >= MIN_CURRENT_R):
        out["resistance"] = None
        out["without_current"] = (f"no current sensor: the logged current does not move with the throttle ({amps:.2f} A "
                                  f"of it does, correlation {r:.2f} with the mean motor command; {MIN_CURRENT_A:g} A and "
                                  f"{MIN_CURRENT_R:g} or more for a sensor: a constant or a noise is logged where none is "
                                  "fitted): the sag is the voltage's range, no internal resistance")
        return out
    return {**out, **_resistance(rows, cells, V, rest)}


def throttle_current(rows) -> tuple[float, float]:
    """(r, amps): the correlation of the logged current (averaged over SMOOTH_S) with the mean motor command
    (the same, over the rows with the motors running only) on those rows, and the current's spread that
    follows the throttle, |r| times its standard deviation. A current sensor's reading moves with the
    throttle (the motors draw it); a constant or a noise logged where no sensor is fitted does not (0 when
    either is constant)."""
    x, y = [], []
    for f, ok, _, cur, _ in rows:
        x.append(moving_mean(f.t, np.where(ok, np.nanmean(f.P, axis=0), np.nan), SMOOTH_S)[0][ok])
        y.append(cur[ok])
    x, y = np.concatenate(x), np.concatenate(y)
    if x.size < MIN_ROWS or x.std() == 0.0 or y.std() == 0.0:
        return 0.0, 0.0
    r = float(np.corrcoef(x, y)[0, 1])
    return r, abs(r) * float(y.std())


def _fit(rows, lag: float):
    """(design matrix, V, time) over the rows for the current `lag` s earlier."""
    X, y, t = [], [], []
    for f, ok, V, cur, q in rows:
        c = _lagged(f.t, cur, lag)
        X.append(np.column_stack([np.ones(ok.sum()), -c[ok], -q[ok]]))
        y.append(V[ok])
        t.append(f.t[ok])
    return np.vstack(X), np.concatenate(y), np.concatenate(t)


def _resistance(rows, cells: int | None, V: np.ndarray, rest: float) -> dict:
    best = None
    for lag in np.arange(0.0, MAX_LAG_S + 1e-9, LAG_STEP_S):
        X, y, _ = _fit(rows, lag)
        beta, res, *_ = np.linalg.lstsq(X, y, rcond=None)
        sse = float(np.sum((y - X @ beta) ** 2))
        if best is None or sse < best[0] - 1e-12:
            best = (sse, lag, beta)
    _, lag, beta = best
    X, y, _ = _fit(rows, lag)
    n = y.size
    idx = (np.arange(n) * N_BLOCKS) // n
    jack = np.array([np.linalg.lstsq(X[idx != b], y[idx != b], rcond=None)[0] for b in range(N_BLOCKS)])
    sd = np.sqrt((N_BLOCKS - 1) / N_BLOCKS * ((jack - jack.mean(axis=0)) ** 2).sum(axis=0))
    E0, R, k = (float(v) for v in beta)
    current = -X[:, 1]
    i_max = float(current.max())
    checks, passed = [], True
    lo, hi = (R_CELL[0] * cells, R_CELL[1] * cells) if cells else (0.0, math.inf)
    ok = lo < R < hi and R > R_T * sd[1]
    passed &= ok
    checks.append(f"R = {1e3 * R:.1f} +- {1e3 * sd[1]:.2g} mOhm above {R_T:g} standard errors and within "
                  + (f"{1e3 * lo:.1f}-{1e3 * hi:.0f} mOhm ({cells} cells x {1e3 * R_CELL[0]:g}-{1e3 * R_CELL[1]:g})"
                     if cells else "(no cell count: no range)") + (": passed" if ok else ": failed"))
    v_hi = rest + E_TOL * (cells or 1)
    ok = (E_CELL[0] * cells <= E0 <= E_CELL[1] * cells if cells else True) and float(V.min()) <= E0 <= v_hi
    passed &= ok
    checks.append(f"E0 = {E0:.2f} V" + (f" ({E0 / cells:.3f} V a cell, {E_CELL[0]:g}-{E_CELL[1]:g})" if cells else "")
                  + f" inside the pack's measured {float(V.min()):.2f} V under load to {rest:.2f} V its highest "
                    f"(+ {E_TOL:g} V a cell): " + ("passed" if ok else "failed"))
    ok = k >= -2.0 * sd[2]
    passed &= ok
    checks.append(f"the open-circuit voltage falls with the charge drawn (k = {k:.3f} +- {sd[2]:.2g} V/Ah): "
                  + ("passed" if ok else "failed"))
    return {"resistance": {"ohm": round(R, 5), "stderr": float(f"{sd[1]:.2g}"), "E0": round(E0, 3),
                           "E0_stderr": float(f"{sd[0]:.2g}"), "k_v_per_ah": round(k, 4), "k_stderr": float(f"{sd[2]:.2g}"),
                           "current_lag_s": round(float(lag), 3), "current_max_a": round(i_max, 1),
                           "sag_at_max_v": round(R * i_max, 3), "rows": int(n), "blocks": N_BLOCKS,
                           "check": "; ".join(checks), "passed": bool(passed),
                           "what": "V = E0 - k q - R I(t - lag) by least squares over the rows with the motors "
                                   "running (q: the charge drawn, Ah); block jackknife standard errors; sag_at_max_v: "
                                   "R times the largest current"}}
