"""`flightctl diagnose`: name what the model gets wrong in flight logs (docs/measured-data.md).

    flightctl diagnose FLIGHT.csv|F.ulg|F.bin|F.bbl|F.bfl|F.txt [...] [--index N] [--params PARAMS.toml]
                       --json REPORT.json [--validate OTHER ...] [--plot PREFIX] [--steps STEPS.png] [--quiet]
    flightctl diagnose --corpus DIR [DIR ...] [--table OUT.md] [--json OUT.json] [--jobs N] [--quiet]
                       [--fleet REPORT [--vehicles MAP.csv]]

Logs of other autopilots (PX4's ULog, ArduPilot's DataFlash, the blackbox of Betaflight and INAV) are
read by `flightctl.sim.logs` into the same table as `flightctl log import` writes; their vehicle's
base model is identified from the flight (docs/real-flights.md).

Two tiers (docs/diagnose.md, "Static tier"): a log fast enough for the dynamic tier (the causes chain)
gets it and the static tier's findings beside it; a log the dynamic tier refuses gets the static tier
alone (hover, motor shares, centre of mass against weak motor against yaw trim, battery, vibration),
exit status 0, with the refusal as `tier_why`. REPORT.json's `tier` says which. Either way REPORT.json's
`steps` holds each log's measured step responses, per loop and axis, or the reason it cannot show one
(steps.py, docs/steps.md), each rate axis's with the step the base model identified on the log's first half
predicts on its second (`predicted`, predict.py); `--steps STEPS.png` draws them; `controller` the firmware's rate controller as
the log's settings give it (sim/logs/controller.py).

Several files are one vehicle, diagnosed jointly. One file of many logs (a blackbox file holds one
per arming) is diagnosed log by log: each log that can be judged gets its own report, the others are
named with the reason they were skipped (REPORT.json's `logs` list); the exit status is 0 when at
least one log was judged.

Prints a text report on stdout and progress on stderr. Everything is read, checked, computed and
rendered before the first file is written: bad input writes nothing (one line on stderr naming the
file, row or column; exit status 2, see flightctl.cli).
"""
from __future__ import annotations

# One BLAS thread, set before numpy is imported (here, at the command's entry point: flightctl.cli imports
# nothing numerical before it), so that OpenBLAS starts no thread pool: its fits are small matrices, and on
# a busy machine its threads spun for a quarter to two fifths of the user time (docs/diagnose.md, "Speed").
# A process that had numpy loaded before (a test calling `main`) gets its pool set to one thread in `main`.
from flightctl.blas import OneBlasThread, one_thread_environment   # flightctl/blas.py: nothing numerical

one_thread_environment()

import argparse
import json
import sys
import time
from pathlib import Path

from flightctl import params as paramfile
from flightctl.errors import InputError, Parser
from flightctl.files import output_file, output_prefix, write_atomic
from flightctl.logfile import read_flight_log
from flightctl.sim import engine
from flightctl.sim.progress import Stages
from flightctl.sim.diagnose.data import FOREIGN_COLUMNS
from flightctl.sim.diagnose import predict, report as diagnose_report, steps
from flightctl.sim.diagnose.verdict import diagnose, validate
from flightctl.sim.diagnose.static import STATIC_COLUMNS, StaticOnly
from flightctl.sim.logs import controller
from flightctl.sim.diagnose.static.curve import declared as declared_curve

MIN_LOG_S = 2.0   # a log shorter than this cannot hold a take-off and a flight: too short to judge


