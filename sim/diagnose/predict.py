"""The prediction, checked (docs/steps.md, "Predicted and measured"): the base model identified on one part
of a flight (`basemodel.identify`, diagnose's own) flying the firmware's controller as the log gives it
(sim/logs/controller.py; PX4's, ArduPilot's, INAV's and flightctl's attitude loop and mix in loops.py, whose
terms the closed loop below takes: target and error low-passes, FF, D on the raw gyro, the attitude loop's
angle) predicts each axis's step response of the loop it closes; it is set beside the step measured
(steps.py) on the rest of the flight, which the identification did not see, or on another log of the same
vehicle flown with other gains (`cross`).

The loop, per axis, on s = j 2 pi f and z = exp(s T) at the firmware's loop period T: the controller's and
the filters' difference equations, the vehicle's rate as the loop samples it (the command held over a
period, integrated: omega[n + 1] = omega[n] + b T u[n] behind the delay):

    vehicle   omega = G u,  G = b exp(-s tau) T z^-1 / (1 - z^-1)
              b: the base model linearised at the flight's median command Pm (basemodel.py's channels,
              p_dot = k_p sum_i g_i y_i (P_i - h2)^2, and likewise q_dot, r_dot):
              b = 2 R k_axis sum_i g_i c_i m_i (Pm - h2), c_i the model's lever (y_i, -x_i, -s_i of the
              identified layout), m_i the mixer's coefficient of the rotor (Betaflight's quad X,
              src/main/flight/mixer.c:74-78 of v3.1.5: +-1, the declared layout's y_i / max|y|, -x_i / max|x|,
              -s_i), R the motor range in P units a full share moves (mixer.c:526: motorOutputMin +
              motorOutputRange (mix + throttle); the reader's P = 255 (motor - min) / (max - min): R = 255);
              tau the commands' timing the identification found (basemodel.py `_timing`)
    gyro      y_f = F_g omega, F_g the firmware's gyro low-pass (the reader's chain, dataset.sensor_filters)
    PID       u = (Kp Fp + Ki T / (1 - z^-1)) (r - y_f) + Kd Fd (1 - z^-1) / T (c r - y_f)
              (Betaflight 3.1.5 flight/pid.c:245-289: P and I on the error, D on c r - y with c =
              dtermSetpointWeight / 100 (pid.c:163, 272-276), Fd its D low-pass, biquad by default
              (fc/config.c:169; the header does not log its type), on roll and pitch only: no D on yaw
              (pid.c:262-264), whose P goes through a pt1 at yaw_lpf_hz (pid.c:143-150, 249-250)); Betaflight
              from 3.2 takes D on the measurement only (c = 0) and its feed-forward is not converted: named
    closed    omega / r = G Cr / (1 + G Cy F_g), the logged response F_g omega where the log's gyro column
              is the filtered one (its `# gyro_filter:`), else omega.

The predicted step is `steps.band_step` of that response on the measured one's window and band: the
same roll-off, so the two are alike in what the band can show. Not modelled (named in each entry):
TPA (the gains' cut above tpa_breakpoint), the battery compensation of the mix, the motors' and the
mix's saturation, the acceleration limits, feed-forward.

Agreement, per axis: `step_error`, the RMS of predicted less measured over the response (0 to its length)
over the measured final value; and for the delay, the rise and the overshoot the predicted value against
the measured one's spread over its windows (10th-90th percentiles): outside it by more than the spread's
width is a disagreement. What it points to (`_points_to`, POINTS_TO): delay and rise both slower or both
faster by SCALE, a time scale: the effectiveness; else a delay off: the timing; else an overshoot off:
the damping. `agrees`: step_error under AGREE_ERROR and none of the three off.
"""
from __future__ import annotations

import math

import numpy as np

from flightctl.errors import InputError
from flightctl.logfile import Table
from flightctl.safety import CRASH_TILT, first_tilt_past
from flightctl.sim.diagnose import loops, steps
from flightctl.sim.diagnose.basemodel import YAW_UNKNOWN, identify, yaw_identified
from flightctl.sim.diagnose.data import load_file, parse_filters
from flightctl.sim.diagnose.dataset import DYNAMIC_MIN_HZ, LOWPASS_HZ, sensor_filters
from flightctl.sim.diagnose.rotorspeed import rotor_speed_lag
from flightctl.sim.logs.bbfields import version

