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
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
from pathlib import Path

import numpy as np

from flightctl.errors import InputError, output_file
from flightctl.params import TABLE4, Gains, dumps

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
    from flightctl.sim.analyze import TRUTH, analyse
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
                     "table4": {"kp": getattr(TABLE4, kp_name), "kd": getattr(TABLE4, kd_name)}}
        if progress:
            progress(f"{ch}: kd {kd:.4g}: an overshoot of {100 * found[ch]['overshoot']:.1f} %, then none")
    return gains, found


def plot(params, gains: Gains, path) -> None:
    """The tuned gains and Table 4 flown through the nonlinear simulator with perfect state feedback:
    the step of each channel (figures 13-16)."""
    import tempfile

    from flightctl.sim.metrics import TRUE
    from flightctl.sim.plots import figure, legend, save
    from flightctl.sim.run import fly
    from flightctl.sim.scenarios import SCENARIOS
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


def main(argv: list[str] | None = None) -> int:
    from flightctl.sim import causes
    p = argparse.ArgumentParser(prog="flightctl tune", description=__doc__.split("\n\n")[0].replace("\n", " "))
    p.add_argument("--params", help="parameter file or shipped vehicle (default: the reference airframe)")
    p.add_argument("--out", required=True, metavar="GAINS.toml", help="the parameter file to write, with the tuned [gains]")
    p.add_argument("--json", metavar="T.json", help="what was found per channel, with Table 4 beside it")
    p.add_argument("--plot", metavar="P.png", help="the tuned gains and Table 4 flown through the simulator")
    p.add_argument("--strict", action="store_true",
                   help="read 'no oscillation remains' as no overshoot beyond the allowable error either")
    args = p.parse_args(argv)
    out = output_file(args.out, "--out", ".toml")
    if args.json:
        output_file(args.json, "--json")
    if args.plot:
        output_file(args.plot, "--plot", ".png")
    params = causes.load_vehicle(args.params)
    if params.effects:
        print("flightctl tune: the plant carries " + ", ".join(e.cause for e in params.effects)
              + "; the linearised loops include them", file=sys.stderr)
    gains, found = tune(params, lambda m: print(f"tune {m}", file=sys.stderr, flush=True), args.strict)
    src = {f"{k}_{NAME[ch]}": f"flightctl tune (paper sec. 3.3 automated: {OSCILLATIONS[ch]} oscillations "
           f"in {SETTLE_S:g} s, then no oscillation beyond {TOLERANCE[ch] if ch == 'alt' else 0.1:g} "
           f"{'m' if ch == 'alt' else 'deg'}); Table 4: {getattr(TABLE4, f'{k}_{NAME[ch]}'):g}"
           for ch in ORDER for k in ("kp", "ki", "kd")}
    out.write_text("# Gains tuned by flightctl tune on " + (args.params or "the reference airframe") + "\n"
                   + dumps(dataclasses.replace(params, gains=gains), src, tables=("gains",)))
    print("channel   kp (tuned / Table 4)    kd (tuned / Table 4)")
    for ch in ORDER:
        f = found[ch]
        print(f"{ch:<8} {f['kp']:8.3f} / {f['table4']['kp']:<8g}    {f['kd']:8.3f} / {f['table4']['kd']:<8g}")
    print(f"  -> {out}")
    if args.json:
        Path(args.json).write_text(json.dumps(found, indent=1) + "\n")
    if args.plot:
        plot(params, gains, args.plot)
        print(f"  plot -> {args.plot}")
    return 0
