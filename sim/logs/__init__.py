"""Flight logs of other autopilots, read into this project's flight-log table (docs/measured-data.md,
"Foreign logs"; docs/log-import.md): PX4's ULog through pyulog, ArduPilot's DataFlash through
pymavlink's DFReader, and the blackbox of Betaflight, INDIflight and INAV through orangebox 0.4.0, all
in the `logs` extra (orangebox is GPL-3.0: an optional extra only).

    each_log(path, index=None, progress=None) -> [LogEntry]   every log of the file, read or skipped on its own
    read_foreign(path, index=None, progress=None) -> [Table]  the logs read (InputError when none is)
    import_text(path, index, progress) -> str                 the flight-log CSV of one log (`flightctl log import`)
    read_figure(table) -> Figure                              what was read: rates, gaps, channels
"""
from __future__ import annotations

import importlib
import re
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from flightctl.errors import InputError

from flightctl.files import read_bytes
from flightctl.logfile import Table
from flightctl.sim.logs.columns import all_running, motor_columns
from flightctl.sim.logs.common import EXTRA as EXTRA_COLUMNS
from flightctl.sim.logs.common import Imported, flight_text, parser_said, to_table

DATAFLASH_MAGIC = b"\xa3\x95\x80"        # a DataFlash file opens with its FMT message's definition
ULOG_MAGIC = b"ULog\x01\x12\x35"        # ULog's file header (PX4's ULog file format), then its version byte
BLACKBOX_MAGIC = b"H Product:Blackbox"   # a blackbox log's first header line (Betaflight's, INAV's)
MIN_FLIGHT_S = 2.0                       # s with all four motors running: a log that holds a flight


@dataclass
class LogEntry:
    """One log of a file: its table when read (`reason` None), else why it was skipped (one line).
    `seconds` is the log's length (s of rows read), `running_s` how long all four motors ran (above
    1 % of their range), `text` the flight-log CSV that `flightctl log import` writes of it."""
    index: int
    table: Table | None
    reason: str | None
    seconds: float
    text: str | None = None
    running_s: float = 0.0

    @property
    def flight(self) -> bool:
        return self.table is not None and self.running_s >= MIN_FLIGHT_S


@dataclass(frozen=True)
class Reader:
    """One log format: a row of READERS. `magic`: the bytes its file opens with, or a test of the file's
    first 4096 bytes; `reader` ("module:function", imported when a log is read) gives a log's Imported
    (or a str: the text of this project's own log) from the path, or with `split` ("module:function":
    the file's bytes -> [(start, end)] of each log, several logs per file) from (path, the log's bytes,
    start, the file's size, its name); `called` and `missing` say what a file named like it but
    without its content is not, and lacks."""
    name: str
    what: str
    suffixes: tuple[str, ...]            # compared in lower case
    magic: bytes | Callable[[bytes], bool]
    reader: str
    split: str | None = None
    options: tuple[tuple[str, object], ...] = ()      # keyword arguments of `reader`
    called: str = ""
    missing: str = ""

    def matches(self, head: bytes) -> bool:
        return head.startswith(self.magic) if isinstance(self.magic, bytes) else self.magic(head)

    def read(self, *args):
        return _resolve(self.reader)(*args, **dict(self.options))


def _resolve(name: str):
    module, _, function = name.partition(":")
    return getattr(importlib.import_module(module), function)


def _dataflash_text(head: bytes) -> bool:
    from flightctl.sim.logs.dataflash import preamble
    return preamble(head) is not None     # FMT lines, after a dump's few header lines


