"""Flight logs of other autopilots, read into this project's flight-log table (measured-data.md,
"Foreign logs"; docs/log-import.md): PX4's ULog through pyulog and Betaflight's blackbox through
orangebox 0.4.0, both in the `logs` extra (orangebox is GPL-3.0: an optional extra only).

    read_foreign(path, index=None) -> [Table]     every log of the file (a blackbox may hold several)
    import_text(path, index) -> str               the flight-log CSV of one log (`flightctl log import`)
    read_figure(table) -> Figure                  what was read: rates, gaps, channels
"""
from __future__ import annotations

from pathlib import Path

from flightctl.errors import InputError, read_bytes
from flightctl.logfile import Table
from flightctl.sim.logs.common import EXTRA as EXTRA_COLUMNS
from flightctl.sim.logs.common import Imported, flight_text, to_table

FOREIGN_SUFFIXES = (".ulg", ".bbl", ".bfl")      # compared in lower case: .BFL is Betaflight's too


def _kind(path: str) -> str:
    suffix = Path(path).suffix.lower()
    if suffix not in FOREIGN_SUFFIXES:
        raise InputError(f"{path}: unknown log type {suffix or '(no suffix)'}: PX4 .ulg or Betaflight .bbl/.bfl")
    head = read_bytes(path)[:32]          # a regular, readable file (errors.read_bytes), and its magic
    if not head:
        raise InputError(f"{path}: empty file")
    if suffix == ".ulg":
        if not head.startswith(b"ULog"):
            raise InputError(f"{path}: not a ULog (no ULog header)")
        return "ulog"
    if not head.startswith(b"H Product:Blackbox"):
        raise InputError(f"{path}: not a blackbox log (no 'H Product:Blackbox' header)")
    return "blackbox"


def count_logs(path: str) -> int:
    """How many logs the file holds (a ULog one, a blackbox file one or more)."""
    if _kind(path) == "ulog":
        return 1
    from flightctl.sim.logs import blackbox
    return _guarded(path, lambda: blackbox.count(path))


def _guarded(path: str, fn):
    """Run a reader; what a third-party parser raises on a damaged file becomes one line."""
    try:
        return fn()
    except InputError:
        raise
    except Exception as e:        # orangebox and pyulog raise what the bytes give them
        raise InputError(f"{path}: damaged or unreadable log ({type(e).__name__}: {e})") from None


def read_imported(path: str, index: int | None = None) -> list[Imported]:
    kind = _kind(path)
    if kind == "ulog":
        if index not in (None, 1):
            raise InputError(f"{path}: a ULog holds one log: --index {index} does not exist")
        from flightctl.sim.logs import ulog
        return [_guarded(path, lambda: ulog.read(path))]
    from flightctl.sim.logs import blackbox
    n = count_logs(path)
    if n == 0:
        raise InputError(f"{path}: no log in this blackbox file")
    if index is not None and not 1 <= index <= n:
        raise InputError(f"{path}: --index {index} does not exist (the file holds {n} log{'s' if n > 1 else ''})")
    return [_guarded(path, lambda i=i: blackbox.read(path, i)) for i in ([index] if index else range(1, n + 1))]


def import_text(path: str, index: int | None = None, progress=None) -> str:
    """The flight-log CSV text of the one log of `path` (`index` when it holds several)."""
    if index is None and count_logs(path) > 1:
        raise InputError(f"{path}: holds {count_logs(path)} logs: choose one with --index 1..{count_logs(path)}")
    (imp,) = read_imported(path, index)
    return _guarded(path, lambda: flight_text(imp, progress))


def read_foreign(path: str, index: int | None = None, progress=None) -> list[Table]:
    """Each log of `path` (or the one at `index`, from 1) as the table `read_flight_log` gives for the
    CSV `flightctl log import` writes of it: the same text, read by the same reader."""
    out = []
    for imp in read_imported(path, index):
        out.append(to_table(_guarded(path, lambda: flight_text(imp, progress)), imp.path))
    return out


def read_figure(table: Table):
    """What was read (from the table and its metadata alone, so a foreign log and its CSV draw the
    same figure): each stream's rate and gaps, and the channels over time."""
    from flightctl.sim.logs.figure import read_figure as draw
    return draw(table)
