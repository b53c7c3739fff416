"""`flightctl tune [--params P] --out GAINS.toml [--plot P.png] [--json T.json]`: the paper's PID tuning
procedure (section 3.3), automated on the simulator's model.

The paper's words: with ki = 0, "kp is manually increased until the desired number of oscillations
is reached. Then kd is manually increased until no oscillation remains"; the settling period 3 s;
the desired oscillations 1 for the altitude, 2 for the yaw, 11 for the roll and pitch; the allowable
error 1 cm and 0.1 degree; "a single initial overshoot is allowed"; the steps 2 m, 5 and 30 degrees;
the altitude first with the other controllers off, then roll and pitch with it, then the yaw with
all of them. Read here as:

- the oscillations: whole periods of the step response within the 3 s settling period (two crossings
  of the target each), so kp is the smallest that gives N of them (bisection: their number grows
  with kp);
- no oscillation remaining: after the single initial overshoot the response never falls back below
  the target by more than the allowable error, so kd is the smallest that keeps it there (bisection);
  `--strict`: not even the first overshoot passes the allowable error.

Each response is the loop of `flightctl analyze` with perfect state feedback (sim/analysis: the
model linearised about the hover at 1.5 m, sampled at 450 Hz, the PID of eq. 24 as the loop runs it),
the paper's own simulation setting; the tuned gains are then flown through the nonlinear simulator
(the figure). ki stays 0, as in Table 4.

`--robust N`: the procedure's gains are a point answer on one model; the parameter file's ranges
(`range.NAME = [lo, hi]`, `--params paper-as-flown`) say the model is not known that well. The robust
mode takes N draws of those ranges and flies the scenario's attitude steps on the batched simulator
(sim/sweeps/batch.py, the Monte Carlo's `--batch` setting) with the roll and pitch gains scaled, kp and kd
each by a factor on a grid, every candidate on the same draws, each flight to its landing, judged as the
Monte Carlo judges (sim/sweeps/judge.py: it flies and lands upright; each step's ringing, the true
angle's peak-to-peak once the step has arrived, and the controller's held error, both apart from the
estimator's bias, which no gains remove). The candidate that holds (flies, and every step rings and
holds within its band) in the largest share of the draws wins, then the one that flies in the largest
share, then the lowest median score (the worst ringing over its band); a second, finer grid around it
refines it, and the altitude and yaw gains stay the procedure's. Among candidates that tie, the least
change from the procedure's gains wins (the factors nearest 1). Table 4 and Table 6 are flown on the
same draws beside them.
"""
from __future__ import annotations

import dataclasses
import json
import math
import sys
from pathlib import Path

import numpy as np

from flightctl.errors import InputError, Parser, seed

from flightctl.files import output_file, write_atomic
from flightctl.params import TABLE4, TABLE6, Gains, dumps
from flightctl.sim import engine
from flightctl.sim.sweeps import fromlog

SETTLE_S = 3.0
STEPS = {"alt": 2.0, "roll": math.radians(5), "pitch": math.radians(5), "yaw": math.radians(30)}
OSCILLATIONS = {"alt": 1, "roll": 11, "pitch": 11, "yaw": 2}
TOLERANCE = {"alt": 0.01, "roll": math.radians(0.1), "pitch": math.radians(0.1), "yaw": math.radians(0.1)}
ORDER = ("alt", "roll", "pitch", "yaw")
NAME = {"alt": "z", "roll": "phi", "pitch": "theta", "yaw": "psi"}
KP_MAX, KD_MAX = 100.0, 100.0   # the parameter schema's limits
KD_MAX_STRICT = 5.0             # a kd far past the overshoot-free one destabilises the sampled loop again
ITERATIONS = 30                 # bisection steps: 100 / 2^30, far below the gains' printed digits


