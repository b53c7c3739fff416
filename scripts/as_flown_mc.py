"""The paper flight over every range of `paper-as-flown`, through the full onboard path, judged as the
paper judged its real flights, and written into docs/as-flown.md (between its `as-flown monte carlo`
markers) with its two figures. The shares are the Monte Carlo's (`flightctl sim paper --params
paper-as-flown --monte-carlo N --seed S --json MC.json`, sim/sweeps/montecarlo.py); this script runs
it, or reads its JSON, and renders them.

    python scripts/as_flown_mc.py [--n 200] [--seed 1]      # fly the draws (minutes on two cores)
    python scripts/as_flown_mc.py --from docs/as-flown-mc.json    # render a Monte Carlo's JSON

tests/test_as_flown_doc.py checks that the docs hold what this renders from the committed JSON.
"""
from __future__ import annotations

import argparse
import json
import statistics
from pathlib import Path

from flightctl.sim.docs import write_or_exit
from flightctl.sim.progress import Progress
from flightctl.sim.sweeps import montecarlo

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "as-flown.md"
JSON = ROOT / "docs" / "as-flown-mc.json"
BEGIN, END = "<!-- as-flown monte carlo begin -->", "<!-- as-flown monte carlo end -->"
README = ROOT / "README.md"
FACTS_BEGIN, FACTS_END = "<!-- paper facts begin -->", "<!-- paper facts end -->"
NAMES = {"table4": "Table 4 (tuned in simulation)", "table6": "Table 6 (retuned on the vehicle)"}


def _median(values) -> str:
    values = [v for v in values if v is not None]
    return f"{statistics.median(values):.2f}" if values else "-"


def render(result: dict) -> str:
    """The docs block: the shares per gain set, the paired verdicts, the held error beside the
    estimator's bias, and the ranges that decide the paper's account."""
    n, rows, p = result["n"], result["draws"], result["paired"]
    count = lambda what: sum(r[what] for r in rows)   # noqa: E731
    lines = [f"`flightctl sim {result['scenario']} --params {result['params']} --monte-carlo {n} --seed "
             f"{result['seed']}` (`python scripts/as_flown_mc.py`): {len(result['ranges'])} ranges drawn, both gain "
             f"sets on each draw, the full onboard path. \"Flies\": left the ground, no crash, landed upright; "
             f"\"settles\": every bank within 1 degree and turn within 3 degrees from 3 s after the step; ringing: "
             f"the peak-to-peak of the true angle from 1 s after each step to the next (sim/sweeps/judge.py).", "",
             f"| {n} draws | flies | settles | worst bank ringing, median (deg) | worst turn ringing, median (deg) | "
             f"held bank error, median (deg) | estimator's bank bias, median (deg) |",
             "|---|---|---|---|---|---|---|"]
    for g in montecarlo.GAINS:
        s = result["share"][g]
        flown = [r[g] for r in rows if r[g]["flies"]]
        bank = lambda key: [max(f[ch][key] for ch in ("roll", "pitch")) for f in flown if "roll" in f]   # noqa: E731
        lines.append(f"| {NAMES[g]} | {100 * s['flies']:.0f} % | {100 * s['settles']:.0f} % | "
                     f"{_median(bank('ringing_deg'))} | {_median(f['yaw']['ringing_deg'] for f in flown if 'yaw' in f)} | "
                     f"{_median(bank('held_deg'))} | {_median(bank('bias_deg'))} |")
    both = sum(r["table4"]["flies"] and r["table6"]["flies"] for r in rows)
    lines += ["", f"Paired, draw by draw: **Table 6 beats Table 4 in {100 * p['table6 beats table4']:.0f} % of the draws** "
              f"({count('table6 beats table4')} of {n}: it flies where Table 4 does not, or both fly and its worst "
              f"ringing, each in its channel's band, is lower), and **the paper's account holds in "
              f"{100 * p[montecarlo.VERDICTS[0]]:.0f} %** ({count(montecarlo.VERDICTS[0])} of {n}: Table 4 flies, Table 6 "
              f"flies and beats it). Both fly in {both}; Table 4 beats Table 6 in "
              f"{sum(r['table4']['flies'] and (not r['table6']['flies'] or (r['table4']['score'] or 0) < (r['table6']['score'] or 0)) for r in rows)}. "
              f"By the old criterion (settles), Table 6 settles where Table 4 does not in {p['table6 settles, table4 not']} "
              f"draws, the other way in {p['table4 settles, table6 not']}.", "",
              "Which ranges decide it (the share of the draws where the paper's account holds, in the lower and the "
              "upper half of each range; in its logarithm where it spans a decade):", "",
              "| range | lower half | upper half |", "|---|---|---|"]
    for key, low, high, n_low, n_high in montecarlo.deciding(result)[:8]:
        lines.append(f"| `{key}` | {100 * low:.0f} % ({n_low}) | {100 * high:.0f} % ({n_high}) |")
    lines += ["", "![Which ranges decide the paper's account](as-flown-deciding.png)", "",
              "![Outcomes over the motor time constant and the delay chain](as-flown-monte-carlo.png)"]
    return "\n".join(lines)


