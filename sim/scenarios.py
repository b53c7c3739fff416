"""Scenarios: a flight plan plus the steps whose responses are measured (the paper's figures).

Take-offs and ordinary altitude changes follow smooth 4 s ramps, as a pilot would fly them; the
steps of figures 13-16 are true steps, as the paper commanded them."""
from __future__ import annotations

from dataclasses import dataclass
from math import radians

from flightctl.plan import Move, Plan

HOVER_ALT = 1.5
TAKEOFF = Move(0.0, "alt", HOVER_ALT, 4.0)


@dataclass(frozen=True)
class Step:
    """A setpoint step whose response is measured from `t` (since arming) for `window` seconds."""
    channel: str
    t: float
    start: float
    end: float
    window: float


@dataclass(frozen=True)
class Scenario:
    name: str
    plan: Plan
    steps: tuple[Step, ...]
    doc: str


def _angle_steps(channel: str, schedule: list[tuple[float, float, float]]):
    """(t, value in degrees, hold s) -> moves and measured steps, each step returning to 0."""
    moves, steps, prev = [], [], 0.0
    for t, deg, hold in schedule:
        moves.append(Move(t, channel, radians(deg)))
        steps.append(Step(channel, t, radians(prev), radians(deg), hold))
        prev = deg
    return moves, steps


def hover() -> Scenario:
    return Scenario("hover", Plan([TAKEOFF], 24.0, "hover"), (),
                    "take off to 1.5 m (4 s ramp) and hold for 20 s")


def paper() -> Scenario:
    """The test flight of figures 13-20: take off, roll +-5, pitch +-5, yaw +-30 deg, climb and descend, land."""
    r_moves, r_steps = _angle_steps("roll", [(8, 5, 3), (11, 0, 4), (15, -5, 5), (20, 0, 4)])
    p_moves, p_steps = _angle_steps("pitch", [(24, 5, 3), (27, 0, 4), (31, -5, 5), (36, 0, 4)])
    y_moves, y_steps = _angle_steps("yaw", [(40, 30, 6), (46, 0, 6), (52, -30, 6), (58, 0, 6)])
    moves = [TAKEOFF] + r_moves + p_moves + y_moves + [Move(64, "alt", 2.0, 3.0), Move(71, "alt", 1.0, 4.0),
                                                       Move(78, "alt", 0.0, 4.0)]
    return Scenario("paper", Plan(moves, 86.0, "paper"), tuple(r_steps + p_steps + y_steps),
                    "take off, roll +-5 deg, pitch +-5 deg, yaw +-30 deg, climb to 2 m, descend, land")


def step_alt() -> Scenario:
    """Figure 13: ascend from 0 to 2 m, and land from 2 m, as steps."""
    moves = [Move(0.0, "alt", 2.0), Move(12.0, "alt", 0.0)]
    steps = (Step("alt", 0.0, 0.0, 2.0, 12.0),)
    return Scenario("step_alt", Plan(moves, 20.0, "step_alt"), steps, "figure 13: altitude steps 0 -> 2 m -> 0")


def _single(name: str, channel: str, deg: float, fig: str) -> Scenario:
    moves = [TAKEOFF, Move(10.0, channel, radians(deg))]
    steps = (Step(channel, 10.0, 0.0, radians(deg), 8.0),)
    return Scenario(name, Plan(moves, 18.0, name), steps, f"{fig}: hover at 1.5 m, then a {deg:+g} deg {channel} step")


def step_yaw() -> Scenario:
    moves = [TAKEOFF, Move(10.0, "yaw", radians(30)), Move(18.0, "yaw", radians(-30))]
    steps = (Step("yaw", 10.0, 0.0, radians(30), 8.0), Step("yaw", 18.0, radians(30), radians(-30), 8.0))
    return Scenario("step_yaw", Plan(moves, 26.0, "step_yaw"), steps, "figure 16: yaw steps to +30 and -30 deg")


SCENARIOS = {
    "hover": hover,
    "paper": paper,
    "step_alt": step_alt,
    "step_roll": lambda: _single("step_roll", "roll", 5.0, "figure 14"),
    "step_pitch": lambda: _single("step_pitch", "pitch", -5.0, "figure 15"),
    "step_yaw": step_yaw,
}
