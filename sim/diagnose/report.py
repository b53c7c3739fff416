"""The human-readable side of `flightctl diagnose`: a text report (residual before and after, its
whiteness, its cross-correlation with each input) and figures (residual against time, residual
against the variable that explains it). matplotlib is imported only when figures are asked for."""
from __future__ import annotations

import math

import numpy as np

from flightctl.sim.diagnose.candidate import Result
from flightctl.sim.diagnose.dataset import CHANNELS, UNITS, C
from flightctl.sim.diagnose.verdict import Diagnosis
from flightctl.sim.diagnose.static import static_text, text as static_section
from flightctl.sim.diagnose.static.centre import centre_text

LB_LAGS = 10          # Ljung-Box lags, on the residual decimated to the low-pass bandwidth
XCORR_MAX_S = 0.25    # cross-correlations are searched over lags within +-this


def _decimate_step(d: Diagnosis) -> int:
    return max(1, int(d.ds.fs_flat / (2.0 * d.lowpass_hz)))


def whiteness(x: np.ndarray, step: int) -> tuple[float, float]:
    """Lag-1 autocorrelation and the Ljung-Box Q(LB_LAGS) of x sampled every `step` samples (the
    residual is low-passed, so its samples closer than the filter's time constant are correlated by
    construction; decimated to twice the bandwidth a white error stays white). Q is about
    chi-square with LB_LAGS degrees of freedom (mean 10, 99th percentile 23) for white noise."""
    y = x[::step] - x[::step].mean()
    n = y.size
    v = float(y @ y)
    if n <= LB_LAGS + 1 or v <= 0:
        return float("nan"), float("nan")
    rho = np.array([float(y[:-k] @ y[k:]) / v for k in range(1, LB_LAGS + 1)])
    q = n * (n + 2) * float(np.sum(rho ** 2 / (n - np.arange(1, LB_LAGS + 1))))
    return float(rho[0]), q


def inputs(d: Diagnosis) -> dict[str, np.ndarray]:
    ds = d.ds
    out = {f"thrust{i + 1}": ds.thrust[i] for i in range(4)}
    out["battery_v"] = ds.V
    out["altitude"] = ds.z
    for name, w in zip(("p", "q", "r"), ds.w):
        out[name] = w
    return out


def xcorr(res: np.ndarray, x: np.ndarray, max_lag: int, step: int) -> float:
    """Largest |normalised cross-correlation| of res with x over lags within +-max_lag samples (every
    `step`-th lag), all lags at once by FFT."""
    from scipy import signal
    ok = np.isfinite(x)
    if ok.sum() < 10:
        return float("nan")
    x = np.where(ok, x, np.nanmean(x))
    a = res - res.mean()
    b = x - x.mean()
    na, nb = np.sqrt(a @ a), np.sqrt(b @ b)
    if na == 0 or nb == 0:
        return float("nan")
    full = signal.correlate(a, b, mode="full", method="fft")       # index n - 1 + lag: sum_k a[k + lag] b[k]
    lags = np.arange(-max_lag, max_lag + 1, step)
    lags = lags[np.abs(lags) < a.size]
    return float(np.max(np.abs(full[a.size - 1 + lags])) / (na * nb))


