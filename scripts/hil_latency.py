"""The HIL link's latency on this machine (docs/hil.md, "Latency"): `flightctl hil demo` flown a few
times over each link, one after another, each run's frames lost, latency (p50, p99, max), the CPU the
host of a virtual machine took meanwhile (steal) and the outcome.

    python scripts/hil_latency.py [--runs 4] [--seconds 20] [--markdown]

The figures are the machine's and its load's (a shared virtual machine's vary by the minute);
`--markdown` prints docs/hil.md's block with the day and the machine they were measured on
(scripts/docs.py writes it there and checks only its form).
"""
from __future__ import annotations

import argparse
import datetime
import json
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "scripts"))

LINKS = ("pty", "tcp")
HEADER = ("| link | run | lost | latency p50 | latency p99 | max | host steal | outcome |",
          "|---|---|---|---|---|---|---|---|")
STAMP = "Measured by `python scripts/hil_latency.py --markdown` on {date}: {machine}."


def demo(link: str, seconds: float) -> dict:
    """One `flightctl hil demo` in a child process: its --json figures (exit 1, a flight that did not
    land, is a figure too)."""
    with tempfile.TemporaryDirectory(prefix="flightctl-hil-") as tmp:
        out = Path(tmp) / "demo.json"
        r = subprocess.run([sys.executable, "-P", "-m", "flightctl.cli", "hil", "demo", "--seconds", f"{seconds:g}",
                            "--link", link, "--json", str(out)], cwd=ROOT, stdout=subprocess.DEVNULL)
        if r.returncode not in (0, 1) or not out.exists():
            raise SystemExit(f"hil_latency: flightctl hil demo --link {link} failed (exit status {r.returncode})")
        return json.loads(out.read_text())


def row(link: str, run: int, f: dict) -> str:
    steal = f.get("machine_steal_pct")
    return (f"| {link} | {run} | {f['frames_lost']} | {f['latency_p50_ms']:.2f} ms | {f['latency_p99_ms']:.2f} ms "
            f"| {f['latency_max_ms']:.1f} ms | {'-' if steal is None else f'{steal:.1f} %'} | {f['outcome']} |")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0].replace("\n", " "))
    ap.add_argument("--runs", type=int, default=4, help="demos per link (default 4)")
    ap.add_argument("--seconds", type=float, default=20.0, help="each demo's flight, s (default 20)")
    ap.add_argument("--markdown", action="store_true", help="print docs/hil.md's block: the date, the machine, a table")
    args = ap.parse_args(argv)
    if args.runs < 1 or args.seconds <= 0:
        ap.error("--runs: at least 1; --seconds: above 0")
    from benchmark import machine
    from flightctl.sim.progress import Progress
    where = machine()
    bar = Progress(args.runs * len(LINKS), "hil_latency ")
    rows = []
    for link in LINKS:
        for run in range(1, args.runs + 1):
            rows.append(row(link, run, demo(link, args.seconds)))
            bar.step(rows[-1])
    if args.markdown:
        print("\n".join([STAMP.format(date=datetime.date.today().isoformat(), machine=where), "", *HEADER, *rows]))
    else:
        print("\n".join([where, *HEADER, *rows]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
