"""A base model from the flight itself, for a vehicle that is not the paper's (docs/real-flights.md).

The structure is the paper's: each rotor's thrust follows eq. 26's form, f_i = h1 (P_i - h2)^2 with
one curve for the four rotors; the thrusts act through the rotor layout the log declares (eq. 25's
structure: roll torque sum y_i f_i, pitch -sum x_i f_i, yaw -sum s_i g1 f_i by eq. 28 with g2 = 0)
on eq. 7 with its inertia coupling and eq. 6's yaw drag. Mass, inertia, arm length, h1 and g1 are
not known, so what is identified is each channel's effectiveness per unit of them:

    acc_z = k_z sum_i (P_i - h2)^2                  k_z = h1 / M
    p_dot = k_p sum_i y_i (P_i - h2)^2 + a_p q r     k_p = h1 l / Jxx   (y_i in arm lengths)
    q_dot = -k_q sum_i x_i (P_i - h2)^2 + a_q p r    k_q = h1 l / Jyy
    r_dot = -k_r sum_i s_i (P_i - h2)^2 + a_r p q - gamma r |r|     k_r = h1 g1 / Jzz, gamma = gamma1 / Jzz

and one offset per accelerometer channel. Eq. 7's coupling a_p = (Jyy - Jzz) / Jxx, a_q = (Jzz - Jxx)
/ Jyy, a_r = (Jxx - Jyy) / Jzz is not fitted: in steady flight q r, p r and p q hardly move, and a fit
lets them stand in for whatever else the base model lacks (on the indiflight logs they came out of
the physical range [-1, 1] with the wrong signs). A quadrotor is nearly flat, so the perpendicular-axis
theorem, Jzz = Jxx + Jyy (the paper's Table 2 meets it within 4 %), gives a_p = -1, a_q = +1 and,
with Jxx / Jyy = k_q / k_p for rotors at the declared positions, a_r = (k_q - k_p) / (k_q + k_p). Expanded, (P -
h2)^2 = P^2 - 2 h2 P + h2^2, every channel is linear in its
coefficients on P^2 and P (the constant cancels in the torques of a symmetric layout and joins the
accelerometer's offset in acc_z): one weighted least-squares fit (`scoring.solve`), and h2 from the
thrust channel, h2 = -c_1 / (2 c_2). The result is an equivalent airframe (M = 1 kg, Jzz = 1 kg m^2,
arm lengths in units of the arm, h1 = k_z, Jxx = k_z / k_p, Jyy = k_z / k_q, g1 = k_r / k_z,
gamma1 = gamma, c1 = k_z so that a rotor's speed is P - h2 in command units, Jp = 0): the candidates'
parameters come out per unit mass and inertia. Every score refits each channel's coefficients on
its drive's thrust and speed parts (so the curve's scale and shape per channel) on the training blocks
of each fold (`DataSet.base_free`): the base model is identified on training data only, except for
gamma. Yaw rates large enough to show eq. 6's drag come in short bursts (a throw, a fast turn), so a
gamma fitted without the block that holds them is noise and, extrapolated to it, ruins its
prediction (on the indiflight logs a hover-only fit gave 25/rad against 0.3/rad, and 250 rad/s^2 of
error in the held-out recovery): it is fitted once, with the curves, on all the data. Uncertainties: the
delete-one-block jackknife over the scoring's blocks, which
respects the residual's correlation in time.
"""
from __future__ import annotations


import numpy as np

from flightctl.errors import InputError
from flightctl.params import Airframe
from flightctl.physics import G, thrust_from_command
from flightctl.sim.diagnose import axischeck
from flightctl.sim.diagnose.data import BARO_CLIMB_M, FileData, Layout
from flightctl.sim.diagnose.dataset import C, N_BLOCKS, THRUST_CHANNELS, DataSet, Vehicle
from flightctl.sim.diagnose.rotorspeed import hover_gains
from flightctl.sim.diagnose.scoring import linear_stats, reparametrized, solve

