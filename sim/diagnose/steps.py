"""The measured step response of a flight log, per loop and axis: setpoint to response, by the
averaged cross-spectrum over overlapping Hann windows (docs/steps.md).

What it follows, written anew (none of their code):
- PX4 flight_review, app/plot_app/rate_response.py (`estimate_response`, BSD-3): the H1 estimate, the
  averaged cross-spectrum over the averaged setpoint spectrum, over half-overlapping Hann windows whose
  setpoint varies (its MIN_SETPOINT_STD, 5 deg/s), trusted up to where the coherence (smoothed over 5
  bins) first drops below 0.6 (its MIN_COHERENCE) and rolled off above it by a raised cosine; the step is
  the running sum of the impulse response; each window's own estimate is regularised toward the average
  where that window has little setpoint power (its WINDOW_REGULARIZATION, 0.02 of the window's peak);
  delay the time to 50 % of the final value (the mean over the last 40 %), rise 10-90 %, overshoot.
- Plasmatree PID-Analyzer (README: a 0.5 s response from windows of about 1.5 s, Hann windowed) and
  PIDtoolbox's PTstepcalc.m (2 s segments, a 500 ms response, segments below 20 deg/s of setpoint
  masked out): the response length and the window length of the rate loops.

Loops: the rate loop where the log has a rate setpoint (`setpoint_x/y/z`: Betaflight setpoint[], INAV
axisRate[], PX4 vehicle_rates_setpoint, ArduPilot RATE or PIDR/PIDP/PIDY's Tar; sim/logs) against the gyro; the attitude loop
where it has an attitude setpoint (`roll_sp`, `pitch_sp`, `yaw_sp`: this project's own logs, ArduPilot
ATT's DesRoll/DesPitch/DesYaw) against the logged attitude. Only rows where all four motors run are used.
Every number is SI (s, a share); the figure converts to ms at its edge.
"""
from __future__ import annotations

import math
import textwrap
from dataclasses import dataclass

import numpy as np

from flightctl.logfile import Table
from flightctl.sim.diagnose.data import all_running

DEG = math.pi / 180.0
SEGMENT_S = 2.0              # PTstepcalc.m's 2 s segments; flight_review's SEGMENT_S
SEGMENT_PER_RESPONSE = 2.5   # flight_review: a window at least 2.5 times the response shown
MIN_COHERENCE = 0.6          # flight_review's MIN_COHERENCE
COHERENCE_SMOOTH = 5         # bins the coherence is averaged over before the gate
WINDOW_REGULARIZATION = 0.02
MIN_WINDOWS = 3              # windows with input needed for a response and its spread
# The roll-off above the coherent band is zero-phase: it spreads the impulse response by about 1 / band to
# both sides, so the step is computed from PRE_SHARE of the response's length before the setpoint's step:
# its mass before zero is kept (the final value stays the low frequencies' gain) and the 50 % crossing, which
# a symmetric spread does not move, stays the delay. The rise is widened by the same spread: the fastest
# 10-90 % rise a band B can show is about RISE_BANDWIDTH / B (a first-order lag's 0.35 / f_3dB).
# A rise within BAND_LIMITED times that fastest one is the band's, not the loop's: an upper bound, and the
# delay beside it uncertain by about half of it (`limited_by_band`).
PRE_SHARE = 0.2
RISE_BANDWIDTH = 0.35
BAND_LIMITED = 1.25
FINAL_SHARE = 0.4            # the final value: the mean over the last 40 % of the response
MIN_FINAL = 0.5              # a response reaching less of its setpoint in its length is no step of that loop
SETTLE_BAND = 0.05           # settled: within 5 % of the final value from then on
SPREAD = (10.0, 90.0)        # the spread over the windows: their 10th and 90th percentiles
GAP_PERIODS = 3.0            # a window across a logging gap longer than this many periods is not used
# A window is in the air when all four motors run on at least this share of its rows: in a flip or a
# punch-out a motor touches its idle for a few rows, and those windows are the ones with the input
AIR_SHARE = 0.9
AXES = ("x", "y", "z")
NAMES = {"x": "roll", "y": "pitch", "z": "yaw"}


