"""The hover findings of the static tier, from the motor commands through the thrust curve (`curve`) on
the hover rows (`blocks`), each with its block-jackknife standard error:

- **hover throttle and thrust margin**: the mean command in hover, and the thrust it asks for against
  full thrust, scaled by g over the mean acc_z (the body-z specific force: a vehicle climbing or tilted
  asks for more than its weight); its inverse is the thrust-to-weight ratio at full command. A ratio of
  the blocks' means, never the mean of the rows' ratios: on a vibrating accelerometer that one is
  biased high by var(acc_z) / acc_z^2 and more.
- **each motor's share of the hover thrust** (the motors' mean is 1) and its **drift** over the flight
  (the blocks' shares regressed on their times).
- **what the pattern of the shares is**, worked out from eq. 25's structure on the log's rotor layout:
  in hover the rotors' thrusts balance the weight and hold zero roll, pitch and yaw torque about the
  centre of mass. A centre of mass off the middle asks the rotors nearest it for more thrust in a
  pattern linear in their positions and leaves the yaw balance alone (`trim_pattern`); a yaw torque the
  loop holds (a motor mounted tilted, a propeller of another drag) asks one spin direction's pair for
  more (`yaw_trim_of_gains`); a weak motor (less thrust for its command) gets a higher command for the
  same thrust, alone, which is a part of each pattern in a fixed ratio (its position and its spin).
  Each hypothesis's pattern of the shares (`_hypotheses`) is fitted to them by generalised least squares
  with their jackknife covariance; the one with the fewest parameters that fits (chi-square, P_FIT) is named. A
  quadrotor's four shares have three free numbers, which a centre of mass and a yaw trim together
  always fit: a weak motor is also such a mix, told apart only by its fixed ratio, or by the rotor
  speeds where the log has them (`rotorspeed.rotor_gain_check`: the speed each rotor turns at for its
  command is its motor's part).
"""
from __future__ import annotations

import numpy as np
from scipy import stats

from flightctl.sim.diagnose.data import FileData, Layout
from flightctl.sim.diagnose.rotorspeed import (GAIN_TOL, rotor_gain_check,
                                                        trim_pattern, yaw_trim_of_gains)
from flightctl.sim.diagnose.static.blocks import G, Blocks, drift
from flightctl.sim.diagnose.static.curve import P_FULL, Curve, SpeedCurve

P_FIT = 0.01            # a hypothesis fits when its chi-square's upper tail is at least this
DRIFT_TOL = 0.02        # a share's change over the flight worth naming (and 3 standard errors)
DRIFT_T = 3.0
MIN_DRIFT_SPAN_S = 30.0   # s between the first and last hover block: shorter, a trend is the flight's manoeuvres
MAX_COM = 0.5           # arm lengths: a centre of mass further off leaves too little roll/pitch authority
# A yaw trim is a small thrust difference between the pairs (a rotor's reaction torque is a few % of its
# thrust times the arm): one pair at more than this share above the other is a declared motor order or
# spin that is not the vehicle's, not a trim.
MAX_YAW_SPLIT = 0.3
MIN_WEAK = 0.5          # a motor giving less than half the thrust for its command would not hover


def _num(x, digits=4):
    return round(float(x), digits)


def _gains(share: np.ndarray) -> np.ndarray:
    """The gain a model with equal rotors calls each rotor: the inverse of its share of the hover
    command's thrust, against the motors' mean."""
    g = 1.0 / np.asarray(share, float)
    return g / g.mean()