H2_LOW = -1000.0   # P units: far below the idle, the curve is nearly linear in P over the flight
# The timings at which the base model may be identified (`_timing`): the candidates' 0-300 ms. A pure
# delay aligns the commands with the motion as well as a lag of the same total for this purpose.
TIMING_DELAYS = np.concatenate([np.arange(0.0, 0.1, 0.005), np.arange(0.1, 0.3001, 0.01)])     # s
# A base model for causes: each axis' effectiveness at least T_BASE jackknife standard errors above zero
# (8 blocks: t with 7 degrees of freedom, one-sided 4 %). A log scrambled on purpose gives a negative
# effectiveness or one within a standard error of zero on the axis it scrambles (t below 1.1 in
# tests/sim/diagnose/test_diagnose_real_hidden.py); the INDIflight throws, whose blocks hold a throw and a hover, give
# 2.3-2.9 on pitch and 3 needlessly refused three of six.
T_BASE = 2.0
# An axis whose effectiveness is not significant: do the rotors drive it at all? Each rotor's thrust fitted
# freely on that channel alone (four coefficients, no layout): the t of the fit in the direction the data
# prefer (its length over the jackknife error of its projection). With no drive it is the length of a
# four-dimensional normal vector, about chi with 4 degrees of freedom: above T_FREE in 1.6 % of logs. Above
# it, the rotors drive the axis and the declared layout does not say how: a contradiction; below it, this
# log does not show the axis (docs/real-flights.md). A motor order scrambled on purpose leaves the free fit
# as it was (it is the same four columns): 4.0-11 on the axes it scrambles in LOG00230 and LOG00037;
# btfl_all.bbl #12's pitch, which its 3.7 s of flight hardly move, 0.4.
T_FREE = 3.5
# The smallest yaw effectiveness of a quadrotor against its roll and pitch effectiveness (arm lengths):
# k_r / k_p = (g1 / l) (Jxx / Jzz), Jxx / Jzz >= 1/2 for a flat vehicle (Jzz <= Jxx + Jyy), and g1 / l
# = (C_P / C_T) (D / l) / (2 pi), the rotor's torque per thrust over the arm: C_P / C_T >= 0.3 for
# propellers at rest and a rotor diameter D at least half the arm give 0.024; the paper's airframe
# has g1 / (2 l) = 0.040 (conventions.md). Taken at 0.01 (docs/real-flights.md).
YAW_RATIO_MIN = 0.01
YAW_UNKNOWN = "the yaw effectiveness is not identified from this log"
NO_THRUST = ("the thrust's effectiveness is not answered: the log has no accelerometer (k_z = 1 is a unit, "
             "not a measurement: the torques' effectiveness is per unit of it)")
NAMES = ("k_p", "k_q", "k_r", "k_z", "gamma")
UNITS = ("rad/s^2 per P^2 (arm)", "rad/s^2 per P^2 (arm)", "rad/s^2 per P^2", "m/s^2 per P^2", "1/rad")
WHAT = ("h1 l / Jxx: roll", "h1 l / Jyy: pitch", "h1 g1 / Jzz: yaw", "h1 / M: specific force",
        "gamma1 / Jzz: eq. 6's yaw drag")


class LayoutContradicted(InputError):
    """The log's data contradict its declared rotor layout, signs or scaling: the log is refused whole
    (docs/measured-data.md), the static tier too, whose motor shares are read through the same layout."""


def equivalent(h2: float, theta=None) -> Airframe:
    """The equivalent airframe of the coefficients `theta` (NAMES order); unit effectiveness and
    h2 = 0 without them (the identification's own predictions: drive P^2 and P)."""
    if theta is None:
        return Airframe(M=1.0, l=1.0, Jxx=1.0, Jyy=1.0, Jzz=1.0, Jp=0.0, gamma1=0.0, gamma2=0.0, h1=1.0,
                        h2=h2, c1=1.0, g1=1.0, g2=0.0, g=G)
    k_p, k_q, k_r, k_z, gamma = theta
    return Airframe(M=1.0, l=1.0, Jxx=k_z / k_p, Jyy=k_z / k_q, Jzz=1.0, Jp=0.0, gamma1=gamma, gamma2=0.0,
                    h1=k_z, h2=h2, c1=k_z, g1=k_r / k_z, g2=0.0, g=G)


