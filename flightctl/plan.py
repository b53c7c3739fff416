"""A flight plan: setpoints for roll, pitch, yaw (rad) and altitude (m) over time since arming.

Each `Move` changes one channel from its current value to `value`, starting at `t`, over `ramp`
seconds along a smooth (raised-cosine) profile; `ramp = 0` is a step. The plan ends at `duration`;
a plan whose altitude returns to 0 lands, and the loop disarms on touchdown.
"""
from __future__ import annotations

from dataclasses import dataclass
from math import cos, pi

CHANNELS = ("roll", "pitch", "yaw", "alt")


@dataclass(frozen=True)
class Move:
    t: float
    channel: str
    value: float
    ramp: float = 0.0


class Plan:
    def __init__(self, moves: list[Move], duration: float, name: str = "plan"):
        for m in moves:
            if m.channel not in CHANNELS:
                raise ValueError(f"unknown channel {m.channel!r}")
        self.name = name
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

    def at(self, t: float) -> list[float]:
        """The setpoints at time t (non-decreasing between calls); the list is reused."""
        sp = self.sp
        for c in range(4):
            moves, k = self._by_channel[c], self._next[c]
            while k < len(moves) and moves[k].t <= t:
                self._start[c] = self._value(c, moves[k].t)
                self._active[c] = moves[k]
                k += 1
            self._next[c] = k
            sp[c] = self._value(c, t)
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
