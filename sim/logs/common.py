"""What every foreign log becomes: streams on their own clocks, put on one time base (the gyro's; the
attitude's in a log without one: `time_base`), and written as this project's flight log (docs/measured-data.md)
with the facts the diagnosis needs in `# key: value` lines (docs/log-import.md).

A reader fills a `Imported`: each stream is its own sample times and values (SI, our frames already:
the reader converts at its edge), the metadata, and notes. `flight_text` turns it into the flight-log
text and `to_table` reads that text back with the project's one reader, so that a foreign log and the
CSV that `flightctl log import` writes give the diagnosis the same table, number for number. A missing
value is an empty cell in every column (docs/measured-data.md).
"""
from __future__ import annotations

import io
import math
import re
import struct
from dataclasses import dataclass, field, replace

import numpy as np

from flightctl.errors import InputError
from flightctl.logfile import FLIGHT_COLUMNS, FlightLogWriter, Table, read_flight_log
from flightctl.sim.logs.columns import MOTOR_COLUMNS, OMEGA_COLUMNS, all_running   # all motors above 1 % of their range
from flightctl.sim.logs.columns import DYNAMIC_MIN_HZ   # what diagnose needs to time and to follow

AXES = ("x", "y", "z")
# Extra columns (docs/log-import.md has each one's source and unit): the measurements the diagnosis
# reads, then what draws rate tracking (the rate setpoint, the sticks, the PID terms).
EXTRA = (MOTOR_COLUMNS + ("current", "height", "landed") + OMEGA_COLUMNS + ("gyro_f_x", "gyro_f_y", "gyro_f_z")
         + tuple(f"setpoint_{a}" for a in AXES) + ("rc_roll", "rc_pitch", "rc_yaw", "rc_throttle")
         + tuple(f"pid_{term}_{a}" for term in "pidf" for a in AXES) + ("vibe_x", "vibe_y", "vibe_z", "clip"))
# stream name -> its columns (streams of one value write the stream's name)
GROUPS = {"gyro": tuple(f"gyro_{a}" for a in AXES), "acc": tuple(f"acc_{a}" for a in AXES), "gyro_f": tuple(f"gyro_f_{a}" for a in AXES),
          "omega": OMEGA_COLUMNS, "attitude": ("roll", "pitch", "yaw"),
          "attitude_sp": ("roll_sp", "pitch_sp", "yaw_sp"),
          "setpoint": tuple(f"setpoint_{a}" for a in AXES), "rc": ("rc_roll", "rc_pitch", "rc_yaw", "rc_throttle"),
          "pid": tuple(c for c in EXTRA if c.startswith("pid_")), "vibe": ("vibe_x", "vibe_y", "vibe_z")}
GAP_PERIODS = 3.0        # a measured stream is empty across gaps longer than this many of its own periods
MIN_ROWS = 10
ISLAND_GAP_S = 1.0       # a few rows cut off from the log by a gap this long at its start or end are not data
ISLAND_SHARE = 0.01      # ... when they are under this share of the rows
CELL_FULL_V = 4.2        # a LiPo cell at full charge
# ... as a log reads it: a charger ends within about 1 % of 4.2 V and a power module's divider reads within a
# few %, so the cell count of a resting pack is ceil(V / 4.25) (mechanical_fail.log's pack reads 16.91 V at rest:
# 4S by its FS_BATT_VOLTAGE, 14 V or 3.5 V a cell; ceil(V / 4.2) made it 5S at 3.4 V a cell)
CELL_READ_V = 4.25
FRD = np.array([[1.0], [-1.0], [-1.0]])     # body FRD (or earth NED) to ours (conventions.md): y and z change sign
DEG = math.pi / 180.0


@dataclass
class Stream:
    """One stream of a log: its sample times (s, the log's clock) and values (k, n), SI."""
    name: str
    t: np.ndarray
    values: np.ndarray
    held: bool = False       # commands: held between samples (zero-order); measurements are interpolated

    def rate_hz(self) -> float:
        """The rate of the stream's own samples (distinct times) while it was logged: over its span less
        its gaps (longer than GAP_PERIODS median periods: a log paused for 20 s is not logged slowly)."""
        d = np.diff(np.unique(self.t))
        if d.size == 0:
            return 0.0
        d = d[d <= GAP_PERIODS * np.median(d)]
        return float(d.size / d.sum()) if d.sum() > 0 else 0.0

    def gaps(self) -> tuple[int, float]:
        """(the gaps longer than GAP_PERIODS median periods, the longest interval in s)."""
        if self.t.size < 2:
            return 0, 0.0
        d = np.diff(self.t)
        return int((d > GAP_PERIODS * np.median(d)).sum()), float(d.max())


