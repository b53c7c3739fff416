"""What every foreign log becomes: streams on their own clocks, put on one time base (the gyro's), and
written as this project's flight log (measured-data.md) with the facts the diagnosis needs in
`# key: value` lines (docs/log-import.md).

A reader fills a `Imported`: each stream is its own sample times and values (SI, our frames already:
the reader converts at its edge), the metadata, and notes. `table` turns it into the flight-log text
and reads that text back with the project's one reader, so that a foreign log and the CSV that
`flightctl log import` writes give the diagnosis the same table, number for number.
"""
from __future__ import annotations

import io
import math
from dataclasses import dataclass, field

import numpy as np

from flightctl.errors import InputError
from flightctl.logfile import FLIGHT_COLUMNS, FlightLogWriter, Table, read_flight_log

EXTRA = ("current", "height", "omega1", "omega2", "omega3", "omega4", "gyro_f_x", "gyro_f_y", "gyro_f_z")
GAP_PERIODS = 3.0        # a measured stream is empty across gaps longer than this many of its own periods
MIN_ROWS = 10


@dataclass
class Stream:
    """One stream of a log: its sample times (s, the log's clock) and values (k, n), SI."""
    name: str
    t: np.ndarray
    values: np.ndarray
    held: bool = False       # commands: held between samples (zero-order); measurements are interpolated

    def rate_hz(self) -> float:
        """The rate of the stream's own samples (distinct times) over its span."""
        t = np.unique(self.t)
        span = t[-1] - t[0] if t.size > 1 else 0.0
        return float((t.size - 1) / span) if span > 0 else 0.0

    def gaps(self) -> tuple[int, float]:
        """(the gaps longer than GAP_PERIODS median periods, the longest interval in s)."""
        if self.t.size < 2:
            return 0, 0.0
        d = np.diff(self.t)
        return int((d > GAP_PERIODS * np.median(d)).sum()), float(d.max())


@dataclass
class Imported:
    """A foreign log read: streams by column group, metadata, notes. Required streams: `gyro` (3, n,
    rad/s), `acc` (3, n, m/s^2), `motors` (4, n, P on 0-255); optional: `battery_v`, `current`,
    `height`, `range`, `omega` (4), `attitude` (3: roll, pitch, yaw), `alt`, `gyro_f` (3)."""
    path: str
    streams: dict[str, Stream]
    meta: dict[str, str]
    notes: list[str] = field(default_factory=list)

    def fail(self, what: str):
        raise InputError(f"{self.path}: {what}")


def _on(t: np.ndarray, s: Stream) -> np.ndarray:
    """Stream s on the times t: held (last sample at or before) for commands; for measurements
    interpolated, empty across its own long gaps and outside its span."""
    k = s.values.shape[0]
    if s.t.size == 0:
        return np.full((k, t.size), np.nan)
    if s.held:
        i = np.searchsorted(s.t, t, side="right") - 1
        out = s.values[:, np.clip(i, 0, None)].astype(float)
        out[:, i < 0] = np.nan
        return out
    out = np.vstack([np.interp(t, s.t, v, left=np.nan, right=np.nan) for v in s.values])
    if s.t.size >= 2:
        period = float(np.median(np.diff(s.t)))
        j = np.clip(np.searchsorted(s.t, t), 1, s.t.size - 1)
        gap = s.t[j] - s.t[j - 1]
        out[:, gap > GAP_PERIODS * period] = np.nan
    return out


def _new_samples(t: np.ndarray, s: Stream) -> np.ndarray:
    """Stream s's values on the rows of t where a new sample arrived (the contract's `range`), else NaN."""
    out = np.full(t.size, np.nan)
    i = np.searchsorted(t, s.t)
    ok = i < t.size
    out[i[ok]] = s.values[0, ok]
    return out