def facts(result: dict) -> str:
    """The README's table of the paper's real-flight facts, as shares of the Monte Carlo's draws."""
    n, rows, s = result["n"], result["draws"], result["share"]
    pct = lambda k: f"{100 * k / n:.0f} % ({k} of {n})"   # noqa: E731
    count = lambda test: sum(1 for r in rows if test(r))   # noqa: E731
    return "\n".join([
        f"| the paper's fact (sec. 4.4.5, figures 17-20) | share of {n} draws of every range of paper-as-flown, "
        f"full onboard path (`python scripts/as_flown_mc.py`) |", "|---|---|",
        f"| Table 4's gains, tuned in simulation, fly and land on the vehicle | {pct(count(lambda r: r['table4']['flies']))} |",
        f"| Table 6's gains, retuned on the vehicle, fly and land | {pct(count(lambda r: r['table6']['flies']))} |",
        f"| Table 6 rings less than Table 4 (paired, each flight's worst step in its band) | "
        f"{pct(count(lambda r: r['table6 beats table4']))} |",
        f"| all of it: the paper's account | {pct(count(lambda r: r[montecarlo.VERDICTS[0]]))} |",
        f"| Table 6's banks within 1 degree and turns within 3 degrees from 3 s after each step | "
        f"{100 * s['table6']['settles']:.0f} % (Table 4: {100 * s['table4']['settles']:.0f} %) |"])


def write_doc(result: dict, doc: Path | None = DOC, readme: Path | None = README) -> None:
    if doc is not None:
        write_or_exit(doc, BEGIN, END, render(result))
    if readme is not None:
        write_or_exit(readme, FACTS_BEGIN, FACTS_END, facts(result))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=200)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--from", dest="source", help="render this Monte Carlo JSON instead of flying the draws")
    ap.add_argument("--doc", help="write only docs/as-flown.md's block, into this copy of it (scripts/docs.py)")
    ap.add_argument("--readme", help="write only the README's block of the paper's facts, into this copy of it")
    args = ap.parse_args()
    if args.doc or args.readme:
        if not args.source:
            ap.error("--doc/--readme render a Monte Carlo's JSON: give it with --from")
        result = json.loads(Path(args.source).read_text())
        write_doc(result, Path(args.doc) if args.doc else None, Path(args.readme) if args.readme else None)
        return
    if args.source:
        result = json.loads(Path(args.source).read_text())
    else:
        bar = Progress(2 * args.n, "monte carlo")
        result = montecarlo.run("paper-as-flown", "paper", args.n, args.seed, progress=bar)
    if Path(args.source or "").resolve() != JSON:
        montecarlo.write_json(result, JSON)
    montecarlo.plot(result, DOC.parent / "as-flown-monte-carlo.png")
    montecarlo.plot_deciding(result, DOC.parent / "as-flown-deciding.png")
    write_doc(result)
    print(montecarlo.summary(result))
    print(f"-> {DOC.relative_to(ROOT)}, {JSON.relative_to(ROOT)} and its figures")


if __name__ == "__main__":
    main()