@dataclass
class Imported:
    """A foreign log read: streams by column group, metadata, notes. Required streams: `gyro` (3, n,
    rad/s), `acc` (3, n, m/s^2), `motors` (N, n, P on 0-255: the `# rotors:` line's N); optional: `battery_v`, `current`,
    `height`, `range`, `alt`, `landed` (1 landed: the autopilot's landing detector, held), `omega` (one per motor,
    rad/s), `attitude` (3: roll, pitch, yaw), `gyro_f` (3),
    `setpoint` (3, rad/s), `attitude_sp` (3: the attitude setpoint's roll, pitch, yaw), `rc` (4), `pid` (12:
    P, I, D, F terms on x, y, z)."""
    path: str
    streams: dict[str, Stream]
    meta: dict[str, str]
    notes: list[str] = field(default_factory=list)

    def fail(self, what: str):
        raise InputError(f"{self.path}: {what}")


# the packages whose exceptions describe the bytes they read (orangebox's "Invalid header at 0x47A: ...",
# pyulog's, pymavlink's), and the standard library's for bytes that do not unpack or decode
_DESCRIBED = ("orangebox", "pyulog", "pymavlink")
_DECODING = (struct.error, UnicodeDecodeError, EOFError, OSError)


def parser_said(e: Exception) -> str:
    """What a third-party parser's exception says of the bytes, in words, never its class name (a user
    reads "Invalid header at 0x47A: b'H P interva'", not `InvalidHeaderException:`): the text of an
    exception of the parser's own package or of a decoding error; a Python error inside the parser (a
    `TypeError`, `ZeroDivisionError`, `KeyError` ... on bytes it did not expect) says nothing to the user
    and becomes "bytes the parser could not decode"."""
    text = " ".join(str(e).split())
    own = type(e).__module__.split(".")[0] in _DESCRIBED or isinstance(e, _DECODING)
    if not own or not text:
        return "bytes the parser could not decode"
    text = re.sub(r"\b[A-Za-z_.]*(Error|Exception)\b:?\s*", "", text).strip() or "bytes the parser could not decode"
    return text[:160]


def rate_notes(imp: Imported, motors: str, how: str) -> None:
    """Notes when the gyro or the motor commands (`motors`: what they are in the log) were logged slower
    than diagnose needs (DYNAMIC_MIN_HZ: sensors slower are not judged, motors slower for static effects
    only), and `# log_faster:` with `how` (what the autopilot's logger needs) for its refusals."""
    slow = False
    base = time_base(imp)
    rate = base.rate_hz()
    if "gyro" not in imp.streams:
        imp.notes.append(f"no gyro or accelerometer ({imp.meta['imu'].removeprefix('none: ')}): the rows are {base.name}'s samples "
                         f"({rate:.1f} Hz), the gyro and acc columns empty")
    elif rate < DYNAMIC_MIN_HZ:
        slow = True
        imp.notes.append(f"{imp.streams['gyro'].name} at {rate:.1f} Hz: too slow to follow the vehicle's motion "
                         f"(diagnose needs {DYNAMIC_MIN_HZ:g} Hz); " + how)
    rate = imp.streams["motors"].rate_hz()
    if rate < DYNAMIC_MIN_HZ:
        slow = True
        imp.notes.append(f"{motors} logged at {rate:.1f} Hz: held between their samples, enough for static effects "
                         "only; " + how)
    if slow:
        imp.meta["log_faster"] = how


def time_base(imp: Imported) -> Stream:
    """The stream whose samples are the rows: the gyro; in a log without one (`# imu: none ...`, the reason
    in the metadata: ArduCopter's LOG_BITMASK without IMU) the attitude, with the gyro and accelerometer
    columns left empty (docs/measured-data.md: missing values), which only diagnose's static tier reads."""
    if "gyro" in imp.streams:
        return imp.streams["gyro"]
    if "imu" in imp.meta and "attitude" in imp.streams:
        return imp.streams["attitude"]
    imp.fail("no gyro and no attitude: nothing to put the log's rows on")


def command_p(imp: Imported, raw: np.ndarray, lo, hi, outside: str) -> np.ndarray:
    """The motor commands `raw` (N, n) as P on 0-255 over [lo, hi] (scalars, or (N, 1) per motor),
    clipped; a note "N `outside` clipped to 0-255" when N samples had a command outside the range."""
    P = 255.0 * (raw - lo) / (hi - lo)
    clipped = int(((P < 0) | (P > 255)).any(axis=0).sum())
    if clipped:
        imp.notes.append(f"{clipped} {outside} clipped to 0-255")
    return np.clip(P, 0.0, 255.0)


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