def _response(params, gains: Gains, channel: str):
    """(t, y): the unit step response of `channel` with perfect state feedback over SETTLE_S."""
    from flightctl.sim.analysis.cli import TRUTH, analyse
    with np.errstate(over="ignore", invalid="ignore"):      # a loop with kd = 0 may grow without bound
        an = analyse(dataclasses.replace(params, gains=gains), (), estimators=(TRUTH,), channels=(channel,),
                     horizon=SETTLE_S)
    loop = an.loops[TRUTH][channel]
    return loop.t, loop.y


def oscillations(t, y) -> float:
    """How many periods of the response's oscillation fit in SETTLE_S: SETTLE_S over the period its
    crossings of the target (1 for a unit step) give within SETTLE_S, two a period; 0 with fewer than
    two crossings. (Counting whole periods from the step instead would count the first quarter period
    too, and put the threshold at a lower kp.)"""
    sel = t <= SETTLE_S
    e = y[sel] - 1.0
    if not np.all(np.isfinite(e)):
        return math.inf                        # grown past any number: an unstable loop
    k = np.flatnonzero(np.sign(e[1:]) * np.sign(e[:-1]) < 0)
    if k.size < 2:
        return 0.0
    tc = t[sel][k] - e[k] * (t[sel][k + 1] - t[sel][k]) / (e[k + 1] - e[k])   # interpolated crossings
    return float(SETTLE_S / (2.0 * np.mean(np.diff(tc))))


def oscillation_remains(t, y, tol: float) -> bool:
    """After the first overshoot's peak, the response falls back below the target by more than `tol`
    (relative to the step) within SETTLE_S: the single initial overshoot is allowed, nothing after it."""
    y = y[t <= SETTLE_S]
    above = np.flatnonzero(y > 1.0)
    if not above.size:
        return False
    peak = above[0] + int(np.argmax(y[above[0]:]))
    return bool(np.any(y[peak:] < 1.0 - tol))


def _bisect(ok, lo: float, hi: float) -> float:
    """The smallest x in [lo, hi] with ok(x), ok monotone (false below, true above)."""
    if not ok(hi):
        raise InputError(f"no gain up to {hi:g} meets the criterion")
    for _ in range(ITERATIONS):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if ok(mid) else (mid, hi)
    return hi


def overshoots(t, y, tol: float) -> bool:
    """The strict reading of "no oscillation": the response overshoots the target by more than `tol`."""
    return bool(np.max(y[t <= SETTLE_S]) > 1.0 + tol)


def tune(params, progress=None, strict: bool = False) -> tuple[Gains, dict]:
    """The procedure, channel after channel: (the gains, per channel what was found). `strict`: kd
    until not even the first overshoot passes the allowable error."""
    remains = overshoots if strict else oscillation_remains
    zero = {f"{k}_{NAME[ch]}": 0.0 for ch in ORDER for k in ("kp", "ki", "kd")}
    gains = Gains(**zero)
    found = {}
    for ch in ORDER:
        n, tol = OSCILLATIONS[ch], TOLERANCE[ch] / STEPS[ch]
        kp_name, kd_name = f"kp_{NAME[ch]}", f"kd_{NAME[ch]}"

        def count(kp):
            return oscillations(*_response(params, dataclasses.replace(gains, **{kp_name: kp, kd_name: 0.0}), ch))
        kp = _bisect(lambda kp: count(kp) >= n, 0.0, KP_MAX)
        if progress:
            progress(f"{ch}: kp {kp:.4g} gives {count(kp):.2f} oscillations in {SETTLE_S:g} s")
        kd = _bisect(lambda kd: not remains(*_response(
            params, dataclasses.replace(gains, **{kp_name: kp, kd_name: kd}), ch), tol), 0.0, KD_MAX_STRICT if strict else KD_MAX)
        gains = dataclasses.replace(gains, **{kp_name: kp, kd_name: kd})
        t, y = _response(params, gains, ch)
        found[ch] = {"kp": kp, "kd": kd, "oscillations_at_kp": count(kp), "overshoot": float(np.max(y) - 1.0),
                     "table4": {"kp": getattr(TABLE4, kp_name), "kd": getattr(TABLE4, kd_name),
                                "oscillations_at_kp": count(getattr(TABLE4, kp_name))}}
        if progress:
            progress(f"{ch}: kd {kd:.4g}: an overshoot of {100 * found[ch]['overshoot']:.1f} %, then none")
    return gains, found


