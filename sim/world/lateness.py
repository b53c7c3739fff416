"""The loop's lateness flown: a simulated board's clock whose ticks come late as a loaded Pi's do.

The lock-step `SimClock` serves every tick on its deadline, so a flight is the same whatever the
lateness of the loop that flies it. `LateClock` draws, for each tick, whether the loop reaches its
deadline late and by how much, from a measured distribution (`Lateness`: a share of late ticks and
the quantiles of their lateness, `loop_lateness/*.json`, written by scripts/loop_lateness.py with
its provenance), with its own seeded generator (the world's random numbers, the sensors' noise, are
left as they are). A late tick is flown late: the plant integrates through the deadline to the late
moment with the motors holding the last command (an ESC keeps its last pulse width), the sensors
are read there, and the command issued there acts from there (plus the actuation delay:
`Plant.issue_times`). A tick later than whole periods skips them, as `WallClock` does
(`flightctl.clock.missed_periods`), and the loop sees the jump (flightctl/loop.py's stall check);
every late tick is an overrun, counted as on the Pi (`overruns`, the loop's `FlightResult.overruns`).
The tick returns its deadline, as `WallClock.wait_next` does: the loop's time is the grid's.

Each tick's lateness is drawn on its own (independent ticks): the measured share of late ticks and
the shape of their lateness, not their runs in time. The fault `loop_late:dist=NAME[,rate=R,seed=S,at=T]`
(sim/world/faults.py) puts it on a board; `rate` multiplies the share of late ticks (a stressed Pi).
"""
from __future__ import annotations

import json
import math
import random
from dataclasses import dataclass
from pathlib import Path

from flightctl.clock import missed_periods
from flightctl.errors import InputError

FOLDER = Path(__file__).with_name("loop_lateness")   # the shipped distributions, one JSON file each


@dataclass(frozen=True)
class Lateness:
    """A loop's lateness: the share of ticks that reach their deadline late, and the lateness (s) of
    those at the quantiles 0, 1/(n-1), ..., 1 (`quantiles_s`, rising). `source`: how it was measured."""
    name: str
    share: float
    quantiles_s: tuple[float, ...]
    source: dict

    def draw(self, u: float) -> float:
        """The lateness (s) at the quantile u in [0, 1), linear between the stored quantiles."""
        q = self.quantiles_s
        x = u * (len(q) - 1)
        i = int(x)
        return q[i] + (x - i) * (q[i + 1] - q[i]) if i + 1 < len(q) else q[-1]

    def to_json(self) -> str:
        return json.dumps({"name": self.name, "share": self.share, "quantiles_s": [max(round(v, 7), 1e-7) for v in self.quantiles_s],
                           "source": self.source}, indent=1) + "\n"


def names() -> tuple[str, ...]:
    return tuple(sorted(p.stem for p in FOLDER.glob("*.json")))


def load(name: str) -> Lateness:
    """A shipped distribution by name (`names()`); a bad file is an InputError naming it."""
    path = FOLDER / f"{name}.json"
    if name not in names():
        raise InputError(f"loop_late: unknown distribution {name!r} (known: {', '.join(names())})")
    try:
        d = json.loads(path.read_text())
        q = tuple(float(v) for v in d["quantiles_s"])
        share = float(d["share"])
        source = dict(d["source"])
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise InputError(f"{path}: not a loop lateness distribution ({e})") from None
    if not (0.0 <= share <= 1.0 and len(q) >= 2 and all(math.isfinite(v) and v > 0.0 for v in q)
            and all(a <= b for a, b in zip(q, q[1:]))):
        raise InputError(f"{path}: share must be in 0..1 and quantiles_s at least 2 rising positive times")
    return Lateness(name, share, q, source)


class LateClock:
    """The simulated board's clock with late ticks (this module's docstring). From world time `at`,
    each tick is late with probability `share` (the distribution's times `rate`, at most 1)."""

    def __init__(self, world, lateness: Lateness, rate: float = 1.0, seed: int = 0, at: float = 0.0):
        self.world, self.period = world, world.dt
        self.lateness, self.at = lateness, at
        self.share = min(1.0, lateness.share * rate)
        self._rng = random.Random(f"loop_late {seed}")   # (not the world's stream of the same seed)
        self.ticks = 0              # deadlines served (skipped ones not counted), as WallClock's
        self.overruns = 0           # ticks that came late
        self.skipped = 0            # whole periods dropped after long overruns
        self.max_late_s = 0.0
        world.plant.issue_times()   # each command from its issue time: a late one acts late

    def now(self) -> float:
        return self.world.t

    def wait_next(self) -> float:
        w, period = self.world, self.period
        w.advance(period)           # to this deadline (the rest of a late period: its command held)
        self.ticks += 1
        if w.t >= self.at and self._rng.random() < self.share:
            late = self.lateness.draw(self._rng.random())
            self.overruns += 1
            self.max_late_s = max(self.max_late_s, late)
            behind = missed_periods(late, period)
            for _ in range(behind):  # the last command held through the periods missed
                w.advance(period)
            self.skipped += behind
            frac = late / period - behind
            if frac > 0.0:
                w.advance_part(frac)
        p = w.plant
        return p.periods * p.dt
