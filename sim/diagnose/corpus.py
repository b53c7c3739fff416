"""`flightctl diagnose --corpus DIR`: every flight log in a folder (and its folders; every log of a file
of many) diagnosed or refused, in parallel, one row per log, so that a person can look at fifty logs at
once (docs/real-flights.md, whose table it writes).

    flightctl diagnose --corpus DIR [--table OUT.md] [--json OUT.json] [--jobs N] [--quiet]

Each log is read (`flightctl.sim.logs.count_logs`, then each log on its own as `each_log` reads it, or
this project's CSV)
and diagnosed on the engine (sim/engine.py: Dask's workers, at most the machine's cores, one BLAS thread
each; a log that kills its worker is that log's failure), each row written to the results table as
it finishes (`--results`, sim/diagnose/results.py; a run started again skips the logs in it); a log that
cannot be read, never flew, or whose data contradict its layout is that log's refusal, with its one
line. The rows are a function of the logs and the code only: sorted by path and index, paths relative
to DIR. `--table` writes the table between OUT.md's markers (`TABLE_BEGIN`, `TABLE_END`) when it has
them, else OUT.md is the table; `--json` every log's report or refusal.
"""
from __future__ import annotations

import json
import os
import sys
from dataclasses import dataclass, field
from pathlib import Path

from flightctl.errors import InputError

from flightctl.files import output_file, output_room, write_atomic
from flightctl.sim.diagnose.static import summary
from flightctl.sim.diagnose.results import default_path
from flightctl.sim.logs.frames import NOT_MULTIROTOR

TABLE_BEGIN = "<!-- diagnose --corpus table: begin -->"
TABLE_END = "<!-- diagnose --corpus table: end -->"
CSV_SUFFIXES = (".csv",)
REPORT_BYTES = 65536      # a log's whole report and its line in the results table, at most: a 30 s hover's
#                           report is 21 kB, a line under 2 kB (checked against the disk before the run)
CRASH_ENV = "FLIGHTCTL_TEST_CRASH_ON"   # tests only: the worker diagnosing the log of this file name exits at once
COLUMNS = ("log", "vehicle", "what was read", "airborne", "tier", "static tier", "causes (each on top of the ones before)",
           "fits, but not physical", "base model: effectiveness (t = value / its jackknife error)", "refused")


@dataclass
class Row:
    log: str                    # the path relative to the corpus, with #index for a file of many logs
    path: str
    index: int | None
    status: str = "refused"     # "diagnosed", "refused", "duplicate" (a byte-identical copy of an earlier file),
                                # or "failed" (a fault of diagnose's, said as such)
    reason: str = ""            # the refusal's one line
    meta: dict = field(default_factory=dict)
    report: dict | None = None
    report_file: str | None = None   # where the report is kept once the row is `stored`
    _cells: list[str] | None = None
    _tier: str | None = None
    _about: bool | None = None

    def stored(self, report_file: str | None) -> None:
        """The report is in `report_file` (the results table's): keep only the table's cells and the
        tier, so that a corpus of many logs is not held in memory until the end."""
        self._cells, self._tier, self._about = self.cells(), self.tier(), self.diagnosed()
        self.report_file, self.report = report_file, None

    def tier(self) -> str | None:
        return self.report.get("tier") if self.report is not None else self._tier

    def diagnosed(self) -> bool:
        """A tier answered about the vehicle itself (`about_the_vehicle`): what the headline counts as diagnosed."""
        if self.report is None:
            return bool(self._about)
        return self.status == "diagnosed" and about_the_vehicle(self.report)

    def full_report(self) -> dict | None:
        """The report, read back from its file when the row was `stored`."""
        if self.report is None and self.report_file:
            return json.loads(Path(self.report_file).read_text())
        return self.report

    def cells(self) -> list[str]:
        if self._cells is not None:
            return self._cells
        read = _read(self.meta, self.report) if self.meta else ""
        vehicle = _vehicle(self.meta) if self.meta else ""
        if self.status != "diagnosed":
            return [self.log, vehicle, read, "", "duplicate" if self.status == "duplicate" else "refused", "", "", "",
                    "", _clean(self.reason)]
        r = self.report
        causes = "; ".join(f"{c['cause']} {_params(c['parameters'])} (gain {c['gain']:.3f})" for c in r["causes"]) or "none"
        unphysical = "; ".join(f"{c['cause']} {_params(c['parameters'])}: {c['why']}" for c in r["not_physical"])
        tier = r.get("tier", "dynamic") + (" (static too)" if r.get("tier") == "dynamic" and r.get("static") else "")
        static = _clean(summary(r["static"])) if r.get("static") else ""
        if r.get("tier") == "static":
            causes = f"not judged: {r['tier_why']}"
        return [self.log, vehicle, read, f"{r['data']['airborne_s']:.1f} s", tier, static, _clean(causes),
                _clean(unphysical), _base(r), ""]