def forward(t: np.ndarray) -> np.ndarray:
    """(n,) bool: the rows whose time is after every earlier row's. A clock that jumps back (a logger's
    restart, a time stamp reset mid-log) would repeat times already logged: the rows up to the time it
    had reached are dropped (counted by the caller), the ones after it kept."""
    keep = np.ones(t.size, bool)
    if t.size > 1:
        keep[1:] = t[1:] > np.maximum.accumulate(t)[:-1]
    return keep


def backward_note(t: np.ndarray, keep: np.ndarray, what: str) -> str:
    """The note of `forward`'s drop: how many rows, and the largest jump back (s)."""
    jumps = -np.diff(t)
    return (f"{int((~keep).sum())} {what} with a repeated or backward time dropped (the largest jump back "
            f"{max(float(jumps.max()), 0.0):.3g} s)")


def _islands(t: np.ndarray, notes: list[str]) -> np.ndarray:
    """The rows kept: a few rows cut off by a long gap at the start or the end of the log (a logger's
    first frames before it settles, a last frame written at power-off) are not flight data."""
    keep = np.ones(t.size, bool)
    gaps = np.flatnonzero(np.diff(t) > ISLAND_GAP_S)
    if gaps.size and gaps[0] + 1 <= ISLAND_SHARE * t.size:
        k = gaps[0] + 1
        keep[:k] = False
        notes.append(f"{k} rows before a {t[k] - t[k - 1]:.2f} s gap at the start of the log dropped "
                     "(a logger's first frames, not flight data)")
    if gaps.size and t.size - gaps[-1] - 1 <= ISLAND_SHARE * t.size and keep[gaps[-1] + 1]:
        k = gaps[-1] + 1
        keep[k:] = False
        notes.append(f"{t.size - k} rows after a {t[k] - t[k - 1]:.2f} s gap at the end of the log dropped")
    return keep


def battery_cells(imp: Imported, P: np.ndarray | None = None) -> None:
    """`battery_cells` and `battery_cells_source`: what the reader found in the log's own settings,
    else ceil(V / 4.2) of the resting voltage (the median before the motors first run)."""
    if "battery_cells" in imp.meta or "battery_v" not in imp.streams:
        return
    s = imp.streams["battery_v"]
    motors = imp.streams["motors"]
    running = all_running(motors.values)
    start = motors.t[np.argmax(running)] if running.any() else np.inf
    rest = s.values[0, s.t < start]
    v = float(np.median(rest if rest.size else s.values[0, :10]))
    if v <= 0:
        return
    imp.meta["battery_cells"] = str(max(1, math.ceil(v / CELL_READ_V - 1e-9)))
    imp.meta["battery_cells_source"] = (f"estimated: ceil(V / {CELL_READ_V:g} V) of the resting voltage "
                                        f"{v:.2f} V ({'before the motors start' if rest.size else 'the first readings'})")


def _format(x: np.ndarray, fmt: str) -> list[str]:
    """Cells of one column: a missing value is an empty cell."""
    return [fmt % v if v == v else "" for v in x.tolist()]