@dataclass(frozen=True)
class Loop:
    """One loop a log can show: its setpoint and response columns, the response's length (s), the
    setpoint variation a window needs (std, in the setpoint's SI unit), and the slowest rows and setpoint
    samples it needs (the setpoint's own rate: the log's `# KEY:` line, sim/logs/common.py, else the rows')."""
    name: str
    setpoint: tuple[str, str, str]
    response: tuple[str, str, str]
    response_s: float
    min_std: float
    unit: str
    min_rate_hz: float
    rate_key: str
    response_rate_key: str | None
    min_band_hz: float           # a response coherent only below this shows no step of the loop


# The rate loop: PID-Analyzer's 0.5 s response, flight_review's 5 deg/s; its setpoint sampled at 40 Hz at
# least (a rate loop's rise is tens of ms: PX4 logs vehicle_rates_setpoint at 50 Hz, ArduPilot RATE at 10).
# The attitude loop: a slower loop around it (its rise a few hundred ms), its setpoint at 8 Hz at least
# (ArduPilot's ATT at 10 Hz), a step of a degree.
LOOPS = (Loop("rate", ("setpoint_x", "setpoint_y", "setpoint_z"), ("gyro_x", "gyro_y", "gyro_z"),
              0.5, 5.0 * DEG, "rad/s", 40.0, "setpoint_rate_hz", None, 5.0),
         Loop("attitude", ("roll_sp", "pitch_sp", "yaw_sp"), ("roll", "pitch", "yaw"),
              1.5, 1.0 * DEG, "rad", 8.0, "attitude_sp_rate_hz", "attitude_rate_hz", 2.0))

# What each firmware logs the rate setpoint as, for a log that has none
RATE_SETPOINT = {"betaflight blackbox": "Betaflight's setpoint[] (blackbox fields, on by default)",
                 "inav blackbox": "INAV's axisRate[] (blackbox fields)",
                 "px4 ulog": "PX4's vehicle_rates_setpoint (the logger's default topics; SDLOG_PROFILE)",
                 "ardupilot dataflash": "ArduPilot's RATE message (LOG_BITMASK's ATTITUDE_FAST bit), or PIDR/PIDP/PIDY "
                                        "at the loop's rate (its PID bit)"}
SNAP = {"roll": "snap rolls", "pitch": "flips", "yaw": "quick yaw spins"}
FLY = {"rate": "stick inputs on {axis}: sharp moves back and forth and {snap}, held for a fraction of "
               "a second each, for 20 s or more in the air",
       "attitude": "steps of the {axis} setpoint (angle mode, or a plan's steps) of several degrees, for 20 s "
                   "or more in the air"}


def _col(table: Table, name: str) -> np.ndarray | None:
    if name not in table:
        return None
    x = table[name]
    return x if np.isfinite(x).any() else None


def metrics(t: np.ndarray, step: np.ndarray) -> dict[str, float]:
    """Delay (to 50 % of the final value), rise (10 % to 90 %), overshoot (a share of the final value),
    settling (the time after which it stays within SETTLE_BAND of it) and the final value (the mean over
    the last FINAL_SHARE of the response) of a step response sampled at t (s). NaN where the step never
    reaches a level (flight_review's metrics, with settling added)."""
    final = float(step[t >= (1.0 - FINAL_SHARE) * t[-1]].mean())    # t[-1]: the response's length
    out = {"final": final, "delay_s": math.nan, "rise_s": math.nan, "overshoot": math.nan, "settling_s": math.nan}
    if not final > 0.1:
        return out

    def crossing(level):
        k = np.flatnonzero(step >= level * final)
        if k.size == 0:
            return math.nan
        k = int(k[0])
        if k == 0:
            return float(t[0])
        a, b = step[k - 1], step[k]          # linear between the samples either side
        return float(t[k - 1] + (t[k] - t[k - 1]) * (level * final - a) / (b - a))

    out["delay_s"] = crossing(0.5)
    out["rise_s"] = crossing(0.9) - crossing(0.1)
    out["overshoot"] = max(0.0, float(step.max() - final) / final)
    outside = np.flatnonzero(np.abs(step - final) > SETTLE_BAND * abs(final))
    out["settling_s"] = float(t[outside[-1] + 1]) if outside.size and outside[-1] + 1 < t.size else (
        float(t[0]) if not outside.size else math.nan)
    return out