def _parser() -> argparse.ArgumentParser:
    p = Parser(prog="flightctl diagnose",
                description="Fit every candidate extension of the model to part of the flight logs, score "
                            "it on the rest, and name the one that explains the discrepancy, or none "
                            "(the method: docs/diagnose.md in the flightctl checkout).")
    p.add_argument("logs", nargs="*", metavar="FLIGHT",
                   help="flight logs of one vehicle: this project's CSV (docs/formats.md), PX4's .ulg, "
                        "ArduPilot's .bin or a Betaflight/INAV .bbl/.bfl/.txt (the `logs` extra); one file of "
                        "many logs is diagnosed log by log")
    p.add_argument("--index", type=int, metavar="N",
                   help="of a file holding several logs, only log N (counted from 1; default: each log that "
                        "can be judged, on its own)")
    p.add_argument("--validate", nargs="+", metavar="OTHER",
                   help="other flights of the same vehicle: predict them with the model fitted here (nothing refitted "
                        "but the accelerometer's bias) and report the gain of the causes there")
    p.add_argument("--params", metavar="PARAMS.toml",
                   help="the base model: its airframe and its [[effect]] tables (default: the reference "
                        "airframe, no effects)")
    p.add_argument("--json", metavar="REPORT.json",
                   help="the report (its keys: docs/diagnose.md); with --corpus, every log's report and refusal")
    p.add_argument("--corpus", metavar="DIR", nargs="+",
                   help="diagnose every log in each DIR and its folders (every log of a file of many), in parallel, "
                        "one row per log, the share of the airborne flights that get a diagnosis on top "
                        "(docs/real-flights.md)")
    p.add_argument("--table", metavar="OUT.md",
                   help="with --corpus: the table, written between OUT.md's corpus markers if it has them")
    p.add_argument("--jobs", type=int, metavar="N", help="with --corpus: processes (default: the cores, at most)")
    p.add_argument("--results", metavar="R.jsonl",
                   help="with --corpus: each log's row as it finishes; a run started again skips the logs in it "
                        "(default: beside --json: OUT.results.jsonl; rows written by another version of the code are diagnosed again)")
    p.add_argument("--fleet", metavar="REPORT",
                   help="with --corpus: the fleet report into the folder REPORT (fleet.md, fleet.json, vehicle-N.png): the "
                        "logs grouped by vehicle, in flight order, what changed on which vehicle from which flight (docs/fleet.md)")
    p.add_argument("--vehicles", metavar="MAP.csv",
                   help="with --fleet: which vehicle each log is of, rows 'log,vehicle' (default: the logs' headers, else "
                        "their folders)")
    engine.add_flag(p, "with --corpus")
    p.add_argument("--plot", metavar="PREFIX",
                   help="write PREFIX-residuals.png (residual vs time, base and after each cause), "
                        "PREFIX-explained.png (residual vs the variable that explains it) and, per log, "
                        "PREFIX-read-K.png (what was read: rates, gaps, channels)")
    p.add_argument("--steps", metavar="STEPS.png",
                   help="the measured step responses of each log: per loop (rate, attitude) and axis, the mean over the "
                        "windows with stick input and their band (docs/steps.md); the numbers are REPORT.json's `steps`")
    p.add_argument("--quiet", action="store_true", help="no progress on stderr")
    return p


def read_logs(paths: list[str], index: int | None, progress, extra: tuple[str, ...] = ()) -> list:
    """Each log as a flight-log table: this project's CSV, or a foreign log through
    `flightctl.sim.logs` (every log of a blackbox file that can be read, or the one at `index`);
    the logs skipped are named on the progress lines; `extra`: more columns a CSV log keeps."""
    from flightctl.sim.logs import kind, read_foreign
    tables = []
    for log in paths:
        progress(f"reading {log}")
        if kind(log) is not None:
            tables += read_foreign(log, index, progress)
        else:
            tables.append(read_flight_log(log, min_seconds=MIN_LOG_S, min_rows=10, extra=FOREIGN_COLUMNS + STATIC_COLUMNS + extra))
    for t in tables:          # a malformed `# thrust_curve:` is bad input, refused before any work
        declared_curve(t)
    return tables


def _per_log(path: str, index: int | None) -> bool:
    """A single file of many logs (and no --index): each log is diagnosed on its own."""
    if index is not None:
        return False
    from flightctl.sim.logs import count_logs, kind
    return kind(path) is not None and count_logs(path) > 1


def main(argv: list[str]) -> int:
    with OneBlasThread():
        return _main(argv)


def _main(argv: list[str]) -> int:
    args = _parser().parse_args(argv)
    if args.corpus is not None and args.steps:
        raise InputError("--steps: the figure is of the logs named; with --corpus each log's `steps` is in --json")
    if args.corpus is not None:
        from flightctl.sim.diagnose.corpus import main as corpus
        engine.use(args.scheduler, args.quiet)
        return corpus(args)
    for flag in ("fleet", "vehicles"):
        if getattr(args, flag):
            raise InputError(f"--{flag}: the fleet report is of a corpus: add --corpus DIR")
    if not args.logs:
        raise InputError("name the flight logs to diagnose, or a folder of them with --corpus DIR")
    if args.json is None:
        raise InputError("--json REPORT.json is required (its keys: docs/diagnose.md)")
    progress = Stages(args.quiet, prefix="diagnose:")
    t0 = time.perf_counter()
    params = paramfile.load(args.params)
    out_json = Path(args.json)
    if args.index is not None and args.index < 1:
        raise InputError(f"--index {args.index}: logs are counted from 1")
    output_file(out_json, "--json", ".json")
    if args.plot:
        output_prefix(args.plot)
    if args.steps:
        output_file(Path(args.steps), "--steps", ".png")
    if len(args.logs) == 1 and _per_log(args.logs[0], args.index):
        return _each(args, params, progress, t0)
    tables = read_logs(args.logs, args.index, progress)
    others = read_logs(args.validate, None, progress) if args.validate else []
    plots = _plot_paths(args.plot, len(tables))
    d = _judge(tables, others, params, args.params is not None, progress)
    images = _images(d, tables, plots)
    report = d.report()
    report["steps"], curves = steps.of(tables)
    report["controller"] = [controller.of_table(t) for t in tables]
    predict.attach(report["steps"], curves, tables, report["controller"], params.airframe, progress)
    _steps_figure(args.steps, curves, plots, images)
    text = diagnose_report.text(d, report) + steps.text(report["steps"]) + controller.text(report["controller"])
    report["runtime_s"] = round(time.perf_counter() - t0, 2)
    _write(out_json, report, plots, images)
    print(text, end="")
    progress(f"done in {time.perf_counter() - t0:.1f} s: {d.cause} {d.parameters}")
    progress.release()
    return 0


