"""`flightctl tune --from-log LOG [--check-on LOG2] [--target-pm 45 --target-gm 6 --ms 2 --overshoot 0.15
--max-change 2 --draws 48 --seed 0] [--out LINES] [--json R.json]`: gains from a flight log (docs/tune.md, "Gains
from a log").

1. **The vehicle and its controller.** The base model diagnose identifies (`predict.base_model`, basemodel.py) on
   the log's first `predict.SPLIT` of time, and the firmware's rate controller as the log gives it
   (sim/logs/controller.py, `predict.loop_parts`). A log that ends in a crash is taken to
   `predict.CRASH_MARGIN_S` before its attitude passes the crash limit (`predict.before_crash`): the fall
   is not the loop the gains close.
2. **The check.** That model flying the logged controller predicts each rate axis's step on the rest of the
   log (`predict.held_out_model`), or, with `--check-on LOG2`, the model of the whole LOG predicts another log
   of the same vehicle flown with its own gains (`predict.cross_model`). An axis whose prediction does not
   agree (`agrees`: predict.py's step error and spread tests) is refused, with what the disagreement points
   to; no gains are recommended for it. Every axis refused: exit 1.
3. **The plausible models.** The identification's own uncertainty, drawn (`DRAWS` models, `--seed`): the
   axis's effectiveness k (k_p, k_q, k_r), h2 and each rotor's gain each from a normal with its jackknife
   standard error (basemodel.py), truncated to the physical side (k > 0, h2 below the median command); the commands'
   timing uniform over the identification's grid step either side of the value found (basemodel.TIMING_DELAYS: the
   search's resolution, the only figure of its uncertainty the identification gives, or its `stderr` where it
   has one). Each draw's effectiveness b is predict.py's linearisation (`predict.effectiveness`) of the drawn
   figures through the log's firmware's own mix and range (`predict.loop_parts`), and the loop is predict.py's
   (`predict.loop_terms`, its gyro chains `predict.chains`), so a draw is the same loop the check checked.
4. **The search.** Per axis the logged P, I and D each times a factor on a log grid `GRID` over [1/m, m],
   m = `--max-change` (a bounded change per pass, the Betaflight App's 0.5-2x; D stays where the firmware has
   none). Each candidate on every drawn model: on the open loop L = b G Fg (kp P + ki I + kd D), over the
   frequencies `F_LO` to the loop's Nyquist (`MARGIN_POINTS`, log-spaced): the phase margin (the smallest at
   any |L| = 1), the gain margin (the smallest 1/|L| at a phase crossing of -180 deg where |L| < 1: the
   crossings below the integrators' region, where only a gain fall harms, are not margins of a gain rise), the
   peak sensitivity Ms = max |1 / (1 + L)| over the whole band; on the closed loop (`predict.closed_loop`) its
   step (`steps.band_step` at `STEP_HZ`, `STEP_S` long; steps.metrics): the rise (10-90 %) and the overshoot.
   A candidate **meets the targets** when its worst over the models meets each: phase margin >= --target-pm,
   gain margin >= --target-gm, Ms <= --ms, overshoot <= --overshoot, every draw's step settling to its
   setpoint (`SETTLED`), and, with --rise-ms, its median rise no slower. Among those the fastest median rise
   wins; within `TIE` of it, the least change (the sum of |log factor|).
   None meets them: the axis gets no recommendation and the report names the candidate nearest (the fewest
   drawn models on which it diverges, then the least worst shortfall, each target's in its own scale) and which
   target fails. Where that nearest is stable on every drawn model and nearer than the logged gains on every
   target (no worst shortfall larger, one smaller; or the logged gains diverge on some model), it is a
   **step**: a pass toward the targets, written to paste with a line saying so; flown, its log is tuned
   from again (the bound per pass is the Betaflight App's; a pilot makes several passes). The exit stays 1
   without a recommendation.
5. **The lines to paste** in the log's firmware's own terms (`paste`): Betaflight's CLI `set` lines (the
   integers of the header's rollPID etc.: the physical gain over PTERM/ITERM/DTERM_SCALE / PID_MIXER_SCALING,
   controller.py's constants, pid_init.c:274-276, pid.h:32, 44-46; the names and 0-200 range of the CLI's
   value table, `{ "p_roll", VAR_UINT8 | PROFILE_VALUE, ...P8[ROLL], 0, 200 }` in src/main/io/serial_cli.c of
   3.1 and `pid[PID_ROLL].P, 0-200` in src/main/cli/settings.c of 4.x), PX4's `param set MC_ROLLRATE_P`
   (the ideal form's gain over the log's MC_ROLLRATE_K, MulticopterRateControl.cpp), an ArduPilot parameter
   file (ATC_RAT_RLL_P etc. as they are, AC_AttitudeControl_Multi.cpp) or a flightctl parameter file
   ([gains], eq. 24). A gain is only in the units of the firmware whose mixer scaled it: the lines are the
   log's firmware's, never another's.
"""
from __future__ import annotations

