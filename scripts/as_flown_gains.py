"""The gain of each term of `paper-as-flown` on held-out data (docs/as-flown.md): a flight of the as-flown
plant, `flightctl sim hover_low --params paper-as-flown --seed 7`, diagnosed from its log alone twice,
against the paper's base model and with `--params paper-as-flown` (the file's terms carried in the base
model). Prints a table of what each term's candidate finds alone and in the chain against the file's
value, then what carrying the terms does; `--doc` writes it between the markers of docs/as-flown.md.

    python scripts/as_flown_gains.py [--doc docs/as-flown.md]
"""
from __future__ import annotations

import argparse
import contextlib
import io
import json
import sys
import tempfile
from pathlib import Path

from flightctl.cli import main as flightctl
from flightctl.params import load
from flightctl.sim.docs import marked, publish

BEGIN, END = marked("as-flown gains")
TERMS = ("rotor_inflow", "motor_lag", "motor_dynamics", "rotor_drag", "actuation_delay")
SEED = 7


def _p(parameters: dict) -> str:
    return ", ".join(f"{k} = {v:.3g}" for k, v in parameters.items()) or "-"


def diagnose(log: Path, *extra: str) -> dict:
    out = log.with_suffix(f".{len(extra)}.json")
    if flightctl(["diagnose", str(log), "--json", str(out), "--quiet", *extra]) != 0:
        raise SystemExit(f"as_flown_gains: flightctl diagnose {log.name} {' '.join(extra)} failed")
    return json.loads(out.read_text())


def table(flight: dict, bare: dict, carried: dict) -> str:
    effects = {e.cause: dict(e.parameters) for e in load("paper-as-flown").effects}
    alone = {c["cause"]: c for c in bare["candidates"]}
    chain = {c["cause"]: (k, c) for k, c in enumerate(bare["causes"], 1)}
    refit = {c["cause"]: c for c in carried["candidates"]}
    lines = [f"A log of the as-flown plant (`flightctl sim hover_low --params paper-as-flown --seed {SEED}`: "
             f"{flight['seconds']:.0f} s, {bare['data']['airborne_s']:.0f} s airborne), diagnosed against the "
             "paper's base model; gains are 1 - rmse_extended / rmse_base on held-out blocks.", "",
             "| term | the file's value | fitted alone | held-out gain alone | in the chain |",
             "|---|---|---|---|---|"]
    for term in TERMS:
        c = alone.get(term)
        fitted = (_p(c["parameters"]), f"{c['gain']:.3f}" + (" (named)" if bare["cause"] == term else "")) \
            if c else ("not judged", "-")
        k, named = chain.get(term, (None, None))
        lines.append(f"| {term} | {_p(effects[term]) if term in effects else '-'} | {fitted[0]} | {fitted[1]} | "
                     + (f"{k}: {_p(named['parameters'])}, gain {named['gain']:.3f}" if named else "not named") + " |")
    named_then = ", ".join(c["cause"] for c in carried["causes"]) or "nothing"
    lines += ["", f"With `--params paper-as-flown` the base model carries the file's terms: its held-out RMSE "
              f"falls from {bare['rmse_base']:.3f} to {carried['rmse_base']:.3f}; {named_then} is named; the carried "
              "terms refit to " + "; ".join(f"{t} {_p(refit[t]['parameters'])} (gain {refit[t]['gain']:+.4f})"
                                            for t in TERMS if t in refit and t in effects) + "."]
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0].replace("\n", " "))
    ap.add_argument("--doc", type=Path, help="write the table between the markers of this Markdown file")
    args = ap.parse_args(argv)
    if args.doc is not None and not args.doc.is_file():
        ap.error(f"--doc {args.doc}: no such file")
    with tempfile.TemporaryDirectory(prefix="flightctl-as-flown-") as tmp:
        log = Path(tmp) / "hover_low.csv"
        with contextlib.redirect_stdout(io.StringIO()):
            status = flightctl(["sim", "hover_low", "--params", "paper-as-flown", "--seed", str(SEED), "--log", str(log),
                                "--no-plot", "--quiet"])
            if status not in (0, 1):
                raise SystemExit(f"as_flown_gains: the flight failed (exit status {status})")
            rows = [line for line in log.read_text().splitlines() if line and not line.startswith("#")]
            t = [float(r.split(",", 1)[0]) for r in rows[1:]]
            flight = {"seconds": t[-1] - t[0]}
            bare, carried = diagnose(log), diagnose(log, "--params", "paper-as-flown")
    publish(table(flight, bare, carried), args.doc, BEGIN, END)
    return 0


if __name__ == "__main__":
    sys.exit(main())