def flight_text(imp: Imported, progress=None) -> str:
    """The flight log (docs/measured-data.md) of an imported log, as text: one row per sample of its time base
    (`time_base`: the gyro's, else the attitude's)."""
    base = time_base(imp)
    imu = "gyro" in imp.streams
    what = "gyro" if imu else base.name
    t = base.t
    keep = forward(t)                                    # a repeated or backward time is not a new sample
    if not keep.all():
        imp.notes.append(backward_note(t, keep, f"{what} samples"))
    t = t[keep]
    own = base.values[:, keep]                           # the time base's own samples, as they are
    dropped = []
    for name, s in list(imp.streams.items()):           # the other streams' clocks jumped back with it
        if s is not base and s.t.size > 1 and (np.diff(s.t) < 0).any():
            ok = forward(s.t)
            imp.streams[name] = replace(s, t=s.t[ok], values=s.values[:, ok])
            dropped.append(f"{name} {int((~ok).sum())}")
    if dropped:
        imp.notes.append("the other streams' samples with a repeated or backward time dropped too: " + ", ".join(dropped))
    if t.size < MIN_ROWS:
        imp.fail(f"{t.size} {what} samples: too short to be a flight log")
    island = _islands(t, imp.notes)
    t, own = t[island], own[:, island]
    cols: dict[str, np.ndarray] = {"t": t - t[0]}
    P = _on(t, imp.streams["motors"])
    for i in range(P.shape[0]):           # P5.. of a vehicle of more motors: MOTOR_COLUMNS
        cols[f"P{i + 1}"] = P[i]
    for name, s in imp.streams.items():
        if name in ("motors", "range"):
            continue
        v = own if s is base else _on(t, s)
        for j, c in zip(range(len(v)), GROUPS.get(name, (name,))):    # (omega: as many as the log's motors)
            cols[c] = v[j]
    if "range" in imp.streams:
        cols["range"] = _new_samples(t, imp.streams["range"])
    needed = ("acc_x", "acc_y", "acc_z", "P1", "P2", "P3", "P4") if imu else ("P1", "P2", "P3", "P4", "roll", "pitch", "yaw")
    if imu and "acc" in imp.streams and not np.isfinite(imp.streams["acc"].values).any():
        needed = needed[3:]      # the reader found the accelerometer switched off (its note): judged on the gyro
        imp.meta.setdefault("imu", "gyro only: no accelerometer logged (switched off on the vehicle)")
    for name in needed[:4]:
        if name not in cols or not np.isfinite(cols[name]).any():
            imp.fail(f"no {name} on the {what}'s time base")
    ok = np.ones(t.size, bool)
    for name in needed:
        ok &= np.isfinite(cols[name])
    if not ok.all():          # before the first command or accelerometer sample, after the last
        imp.notes.append(f"{int((~ok).sum())} rows without a command or {'accelerometer' if imu else 'attitude'} "
                         "sample dropped")
        cols = {k: v[ok] for k, v in cols.items()}
        cols["t"] = cols["t"] - cols["t"][0]
    if cols["t"].size < MIN_ROWS:
        imp.fail(f"{cols['t'].size} rows with a command and an {'accelerometer' if imu else 'attitude'} sample: too "
                 "short to be a flight log")
    battery_cells(imp)
    meta = dict(imp.meta)
    meta["rate_hz"] = f"{1.0 / float(np.median(np.diff(cols['t']))):.1f}"
    meta["motor_rate_hz"] = f"{imp.streams['motors'].rate_hz():.1f}"
    for name in ("setpoint", "attitude_sp", "attitude"):     # the step responses' inputs' own rates (diagnose/steps.py)
        if name in imp.streams:
            meta[f"{name}_rate_hz"] = f"{imp.streams[name].rate_hz():.1f}"
    lines = []
    for s in imp.streams.values():
        n_gaps, longest = s.gaps()
        lines.append(f"{s.name} rate_hz={s.rate_hz():.1f} samples={s.t.size} gaps={n_gaps} longest_gap_s={longest:.4f}")
    meta["stream"] = "\n".join(lines)
    if imp.notes:
        meta["import_notes"] = "\n".join(imp.notes)
    text = log_text(meta, cols, tuple(c for c in EXTRA if c in cols))
    if progress:
        progress(f"{imp.path}: {cols['t'].size} rows, {cols['t'][-1]:.1f} s at {meta['rate_hz']} Hz, motors at "
                 f"{meta['motor_rate_hz']} Hz")
    return text


def log_text(meta: dict[str, str], cols: dict[str, np.ndarray], extra: tuple[str, ...]) -> str:
    """The flight log's text of columns (FLIGHT_COLUMNS, empty where `cols` lacks one, then `extra`) as
    FlightLogWriter writes it: `t` in whole microseconds, the rest to 6 significant digits."""
    n = cols["t"].size
    empty = [""] * n
    cells = [_format(cols["t"], "%.6f")]
    cells += [_format(cols[c], "%.6g") if c in cols else empty for c in FLIGHT_COLUMNS[1:]]
    cells += [_format(cols[c], "%.6g") for c in extra]
    out = io.StringIO()
    FlightLogWriter(out, meta, extra=extra).close()          # the `# key: value` lines and the header row
    out.write("".join(",".join(row) + "\n" for row in zip(*cells)))
    return out.getvalue()


def to_table(text: str, name: str) -> Table:
    """The flight-log text read back with the project's reader (the diagnosis' columns kept)."""
    return read_flight_log(name, min_rows=MIN_ROWS, extra=EXTRA, text=text)


def euler_from_frd_ned(q: np.ndarray) -> np.ndarray:
    """(roll, pitch, yaw) in our frames (conventions.md: body x forward, y left, z up; inertial North,
    West, Up) of quaternions (4, n; any scale) from body FRD to NED: the same rotation seen with y and
    z negated in both frames keeps the roll and negates the pitch and yaw."""
    w, x, y, z = q / np.linalg.norm(q, axis=0)
    roll = np.arctan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    pitch = np.arcsin(np.clip(2.0 * (w * y - z * x), -1.0, 1.0))
    yaw = np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return np.vstack([roll, -pitch, -yaw])
