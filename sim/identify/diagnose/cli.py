"""`flightctl diagnose`: name what the model gets wrong in flight logs (measured-data.md).

    flightctl diagnose FLIGHT.csv|F.ulg|F.bbl|F.bfl [...] [--index N] [--params PARAMS.toml] --json REPORT.json
                       [--validate OTHER ...] [--plot PREFIX] [--quiet]

Logs of other autopilots (PX4's ULog, Betaflight's blackbox) are read by `flightctl.sim.logs` into
the same table as `flightctl log import` writes; their vehicle's base model is identified from the
flight (docs/real-flights.md).

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
from flightctl.errors import InputError, output_file
from flightctl.logfile import read_flight_log
from flightctl.sim.identify.diagnose.data import FOREIGN_COLUMNS
from flightctl.sim.logs import FOREIGN_SUFFIXES
from flightctl.sim.identify.diagnose import report as diagnose_report
from flightctl.sim.identify.diagnose.verdict import diagnose, say, validate

MIN_LOG_S = 2.0   # a log shorter than this cannot hold a take-off and a flight: too short to judge


class _Parser(argparse.ArgumentParser):
    def error(self, message):
        raise InputError(message)


def _parser() -> argparse.ArgumentParser:
    p = _Parser(prog="flightctl diagnose",
                description="Fit every candidate extension of the model to part of the flight logs, score "
                            "it on the rest, and name the one that explains the discrepancy, or none "
                            "(the method: docs/diagnose.md in the flightctl checkout).")
    p.add_argument("logs", nargs="+", metavar="FLIGHT",
                   help="flight logs of one vehicle: this project's CSV (docs/formats.md), PX4's .ulg or "
                        "Betaflight's .bbl/.bfl (the `logs` extra)")
    p.add_argument("--index", type=int, metavar="N",
                   help="of a blackbox file holding several logs, only log N (counted from 1; default: every log)")
    p.add_argument("--validate", nargs="+", metavar="OTHER",
                   help="other flights of the same vehicle: predict them with the model fitted here (nothing refitted "
                        "but the accelerometer's bias) and report the gain of the causes there")
    p.add_argument("--params", metavar="PARAMS.toml",
                   help="the base model: its airframe and its [[effect]] tables (default: the reference "
                        "airframe, no effects)")
    p.add_argument("--json", required=True, metavar="REPORT.json", help="the report (its keys: docs/diagnose.md)")
    p.add_argument("--plot", metavar="PREFIX",
                   help="write PREFIX-residuals.png (residual vs time, base and after each cause), "
                        "PREFIX-explained.png (residual vs the variable that explains it) and, per log, "
                        "PREFIX-read-K.png (what was read: rates, gaps, channels)")
    p.add_argument("--quiet", action="store_true", help="no progress on stderr")
    return p


def read_logs(paths: list[str], index: int | None, progress) -> list:
    """Each log as a flight-log table: this project's CSV, or a foreign log through
    `flightctl.sim.logs` (every log of a blackbox file, or the one at `index`)."""
    tables = []
    for log in paths:
        progress(f"reading {log}")
        if Path(log).suffix.lower() in FOREIGN_SUFFIXES:
            from flightctl.sim.logs import read_foreign
            tables += read_foreign(log, index, progress)
        else:
            tables.append(read_flight_log(log, min_seconds=MIN_LOG_S, min_rows=10, extra=FOREIGN_COLUMNS))
    return tables


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
    if args.index is not None and args.index < 1:
        raise InputError(f"--index {args.index}: logs are counted from 1")
    tables = read_logs(args.logs, args.index, progress)
    others = read_logs(args.validate, None, progress) if args.validate else []
    plots = {}
    if args.plot:
        plots = {k: Path(f"{args.plot}-{k}.png") for k in ("residuals", "explained")}
        plots.update({f"read-{k}": Path(f"{args.plot}-read-{k}.png") for k in range(1, len(tables) + 1)})
    output_file(out_json, "--json")
    for path in plots.values():
        output_file(path, "--plot")
    d = diagnose(tables, params.airframe, progress, params.effects, params_given=args.params is not None)
    if others:
        d.validation = validate(d, others, params.airframe, progress)
    report_text = diagnose_report.text(d)
    images = diagnose_report.figures(d) if plots else {}
    if plots:
        from flightctl.sim.logs import read_figure
        from flightctl.sim.plots import png
        images.update({f"read-{k}": png(read_figure(t)) for k, t in enumerate(tables, 1)})
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