def identify(files: list[FileData], lowpass_hz: float, progress, speeds: dict | None = None,
             slow: str | None = None) -> tuple[Vehicle, list[str]]:
    """The base model of a vehicle that is not the paper's, from its flights (module docstring):
    (the identified Vehicle with its report, notes). `slow`: why the motor commands were logged too
    slowly to time (then the base model is identified at zero timing), else None: identified at the
    commands' timing the flight prefers (`_timing`). A base model the data contradict or do not show
    (`_refuse`) raises InputError."""
    layout: Layout = files[0].layout
    notes = []
    if any(f.layout != layout for f in files[1:]):
        notes.append("the logs declare different rotor layouts: the first one's is used")
    ds = identification_set(files, lowpass_hz)
    drag = yaw_drag_column(ds)
    allb = np.ones(N_BLOCKS, bool)

    def jackknife_sd(jack):
        return np.sqrt((N_BLOCKS - 1) / N_BLOCKS * ((jack - jack.mean(axis=0)) ** 2).sum(axis=0))

    delay = _timing(ds, drag) if slow is None else 0.0
    Ps = delayed_commands(ds, delay)
    if delay > 0:
        progress(f"base model: identified at the timing the flight prefers, delay {1e3 * delay:.0f} ms")

    # one curve for the four rotors: h2 by a bounded scalar search (below every command in flight, where
    # the curve is zero), the effectiveness of each channel on it by least squares
    P_air = np.concatenate([f.P[:, f.airborne] for f in files], axis=1)
    hi = float(P_air.min()) - 1.0

    # (P - h2)^2 = P^2 - 2 h2 P + h2^2 (every airborne P is above h2): the channels of the three parts,
    # filtered once; the block statistics of each thrust channel's three, and of the yaw drag, give
    # the fit at any h2 without another pass over the data (`reparametrized`)
    parts = [ds.flat_filtered([ds.predict_file(i, ds.drive(P ** k)).unit[0] for i, P in enumerate(Ps)])
             for k in (2, 1, 0)]
    cols = []
    for c in THRUST_CHANNELS:
        for part in parts:
            x = np.zeros((C, ds.n))
            x[c] = part[c]
            cols.append(x)
    st_parts = linear_stats(ds, ds.measured, np.stack(cols + [drag], axis=-1))
    del cols

    def at(h2):
        """The columns' map: each thrust channel's (P - h2)^2 from its three parts, the drag as is."""
        M = np.zeros((3 * len(THRUST_CHANNELS) + 1, len(THRUST_CHANNELS) + 1))
        for j in range(len(THRUST_CHANNELS)):
            M[3 * j:3 * j + 3, j] = (1.0, -2.0 * h2, h2 * h2)
        M[-1, -1] = 1.0
        return M

    def best_h2(keep):
        from scipy import optimize
        obj = lambda h: solve(reparametrized(st_parts, at(h)), keep, ds.block_counts)[0]
        grid = np.concatenate([np.linspace(H2_LOW, -100.0, 4), np.linspace(-100.0, hi, 12)])
        j = int(np.argmin([obj(h) for h in grid]))
        lo, up = grid[max(j - 1, 0)], grid[min(j + 1, grid.size - 1)]
        return float(optimize.minimize_scalar(obj, bounds=(lo, up), method="bounded", options={"xatol": 0.1}).x)

    at_bound = False
    if speeds is not None and speeds["h2"] < hi:
        # the rotors' measured speeds give the curve's zero directly (rotorspeed.py): Omega = a (P - h2)
        h2, h2_sd, h2_source = speeds["h2"], speeds["h2_spread"], "the log's measured rotor speeds"
    else:
        h2 = best_h2(allb)
        h2_sd = float(jackknife_sd(np.array([best_h2(np.arange(N_BLOCKS) != b) for b in range(N_BLOCKS)])))
        h2_source = "the flight's thrust and torques (one curve for the four rotors)"
        at_bound = h2 <= H2_LOW + 1.0 or h2 >= hi - 0.5
        if at_bound:
            notes.append(f"h2 = {h2:.1f} is at the end of its range: this flight does not show the curve's shape "
                         "(every fit refines it: the speed part of the drive is a free column)")
    # each channel's effectiveness a_c and each rotor's gain g_i: channel c = a_c sum_i g_i X_ci
    st = linear_stats(ds, ds.measured, _rotor_columns(ds, Ps, h2, drag))
    theta, gains, com = _effectiveness(st, allb, ds.block_counts)
    jack = [_effectiveness(st, np.arange(N_BLOCKS) != b, ds.block_counts) for b in range(N_BLOCKS)]
    sd = np.concatenate([[h2_sd], jackknife_sd(np.array([j[0] for j in jack]))])
    gains_sd = jackknife_sd(np.array([j[1] for j in jack]))
    com_sd = jackknife_sd(np.array([j[2] for j in jack]))
    accel = any(f.accel for f in files)
    progress(f"base model identified from the flight: h2 = {h2:.1f}, "
             + ", ".join(f"{n} = {v:.4g} +- {e:.2g}" if accel or n != "k_z" else "k_z not measured (no accelerometer)"
                         for n, v, e in zip(NAMES, theta, sd[1:])))
    free_t = {c: _free_t(st, c, ds.block_counts, jackknife_sd) for c in (0, 1, 5)}
    thrust_source = "the motor commands, f = h1 (P - h2)^2 (eq. 26)"
    measured = thrust_from_speeds(ds, speeds, jackknife_sd) if accel else None
    if not accel:
        # no accelerometer: the specific force is not measured, so neither is h1 / M; the equivalent
        # airframe is taken per unit of it (k_z = 1), which scales no torque channel (Jxx = k_z / k_p ...)
        theta[3], sd[4] = 1.0, 0.0
        thrust_source = NO_THRUST
    elif measured is not None:
        theta[3], sd[4] = measured
        thrust_source = (f"the log's rotor speeds, f = c1 Omega^2 (eq. 27): acc_z on the sum of the squared speeds, "
                         f"times the speed-per-command slope squared ({speeds['slope']:.4g} rad/s per P unit)")
        progress(f"base model: the thrust effectiveness from the rotor speeds, k_z = {theta[3]:.4g} +- {sd[4]:.2g}")
    layout, more = _refuse(files, layout, theta, sd[1:], free_t, _shown(ds, slow), accel)
    notes += more
    hover = hover_gains(gains, com, layout)
    hover_sd = jackknife_sd(np.array([hover_gains(j[1], j[2], layout) for j in jack]))
    report_com = {"dx": round(float(com[0]), 4), "dy": round(float(com[1]), 4),
                  "stderr": [float(f"{e:.2g}") for e in com_sd], "unit": "arm lengths",
                  "what": "the centre of mass off the thrust centre (x forward, y left): the rotors' torques "
                          "are taken about it (each rotor at (x_i - dx, y_i - dy))"}
    layout = Layout(tuple(x - com[0] for x in layout.x), tuple(y - com[1] for y in layout.y), layout.spin,
                    layout.unit, layout.source + f"; centre of mass at ({com[0]:+.3f}, {com[1]:+.3f}) arm lengths "
                                                 "from the data")
    k_p, k_q, k_r, k_z = theta[:4]
    report = {"h2": {"value": float(f"{h2:.5g}"), "stderr": float(f"{sd[0]:.2g}"), "unit": "P units",
                     "at_bound": bool(at_bound),
                     "what": f"eq. 26: the thrust is zero at P = h2 (from {h2_source})"
                             + (f"; at_bound: h2 sits at the end of its range ({H2_LOW:g} to {hi:.1f}), the bound of "
                                "the search and not a value the flight shows (its curve's shape is not in the data)"
                                if at_bound else "")}}
    report.update({name: {"value": float(f"{v:.5g}"), "stderr": float(f"{e:.2g}"), "unit": u, "what": w}
                   for name, v, e, u, w in zip(NAMES, theta, sd[1:], UNITS, WHAT)})
    report["k_z"]["source"] = thrust_source
    if not accel:
        report["k_z"]["unanswered"] = True
    report["rotor_gain"] = {"value": [round(float(g), 4) for g in gains],
                            "stderr": [float(f"{e:.2g}") for e in gains_sd], "unit": "-",
                            "what": "each rotor's thrust and torque against the mean of the four (eq. 7's "
                                    "effectiveness of each rotor), the centre of mass apart"}
    report["com"] = report_com
    report["hover_gain"] = {"value": [round(float(g), 4) for g in hover], "stderr": [float(f"{e:.2g}") for e in hover_sd],
                            "unit": "-", "what": "each rotor's thrust in hover against the mean of the four: its gain "
                                                 "and the centre of mass's trim together (rotor_gain_check)"}
    report["median_P"] = {"value": round(float(np.median(P_air)), 1), "unit": "P units",
                          "what": "the median command in flight (the accelerometer's bias hides the thrust's level)"}
    report["layout"] = {"x": list(layout.x), "y": list(layout.y), "spin": list(layout.spin), "unit": layout.unit,
                        "source": layout.source}
    report["timing"] = {"kind": "delay", "value": round(float(delay), 4), "unit": "s",
                        "what": "the commands' timing (a pure delay) at which the base model "
                                "was identified: the one the flight prefers on a 0-300 ms grid. The base model "
                                "itself has none: the timing is judged as a cause"}
    report["notes"] = more
    coupling = (-1.0, 1.0, float((k_q - k_p) / (k_q + k_p)))
    report["coupling"] = {"value": list(coupling), "what": "eq. 7's a_p, a_q, a_r of a flat vehicle, Jzz = Jxx + Jyy"}
    return Vehicle(equivalent(h2, theta), layout, coupling, identified=True, identification=report,
                   gains=tuple(float(g) for g in gains)), notes