@dataclass
class Response:
    """The measured response of one axis: the step of the averaged estimate, each window's, and the gate's figures."""
    t: np.ndarray
    step: np.ndarray
    windows: np.ndarray          # (k, n) each window's step
    band_hz: float               # coherent (>= MIN_COHERENCE) up to here
    used: int                    # windows with input
    flown: int                   # windows with all motors running
    fs: float = 0.0              # the grid's rate (Hz) and its window, for a response set beside this one
    n_seg: int = 0


def band_step(H: np.ndarray, f: np.ndarray, band: float, n_seg: int, n_pre: int, n_resp: int) -> np.ndarray:
    """The step of a frequency response H on the bins f of an n_seg window, rolled off above `band` (raised
    cosine to twice it), from -n_pre to n_resp rows: the roll-off is zero-phase and smears the impulse to both
    sides (the module's PRE_SHARE). One definition for the measured steps and a model's set beside them."""
    taper = np.clip(0.5 * (1.0 + np.cos(np.pi * (f - band) / band)), 0.0, 1.0)
    taper[f <= band] = 1.0
    taper[f >= 2.0 * band] = 0.0
    imp = np.fft.irfft(H * taper, n_seg)
    return np.cumsum(np.concatenate([imp[..., n_seg - n_pre:], imp[..., :n_resp]], axis=-1), axis=-1)


def _uniform(t: np.ndarray, cols: list[np.ndarray], ok: np.ndarray, air: np.ndarray):
    """The columns on a uniform grid at the rows' median rate; a grid point is valid when the rows either
    side are valid (`ok`) and no farther apart than GAP_PERIODS periods, in the air when both are (`air`)."""
    dt = float(np.median(np.diff(t)))
    grid = np.arange(t[0], t[-1], dt)
    j = np.clip(np.searchsorted(t, grid, side="right"), 1, t.size - 1)
    valid = ok[j - 1] & ok[j] & (t[j] - t[j - 1] <= GAP_PERIODS * dt)
    filled = [np.interp(grid, t[ok], c[ok]) for c in cols]
    return 1.0 / dt, valid, air[j - 1] & air[j], filled


