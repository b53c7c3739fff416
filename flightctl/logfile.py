"""The measured-data files of `docs/measured-data.md`: reading with one-line errors, and the flight log writer.

Every reader returns a `Table`: float columns (empty cells and `nan` are NaN) plus the `# key: value`
metadata. Errors name the file, the row (line number in the file) or column, and what is wrong.
"""
from __future__ import annotations

import csv
import io
import math
import multiprocessing
import os
import queue
import signal
import sys
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO

import numpy as np

from flightctl.errors import NUMBER_CHARS, InputError, parse_number

from flightctl.files import output_room, read_text, temporary_beside

FLIGHT_COLUMNS = ("t", "P1", "P2", "P3", "P4", "gyro_x", "gyro_y", "gyro_z", "acc_x", "acc_y", "acc_z",
                  "range", "battery_v", "roll", "pitch", "yaw", "alt",
                  "roll_sp", "pitch_sp", "yaw_sp", "alt_sp")
MAG_COLUMNS = ("mag_x", "mag_y", "mag_z")
IMU_COLUMNS = ("gyro_x", "gyro_y", "gyro_z", "acc_x", "acc_y", "acc_z")
# Columns that may be empty on most rows: range is only written on rows where an echo arrived.
SPARSE_COLUMNS = ("range",) + MAG_COLUMNS
# The controller's own estimates and setpoints: a log of another autopilot may not have them
# (docs/measured-data.md: empty cells are missing values); the measurements and commands are required.
ESTIMATE_COLUMNS = ("roll", "pitch", "yaw", "alt", "roll_sp", "pitch_sp", "yaw_sp", "alt_sp")
BENCH_COLUMNS = ("motor", "P", "thrust", "omega", "voltage", "current")
YAW_DRAG_COLUMNS = ("torque", "yaw_rate")
PENDULUM_COLUMNS = ("axis", "pivot_distance", "period")


@dataclass
class Table:
    path: str
    columns: dict[str, np.ndarray]
    meta: dict[str, str] = field(default_factory=dict)
    lines: np.ndarray | None = None  # file line number of each row, for error messages
    cut_short: str | None = None     # how the file was cut short (read_table's whole_lines), or None

    def __getitem__(self, name: str) -> np.ndarray:
        return self.columns[name]

    def __contains__(self, name: str) -> bool:
        return name in self.columns

    def __len__(self) -> int:
        return len(self.lines) if self.lines is not None else 0

    def row_line(self, i: int) -> int:
        return int(self.lines[i])

    def fail(self, what: str, row: int | None = None, column: str | None = None):
        where = [self.path]
        if row is not None:
            where.append(f"row {self.row_line(row)}")
        if column is not None:
            where.append(f"column {column!r}")
        raise InputError(f"{': '.join(where)}: {what}")


def read_table(path: str | Path, required: tuple[str, ...], text_columns: tuple[str, ...] = (),
               optional: tuple[str, ...] = (), min_rows: int = 1,
               allow_missing: tuple[str, ...] = (), text: str | None = None, whole_lines: bool = False) -> Table:
    """Read a CSV with a header row. `required` columns must be present; cells in them must be
    numbers (or, in `allow_missing`, empty/nan). `text_columns` are kept as strings. `text`: the
    file's content already in hand (a log imported in memory), named `path` in messages.

    `whole_lines`: every row of the file ends with a newline (FlightLogWriter's flight logs), so that a
    last line without one is a row cut short (a full card, a copy stopped half-way): it is left out and
    named in `Table.cut_short` (read_flight_log says it)."""
    path = str(path)
    content = read_text(path) if text is None else text
    f = io.StringIO(content, newline="")   # regular file, UTF-8, bounded lines
    meta: dict[str, str] = {}
    with f:
        header, header_line = None, 0
        rows, lines = [], []
        last_is_row = False
        for lineno, raw in enumerate(f, start=1):
            s = raw.strip()
            if not s:
                continue
            last_is_row = False
            if s.startswith("#"):
                key, sep, value = s[1:].partition(":")
                if sep:
                    key, value = key.strip(), value.strip()   # FlightLogWriter writes a multi-line value as repeated keys
                    meta[key] = f"{meta[key]}\n{value}" if key in meta else value
                continue
            try:
                cells = next(csv.reader([raw]))
            except csv.Error as e:
                raise InputError(f"{path}: row {lineno}: not CSV ({e})") from None
            if header is None:
                header, header_line = [c.strip() for c in cells], lineno
                continue
            rows.append(cells)
            lines.append(lineno)
            last_is_row = raw == raw.rstrip("\r\n")         # the file's last line, without its newline
    if header is None:
        raise InputError(f"{path}: no header row (the file is empty)")
    cut = None
    if last_is_row and whole_lines:
        cut = f"its last line ({lines[-1]}) ends mid-row, without a newline; read without it"
        rows.pop()
        lines.pop()
    index = {name: i for i, name in enumerate(header)}
    if len(index) < len(header):
        twice = next(name for name in header if header.count(name) > 1)
        raise InputError(f"{path}: line {header_line}: column {twice!r} appears twice in the header")
    for name in required:
        if name not in index:
            raise InputError(f"{path}: missing column {name!r} (line {header_line} has: {', '.join(header)})")
    if len(rows) < min_rows:
        raise InputError(f"{path}: too short: {len(rows)} data rows, at least {min_rows} needed")
    wanted = tuple(required) + tuple(c for c in optional if c in index)
    columns = {} if text_columns else _fast_columns(rows, index, wanted, allow_missing)
    if columns is None or text_columns:
        columns = _checked_columns(path, rows, lines, index, wanted, text_columns, allow_missing)
    return Table(path, columns, meta, np.array(lines), cut)


