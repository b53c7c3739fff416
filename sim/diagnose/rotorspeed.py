"""Checks of the diagnosis against the log's own rotor speeds, where the log has them (ESC telemetry,
`omega1..omega4`; docs/real-flights.md).

The diagnosis measures the actuation from the gyro and the accelerometer alone. A log that also
measured each rotor's speed shows two things directly:

- **the timing**: the command P through a first-order lag of time constant tau and a pure delay,
  against the measured speed, affine per rotor (Omega = a (P - h2) by eq. 26 and 27: a scale and an
  offset for each rotor), fitted by least squares over the whole physical range (lag and delay each
  0-300 ms: a grid, then refined), on the airborne rows only (`rotor_speed_lag`);
- **what a pattern of the rotors' thrusts in hover is** (`rotor_gain_check`): a motor that gives less
  thrust for its command (weak, or its ESC) also turns slower for it, so its speed falls below the
  others' common speed-per-command curve, by the square root of its thrust (eq. 27); a centre of mass
  off the middle asks the rotors on one side for more thrust, which in hover leaves the same pattern
  as rotor gains: then all four turn on one curve, and the pattern is front/rear or left/right
  (linear in the rotors' positions, `trim_pattern`).
"""
from __future__ import annotations

import math

import numpy as np

from flightctl.sim.causes.actuation_delay import shift
from flightctl.sim.causes.motor_lag import lag_held
from flightctl.sim.diagnose.candidate import MAX_TIMING_S
from flightctl.sim.diagnose.data import FileData, Layout

TAUS = np.concatenate([[0.0], np.geomspace(0.002, MAX_TIMING_S, 30)])   # s: the coarse grid of the lag
DELAYS = np.arange(0.0, MAX_TIMING_S + 1e-9, 0.004)                      # s: ... and of the delay
FINE_S = 0.001                     # the refined timing's resolution
MAX_ROWS = 20000                   # airborne rows used by the coarse grid (evenly spaced)
# Timings from the gyro and from the rotor speeds agree when within this (s) or this share of the
# larger: a lag and a delay of the same total look alike on hover data, and the gyro sees the thrust
# through the sensors' own timing (docs/real-flights.md)
AGREE_S, AGREE_SHARE = 0.005, 0.2
# A rotor is slow for its command when the thrust its speed gives (the square of its speed against
# the four's common speed-per-command curve) is CURVE_TOL below the mean: the four rotors of the
# INDIflight logs spread by up to 2.4 % of thrust; a pattern of thrusts is worth explaining when some
# rotor is off the mean by more than GAIN_TOL and by two jackknife standard errors.
CURVE_TOL = 0.03
GAIN_TOL = 0.03


def _with_speeds(files: list[FileData]) -> list[FileData]:
    return [f for f in files if f.omega is not None and f.airborne.any()
            and np.isfinite(f.omega[:, f.airborne]).all() and np.abs(f.omega[:, f.airborne]).max() > 0]