def identification_set(files: list[FileData], lowpass_hz: float) -> DataSet:
    """The data set the base model is identified on: the log's layout, unit effectiveness, no coupling."""
    return DataSet(files, Vehicle(equivalent(0.0), files[0].layout, (0.0, 0.0, 0.0), identified=True), lowpass_hz)


def yaw_drag_column(ds: DataSet) -> np.ndarray:
    """Eq. 6 on r_dot, -r |r| per unit gamma, filtered as the data are (C, n)."""
    drag = []
    for w in ds.wmid:
        x = np.zeros((C, w.shape[1]))
        x[2] = -w[2] * np.abs(w[2])
        drag.append(x)
    return ds.flat_filtered(drag)


def thrust_from_speeds(ds: DataSet, speeds: dict | None, jackknife_sd) -> tuple[float, float] | None:
    """(k_z, its jackknife standard error) from the log's own rotor speeds, or None when a log has none on
    its airborne rows. Each rotor's thrust is c1 Omega^2 (eq. 27): acc_z = (c1 / M) sum_i Omega_i^2 and an
    offset, the sum low-passed and sensed as the data are (row k: the speeds with the accelerometer's
    sample k + 1), fitted by the same weighted least squares on the blocks; with Omega = a (P - h2)
    (`rotorspeed.rotor_speed_lag`'s common slope a) it is k_z = (c1 / M) a^2 per P^2. The speeds measure
    the thrust where the commands only ask for it: a small quad's punch-outs shake the commands' fit
    (its rotor lags, its ESC's curve) but not this one."""
    if speeds is None or not speeds.get("slope", 0) > 0:
        return None
    per_file = []
    for f in ds.files:
        if f.omega is None or not np.isfinite(f.omega[:, f.airborne]).all():
            return None
        x = np.zeros((C, f.t.size))
        x[5, :-1] = (np.nan_to_num(f.omega[:, 1:]) ** 2).sum(axis=0)
        per_file.append(x)
    st = linear_stats(ds, ds.measured, ds.flat_filtered(per_file)[..., None])
    fit = lambda keep: float(solve(st, keep, ds.block_counts)[1][0])
    a2 = float(speeds["slope"]) ** 2
    jack = np.array([fit(np.arange(N_BLOCKS) != b) for b in range(N_BLOCKS)])
    return fit(np.ones(N_BLOCKS, bool)) * a2, float(jackknife_sd(jack)) * a2