SPLIT = 0.5                 # identified on the rows before this share of the log's time, checked on the rest
P_RANGE = 255.0             # P units a full share of the mixer moves (mixer.c:526; the reader's P scale)
AGREE_ERROR = 0.15          # step_error under this: the prediction follows the measured step
SCALE = 1.5                 # delay and rise both off by this factor the same way: a time scale (_points_to)
POINTS_TO = {"rise_s": "the effectiveness (the gain from the commands to the angular acceleration, k_axis and h2)",
             "delay_s": "the timing (the commands' delay tau, the filters)",
             "overshoot": "the damping (the D term and its filters, the timing against the gains)"}
AXIS_INDEX = {"x": 0, "y": 1, "z": 2}
CRASH_MARGIN_S = 0.5        # s: a log that ends in a crash is taken to this long before its tilt passes the limit


def _rows(table: Table, keep: np.ndarray, tag: str) -> Table:
    return Table(f"{table.path} ({tag})", {k: v[keep] for k, v in table.columns.items()}, dict(table.meta),
                 None if table.lines is None else table.lines[keep])


def halves(table: Table, split: float = SPLIT) -> tuple[Table, Table, float]:
    """(the rows before `split` of the log's time, the rows from it, that time in s)."""
    t = table["t"]
    cut = float(t[0] + split * (t[-1] - t[0]))
    return (_rows(table, t < cut, f"to {cut:.1f} s"), _rows(table, t >= cut, f"from {cut:.1f} s"), cut)


def before_crash(table: Table, margin_s: float = CRASH_MARGIN_S) -> tuple[Table, float | None]:
    """The rows before a crash that ends the log: (the rows more than `margin_s` before the logged attitude
    first tilts past the crash limit (flightctl.safety.CRASH_TILT, roll or pitch), the time of that tilt), or
    (the table, None) where it never does. A log whose last row is tilted past half the limit ended over, not
    landed (flightctl's loop stops at the limit before it logs the row past it; a firmware's log ends at its
    disarm): its crash is that last row. The rows of the fall are no flight of the loop the log's gains
    close; those before it are, an unstable loop's growing swing included."""
    if "roll" not in table or "pitch" not in table or len(table["t"]) == 0:
        return table, None
    first = first_tilt_past(table["roll"], table["pitch"])
    if first is None and first_tilt_past(table["roll"][-1:], table["pitch"][-1:], 0.5 * CRASH_TILT) is not None:
        first = len(table["t"]) - 1
    if first is None:
        return table, None
    t_c = float(table["t"][first])
    return _rows(table, table["t"] < t_c - margin_s, f"to {t_c - margin_s:.1f} s, before its crash"), t_c


def base_model(table: Table, a, progress=lambda *_: None):
    """The base model diagnose identifies (`basemodel.identify`) from `table`'s rows, or why not."""
    try:
        rate = float(table.meta.get("motor_rate_hz", "inf"))
        if rate < DYNAMIC_MIN_HZ:
            return f"the motor outputs logged at {rate:.1f} Hz: the base model's timing needs {DYNAMIC_MIN_HZ:g} Hz"
        files = [load_file(table, a)]
        vehicle, _ = identify(files, LOWPASS_HZ, progress, rotor_speed_lag(files))
    except InputError as e:
        return f"no base model from {table.path}: {str(e).split(': ', 1)[-1]}"
    return vehicle, files[0].layout


def _stages(chain: str, fs: float) -> list:
    def fail(what):
        raise InputError(f"# gyro_filter: {what}")
    return sensor_filters(parse_filters(chain, fail), fs)


def _freq(stages, z1: np.ndarray) -> np.ndarray:
    """The response of (b, a) stages at z^-1 = z1."""
    H = np.ones_like(z1)
    for b, a in stages:
        H = H * np.polyval(list(b)[::-1], z1) / np.polyval(list(a)[::-1], z1)
    return H


def _pt1(hz: float, fs: float):
    """Betaflight's pt1 (common/filter.c: k = dT / (RC + dT), RC = 1 / (2 pi f))."""
    k = (1.0 / fs) / (1.0 / (2.0 * math.pi * hz) + 1.0 / fs)
    return [k, 0.0], [1.0, -(1.0 - k)]