# The log formats, tried in this order on the file's first bytes, whatever its name (adding one: its
# reader module beside these and one row; docs/architecture.md, "Where to add").
READERS = (
    Reader("ulog", "PX4's ULog", (".ulg",), ULOG_MAGIC, "flightctl.sim.logs.ulog:read",
           called="a ULog", missing="no ULog header"),
    Reader("dataflash", "ArduPilot's DataFlash", (".bin",), DATAFLASH_MAGIC, "flightctl.sim.logs.dataflash:read",
           called="an ArduPilot DataFlash log", missing="no FMT message at its start"),
    Reader("blackbox", "the blackbox of Betaflight, INDIflight and INAV", (".bbl", ".bfl", ".txt"), BLACKBOX_MAGIC,
           "flightctl.sim.logs.blackbox:read", split="flightctl.sim.logs.blackbox:split",
           called="a blackbox log", missing="no 'H Product:Blackbox' header"),
    Reader("dataflash-text", "ArduPilot's DataFlash as text", (".log", ".txt"), _dataflash_text,
           "flightctl.sim.logs.dataflash:read", options=(("text", True),),
           called="an ArduPilot DataFlash text dump", missing="no FMT lines"),
)
BY_NAME = {r.name: r for r in READERS}
TEXT_SUFFIXES = (".txt", ".log")     # text of other formats and of this project's own logs: never refused by name
FOREIGN_SUFFIXES = tuple(dict.fromkeys(s for r in READERS for s in r.suffixes))


def known_formats() -> str:
    """The formats READERS reads, each with its suffixes: for an error line."""
    return ", ".join(f"{r.what} ({'/'.join(r.suffixes)})" for r in READERS)


def kind(path: str) -> str | None:
    """The name of the READERS row whose magic the file's first bytes have, whatever the file's name
    ('ulog', 'dataflash', 'blackbox', 'dataflash-text'); None for a file that is not another autopilot's
    log (this project's CSV). InputError for a file whose suffix claims a binary log format its bytes
    do not have, naming the formats known."""
    suffix = Path(path).suffix.lower()
    head = read_bytes(path, 4096)         # a regular, readable file (files.read_bytes), and its magic
    for r in READERS:
        if r.matches(head):
            return r.name
    claimed = next((r for r in READERS if suffix in r.suffixes), None)
    if claimed is None or suffix in TEXT_SUFFIXES:
        return None                       # a text file of this project's kind (docs/measured-data.md)
    if not head:
        raise InputError(f"{path}: empty file")
    raise InputError(f"{path}: not {claimed.called} ({claimed.missing}); the formats read by their content, "
                     f"whatever the file's name: {known_formats()}")


def _kind(path: str) -> Reader:
    k = kind(path)
    if k is None:
        raise InputError(f"{path}: unknown log type {Path(path).suffix or '(no suffix)'}: its content is none of "
                         f"{known_formats()}")
    return BY_NAME[k]


def count_logs(path: str) -> int:
    """How many logs the file holds (one, or as its format's `split` finds them: a blackbox file one or more)."""
    r = _kind(path)
    return 1 if r.split is None else len(_resolve(r.split)(read_bytes(path)))


def _guarded(name: str, fn):
    """Run a reader; what a third-party parser raises on damaged bytes becomes one line."""
    try:
        return fn()
    except InputError:
        raise
    except Exception as e:        # pyulog, pymavlink and orangebox raise what the bytes give them
        raise InputError(f"{name}: damaged or unreadable log ({parser_said(e)})") from None


def reason(error: str, path: str) -> str:
    """An InputError's line without the file's path (`PATH: `, `PATH#k: `, or so with the file's name):
    the reason a log was skipped or refused, where the row or the list names the log."""
    for p in (path, Path(path).name):
        error = re.sub(rf"^{re.escape(p)}(#\d+)?: ", "", error)
    return error


def _entry(index: int, name: str, read, progress) -> LogEntry:
    """Read one log (`read` gives its Imported, or the text of a log of this project's own: its ULog)
    into an entry, or the reason it was skipped."""
    try:
        imp: Imported | str = _guarded(name, read)        # (a str: the project's own log's text, read whole)
        text = imp if isinstance(imp, str) else _guarded(name, lambda: flight_text(imp, progress))
        table = to_table(text, name)
        if isinstance(imp, str) and progress:
            progress(f"{name}: flightctl's own ULog, read back whole: {len(table)} rows")
    except InputError as e:
        return LogEntry(index, None, reason(str(e), name), 0.0)
    t = table["t"]
    running = all_running(np.vstack([table[c] for c in motor_columns(table)]))
    running_s = float(np.sum(np.diff(t)[running[:-1]])) if t.size > 1 else 0.0
    return LogEntry(index, table, None, float(t[-1] - t[0]), text, running_s)


