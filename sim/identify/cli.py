"""`flightctl identify`: fit the paper's models (sections 3.2 and 4.1) to measured data.

    flightctl identify bench|yaw-drag|pendulum|rotor FILE.csv --json OUT.json
                       [--params P.toml] [--write-params P.toml] [--plot OUT.png]
    flightctl identify rcbenchmark RUN.csv [RUN.csv ...] --out bench.csv
    flightctl identify real-data [--data DIR] --out DIR

Everything is read, checked and fitted, and the figure rendered, before the first file is written:
bad input writes nothing (one line on stderr, exit status 2, see flightctl.cli).
"""
from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path

import numpy as np

from flightctl import params as paramfile
from flightctl.errors import InputError, Parser
from flightctl.files import output_file, read_toml, write_atomic
from flightctl.logfile import BENCH_COLUMNS, PENDULUM_COLUMNS, YAW_DRAG_COLUMNS, read_table
from flightctl.sim.identify import inertia, propeller, yaw_drag
from flightctl.sim.identify.fits import FitError, Identified, check_result

KINDS = {  # kind: (help, columns, text columns, identify)
    "bench": ("eq. 26-28 from one steady point per row and motor", BENCH_COLUMNS, (), propeller.identify),
    "yaw-drag": ("eq. 6 from steady spins on the bearing", YAW_DRAG_COLUMNS, (), yaw_drag.identify),
    "pendulum": ("eq. 17-18: Jxx, Jyy, Jzz from pendulum periods", PENDULUM_COLUMNS, ("axis",),
                 inertia.identify_pendulum),
    "rotor": ("eq. 19-21: Jp from blade and motor masses and radii", inertia.ROTOR_COLUMNS, ("part",),
              inertia.identify_rotor),
}

SUBCOMMANDS = (*KINDS, "rcbenchmark", "real-data")    # an error names `flightctl identify bench` (flightctl/cli.py)


def _parser() -> argparse.ArgumentParser:
    parser = Parser(prog="flightctl identify", description="Fit the paper's models to measured data "
                     "(the files' columns and units: docs/identification.md in the flightctl checkout).")
    sub = parser.add_subparsers(dest="kind", required=True, metavar="KIND")
    for kind, (doc, *_rest) in KINDS.items():
        p = sub.add_parser(kind, help=doc, description=doc)
        p.add_argument("file", metavar="FILE.csv", help="the measured data (its columns: docs/identification.md)")
        p.add_argument("--json", required=True, metavar="OUT.json", help="the fitted parameters with stderr")
        p.add_argument("--params", metavar="P.toml", help="parameter file (the pendulum takes M and g from it)")
        p.add_argument("--write-params", metavar="P.toml", help="write the fitted values into this parameter file")
        p.add_argument("--plot", metavar="OUT.png", help="data, fit and residuals like the paper's figures 6-9")
    p = sub.add_parser("rcbenchmark", help="convert RCbenchmark stand exports (one per motor, at most 4) "
                       "to a bench.csv")
    p.add_argument("runs", nargs="+", metavar="RUN.csv", help="the stand's CSV exports, motor 1 first")
    p.add_argument("--out", required=True, metavar="bench.csv", help="the bench file to write")
    p = sub.add_parser("real-data", help="report: the paper's propeller method against real thrust-stand data")
    p.add_argument("--data", metavar="DIR", help="the real data (default: ../shared/data/real beside the checkout you run in)")
    p.add_argument("--out", required=True, metavar="DIR", help="where the figures and identification.md go")
    return parser


def _check_params_update(path: str, values: dict[str, float]) -> None:
    """What `params.update_file` will do, without writing: refuse before anything is written."""
    target = Path(path)
    data = {}
    if target.exists():
        paramfile.load(target)
        data = read_toml(target)
    try:
        paramfile.from_dict({**data, **values})
    except InputError as e:
        raise InputError(f"{path}: the fitted values are refused by the parameter schema: {e}") from None


def identify(args) -> Identified:
    _doc, columns, text, fit = KINDS[args.kind]
    for flag, path, suffix in (("--json", args.json, ".json"), ("--write-params", args.write_params, ".toml"),
                               ("--plot", args.plot, ".png")):
        if path:
            output_file(path, flag, suffix)
    airframe = paramfile.load(args.params).airframe
    table = read_table(args.file, columns, text_columns=text)
    try:
        with np.errstate(all="ignore"):      # an overflow is found below, not printed as a warning
            result = fit(table, airframe)
        check_result(result)
    except FitError as e:
        table.fail(str(e))
    if args.write_params:
        _check_params_update(args.write_params, result.values)
    image = None
    if args.plot:
        from flightctl.sim.identify.plots import FIGURES
        from flightctl.sim.plots import png
        image = png(FIGURES[args.kind](*result.figure_data))
    write_atomic(args.json, json.dumps(result.report, indent=2, allow_nan=False) + "\n")
    written = [f"  fit -> {args.json}"]
    if args.write_params:
        paramfile.update_file(args.write_params, result.values, f"flightctl identify {args.kind} {args.file}")
        written.append(f"  parameters -> {args.write_params}")
    if image is not None:
        write_atomic(args.plot, image)
        written.append(f"  plot -> {args.plot}")
    return dataclasses.replace(result, summary=list(result.summary) + written)


def main(argv: list[str]) -> int:
    args = _parser().parse_args(argv)
    if args.kind == "rcbenchmark":
        output_file(args.out, "--out", ".csv")
        from flightctl.sim.identify import realdata
        lines = realdata.convert(args.runs, args.out)
    elif args.kind == "real-data":
        from flightctl.sim.identify import realdata
        data_dir, out_dir = realdata.report_dirs(args.data, args.out)
        from flightctl.sim.identify import realplots
        res = realdata.analyse(data_dir)
        lines = realdata.write_report(res, realplots.images(res), args.data, out_dir)
    else:
        lines = identify(args).summary
    print("\n".join(lines))
    return 0