def text(d: Diagnosis, rep: dict | None = None) -> str:
    """The printed report of `d`; `rep`: its `d.report()`, where the caller has it already."""
    rep = d.report() if rep is None else rep
    if rep.get("tier") == "static":
        return static_text(rep)
    ds = d.ds
    L = []
    L.append(f"flightctl diagnose: {', '.join(rep['data']['files'])}")
    L.append(f"  {ds.seconds:.1f} s airborne, {ds.n} samples kept at {ds.fs_flat:.0f} Hz of the log's {ds.fs:.0f} Hz, "
             f"{len(ds.stretches)} stretch(es)")
    L.append(f"  metric: {rep['metric']}")
    base = ", ".join(f"{e['cause']} {e['parameters']}" for e in d.carried)
    if ds.vehicle.identified:
        L.append("  base model: identified from the flight (another vehicle; docs/real-flights.md), per unit mass "
                 "and inertia, arm lengths as unit:")
        for name, v in rep["base_model"].items():
            if isinstance(v, dict) and "value" in v and "stderr" in v and not isinstance(v["value"], list):
                L.append(f"    {name:<7} {v['value']:>11.5g} +- {v['stderr']:<9.2g} {v['unit']:<22} {v['what']}")
        g = rep["base_model"]["rotor_gain"]
        L.append("    rotor gains (each rotor's thrust against the mean of the four): "
                 + ", ".join(f"{k + 1}: {v:.3f} +- {e:.2g}" for k, (v, e) in enumerate(zip(g["value"], g["stderr"]))))
        bm = rep["base_model"]
        L.append(f"    median command in flight P = {bm['median_P']['value']}; rotors: {bm['layout']['source']}")
    else:
        L.append(f"  base model: the paper's{' with ' + base if base else ''}")
    if (gn := rep["data"]["gyro_noise"]) is not None:
        L.append(f"  gyro noise in flight, above {gn['above_hz']:g} Hz (not a cause; beside the parameter file's [sensors]): "
                 + ", ".join(f"{k} {v:.3g}" for k, v in gn["rms"].items()) + " rad/s rms, as white noise per read "
                 + ", ".join(f"{k} {v:.3g}" for k, v in gn["white_per_read"].items()) + " rad/s")
    L.append("")
    L.append(f"  {'candidate':<16} {'parameters':<34} {'gain':>8} {'t':>7}  {'best channel (gain, t)':<24} named?")
    for c in rep["candidates"]:
        params = ", ".join(f"{k}={v:.4g}" if isinstance(v, (int, float)) else f"{k}={v}"
                           for k, v in c["parameters"].items())
        ch, cg = max(c["channels"].items(), key=lambda kv: -math.inf if kv[1]["gain"] is None else kv[1]["gain"])
        named = "yes" if c["cause"] == d.cause else "significant" if c["significant"] else "no"
        if c["significant"] and c["significant_in"] != "all channels":
            named += f" (in {c['significant_in']})"
        L.append(f"  {c['cause']:<16} {params:<34} {c['gain']:>+8.4f} {c['t_stat']:>7.1f}  "
                 f"{ch + ' ' + format(cg['gain'], '+.3f') + ', ' + format(cg['t'], '.1f'):<24} {named}")
    for nj in rep["not_judged"]:
        L.append(f"  {nj['cause']:<16} not judged: {nj['why']}")
    L.append("")
    if rep["causes"]:
        L.append("  causes, each fitted on top of the ones before it (gain: held-out, over the model before it):")
        for k, c in enumerate(rep["causes"], 1):
            params = ", ".join(f"{n}={v:.4g}" if isinstance(v, (int, float)) else f"{n}={v}"
                               for n, v in c["parameters"].items())
            L.append(f"    {k}. {c['cause']:<16} {params:<34} gain {c['gain']:+.3f} (t = {c['t_stat']:.1f}, "
                     f"in {c['significant_in']}); on top of all the others: gain {c['gain_last']:+.3f}")
        L.append("    (parameters: each cause refitted on top of all the others)")
    if d.cause == "none":
        sig = rep["significance"]
        L.append(f"  verdict: none (no candidate has a held-out gain >= {sig['min_gain']} with t >= "
                 f"{sig['t_crit']}, nor one channel's gain >= {sig['min_channel_gain']} "
                 f"with t >= {sig['t_channel']})")
    else:
        L.append(f"  verdict: {d.cause} {d.parameters}: held-out RMSE {d.rmse_base:.4g} -> {d.rmse_extended:.4g}, "
                 f"gain {d.gain:.3f} (significant in {d.significant[d.cause]})")
    best = next((r for r in d.results if r.cause == d.cause), None)
    for r in rep["not_physical"]:
        params = ", ".join(f"{k}={v:.4g}" if isinstance(v, (int, float)) else f"{k}={v}" for k, v in r["parameters"].items())
        L.append(f"  fits, but not physical: {r['cause']} {params} (gain {r['gain']:+.3f}): {r['why']}")
    check = rep.get("rotor_speed_check")
    if check:
        L.append(f"  check against the log's rotor speeds: commanded speed -> measured, lag {1e3 * check['tau']:.1f} ms "
                 f"(per motor {', '.join(f'{1e3 * t:.0f}' for t in check['per_motor_tau'])} ms) and delay "
                 f"{1e3 * check['delay']:.1f} ms; {check['agreement']['what']}")
    gains = rep.get("rotor_gain_check")
    if gains:
        L.append(f"  rotor gains: {gains['verdict']}: {gains['why']}")
    if com := rep.get("centre_of_mass"):
        L.append(centre_text(com))
    val = rep.get("validation")
    if val:
        L.append(f"  validation on {', '.join(val['files'])} ({val['airborne_s']} s airborne), the model as fitted here: "
                 f"RMSE {val['rmse_base']:.4g} (base) -> {val['rmse_extended']:.4g} (with the causes), gain {val['gain']:+.3f}")
    if rep.get("static"):
        L.append(static_section(rep["static"]))
    L.append("")
    L.append(_residual_table(d, best))
    if d.notes:
        L.append("")
        L += [f"  note: {n}" for n in dict.fromkeys(d.notes)]
    return "\n".join(L) + "\n"