def _plot_paths(prefix: str | None, n_tables: int, tag: str = "") -> dict[str, Path]:
    if not prefix:
        return {}
    output_prefix(prefix)
    plots = {k: Path(f"{prefix}{tag}-{k}.png") for k in ("residuals", "explained")}
    plots.update({f"read-{k}": Path(f"{prefix}{tag}-read-{k}.png") for k in range(1, n_tables + 1)})
    for path in plots.values():
        output_file(path, "--plot")
    return plots


def _judge(tables, others, params, given: bool, progress):
    d = diagnose(tables, params.airframe, progress, params.effects, params_given=given, accepted=progress.release)
    if others and isinstance(d, StaticOnly):
        raise InputError(f"--validate predicts with the dynamic tier's model, which these logs did not reach: {d.why}")
    if others:
        d.validation = validate(d, others, params.airframe, progress)
    return d


def _images(d, tables, plots) -> dict[str, bytes]:
    if not plots:
        return {}
    from flightctl.sim.logs import read_figure
    from flightctl.sim.plots import png
    if isinstance(d, StaticOnly):      # no residuals without the dynamic tier: what was read only
        for k in ("residuals", "explained"):
            plots.pop(k, None)
        return {f"read-{k}": png(read_figure(t)) for k, t in enumerate(tables, 1)}
    images = diagnose_report.figures(d)
    images.update({f"read-{k}": png(read_figure(t)) for k, t in enumerate(tables, 1)})
    return images


def _steps_figure(path: str | None, curves: list, plots: dict, images: dict) -> None:
    """--steps: the step responses' figure, written with the others."""
    if path:
        from flightctl.sim.plots import png
        plots["steps"], images["steps"] = Path(path), png(steps.figure(curves))


def _write(out_json: Path, report: dict, plots: dict, images: dict) -> None:
    write_atomic(out_json, json.dumps(report, indent=2, allow_nan=False) + "\n")
    for k, path in plots.items():
        write_atomic(path, images[k])


def _each(args, params, progress, t0) -> int:
    """A file of many logs: each log that holds a flight diagnosed on its own; the others named."""
    from flightctl.sim.logs import each_log, reason, skipped
    path = args.logs[0]
    progress(f"reading {path}: a file of many logs, each diagnosed on its own")
    entries = each_log(path, None, progress)
    others = read_logs(args.validate, None, progress) if args.validate else []
    judged, logs = [], []
    for e in entries:
        if e.table is not None:
            progress(f"log {e.index}: diagnosing {e.seconds:.1f} s")
            try:
                judged.append((e, _judge([e.table], others, params, args.params is not None, progress)))
            except InputError as err:
                e.reason, e.table = reason(str(err), path), None
    if not judged:
        raise InputError(f"{path}: no log could be judged: {skipped(entries)}")
    reports = {e.index: d.report() for e, d in judged}
    curves = []
    for e, d in judged:
        reports[e.index]["steps"], c = steps.of([e.table])
        reports[e.index]["controller"] = [controller.of_table(e.table)]
        predict.attach(reports[e.index]["steps"], c, [e.table], reports[e.index]["controller"], params.airframe, progress)
        curves += c
    for e in entries:
        logs.append({"index": e.index, "judged": True, "report": reports[e.index]} if e.index in reports
                    else {"index": e.index, "judged": False, "reason": e.reason})
    first, d0 = judged[0]
    plots, images = {}, {}
    for e, d in judged:              # PREFIX-logK-residuals.png, ... per log judged
        p = _plot_paths(args.plot, 1, f"-log{e.index}")
        for k, image in _images(d, [e.table], p).items():
            plots[str(p[k])], images[str(p[k])] = p[k], image
    _steps_figure(args.steps, curves, plots, images)
    report = dict(reports[first.index])
    report["logs"] = logs
    report["logs_note"] = (f"the file holds {len(entries)} logs, each diagnosed on its own: the top-level keys are "
                           f"the report of log {first.index}, the first judged; every log's report or the reason it "
                           "was skipped is in `logs`")
    report["runtime_s"] = round(time.perf_counter() - t0, 2)
    texts = [f"== {path} log {e.index} of {len(entries)} ==\n" + diagnose_report.text(d, reports[e.index])
             + steps.text(reports[e.index]["steps"]) + controller.text(reports[e.index]["controller"]) for e, d in judged]
    _write(Path(args.json), report, plots, images)
    print("".join(texts), end="")
    if any(e.table is None for e in entries):
        print(f"skipped: {skipped(entries)}")
    progress(f"done in {time.perf_counter() - t0:.1f} s: {len(judged)} of {len(entries)} logs judged")
    progress.release()
    return 0
