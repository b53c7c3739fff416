"""Two effects hidden at once, many times (docs/diagnose.md, "Every cause"): pairs drawn exactly as
tests/sim/diagnose/test_verdict_chain.py draws them (one seeded generator per pair, seeds FIRST, FIRST+1, ...),
each flown on the tests' quick plan with `flightctl sim --effect` twice and diagnosed from the log
alone. Prints, per pair, what was hidden and what the chain named, then the totals; `--doc` writes
the summary between the markers of docs/diagnose.md.

    python scripts/diagnose_pairs.py [--pairs 30] [--first 100] [--jobs 2] [--doc docs/diagnose.md]
"""
from __future__ import annotations

import argparse
import contextlib
import io
import sys
import tempfile
from collections import Counter
from pathlib import Path

import numpy as np

from flightctl.sim.docs import marked, publish
from flightctl.sim import engine
from flightctl.sim.progress import Progress

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))   # the tests' drawing and tolerances (helpers/diagnose_cases.py): one definition

BEGIN, END = marked("diagnose_pairs")


def judge(seed: int) -> dict:
    """One pair: {seed, hidden, named, verdict} where verdict is 'ok' or what went wrong."""
    from helpers.diagnose_cases import close_enough, fly_pair   # (no pytest: the base install runs this)

    with tempfile.TemporaryDirectory() as tmp, contextlib.redirect_stdout(io.StringIO()):
        truth, report = fly_pair(Path(tmp), np.random.default_rng(seed))   # the flights' own printing aside
    named = {c["cause"]: c["parameters"] for c in report["causes"]}
    wrong = [f"missed {c}" for c in truth if c not in named]
    wrong += [f"named {c} (not hidden)" for c in named if c not in truth]
    wrong += [f"{c} mis-sized" for c in truth if c in named and not close_enough(c, truth[c], named[c])[0]]
    return {"seed": seed, "hidden": truth, "named": named, "airborne_s": report["data"]["airborne_s"],
            "verdict": "; ".join(wrong) or "ok"}


def _short(parameters: dict) -> str:
    return ",".join(f"{k}={v:.3g}" for k, v in parameters.items())


def summary(rows: list[dict], first: int) -> str:
    ok = sum(r["verdict"] == "ok" for r in rows)
    kinds = Counter(part.strip() for r in rows if r["verdict"] != "ok" for part in r["verdict"].split(";"))
    extra = sum("(not hidden)" in r["verdict"] for r in rows)
    sized = sum("mis-sized" in r["verdict"] for r in rows)
    lines = [f"{ok} of {len(rows)} pairs (seeds {first}-{first + len(rows) - 1}) had both causes named and "
             "sized within their single-effect tolerances and nothing else.",
             "",
             f"A cause named that was not hidden: in {extra} of {len(rows)} pairs; a named cause sized outside "
             f"its tolerance: in {sized}.", ""]
    if kinds:
        lines += ["| what went wrong | pairs |", "|---|---|"]
        lines += [f"| {k} | {n} |" for k, n in kinds.most_common()]
        lines += ["", "The pairs that failed:", ""]
        lines += [f"- seed {r['seed']}: hidden " + "; ".join(f"{c} ({_short(p)})" for c, p in r["hidden"].items())
                  + " -> named " + ("; ".join(f"{c} ({_short(p)})" for c, p in r["named"].items()) or "nothing")
                  + f": {r['verdict']}" for r in rows if r["verdict"] != "ok"]
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0].replace("\n", " "))
    ap.add_argument("--pairs", type=int, default=30, help="how many pairs (default 30)")
    ap.add_argument("--first", type=int, default=100, help="the first pair's seed (default 100)")
    ap.add_argument("--jobs", type=int, default=2, help="pairs flown at once (default 2)")
    ap.add_argument("--doc", type=Path, help="write the summary between the markers of this Markdown file")
    args = ap.parse_args(argv)
    if args.pairs < 1 or args.first < 0 or args.jobs < 1:
        ap.error("--pairs and --jobs: at least 1; --first: a seed from 0")
    seeds = list(range(args.first, args.first + args.pairs))

    def describe(row: dict) -> str:
        return (f"seed {row['seed']}: hidden {', '.join(row['hidden'])} -> named {', '.join(row['named']) or 'nothing'} "
                f"({row['airborne_s']:.0f} s airborne): {row['verdict']}")
    rows = sweep("diagnose_pairs", judge, seeds, args.jobs, describe)
    if rows is None:
        return 130
    publish(summary(rows, args.first), args.doc, BEGIN, END)
    return 0


def sweep(name: str, fn, jobs: list, n: int, describe) -> list | None:
    """`fn(job)` for every job in `n` processes, a progress line per job (`describe(row)`); None after
    Ctrl-C, said in one line."""
    bar = Progress(len(jobs), f"{name} ")
    try:
        return engine.run(fn, jobs, n, lambda k, row: bar.step(describe(row)))
    except KeyboardInterrupt:
        print(f"{name}: interrupted; nothing written", file=sys.stderr)
        return None

if __name__ == "__main__":
    sys.exit(main())