def _fast_columns(rows, index, wanted, allow_missing):
    """All numeric, no missing cell where one is not allowed: one numpy conversion per column.
    None sends the caller to the cell-by-cell path, which finds and names what is wrong."""
    try:
        width = len(index)
        if any(len(r) != width for r in rows):
            return None
        out = {}
        for name in wanted:
            i = index[name]
            cells = [r[i] for r in rows]
            if name in allow_missing:
                cells = [c if c.strip() else "nan" for c in cells]
            if not set("".join(cells)) <= NUMBER_CHARS:   # '1_0', ' 5 ': numpy would read them (10, 5)
                return None
            values = np.array(cells, dtype=float)
            if not np.isfinite(values).all() and (name not in allow_missing or np.isinf(values).any()):
                return None
            out[name] = values
        return out
    except ValueError:
        return None


def _checked_columns(path, rows, lines, index, wanted, text_columns, allow_missing):
    columns: dict[str, np.ndarray] = {}
    for name in wanted:
        i = index[name]
        if name in text_columns:
            columns[name] = np.array([(r[i].strip() if i < len(r) else "") for r in rows])
            continue
        values = np.empty(len(rows))
        for k, r in enumerate(rows):
            cell = r[i] if i < len(r) else ""
            if cell.strip() == "" or cell.strip().lower() == "nan":
                if name not in allow_missing:
                    raise InputError(f"{path}: row {lines[k]}: column {name!r} is empty")
                values[k] = math.nan
                continue
            v = parse_number(cell)
            if v is None:
                why = ("spaces around a number" if parse_number(cell.strip()) is not None else
                       "digits, a point and an exponent only" if "_" in cell and parse_number(cell.replace("_", "")) is not None
                       else "")
                raise InputError(f"{path}: row {lines[k]}: column {name!r}: {cell!r} is not a number"
                                 + (f" ({why})" if why else ""))
            if not math.isfinite(v):
                raise InputError(f"{path}: row {lines[k]}: column {name!r}: {cell!r} is not finite")
            values[k] = v
        columns[name] = values
    return columns


def read_flight_log(path: str | Path, min_seconds: float = 0.0, min_rows: int = 2,
                    extra: tuple[str, ...] = (), text: str | None = None) -> Table:
    """A flight log as the contract defines it; time must be strictly increasing. `extra` names
    further columns to keep when present (they may be empty). `text`: as for `read_table`."""
    table = read_table(path, FLIGHT_COLUMNS, optional=MAG_COLUMNS + tuple(extra), min_rows=min_rows,
                       allow_missing=SPARSE_COLUMNS + ESTIMATE_COLUMNS + IMU_COLUMNS + ("battery_v",) + tuple(extra),
                       text=text, whole_lines=text is None)
    for name in IMU_COLUMNS:     # a sensor not logged is empty on every row (`# imu: none ...`), not on a few
        gaps = np.flatnonzero(np.isnan(table[name]))
        if gaps.size and (gaps.size < table[name].size or "imu" not in table.meta):
            table.fail("an empty cell" + ("" if gaps.size < table[name].size else
                                          " on every row without a '# imu: none ...' line saying the IMU was not logged"),
                       row=int(gaps[0]), column=name)
    t = table["t"]
    bad = np.flatnonzero(np.diff(t) <= 0)
    if bad.size:
        k = int(bad[0]) + 1
        table.fail(f"time is not increasing (t = {t[k]:g} s after {t[k - 1]:g} s)", row=k, column="t")
    if t[-1] - t[0] < min_seconds:
        table.fail(f"too short to judge: {t[-1] - t[0]:.2f} s of data, at least {min_seconds:g} s needed")
    for name, (lo, hi), what in _FLIGHT_RANGES:
        x = table[name]
        bad = np.flatnonzero(~((x >= lo) & (x <= hi)) & ~np.isnan(x))   # NaN: an allowed empty cell
        if bad.size:
            k = int(bad[0])
            table.fail(f"{x[k]:g} is outside {what}", row=k, column=name)
    # read: the one word that it is not the whole flight (a `# partial:` line is FlightLogWriter's own)
    for what in filter(None, (table.cut_short, table.meta.get("partial") and
                              f"the log says `# partial: {table.meta['partial']}`; read as far as it goes")):
        print(f"{table.path}: cut short: {what}", file=sys.stderr)
    return table


