"""The paper flight over every range of `paper-as-flown`, through the full onboard path, judged as the
paper judged its real flights, and written into docs/as-flown.md (between its `as-flown monte carlo`
markers) with its two figures. The shares are the Monte Carlo's (`flightctl sim paper --params
paper-as-flown --monte-carlo N --seed S --json MC.json`, sim/sweeps/montecarlo.py); this script runs
it, or reads its JSON, and renders them.

    python scripts/as_flown_mc.py [--n 200] [--seed 1]      # fly the draws (minutes on two cores)
    python scripts/as_flown_mc.py --batch                   # the same draws on the batched simulator (a minute)
    python scripts/as_flown_mc.py --from docs/as-flown-mc.json    # re-judge a Monte Carlo's JSON, render it

Each draw is judged from its stored per-flight figures (sim/sweeps/judge.py: `verdict`, `bounded`), so a
change of the judgement re-judges the committed JSON without flying it again (`--from`), and writes its
verdicts back. tests/sim/sweeps/test_as_flown_doc.py checks that the docs hold what this renders from that JSON.
"""
from __future__ import annotations

import argparse
import json
import statistics
from pathlib import Path

from flightctl.sim.docs import write_or_exit
from flightctl.sim.progress import Progress
from flightctl.sim.sweeps import judge, montecarlo

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "as-flown.md"
JSON = ROOT / "docs" / "as-flown-mc.json"
BEGIN, END = "<!-- as-flown monte carlo begin -->", "<!-- as-flown monte carlo end -->"
README = ROOT / "README.md"
FACTS_BEGIN, FACTS_END = "<!-- paper facts begin -->", "<!-- paper facts end -->"
BOUND_PNG = DOC.parent / "as-flown-bound.png"
SCALES = [i / 20 for i in range(0, 81)]   # the bound over RING_BOUND_DEG: 0 to 4 times the tuning step
GIVEN_MIN = 10    # draws: the conditional share is drawn where at least this many hold
LANDING = "paper's account, landing only"
ACCOUNT = "paper's account"
NAMES = {"table4": "Table 4 (tuned in simulation)", "table6": "Table 6 (retuned on the vehicle)"}


def _median(values) -> str:
    values = [v for v in values if v is not None]
    return f"{statistics.median(values):.2f}" if values else "-"


def rejudge(result: dict) -> dict:
    """The Monte Carlo's verdicts and shares from its draws' stored figures, by the judge of today
    (sim/sweeps/montecarlo.py's `_result`, which the Monte Carlo itself ends with)."""
    extra = {k: v for k, v in result.items()
             if k not in ("scenario", "params", "n", "seed", "ranges", "share", "paired", "draws")}
    spans = [(r["cause"], r["parameter"], r["lo"], r["hi"]) for r in result["ranges"]]
    return montecarlo._result(result["params"], result["scenario"], result["n"], result["seed"], spans,
                              result["draws"], **extra)


def over_bound(result: dict) -> list[tuple[float, int, int, int, int]]:
    """Per scale of the bound (SCALES, times judge.RING_BOUND_DEG): (scale, draws where Table 4 holds
    within it, where Table 6 does, where the paper's account holds, and the paper's account where
    Table 6 holds)."""
    rows = result["draws"]
    out = []
    for k in SCALES:
        b4 = [judge.bounded(r["table4"], k) for r in rows]
        b6 = [judge.bounded(r["table6"], k) for r in rows]
        account = [judge.verdict(r["table4"], r["table6"], k)["paper's account"] for r in rows]
        out.append((k, sum(b4), sum(b6), sum(account), sum(a for a, b in zip(account, b6) if b)))
    return out


def plot_bound(result: dict, path: Path = BOUND_PNG) -> None:
    """The shares against the bound on the ringing: the curve the README's facts are one point of."""
    from flightctl.sim.plots import figure, save
    n, bank = result["n"], judge.RING_BOUND_DEG["roll"]
    curve = over_bound(result)
    x = [bank * k for k, *_ in curve]
    fig, ax = figure(1, 1, size=(9.0, 5.4))
    a = ax[0, 0]
    a.plot(x, [100 * c[1] / n for c in curve], color="tab:blue", label="Table 4 holds within the bound")
    a.plot(x, [100 * c[2] / n for c in curve], color="tab:orange", label="Table 6 holds within the bound")
    a.plot(x, [100 * c[3] / n for c in curve], color="k", lw=2, label="the paper's account")
    a.plot(x, [100 * c[4] / c[2] if c[2] >= GIVEN_MIN else float("nan") for c in curve], color="k", ls="--",
           label=f"the paper's account, given that Table 6 holds (where {GIVEN_MIN} draws or more do)")
    a.axhline(100 * sum(r[LANDING] for r in result["draws"]) / n, color="grey", ls=":",
              label="the paper's account, landing only (no bound)")
    a.axvline(bank, color="tab:red", lw=0.8, label=f"the bound: sec. 3.3's tuning steps ({bank:g} and "
              f"{judge.RING_BOUND_DEG['yaw']:g} deg)")
    a.set_xlabel(f"bound on a bank's ringing (deg peak-to-peak from {judge.RING_AFTER_S:g} s after its step; "
                 f"a turn's {judge.RING_BOUND_DEG['yaw'] / bank:g} x)")
    a.set_ylabel(f"share of the {n} draws (%)")
    a.set_ylim(0, 100)
    a.grid(alpha=0.3)
    a.legend(loc="upper right", fontsize="small")
    fig.suptitle(f"The shares against the bound on the ringing ({n} draws of {result['params']}, seed "
                 f"{result['seed']})")
    save(fig, path)