AXES = (("roll", 0, 0), ("pitch", 1, 1), ("thrust", 3, 5))      # (axis, its index in NAMES, its channel)


def _refuse(files: list[FileData], layout: Layout, theta: np.ndarray, sd: np.ndarray, free_t: dict,
            shown: str, accel: bool = True) -> tuple[Layout, list[str]]:
    """The base model is a base for causes only if the data confirm the log's layout, signs and scaling:
    the effectiveness of roll, pitch and thrust (`theta`: NAMES order, `sd` their jackknife standard
    errors) positive and at least T_BASE standard errors from zero. Otherwise InputError, saying which:
    an effectiveness below zero by T_BASE standard errors, or one the rotors drive freely (`free_t`
    above T_FREE: `_free_t`) but not through the declared layout, contradicts the layout, signs or
    scaling; one neither shows is not identified by this log, for the reason `shown` gives (`_shown`).
    Yaw: a log may not say which way its rotors turn (Betaflight's props in or out), so an effectiveness
    below zero by 2 standard errors reverses the declared spins (the layout is mirrored in spin, which
    only flips the sign of the yaw column; `theta` is changed in place). One that is then not significant
    is refused only if the log could have shown the smallest yaw effectiveness a quadrotor of this roll
    and pitch effectiveness has (YAW_RATIO_MIN, docs/real-flights.md): a log without yaw manoeuvres
    cannot tell, and its yaw channel is then not a base for the causes that act on yaw. Without an
    accelerometer (`accel` False) the thrust is not asked: it is named as unanswered (NO_THRUST).
    Returns (the layout, notes)."""
    paths = ", ".join(f.path for f in files)
    contradicted, unshown = [], []
    notes = [] if accel else [NO_THRUST]
    for axis, k, c in AXES:
        if axis == "thrust" and not accel:
            continue
        v, e = theta[k], sd[k]
        if v >= T_BASE * e and v > 0:
            continue
        if v <= -T_BASE * e:
            contradicted.append(f"{axis} effectiveness {v:.3g} +- {e:.2g} (negative: t = {v / e:.1f})")
        elif free_t[c] >= T_FREE:
            contradicted.append(f"{axis} effectiveness {v:.3g} +- {e:.2g} (t = {v / e:.1f}) where the rotors, "
                                f"each fitted freely, drive {axis} with t = {free_t[c]:.1f}")
        else:
            unshown.append((axis, v, e, free_t[c]))
    k_r, k_r_sd = theta[2], sd[2]
    if k_r < -2.0 * k_r_sd:
        layout = Layout(layout.x, layout.y, tuple(-s for s in layout.spin), layout.unit,
                        layout.source + "; spins reversed: the yaw data say so")
        theta[2] = k_r = -k_r
        notes.append(f"the yaw effectiveness had the sign opposite to the declared spin directions "
                     f"({-k_r:.3g} +- {k_r_sd:.2g}): the rotors spin the other way, and are taken so")
    if not k_r >= T_BASE * k_r_sd:
        k_min = YAW_RATIO_MIN * 0.5 * (abs(theta[0]) + abs(theta[1]))
        if k_r_sd < k_min / T_BASE and not unshown:
            contradicted.append(f"yaw effectiveness {k_r:.3g} +- {k_r_sd:.2g} (t = {k_r / k_r_sd:.1f}) where a "
                                f"quadrotor of this roll and pitch effectiveness has at least {k_min:.2g}")
        elif k_r_sd < k_min / T_BASE:
            unshown.append(("yaw", k_r, k_r_sd, float("nan")))
        else:
            notes.append(f"{YAW_UNKNOWN} ({k_r:.3g} +- {k_r_sd:.2g}; the yaw data could not show even the smallest "
                         f"yaw effectiveness a quadrotor of this roll and pitch effectiveness has, {k_min:.2g})")
    if contradicted:
        names = [w.split(" ", 1)[0] for w in contradicted]
        check = axischeck.said(files, names)
        raise LayoutContradicted(f"{paths}: the log's layout, signs or scaling contradict its data on "
                                 f"{' and '.join(names)}: {'; '.join(contradicted)}" + (f"; {check}" if check else "")
                                 + "; no base model for causes")
    if unshown:
        axes = " and ".join(a for a, *_ in unshown)
        what = ", ".join(f"{a} t = {v / e:.1f}" for a, v, e, _ in unshown)
        check = axischeck.said(files, [a for a, *_ in unshown])
        raise InputError(f"{paths}: this log does not identify the vehicle's {axes} effectiveness ({what}; "
                         f"{T_BASE:g} needed, and the rotors fitted freely do not drive it either"
                         + (f"; {check}" if check else "") + f"): {shown}; no base model for causes")
    return layout, notes