def _clean(text: str) -> str:
    return text.replace("|", "/").replace("\n", " ")


def _params(p: dict) -> str:
    return ", ".join(f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}" for k, v in p.items())


def _vehicle(meta: dict) -> str:
    parts = [meta.get("craft", "").strip(), meta.get("firmware", "").strip() or meta.get("format", "").strip()]
    return _clean(", ".join(p for p in parts if p)) or "this project's log"


def _read(meta: dict, report: dict | None) -> str:
    """What was read: rates, rotor speeds, battery."""
    out = []
    if meta.get("rate_hz"):
        out.append(f"{float(meta['rate_hz']):.0f} Hz")
    if meta.get("motor_rate_hz"):
        out.append(f"motors {float(meta['motor_rate_hz']):.0f} Hz")
    out.append("rotor speeds" if meta.get("omega_source") else "no rotor speeds")
    if meta.get("battery_cells"):
        out.append(f"{meta['battery_cells']}S")
    if report is not None:
        v = report["data"].get("battery_v")
        out.append(f"battery {v[0]:.1f}-{v[1]:.1f} V" if v else "no battery")
    return ", ".join(out)


def _base(r: dict) -> str:
    b = r["base_model"]
    if r.get("tier") == "static":
        return ""
    if not b.get("identified"):
        return "this project's airframe"
    axes = []
    for name, axis in (("k_p", "roll"), ("k_q", "pitch"), ("k_r", "yaw"), ("k_z", "thrust")):
        v, e = b[name]["value"], b[name]["stderr"]
        if b[name].get("unanswered"):
            axes.append(f"{axis}: no accelerometer")
            continue
        axes.append(f"{axis} {v / e:.0f}" if e > 0 else f"{axis} {v:.3g}")
    extra = "; spins reversed by the data" if "spins reversed" in b["layout"]["source"] else ""
    gains = r.get("rotor_gain_check")
    if gains and gains["verdict"] not in ("none",):
        extra += f"; rotor gains: {gains['verdict']}"
    return f"t: {', '.join(axes)}{extra}"


NOT_A_LOG = "not a flight log: no log format's magic bytes (ULog, DataFlash, blackbox), no DataFlash text, not .csv"


def find_logs(folder: Path, others: list | None = None) -> list[Path]:
    """Every file under `folder` that is a flight log, sorted: this project's CSV, and a file another
    autopilot's by its content (`flightctl.sim.logs.kind`: its magic bytes, whatever its name); a file
    whose suffix claims a format and is damaged stays, to be refused with its reason. Each other file
    (a licence, a README) is appended to `others` as (path, why), to be said, never skipped silently."""
    from flightctl.sim.logs import kind
    out = []
    for p in sorted(folder.rglob("*")):
        if not p.is_file():
            continue
        if p.suffix.lower() not in CSV_SUFFIXES:
            try:
                if kind(str(p)) is None:
                    if others is not None:
                        others.append((p, NOT_A_LOG))
                    continue
            except InputError:
                pass
        out.append(p)
    return out