def _residual_table(d: Diagnosis, best: Result | None) -> str:
    step = _decimate_step(d)
    ins = inputs(d)
    max_lag = int(XCORR_MAX_S * d.ds.fs_flat)
    base = d.base.score.residual
    ext = best.score.residual if best is not None else base
    L = ["  held-out residual per channel, base -> extended"
         f"{' (' + best.cause + ')' if best is not None else ''}:",
         f"  {'channel':<7} {'unit':<8} {'RMSE':>21} {'lag-1 acf':>15} {'Ljung-Box Q(10)':>19}  strongest input correlation"]
    for c, (name, unit) in enumerate(zip(CHANNELS, UNITS)):
        rb, re = np.sqrt(np.mean(base[c] ** 2)), np.sqrt(np.mean(ext[c] ** 2))
        a1b, qb = whiteness(base[c], step)
        a1e, qe = whiteness(ext[c], step)
        xb = {k: xcorr(base[c], v, max_lag, step) for k, v in ins.items()}
        xe = {k: xcorr(ext[c], v, max_lag, step) for k, v in ins.items()}
        kb = max(xb, key=lambda k: -1 if np.isnan(xb[k]) else xb[k])
        ke = max(xe, key=lambda k: -1 if np.isnan(xe[k]) else xe[k])
        L.append(f"  {name:<7} {unit:<8} {rb:>9.4g} -> {re:<9.4g} {a1b:>6.2f} -> {a1e:<6.2f} {qb:>8.0f} -> {qe:<8.0f}"
                 f"  {kb} {xb[kb]:.2f} -> {ke} {xe[ke]:.2f}")
    L.append("  (whiteness on the residual decimated to twice the low-pass bandwidth; Q of white noise ~ 10, "
             "99 % below 23; cross-correlation = largest |normalised| over lags within "
             f"+-{XCORR_MAX_S:g} s, against thrust1-4, battery_v, altitude, p, q, r)")
    L.append("  all correlations:")
    for c, name in enumerate(CHANNELS):
        xb = [xcorr(base[c], v, max_lag, step) for v in ins.values()]
        xe = [xcorr(ext[c], v, max_lag, step) for v in ins.values()]
        L.append(f"    {name:<7} " + " ".join(f"{k}={b:.2f}/{e:.2f}" for k, b, e in zip(ins, xb, xe)))
    return "\n".join(L)


CHAIN_COLOURS = ("tab:blue", "tab:green", "tab:purple", "tab:orange", "tab:brown", "tab:pink")


def figures(d: Diagnosis) -> dict[str, bytes]:
    """{"residuals": png, "explained": png}: the held-out residual against time for every channel,
    of the base model and after each cause of the chain (each on top of the ones before it), and
    the base residual of the most changed channel against the variable that explains the first
    cause (or the best candidate when none is named)."""
    from flightctl.sim.plots import empty_panel, figure, figure_legend, legend, png

    ds = d.ds
    best = next((r for r in d.results if r.cause == d.cause), None)
    shown = best if best is not None else (d.results[0] if d.results else None)
    base = d.base.score.residual
    ext = shown.score.residual if shown is not None else base
    steps = d.chain if d.chain else ([shown] if shown is not None else [])
    t = ds.time
    out = {}
    fig, axes = figure(C, 1, size=(9, 11), sharex="col")
    axes = axes[:, 0]
    step = max(1, ds.n // 6000)
    for c, ax in enumerate(axes):
        ax.plot(t[::step], base[c, ::step], ",", color="tab:red", label="base model")
        after = []
        for k, r in enumerate(steps):   # no candidate judged: the base residual alone, not twice
            after.append(r.cause)
            ax.plot(t[::step], r.score.residual[c, ::step], ",", color=CHAIN_COLOURS[k % len(CHAIN_COLOURS)],
                    label="with " + " + ".join(after))
        ax.set_ylabel(f"{CHANNELS[c]}\n[{UNITS[c]}]", fontsize=8)
        ax.tick_params(labelsize=7)
    if steps:
        figure_legend(fig, axes[0], ncol=min(len(steps) + 1, 4))
    axes[0].set_title(("held-out residual of the base model (red) and after each cause of the chain; causes: "
                       + (" + ".join(r.cause for r in d.chain) or "none")) if steps else
                      f"held-out residual of the base model (no candidate could be judged); verdict: {d.cause}",
                      fontsize=9)
    axes[-1].set_xlabel("time in the log [s] (airborne stretches only)")
    out["residuals"] = png(fig)

    fig, axes = figure(size=(9.5, 4.5))   # room for the legend beside the data
    ax = axes[0, 0]
    if shown is not None and shown.explanatory is not None:
        change = np.sqrt(np.mean((base - ext) ** 2, axis=1)) / np.sqrt(np.mean(base ** 2, axis=1))
        c = int(np.argmax(change))
        x = shown.explanatory
        ok = np.isfinite(x)
        s = max(1, ok.sum() // 4000)
        ax.plot(x[ok][::s], base[c][ok][::s], ".", ms=2, color="tab:red", label="base residual")
        ax.plot(x[ok][::s], (base[c] - ext[c])[ok][::s], ".", ms=2, color="tab:blue",
                label=f"what {shown.cause} {shown.parameters} predicts")
        ax.set_xlabel(shown.explains)
        ax.set_ylabel(f"{CHANNELS[c]} [{UNITS[c]}]")
        legend(ax, fontsize=7, markerscale=4)
        ax.set_title(f"residual against the variable that explains it ({CHANNELS[c]})", fontsize=9)
    elif shown is None:
        empty_panel(ax, "Nothing to show: no candidate could be judged on these logs "
                        f"({', '.join(n['cause'] for n in d.not_judged) or 'none'}; the report says why).")
    else:
        empty_panel(ax, f"Nothing to show: {shown.cause} has no single variable that explains the residual.")
    out["explained"] = png(fig)
    return out