def throttle(bl: Blocks, c: np.ndarray, P: np.ndarray, acc_z: np.ndarray, curve: Curve) -> dict:
    """Hover throttle and thrust margin (the module's docstring)."""
    m = bl.means(np.vstack([c.mean(axis=0), P.mean(axis=0) / P_FULL, acc_z]))
    # a ratio of means over the blocks, never a mean of the rows' ratios: E[g / acc_z] exceeds g / E[acc_z] by
    # about var(acc_z) / E[acc_z]^2 (Jensen), a factor 1.25-1.9 on an accelerometer shaking by 5 m/s^2 in hover
    ratio = lambda v: np.array([v[0] * G / max(v[2], 0.1 * G), v[1], v[2]])
    (frac, cmd, az), (frac_sd, cmd_sd, az_sd), _ = bl.jackknife(m, ratio)
    ok = 0.0 < frac < 1.0 and abs(az / G - 1.0) < 0.1
    return {"command": _num(cmd), "command_stderr": float(f"{cmd_sd:.2g}"),
            "thrust_share": _num(frac), "thrust_share_stderr": float(f"{frac_sd:.2g}"),
            "thrust_to_weight": _num(1.0 / frac, 3) if frac > 0 else None,
            "thrust_to_weight_stderr": float(f"{frac_sd / frac ** 2:.2g}") if frac > 0 else None,
            "acc_z": _num(az, 3), "curve": curve.source,
            "check": (f"hover needs {100 * frac:.0f} % of full thrust (0-100 %) with the specific force "
                      f"{az:.2f} m/s^2 within 10 % of g: " + ("passed" if ok else "failed")),
            "passed": bool(ok),
            "what": "command: the mean motor command in hover (0-1 of the range); thrust_share: the mean thrust it asks "
                    "for against full thrust through the curve, times g over the mean acc_z (a ratio of means, free of "
                    "the accelerometer's vibration); thrust_to_weight: its inverse"}


def shares(bl: Blocks, c: np.ndarray) -> tuple[dict, np.ndarray, np.ndarray]:
    """Each motor's share of the hover thrust (mean 1) with its standard error and its drift over the
    flight; and (the shares' block means, the gains' leave-one-out values) for the pattern."""
    m = bl.means(c)
    share, sd, _ = bl.jackknife(m, lambda v: v / v.mean())
    per_block = m / m.mean(axis=1, keepdims=True)
    t = bl.times()
    slope, se = drift(t, per_block)
    span = float(t[-1] - t[0])
    named = [i for i in range(m.shape[1]) if abs(slope[i] * span) >= DRIFT_TOL and abs(slope[i]) >= DRIFT_T * se[i]
             and span >= MIN_DRIFT_SPAN_S]
    out = {"share": [_num(v) for v in share], "stderr": [float(f"{e:.2g}") for e in sd],
           "drift_per_min": [_num(60 * v, 5) for v in slope], "drift_stderr_per_min": [float(f"{60 * e:.2g}") for e in se],
           "span_s": round(span, 1), "blocks": bl.n_blocks,
           "drifting": [i + 1 for i in named],
           "check": (f"a share drifts when its change over the {span:.0f} s between the first and last block is at least "
                     f"{100 * DRIFT_TOL:g} % and {DRIFT_T:g} standard errors (regression over the {bl.n_blocks} blocks), over "
                     f"at least {MIN_DRIFT_SPAN_S:g} s"),
           "what": "each motor's share of the hover thrust through the curve (the motors' mean is 1), block "
                   "jackknife standard error; drift: the blocks' shares regressed on time"}
    return out, m, per_block


def _mixer(layout: Layout) -> np.ndarray:
    """(N, 4) the mixer's columns in thrust (eq. 25's structure, as the firmwares mix: AP_MotorsMatrix's
    throttle, roll, pitch and yaw factors, sim/logs/frames.py): 1, y_i, x_i, s_i. The rotors' wrench of
    thrusts f is the same columns' transpose (times the arm and eq. 28's torque ratio), so a vehicle in
    hover with thrusts S c for its commanded thrusts c = A v holds A^T S A v = (W, 0, 0, 0)."""
    return np.column_stack([np.ones(len(layout.x)), layout.y, layout.x, layout.spin])


def weak_shares(layout: Layout, j: int, scale: float) -> np.ndarray:
    """(N,) the commanded thrusts' shares (mean 1) in hover when motor j gives `scale` of the thrust for its
    command (`_mixer`: c = A (A^T S A)^-1 e_1). A quadrotor's mixer is square: motor j's command alone rises,
    by 1 / scale; more rotors than four share the correction as the mixer's columns allow."""
    A = _mixer(layout)
    S = np.ones(A.shape[0])
    S[j] = scale
    c = A @ np.linalg.lstsq(A.T @ (S[:, None] * A), np.eye(4)[0], rcond=None)[0]
    return c / c.mean()


def _weak_pattern(layout: Layout, j: int) -> np.ndarray:
    """(N, 1) the direction of a weak motor j's pattern of the shares (its small-loss limit, `weak_shares`):
    for a quadrotor e_j - 1/N exactly."""
    e = weak_shares(layout, j, 1.0 - 1e-4) - 1.0
    return (e * (1.0 - 1.0 / e.size) / e[j])[:, None]


