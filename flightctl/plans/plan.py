"""A flight plan: setpoints for roll, pitch, yaw (rad) and altitude (m) over time since arming, and
the plan file that describes one.

Each `Move` changes one channel from its current value to `value`, starting at `t`, over `ramp`
seconds along a smooth (raised-cosine) profile; `ramp = 0` is a step. The plan ends at `duration`;
a plan whose altitude returns to 0 lands, and the loop disarms on touchdown.

A plan file (TOML, SI units; angles may be given in degrees as `value_deg`):

    name = "hover-test"              # optional; default: the file name
    duration = 30.0                  # s since arming
    [[move]]
    t = 0.0                          # s since arming
    channel = "alt"                  # roll, pitch, yaw (rad) or alt (m)
    value = 1.0
    ramp = 4.0                       # s, raised-cosine; 0 = step

`check_plan` holds every plan, read from a file or named in `flightctl.plans`, to the same limits.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from math import cos, inf, pi
from pathlib import Path

from flightctl.errors import InputError, number

from flightctl.files import read_toml

CHANNELS = ("roll", "pitch", "yaw", "alt")
MAX_PLAN_S = 3600.0
MAX_PLAN_ALT_M = 3.0           # the HC-SR04 reads to 4 m
MAX_PLAN_TILT_DEG = 30.0


@dataclass(frozen=True)
class Move:
    t: float
    channel: str
    value: float
    ramp: float = 0.0


class Plan:
    def __init__(self, moves: list[Move], duration: float, name: str = "plan", doc: str = ""):
        for m in moves:
            if m.channel not in CHANNELS:
                raise ValueError(f"unknown channel {m.channel!r}")
        self.name = name
        self.doc = doc
        self.duration = duration
        self.moves = sorted(moves, key=lambda m: m.t)
        self._by_channel = [[m for m in self.moves if m.channel == c] for c in CHANNELS]
        self.restart()

    def restart(self) -> None:
        # per channel: index of the next move, value before the active move, the active move
        self._next = [0, 0, 0, 0]
        self._start = [0.0, 0.0, 0.0, 0.0]
        self._active: list[Move | None] = [None, None, None, None]
        self.sp = [0.0, 0.0, 0.0, 0.0]
        self._steady_until = -inf   # before this time no move starts and none ramps: `sp` stands

    def at(self, t: float) -> list[float]:
        """The setpoints at time t (non-decreasing between calls); the list is reused."""
        sp = self.sp
        if t < self._steady_until:
            return sp
        steady = inf
        for c in range(4):
            moves, k = self._by_channel[c], self._next[c]
            while k < len(moves) and moves[k].t <= t:
                self._start[c] = self._value(c, moves[k].t)
                self._active[c] = moves[k]
                k += 1
            self._next[c] = k
            sp[c] = self._value(c, t)
            if k < len(moves) and moves[k].t < steady:
                steady = moves[k].t
            m = self._active[c]
            if m is not None and m.ramp > 0.0 and t < m.t + m.ramp:
                steady = -inf            # ramping
        self._steady_until = steady
        return sp

    def _value(self, c: int, t: float) -> float:
        m = self._active[c]
        if m is None:
            return 0.0
        if m.ramp <= 0.0 or t >= m.t + m.ramp:
            return m.value
        s = (t - m.t) / m.ramp
        return self._start[c] + (m.value - self._start[c]) * 0.5 * (1.0 - cos(pi * s))

    def lands(self) -> bool:
        alts = self._by_channel[3]
        return bool(alts) and alts[-1].value <= 0.0


def check_plan(plan: Plan, where: str | None = None) -> Plan:
    """Refuse (InputError naming the move) a plan beyond what the vehicle may be asked to do."""
    where = where or f"plan {plan.name}"
    if not 0.0 < plan.duration <= MAX_PLAN_S:
        raise InputError(f"{where}: duration: a number of seconds in (0, {MAX_PLAN_S:g}] is needed, "
                         f"got {plan.duration!r}")
    for k, m in enumerate(plan.moves, start=1):
        check_move(m, f"{where}: move {k}")
    return plan


def check_move(m: Move, where: str) -> Move:
    if m.t < 0 or m.ramp < 0:
        raise InputError(f"{where}: t and ramp must not be negative")
    if m.channel == "alt" and not 0.0 <= m.value <= MAX_PLAN_ALT_M:
        raise InputError(f"{where}: altitude {m.value:g} m outside [0, {MAX_PLAN_ALT_M:g}] m")
    if m.channel in ("roll", "pitch") and abs(m.value) > math.radians(MAX_PLAN_TILT_DEG):
        raise InputError(f"{where}: {m.channel} {math.degrees(m.value):g} deg beyond +-{MAX_PLAN_TILT_DEG:g} deg")
    return m


def _number(where: str, key: str, v) -> float:
    x = number(v)
    if x is None:
        shown = repr(v) if len(repr(v)) <= 40 else f"{repr(v)[:37]}..."
        raise InputError(f"{where}: {key}: expected a number, got {shown}")
    return x


def read_plan_file(path: str | Path) -> Plan:
    """Read and check a plan file (the format above); every problem is one InputError line."""
    path = Path(path)
    data = read_toml(path)
    unknown = set(data) - {"name", "duration", "move"}
    if unknown:
        raise InputError(f"{path}: unknown key {sorted(unknown)[0]!r} (known: name, duration, move)")
    duration = number(data.get("duration"))
    if duration is None or not 0 < duration <= MAX_PLAN_S:
        raise InputError(f"{path}: duration: a number of seconds in (0, {MAX_PLAN_S:g}] is needed, "
                         f"got {str(data.get('duration'))[:40]!r}")
    table = data.get("move", [])
    if not isinstance(table, list):
        raise InputError(f"{path}: move: expected [[move]] tables")
    moves = []
    for k, m in enumerate(table, start=1):
        where = f"{path}: move {k}"
        if not isinstance(m, dict):
            raise InputError(f"{where}: expected a [[move]] table")
        unknown = set(m) - {"t", "channel", "value", "value_deg", "ramp"}
        if unknown:
            raise InputError(f"{where}: unknown key {sorted(unknown)[0]!r}")
        channel = m.get("channel")
        if channel not in CHANNELS:
            raise InputError(f"{where}: channel must be one of {', '.join(CHANNELS)}, got {channel!r}")
        if ("value" in m) == ("value_deg" in m):
            raise InputError(f"{where}: give exactly one of value, value_deg")
        if "value_deg" in m and channel == "alt":
            raise InputError(f"{where}: alt is in metres (value), not degrees")
        t = _number(where, "t", m.get("t"))
        ramp = _number(where, "ramp", m.get("ramp", 0.0))
        if "value_deg" in m:
            value = math.radians(_number(where, "value_deg", m["value_deg"]))   # degrees at the edge only
        else:
            value = _number(where, "value", m["value"])
        moves.append(check_move(Move(t, channel, value, ramp), where))     # in the file's order
    name = data.get("name", path.stem)
    if not isinstance(name, str) or not name:
        raise InputError(f"{path}: name: a text is needed (it names the log), got {name!r}")
    bad = next((c for c in name if c in "/\\" or not c.isprintable()), None)
    if bad is not None:
        what = {"/": "a slash", "\\": "a backslash", "\0": "a NUL character (\\0)"}.get(bad, f"the control character {bad!r}")
        raise InputError(f"{path}: name {name!r} holds {what}: it names the log files, so only printable "
                         "characters without slashes")
    return Plan(moves, float(duration), name, f"plan file {path}")