def _jobs(folder: Path, files: list[Path], name: str = "") -> tuple[list[Row], list[Row]]:
    """(rows to diagnose, one per log, and rows already refused: files that cannot be read); each log
    named by its path under `folder`, after `name/` when given."""
    from flightctl.sim.logs import count_logs, reason
    from flightctl.sim.diagnose.results import sha256
    todo, refused, seen = [], [], {}
    for p in files:
        rel = (f"{name}/" if name else "") + p.relative_to(folder).as_posix()
        try:
            first = seen.setdefault(sha256(p), rel)
        except OSError:               # (unreadable: refused below with its reason)
            first = rel
        if first != rel:              # a byte-identical copy: one flight, counted once
            refused.append(Row(rel, str(p), None, status="duplicate",
                               reason=f"a byte-identical copy of {first}: counted once, there"))
            continue
        if p.suffix.lower() in CSV_SUFFIXES:
            todo.append(Row(rel, str(p), None))
            continue
        try:
            n = count_logs(str(p))
        except InputError as e:
            refused.append(Row(rel, str(p), None, reason=reason(str(e), str(p))))
            continue
        if n == 0:
            refused.append(Row(rel, str(p), None, reason="no log in this file"))
        for k in range(1, n + 1):
            todo.append(Row(rel if n == 1 else f"{rel} #{k}", str(p), k if n > 1 else None))
    return todo, refused


def run_one(row: Row) -> Row:
    """Read and diagnose one log, quietly: the row with its report, or its refusal."""
    from flightctl.params import load
    from flightctl.sim.logs import reason
    from flightctl.sim.diagnose.cli import read_logs
    from flightctl.sim.diagnose import steps
    from flightctl.sim.logs import controller
    from flightctl.sim.diagnose.verdict import diagnose
    quiet = lambda *a: None   # noqa: E731
    if os.environ.get(CRASH_ENV) == Path(row.path).name:    # tests/sim/diagnose/test_corpus.py: a log that kills its worker
        os._exit(3)
    try:
        tables = read_logs([row.path], row.index, quiet)
        row.meta = dict(tables[0].meta) if tables else {}
        d = diagnose(tables, load(None).airframe, quiet)
        row.report = d.report()
        row.report["steps"] = steps.of(tables)[0]
        row.report["controller"] = [controller.of_table(t) for t in tables]
        row.status = "diagnosed"
    except InputError as e:
        row.reason = reason(str(e), row.path)
    except Exception as e:         # a fault of diagnose's on this log: said, and the other logs go on
        row.status = "failed"
        row.reason = f"diagnose failed on this log ({type(e).__name__}: {e}): a fault to report"
    return row


# A refusal that says the log holds no flight (data.py, verdict.py, basemodel.py and the readers word them so):
# such a log is not counted among the airborne flights of the corpus' headline.
NO_FLIGHT = ("header only", "never armed", "too short to judge", "may never have left the ground")


def about_the_vehicle(report: dict) -> bool:
    """The report says something of the vehicle itself, what "diagnosed" means in the corpus' headline: the
    dynamic tier ran (its base model and chain of causes, or its refusals of each cause, on the vehicle's
    motion), or the static tier found the hover (thrust margin, the motors' shares, their pattern), the
    vibration or a motor at full command while the vehicle tipped toward it. The battery's voltage and
    resistance alone are the pack's: a log answered on them only (btfl_all.bbl #12: 3.7 s in the air, too
    little hover for the shares) is a flight with no diagnosis of its vehicle."""
    if report.get("tier", "dynamic") != "static":
        return True
    st = report.get("static") or {}
    return any(k in st for k in ("hover", "vibration")) or bool((st.get("motor_at_full") or {}).get("spans"))


def other_vehicle(row: Row) -> bool:
    """The log is of a vehicle that is no multirotor (a plane, a VTOL, a helicopter, a rover: the readers'
    refusals say `frames.NOT_MULTIROTOR`): not one of the airborne multirotor flights of the headline."""
    return row.status == "refused" and NOT_MULTIROTOR in row.reason


def flew(row: Row) -> bool:
    """The log holds a multirotor's flight: it was diagnosed (a tier answered), or refused for a reason
    other than holding no flight or being another vehicle (a failure of diagnose's counts as a flight
    not answered)."""
    return row.status == "diagnosed" or (row.status != "duplicate" and not other_vehicle(row)
                                         and not any(w in row.reason for w in NO_FLIGHT))