def _free_t(st, c: int, counts, jackknife_sd) -> float:
    """The t of each rotor's thrust fitted freely on channel c (`_rotor_columns`' four columns of that
    channel, no layout): the fit's length over the jackknife error of its projection on its own
    direction (T_FREE)."""
    j = THRUST_CHANNELS.index(c)
    M = np.zeros((25, 4))
    M[4 * j:4 * j + 4] = np.eye(4)
    sub = reparametrized(st, M)
    b = solve(sub, np.ones(N_BLOCKS, bool), counts)[1]
    norm = float(np.linalg.norm(b))
    if norm == 0:
        return 0.0
    u = b / norm
    proj = np.array([solve(sub, np.arange(N_BLOCKS) != k, counts)[1] @ u for k in range(N_BLOCKS)])
    err = float(jackknife_sd(proj))
    return norm / err if err > 0 else float("inf")


def _shown(ds: DataSet, slow: str | None) -> str:
    """Why a log may not show an axis, in its own numbers: the motor commands logged too slowly (`slow`),
    else how much flight it holds and how much the rotors moved each axis in it (each axis' rotor
    thrust difference, low-passed as the data are, in % of the total thrust: its standard deviation).
    A barometer that never rose BARO_CLIMB_M while the motors ran adds that the vehicle may not have flown."""
    climbs = [f.baro_climb for f in ds.files if f.baro_climb is not None]
    ground = (f"; and its barometer rose at most {max(climbs):.2f} m while the motors ran: the vehicle may never "
              f"have left the ground" if climbs and len(climbs) == len(ds.files) and max(climbs) < BARO_CLIMB_M
              else "")
    if slow is not None:
        return slow + ground
    F = [thrust_from_command(f.P, 1.0, 0.0) for f in ds.files]
    lay = ds.vehicle.layout
    x, y = np.asarray(lay.x)[:, None], np.asarray(lay.y)[:, None]
    total = ds.flat_filtered([Fi.sum(axis=0) for Fi in F])
    level = float(np.mean(total))
    moved = {"roll": ds.flat_filtered([(y * Fi).sum(axis=0) for Fi in F]),
             "pitch": ds.flat_filtered([(-x * Fi).sum(axis=0) for Fi in F]), "thrust": total}
    spread = ", ".join(f"{a} {100.0 * float(np.std(v)) / level:.2g} %" for a, v in moved.items())
    return (f"too little of it in the flight: {ds.seconds:.1f} s in the air, in which the rotors' thrust "
            f"differences moved {spread} of the total thrust (standard deviation)" + ground)


