"""The results table of `flightctl diagnose --corpus`: one JSON line per log, written as the log
finishes (JSON lines: https://jsonlines.org), and what a run started again skips.

A row is keyed by the log file's content (its sha256) and its index in a file of many logs, so that a
log renamed or moved is still done and a log rewritten is diagnosed again; and it names the code that
judged it (`code`: a digest of the readers' and the diagnosis' sources), so that a row of another
version of flightctl is diagnosed again rather than reused. It holds the key figures
(status, the refusal's or failure's line, the seconds airborne, the causes named, what was read: the
vehicle's identity and the flight's start among it; the figures the fleet report follows across flights,
sim/diagnose/fleet/followed.py, each with its standard error) and
the path of the log's whole report, a JSON file of its own in the folder beside the table
(`R.reports/`). A log whose worker died (it crashed the process: sim/engine.py's `WorkerDied`) is a
row too, status "failed", its reason "worker died: ...": the run goes on, and a run started again
does not fly it again (delete its line to retry it). A last line cut short by a killed run is ignored.
"""
from __future__ import annotations

import hashlib
import json
import os
import time
from pathlib import Path

from flightctl.sim.diagnose.fleet.followed import figures

META = ("craft", "firmware", "format", "rate_hz", "motor_rate_hz", "omega_source", "battery_cells", "vehicle_id",
        "vehicle_id_source", "board", "start_utc", "start_source")


def sha256(path: str | Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def code_digest() -> str:
    """The sources that decide a log's row (the readers, the diagnosis and its causes, the static tier),
    as one sha256: rows written by other code are not reused."""
    import flightctl.sim as sim
    root = Path(sim.__file__).parent
    h = hashlib.sha256()
    for sub in ("logs", "identify", "causes"):
        for f in sorted((root / sub).rglob("*.py")):
            if f.parent.name == "fleet" and f.name != "followed.py":    # the fleet report reads rows, makes none
                continue
            h.update(f.relative_to(root).as_posix().encode())
            h.update(f.read_bytes())
    return h.hexdigest()[:16]


def default_path(out: Path) -> Path:
    """Beside the command's output: OUT.json -> OUT.results.jsonl."""
    return out.with_suffix(".results.jsonl")


class Results:
    def __init__(self, path: Path):
        self.path = Path(path)
        self.reports = self.path.with_suffix(".reports")
        self._hash: dict[str, str] = {}
        self.code = code_digest()

    def key(self, row) -> tuple[str, int]:
        if row.path not in self._hash:
            self._hash[row.path] = sha256(row.path)
        return self._hash[row.path], row.index or 0

    def done(self) -> dict[tuple[str, int], dict]:
        """The rows already written by this code, by key (the last one of a key wins)."""
        out = {}
        if not self.path.exists():
            return out
        for line in self.path.read_text().splitlines():
            try:
                d = json.loads(line)
            except json.JSONDecodeError:       # a line cut short by a killed run
                continue
            if d.get("code") == self.code:
                out[(d["sha256"], d["index"] or 0)] = d
        return out

    def restore(self, row, d: dict):
        """`row` (a corpus Row) as the table recorded it: status, reason, what was read, the report."""
        row.status, row.reason, row.meta = d["status"], d["reason"] or "", d.get("meta") or {}
        row.report = json.loads(Path(d["report"]).read_text()) if d.get("report") else None
        return row

    def write(self, row) -> str | None:
        """The row of a finished log: its report into the reports folder, its line appended and flushed;
        the report's file (None: no report)."""
        digest, index = self.key(row)
        report = None
        if row.report is not None:
            self.reports.mkdir(parents=True, exist_ok=True)
            report = self.reports / f"{digest[:16]}{f'-{index}' if index else ''}.json"
            report.write_text(json.dumps(row.report, indent=1, allow_nan=False) + "\n")
        r = row.report or {}
        line = {"sha256": digest, "index": row.index, "code": self.code, "log": row.log, "path": row.path, "status": row.status,
                "reason": row.reason or None, "airborne_s": (r.get("data") or {}).get("airborne_s"),
                "causes": [c["cause"] for c in r.get("causes", [])],
                "not_physical": [c["cause"] for c in r.get("not_physical", [])],
                "meta": {k: _plain(row.meta[k]) for k in META if k in (row.meta or {})},
                "figures": figures(row.report), "report": str(report) if report else None,
                "finished": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
        with open(self.path, "a") as f:
            f.write(json.dumps(line, allow_nan=False) + "\n")
            f.flush()
            os.fsync(f.fileno())
        return line["report"]


def _plain(v):
    """A header value as JSON holds it."""
    if isinstance(v, (str, int, float, bool)) or v is None:
        return v.item() if hasattr(v, "item") else v
    try:
        return float(v)
    except (TypeError, ValueError):
        return str(v)