import dataclasses
import json
import math
import time
import types

import numpy as np

from flightctl.errors import InputError
from flightctl.sim.diagnose import predict, steps
from flightctl.sim.diagnose.basemodel import TIMING_DELAYS
from flightctl.sim.logs import controller as ctl

DRAWS = 48                  # plausible models drawn per axis
GRID = 9                    # factors per gain on [1/m, m], log-spaced (9^3 candidates an axis with D)
F_LO = 0.2                  # Hz: the margins' band starts here (a period of 5 s is not the rate loop's)
MARGIN_POINTS = 500         # log-spaced frequencies for the margins and Ms
STEP_HZ = 2000.0            # the closed loop's step sampled at this rate (or the loop's, if slower) ...
STEP_S = 1.0                # ... over a window this long (the response, its final value on its last 40 %)
RESPONSE_S = 0.5            # the step's response shown (rise, overshoot)
SETTLED = 0.05              # each draw's step ends within this of its setpoint (a stable loop, integral on)
TIE = 0.02                  # median rises within this share of the fastest are ties: the least change wins
TARGETS = {"pm_deg": 45.0, "gm_db": 6.0, "ms": 2.0, "overshoot": 0.15}
GAIN_KEYS = ("kp", "ki", "kd")


@dataclasses.dataclass
class Targets:
    pm_deg: float = TARGETS["pm_deg"]
    gm_db: float = TARGETS["gm_db"]
    ms: float = TARGETS["ms"]
    overshoot: float = TARGETS["overshoot"]
    rise_s: float | None = None          # the slowest median rise allowed (None: unbounded, the fastest wins)
    max_change: float = 2.0