def rotor_speed_lag(files: list[FileData]) -> dict | None:
    """{tau, delay, rmse, per_motor_tau, h2, h2_spread, samples} of the lag and delay from the command
    to the measured rotor speed, or None when no log has rotor speeds."""
    have = _with_speeds(files)
    if not have:
        return None
    fs = 1.0 / float(np.median(np.concatenate([np.diff(f.t) for f in have])))
    rows = [np.flatnonzero(f.airborne) for f in have]
    total = sum(r.size for r in rows)
    step = max(1, total // MAX_ROWS)

    def lagged(tau):
        return [lag_held(f.P, tau, fs)[1] if tau > 0 else f.P for f in have]

    def fit(U, delay, every=1):
        """(RMSE per rotor, h2 per rotor) of Omega = a (x - h2), x the lagged command `delay` later."""
        xs, ys = [], []
        for f, u, r in zip(have, U, rows):
            r = r[::every]
            xs.append(_delayed_at(u, delay * fs, r))
            ys.append(f.omega[:, r])
        x, y = np.concatenate(xs, axis=1), np.concatenate(ys, axis=1)
        xm, ym = x.mean(axis=1, keepdims=True), y.mean(axis=1, keepdims=True)
        k = np.einsum("mn,mn->m", x - xm, y - ym) / np.maximum(np.einsum("mn,mn->m", x - xm, x - xm), 1e-300)
        e = (y - ym) - k[:, None] * (x - xm)
        return np.sqrt(np.mean(e * e, axis=1)), (xm[:, 0] - ym[:, 0] / np.where(k == 0, np.inf, k))

    # coarse: every lag of the grid with every delay (the lag filtered once, the delay a shift of it)
    best = (math.inf, 0.0, 0.0)
    for tau in TAUS:
        U = lagged(tau)
        for d in DELAYS:
            best = min(best, (float(fit(U, d, step)[0].mean()), float(tau), float(d)))
    _, t0, d0 = best
    # fine: 1 ms steps around it, on every row
    j = int(np.searchsorted(TAUS, t0))
    t_lo, t_hi = TAUS[max(j - 1, 0)], TAUS[min(j + 1, TAUS.size - 1)]
    taus = np.unique(np.concatenate([np.arange(t_lo, t_hi + 1e-9, FINE_S), [t0]]))
    delays = np.arange(max(0.0, d0 - 0.004), min(MAX_TIMING_S, d0 + 0.004) + 1e-9, FINE_S)
    rmse, tau, delay = min((float(fit(U, d)[0].mean()), float(t), float(d))
                           for t in taus for U in [lagged(t)] for d in delays)
    U = lagged(tau)
    _, h2 = fit(U, delay)
    per_motor = []
    for m in range(4):    # each rotor's own lag at the common delay
        errs = [fit(lagged(t), delay)[0][m] for t in taus]
        per_motor.append(float(taus[int(np.argmin(errs))]))
    gains, slope = common_speed_gains(have, U, delay, fs)
    return {"tau": round(tau, 4), "delay": round(delay, 4), "rmse": round(rmse, 2),
            "per_motor_tau": [round(t, 4) for t in per_motor], "h2": round(float(np.median(h2)), 1),
            "h2_spread": round(float(np.std(h2)), 1), "samples": total,
            "speed_gain": [round(float(g), 4) for g in gains], "slope": float(f"{slope:.6g}"),
            "what": "first-order lag and pure delay from the command to the measured rotor speed, "
                    "Omega = a (P - h2) per rotor (eq. 26, 27), fitted on the airborne rows over 0-300 ms "
                    "of each; speed_gain: each rotor's speed against the four's common speed-per-command curve; "
                    "slope: that curve's a (rad/s per P unit)"}


def _delayed_at(u: np.ndarray, samples: float, rows: np.ndarray) -> np.ndarray:
    """`shift(u, samples)[:, rows]` without shifting the whole array (the coarse grid's inner loop)."""
    m = int(math.floor(samples))
    frac = samples - m
    x = u[:, np.maximum(rows - m, 0)]
    return x if frac == 0.0 else (1.0 - frac) * x + frac * u[:, np.maximum(rows - m - 1, 0)]


def common_speed_gains(have, U, delay: float, fs: float) -> tuple[np.ndarray, float]:
    """((4,): each rotor's measured speed against one speed-per-command curve for the four, Omega =
    a (x - h2) with x the timed command (least squares through the common curve, airborne rows); a)."""
    xs, ys = [], []
    for f, u in zip(have, U):
        xs.append(shift(u, delay * fs)[:, f.airborne])
        ys.append(f.omega[:, f.airborne])
    x, y = np.concatenate(xs, axis=1), np.concatenate(ys, axis=1)
    A = np.stack([x.ravel(), np.ones(x.size)], axis=1)
    a, b = np.linalg.lstsq(A, y.ravel(), rcond=None)[0]
    common = a * x + b
    return np.einsum("mn,mn->m", y, common) / np.einsum("mn,mn->m", common, common), float(a)


def timing_agreement(check: dict, gyro: tuple[str, float] | None) -> dict:
    """The timing fitted from the rotor speeds beside the one from the gyro (the chain's timing cause,
    else the best timing candidate): {gyro_cause, gyro_s, speed_s (lag + delay), agree, what}."""
    speed = check["tau"] + check["delay"]
    if gyro is None:
        return {"gyro_cause": None, "gyro_s": None, "speed_s": round(speed, 4), "agree": None,
                "what": "the gyro gave no timing to compare (no timing candidate was judged)"}
    cause, value = gyro
    tol = max(AGREE_S, AGREE_SHARE * max(value, speed))
    agree = abs(value - speed) <= tol
    return {"gyro_cause": cause, "gyro_s": round(value, 4), "speed_s": round(speed, 4), "agree": bool(agree),
            "what": (f"the gyro's {cause} {1e3 * value:.1f} ms against the rotor speeds' lag + delay "
                     f"{1e3 * speed:.1f} ms: {'they agree' if agree else 'they disagree'} (within "
                     f"{1e3 * tol:.1f} ms: {1e3 * AGREE_S:g} ms or {100 * AGREE_SHARE:g} % of the larger)")}


def trim_pattern(layout: Layout) -> np.ndarray:
    """(N, 2): the gains' pattern of a centre of mass off the middle in hover, g_i - 1 = pattern @ (dx, dy).
    In hover (equal thrusts f) rotors with gains g_i give the torques f sum_i r_i (g_i - 1) about the
    thrust centre, a centre of mass at d gives -f N d (N rotors): the pattern linear in the rotors'
    positions r_i that does so is g - 1 = -N R (R^T R)^-1 d."""
    R = np.column_stack([layout.x, layout.y])
    return -R.shape[0] * R @ np.linalg.inv(R.T @ R)


def hover_gains(gains, com, layout: Layout) -> np.ndarray:
    """Each rotor's thrust in hover against the mean of the four: its own gain and the centre of mass's
    trim together (what a base model without a centre of mass would call the rotors' gains)."""
    g = np.asarray(gains, float) * (1.0 + trim_pattern(layout) @ np.asarray(com, float))
    return g / g.mean()


def com_of_gains(gains, layout: Layout) -> tuple[float, float, float]:
    """(dx, dy, share): the centre of mass whose hover trim the gains (mean 1) stand for, in the
    layout's units, and the share of the gains' pattern it explains (least squares on `trim_pattern`)."""
    g = np.asarray(gains, float) - np.mean(gains)
    T = trim_pattern(layout)
    d = np.linalg.lstsq(T, g, rcond=None)[0]
    total = float(g @ g)
    share = float(1.0 - np.sum((g - T @ d) ** 2) / total) if total > 0 else 1.0
    return float(d[0]), float(d[1]), share


def com_of_gains_stderr(gains_sd, layout: Layout) -> tuple[float, float]:
    """(dx, dy): the standard errors of `com_of_gains`'s centre of mass, the gains' standard errors
    `gains_sd` carried through its linear map (d = T^+ (g - mean g), T the `trim_pattern`) as independent:
    a first-order figure (the gains' normalisation to mean 1 and their covariance left out)."""
    T = trim_pattern(layout)
    n = T.shape[0]
    J = np.linalg.pinv(T) @ (np.eye(n) - 1.0 / n)
    sd = np.sqrt((J * J) @ np.square(np.asarray(gains_sd, float)))
    return float(sd[0]), float(sd[1])


def yaw_trim_of_gains(gains, layout: Layout) -> tuple[float, float]:
    """(split, share): how much more thrust (a share of the mean) the counter-clockwise rotors give in hover
    than the clockwise ones, and the share of the gains' pattern it explains. The yaw loop holds a yaw
    torque in hover (a motor mounted tilted, propellers of another drag) by letting one spin direction's
    pair push harder (eq. 6's reaction torques): a pattern of the spins, not of the positions, so no
    centre of mass and no single weak motor."""
    g = np.asarray(gains, float) - np.mean(gains)
    s = np.asarray(layout.spin, float)
    a = float(g @ s / (s @ s))
    total = float(g @ g)
    return 2.0 * a, (a * a * float(s @ s) / total if total > 0 else 0.0)


def rotor_gain_check(gains, gains_sd, layout: Layout, speeds: dict | None, speed_com=None) -> dict:
    """What the pattern of the rotors' thrusts in hover is (`hover_gains`, with their jackknife standard
    errors): {"verdict", "why", "thrust_gain", "speed_thrust_gain", "com"} (com: the centre of mass the pattern,
    or what the speeds leave of it, stands for, with its first-order standard errors, `com_of_gains_stderr`;
    static/centre.py weighs it against the flight's other figures). A weak motor and a centre of
    mass off the middle leave the same pattern in hover; the log's rotor speeds tell them apart: the
    thrust each rotor's speed gives (eq. 27) is its motor's part, the rest of the pattern is the centre
    of mass's (linear in the rotors' positions), a yaw trim's (a pattern of the spins,
    `yaw_trim_of_gains`) or a propeller's. verdict: "none"; "weak motor" (the slowest rotor for its
    command, CURVE_TOL and two standard errors (`speeds["speed_gain_stderr"]` where given) below the
    common curve, whatever its thrust in hover: a centre of mass may hide it there); "centre of
    mass" (what the speeds leave is a front/rear or left/right pattern); "yaw trim"; both; "rotor"
    (what the speeds leave is no centre of mass's pattern: a propeller that gives another thrust at its
    speed); "not told apart" (a pattern, and no rotor speeds in the log). `speed_com`: (dx, dy) of the centre
    of mass the rotor speeds give directly (static.centre.from_speeds), named in place of the one the
    speeds' remainder stands for (the two agree to first order in the pattern)."""
    g = np.asarray(gains, float)
    sd = np.asarray(gains_sd, float)
    unit = "m" if layout.unit == "m" else "arm lengths"
    out = {"thrust_gain": [round(float(v), 4) for v in g], "speed_thrust_gain": None}

    def pattern(r):
        return bool(np.any((np.abs(r - 1.0) > GAIN_TOL) & (np.abs(r - 1.0) > 2.0 * sd)))

    def com(r, r_sd, what):
        """(the centre of mass's share, the yaw trim's share, the words for the larger)."""
        dx, dy, share = com_of_gains(r, layout)
        named = speed_com is not None and r is not g
        if named:
            dx, dy = speed_com
        out["com"] = {"dx": round(dx, 4), "dy": round(dy, 4), "share": round(share, 3), "unit": unit,
                      **({} if named else {"stderr": [float(f"{e:.2g}") for e in com_of_gains_stderr(r_sd, layout)]})}
        split, yaw = yaw_trim_of_gains(r, layout)
        out["yaw_trim"] = {"ccw_minus_cw": round(split, 4), "share": round(yaw, 3)}
        if yaw > share:
            more = "more" if split > 0 else "less"
            return share, yaw, (f"{what} a pattern of the spins: the counter-clockwise rotors give {100 * abs(split):.0f} % "
                                f"{more} thrust than the clockwise ones ({100 * yaw:.0f} % of it), the trim of a yaw "
                                "torque the loop holds (a motor mounted tilted, propellers of another drag), not a "
                                "centre of mass")
        side = "front/rear" if abs(dx) >= abs(dy) else "left/right"
        return share, yaw, (f"{what} a {side} pattern, the hover trim of a centre of mass at ({dx:+.3f}, {dy:+.3f}) "
                            f"{unit} ({100 * share:.0f} % of it)")

    if speeds is None or speeds.get("speed_gain") is None:
        _, yaw, text = com(g, sd, "the thrusts in hover are")
        if not pattern(g):
            out.update(verdict="none", why=f"every rotor's thrust in hover is the mean's within {GAIN_TOL:g} or two "
                                           "of its standard errors")
        else:
            out.update(verdict="not told apart",
                       why=f"{text}; without rotor speeds in the log a weak motor, a centre of mass off the middle and "
                           "a yaw trim look the same in hover")
        return out
    s = np.asarray(speeds["speed_gain"], float)
    q = s * s / np.mean(s * s)                 # the thrust each rotor's speed gives (eq. 27), against the mean
    # its standard error from the speed gains' (dq/ds = 2 s / mean(s^2), the mean's own share left out)
    s_sd = speeds.get("speed_gain_stderr")
    q_sd = np.zeros_like(q) if s_sd is None else 2.0 * s * np.asarray(s_sd, float) / np.mean(s * s)
    out["speed_thrust_gain"] = [round(float(v), 4) for v in q]
    found, why = [], []
    m = int(np.argmin(q))
    # The rule is the speed per command alone, where speeds exist: a centre of mass that moves the weak motor's
    # hover share back to the mean's (its hover gain at 1) leaves it turning slower for its command all the same
    if q[m] < 1.0 - CURVE_TOL and 1.0 - q[m] > 2.0 * q_sd[m]:
        others = float(np.mean(np.delete(q, m)))
        scale, scale_sd = float(q[m] / others), float(q_sd[m] / others)
        found.append("weak motor")
        out["weak_motor"] = {"motor": m + 1, "thrust_scale": round(scale, 4), "stderr": float(f"{scale_sd:.2g}"),
                             "speed_gain": round(float(s[m] / np.mean(np.delete(s, m))), 4),
                             "what": "the thrust its speed gives for its command (eq. 27: the square of its speed "
                                     "against the common speed-per-command curve) against the others'"}
        why.append(f"motor {m + 1} turns slower for its command than the others (its speed per command "
                   f"{out['weak_motor']['speed_gain']:.3f} of theirs: it gives {100 * scale:.1f} +- {100 * scale_sd:.2g} % "
                   f"of their thrust for its command; in hover it gives {100 * (1 - g[m]):+.0f} % less than the mean): "
                   "a weak motor")
    rest = g / q
    rest_sd = rest * np.hypot(sd / g, q_sd / q) / rest.mean()   # first order, the two independent
    rest = rest / rest.mean()
    share, yaw, text = com(rest, rest_sd, "what the speeds leave is")
    if pattern(rest):
        if share >= 0.5:
            found.append("centre of mass")
            why.append(f"{text}: the rotors turn on their speed-per-command curve there, so not a weak motor")
        elif yaw >= 0.5:
            found.append("yaw trim")
            why.append(f"{text}: the rotors turn on their speed-per-command curve there, so not a weak motor")
        else:
            found.append("rotor")
            why.append(f"{text}: not a centre of mass's; a propeller that gives another thrust at its speed")
    if not found:
        out.update(verdict="none", why=f"every rotor's thrust in hover is what its speed gives within {GAIN_TOL:g} or "
                                       f"two of its standard errors, and no rotor is {100 * CURVE_TOL:g} % slow")
    else:
        out.update(verdict=" and ".join(found), why="; ".join(why))
    return out