def _weak_size(layout: Layout, j: int, beta: float) -> tuple[float, float]:
    """(the scale whose `weak_shares` project on `_weak_pattern` as beta, d scale / d beta): the weak motor's
    thrust for its command against the others'. A quadrotor's is (1 - beta / N) / (1 + (N - 1) / N beta)."""
    e = _weak_pattern(layout, j)[:, 0]
    proj = lambda sc: float((weak_shares(layout, j, sc) - 1.0) @ e / (e @ e))
    lo, hi = 0.05, 1.5
    if not proj(hi) <= beta <= proj(lo):
        return (hi if beta < proj(hi) else lo), 0.0
    for _ in range(60):                       # the projection falls as the scale rises: bisection
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if proj(mid) > beta else (lo, mid)
    sc = 0.5 * (lo + hi)
    h = 1e-5
    return sc, 2.0 * h / (proj(sc - h) - proj(sc + h))


def _hypotheses(layout: Layout) -> dict[str, np.ndarray]:
    """name -> (N, k) columns of the pattern of the thrust shares, s - 1, each hypothesis makes (k
    parameters). Exact in the shares: a centre of mass at d asks for sum_i s_i r_i = N d (the torque
    balance about it, eq. 25's roll and pitch rows), the opposite of `trim_pattern`'s gains; a yaw
    trim for a difference of the spins' pairs (eq. 25's yaw row); a weak motor for its own command's
    thrust raised through the mixer (`_weak_pattern`: alone on a quadrotor; the direction exact in the
    small-loss limit, its size a scale, `_weak_size`)."""
    s = np.asarray(layout.spin, float)[:, None]
    out = {"yaw trim": s}
    n = s.shape[0]
    for j in range(n):
        out[f"weak motor {j + 1}"] = _weak_pattern(layout, j)
    out["centre of mass"] = -trim_pattern(layout)
    out["centre of mass and yaw trim"] = np.hstack([-trim_pattern(layout), s])
    return out