# docs/measured-data.md's ranges of the flight log columns, beyond which a row is not a measurement
_FLIGHT_RANGES = ([(f"P{i}", (0.0, 255.0), "the command range 0-255") for i in range(1, 5)]
                  + [(f"gyro_{a}", (-100.0, 100.0), "a gyro reading (+-100 rad/s)") for a in "xyz"]
                  + [(f"acc_{a}", (-1000.0, 1000.0), "an accelerometer reading (+-1000 m/s^2)") for a in "xyz"]
                  + [("t", (-1e7, 1e7), "a time since arming (+-1e7 s)"),
                     ("battery_v", (1e-3, 100.0), "a battery voltage (above 0, at most 100 V)"),
                     ("range", (0.0, 10.0), "the rangefinder's range (0 to 10 m)")])


# A flight log's size at most, to check its disk for room before a flight (flightctl.files.output_room):
# a cell is at most 13 bytes with its comma (FlightLogWriter's formats: '%.6g' gives at most 12
# characters, "-1.23457e-05"; '%.6f' of a time under 1000 s 10), a row one cell per column, one row a
# loop period; the `# key: value` head (the parameter file, the board's lines) is under 64 kB.
CELL_BYTES = 13
HEAD_BYTES = 65536


def log_bytes(seconds: float, loop_hz: float, columns: int) -> float:
    """The most bytes a flight log of `seconds` at `loop_hz` rows a second with `columns` columns takes."""
    return HEAD_BYTES + seconds * loop_hz * columns * CELL_BYTES


def log_room(path, seconds: float, loop_hz: float, columns: int, what: str = "--log") -> None:
    """Refuse a flight whose log would not fit on the disk of `path` (a file or a folder), before it flies."""
    output_room(path, log_bytes(seconds, loop_hz, columns), what,
                f"a log of {seconds:g} s at {loop_hz:g} rows/s, {columns} columns of at most {CELL_BYTES} bytes")


