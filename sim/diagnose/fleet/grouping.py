"""The logs of a corpus grouped by vehicle and put in flight order, from the rows of the results table
(sim/diagnose/results.py), so that the fleet report is rebuilt from the table alone.

Which vehicle, first that applies: the user's mapping (`--vehicles MAP.csv`, rows `log,vehicle`: the
log as the corpus names it, its path, or its file name); the vehicle's identity in the log's header
(sim/logs/identity.py: ArduPilot's board UID or BRD_SERIAL_NUM, PX4's sys_uuid, Betaflight's and INAV's
craft name with its board; never a board's name alone, a model many vehicles share); a log without one in a
file of many logs whose others all name one vehicle (a header-only log refused before its header was read),
that vehicle; else the log's folder (one folder per vehicle). The order of a vehicle's flights:
the logs' own start times (GPS time, the blackbox's RTC, PX4's time_ref_utc) when every log of the
vehicle has one, else the logs' names in natural order (`00000009.BIN` before `00000010.BIN`); the
report says which for each vehicle.
"""
from __future__ import annotations

import csv
import re
from dataclasses import dataclass, field
from pathlib import Path

from flightctl.errors import InputError


@dataclass
class Vehicle:
    name: str
    source: str                  # how its logs were told to be its
    order: str = ""              # how its flights were put in order
    flights: list[dict] = field(default_factory=list)     # results-table rows, in flight order


def natural(name: str) -> list:
    """A name's sort key with its digit runs as numbers."""
    return [int(p) if p.isdigit() else p.lower() for p in re.split(r"(\d+)", name)]


def read_map(path: Path) -> dict[str, str]:
    """The rows of `--vehicles MAP.csv` (a header `log,vehicle`, then one row per log) as log -> vehicle;
    InputError naming the file and row of what is wrong."""
    try:
        text = path.read_text()
    except OSError as e:
        raise InputError(f"--vehicles {path}: {e.strerror or e}") from None
    except UnicodeDecodeError:
        raise InputError(f"--vehicles {path}: not a text file (CSV with the columns log,vehicle)") from None
    rows = list(csv.reader(text.splitlines()))
    if not rows or [c.strip().lower() for c in rows[0]] != ["log", "vehicle"]:
        raise InputError(f"--vehicles {path}: row 1: the header must be 'log,vehicle'")
    out = {}
    for k, row in enumerate(rows[1:], start=2):
        if not row or not "".join(row).strip():
            continue
        if len(row) != 2 or not row[0].strip() or not row[1].strip():
            raise InputError(f"--vehicles {path}: row {k}: expected a log and a vehicle, got {','.join(row)!r}")
        log = row[0].strip()
        if log in out and out[log] != row[1].strip():
            raise InputError(f"--vehicles {path}: row {k}: {log} is given two vehicles ({out[log]}, {row[1].strip()})")
        out[log] = row[1].strip()
    if not out:
        raise InputError(f"--vehicles {path}: no rows after the header")
    return out


def check_map(mapping: dict[str, str], names: list[tuple[str, str]], path: Path) -> None:
    """InputError for a mapped log that is none of the corpus' (`names`: (corpus name, file path))."""
    known = set()
    for log, p in names:
        known |= {log, p, Path(p).name, str(Path(p).resolve())}
    for log in mapping:
        if log not in known:
            raise InputError(f"--vehicles {path}: {log}: no such log in the corpus")


def _vehicle_of(row: dict, mapping: dict[str, str]) -> tuple[str, str]:
    for key in (row["log"], row["path"], Path(row["path"]).name):
        if key in mapping:
            return mapping[key], "--vehicles"
    meta = row.get("meta") or {}
    if meta.get("vehicle_id"):
        return meta["vehicle_id"], meta.get("vehicle_id_source") or "the log's header"
    folder = Path(row["log"]).parent.as_posix()
    why = (f" (its header names only its board, {meta['board']}: a board model, not a vehicle)" if meta.get("board")
           else "")
    return (folder if folder != "." else "(the corpus' folder)"), "the log's folder" + why


def group(rows: list[dict], mapping: dict[str, str] | None = None) -> list[Vehicle]:
    """The vehicles of the table's rows (diagnosed or not: a refused flight keeps its place in the order),
    each with its flights in order; vehicles by name."""
    mapping = mapping or {}
    by: dict[str, Vehicle] = {}
    ids: dict[str, set] = {}                 # a file's logs' identities (a blackbox file of many logs)
    for row in rows:
        if (row.get("meta") or {}).get("vehicle_id"):
            ids.setdefault(row["path"], set()).add((row["meta"]["vehicle_id"], row["meta"].get("vehicle_id_source")))
    for row in rows:
        name, source = _vehicle_of(row, mapping)
        same = ids.get(row["path"], set())
        if source.startswith("the log's folder") and len(same) == 1:
            # a log refused before its header was read (a header-only log), in a file whose other logs all
            # name one vehicle: one flight controller's flash, so that vehicle's
            name, source = next(iter(same))[0], "its file's other logs (one flight controller's flash)"
        v = by.setdefault(name, Vehicle(name, source))
        if source not in v.source.split("; "):
            v.source += f"; {source}"
        v.flights.append(row)
    for v in by.values():
        starts = [(r.get("meta") or {}).get("start_utc") for r in v.flights]
        if all(starts):
            v.flights.sort(key=lambda r: (r["meta"]["start_utc"], natural(r["log"])))
            sources = sorted({r["meta"].get("start_source") or "the log's start time" for r in v.flights})
            v.order = "the logs' start times (" + "; ".join(sources) + ")"
        else:
            v.flights.sort(key=lambda r: (natural(r["log"]), r.get("index") or 0))
            missing = sum(not s for s in starts)
            v.order = (f"the logs' names ({missing} of {len(starts)} logs have no start time: GPS time, the blackbox's "
                       "RTC or PX4's time_ref_utc)")
    return [by[k] for k in sorted(by, key=natural)]