def flight_text(imp: Imported, progress=None) -> str:
    """The flight log (measured-data.md) of an imported log, as text: one row per gyro sample."""
    gyro = imp.streams["gyro"]
    t = gyro.t
    keep = np.concatenate([[True], np.diff(t) > 0])      # a repeated or backward time is not a new sample
    if not keep.all():
        imp.notes.append(f"{int((~keep).sum())} gyro samples with a repeated or backward time dropped")
    t = t[keep]
    if t.size < MIN_ROWS:
        imp.fail(f"{t.size} gyro samples: too short to be a flight log")
    cols: dict[str, np.ndarray] = {"t": t - t[0]}
    g = gyro.values[:, keep]
    for j, a in enumerate("xyz"):
        cols[f"gyro_{a}"] = g[j]
    for name, prefix in (("acc", "acc_"), ("gyro_f", "gyro_f_")):
        if name in imp.streams:
            v = _on(t, imp.streams[name])
            for j, a in enumerate("xyz"):
                cols[f"{prefix}{a}"] = v[j]
    P = _on(t, imp.streams["motors"])
    for i in range(4):
        cols[f"P{i + 1}"] = P[i]
    for name in ("battery_v", "current", "height", "alt"):
        if name in imp.streams:
            cols[name] = _on(t, imp.streams[name])[0]
    if "omega" in imp.streams:
        w = _on(t, imp.streams["omega"])
        for i in range(4):
            cols[f"omega{i + 1}"] = w[i]
    if "attitude" in imp.streams:
        a = _on(t, imp.streams["attitude"])
        cols["roll"], cols["pitch"], cols["yaw"] = a
    if "range" in imp.streams:
        cols["range"] = _new_samples(t, imp.streams["range"])
    for name in ("acc_x", "acc_y", "acc_z", "P1"):
        bad = ~np.isfinite(cols[name])
        if bad.all():
            imp.fail(f"no {name} on the gyro's time base")
    ok = np.ones(t.size, bool)
    for name in ("acc_x", "acc_y", "acc_z", "P1", "P2", "P3", "P4"):
        ok &= np.isfinite(cols[name])
    if not ok.all():          # before the first command or accelerometer sample, after the last
        imp.notes.append(f"{int((~ok).sum())} rows without a command or accelerometer sample dropped")
        cols = {k: v[ok] for k, v in cols.items()}
        cols["t"] = cols["t"] - cols["t"][0]
    meta = dict(imp.meta)
    meta["rate_hz"] = f"{1.0 / float(np.median(np.diff(cols['t']))):.1f}"
    meta["motor_rate_hz"] = f"{imp.streams['motors'].rate_hz():.1f}"
    lines = []
    for s in imp.streams.values():
        n_gaps, longest = s.gaps()
        lines.append(f"{s.name} rate_hz={s.rate_hz():.1f} samples={s.t.size} gaps={n_gaps} longest_gap_s={longest:.4f}")
    meta["stream"] = "\n".join(lines)
    if imp.notes:
        meta["import_notes"] = "\n".join(imp.notes)
    extra = tuple(c for c in EXTRA if c in cols)
    n = cols["t"].size
    nan = math.nan
    rows = []
    for k in range(n):
        row = []
        for c in FLIGHT_COLUMNS:
            if c == "range":
                v = cols["range"][k] if "range" in cols else nan
                row.append("" if not math.isfinite(v) else f"{v:.6g}")
            else:
                row.append(cols[c][k] if c in cols else nan)
        rows.append(tuple(row) + tuple(cols[c][k] for c in extra))
    out = io.StringIO()
    writer = FlightLogWriter(out, meta, extra=extra)
    for r in rows:
        writer.append(r)
    writer.close()
    if progress:
        progress(f"{imp.path}: {n} rows, {cols['t'][-1]:.1f} s at {meta['rate_hz']} Hz, motors at "
                 f"{meta['motor_rate_hz']} Hz")
    return out.getvalue()


def to_table(text: str, name: str) -> Table:
    """The flight-log text read back with the project's reader (the diagnosis' columns kept)."""
    return read_flight_log(name, min_rows=MIN_ROWS, extra=EXTRA, text=text)