def effectiveness(vehicle, declared, axis: str, parts: dict | None = None) -> float:
    """b (rad/s^2 per unit of the controller's output) of one axis: the module's linearisation, with the
    firmware's mix m and range R (loops.py) where `parts` gives them, else Betaflight's."""
    idn = vehicle.identification
    lay = vehicle.layout
    k = idn[{"x": "k_p", "y": "k_q", "z": "k_r"}[axis]]["value"]
    lever = {"x": np.array(lay.y), "y": -np.array(lay.x), "z": -np.array(lay.spin, float)}[axis]
    pm, h2 = idn["median_P"]["value"], idn["h2"]["value"]
    parts = parts or {}
    mix = np.array(parts["mix"]) if "mix" in parts else loops.bf_mix(declared, axis)
    R = parts.get("R", P_RANGE)
    R = R(pm) if callable(R) else R
    factor = ((idn.get("loop_fit") or {}).get("axes", {}).get(axis) or {}).get("factor", 1.0)   # loopfit.py
    return float(2.0 * R * k * factor * np.sum(np.array(vehicle.gains) * lever * mix) * (pm - h2))


def timing(vehicle) -> tuple[float, float]:
    """(delay, motor lag) in s of the loop: the loop fit's (loopfit.py) where it has one, else the base
    model's pure delay (basemodel.py `_timing`) and no lag."""
    fitted = (vehicle.identification.get("loop_fit") or {}).get("timing")
    if fitted:
        return fitted["delay_s"], fitted["lag_s"]
    return float(vehicle.identification["timing"]["value"]), 0.0


def chains(parts: dict, meta: dict) -> tuple[str, str]:
    """(the gyro filter chain inside the loop, the chain of the logged gyro): the firmware's own loop chain where
    loop_parts gives it (loops.py: PX4's and ArduPilot's LowPassFilter2p), else the log's header."""
    return (parts.get("gyro_loop_chain") or meta.get("gyro_loop_filter", meta.get("gyro_filter", "none")),
            meta.get("gyro_filter", "none"))


def loop_parts(ctrl: dict, meta: dict, axis: str, declared=None) -> tuple[dict | None, list[str]]:
    """The controller of one axis as the loop takes it (gains, filters, c), and what is not modelled; None and
    the reason when the log's controller cannot be closed. Other firmwares than Betaflight: loops.py."""
    fw = ctrl.get("firmware")
    g = ctrl.get("axes", {}).get(axis, {})
    if fw != "betaflight":
        return loops.parts(ctrl, meta, axis, declared)
    if any(g.get(k, {}).get("value") is None for k in ("kp", "ki", "kd")):
        return None, ["the controller's gains are not in physical units (controller.unread): the loop cannot be closed"]
    loop = (ctrl.get("loop_hz") or {}).get("value")
    if not loop:
        return None, ["the loop rate is not in the log's header"]
    ver = version(meta.get("firmware", ""))
    old = ver < (3, 2, 0)
    flt = ctrl.get("filters", {})
    hz = lambda k: (flt.get(k) or {}).get("value") or 0.0
    c = (ctrl.get("d_setpoint_weight") or {}).get("value") if old else 0.0
    missing = ["TPA", "the battery compensation of the mix", "the mix's saturation", "the acceleration limits"]
    if not old:
        missing.append("feed-forward (its unit not converted)")
    if c is None:
        c = 0.0
        missing.append("the D term's setpoint weight (not in the header: D on the gyro alone taken)")
    parts = {"kp": g["kp"]["value"], "ki": g["ki"]["value"], "kd": g["kd"]["value"], "c": float(c), "loop_hz": float(loop),
             "d_lowpass_hz": hz("dterm_lowpass_hz"), "p_lowpass_hz": 0.0}
    if axis == "z" and old:
        parts.update(kd=0.0, p_lowpass_hz=hz("yaw_lowpass_hz"))
    if parts["d_lowpass_hz"] and not (axis == "z" and old):
        missing.append("the D low-pass's type (taken as biquad, 3.1's default, fc/config.c:169: the header's "
                       "enumeration, where it has one, is not read)")
    return parts, missing


def motor_lag(lag_s: float, T: float, z1: np.ndarray) -> np.ndarray | float:
    """The motors' first-order lag of time constant `lag_s` on the command, once per loop period T:
    m[n] = a m[n - 1] + (1 - a) u[n], a = exp(-T / lag_s) (the exact step of tau_m m' = u - m over a period,
    taken at its end: half a period early against the lag held over it, 0.5 ms at 1 kHz); 1 without one."""
    if not lag_s > 0:
        return 1.0
    a = math.exp(-T / lag_s)
    return (1.0 - a) / (1.0 - a * z1)