def estimate(t: np.ndarray, u: np.ndarray, y: np.ndarray, ok: np.ndarray, air: np.ndarray, loop: Loop,
             nyquist_hz: float = math.inf) -> Response | str:
    """The step response of `loop` from setpoint u to response y (rows t, s; `ok` the rows with both, `air`
    those with all motors running; `nyquist_hz`: half the slower of their own sample rates, above which
    rows interpolated between their samples show nothing), or why not."""
    response_s, min_std, min_band_hz = loop.response_s, loop.min_std, loop.min_band_hz
    if ok.sum() < 2:
        return "no row with both the setpoint and the response"
    fs, valid, up, (u, y) = _uniform(t, [u, y], ok, air)
    n_seg = int(2 ** round(math.log2(max(SEGMENT_S, SEGMENT_PER_RESPONSE * response_s) * fs)))
    n_resp = min(int(round(response_s * fs)), n_seg // 2)
    n_pre = int(round(PRE_SHARE * response_s * fs))
    if u.size < n_seg:
        return f"{u.size / fs:.1f} s of log: shorter than one {n_seg / fs:.1f} s window"
    bad = np.concatenate([[0], np.cumsum(~valid)])
    flying = np.concatenate([[0], np.cumsum(up)])
    starts = np.arange(0, u.size - n_seg + 1, n_seg // 2)
    starts = starts[(bad[starts + n_seg] == bad[starts]) & (flying[starts + n_seg] - flying[starts] >= AIR_SHARE * n_seg)]
    if starts.size == 0:
        return (f"no {n_seg / fs:.1f} s window in the air (all four motors running on {AIR_SHARE:.0%} of its rows) "
                "with the setpoint and the response logged throughout")
    idx = starts[:, None] + np.arange(n_seg)
    us, ys = u[idx], y[idx]
    moving = us.std(axis=1) >= min_std
    if moving.sum() < MIN_WINDOWS:
        return (f"{int(moving.sum())} of {starts.size} {n_seg / fs:.1f} s windows in the air have the setpoint "
                f"varying by {min_std:.3g} {loop.unit} (std) or more; {MIN_WINDOWS} are needed")
    us, ys = us[moving], ys[moving]
    w = np.hanning(n_seg)
    U = np.fft.rfft((us - us.mean(axis=1, keepdims=True)) * w, axis=1)
    Y = np.fft.rfft((ys - ys.mean(axis=1, keepdims=True)) * w, axis=1)
    suu, syy = (np.abs(U) ** 2).sum(axis=0), (np.abs(Y) ** 2).sum(axis=0)
    suy = (np.conj(U) * Y).sum(axis=0)
    H = suy / np.maximum(suu, 1e-30)
    H[0] = H[1]                                         # the means are removed: the lowest bin's gain
    coh = np.abs(suy) ** 2 / np.maximum(suu * syy, 1e-30)
    f = np.fft.rfftfreq(n_seg, 1.0 / fs)
    smooth = np.convolve(coh, np.ones(COHERENCE_SMOOTH) / COHERENCE_SMOOTH, mode="same")
    low = np.flatnonzero((f > 0.5) & (smooth < MIN_COHERENCE))
    coherent = float(f[low[0]]) if low.size else float(f[-1])
    band = min(coherent, nyquist_hz)
    if band < min_band_hz:
        why = (f"the setpoint explains the response only below {band:.1f} Hz (coherence under {MIN_COHERENCE:g} above it"
               if coherent <= nyquist_hz else
               f"the setpoint or the response sampled so slowly that nothing above {band:.1f} Hz is in the log (half "
               "their slower rate")
        return why + f", over {int(moving.sum())} windows with input; a step needs {min_band_hz:g} Hz): too little to show a step"
    def to_step(h):
        return band_step(h, f, band, n_seg, n_pre, n_resp)

    power = np.abs(U) ** 2
    lam = WINDOW_REGULARIZATION * power.max(axis=1, keepdims=True)
    Hw = (np.conj(U) * Y + lam * H) / (power + lam)
    Hw[:, 0] = Hw[:, 1]
    return Response(np.arange(-n_pre, n_resp) / fs, to_step(H), to_step(Hw), band, int(moving.sum()), int(starts.size),
                    fs, n_seg)


def _num(x: float, nd: int = 4):
    return None if not math.isfinite(x) else round(float(x), nd)


def axis_report(r: Response) -> dict:
    """The numbers of one axis: each metric of the averaged response with its spread over the windows."""
    m = metrics(r.t, r.step)
    each = [metrics(r.t, s) for s in r.windows]
    out = {"windows": r.used, "windows_in_air": r.flown, "coherent_to_hz": _num(r.band_hz, 1),
           "fastest_rise_shown_s": _num(RISE_BANDWIDTH / r.band_hz), "final": _num(m["final"], 3)}
    for k in ("delay_s", "rise_s", "overshoot", "settling_s"):
        v = np.array([e[k] for e in each])
        v = v[np.isfinite(v)]
        lo, hi = np.percentile(v, SPREAD) if v.size else (math.nan, math.nan)
        out[k] = {"value": _num(m[k]), "spread": [_num(lo), _num(hi)], "windows": int(v.size)}
    out["limited_by_band"] = bool(m["rise_s"] < BAND_LIMITED * RISE_BANDWIDTH / r.band_hz)
    return out


def _unwrap(x: np.ndarray) -> np.ndarray:
    """An angle unwrapped over its logged (finite) rows."""
    out = x.copy()
    ok = np.isfinite(x)
    out[ok] = np.unwrap(x[ok])
    return out


def _rate(table: Table, key: str | None, rows: float) -> float:
    """A stream's own sample rate from the log's `# KEY:` line (sim/logs/common.py), else the rows'."""
    try:
        return float(table.meta[key]) if key and key in table.meta else rows
    except ValueError:
        return rows


def measure(table: Table) -> tuple[dict, dict]:
    """(the report's `steps` of one log, the responses for the figure): per loop the log can show, per
    axis its numbers or the reason it cannot."""
    P = np.vstack([table[f"P{i}"] for i in range(1, 5)])
    running = all_running(P)
    t = table["t"]
    fmt = table.meta.get("format", "flightctl")
    out = {"file": table.path, "method": "H1 over half-overlapping Hann windows, coherence gate "
                                         f"{MIN_COHERENCE:g} (docs/steps.md)"}
    curves = {}
    for loop in LOOPS:
        sp = [_col(table, c) for c in loop.setpoint]
        resp = [_col(table, c) for c in loop.response]
        if not any(s is not None for s in sp):
            if loop.name == "rate":
                out[loop.name] = {"why": "no rate setpoint in the log: log " + RATE_SETPOINT.get(
                    fmt, "the rate setpoint (setpoint_x/y/z, docs/formats.md)")}
            continue
        rows = 1.0 / float(np.median(np.diff(t)))
        sp_rate = _rate(table, loop.rate_key, rows)
        resp_rate = _rate(table, loop.response_rate_key, rows)
        part = {"unit": loop.unit, "response_s": loop.response_s, "min_setpoint_std": round(loop.min_std, 5),
                "rows_hz": round(rows, 1), "setpoint_hz": round(sp_rate, 1)}
        for a, s, y in zip(AXES, sp, resp):
            fly = FLY[loop.name].format(axis=NAMES[a], snap=SNAP[NAMES[a]])
            if s is None or y is None:
                part[a] = {"why": f"no {loop.setpoint[AXES.index(a)] if s is None else loop.response[AXES.index(a)]} "
                                  "in the log"}
                continue
            if min(rows, sp_rate) < loop.min_rate_hz:
                what = "rows" if rows < loop.min_rate_hz else "setpoint"
                how = f" ({RATE_SETPOINT[fmt]})" if loop.name == "rate" and fmt in RATE_SETPOINT else ""
                part[a] = {"why": f"the {what} logged at {min(rows, sp_rate):.1f} Hz: a {loop.name} loop's step needs "
                                  f"{loop.min_rate_hz:g} Hz; log {'it' if what == 'setpoint' else 'the gyro and it'} faster{how}"}
                continue
            if loop.name == "attitude" and a == "z":
                s, y = _unwrap(s), _unwrap(y)
            r = estimate(t, s, y, np.isfinite(s) & np.isfinite(y), running, loop, 0.5 * min(rows, sp_rate, resp_rate))
            if isinstance(r, str):
                part[a] = {"why": r + "; fly next time: " + fly}
                continue
            m = metrics(r.t, r.step)
            delay = m["delay_s"]
            if not m["final"] >= MIN_FINAL:
                part[a] = {"why": f"the response reaches {m['final']:.2f} of the setpoint within {loop.response_s:g} s: the loop "
                                  "does not follow this setpoint (a flight mode that overrides it, a loop saturated, or "
                                  "one slower than the response shown); fly next time: " + fly}
                continue
            if not delay > 0.0:
                part[a] = {"why": f"the setpoint follows the response, not the reverse (the step's 50 % at {1e3 * delay:.0f} ms, "
                                  "before the setpoint moved): the firmware sets it from the vehicle's own state here "
                                  "(a heading or attitude hold, a position controller); fly next time: " + fly}
                continue
            part[a] = axis_report(r)
            curves[(loop.name, a)] = r
        out[loop.name] = part
    return out, curves


def of(tables: list[Table]) -> tuple[list[dict], list[tuple[dict, dict]]]:
    """The report's `steps` (one entry a log, in order) and, for `figure`, each log's entry with its responses."""
    out = [measure(t) for t in tables]
    return [r for r, _ in out], out


def text(steps: list[dict]) -> str:
    """The step responses' lines of the printed report."""
    L = []
    for s in steps:
        for loop in LOOPS:
            part = s.get(loop.name)
            if part is None:
                continue
            if "why" in part:
                L.append(f"  step response, {loop.name} loop: {part['why']}")
                continue
            for a in AXES:
                e = part.get(a, {})
                if "why" in e:
                    L.append(f"  step response, {loop.name} {NAMES[a]}: {e['why']}")
                    continue
                def ms(k):
                    v, (lo, hi) = e[k]["value"], e[k]["spread"]
                    lo_ms = "-" if lo is None else f"{1e3 * lo:.0f}"
                    hi_ms = "-" if hi is None else f"{1e3 * hi:.0f}"
                    return "-" if v is None else f"{1e3 * v:.0f} ms ({lo_ms}-{hi_ms})"
                o = e["overshoot"]["value"]
                L.append(f"  step response, {loop.name} {NAMES[a]}: delay {ms('delay_s')}, rise {ms('rise_s')}, "
                         f"overshoot {'-' if o is None else f'{100 * o:.0f} %'}, settling {ms('settling_s')}, final "
                         f"{e['final']}; {e['windows']} windows, coherent to {e['coherent_to_hz']} Hz"
                         + (" (the rise is the band's: an upper bound, the delay uncertain by half of it)"
                            if e["limited_by_band"] else ""))
                if "predicted" in e:
                    L.append("    " + prediction_text(e["predicted"]))
    return "\n".join(L) + ("\n" if L else "")


def prediction_text(p: dict) -> str:
    """One line of a predicted step beside its measured one (predict.py)."""
    if "why" in p:
        return f"predicted: {p['why']}"
    def pair(k, scale, unit):
        v = p[k]
        f = lambda x: "-" if x is None else f"{scale * x:.0f}"
        return f"{k.split('_')[0]} {f(v['predicted'])} {unit} (measured {f(v['measured'])})"
    return (f"predicted on {p['checked_on']} by the model of {p['identified_on']}: " + ", ".join(
        (pair("delay_s", 1e3, "ms"), pair("rise_s", 1e3, "ms"), pair("overshoot", 100, "%")))
        + f"; step error {p['step_error']}; " + ("agrees" if p["agrees"] else f"disagrees: {p['points_to'] or 'its shape'}"))


def figure(curves: list[tuple[dict, dict]]):
    """The mean response with its band (the windows' 10th-90th percentiles) per loop and axis, one
    row per log, and on a rate axis with a prediction (predict.py) the held-out half measured and the step
    predicted for it; an axis the log cannot show says why in its panel."""
    from matplotlib.figure import Figure
    rows = [(i, loop.name) for i, c in enumerate(curves) for loop in LOOPS if any(k[0] == loop.name for k in c[1])]
    fig = Figure(figsize=(12, 3.2 * max(1, len(rows))), layout="constrained")
    axes = fig.subplots(max(1, len(rows)), 3, squeeze=False)
    for row, (i, name) in enumerate(rows):
        report, c = curves[i]
        for j, a in enumerate(AXES):
            ax = axes[row, j]
            r = c.get((name, a))
            ax.set_title(f"{report['file'].rsplit('/', 1)[-1]}: {name} {NAMES[a]}", fontsize=9)
            if r is None:
                ax.axis("off")
                why = report[name].get(a, report[name]).get("why", "")
                ax.text(0.02, 0.5, "\n".join(textwrap.wrap(why, 60)), transform=ax.transAxes, fontsize=7, va="center")
                continue
            ax.axhline(1.0, color="k", lw=0.8, ls="--")
            lo, hi = np.percentile(r.windows, SPREAD, axis=0)
            ax.fill_between(1e3 * r.t, lo, hi, color="tab:blue", alpha=0.25, label="windows 10-90 %")
            ax.plot(1e3 * r.t, r.step, color="tab:blue", lw=2, label=f"mean of {r.used} windows")
            held = c.get(("predicted", a)) if name == "rate" else None
            if held is not None:          # predict.py: the second half measured, the first half's model predicting it
                m, pred = held
                e = report[name][a].get("predicted", {})
                ax.plot(1e3 * m.t, m.step, color="tab:green", lw=1.2, ls="--", label="measured, second half")
                ax.plot(1e3 * m.t, pred, color="tab:red", lw=1.5,
                        label=f"predicted (first half's model), error {e.get('step_error')}")
            ax.set_xlabel("time after the step (ms)")
            ax.legend(fontsize=7, loc="lower right")
        axes[row, 0].set_ylabel("response / setpoint")
    if not rows:
        axes[0, 0].text(0.02, 0.5, "no loop with a setpoint and a response in these logs", transform=axes[0, 0].transAxes)
    return fig