def headline(rows: list[Row]) -> str:
    """The share of the airborne multirotor flights that get a diagnosis (`about_the_vehicle`), and of which tier;
    those answered on their battery alone said apart; the logs of
    other vehicles and those of no flight counted apart; a byte-identical copy of another file counted
    once (its own line)."""
    copies = sum(r.status == "duplicate" for r in rows)
    logs = len(rows) - copies
    others = sum(other_vehicle(r) for r in rows)
    flights = [r for r in rows if flew(r)]
    done = [r for r in flights if r.diagnosed()]
    battery = sum(r.status == "diagnosed" and not r.diagnosed() for r in flights)
    static_only = sum(r.tier() == "static" for r in done)
    share = f"{100 * len(done) / len(flights):.0f} %" if flights else "-"
    return (f"**{len(done)} of {len(flights)} airborne multirotor flights get a diagnosis ({share})**: "
            f"{len(done) - static_only} the dynamic tier, {static_only} the static tier only"
            + (f", {battery} {'gets' if battery == 1 else 'get'} the battery's figures alone (no finding of the "
               "vehicle: not counted as diagnosed)" if battery else "") + "; "
            f"{logs - len(flights) - others} of the {logs} logs hold no flight (header only, never armed, "
            "too short or idle, or by its barometer never off the ground)"
            + (f"; {others} {'is a log' if others == 1 else 'are logs'} of another vehicle (a plane, a VTOL, a "
               "helicopter: 'not a multirotor'), not counted" if others else "")
            + (f"; {copies} file{'s' if copies > 1 else ''} a byte-identical copy of another, counted once" if copies
               else ""))


def table(rows: list[Row]) -> str:
    """The headline, then one row per log."""
    from flightctl.sim.docs import table as markdown_table
    return headline(rows) + "\n\n" + "\n".join(markdown_table(COLUMNS, [r.cells() for r in rows]))


def write_table(path: Path, text: str) -> None:
    """The table between the file's markers, or the whole file."""
    from flightctl.sim.docs import write_block
    if not (path.exists() and write_block(path, TABLE_BEGIN, TABLE_END, text)):
        write_atomic(path, f"{TABLE_BEGIN}\n{text}\n{TABLE_END}\n")


def corpus(folders: Path | list[Path], jobs: int | None = None, progress=None,
           results: Path | None = None) -> list[Row]:
    """Every log under the folders diagnosed or refused, rows sorted by path and index, on the engine
    (sim/engine.py); with several folders each row's log is named from its folder's name on. `results`:
    the results table (sim/diagnose/results.py), each log's row written as it finishes; the
    logs already in it are not diagnosed again."""
    folders = [folders] if isinstance(folders, Path) else list(folders)
    todo, rows = [], []
    for folder in folders:
        if not folder.is_dir():
            raise InputError(f"--corpus {folder}: not a folder")
        others: list = []
        files = find_logs(folder, others)
        if not files:
            raise InputError(f"--corpus {folder}: no flight logs in it (.csv, or a ULog, DataFlash or blackbox log "
                             "by its content)")
        if progress and others:
            print(f"diagnose --corpus: {len(others)} files under {folder} not read: "
                  + "; ".join(f"{p.relative_to(folder).as_posix()}: {why}" for p, why in others), file=sys.stderr)
        t, r = _jobs(folder, files, folder.resolve().name if len(folders) > 1 else "")
        todo += t
        rows += r
    from flightctl.sim import engine
    from flightctl.sim.diagnose.results import Results
    table_ = Results(results) if results is not None else None
    if table_ is not None:
        done = table_.done()
        skipped = [table_.restore(r, done[table_.key(r)]) for r in todo if table_.key(r) in done]
        for r in skipped:
            r.stored(done[table_.key(r)].get("report"))
        todo = [r for r in todo if table_.key(r) not in done]
        rows += skipped
        if progress and skipped:
            print(f"diagnose --corpus: {len(skipped)} logs already in {results}, not run again", file=sys.stderr)
    workers = max(1, min(jobs or os.cpu_count() or 1, os.cpu_count() or 1, len(todo) or 1))
    from flightctl.sim.progress import Progress
    bar = Progress(len(todo), "diagnose --corpus ", out=sys.stderr) if progress else None

    def finished(k: int, row: Row) -> None:
        if table_ is not None:
            row.stored(table_.write(row))
        if bar is not None:
            bar.step(f"{row.log}: {row.status}")

    def died(k: int, e: Exception) -> Row:
        row = todo[k]
        row.status, row.reason = "failed", "worker died: its process ended while diagnosing this log (a crash or " \
                                           "the memory exhausted): a fault to report"
        return row
    rows += engine.run(run_one, todo, workers, finished, died, isolate=True)
    return sorted(rows, key=lambda r: (r.path, r.index or 0))