def loop_terms(f: np.ndarray, tau: float, parts: dict, loop_chain: str, response_chain: str) -> dict:
    """The module's loop at the frequencies f (Hz), per unit effectiveness and per unit gain, linear in the
    gains: the vehicle's `G` (b = 1), the response's filter `Fr`, and the controller u = Cr r - Cy omega with
    Cr = kp rP + ki rI + kd rD + kf rF and Cy = kp yP + ki yI + kd yD. The rate loop: FF kf Ft r, and P, I,
    D on Fe (Ft r - y) (D on c Ft r - y_d, y_d the gyro the D term takes: the loop's filtered one, or the raw
    one through its own low-pass); the attitude loop (flightctl's) on the estimator's angle A Fg omega with its
    D on the filtered rate. The open loop is b G Cy; `closed_loop` closes it."""
    fs = parts["loop_hz"]
    T = 1.0 / fs
    s = 2j * np.pi * np.maximum(f, 1e-6)
    z1 = np.exp(-s * T)
    A = T * z1 / (1.0 - z1)                  # the command held a period and integrated
    Fg = _freq(_stages(loop_chain, fs), z1)
    Fr = _freq(_stages(response_chain, fs), z1)
    one = np.ones_like(z1)
    lp = lambda key, kind="pt1": (_freq(sensor_filters(((parts.get("d_filter", "biquad") if key == "d_lowpass_hz" else kind,
                                                         parts[key]),), fs), z1) if parts.get(key) else one)
    Fp = _freq([_pt1(parts["p_lowpass_hz"], fs)], z1) if parts.get("p_lowpass_hz") else one
    I = T / (1.0 - z1)
    if parts.get("loop") == "attitude":
        return {"G": np.exp(-s * tau) * motor_lag(parts.get("motor_lag_s", 0.0), T, z1) * A, "Fr": Fr * A,
                "rP": Fp, "rI": I, "rD": 0.0 * one, "rF": 0.0 * one,
                "yP": Fp * Fg * A, "yI": I * Fg * A, "yD": lp("tau_rate_hz") * Fg}
    D = lp("d_lowpass_hz") * (1.0 - z1) / T
    Ft, Fe = lp("target_lowpass_hz"), lp("error_lowpass_hz")
    return {"G": np.exp(-s * tau) * motor_lag(parts.get("motor_lag_s", 0.0), T, z1) * A, "Fr": Fr, "rP": Fe * Ft * Fp, "rI": Fe * Ft * I,
            "rD": parts["c"] * Fe * Ft * D, "rF": Ft, "yP": Fe * Fp * Fg, "yI": Fe * I * Fg,
            "yD": Fe * D * (one if parts.get("d_on_raw_gyro") else Fg)}


def controller(t: dict, kp, ki, kd, kf=0.0):
    """The loop's controller from `loop_terms` at these gains (scalars, or arrays broadcast over the
    frequencies): the setpoint's path Cr and the response's path Cy."""
    return (kp * t["rP"] + ki * t["rI"] + kd * t["rD"] + kf * t["rF"],
            kp * t["yP"] + ki * t["yI"] + kd * t["yD"])


def closed_loop(f: np.ndarray, b: float, tau: float, parts: dict, loop_chain: str, response_chain: str) -> np.ndarray:
    """The loop's response from the setpoint to the logged response at the frequencies f (Hz): the module's loop."""
    t = loop_terms(f, tau, parts, loop_chain, response_chain)
    Cr, Cy = controller(t, parts["kp"], parts["ki"], parts["kd"], parts.get("kf", 0.0))
    G = b * t["G"]
    H = t["Fr"] * G * Cr / (1.0 + G * Cy)
    H[f == 0] = 1.0 if parts["ki"] or parts.get("loop") == "attitude" else H[1]
    return H