def _gls(v: np.ndarray, W: np.ndarray, A: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """(beta, its standard errors, chi-square) of v ~ A beta weighted by W (the covariance's pseudo-inverse)."""
    F = A.T @ W @ A
    beta = np.linalg.lstsq(F, A.T @ W @ v, rcond=None)[0]
    r = v - A @ beta
    return beta, np.sqrt(np.abs(np.diag(np.linalg.pinv(F)))), float(r @ W @ r)


def pattern(bl: Blocks, m: np.ndarray, layout: Layout, speed_gain=None, speed_com: dict | None = None) -> dict:
    """What the pattern of the shares in hover is (the module's docstring); `speed_com`: the centre of mass
    the rotor speeds give (`centre.from_speeds`), the one the rotor speeds' finding names and carries."""
    unit = "m" if layout.unit == "m" else "arm lengths"
    stat = lambda v: v / v.mean()
    share, share_sd, jack = bl.jackknife(m, stat)
    g, g_sd, _ = bl.jackknife(m, lambda v: _gains(v / v.mean()))
    B = bl.n_blocks
    cov = (B - 1) / B * (jack - jack.mean(axis=0)).T @ (jack - jack.mean(axis=0))
    W = np.linalg.pinv(cov, rcond=1e-10)
    v = share - 1.0
    dof_all = int(np.linalg.matrix_rank(cov, tol=1e-12 * max(np.trace(cov), 1e-300)))
    hyp = _hypotheses(layout)
    com = lambda x: np.linalg.lstsq(hyp["centre of mass"], stat(x) - 1.0, rcond=None)[0]
    yaw = lambda x: np.array(yaw_trim_of_gains(stat(x), layout)[:1])    # of the thrust shares: a pattern of the spins
    (dx, dy), com_sd, _ = bl.jackknife(m, com)
    (split,), (split_sd,), _ = bl.jackknife(m, yaw)
    total = float(v @ v)
    com_share = 1.0 - float(np.sum((v - hyp["centre of mass"] @ np.array([dx, dy])) ** 2)) / total if total > 0 else 1.0
    _, yaw_share = yaw_trim_of_gains(share, layout)
    fits = []
    for name, A in hyp.items():
        beta, beta_sd, chi2 = _gls(v, W, A)
        dof = max(dof_all - A.shape[1], 0)
        p = float(stats.chi2.sf(chi2, dof)) if dof > 0 else 1.0
        size = None
        if name.startswith("weak motor"):
            size, slope = _weak_size(layout, int(name.split()[-1]) - 1, float(beta[0]))
            size_sd = beta_sd[0] * abs(slope)
            if not (MIN_WEAK <= size < 1.0):
                p = 0.0                 # a stronger motor, or one too weak to hover: not physical
        fits.append({"hypothesis": name, "parameters": A.shape[1], "chi2": round(chi2, 2), "dof": dof,
                     "p": float(f"{p:.3g}"),
                     **({"thrust_scale": _num(size), "thrust_scale_stderr": float(f"{size_sd:.2g}")} if size is not None
                        else {})})
    none_chi2 = float(v @ W @ v)
    worth = bool(np.any((np.abs(v) > GAIN_TOL) & (np.abs(v) > 2.0 * share_sd)))
    out = {"gains": [_num(x) for x in g], "gains_stderr": [float(f"{e:.2g}") for e in g_sd],
           "com": {"dx": _num(dx), "dy": _num(dy), "stderr": [float(f"{e:.2g}") for e in com_sd], "unit": unit,
                   "share": _num(com_share, 3),
                   "what": "the centre of mass off the thrust centre (x forward, y left) that the shares' front/rear "
                           "and left/right parts balance (sum_i s_i r_i = N d, least squares); share: the part of "
                           "the pattern it explains"},
           "yaw_trim": {"ccw_minus_cw": _num(split), "stderr": float(f"{split_sd:.2g}"), "share": _num(yaw_share, 3),
                        "what": "how much more thrust the counter-clockwise pair gives than the clockwise one in hover"},
           "hypotheses": fits, "chi2_none": round(none_chi2, 2), "dof": dof_all}
    if not worth:
        out.update(verdict="none", why=f"every motor's share in hover is the mean's within {100 * GAIN_TOL:g} % or two "
                                       "of its standard errors")
    else:
        ok = [f for f in fits if f["p"] >= P_FIT and f["dof"] > 0]
        best = min(ok, key=lambda f: (f["parameters"], f["chi2"])) if ok else None
        if best is None:
            out.update(verdict="centre of mass and yaw trim",
                       why="no single cause fits the pattern within its uncertainty (chi-square P < "
                           f"{P_FIT:g} for each): a mix, read as a centre of mass at ({dx:+.3f} +- {com_sd[0]:.2g}, "
                           f"{dy:+.3f} +- {com_sd[1]:.2g}) {unit} and a yaw trim of {100 * split:+.1f} +- "
                           f"{100 * split_sd:.2g} % (counter-clockwise pair over clockwise); a weak motor is "
                           "such a mix too")
        else:
            out["verdict"] = best["hypothesis"]
            if best["hypothesis"] == "centre of mass":
                out["why"] = (f"a front/rear and left/right pattern with no yaw part: a centre of mass at ({dx:+.3f} +- "
                              f"{com_sd[0]:.2g}, {dy:+.3f} +- {com_sd[1]:.2g}) {unit} (chi-square {best['chi2']} on "
                              f"{best['dof']} dof)")
            elif best["hypothesis"] == "yaw trim":
                out["why"] = (f"a pattern of the spins alone: the counter-clockwise pair gives {100 * abs(split):.1f} +- "
                              f"{100 * split_sd:.2g} % {'more' if split > 0 else 'less'} thrust than the clockwise one "
                              f"(a yaw torque the loop holds: a motor mounted tilted, a propeller of another drag; "
                              f"chi-square {best['chi2']} on "
                              f"{best['dof']} dof)")
            elif best["hypothesis"] == "centre of mass and yaw trim":
                out["why"] = (f"a centre of mass at ({dx:+.3f} +- {com_sd[0]:.2g}, {dy:+.3f} +- {com_sd[1]:.2g}) {unit} "
                              f"and a yaw trim of {100 * split:+.1f} +- {100 * split_sd:.2g} % (chi-square {best['chi2']} "
                              f"on {best['dof']} dof)")
            else:
                out["why"] = (f"one motor's command raised (alone on a quadrotor, with the mixer's share of the others "
                              f"on more rotors: its roll, pitch and yaw parts in its position's and spin's ratio): "
                              f"{best['hypothesis']} gives {100 * best['thrust_scale']:.1f} +- "
                              f"{100 * best['thrust_scale_stderr']:.2g} % of the others' thrust for its command "
                              f"(chi-square {best['chi2']} on {best['dof']} dof)")
            alike = [f["hypothesis"] for f in ok if f["parameters"] == best["parameters"] and f is not best]
            if alike:
                out["why"] += "; " + ", ".join(alike) + " fit" + ("s" if len(alike) == 1 else "") + " as well"
        _bounds(out, float(np.hypot(dx, dy)), split, unit)
    if speed_gain is not None:
        check = rotor_gain_check(g, g_sd, layout, {"speed_gain": speed_gain[0], "speed_gain_stderr": speed_gain[1]},
                                 None if speed_com is None else (speed_com["dx"], speed_com["dy"]))
        out["rotor_speeds"] = {"verdict": check["verdict"], "why": check["why"],
                               "speed_thrust_gain": check["speed_thrust_gain"], "speed_gain": speed_gain[0],
                               "speed_gain_stderr": [float(f"{e:.2g}") for e in speed_gain[1]],
                               "weak_motor": check.get("weak_motor"), "com": speed_com}
    else:
        out["rotor_speeds"] = None
        out["without_speeds"] = ("no rotor speeds in the log (ESC telemetry, one per motor): a weak motor is told from a "
                                 "centre of mass or a yaw trim by its pattern's ratio alone; with the speeds, a weak "
                                 "motor turns slower for its command than the others")
    return out


def _bounds(out: dict, com: float, split: float, unit: str) -> None:
    """The verdict "not physical" when a figure it names is beyond its physical bound (MAX_COM, MAX_YAW_SPLIT),
    whether it came from that cause alone or from a mix: each figure's bound is the vehicle's, not the
    hypothesis's."""
    bad = []
    if "centre of mass" in out["verdict"] and com > MAX_COM:
        bad.append(f"the centre of mass {com:.2f} {unit} off the thrust centre, further than {MAX_COM:g} arm lengths "
                   "(too little roll and pitch authority left to fly)")
    if "yaw trim" in out["verdict"] and abs(split) > MAX_YAW_SPLIT:
        bad.append(f"the spin pairs {100 * abs(split):.0f} % of thrust apart, more than a trim's {100 * MAX_YAW_SPLIT:g} % "
                   "(a motor order or spin the log declares that is not the vehicle's?)")
    if bad:
        out["why"] += ": not physical: " + "; ".join(bad)
        out["verdict"] = "not physical"


def speed_gains(files: list[FileData], bl: Blocks, line: SpeedCurve | None) -> tuple[list[float], list[float]] | None:
    """(each rotor's measured speed in hover against the rotors' common speed-per-command line `line`
    (`curve.speed_curve`, the flight's), its block jackknife standard error), or None without speeds. Per
    rotor, least squares through the line over the hover rows (no timing: hover is steady)."""
    if line is None:
        return None
    num, den = [], []
    for f, m in zip(files, bl.masks):
        if not m.any():
            continue
        if f.omega is None:
            return None
        ok = np.isfinite(f.omega[:, m]).all(axis=0)      # rows without the four speeds add nothing
        c = np.where(ok, line.speed(f.P[:, m]), 0.0)
        num.append(np.where(ok, f.omega[:, m], 0.0) * c)
        den.append(c * c)
    num, den = np.concatenate(num, axis=1), np.concatenate(den, axis=1)
    sums = np.vstack([bl.means(num) * np.bincount(bl.index, minlength=bl.n_blocks)[:, None],
                      bl.means(den) * np.bincount(bl.index, minlength=bl.n_blocks)[:, None]])
    B, n = bl.n_blocks, num.shape[0]
    full = sums[:B].sum(axis=0) / sums[B:].sum(axis=0)
    keep = ~np.eye(B, dtype=bool)
    jack = np.array([sums[:B][k].sum(axis=0) / sums[B:][k].sum(axis=0) for k in keep])
    sd = np.sqrt((B - 1) / B * ((jack - jack.mean(axis=0)) ** 2).sum(axis=0))
    return [float(v) for v in full[:n]], [float(v) for v in sd[:n]]
