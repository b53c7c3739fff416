"""The loop's effectiveness and timing identified through the closed loop (issue 42 part 1, docs/steps.md,
"How far to trust it"): the indirect method of closed-loop identification.

Why: the base model (basemodel.py) regresses the angular acceleration on the motor commands. In a flying loop
the commands are the controller's answer to the gyro: a disturbance torque d (propwash, vibration, the
gyro's noise through P and D) moves the gyro, and the controller's commands move against it within a few
milliseconds, so the commands are correlated with the regression's error and the slope is biased toward
zero (the errors-in-variables and feedback bias of closed-loop identification; Ljung, System
Identification, 2nd ed., section 13.4). The stiffer and noisier the loop, the worse: on PID-Analyzer's
CS110 better tune the slope is 1/30-1/42 of what its own steps need (scripts/closed_loop_bias.py: an
instrumental-variable estimate with the rate setpoint as the instrument, which the loop does not feed
back, moves it 14-20x the same way; the instrument is weak there, first-stage R^2 0.02-0.06, so it stays
biased toward the direct fit).

How: the setpoint is external to the loop. The measured setpoint-to-gyro response of the identification
rows (`steps.measure`, deconvolution over windows) is the closed loop T(b, timing) of the logged
controller (predict.py's `closed_loop`, whose controller the log gives); the controller known, the plant's
effectiveness b of each axis is the value whose closed-loop step best matches the measured one (the RMS
step error, `steps.band_step` on the measured window and band), by a bounded search of its factor on the
base model's own (FACTOR_RANGE, log-spaced grid then refined), at the base model's timing or the motor lag
it stands in for (LAGS); only on an axis the direct fit does not already predict (predict.AGREE_ERROR).
The fit sees only the rows it is given (the first half in `held_out`,
the identifying log in `cross`): the rest is the check.

What it cannot do: a controller term the log does not give (TPA, feed-forward of 3.2+, the battery
compensation) is absorbed into b and the timing; an axis without a measured step on the identifying rows
keeps the base model's b (named in the entry).
"""
from __future__ import annotations

import numpy as np

from flightctl.sim.diagnose import steps

# The timing: the base model's pure delay tau (basemodel.py `_timing`, from the commands and the motion), or a
# first-order motor lag L and the delay tau - L (the same total latency, a smoother shape: the lag a pure
# delay stands in for), when the identifying steps prefer it by LAG_MARGIN in the sum of the axes' step
# errors. A free delay and lag fitted to the steps alone trade against b and run to the ends of any grid
# (0 and 30 ms on the CS110 pair): the step's 3-11 ms delay is a small part of its RMS.
LAGS = (0.005, 0.01, 0.015, 0.02)                 # s: a small quad's motor time constant (docs/as-flown.md)
LAG_MARGIN = 0.01
FACTOR_RANGE = (0.1, 300.0)                       # b against the base model's direct fit (module docstring)
GRID = 36                                         # log-spaced factors before the refinement
# An axis whose base model already predicts its identifying steps (step error under predict.AGREE_ERROR at
# factor 1) keeps it: a quiet loop's direct fit is unbiased (the paper's vehicle in `flightctl sim`: eq. 25's
# 2 l / J within 1 %), and the closed-loop fit would absorb the loop model's own errors into b.


def _error(r: steps.Response, final: float):
    """(the response's bins, the step error of a frequency response H on them against `r`'s measured step)."""
    f = np.fft.rfftfreq(r.n_seg, 1.0 / r.fs)
    n_pre = int(np.sum(r.t < 0))
    n_resp = r.t.size - n_pre
    after = r.t >= 0
    meas = r.step[after]

    def err(H):
        pred = steps.band_step(H, f, r.band_hz, r.n_seg, n_pre, n_resp)
        return float(np.sqrt(np.mean((pred[after] - meas) ** 2)) / abs(final))
    return f, err