def _stored(rows) -> bool:
    """Whether every flown flight of the draws carries its true held error (judge.summary's
    `true_held_deg`: Monte Carlos flown before it was there lack it)."""
    return all("true_held_deg" in r[g][ch] for r in rows for g in montecarlo.GAINS for ch in ("roll", "pitch", "yaw")
               if ch in r[g])


def _true_note(rows) -> str:
    return "" if _stored(rows) else (": this Monte Carlo was flown before judge.summary kept the true held error "
                                     "(`true_held_deg`), so its table has none; it is at most the sum of the two "
                                     "columns before it, and the next Monte Carlo stores it")


def _at(result: dict, scale: float = 1.0) -> tuple[int, int, int, int]:
    k, b4, b6, account, given = next(c for c in over_bound(result) if abs(c[0] - scale) < 1e-9)
    return b4, b6, account, given


def _path(result: dict) -> str:
    """Which simulator flew the draws, as the docs say it."""
    if "simulator" in result:
        return ("the batched simulator (`--batch`: sim/sweeps/batch.py, each draw flown as the full onboard path "
                "flies it, draw for draw: tests/sim/sweeps/test_batch.py)")
    return "the full onboard path"


def headline(result: dict) -> dict:
    """The figures the docs compare across Monte Carlos: per gain set the share that flies and that
    holds, the medians of the worst bank ringing and of the estimator's bank bias; paired, the paper's
    account, where Table 6 holds, by landing alone, and Table 6 beating Table 4."""
    n, rows = result["n"], result["draws"]
    b4, b6, account, given = _at(result)
    out = {"n": n, "paper's account": account / n, "given table6 holds": given / b6 if b6 else None,
           "landing only": sum(r[LANDING] for r in rows) / n,
           "table6 beats table4": result["paired"]["table6 beats table4"]}
    for g, held in (("table4", b4), ("table6", b6)):
        flown = [r[g] for r in rows if r[g]["flies"] and "roll" in r[g]]
        med = lambda key: statistics.median([max(f[ch][key] for ch in ("roll", "pitch")) for f in flown]) \
            if flown else None   # noqa: E731
        out[g] = {"flies": result["share"][g]["flies"], "holds": held / n, "ringing": med("ringing_deg"),
                  "bias": med("bias_deg"), "true held": med("true_held_deg") if _stored(rows) else None}
    return out


def moved(result: dict) -> list[str]:
    """The table of what moved against the Monte Carlo before (`before` in the JSON, `--before`)."""
    b, now = result["before"], headline(result)
    pct = lambda v: "-" if v is None else f"{100 * v:.0f} %"   # noqa: E731
    deg = lambda v: "-" if v is None else f"{v:.2f}"   # noqa: E731
    lines = ["", f"What moved against the Monte Carlo before ({b['what']}; {b['n']} draws, seed {b['seed']}):", "",
             "| | before | now |", "|---|---|---|"]
    for g in montecarlo.GAINS:
        lines += [f"| {NAMES[g]}: flies | {pct(b[g]['flies'])} | {pct(now[g]['flies'])} |",
                  f"| {NAMES[g]}: holds | {pct(b[g]['holds'])} | {pct(now[g]['holds'])} |",
                  f"| {NAMES[g]}: worst bank ringing, median (deg) | {deg(b[g]['ringing'])} | {deg(now[g]['ringing'])} |",
                  f"| {NAMES[g]}: estimator's bank bias, median (deg) | {deg(b[g]['bias'])} | {deg(now[g]['bias'])} |",
                  f"| {NAMES[g]}: true held bank error, median (deg) | {deg(b[g].get('true held'))} | "
                  f"{deg(now[g]['true held'])} |"]
    lines += [f"| Table 6 beats Table 4 | {pct(b['table6 beats table4'])} | {pct(now['table6 beats table4'])} |",
              f"| the paper's account | {pct(b[ACCOUNT])} | {pct(now[ACCOUNT])} |",
              f"| ... where Table 6 holds | {pct(b['given table6 holds'])} | {pct(now['given table6 holds'])} |",
              f"| ... by landing alone | {pct(b['landing only'])} | {pct(now['landing only'])} |"]
    return lines