def corpus_json(folders: list[str], rows: list[Row]):
    """`--json`'s text, piece by piece: {"corpus": folders, "logs": [one entry a log, its report read
    back from the results table's file]}, never the whole corpus's reports in memory at once."""
    yield '{"corpus": ' + json.dumps(folders) + ', "logs": ['
    for k, r in enumerate(rows):
        entry = {"log": r.log, "status": r.status, "refused": r.reason or None, "report": r.full_report()}
        yield ("," if k else "") + "\n" + json.dumps(entry, indent=1, allow_nan=False)
    yield "\n]}\n"


def main(args) -> int:
    if args.logs:
        raise InputError("--corpus DIR [DIR ...] takes no other logs: put them in a folder")
    if args.table is None and args.json is None and not args.fleet:
        raise InputError("--corpus: say where the rows go: --table OUT.md, --json OUT.json and/or --fleet REPORT")
    for flag in ("index", "validate", "params", "plot"):
        if getattr(args, flag, None):
            raise InputError(f"--corpus: --{flag} applies to one diagnosis, not to a folder of logs")
    if args.jobs is not None and args.jobs < 1:
        raise InputError(f"--jobs {args.jobs}: at least 1")
    out_table = Path(args.table) if args.table else None
    out_json = Path(args.json) if args.json else None
    for path, flag, suffix in ((out_table, "--table", ".md"), (out_json, "--json", ".json")):
        if path is not None:
            output_file(path, flag, suffix)
    from flightctl.sim.diagnose.fleet import cli as fleet
    fleet_dir, mapping = fleet.check(args, [Path(c) for c in args.corpus], find_logs, _jobs)
    # the results table: --results, else beside --json, else in the fleet report's folder (a table alone,
    # such as docs/'s, keeps none)
    results = Path(args.results) if getattr(args, "results", None) else (
        default_path(out_json) if out_json else fleet_dir / "results.jsonl" if fleet_dir else None)
    if results is not None and results.parent != fleet_dir:
        output_file(results, "--results", ".jsonl")
    if results is not None:       # each log's report goes beside the table: the disk's room first
        n = sum(len(find_logs(Path(c))) for c in args.corpus if Path(c).is_dir())
        output_room(results, n * REPORT_BYTES, "--results" if args.results else "the results table",
                    f"{n} logs' reports of at most {REPORT_BYTES // 1024} kB each")
    if fleet_dir is not None:
        fleet_dir.mkdir(parents=True, exist_ok=True)
    rows = corpus([Path(c) for c in args.corpus], args.jobs, progress=not args.quiet, results=results)
    text = table(rows)
    if out_table is not None:
        write_table(out_table, text)
    if out_json is not None:
        write_atomic(out_json, corpus_json([str(c) for c in args.corpus], rows))
    print(text)
    if fleet_dir is not None:
        fleet.report(rows, results, fleet_dir, mapping, args.quiet)
    done = sum(r.status == "diagnosed" for r in rows)
    failed = sum(r.status == "failed" for r in rows)
    if not args.quiet:
        print(f"diagnose --corpus: {done} of {len(rows)} logs diagnosed, {len(rows) - done - failed} refused"
              + (f", {failed} failed (a fault of diagnose's)" if failed else ""), file=sys.stderr)
    return 0