def each_log(path: str, index: int | None = None, progress=None) -> list[LogEntry]:
    """Every log of `path` (or the one at `index`, from 1), each read or skipped on its own: a log
    that is empty, damaged or of a vehicle not read never takes the others with it. File-level problems
    (unreadable, unknown, an index that does not exist) raise InputError."""
    r = _kind(path)
    say = progress or (lambda *a: None)
    if r.split is None:
        if index not in (None, 1):
            raise InputError(f"{path}: this log type holds one log: --index {index} does not exist")
        return [_entry(1, path, lambda: r.read(path), progress)]
    data = read_bytes(path)
    spans = _resolve(r.split)(data)
    n = len(spans)
    if n == 0:
        raise InputError(f"{path}: no log in this {r.name} file")
    if index is not None and not 1 <= index <= n:
        raise InputError(f"{path}: --index {index} does not exist (the file holds {n} log{'s' if n > 1 else ''})")
    out = []
    for i in [index] if index else range(1, n + 1):
        a, b = spans[i - 1]
        name = f"{path}#{i}" if n > 1 else path
        start = time.perf_counter()
        entry = _entry(i, name, lambda: r.read(path, data[a:b], a, len(data), name), progress)
        if n > 1:
            say(f"log {i} of {n}: " + (entry.reason or f"{entry.seconds:.1f} s, motors running {entry.running_s:.1f} s")
                + f" ({time.perf_counter() - start:.1f} s)")
        out.append(entry)
    return out


def _ranges(indices: list[int]) -> str:
    """'2-3, 5, 7-11' of sorted log numbers."""
    parts, i = [], 0
    while i < len(indices):
        j = i
        while j + 1 < len(indices) and indices[j + 1] == indices[j] + 1:
            j += 1
        parts.append(f"{indices[i]}" if i == j else f"{indices[i]}-{indices[j]}")
        i = j + 1
    return ", ".join(parts)


def skipped(entries: list[LogEntry]) -> str:
    """Which logs were skipped and why, grouped by reason: '2-3, 5: header only ...; 9: damaged ...'."""
    by: dict[str, list[int]] = {}
    for e in entries:
        if e.table is None:
            by.setdefault(e.reason or "", []).append(e.index)
    return "; ".join(f"{'log' if len(v) == 1 else 'logs'} {_ranges(v)}: {r}" for r, v in by.items())


def summary(path: str, entries: list[LogEntry]) -> str:
    """One line: which logs of a file hold a flight, which were read without one, which were skipped."""
    flights = [e for e in entries if e.flight]
    ground = [e.index for e in entries if e.table is not None and not e.flight]
    parts = [f"{path}: holds {len(entries)} logs"]
    if flights:
        parts.append(f"{len(flights)} hold a flight (" + ", ".join(
            f"{e.index}: {e.seconds:.0f} s, motors running {e.running_s:.0f} s" for e in flights) + ")")
    if ground:
        parts.append(f"{_ranges(ground)} read without a flight (all four motors running under {MIN_FLIGHT_S:g} s)")
    if any(e.table is None for e in entries):
        parts.append("skipped " + skipped(entries))
    return "; ".join(parts)


def read_foreign(path: str, index: int | None = None, progress=None) -> list[Table]:
    """The tables of the logs of `path` that were read (as `read_flight_log` gives the CSV that
    `flightctl log import` writes of each); InputError naming every reason when none was."""
    entries = each_log(path, index, progress)
    tables = [e.table for e in entries if e.table is not None]
    if not tables:
        if len(entries) == 1:
            raise InputError(f"{path}: {entries[0].reason}")
        raise InputError(f"{path}: no log could be read: {skipped(entries)}")
    return tables


def import_text(path: str, index: int | None = None, progress=None) -> str:
    """The flight-log CSV text of the one log of `path` (`index` when it holds several)."""
    entries = each_log(path, index, progress)
    if len(entries) > 1:
        raise InputError(summary(path, entries) + ": choose one with --index N")
    (entry,) = entries
    if entry.table is None:
        raise InputError(f"{path}{'#' + str(entry.index) if index else ''}: {entry.reason}")
    return entry.text


def read_figure(table: Table):
    """What was read (from the table and its metadata alone, so a foreign log and its CSV draw the
    same figure): each stream's rate and gaps, and the channels over time."""
    from flightctl.sim.logs.figure import read_figure as draw
    return draw(table)