def fit(vehicle, declared, table, ctrl: dict) -> dict:
    """The loop fit of `vehicle` (basemodel.py's) on `table`'s own measured steps with its controller `ctrl`:
    {"timing": {"delay_s", "lag_s"}, "axes": {axis: {"factor", "b", "b_direct", "step_error"} or {"why"}},
    "what"}. Written into vehicle.identification["loop_fit"] by `attach_fit`."""
    from scipy import optimize

    from flightctl.sim.diagnose import predict
    measured, curves = steps.measure(table)
    loop = predict.loop_of(ctrl)
    rate = measured.get(loop, {})
    axes, out = {}, {}
    for axis in steps.AXES:
        e = rate.get(axis, rate)
        if "why" in e:
            out[axis] = {"why": f"no measured step on the identifying rows: {e['why']}"}
            continue
        if axis == "z" and not predict.yaw_identified(vehicle):
            out[axis] = {"why": "the yaw effectiveness is not identified"}
            continue
        parts, _ = predict.loop_parts(ctrl, table.meta, axis, declared)
        if parts is None:
            out[axis] = {"why": "the identifying log's controller cannot be closed"}
            continue
        b0 = predict.effectiveness(vehicle, declared, axis, parts)
        if not b0 > 0:
            out[axis] = {"why": f"the base model's effectiveness {b0:.3g} is not positive"}
            continue
        r = curves[(loop, axis)]
        f, err = _error(r, e["final"])
        chain = parts.get("gyro_loop_chain") or table.meta.get("gyro_loop_filter", table.meta.get("gyro_filter", "none"))
        axes[axis] = (parts, b0, f, err, chain, table.meta.get("gyro_filter", "none"))
    if not axes:
        return {"axes": out, "timing": None, "what": "no axis with a measured step on the identifying rows"}
    grid = np.geomspace(*FACTOR_RANGE, GRID)

    def best_factor(t, b0, err, free=True):
        """(step error, factor) of the best b = factor b0 on the loop terms t (factor 1 unless `free`)."""
        Cr, Cy = predict.controller(t["_terms"], *t["_gains"])
        G = b0 * t["_terms"]["G"]

        def e_of(x):
            H = t["_terms"]["Fr"] * x * G * Cr / (1.0 + x * G * Cy)
            H[t["_f"] == 0] = t["_dc"] if t["_dc"] is not None else H[1]
            return err(H)
        if not free:
            return e_of(1.0), 1.0
        errs = [e_of(x) for x in grid]
        j = int(np.argmin(errs))
        lo, hi = np.log(grid[max(j - 1, 0)]), np.log(grid[min(j + 1, grid.size - 1)])
        res = optimize.minimize_scalar(lambda u: e_of(np.exp(u)), bounds=(lo, hi), method="bounded",
                                       options={"xatol": 0.005})
        return (float(res.fun), float(np.exp(res.x))) if res.fun < errs[j] else (errs[j], float(grid[j]))

    tau = float(vehicle.identification["timing"]["value"])
    direct = {}
    for axis, (parts, b0, f, err, chain, resp) in axes.items():
        direct[axis] = best_factor(_terms(parts, f, tau, 0.0, chain, resp), b0, err, free=False)[0]
    free = {axis: not direct[axis] < predict.AGREE_ERROR for axis in axes}
    best = None
    for lag in (0.0,) + tuple(L for L in LAGS if L <= tau):
        for delay in (tau - lag,):
            total, per = 0.0, {}
            for axis, (parts, b0, f, err, chain, resp) in axes.items():
                e_, x = best_factor(_terms(parts, f, float(delay), float(lag), chain, resp), b0, err, free[axis])
                per[axis] = (e_, x)
                total += e_
            if best is None or total < best[0] - LAG_MARGIN:
                best = (total, float(delay), float(lag), per)
    _, delay, lag, per = best
    for axis, (e_, x) in per.items():
        b0 = axes[axis][1]
        out[axis] = {"factor": round(x, 4), "b": round(x * b0, 3), "b_direct": round(b0, 3), "step_error": round(e_, 4),
                     "step_error_direct": round(direct[axis], 4), "fitted": free[axis],
                     "at_bound": bool(x >= 0.99 * FACTOR_RANGE[1] or x <= 1.01 * FACTOR_RANGE[0])}
        if out[axis]["at_bound"]:
            out[axis]["why_bound"] = (f"the factor sits at the end of its range {FACTOR_RANGE[0]:g}-{FACTOR_RANGE[1]:g}: the "
                                      "measured step is no slower for any larger b (the loop's filters and delay set it), "
                                      "or a term the loop lacks (feed-forward) makes it faster than any b can")
    return {"axes": out, "timing": {"delay_s": delay, "lag_s": lag},
            "what": "the closed loop's effectiveness per axis and timing fitted to the identifying rows' measured "
                    "steps with their own controller (loopfit.py, the indirect method): the direct regression of "
                    "basemodel.py is biased toward zero by the loop's feedback"}


def _terms(parts: dict, f, delay: float, lag: float, chain: str, resp: str) -> dict:
    """predict.loop_terms at this timing with the axis' gains, for `fit`'s search."""
    from flightctl.sim.diagnose import predict
    p = {**parts, "motor_lag_s": lag}
    return {"_terms": predict.loop_terms(f, delay, p, chain, resp), "_gains": (p["kp"], p["ki"], p["kd"], p.get("kf", 0.0)),
            "_f": f, "_dc": 1.0 if p["ki"] or p.get("loop") == "attitude" else None}


def attach_fit(model, table, ctrl: dict):
    """`model` (predict.base_model's) with its loop fit on `table` (flown with `ctrl`) in its identification."""
    if isinstance(model, str):
        return model
    vehicle, declared = model
    vehicle.identification["loop_fit"] = fit(vehicle, declared, table, ctrl)
    return model