class FlightLogWriter:
    """Writes the contract flight log. Rows are kept as tuples and written in chunks (once a second
    at the loop rate), so the loop pays one tuple per iteration and a crash loses at most a chunk.

    A row is `FLIGHT_COLUMNS` order plus `extra` columns; `range` is passed as a string ('' when no
    echo arrived on that row) so that formatting costs nothing on the 9 rows out of 10 without one.

    Logging never stops the loop. A write that fails (a full disk: OSError) sets `failed` and
    `error`; that chunk and every later one are dropped and counted (`dropped`); the loop lands on it.
    `background=True` (the service) formats and writes on a thread: a chunk that finds
    `queue_chunks` chunks still waiting (a stalled card) is dropped and counted, and the loop goes on.
    `process=True` (the simulator, which runs faster than real time) formats and writes in a forked
    child process, off the loop's core and its interpreter lock: the loop pays the chunk's pickling
    (about 1 us a row against 10 us of formatting); a write failure reaches `failed` at the next chunk.
    It writes in-process where fork is not available (Windows) or the output is not a file.
    At close, dropped rows are named in a last `# dropped_rows: N (why)` line when the file takes it.
    """

    def __init__(self, out: str | Path | IO[str], meta: dict[str, str], extra: tuple[str, ...] = (),
                 chunk: int = 450, keep: bool = False, background: bool = False, queue_chunks: int = 8,
                 process: bool = False, atomic: bool = True):
        self._own = not hasattr(out, "write")
        self._final = self._tmp = None
        if self._own:
            # atomic: written under a temporary name in the same folder and renamed at close, so that
            # two runs writing one log never interleave (the last to close wins, whole)
            if atomic and (not os.path.exists(out) or os.path.isfile(out)):
                self._final, self._tmp = Path(out), temporary_beside(out)
            self._f = _RawFile(self._tmp or out)
        else:
            self._f = out
        self.partial: str | None = None   # set before close (an interrupted flight): a `# partial:` line
        self.columns = FLIGHT_COLUMNS + tuple(extra)
        self._head = "".join(f"# {key}: {line}\n" for key, value in meta.items()
                             for line in str(value).splitlines() or [""]) + ",".join(self.columns) + "\n"
        process = (process and not background and (self._own or hasattr(out, "fileno"))
                   and "fork" in multiprocessing.get_all_start_methods()
                   and not multiprocessing.current_process().daemon)   # (a daemon may not have children)
        if not process:
            self._write_head()
        fmts = {"t": "%.6f", "range": "%s"}
        self._fmt = ",".join(fmts.get(c, "%.6g") for c in self.columns) + "\n"
        self._rows: list[tuple] = []
        self._chunk = chunk
        self.count = 0
        self.path = str(out) if self._own else getattr(out, "name", "<log>")
        self.meta = {k: str(v) for k, v in meta.items()}
        self._meta_lines = sum(len(str(v).splitlines()) or 1 for v in meta.values())
        self._kept: list[tuple] | None = [] if keep else None
        self.dropped = 0
        self.failed = False
        self.error: str | None = None
        self._queue: queue.Queue | None = None
        self._thread = None
        if background:
            self._queue = queue.Queue(queue_chunks)
            self._thread = threading.Thread(target=self._drain, name="flight-log", daemon=True)
            self._thread.start()
        self._child = self._pipe = self._status = None
        self._sent = self._unsent = 0                 # rows sent to the child; not sent after a failure
        if process:                                    # the child writes the head, then the rows
            ctx = multiprocessing.get_context("fork")
            rows_in, self._pipe = ctx.Pipe(duplex=False)
            self._status, status_out = ctx.Pipe(duplex=False)
            self._child = ctx.Process(target=self._serve, args=(rows_in, status_out), name="flight-log",
                                      daemon=True)
            self._child.start()
            rows_in.close()
            status_out.close()

    def append(self, row: tuple) -> None:
        self._rows.append(row)
        if len(self._rows) >= self._chunk:
            self.flush()

    def flush(self) -> None:
        rows, self._rows = self._rows, []
        if self._kept is not None:
            self._kept.extend(rows)
        if not rows:
            return
        if self._pipe is not None:
            if not self.failed and not (self._child_status() and self._child.is_alive()):
                self.failed, self.error = True, self.error or f"{self.path}: the log writer process died"
            if self.failed:
                self._unsent += len(rows)
                return
            try:
                self._pipe.send(rows)
                self._sent += len(rows)
            except OSError:
                self._unsent += len(rows)
                self.failed, self.error = True, self.error or f"{self.path}: the log writer process died"
            return
        if self._queue is None:
            self._write(rows)
            return
        try:
            self._queue.put_nowait(rows)
        except queue.Full:
            self._drop(len(rows), "the writer could not keep up")

    def _drop(self, n: int, why: str) -> None:
        self.dropped += n
        if self.error is None:
            self.error = f"{self.path}: {why}"

    def _write_head(self) -> None:
        try:
            self._f.write(self._head)             # (a caller's buffered file: flushed with the first chunk)
        except (OSError, ValueError) as e:
            self.error = f"{self.path}: {getattr(e, 'strerror', None) or e}"
            self.failed = True

    def _write(self, rows: list[tuple]) -> None:
        if self.failed:
            self.dropped += len(rows)
            return
        try:
            fmt = self._fmt
            self._f.write("".join([fmt % r for r in rows]))
            self._f.flush()
        except (OSError, ValueError) as e:          # ValueError: the file was closed under us
            self.dropped += len(rows)
            self.error = f"{self.path}: {getattr(e, 'strerror', None) or e}"
            self.failed = True
            if isinstance(self._f, _RawFile):       # a chunk written in part: the file ends at a whole row
                self._f.cut()
            return
        self.count += len(rows)

    def _serve(self, rows_in, status_out) -> None:
        """The child process of `process=True`: write each chunk and report (rows written, failed,
        error) after it. Ctrl-C reaches the whole process group: the child leaves it to the parent,
        which ends the flight and closes the log, and writes every row it was sent."""
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        self._pipe.close()            # the parent's end: its death (killed with its pool) ends the child
        self._write_head()
        while True:
            try:
                rows = rows_in.recv()
            except (EOFError, OSError):   # the parent is gone without closing the log
                self.partial = self.partial or "the flight's process ended without closing the log"
                rows = None
            if rows is None:
                return
            self._write(rows)
            status_out.send((self.count, self.failed, self.error))

    def _child_status(self) -> bool:
        """What the child reported (a failure, or its final counts); False once it is gone."""
        try:
            while self._status.poll():
                self.count, failed, error = self._status.recv()
                if failed:
                    self.failed, self.error = True, error
        except (OSError, EOFError):
            return False
        return True

    def _drain(self) -> None:
        while True:
            rows = self._queue.get()
            if rows is None:
                return
            self._write(rows)

    def table(self) -> Table:
        """What was written, as read back (needs `keep=True`), without parsing the file again."""
        rows = self._kept
        k = self.columns.index("range")
        ranges = np.array([float(r[k]) if r[k] else math.nan for r in rows])
        data = np.array([r[:k] + (0.0,) + r[k + 1:] for r in rows], dtype=float).reshape(len(rows), len(self.columns))
        columns = {name: data[:, i] for i, name in enumerate(self.columns)}
        columns["range"] = ranges
        return Table(self.path, columns, dict(self.meta), np.arange(len(rows)) + 2 + self._meta_lines)

    def close(self, timeout: float = 2.0) -> None:
        """Write what is left (waiting at most `timeout` for a background writer), name the dropped
        rows, close. Never raises for the file's sake."""
        if self._f is None:
            return
        if self._pipe is not None:                 # (after the flight: the child may take its time)
            self.flush()
            try:
                self._pipe.send(None)
            except OSError:
                pass
            self._child.join(max(timeout, 60.0))
            self._child_status()
            if self._child.exitcode != 0:             # killed, or stuck in a write
                self.failed, self.error = True, self.error or f"{self.path}: the log writer process died"
            self.dropped = self._sent + self._unsent - self.count   # what the child did not write
            self._pipe.close()
            self._status.close()
            if self._child.is_alive():
                self._child.kill()
            self._pipe = None
        elif self._queue is not None:
            rows, self._rows = self._rows, []
            if self._kept is not None:
                self._kept.extend(rows)
            try:
                if rows:
                    self._queue.put(rows, timeout=timeout)
                self._queue.put(None, timeout=timeout)
            except queue.Full:
                self._drop(len(rows), "the writer could not keep up")
            self._thread.join(timeout)
            if self._thread.is_alive():           # still stuck in a write: leave the file to it
                self._drop(sum(len(r) for r in list(self._queue.queue) if r), "the writer could not keep up")
                self._f = None
                return
        else:
            self.flush()
        tail = ""
        if self.dropped:
            tail += f"# dropped_rows: {self.dropped} ({self.error})\n"
        if self.partial or self.failed:
            tail += f"# partial: {self.partial or self.error}, after {self.count} rows\n"
        try:
            if tail:                               # (on a full card this may not fit: the rows stay whole)
                self._f.write(tail)
            if self._own:
                self._f.close()
            else:
                self._f.flush()
        except (OSError, ValueError) as e:
            self.failed = True
            self.error = self.error or f"{self.path}: {getattr(e, 'strerror', None) or e}"
        self._f = None
        if self._tmp is not None:
            try:
                os.replace(self._tmp, self._final)
            except OSError as e:
                self.failed = True
                self.error = self.error or f"{self.path}: {e.strerror}"

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class _RawFile:
    """The log's file, unbuffered: each chunk is one write to the descriptor, and after a write that
    failed half-way (a full card) `cut()` takes the file back to its last whole chunk, so that the log
    never ends in the middle of a row. The descriptor is shared with a forked writer process."""

    def __init__(self, path):
        self.fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        self.good = 0                     # bytes of whole chunks written

    def write(self, text: str) -> int:
        data = memoryview(text.encode())
        while data:
            n = os.write(self.fd, data)
            data = data[n:]
        self.good = os.lseek(self.fd, 0, os.SEEK_CUR)
        return len(text)

    def cut(self) -> None:
        try:
            os.ftruncate(self.fd, self.good)
            os.lseek(self.fd, self.good, os.SEEK_SET)
        except OSError:
            pass

    def fileno(self) -> int:
        return self.fd

    def flush(self) -> None:
        pass

    def close(self) -> None:
        if self.fd >= 0:
            fd, self.fd = self.fd, -1
            os.close(fd)