def compare(r: steps.Response, H_of, measured: dict) -> tuple[dict, np.ndarray]:
    """The predicted step on the measured response's window and band beside the measured one: (the entry,
    the predicted curve)."""
    f = np.fft.rfftfreq(r.n_seg, 1.0 / r.fs)
    n_pre = int(np.sum(r.t < 0))
    n_resp = r.t.size - n_pre
    H = H_of(f)
    pred = steps.band_step(H, f, r.band_hz, r.n_seg, n_pre, n_resp)
    own = steps.metrics(r.t, steps.band_step(H, f, 0.5 * f[-1], r.n_seg, n_pre, n_resp))
    m = steps.metrics(r.t, pred)
    after = r.t >= 0
    final = measured["final"]
    err = float(np.sqrt(np.mean((pred[after] - r.step[after]) ** 2)) / abs(final))
    excess, out = {}, {}
    for k in ("delay_s", "rise_s", "overshoot"):
        mv, (lo, hi) = measured[k]["value"], measured[k]["spread"]
        pv = m[k]
        d = {"predicted": steps._num(pv), "measured": mv, "spread": [lo, hi],
             "difference": None if mv is None or not math.isfinite(pv) else steps._num(pv - mv)}
        if None not in (mv, lo, hi) and math.isfinite(pv):
            width = max(hi - lo, 1e-9)
            x = (lo - pv if pv < lo else pv - hi if pv > hi else 0.0) / width
            d["outside_spread"] = steps._num(x, 2)
            excess[k] = x
        out[k] = d
    worst = _points_to(out, excess)
    entry = {"step_error": steps._num(err, 3), "final": steps._num(m["final"], 3), "band_hz": steps._num(r.band_hz, 3), **out,
             "model_full_band": {k: steps._num(own[k]) for k in ("delay_s", "rise_s", "overshoot")},
             "agrees": bool(err < AGREE_ERROR and worst is None)}
    if worst is not None:
        w = out[worst]
        entry["points_to"] = (f"{worst[:-2] if worst.endswith('_s') else worst} predicted {w['predicted']:.4g} against "
                              f"{w['measured']:.4g} measured ({w['spread'][0]:.4g}-{w['spread'][1]:.4g} over the windows): "
                              + POINTS_TO[worst])
    else:
        entry["points_to"] = None
    return entry, pred


def _points_to(out: dict, excess: dict) -> str | None:
    """Which part of the model a disagreement points to: a prediction slower (or faster) in both its delay and
    its rise by more than SCALE is a time scale, the effectiveness; else a delay outside its spread by more
    than its width, the timing; else such an overshoot, the damping; None when all three agree."""
    ratio = {}
    for k in ("delay_s", "rise_s"):
        p, m = out[k]["predicted"], out[k]["measured"]
        ratio[k] = p / m if p is not None and m else 1.0
    if (excess.get("delay_s", 0) > 1 or excess.get("rise_s", 0) > 1) and (
            min(ratio.values()) > SCALE or max(ratio.values()) < 1.0 / SCALE):
        return "rise_s"
    for k in ("delay_s", "overshoot", "rise_s"):
        if excess.get(k, 0.0) > 1.0:
            return k
    return None


def loop_of(ctrl: dict) -> str:
    """The loop a log's controller closes around the rate: flightctl's the attitude (eq. 24), the others the rate."""
    return "attitude" if ctrl.get("firmware") == "flightctl" else "rate"


def predict(model, ctrl: dict, checked: Table, identified_on: str, checked_on: str) -> tuple[dict, dict]:
    """Each axis's predicted step of the loop the controller closes (`loop_of`) beside the one `checked`
    measures: (per axis the entry or why not, per axis (measured Response, predicted curve) for the figure)."""
    measured, curves = steps.measure(checked)
    loop = loop_of(ctrl)
    rate = measured.get(loop, {})
    out, drawn = {}, {}
    for axis in steps.AXES:
        head = {"identified_on": identified_on, "checked_on": checked_on}
        if isinstance(model, str):
            out[axis] = {**head, "why": model}
            continue
        vehicle, declared = model
        e = rate.get(axis, rate)
        if "why" in e:
            out[axis] = {**head, "why": f"no measured step on the rows checked: {e['why']}"}
            continue
        if axis == "z" and not yaw_identified(vehicle):
            out[axis] = {**head, "why": f"{YAW_UNKNOWN} (basemodel.py): no yaw loop to close"}
            continue
        parts, missing = loop_parts(ctrl, checked.meta, axis, declared)
        if parts is None:
            out[axis] = {**head, "why": missing[0]}
            continue
        b = effectiveness(vehicle, declared, axis, parts)
        if not b > 0:
            out[axis] = {**head, "why": f"the model's effectiveness through the logged mix is {b:.3g}, not positive: the "
                                        "mix's signs and the identified layout's disagree on this axis, no loop to close"}
            continue
        tau, lag = timing(vehicle)
        parts = {**parts, "motor_lag_s": lag}
        loop_chain, response_chain = chains(parts, checked.meta)
        entry, pred = compare(curves[(loop, axis)], lambda f: closed_loop(f, b, tau, parts, loop_chain, response_chain), e)
        shown = {k: (round(v(vehicle.identification["median_P"]["value"]), 6) if callable(v) else v) for k, v in parts.items()}
        fitted = ((vehicle.identification.get("loop_fit") or {}).get("axes") or {}).get(axis, {})
        if entry["points_to"] and "why" in fitted:
            entry["points_to"] += f"; its b is the base model's direct fit, biased toward zero (loopfit.py): {fitted['why']}"
        out[axis] = {**head, **entry, "effectiveness": {"value": round(b, 2), "unit": "rad/s^2 per unit of the controller's output",
                                                        "direct": fitted.get("b_direct"), "closed_loop_factor": fitted.get("factor"),
                                                        "source": "the loop fit (loopfit.py)" if "factor" in fitted else
                                                        "the base model's direct fit (basemodel.py)"
                                                        + (f": {fitted['why']}" if "why" in fitted else "")},
                     "timing_s": tau, "motor_lag_s": lag, "controller": shown, "not_modelled": missing}
        drawn[axis] = (curves[(loop, axis)], pred)
    return out, drawn