def yaw_identified(vehicle: Vehicle) -> bool:
    """Whether the base model of an identified vehicle knows its yaw effectiveness (`_refuse`)."""
    return not any(YAW_UNKNOWN in n for n in vehicle.identification.get("notes", ()))


def delayed_commands(ds: DataSet, delay: float) -> list[np.ndarray]:
    """Each file's commands (4, n) through a pure delay of `delay` s (the candidate's own:
    `actuation_delay.shift`)."""
    from flightctl.sim.causes.actuation_delay import shift
    if delay <= 0:
        return [f.P for f in ds.files]
    return [shift(f.P, delay * ds.fs) for f in ds.files]


def _timing(ds: DataSet, drag: np.ndarray) -> float:
    """The delay (s) of the commands at which a free curve per channel (`timing_objective`) best predicts
    the flight, over TIMING_DELAYS (0-300 ms). A vehicle whose motors lag 150 ms shows almost nothing of its
    effectiveness to a model without it: identified at zero timing, its gains and signs would be noise."""
    _, delay = min((timing_objective(ds, drag, d), float(d)) for d in TIMING_DELAYS)
    return delay


def timing_objective(ds: DataSet, drag: np.ndarray, delay: float, lag: float = 0.0) -> float:
    """The fit's objective (sum_c log RSS_c, `scoring.solve`) of a free curve per channel (each thrust
    channel linear in the timed P^2 and P, a trim on each angular channel, the yaw drag `drag`) on the
    commands through a pure delay `delay` (s) and, if `lag` > 0, a first-order lag of `lag` s (the motor's,
    `motor_lag.lag_held`, averaged over each period). scripts/timing_lag.py asks whether a flight prefers a
    lag and a short delay to a long delay."""
    from flightctl.sim.causes.motor_lag import lag_held
    Ps = delayed_commands(ds, delay)
    if lag > 0:
        Ps = [lag_held(P, lag, ds.fs)[1] for P in Ps]
    U = ds.flat_filtered([ds.predict_file(i, ds.drive(P * P, P)).unit for i, P in enumerate(Ps)])
    cols = []
    for c in THRUST_CHANNELS:
        for k in range(3 if c < 3 else 2):     # an angular channel's trim too (the rotor gains' part)
            x = np.zeros((C, ds.n))
            x[c] = U[k, c] if k < 2 else 1.0
            cols.append(x)
    st = linear_stats(ds, ds.measured, np.stack(cols + [drag], axis=-1))
    return solve(st, np.ones(N_BLOCKS, bool), ds.block_counts)[0]


