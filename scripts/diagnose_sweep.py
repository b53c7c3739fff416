"""One effect hidden at a time, every cause and none, three seeds each (docs/diagnose.md, "Results"):
the flights of the slow hidden-effect test (`pytest tests/sim/diagnose/test_diagnose_hidden.py -m slow`), drawn,
flown and diagnosed exactly as it does (its seeds, tests/helpers/diagnose_cases.py's drawing, the 48 s
`excite` plan, `flightctl sim --effect` then `flightctl diagnose` on the log alone). Prints a row per
flight (what was hidden, what was named and recovered, the held-out gain, the runner-up and what it
did to `acc_z`), then the totals and how much of its tolerance each cause used; `--doc` writes them
between the markers of docs/diagnose.md.

    python scripts/diagnose_sweep.py [--seeds 3] [--jobs 2] [--doc docs/diagnose.md]
"""
from __future__ import annotations

import argparse
import contextlib
import io
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

from flightctl.sim.docs import marked, publish

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))   # the tests' drawing and tolerances (helpers/diagnose_cases.py): one definition
sys.path.insert(0, str(ROOT / "scripts"))

BEGIN, END = marked("diagnose_sweep")


def cases(seeds: int) -> list[tuple[str, int]]:
    """(cause, seed) as tests/sim/diagnose/test_diagnose_hidden.py's slow test numbers them."""
    from helpers.diagnose_cases import CAUSES
    every = ("none",) + CAUSES
    return [(cause, 100 + 10 * s + every.index(cause)) for s in range(seeds) for cause in every]


def used(cause: str, truth: dict, got: dict) -> float:
    """The share of its tolerance the recovered size used (0: exact, 1: at the tolerance's edge)."""
    from helpers.diagnose_cases import close_enough
    if cause == "none" or not got:
        return 0.0
    err = {k: got[k] - truth[k] for k in truth}
    if not any(err.values()):
        return 0.0
    lo, hi = 0.0, 1e6                      # bisect the largest scale of the error close_enough still takes
    for _ in range(60):
        mid = (lo + hi) / 2
        if close_enough(cause, truth, {k: truth[k] + err[k] * mid for k in truth})[0]:
            lo = mid
        else:
            hi = mid
    return 1.0 / lo if lo > 0 else float("inf")


def judge(case: tuple[str, int]) -> dict:
    from helpers.diagnose_cases import close_enough, draw, run_case
    cause, seed = case
    cause, truth = draw(np.random.default_rng(seed), cause)
    with tempfile.TemporaryDirectory() as tmp, contextlib.redirect_stdout(io.StringIO()):
        report = run_case(Path(tmp), cause, truth, seed)
    named = report["cause"]
    right = named == cause and close_enough(cause, truth, report["parameters"])[0]
    others = [c for c in report["candidates"] if c["cause"] != named]
    runner = max(others, key=lambda c: c["gain"]) if others else None
    return {"cause": cause, "seed": seed, "truth": truth, "named": named, "parameters": report["parameters"],
            "gain": report["gain"], "ok": right, "chain": [c["cause"] for c in report["causes"]],
            "airborne_s": report["data"]["airborne_s"],
            "used": used(cause, truth, report["parameters"]) if named == cause else float("nan"),
            "runner": runner and {"cause": runner["cause"], "gain": runner["gain"],
                                  "acc_z": runner["channels"]["acc_z"]["gain"]}}


def _p(parameters: dict) -> str:
    return json.dumps({k: float(f"{v:.4g}") for k, v in parameters.items()})


def summary(rows: list[dict]) -> str:
    ok = sum(r["ok"] and r["chain"] == ([] if r["cause"] == "none" else [r["cause"]]) for r in rows)
    lines = ["| hidden | seed | drawn | named, recovered | held-out gain | within tolerance "
             "| runner-up (its gain, its `acc_z` gain) | airborne s |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        run = r["runner"]
        runner = f"{run['cause']} ({run['gain']:.3f}, {run['acc_z']:+.2f})" if run else "-"
        lines.append(f"| {r['cause']} | {r['seed']} | `{_p(r['truth'])}` | `{r['named']} {_p(r['parameters'])}` "
                     f"| {r['gain']:.3f} | {'OK' if r['ok'] else 'NO'} | {runner} | {r['airborne_s']:.1f} |")
    worst = {}
    for r in rows:
        if r["cause"] != "none" and r["used"] == r["used"]:
            worst[r["cause"]] = max(worst.get(r["cause"], 0.0), r["used"])
    lines += ["", f"{ok} of {len(rows)} flights had the hidden cause named alone (none when nothing was "
              "hidden) and sized within its tolerance.", "",
              "The largest share of its tolerance a recovered size used, per cause: "
              + ", ".join(f"{c} {u:.2f}" for c, u in worst.items()) + "."]
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0].replace("\n", " "))
    ap.add_argument("--seeds", type=int, default=3, help="seeds of each cause (default 3, the slow test's)")
    ap.add_argument("--jobs", type=int, default=2, help="flights at once (default 2)")
    ap.add_argument("--doc", type=Path, help="write the table between the markers of this Markdown file")
    args = ap.parse_args(argv)
    if args.seeds < 1 or args.jobs < 1:
        ap.error("--seeds and --jobs: at least 1")
    if args.doc is not None and not args.doc.is_file():
        ap.error(f"--doc {args.doc}: no such file")
    from diagnose_pairs import sweep
    rows = sweep("diagnose_sweep", judge, cases(args.seeds), args.jobs,
                 lambda r: f"seed {r['seed']}: hidden {r['cause']} -> named {r['named']}: {'ok' if r['ok'] else 'WRONG'}")
    if rows is None:
        return 130
    publish(summary(rows), args.doc, BEGIN, END)
    return 0


if __name__ == "__main__":
    sys.exit(main())