def render(result: dict) -> str:
    """The docs block: the shares per gain set, the paired verdicts, the held error by the vehicle's
    own estimate beside the estimator's bias, and the ranges that decide the paper's account."""
    n, rows, p = result["n"], result["draws"], result["paired"]
    count = lambda what: sum(r[what] for r in rows)   # noqa: E731
    bank, turn = judge.RING_BOUND_DEG["roll"], judge.RING_BOUND_DEG["yaw"]
    lines = [f"`flightctl sim {result['scenario']} --params {result['params']} --monte-carlo {n} --seed "
             f"{result['seed']}` (`python scripts/as_flown_mc.py`): {len(result['ranges'])} ranges drawn, both gain "
             f"sets on each draw, {_path(result)}. \"Flies\": left the ground, no crash, landed upright; "
             f"\"holds\": flies, and every bank rings by at most {bank:g} degrees and every turn by at most {turn:g} "
             f"(peak-to-peak of the true angle from {judge.RING_AFTER_S:g} s after each step to the next: the size "
             f"of sec. 3.3's tuning steps, of which the tuning allowed a single overshoot), its own held error "
             f"within 1 and 3 degrees; \"settles\": every bank's true angle within 1 degree of its command and every "
             f"turn's within 3 degrees from 3 s after the step (sim/sweeps/judge.py). The held error is given as the "
             f"vehicle's own estimate saw it (what the paper's figures show) and as the truth (the estimate's held "
             f"error plus the estimator's bias, step by step){_true_note(rows)}.", "",
             f"| {n} draws | flies | holds | settles | worst bank ringing, median (deg) | worst turn ringing, "
             f"median (deg) | held bank error by its own estimate, median (deg) | estimator's bank bias, median (deg) | "
             f"true held bank error, median (deg) |",
             "|---|---|---|---|---|---|---|---|---|"]
    for g in montecarlo.GAINS:
        s = result["share"][g]
        flown = [r[g] for r in rows if r[g]["flies"]]
        bank_of = lambda key: [max(f[ch][key] for ch in ("roll", "pitch")) for f in flown if "roll" in f]   # noqa: E731
        held = sum(judge.bounded(r[g]) for r in rows)
        lines.append(f"| {NAMES[g]} | {100 * s['flies']:.0f} % | {100 * held / n:.0f} % | {100 * s['settles']:.0f} % | "
                     f"{_median(bank_of('ringing_deg'))} | "
                     f"{_median(f['yaw']['ringing_deg'] for f in flown if 'yaw' in f)} | "
                     f"{_median(bank_of('held_deg'))} | {_median(bank_of('bias_deg'))} | "
                     f"{_median(bank_of('true_held_deg')) if _stored(rows) else 'not stored'} |")
    b4, b6, account, given = _at(result)
    lines += ["", f"Paired, draw by draw: **the paper's account holds in {100 * p[montecarlo.VERDICTS[0]]:.0f} %** "
              f"({count(montecarlo.VERDICTS[0])} of {n}: Table 4 holds, Table 6 holds and rings less), **in "
              f"{100 * given / b6:.0f} % of the draws where Table 6 holds** ({given} of {b6}: Table 6 held on the "
              f"vehicle); Table 6 beats Table 4 in {100 * p['table6 beats table4']:.0f} % ({count('table6 beats table4')} "
              f"of {n}: it holds where Table 4 does not, or both hold and its worst ringing, each in its channel's "
              f"band, is lower). Judged by landing alone, as before the bound, the account held in "
              f"{count(LANDING)} of {n}. By the old criterion (settles), Table 6 settles where "
              f"Table 4 does not in {p['table6 settles, table4 not']} draws, the other way in "
              f"{p['table4 settles, table6 not']}.", "",
              "![The paper's account against the bound on the ringing](as-flown-bound.png)", "",
              "Which ranges decide it (the share of the draws where the paper's account holds, in the lower and the "
              "upper half of each range; in its logarithm where it spans a decade):", "",
              "| range | lower half | upper half |", "|---|---|---|"]
    for key, low, high, n_low, n_high in montecarlo.deciding(result)[:8]:
        lines.append(f"| `{key}` | {100 * low:.0f} % ({n_low}) | {100 * high:.0f} % ({n_high}) |")
    lines += ["", "![Which ranges decide the paper's account](as-flown-deciding.png)", "",
              "![Outcomes over the motor time constant and the delay chain](as-flown-monte-carlo.png)"]
    if "before" in result:
        lines += moved(result)
    return "\n".join(lines)


