"""`flightctl diagnose`: name what the model gets wrong in flight logs (measured-data.md).

    flightctl diagnose FLIGHT.csv [FLIGHT.csv ...] [--params PARAMS.toml] --json REPORT.json
                       [--plot PREFIX] [--quiet]

Prints a text report on stdout and progress on stderr. Everything is read, checked, computed and
rendered before the first file is written: bad input writes nothing (one line on stderr naming the
file, row or column; exit status 2, see flightctl.cli).
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from flightctl import params as paramfile
from flightctl.errors import InputError
from flightctl.logfile import read_flight_log
from flightctl.sim.identify.diagnose import report as diagnose_report
from flightctl.sim.identify.diagnose.verdict import diagnose, say

MIN_LOG_S = 2.0   # a log shorter than this cannot hold a take-off and a flight: too short to judge


class _Parser(argparse.ArgumentParser):
    def error(self, message):
        raise InputError(message)


def _parser() -> argparse.ArgumentParser:
    p = _Parser(prog="flightctl diagnose",
                description="Fit every candidate extension of the model to part of the flight logs, score "
                            "it on the rest, and name the one that explains the discrepancy, or none "
                            "(measured-data.md; method: docs/diagnose.md).")
    p.add_argument("logs", nargs="+", metavar="FLIGHT.csv")
    p.add_argument("--params", metavar="PARAMS.toml",
                   help="the base model: its airframe and its [[effect]] tables (default: the reference "
                        "airframe, no effects)")
    p.add_argument("--json", required=True, metavar="REPORT.json")
    p.add_argument("--plot", metavar="PREFIX",
                   help="write PREFIX-residuals.png (residual vs time) and PREFIX-explained.png "
                        "(residual vs the variable that explains it)")
    p.add_argument("--quiet", action="store_true", help="no progress on stderr")
    return p


def _check_writable(path: Path) -> None:
    parent = path.resolve().parent
    if not parent.is_dir():
        raise InputError(f"{path}: cannot write, no directory {parent}")
    if path.exists() and path.is_dir():
        raise InputError(f"{path}: cannot write, it is a directory")


def main(argv: list[str]) -> int:
    args = _parser().parse_args(argv)
    # On a terminal, progress is live. Otherwise (scripts, checks) it is held until the run succeeds,
    # so that an error is the only line on stderr, as measured-data.md requires.
    held: list[tuple] = []
    progress = ((lambda *a: None) if args.quiet else say if sys.stderr.isatty()
                else (lambda *a: held.append(a)))
    t0 = time.perf_counter()
    params = paramfile.load(args.params)
    out_json = Path(args.json)
    plots = {}
    if args.plot:
        plots = {k: Path(f"{args.plot}-{k}.png") for k in ("residuals", "explained")}
    for path in (out_json, *plots.values()):
        _check_writable(path)
    tables = []
    for log in args.logs:
        progress(f"reading {log}")
        tables.append(read_flight_log(log, min_seconds=MIN_LOG_S, min_rows=10))
    d = diagnose(tables, params.airframe, progress, params.effects)
    report_text = diagnose_report.text(d)
    images = diagnose_report.figures(d) if plots else {}
    report = d.report()
    report["runtime_s"] = round(time.perf_counter() - t0, 2)
    text = json.dumps(report, indent=2, allow_nan=False) + "\n"
    out_json.write_text(text)
    for k, path in plots.items():
        path.write_bytes(images[k])
    print(report_text, end="")
    progress(f"done in {time.perf_counter() - t0:.1f} s: {d.cause} {d.parameters}")
    for a in held:
        say(*a)
    return 0