def _rotor_columns(ds: DataSet, Ps, h2: float, drag: np.ndarray) -> np.ndarray:
    """(C, n, 25): each rotor's unit thrust (from the commands Ps, per file) on each thrust channel (16
    columns, channel-major: its torques through the layout and its thrust), each rotor's thrust on the
    roll and on the pitch channel (8: the torque of the thrust about a centre of mass off the thrust
    centre), and the yaw drag."""
    cols, trim = [], []
    F = [thrust_from_command(P, 1.0, h2) for P in Ps]
    per_rotor = []
    for m in range(4):
        Fm = [np.where(np.arange(4)[:, None] == m, x, 0.0) for x in F]
        per_rotor.append(ds.flat_filtered([ds.predict_file(i, ds.drive(Fm[i])).unit[0] for i in range(len(Ps))]))
        rows = []
        for x in F:
            y = np.zeros((C, x.shape[1]))
            y[0] = y[1] = x[m]
            rows.append(y)
        trim.append(ds.flat_filtered(rows))
    for c in THRUST_CHANNELS:
        for m in range(4):
            x = np.zeros((C, ds.n))
            x[c] = per_rotor[m][c]
            cols.append(x)
    for c in (0, 1):
        for m in range(4):
            x = np.zeros((C, ds.n))
            x[c] = trim[m][c]
            cols.append(x)
    return np.stack(cols + [drag], axis=-1)


def _effectiveness(st, keep, counts, passes: int = 12) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """((k_p, k_q, k_r, k_z, gamma), the rotors' gains with mean 1, the centre of mass (dx, dy) in arm
    lengths) of channel c = a_c sum_i g_i X_ci (+ gamma on r_dot), the roll and pitch channels with the
    torque of the thrust about the centre of mass: roll + a_p (-dy) sum_i g_i f_i, pitch + a_q dx sum_i
    g_i f_i (each rotor at (x_i - dx, y_i - dy) from it). A centre of mass off the middle is not a
    pattern of rotor gains: a rotor's gain changes its thrust in every channel (the specific force, the
    yaw torque), the centre of mass only the roll and pitch torques. Bilinear, fitted by alternating
    least squares on the block statistics of the 25 columns of `_rotor_columns`, each step a linear fit
    through `reparametrized`."""
    g = np.ones(4)
    for _ in range(passes):
        M = np.zeros((25, 7))     # the columns' coefficients from (a_p, a_q, a_r, a_z, b_p, b_q, gamma)
        for c in range(4):
            M[4 * c:4 * c + 4, c] = g
        M[16:20, 4] = g
        M[20:24, 5] = g
        M[24, 6] = 1.0
        a = solve(reparametrized(st, M), keep, counts)[1]
        M = np.zeros((25, 5))     # ... from (g_1..g_4, gamma)
        for c in range(4):
            M[4 * c:4 * c + 4, :4] = a[c] * np.eye(4)
        M[16:20, :4] = a[4] * np.eye(4)
        M[20:24, :4] = a[5] * np.eye(4)
        M[24, 4] = 1.0
        th = solve(reparametrized(st, M), keep, counts)[1]
        g = th[:4] / th[:4].mean()
    k = a[:4] * th[:4].mean()
    com = np.array([a[5] / a[1] if a[1] else 0.0, -a[4] / a[0] if a[0] else 0.0])
    return np.concatenate([k, [th[4]]]), g, com