def facts(result: dict) -> str:
    """The README's table of the paper's real-flight facts, as shares of the Monte Carlo's draws."""
    n, rows, s = result["n"], result["draws"], result["share"]
    pct = lambda k, of=n: f"{100 * k / of:.0f} % ({k} of {of})"   # noqa: E731
    count = lambda test: sum(1 for r in rows if test(r))   # noqa: E731
    bank, turn = judge.RING_BOUND_DEG["roll"], judge.RING_BOUND_DEG["yaw"]
    b4, b6, account, given = _at(result)
    return "\n".join([
        f"| the paper's fact (sec. 4.4.5, figures 17-20) | share of {n} draws of every range of paper-as-flown, "
        f"{_path(result).split(' (')[0]} (`python scripts/as_flown_mc.py`) |", "|---|---|",
        f"| Table 4's gains, tuned in simulation, fly and land on the vehicle | {pct(count(lambda r: r['table4']['flies']))} |",
        f"| ... and hold every bank and turn: ringing within the bound (below), own held error within 1 and 3 degrees "
        f"| {pct(b4)} |",
        f"| Table 6's gains, retuned on the vehicle, fly and land | {pct(count(lambda r: r['table6']['flies']))} |",
        f"| ... and hold every bank and turn | {pct(b6)} |",
        f"| Table 6 holds and rings less than Table 4 (paired, each flight's worst step in its band) | "
        f"{pct(count(lambda r: r['table6 beats table4']))} |",
        f"| all of it: the paper's account (both hold, Table 6 rings less) | {pct(account)} |",
        f"| the paper's account where Table 6 holds (as it did on the vehicle) | {pct(given, b6)} |",
        f"| the paper's account judged by landing alone (no bound) | "
        f"{pct(count(lambda r: r[LANDING]))} |",
        f"| Table 6's banks within 1 degree and turns within 3 degrees of the truth from 3 s after each step | "
        f"{100 * s['table6']['settles']:.0f} % (Table 4: {100 * s['table4']['settles']:.0f} %) |",
        "",
        f"The bound (sim/sweeps/judge.py, `RING_BOUND_DEG`): a bank may still swing by at most {bank:g} degrees "
        f"and a turn by {turn:g} degrees peak-to-peak from {judge.RING_AFTER_S:g} s after its step to the next, the "
        f"size of the paper's tuning steps (sec. 3.3: +-5 degrees of roll and pitch, +-30 of yaw, \"a single initial "
        f"overshoot\" allowed, kd raised \"until no oscillation remains\" within a 3 s settling period). "
        f"docs/as-flown.md draws the shares against the bound."])
def write_doc(result: dict, doc: Path | None = DOC, readme: Path | None = README) -> None:
    if doc is not None:
        write_or_exit(doc, BEGIN, END, render(result))
    if readme is not None:
        write_or_exit(readme, FACTS_BEGIN, FACTS_END, facts(result))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=200)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--batch", action="store_true", help="fly the draws on the batched simulator (the same flights)")
    ap.add_argument("--before", nargs=2, metavar=("JSON", "WHAT"),
                    help="keep this earlier Monte Carlo's headline figures in the new one, to say what moved (WHAT: "
                         "which model it flew)")
    ap.add_argument("--from", dest="source", help="render this Monte Carlo JSON instead of flying the draws")
    ap.add_argument("--doc", help="write only docs/as-flown.md's block, into this copy of it (scripts/docs.py)")
    ap.add_argument("--readme", help="write only the README's block of the paper's facts, into this copy of it")
    args = ap.parse_args()
    if args.doc or args.readme:
        if not args.source:
            ap.error("--doc/--readme render a Monte Carlo's JSON: give it with --from")
        result = rejudge(json.loads(Path(args.source).read_text()))
        write_doc(result, Path(args.doc) if args.doc else None, Path(args.readme) if args.readme else None)
        return
    if args.source:
        result = rejudge(json.loads(Path(args.source).read_text()))
    else:
        if args.batch:
            result = montecarlo.run_batch("paper-as-flown", "paper", args.n, args.seed, progress=Progress(2, "monte carlo"))
        else:
            result = montecarlo.run("paper-as-flown", "paper", args.n, args.seed, progress=Progress(2 * args.n, "monte carlo"))
    if args.before:
        earlier = rejudge(json.loads(Path(args.before[0]).read_text()))
        result["before"] = {"what": args.before[1], "seed": earlier["seed"], **headline(earlier)}
    montecarlo.write_json(result, JSON)
    montecarlo.plot(result, DOC.parent / "as-flown-monte-carlo.png")
    montecarlo.plot_deciding(result, DOC.parent / "as-flown-deciding.png")
    plot_bound(result)
    write_doc(result)
    print(montecarlo.summary(result))
    print(f"-> {DOC.relative_to(ROOT)}, {JSON.relative_to(ROOT)} and its figures")


if __name__ == "__main__":
    main()