COARSE = (0.2, 0.3, 0.45, 0.7, 1.0, 1.5)   # factors on the procedure's roll and pitch kp and kd
FINE = (0.8, 0.9, 1.0, 1.12, 1.25)         # ... then on the coarse grid's best


def scaled(gains: Gains, kp: float, kd: float) -> Gains:
    """The roll and pitch kp and kd times these factors."""
    return dataclasses.replace(gains, kp_phi=gains.kp_phi * kp, kp_theta=gains.kp_theta * kp,
                               kd_phi=gains.kd_phi * kd, kd_theta=gains.kd_theta * kd)


def shares(params, candidates: list[Gains], n: int, seed: int = 0, scenario: str = "paper", workers=None,
           progress=None) -> list[dict]:
    """Per candidate, over n draws of the file's ranges on the batched simulator (every candidate on
    the same draws, each flown to the plan's end), judged as the Monte Carlo judges
    (sim/sweeps/judge.py): the shares that fly (and land upright) and that hold (fly, and every
    attitude step rings and holds within its band, apart from the estimator's bias), and the median
    score (the worst ringing over the bands; None when most draws do not fly). `progress`: a
    sim/progress.py Progress, one step a candidate, the vehicle-steps in between."""
    import os

    from flightctl.sim.sweeps import judge
    from flightctl.sim.sweeps.batch import simulate
    from flightctl.sim.sweeps.montecarlo import _batch_window, draw, ranged
    from flightctl.sim.flights.scenarios import SCENARIOS
    spans = ranged(params)
    if not spans:
        raise InputError("--robust: the parameter file carries no ranges (range.NAME = [lo, hi]; "
                         "--params paper-as-flown has them)")
    sc = SCENARIOS[scenario]()
    start, end, steps = _batch_window(sc)
    draws = draw(params, n, seed)
    per = max(1, 400 // n)             # candidates per batch: at least 400 vehicles at once
    out = []
    for i in range(0, len(candidates), per):
        group = candidates[i:i + per]
        under_way = f"candidates {i + 1}-{i + len(group)} of {len(candidates)}: {n * len(group)} vehicles"
        frac = (lambda f: progress.update(f, under_way, len(group))) if progress else None
        # each draw with its seed, the same vehicle for every candidate, flown from power-on to its landing
        flight = simulate(params, sc.plan, n * len(group), {k: np.tile(v, len(group)) for k, v in draws.items()},
                          [g for g in group for _ in range(n)], seeds=[seed + k for k in range(n)] * len(group),
                          record=(start, end), workers=workers or os.cpu_count() or 1, progress=frac)
        flies = flight.flies
        figures = judge.step_figures(flight.log, steps, 0.0)
        held = judge.holds(figures, flies)
        score = np.where(flies, judge.score(figures), np.inf)
        for j in range(len(group)):
            part = slice(j * n, (j + 1) * n)
            median = float(np.median(score[part]))
            out.append({"flies": float(flies[part].mean()), "holds": float(held[part].mean()),
                        "score": median if math.isfinite(median) else None})
            if progress:
                progress.step(f"candidate {len(out)}/{len(candidates)}: holds {100 * out[-1]['holds']:.0f} %")
    return out


def robust(params, base: Gains, n: int, seed: int = 0, progress=None, workers=None,
           scenario: str = "paper") -> tuple[Gains, dict]:
    """The module docstring's robust mode, from the gains `base`: (the gains, what was found)."""
    grid = [(kp, kd) for kp in COARSE for kd in COARSE]
    coarse = shares(params, [scaled(base, kp, kd) for kp, kd in grid] + [TABLE4, TABLE6], n, seed, scenario,
                    workers=workers, progress=progress)
    coarse, table4, table6 = coarse[:-2], coarse[-2], coarse[-1]

    def best(points, results):
        # the largest share that holds, then that flies, then the lowest median score, then the least
        # change from the procedure
        return max(zip(points, results), key=lambda pr: (
            pr[1]["holds"], pr[1]["flies"], -(math.inf if pr[1]["score"] is None else pr[1]["score"]),
            -abs(math.log(pr[0][0])) - abs(math.log(pr[0][1]))))
    (kp0, kd0), _ = best(grid, coarse)
    fine_grid = [(kp0 * a, kd0 * b) for a in FINE for b in FINE if (a, b) != (1.0, 1.0)]
    fine = shares(params, [scaled(base, kp, kd) for kp, kd in fine_grid], n, seed, scenario, workers=workers,
                  progress=progress)
    (kp, kd), won = best(grid + fine_grid, coarse + fine)
    return scaled(base, kp, kd), {"draws": n, "seed": seed, "kp_factor": kp, "kd_factor": kd, **won,
                                  "procedure_gains": dataclasses.asdict(base),
                                  "procedure": coarse[grid.index((1.0, 1.0))], "table4": table4, "table6": table6,
                                  "table6_factors": (TABLE6.kp_phi / base.kp_phi, TABLE6.kd_phi / base.kd_phi),
                                  "grid": [{"kp_factor": a, "kd_factor": b, **r} for (a, b), r in zip(grid + fine_grid, coarse + fine)]}


def robust_plot(found: dict, path) -> None:
    """Over the grid of factors on the procedure's roll and pitch kp and kd: the share that holds, and
    the median score (the worst ringing over its band, of the draws that fly)."""
    from flightctl.sim.plots import figure, save
    fig, ax = figure(1, 2, size=(13.0, 5.5))
    pts = found["grid"]
    kp, kd = [p["kp_factor"] for p in pts], [p["kd_factor"] for p in pts]
    worst = max([p["score"] for p in pts if p["score"] is not None] + [1.0])
    most = max(10.0, 100 * max(p["holds"] for p in pts))
    panels = ((ax[0, 0], [100 * p["holds"] for p in pts], "holds (% of the draws)", "viridis", 0.0, most, "holds"),
              (ax[0, 1], [p["score"] if p["score"] is not None else np.nan for p in pts],
               "median score (worst ringing / band; blank: most draws crash)", "magma_r", 0.0, worst, "score"))
    for a, colour, label, cmap, lo, hi, key in panels:
        sc = a.scatter(kp, kd, c=colour, cmap=cmap, vmin=lo, vmax=hi, s=60, edgecolors="k", linewidths=0.3,
                       plotnonfinite=True)
        fig.colorbar(sc, ax=a, label=label)

        def said(r):
            v = r[key]
            return "none fly" if v is None else f"{100 * v:.0f} %" if key == "holds" else f"{v:.2g}"
        a.plot([found["kp_factor"]], [found["kd_factor"]], "r*", ms=16, label=f"chosen: {said(found)}")
        a.plot([1.0], [1.0], "ks", ms=8, mfc="none", label=f"the procedure's: {said(found['procedure'])}")
        a.plot(*found["table6_factors"], "wD", ms=8, mec="k", label=f"Table 6 (roll): {said(found['table6'])}")
        a.set_xscale("log")
        a.set_yscale("log")
        a.set_xlabel("factor on roll and pitch kp")
        a.set_ylabel("factor on roll and pitch kd")
        a.legend(fontsize=8)
        a.grid(alpha=0.3, which="both")
    fig.suptitle(f"flightctl tune --robust {found['draws']}: Table 4 flies in {100 * found['table4']['flies']:.0f} %, "
                 f"holds in {100 * found['table4']['holds']:.0f} %", fontsize=10)
    save(fig, path)


def plot(params, gains: Gains, path) -> None:
    """The tuned gains and Table 4 flown through the nonlinear simulator with perfect state feedback:
    the step of each channel (figures 13-16)."""
    import tempfile

    from flightctl.sim.flights.metrics import TRUE
    from flightctl.sim.plots import figure, legend, save
    from flightctl.sim.flights.run import fly
    from flightctl.sim.flights.scenarios import SCENARIOS
    fig, ax = figure(2, 2, size=(11.0, 7.5))
    with tempfile.TemporaryDirectory() as tmp:
        for a, ch, sc_name in zip(ax.ravel(), ORDER, ("step_alt", "step_roll", "step_pitch", "step_yaw")):
            for label, g in (("tuned", gains), ("Table 4", TABLE4)):
                sc = SCENARIOS[sc_name]()
                f = fly(sc, dataclasses.replace(params, gains=g), Path(tmp) / "f.csv", truth=True, noise=False)
                s = sc.steps[0]
                t = f.log["t"] - f.t_arm - s.t
                k = 1.0 if ch == "alt" else 180.0 / math.pi
                sel = (t >= -0.5) & (t <= 4.0)
                a.plot(t[sel], f.log[TRUE[ch]][sel] * k, label=f"{label}: {f.outcome}")
            a.axhline(s.end * k, color="0.4", lw=0.8)
            a.set_title(f"{ch} step ({'m' if ch == 'alt' else 'deg'})")
            a.set_xlabel("time after the step (s)")
            a.grid(alpha=0.3)
            legend(a)
    fig.suptitle("flightctl tune: the paper's procedure (sec. 3.3) against Table 4, perfect state feedback")
    save(fig, path)


LABEL = {"alt": "altitude", "roll": "roll", "pitch": "pitch", "yaw": "yaw"}


def doc_block(found: dict, strict: bool, command: str) -> tuple[str, str]:
    """(marker name, markdown) of what `tune` found, for docs/tune.md (`--doc`): the procedure's gains
    against Table 4 (`tune procedure`), the strict reading's kd (`tune strict`), or the robust search's
    shares (`tune robust`), with the command that wrote it."""
    pct = lambda a, b: f"{100 * a / b:.0f} %"   # noqa: E731
    if "robust" in found:
        r = found["robust"]
        g0 = r["procedure_gains"]
        rows = [("the procedure (base model)", g0["kp_phi"], g0["kp_theta"], g0["kd_phi"], g0["kd_theta"], r["procedure"]),
                ("Table 4", TABLE4.kp_phi, TABLE4.kp_theta, TABLE4.kd_phi, TABLE4.kd_theta, r["table4"]),
                ("Table 6 (retuned on the vehicle)", TABLE6.kp_phi, TABLE6.kp_theta, TABLE6.kd_phi, TABLE6.kd_theta,
                 r["table6"]),
                (f"**robust** (kp x {r['kp_factor']:.2g}, kd x {r['kd_factor']:.2g})", g0["kp_phi"] * r["kp_factor"],
                 g0["kp_theta"] * r["kp_factor"], g0["kd_phi"] * r["kd_factor"], g0["kd_theta"] * r["kd_factor"], r)]
        lines = [f"`{command}`: {len(r['grid'])} candidates, each on the same {r['draws']} draws (seed {r['seed']}), "
                 "flown to their landing and judged as the Monte Carlo judges.", "",
                 "| roll / pitch gains | kp | kd | flies | holds | median score |", "|---|---|---|---|---|---|"]
        for name, kpp, kpt, kdp, kdt, res in rows:
            score = "- (most crash)" if res["score"] is None else f"{res['score']:.2f}"
            lines.append(f"| {name} | {kpp:.3g} / {kpt:.3g} | {kdp:.3g} / {kdt:.3g} | {100 * res['flies']:.0f} % | "
                         f"{100 * res['holds']:.0f} % | {score} |")
        return "tune robust", "\n".join(lines)
    if strict:
        lines = [f"`{command}`:", "", "| channel | kd strict / Table 4 | of Table 4's | overshoot |", "|---|---|---|---|"]
        for ch in ORDER:
            f = found[ch]
            lines.append(f"| {LABEL[ch]} | {f['kd']:.3g} / {f['table4']['kd']:g} | {pct(f['kd'], f['table4']['kd'])} | "
                         f"{100 * f['overshoot']:.1f} % |")
        return "tune strict", "\n".join(lines)
    lines = [f"`{command}`:", "",
             "| channel | kp tuned / Table 4 | of Table 4's | oscillations in 3 s: tuned kp / Table 4's | "
             "kd tuned / Table 4 | of Table 4's | overshoot |", "|---|---|---|---|---|---|---|"]
    for ch in ORDER:
        f, t4 = found[ch], found[ch]["table4"]
        lines.append(f"| {LABEL[ch]} | {f['kp']:.3g} / {t4['kp']:g} | {pct(f['kp'], t4['kp'])} | "
                     f"{f['oscillations_at_kp']:.2f} / {t4['oscillations_at_kp']:.2f} | {f['kd']:.3g} / {t4['kd']:g} | "
                     f"{pct(f['kd'], t4['kd'])} | {100 * f['overshoot']:.1f} % |")
    return "tune procedure", "\n".join(lines)


def _from_log(args) -> int:
    """`--from-log`: its flags checked before any work, then sim/sweeps/fromlog.py."""
    from flightctl import params as paramfile
    bad = [f for f in ("robust", "strict", "plot", "doc", "params") if getattr(args, f) not in (None, False)]
    if bad:
        raise InputError(f"--from-log: --{bad[0]} is not for it (it tunes the logged firmware's rate loop)")
    for name, v, lo, hi in (("--target-pm", args.target_pm, 0.0, 90.0), ("--target-gm", args.target_gm, 0.0, 40.0),
                            ("--ms", args.ms, 1.0, 10.0), ("--overshoot", args.overshoot, 0.0, 2.0),
                            ("--max-change", args.max_change, 1.0, 10.0), ("--draws", args.draws, 1, 10000),
                            ("--rise-ms", args.rise_ms if args.rise_ms is not None else 1.0, 0.1, 10000.0)):
        if not (math.isfinite(v) and lo <= v <= hi):
            raise InputError(f"{name} {v:g}: between {lo:g} and {hi:g}")
    if args.index is not None and args.index < 1:
        raise InputError(f"--index {args.index}: 1 or more")
    for flag, f in (("--from-log", args.from_log), ("--check-on", args.check_on)):
        if f is not None and not Path(f).is_file():
            raise InputError(f"{flag} {f}: " + ("is a directory, a flight log is needed" if Path(f).is_dir() else "no such file"))
    if args.out:
        output_file(args.out, "--out")
    if args.json:
        output_file(args.json, "--json", ".json")
    return fromlog.main(args, paramfile.load(None).airframe)


def main(argv: list[str] | None = None) -> int:
    from flightctl.sim import causes
    from flightctl.sim.sweeps.montecarlo import ranged
    p = Parser(prog="flightctl tune", description=__doc__.split("\n\n")[0].replace("\n", " "))
    p.add_argument("--params", help="parameter file or shipped vehicle (default: the reference airframe)")
    p.add_argument("--out", metavar="GAINS.toml", help="the parameter file to write, with the tuned [gains] (with "
                   "--from-log: the lines to paste, in the log's firmware's terms)")
    p.add_argument("--json", metavar="T.json", help="what was found per channel, with Table 4 beside it")
    p.add_argument("--plot", metavar="P.png", help="the tuned gains and Table 4 flown through the simulator")
    p.add_argument("--strict", action="store_true",
                   help="read 'no oscillation remains' as no overshoot beyond the allowable error either")
    p.add_argument("--robust", type=int, metavar="N",
                   help="then scale the roll and pitch gains for the largest share of N draws of the file's ranges "
                        "that flies and holds each step, as the Monte Carlo judges (batched simulator; "
                        "--plot also draws the grid)")
    p.add_argument("--seed", type=seed, default=0, help="seed of the --robust draws (a whole number from 0)")
    p.add_argument("--scenario", default="paper", help="the scenario whose attitude steps --robust flies (default: paper)")
    p.add_argument("--doc", metavar="FILE.md", help="write what was found into FILE's block (<!-- tune procedure: "
                   "begin --> ... end -->, or tune strict, tune robust: docs/tune.md)")
    engine.add_flag(p, "with --robust")
    g = p.add_argument_group("gains from a flight log (--from-log, docs/tune.md; exit 1: every axis refused)")
    g.add_argument("--from-log", metavar="LOG", help="a flight log (Betaflight blackbox, or any diagnose reads): the "
                   "vehicle identified from it, its logged gains checked against its steps, new gains for the models "
                   "it leaves plausible")
    g.add_argument("--check-on", metavar="LOG2", help="check the model of the whole LOG on this log of the same vehicle "
                   "(flown with its own gains) instead of LOG's second half")
    g.add_argument("--index", type=int, help="which log of a blackbox file of many (1 = the first)")
    g.add_argument("--target-pm", type=float, default=fromlog.TARGETS["pm_deg"], metavar="DEG",
                   help="the least phase margin over the plausible models (default %(default)g)")
    g.add_argument("--target-gm", type=float, default=fromlog.TARGETS["gm_db"], metavar="DB",
                   help="the least gain margin (default %(default)g dB)")
    g.add_argument("--ms", type=float, default=fromlog.TARGETS["ms"], help="the largest peak sensitivity (default %(default)g)")
    g.add_argument("--overshoot", type=float, default=fromlog.TARGETS["overshoot"], metavar="SHARE",
                   help="the largest step overshoot, a share (default %(default)g)")
    g.add_argument("--rise-ms", type=float, metavar="MS", help="the slowest median rise (10-90 %%) allowed (default: "
                   "none; the fastest that meets the other targets wins)")
    g.add_argument("--max-change", type=float, default=2.0, metavar="X",
                   help="each gain changes at most by this factor either way (default %(default)g)")
    g.add_argument("--draws", type=int, default=fromlog.DRAWS, help="plausible models drawn per axis (default %(default)d)")
    g.add_argument("--quiet", action="store_true", help="no progress lines")
    args = p.parse_args(argv)
    if args.from_log is not None:
        return _from_log(args)
    if args.out is None:
        raise InputError("--out GAINS.toml is needed (or --from-log LOG)")
    engine.use(args.scheduler)
    if args.robust is not None and not 1 <= args.robust <= 10000:
        raise InputError(f"--robust {args.robust}: between 1 and 10000 draws")
    from flightctl.sim.flights.scenarios import SCENARIOS
    if args.scenario not in SCENARIOS:
        raise InputError(f"--scenario {args.scenario}: not a named scenario ({', '.join(sorted(SCENARIOS))})")
    out = output_file(args.out, "--out", ".toml")
    if args.json:
        output_file(args.json, "--json", ".json")
    if args.plot:
        output_file(args.plot, "--plot", ".png")
    if args.doc:
        from flightctl.sim.docs import block, marked
        begin, end = marked("tune robust" if args.robust else "tune strict" if args.strict else "tune procedure")
        if not Path(args.doc).is_file() or block(Path(args.doc).read_text(), begin, end) is None:
            raise InputError(f"--doc {args.doc}: no block {begin} ... {end} in it")
        output_file(args.doc, "--doc", ".md")
    params = causes.load_vehicle(args.params)
    if params.effects:
        print("flightctl tune: the plant carries " + ", ".join(e.cause for e in params.effects)
              + "; the linearised loops include them", file=sys.stderr)
    from flightctl.sim.progress import Progress
    if args.robust is not None and not ranged(params):
        raise InputError(f"--robust: {args.params or 'the reference airframe'} carries no ranges "
                         "(range.NAME = [lo, hi]; --params paper-as-flown has them)")
    bar = Progress(len(ORDER) * 2, "tune: the procedure ")
    if args.robust and params.effects:   # the procedure on the paper's model, then robust over the ranges
        print("flightctl tune --robust: the procedure runs on the base model (the paper's), the robust "
              "search over the file's ranges", file=sys.stderr)
        gains, found = tune(dataclasses.replace(params, effects=()), bar.step, args.strict)
    else:
        gains, found = tune(params, bar.step, args.strict)
    src = {f"{k}_{NAME[ch]}": f"flightctl tune (paper sec. 3.3 automated: {OSCILLATIONS[ch]} oscillations "
           f"in {SETTLE_S:g} s, then no oscillation beyond {TOLERANCE[ch] if ch == 'alt' else 0.1:g} "
           f"{'m' if ch == 'alt' else 'deg'}); Table 4: {getattr(TABLE4, f'{k}_{NAME[ch]}'):g}"
           for ch in ORDER for k in ("kp", "ki", "kd")}
    if args.robust:
        procedure = gains
        bar = Progress(len(COARSE) ** 2 + 2 + len(FINE) ** 2 - 1, f"tune --robust {args.robust}: ")
        gains, rob = robust(params, procedure, args.robust, args.seed, progress=bar, scenario=args.scenario)
        found["robust"] = rob
        for k in ("kp", "kd"):
            for ax in ("phi", "theta"):
                name = f"{k}_{ax}"
                src[name] = (f"flightctl tune --robust {args.robust}: the procedure's {getattr(procedure, name):.4g} "
                             f"x {rob[k + '_factor']:.3g}, holds in {100 * rob['holds']:.0f} % and flies in "
                             f"{100 * rob['flies']:.0f} % of the draws of {args.params}'s ranges (the procedure's "
                             f"{100 * rob['procedure']['holds']:.0f} % and {100 * rob['procedure']['flies']:.0f} %, "
                             f"Table 4 {100 * rob['table4']['holds']:.0f} % and {100 * rob['table4']['flies']:.0f} %); "
                             f"Table 4: {getattr(TABLE4, name):g}")
    write_atomic(out, "# Gains tuned by flightctl tune on " + (args.params or "the reference airframe") + "\n"
                 + dumps(dataclasses.replace(params, gains=gains), src, tables=("gains",)))
    print("channel   kp (tuned / Table 4)    kd (tuned / Table 4)")
    for ch in ORDER:
        kp, kd = f"kp_{NAME[ch]}", f"kd_{NAME[ch]}"
        print(f"{ch:<8} {getattr(gains, kp):8.3f} / {getattr(TABLE4, kp):<8g}    {getattr(gains, kd):8.3f} / {getattr(TABLE4, kd):<8g}")
    print(f"  gains -> {out}")
    if args.json:
        write_atomic(args.json, json.dumps(found, indent=1) + "\n")
        print(f"  what was found -> {args.json}")
    if args.robust:
        r = found["robust"]
        print(f"robust over {r['draws']} draws: roll and pitch kp x {r['kp_factor']:.3g}, kd x {r['kd_factor']:.3g} "
              f"of the procedure's")
        for name, g in (("robust", r), ("the procedure's", r["procedure"]), ("Table 4", r["table4"]),
                        ("Table 6", r["table6"])):
            print(f"  {name:<16} flies {100 * g['flies']:3.0f} %, holds {100 * g['holds']:3.0f} %, median score "
                  + ("- (most crash)" if g["score"] is None else f"{g['score']:.2f}"))
    if args.doc:
        from flightctl.sim.docs import marked, write_block
        shown = ["flightctl tune", *(argv if argv is not None else sys.argv[1:])]
        skip = {"--out", "--json", "--plot", "--doc"}
        words = [w for k, w in enumerate(shown) if w not in skip and (k == 0 or shown[k - 1] not in skip)]
        name, body = doc_block(found, args.strict, " ".join(words))
        write_block(args.doc, *marked(name), body)
        print(f"  {name} -> {args.doc}")
    if args.plot:
        plot(params, gains, args.plot)
        print(f"  plot -> {args.plot}")
        if args.robust:
            grid = Path(args.plot).with_name(Path(args.plot).stem + "-grid.png")
            robust_plot(found["robust"], grid)
            print(f"  plot -> {grid}")
    return 0
