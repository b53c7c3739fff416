"""`--fleet REPORT` and `--vehicles MAP.csv` of `flightctl diagnose --corpus`: checked before any log is
read (a bad flag is one line and exit 2, nothing written), and the report made at the run's end from the
results table's rows of the corpus' logs (sim/diagnose/results.py), so that a run resumed from
the table gives the report of the whole corpus."""
from __future__ import annotations

import json
import sys
from pathlib import Path

from flightctl.errors import InputError

from flightctl.files import output_dir


def check(args, folders: list[Path], find_logs, jobs) -> tuple[Path | None, dict | None]:
    """(the report's folder, the mapping log -> vehicle) of the flags, or InputError."""
    from flightctl.sim.diagnose.fleet.grouping import check_map, read_map
    fleet = getattr(args, "fleet", None)
    vehicles = getattr(args, "vehicles", None)
    if vehicles and not fleet:
        raise InputError("--vehicles MAP.csv: applies to the fleet report: add --fleet REPORT")
    if not fleet:
        return None, None
    folder = Path(fleet)
    if folder.exists() and not folder.is_dir():
        raise InputError(f"--fleet {folder}: is a file: the report is a folder (fleet.md, fleet.json, vehicle-N.png)")
    output_dir(folder, "--fleet")
    mapping = None
    if vehicles:
        mapping = read_map(Path(vehicles))
        names = []
        for f in folders:
            if f.is_dir():
                todo, refused = jobs(f, find_logs(f), f.resolve().name if len(folders) > 1 else "")
                names += [(r.log.split(" #")[0], r.path) for r in todo + refused]
        check_map(mapping, names, Path(vehicles))
    return folder, mapping


def table_rows(rows, results: Path) -> list[dict]:
    """The results table's rows of the corpus' logs `rows` (corpus Rows), in their order; a log the table
    does not hold (refused before it was read) keeps its place with its status and no figures."""
    from flightctl.sim.diagnose.results import Results
    table = Results(results)
    done = table.done()
    out = []
    for r in rows:
        d = done.get(table.key(r))
        out.append(dict(d, log=r.log, path=r.path) if d else
                   {"log": r.log, "path": r.path, "index": r.index, "status": r.status, "meta": {}, "figures": None})
    return out


def report(rows, results: Path, folder: Path, mapping: dict | None, quiet: bool) -> dict:
    """The fleet report of the run's rows, written into `folder`; returned."""
    from flightctl.sim.diagnose.fleet.report import build, write
    rep = build(table_rows(rows, results), mapping)
    write(rep, folder)
    if not quiet:
        named = "; ".join(f"{c['vehicle']}: {c['what']} from flight {c['onset_flight'] + 1} ({c['onset_log']})"
                          for c in rep["changes"]) or "no trend named"
        logs = "; ".join(f"{p['vehicle']}: the logs name {p['what']} in {len(p['flights'])} of {p['of']} diagnosed flights from "
                         f"flight {p['first_flight'] + 1}" for p in rep["per_log"]) or "no log names a cause"
        print(f"diagnose --fleet: {len(rep['vehicles'])} vehicles, {rep['findings_tested']} findings tested; {named}; "
              f"{logs}; report in {folder}/fleet.md", file=sys.stderr)
    return rep


def load(folder: Path) -> dict:
    return json.loads((folder / "fleet.json").read_text())
