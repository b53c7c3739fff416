"""Diagnose every shipped real flight log (../shared/data/real/flights) and write the table of
docs/real-flights.md between its markers: what diagnose finds on each, beside what is published.
Its rows are a function of the logs and the code only (tests/test_real_flights.py compares them, -m slow).

    python scripts/real_flights.py [--flights DIR] [--doc docs/real-flights.md] [--json OUT.json]

About 4 minutes on this machine (btfl_002.bbl, 151 s at 500 Hz, takes most of it); progress on
stderr.
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

from flightctl.cli import main as flightctl
from flightctl.sim.docs import write_block

ROOT = Path(__file__).resolve().parents[1]
BEGIN, END = "<!-- real-flights table: written by scripts/real_flights.py -->", "<!-- end of the table -->"
LOGS = ("indiflight/LOG00230.BFL", "indiflight/LOG00231.BFL", "indiflight/LOG00232.BFL", "indiflight/LOG00257.BFL",
        "indiflight/LOG00258.BFL", "indiflight/LOG00259.BFL", "betaflight/LOG00037.BFL", "betaflight/btfl_002.bbl",
        "px4/roboto-test.ulg")


def diagnose(path: Path, out: Path) -> tuple[int, dict | str, float]:
    """(exit status, the report or the error line, seconds)."""
    import contextlib
    import io
    err = io.StringIO()
    start = time.perf_counter()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        status = flightctl(["diagnose", str(path), "--json", str(out), "--quiet"])
    seconds = time.perf_counter() - start
    return status, (json.loads(out.read_text()) if status == 0 else err.getvalue().strip()), seconds


def row(name: str, status: int, report) -> str:
    if status != 0:        # the error line: "flightctl diagnose: error: PATH: what"
        what = report.split(": error: ", 1)[-1].split(": ", 1)[-1]
        return f"| {name} | refused (exit 2) | {what} | | |"
    causes = "; ".join(f"{c['cause']} " + ", ".join(f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}"
                                                    for k, v in c["parameters"].items())
                       + f" (gain {c['gain']:.3f})" for c in report["causes"]) or "none"
    base = report["base_model"]
    gains = ", ".join(f"{g:.2f}" for g in base["rotor_gain"]["value"])
    check = report.get("rotor_speed_check")
    speeds = (f"lag {1e3 * check['tau']:.0f} ms + delay {1e3 * check['delay']:.0f} ms" if check else "not logged")
    flip = " (spins reversed by the data)" if "spins reversed" in base["layout"]["source"] else ""
    return f"| {name} | {report['data']['airborne_s']:.1f} s | {causes} | rotor gains {gains}{flip} | {speeds} |"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--flights", default=str(ROOT / ".." / "shared" / "data" / "real" / "flights"))
    ap.add_argument("--doc", default=str(ROOT / "docs" / "real-flights.md"))
    ap.add_argument("--json", help="also write every report here")
    args = ap.parse_args()
    rows, reports = [], {}
    with tempfile.TemporaryDirectory() as tmp:
        for name in LOGS:
            status, report, seconds = diagnose(Path(args.flights) / name, Path(tmp) / "r.json")
            print(f"real_flights: {name}: {seconds:.0f} s", file=sys.stderr, flush=True)
            rows.append(row(name, status, report))
            reports[name] = report
    table = "\n".join(["| log | airborne | causes (each on top of the ones before) | base model | "
                       "the log's own rotor speeds |", "|---|---|---|---|---|"] + rows)
    if not write_block(args.doc, BEGIN, END, table):
        raise SystemExit(f"{args.doc}: no {BEGIN} ... {END} markers")
    if args.json:
        Path(args.json).write_text(json.dumps(reports, indent=1))
    print(table)


if __name__ == "__main__":
    main()