def held_out(table: Table, ctrl: dict, a, progress=lambda *_: None) -> tuple[dict, dict]:
    """The prediction on one log: identified on its first SPLIT of time, checked on the rest."""
    return held_out_model(table, ctrl, a, progress)[1:]


def held_out_model(table: Table, ctrl: dict, a, progress=lambda *_: None) -> tuple:
    """`held_out` with the model it checked: (the model or why not, per axis the entry, the curves)."""
    first, second, cut = halves(table)
    model = _model(first, ctrl, table.meta, a, progress, first, ctrl)
    return (model, *predict(model, ctrl, second, f"{table.path} before {cut:.1f} s", f"{table.path} from {cut:.1f} s"))


def cross(identify_on: Table, check: Table, ctrl: dict, a, progress=lambda *_: None) -> tuple[dict, dict]:
    """Identified on one log, the other's steps predicted with its own controller `ctrl` (a series of one
    vehicle flown with different gains)."""
    return cross_model(identify_on, check, ctrl, a, progress)[1:]


def cross_model(identify_on: Table, check: Table, ctrl: dict, a, progress=lambda *_: None) -> tuple:
    """`cross` with the model it checked: (the model or why not, per axis the entry, the curves)."""
    from flightctl.sim.logs import controller as logged
    model = _model(identify_on, ctrl, check.meta, a, progress, identify_on, logged.of_table(identify_on))
    return (model, *predict(model, ctrl, check, identify_on.path, check.path))


def _model(table: Table, ctrl: dict, meta: dict, a, progress, fit_on: Table, fit_ctrl: dict):
    """The base model of `table` with its loop fit on `fit_on` flown with `fit_ctrl` (loopfit.py), or, before any
    identification, why the checked log's controller cannot be closed."""
    from flightctl.sim.diagnose import loopfit
    parts, why = loop_parts(ctrl, meta, "x")
    if parts is None:
        return why[0]
    model = base_model(table, a, progress)
    if not isinstance(model, str) and loop_parts(fit_ctrl, fit_on.meta, "x")[0] is not None:
        loopfit.attach_fit(model, fit_on, fit_ctrl)
    return model


def attach(reports: list[dict], curves: list, tables: list[Table], controllers: list[dict], a, progress) -> None:
    """Each log's rate axes with a measured step get `predicted` (`held_out`) in the report's `steps`; the
    figure's curves get ("predicted", axis): (the held-out measured Response, the predicted step)."""
    for rep, (_, c), table, ctrl in zip(reports, curves, tables, controllers):
        rate = rep.get(loop_of(ctrl), {})
        if "why" in rate or not any("why" not in rate.get(x, {"why": ""}) for x in steps.AXES):
            continue
        out, drawn = held_out(table, ctrl, a, lambda m: progress(f"step prediction, its first half: {m}"))
        for axis in steps.AXES:
            if axis in rate and "why" not in rate[axis]:
                rate[axis]["predicted"] = out[axis]
        c.update({("predicted", axis): v for axis, v in drawn.items()})