def drawn_models(vehicle, declared, axis: str, n: int, rng: np.random.Generator,
                 parts: dict | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(b (n,), tau (n,)): the axis's effectiveness and the commands' timing of n plausible models (module
    docstring, 3), b through predict.effectiveness of each drawn identification with the log's firmware's mix
    and range (`parts`, predict.loop_parts: the same b the check of the logged loop used; without it
    Betaflight's, which scales another firmware's loop wrong)."""
    idn = vehicle.identification
    key = {"x": "k_p", "y": "k_q", "z": "k_r"}[axis]
    k, k_se = idn[key]["value"], idn[key]["stderr"]
    h2, h2_se, pm = idn["h2"]["value"], idn["h2"]["stderr"], idn["median_P"]["value"]
    g, g_se = np.array(vehicle.gains), np.array(idn["rotor_gain"]["stderr"], float)
    tau = predict.timing(vehicle)[0]          # the loop fit's delay where it has one (loopfit.py)
    if idn["timing"].get("stderr") is not None:
        lo, hi = tau - 1.7320508 * idn["timing"]["stderr"], tau + 1.7320508 * idn["timing"]["stderr"]  # same sd
    else:
        j = int(np.argmin(np.abs(TIMING_DELAYS - tau)))
        lo, hi = TIMING_DELAYS[max(j - 1, 0)], TIMING_DELAYS[min(j + 1, TIMING_DELAYS.size - 1)]
    b, taus = np.empty(n), rng.uniform(max(lo, 0.0), hi, n)
    for i in range(n):
        d = {**idn, key: {**idn[key], "value": max(rng.normal(k, k_se), 0.05 * abs(k))},
             "h2": {**idn["h2"], "value": min(rng.normal(h2, h2_se), pm - 1.0)}}
        drawn = types.SimpleNamespace(identification=d, layout=vehicle.layout,
                                      gains=tuple(np.maximum(rng.normal(g, g_se), 0.05)))
        b[i] = predict.effectiveness(drawn, declared, axis, parts)
    return b, taus


def _crossings(x: np.ndarray) -> np.ndarray:
    """Where x (..., F) changes sign between neighbours: (..., F - 1) bool."""
    return np.sign(x[..., 1:]) * np.sign(x[..., :-1]) < 0


def loop_margins(L: np.ndarray, f: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Phase margin (deg), gain margin (dB) and Ms of open loops L (..., F) on a rising frequency grid f (module
    docstring, 4): +inf where the loop has no such crossing; with f, the frequencies (Hz) of the smallest phase
    margin's gain crossover and of the smallest gain margin's phase crossover (nan without one)."""
    mag = np.abs(L)
    ph = np.degrees(np.unwrap(np.angle(L), axis=-1))
    lm = np.log(np.maximum(mag, 1e-300))
    gc = _crossings(lm)
    w = lm[..., :-1] / np.where(gc, lm[..., :-1] - lm[..., 1:], 1.0)          # where |L| = 1 between samples
    ph_c = ph[..., :-1] + w * (ph[..., 1:] - ph[..., :-1])
    pm = np.where(gc, (ph_c + 180.0 + 180.0) % 360.0 - 180.0, np.inf).min(axis=-1)
    q = np.floor((ph + 180.0) / 360.0)                                       # a step: a crossing of -180 mod 360
    pc = q[..., 1:] != q[..., :-1]
    level = 360.0 * np.maximum(q[..., 1:], q[..., :-1]) - 180.0
    v = (level - ph[..., :-1]) / np.where(pc, ph[..., 1:] - ph[..., :-1], 1.0)
    lm_c = lm[..., :-1] + v * (lm[..., 1:] - lm[..., :-1])
    gm = np.where(pc & (lm_c < 0), -lm_c * 20.0 / math.log(10.0), np.inf).min(axis=-1)
    ms = (1.0 / np.abs(1.0 + L)).max(axis=-1)
    out = {"pm_deg": pm, "gm_db": gm, "ms": ms}
    if f is not None:
        pm_all = np.where(gc, (ph_c + 180.0 + 180.0) % 360.0 - 180.0, np.inf)
        gm_all = np.where(pc & (lm_c < 0), -lm_c, np.inf)
        for name, x in (("gain_crossover_hz", pm_all), ("phase_crossover_hz", gm_all)):
            j = np.argmin(x, axis=-1)
            out[name] = np.where(np.isfinite(np.take_along_axis(x, j[..., None], -1)[..., 0]), f[j], np.nan)
    return out


def _grid(parts: dict, m: float) -> np.ndarray:
    """The candidates' factors (K, 3) on P, I, D: GRID log-spaced on [1/m, m] each (D at 1 where kd = 0)."""
    f = np.exp(np.linspace(-math.log(m), math.log(m), GRID)) if m > 1.0 else np.ones(1)
    fd = f if parts["kd"] else np.ones(1)
    return np.array(np.meshgrid(f, f, fd, indexing="ij")).reshape(3, -1).T


class Axis:
    """One axis's loop over the drawn models: its terms on the margins' grid and on the step's grid."""

    def __init__(self, parts: dict, b: np.ndarray, tau: np.ndarray, loop_chain: str, response_chain: str):
        self.parts, self.b, self.tau = parts, b, tau
        fs = parts["loop_hz"]
        self.fm = np.geomspace(F_LO, 0.499 * fs, MARGIN_POINTS)
        self.fs_step = min(STEP_HZ, fs)
        self.n_seg = int(2 ** math.ceil(math.log2(STEP_S * self.fs_step)))
        self.fe = np.fft.rfftfreq(self.n_seg, 1.0 / self.fs_step)
        self.n_resp = int(RESPONSE_S * self.fs_step)
        self.n_pre = self.n_resp // 5
        self.t = np.arange(-self.n_pre, self.n_resp) / self.fs_step
        self.m = [predict.loop_terms(self.fm, t_, parts, loop_chain, response_chain) for t_ in tau]
        self.e = [predict.loop_terms(self.fe, t_, parts, loop_chain, response_chain) for t_ in tau]

    def gains(self, factors: np.ndarray) -> np.ndarray:
        return factors * np.array([self.parts[k] for k in GAIN_KEYS])

    def figures(self, factors: np.ndarray, with_steps: bool = True) -> dict[str, np.ndarray]:
        """Per model and candidate (M, K): the margins, Ms and (with_steps) the step's rise, overshoot, final."""
        g = self.gains(factors)
        kp, ki, kd = (g[:, j, None] for j in range(3))
        out = {k: np.empty((self.b.size, len(g))) for k in ("pm_deg", "gm_db", "ms", "gain_crossover_hz",
                                                            "phase_crossover_hz", "rise_s", "overshoot", "final")}
        kf = self.parts.get("kf", 0.0)
        for i, (bm, tm, te) in enumerate(zip(self.b, self.m, self.e)):
            L = bm * tm["G"] * predict.controller(tm, kp, ki, kd, kf)[1]
            for k, v in loop_margins(L, self.fm).items():
                out[k][i] = v
            if not with_steps:
                continue
            G = bm * te["G"]
            Cr, Cy = predict.controller(te, kp, ki, kd, kf)
            H = te["Fr"] * G * Cr / (1.0 + G * Cy)
            H[:, 0] = np.where((ki[:, 0] > 0) | (self.parts.get("loop") == "attitude"), 1.0, H[:, 1])
            st = steps.band_step(H, self.fe, 0.25 * self.fs_step, self.n_seg, self.n_pre, self.n_resp)
            for j in range(len(g)):
                mt = steps.metrics(self.t, st[j])
                out["rise_s"][i, j], out["overshoot"][i, j], out["final"][i, j] = mt["rise_s"], mt["overshoot"], mt["final"]
        return out


def _summary(fig: dict, j: int) -> dict:
    """The median and the worst over the models of candidate j's figures."""
    worst = {"pm_deg": np.min, "gm_db": np.min, "ms": np.max, "rise_s": np.max, "overshoot": np.max}
    out = {k: _num(float(np.nanmedian(fig[k][:, j]))) if np.isfinite(fig[k][:, j]).any() else None
           for k in ("gain_crossover_hz", "phase_crossover_hz")}
    for k, w in worst.items():
        x = fig[k][:, j]
        x = np.where(np.isnan(x), np.inf if k in ("ms", "rise_s", "overshoot") else -np.inf, x)
        out[k] = {"median": _num(float(np.median(x))), "worst": _num(float(w(x)))}
    out["settled"] = bool(np.all(np.abs(fig["final"][:, j] - 1.0) < SETTLED))
    return out


def _num(x: float, nd: int = 4):
    return None if not math.isfinite(x) else (float(f"{x:.{nd}g}"))


def _shortfall(fig: dict, tg: Targets, rise_max: float) -> np.ndarray:
    """(K, 5) each target's worst shortfall over the models in its own scale (0: met)."""
    def worst(k, fn):
        x = fig[k]
        bad = np.inf if fn is np.max else -np.inf
        return fn(np.where(np.isnan(x), bad, x), axis=0)
    with np.errstate(invalid="ignore"):
        s = np.stack([np.maximum(tg.pm_deg - worst("pm_deg", np.min), 0) / max(tg.pm_deg, 1.0),
                      np.maximum(tg.gm_db - worst("gm_db", np.min), 0) / max(tg.gm_db, 1.0),
                      np.maximum(worst("ms", np.max) - tg.ms, 0) / tg.ms,
                      np.maximum(worst("overshoot", np.max) - tg.overshoot, 0) / max(tg.overshoot, 0.01),
                      np.maximum(np.nanmedian(fig["rise_s"], axis=0) - rise_max, 0) / rise_max
                      + (np.abs(fig["final"] - 1.0) >= SETTLED).any(axis=0)], axis=1)
    return np.nan_to_num(s, nan=np.inf)


def _nearest(fig: dict, short: np.ndarray) -> int:
    """The candidate nearest the targets: the fewest drawn models on which its loop is unstable (a negative phase
    margin: there the gain margin and Ms, finite, say nothing of a loop that diverges), then the least worst
    shortfall (`_shortfall`)."""
    unstable = (np.nan_to_num(fig["pm_deg"], nan=-1.0) < 0).sum(axis=0)
    return int(np.lexsort((short.max(axis=1), unstable))[0])


SHORT_NAMES = ("phase margin", "gain margin", "Ms", "overshoot", "rise (or a step that does not settle)")


def tune_axis(ax: Axis, tg: Targets) -> dict:
    """The search of the module docstring (4) on one axis: the logged gains' figures over the models, and the
    recommendation or the nearest candidate and why none."""
    logged = ax.figures(np.ones((1, 3)))
    now = _summary(logged, 0)
    rise_max = tg.rise_s if tg.rise_s is not None else math.inf
    grid = _grid(ax.parts, tg.max_change)
    coarse = ax.figures(grid, with_steps=False)
    ok_m = ((coarse["pm_deg"].min(axis=0) >= tg.pm_deg) & (coarse["gm_db"].min(axis=0) >= tg.gm_db)
            & (coarse["ms"].max(axis=0) <= tg.ms))
    pool = np.flatnonzero(ok_m)
    if pool.size == 0:                 # none meets the margins: the nearest by its margins alone, with its steps
        short = _shortfall({**coarse, "rise_s": np.zeros_like(coarse["ms"]), "overshoot": np.zeros_like(coarse["ms"]),
                            "final": np.ones_like(coarse["ms"])}, tg, math.inf)
        pool = np.array([_nearest(coarse, short)])
    fig = ax.figures(grid[pool])
    short = _shortfall(fig, tg, rise_max)
    met = np.flatnonzero((short == 0).all(axis=1))
    change = np.abs(np.log(grid[pool])).sum(axis=1)
    out = {"logged": {"gains": {k: ax.parts[k] for k in GAIN_KEYS}, **now}, "candidates": int(len(grid)),
           "models": int(ax.b.size), "meet_margins": int(ok_m.sum()), "rise_max_s": _num(rise_max),
           "effectiveness_drawn": [_num(float(np.percentile(ax.b, q))) for q in (10, 50, 90)],
           "timing_drawn_s": [_num(float(ax.tau.min())), _num(float(ax.tau.max()))]}
    if met.size:
        rise = np.nanmedian(fig["rise_s"][:, met], axis=0)
        tie = met[rise <= rise.min() * (1.0 + TIE)]
        j = int(tie[np.argmin(change[tie])])
        out["recommended"] = True
    else:
        j = _nearest(fig, short)
        out["recommended"] = False
        out["why"] = ("no gains within x" + f"{tg.max_change:g} of the logged ones meet the targets on every drawn model: "
                      "nearest fails " + ", ".join(n for n, s in zip(SHORT_NAMES, short[j]) if s > 0))
        was = _shortfall(logged, tg, rise_max)[0]
        nearer = np.all(short[j] <= was) and np.any(short[j] < was)
        if np.nanmin(fig["pm_deg"][:, j]) > 0 and (nearer or not np.nanmin(logged["pm_deg"][:, 0]) > 0):
            out["step"] = True          # a pass toward the targets (module docstring, 4)
            out["why"] += ("; it is stable on every drawn model and nearer than the logged gains on every target (or they "
                           "diverge on some): a pass toward them (fly it, then tune again from its log)")
    g = ax.gains(grid[pool[j]][None])[0]
    keys = GAIN_KEYS if ax.parts["kd"] else GAIN_KEYS[:2]        # no D in this loop (3.1's yaw): none written
    out["new"] = {"gains": {k: float(f"{v:.6g}") for k, v in zip(GAIN_KEYS, g) if k in keys},
                  "factors": {k: float(f"{v:.4g}") for k, v in zip(GAIN_KEYS, grid[pool[j]]) if k in keys},
                  **_summary(fig, j)}
    return out


def from_log(table, a, targets: Targets, check_on=None, draws: int = DRAWS, seed: int = 0,
             progress=lambda *_: None) -> dict:
    """The module docstring's 1-4 on one log (`check_on`: another log of the vehicle, flown with its own
    gains, checked instead of the log's own second part): the report, per axis."""
    ctrl = ctl.of_table(table)
    parts0, why = predict.loop_parts(ctrl, table.meta, "x")
    report = {"log": table.path, "firmware": ctrl.get("firmware"), "targets": dataclasses.asdict(targets),
              "draws": draws, "seed": seed, "axes": {}}
    table, crash_s = predict.before_crash(table)
    if crash_s is not None:
        report["crash_s"] = crash_s
        progress(f"the log ends in a crash (the attitude past {math.degrees(predict.CRASH_TILT):.0f} deg at {crash_s:.1f} s): "
                 f"its rows to {crash_s - predict.CRASH_MARGIN_S:.1f} s are taken")
    if parts0 is None:
        report["refused"] = why[0]
        return report
    if check_on is None:
        progress("identifying the base model on the log's first half, checking it on the rest")
        model, checked, _ = predict.held_out_model(table, ctrl, a, progress)
    else:
        progress(f"identifying the base model on {table.path}, checking it on {check_on.path}")
        model, checked, _ = predict.cross_model(table, check_on, ctl.of_table(check_on), a, progress)
    rng = np.random.default_rng(seed)
    for axis in steps.AXES:
        e = checked[axis]
        entry = {"check": e}
        report["axes"][axis] = entry
        if "why" in e:
            entry["refused"] = f"no check: {e['why']}"
            continue
        if not e["agrees"]:
            entry["refused"] = (f"the model does not predict the {steps.NAMES[axis]} step it is checked on (step error "
                                f"{e['step_error']:.3g}, agreement under {predict.AGREE_ERROR:g}): "
                                + (e["points_to"] or "the step error alone"))
            continue
        vehicle, declared = model
        parts, _ = predict.loop_parts(ctrl, table.meta, axis, declared)   # the firmware's mix and range, as checked
        parts = {**parts, "motor_lag_s": predict.timing(vehicle)[1]}     # the loop fit's motor lag (loopfit.py)
        progress(f"{steps.NAMES[axis]}: the check agrees (step error {e['step_error']:.3g}); {draws} models drawn, "
                 f"{len(_grid(parts, targets.max_change))} candidates")
        b, tau = drawn_models(vehicle, declared, axis, draws, rng, parts)
        entry.update(tune_axis(Axis(parts, b, tau, *predict.chains(parts, table.meta)), targets))
        entry["not_modelled"] = e.get("not_modelled", [])
        band, fc = e.get("band_hz"), entry["logged"]["phase_crossover_hz"]
        if band and fc and fc > band:
            entry["extrapolated"] = (f"the check saw the loop up to {band:.3g} Hz (its coherent band); the gain margins "
                                     f"are read at {fc:.3g} Hz (the logged gains' phase crossover, median), where only the "
                                     "model speaks: its timing as a pure delay, no motor lag")
    if not any(v.get("recommended") for v in report["axes"].values()):
        report["refused"] = "no axis gets gains: " + "; ".join(
            f"{steps.NAMES[x]}: {v.get('refused') or v.get('why')}" for x, v in report["axes"].items())
    return report


def against(first, second, a, targets: Targets, draws: int = DRAWS, seed: int = 0, progress=lambda *_: None) -> dict:
    """A vehicle flown with two tunes, the truth known (docs/tune.md, "Two tunes of one vehicle"): gains from the
    first log (`from_log`, checked on the second log with its own gains), and, per axis with a model, the step each
    set of gains is predicted to give on the second log's windows beside the step the second tune measured there:
    the second tune's gains (the check), the first tune's, the gains from the log (recommended, or the nearest
    candidate where none meets the targets). The first log's model, identified on the whole of it."""
    report = from_log(first, a, targets, second, draws, seed, progress)
    from flightctl.sim.diagnose import loopfit
    c1, c2 = ctl.of_table(first), ctl.of_table(second)
    model = loopfit.attach_fit(predict.base_model(first, a), first, c1)    # the model `from_log`'s check took
    out = {"report": report, "axes": {}}
    for axis in steps.AXES:
        e = report["axes"].get(axis, {})
        if "new" not in e or isinstance(model, str):
            continue
        mine = json.loads(json.dumps(c2))
        for k, v in e["new"]["gains"].items():
            mine["axes"][axis][k]["value"] = v
        row = {}
        for name, c in (("second tune's gains", c2), ("first tune's gains", c1), ("gains from the log", mine)):
            p, _ = predict.predict(model, c, second, first.path, second.path)
            row[name] = {k: p[axis].get(k) for k in ("step_error", "delay_s", "rise_s", "overshoot", "model_full_band")}
        out["axes"][axis] = {"recommended": e["recommended"], "factors": e["new"]["factors"],
                             "second_over_first": {k: float(f"{c2['axes'][axis][k]['value'] / c1['axes'][axis][k]['value']:.4g}")
                                                   for k in GAIN_KEYS if c1["axes"][axis][k]["value"]},
                             "predicted_on_second": row}
    return out


# ---- the lines to paste (module docstring, 5)

BF_NAMES = {"kp": "p", "ki": "i", "kd": "d"}
BF_AXES = {"x": "roll", "y": "pitch", "z": "yaw"}
BF_MAX = 200                 # the CLI's 0-200 of P8/I8/D8 (serial_cli.c of 3.1, cli/settings.c of 4.x)
PX4_AXES = {"x": "ROLL", "y": "PITCH", "z": "YAW"}
AP_AXES = {"x": "RLL", "y": "PIT", "z": "YAW"}


def bf_raw(k: str, value: float) -> int:
    """A Betaflight gain's integer setting of a physical one (controller.py's scaling, inverted), in 0-200."""
    return int(min(max(round(value / (ctl.BF_SCALE[k] / ctl.BF_MIXER * ctl.DEG_PER_RAD)), 0), BF_MAX))


def paste(ctrl: dict, new: dict[str, dict[str, float]]) -> tuple[str, str]:
    """(a file suffix, the lines to paste) of new gains per axis (physical units, as controller.py gives them) in
    the firmware of `ctrl`; the axes not in `new` are not written."""
    fw = ctrl.get("firmware")
    if fw == "betaflight":
        lines = [f"# Betaflight CLI: paste in the CLI tab, then save (the gains' integers: {ctl.BF_SOURCE['kp']} etc.)"]
        for ax, g in new.items():
            lines += [f"set {BF_NAMES[k]}_{BF_AXES[ax]} = {bf_raw(k, v)}" for k, v in g.items()]
        return ".txt", "\n".join(lines + ["save"]) + "\n"
    if fw == "px4":
        lines = ["# PX4: in the MAVLink shell or QGroundControl's console (gains over the log's MC_*RATE_K)"]
        for ax, g in new.items():
            axis = ctrl["axes"][ax]
            K = axis["kp"]["value"] / float(axis["kp"]["raw"]) if float(axis["kp"]["raw"]) else 1.0
            lines += [f"param set MC_{PX4_AXES[ax]}RATE_{k[1].upper()} {v / K:.4g}" for k, v in g.items()]
        return ".txt", "\n".join(lines) + "\n"
    if fw == "ardupilot":
        lines = ["# ArduPilot parameter file: load it in the ground station"]
        for ax, g in new.items():
            lines += [f"ATC_RAT_{AP_AXES[ax]}_{k[1].upper()} {v:.5g}" for k, v in g.items()]
        return ".parm", "\n".join(lines) + "\n"
    if fw == "flightctl":
        name = {"x": "phi", "y": "theta", "z": "psi"}
        lines = ["# flightctl parameter file: --params FILE", "[gains]"]
        for ax, g in new.items():
            lines += [f"k{k[1]}_{name[ax]} = {v:.6g}" for k, v in g.items()]
        return ".toml", "\n".join(lines) + "\n"
    raise InputError(f"gains in {fw or 'this log'}'s own units are not written here (its scaling is not read)")


def recommended(report: dict) -> dict[str, dict[str, float]]:
    return {ax: e["new"]["gains"] for ax, e in report["axes"].items() if e.get("recommended")}


def next_pass(report: dict) -> dict[str, dict[str, float]]:
    """The gains to fly next: each axis's recommendation, or its step toward the targets (`step`)."""
    return {ax: e["new"]["gains"] for ax, e in report["axes"].items() if e.get("recommended") or e.get("step")}


def text(report: dict) -> str:
    """The printed report."""
    L = [f"flightctl tune --from-log {report['log']} ({report['firmware']}): {report['draws']} plausible models per "
         f"axis (seed {report['seed']}); targets: phase margin >= {report['targets']['pm_deg']:g} deg, gain margin >= "
         f"{report['targets']['gm_db']:g} dB, Ms <= {report['targets']['ms']:g}, overshoot <= "
         f"{100 * report['targets']['overshoot']:g} %, changes within x{report['targets']['max_change']:g}"]

    def fig(s):
        r = s["rise_s"]
        return (f"PM {_f(s['pm_deg'])} deg, GM {_f(s['gm_db'])} dB, Ms {_f(s['ms'], 3)}, rise "
                f"{_f(r, ms=True)} ms, overshoot {_f(s['overshoot'], pct=True)} %  (median / worst)")
    if "crash_s" in report:
        L.append(f"  the log ends in a crash (the attitude past {math.degrees(predict.CRASH_TILT):.0f} deg at "
                 f"{report['crash_s']:.1f} s): identified and checked on its rows to "
                 f"{report['crash_s'] - predict.CRASH_MARGIN_S:.1f} s")
    for ax, e in report["axes"].items():
        name = steps.NAMES[ax]
        c = e["check"]
        if "why" not in c:
            L.append(f"  {name}: checked on {c['checked_on']}: " + steps.prediction_text(c))
        if "refused" in e:
            L.append(f"  {name}: no gains: {e['refused']}")
            continue
        lg, nw = e["logged"], e["new"]
        L.append(f"  {name} logged   P {lg['gains']['kp']:.4g} I {lg['gains']['ki']:.4g} D {lg['gains']['kd']:.4g}: "
                 + fig(lg))
        tag = "new     " if e["recommended"] else "step    " if e.get("step") else "nearest "
        L.append(f"  {name} {tag} " + " ".join(f"{k[1].upper()} {v:.4g}" for k, v in nw["gains"].items()) + " ("
                 + ", ".join(f"x{v:.3g}" for v in nw["factors"].values()) + "): " + fig(nw))
        if not e["recommended"]:
            L.append(f"  {name}: no gains: {e['why']}")
        if e.get("extrapolated"):
            L.append(f"  {name}: note: {e['extrapolated']}")
    if "refused" in report:
        L.append(f"refused: {report['refused']}")
    return "\n".join(L) + "\n"


def _f(s: dict, nd: int = 3, ms: bool = False, pct: bool = False) -> str:
    def one(x):
        if x is None:
            return "-"
        return f"{1e3 * x:.3g}" if ms else f"{100 * x:.3g}" if pct else f"{x:.{nd}g}"
    return f"{one(s['median'])} / {one(s['worst'])}"


def main(args, a) -> int:
    """`flightctl tune --from-log` (tune.py's parser): 0 with gains for at least one axis, 1 when every axis is
    refused (the check failed, or no gains meet the targets)."""
    import sys

    from flightctl.files import write_atomic
    from flightctl.sim.diagnose.cli import read_logs
    t0 = time.process_time()
    say = (lambda m: print(f"tune --from-log: {m}", file=sys.stderr)) if not args.quiet else (lambda m: None)

    def one(path, what):
        tables = read_logs([path], args.index, lambda m: None,    # quiet until the logs are read: bad input is one line
                           extra=steps.LOOPS[0].setpoint)         # a CSV log's rate setpoint, where it has one
        if len(tables) != 1:
            raise InputError(f"{what} {path}: {len(tables)} logs in the file; name one with --index")
        return tables[0]
    table = one(args.from_log, "--from-log")
    other = one(args.check_on, "--check-on") if args.check_on else None
    tg = Targets(args.target_pm, args.target_gm, args.ms, args.overshoot,
                 None if args.rise_ms is None else args.rise_ms / 1e3, args.max_change)
    report = from_log(table, a, tg, other, args.draws, args.seed, say)
    report["cpu_s"] = round(time.process_time() - t0, 1)
    sys.stdout.write(text(report))
    new = recommended(report)
    step = next_pass(report)
    if step:
        suffix, lines = paste(ctl.of_table(table), step)
        if step != new:
            lines = ("# a pass toward the targets, not gains that meet them: fly these, then tune again from the log "
                     f"(the axes: {', '.join(steps.NAMES[ax] for ax in step if ax not in new)})\n") + lines
        sys.stdout.write(lines)
        if args.out:
            write_atomic(args.out, lines)
            print(f"  lines -> {args.out}")
    if args.json:
        write_atomic(args.json, json.dumps(report, indent=1, default=float) + "\n")
        print(f"  report -> {args.json}")
    print(f"  {report['cpu_s']:.1f} s of CPU")
    return 0 if new else 1
