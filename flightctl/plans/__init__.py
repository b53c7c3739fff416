"""The named flight plans: one registry for `flightctl run --plan NAME` (on the quadcopter, without
the simulator), `flightctl sim NAME` and the excitation flights of `flightctl diagnose`.

Take-offs and ordinary altitude changes follow smooth ramps, as a pilot would fly them; the steps of
figures 13-16 are true steps, as the paper commanded them. The simulator measures the response to
every step of a plan (`flightctl.sim.flights.scenarios`). Adding a plan: a function returning a `Plan` and
one line in `PLANS`; tests/onboard/plans/test_plan.py holds every named plan to the plan-file limits.
"""
from __future__ import annotations

from math import radians
from pathlib import Path
from typing import Callable

from flightctl.errors import InputError
from flightctl.plans.plan import Move, Plan, check_plan, read_plan_file

HOVER_ALT = 1.5                              # m
TAKEOFF = Move(0.0, "alt", HOVER_ALT, 4.0)   # a 4 s raised-cosine ramp


def _steps(channel: str, schedule: list[tuple[float, float]]) -> list[Move]:
    """(t, value in degrees) -> step moves of one angle channel."""
    return [Move(t, channel, radians(deg)) for t, deg in schedule]


def hover() -> Plan:
    return Plan([TAKEOFF], 24.0, "hover", "take off to 1.5 m (4 s ramp) and hold for 20 s")


def paper() -> Plan:
    """The test flight of figures 13-20."""
    moves = ([TAKEOFF] + _steps("roll", [(8, 5), (11, 0), (15, -5), (20, 0)])
             + _steps("pitch", [(24, 5), (27, 0), (31, -5), (36, 0)])
             + _steps("yaw", [(40, 30), (46, 0), (52, -30), (58, 0)])
             + [Move(64, "alt", 2.0, 3.0), Move(71, "alt", 1.0, 4.0), Move(78, "alt", 0.0, 4.0)])
    return Plan(moves, 86.0, "paper",
                "take off, roll +-5 deg, pitch +-5 deg, yaw +-30 deg, climb to 2 m, descend, land")


def step_alt() -> Plan:
    """Figure 13: (a) ascend from 0 to 2 m as a step; (b) the paper's "controlled landing" from 2 m.
    The landing is an 8 s ramp, not a step: the paper's simulation has no floor, and a step to 0 m
    makes the altitude PID cut the thrust, so the vehicle falls and meets the floor at 5.4 m/s
    (a crash, on the base model with Table 6); the ramp touches down at 0.1-0.6 m/s with either
    table on either model."""
    return Plan([Move(0.0, "alt", 2.0), Move(12.0, "alt", 0.0, 8.0)], 24.0, "step_alt",
                "figure 13: an altitude step 0 -> 2 m, then a controlled landing (8 s ramp; a step to "
                "the floor would be a fall)")


def _single(name: str, channel: str, deg: float, fig: str) -> Plan:
    return Plan([TAKEOFF, Move(10.0, channel, radians(deg))], 18.0, name,
                f"{fig}: hover at 1.5 m, then a {deg:+g} deg {channel} step")


def step_yaw() -> Plan:
    return Plan([TAKEOFF] + _steps("yaw", [(10.0, 30), (18.0, -30)]), 26.0, "step_yaw",
                "figure 16: yaw steps to +30 and -30 deg")


def excite() -> Plan:
    """What `flightctl diagnose` needs to see (docs/diagnose.md), 48 s after arming: a low hover at
    0.25 m (ground effect), a climb, roll and pitch steps of +-4 degrees (horizontal speed: rotor drag;
    sharp command edges: lag against delay), yaw steps of +-60 degrees (yaw rates of 2-3 rad/s: linear
    yaw drag), a climb to 2 m, a fast descent to 0.8 m, a shorter one back to 0.25 m and to the floor
    (thrust changes: battery sag, ground effect again). The descent from 2 m is fast on purpose (its
    setpoint peaks at 0.9 m/s: the vertical speed and thrust changes the inflow and ground-effect fits
    need; a slow descent lets diagnose confuse the two, tests/sim/diagnose/test_diagnose_hidden.py -m slow), and it
    ends at 0.8 m, not at 0.25 m, because of what follows it. Table 6's altitude loop on the base model
    is lightly damped (eq. 24 on M z'' = 4 u_z: zeta = 4 kd_z / (2 sqrt(4 kp_z M)) = 0.07, an 80 %
    overshoot): it lags a fast descent and then undershoots its end by about the vehicle's speed over
    the loop's natural frequency, 0.4-0.5 m, so that a single descent to 0.25 m touched the floor at
    1.2 m/s (a crash: `flightctl sim excite` exited 1, issue 49). From 0.8 m that undershoot clears the
    floor, and the 0.55 m left are flown at half the speed; it lands on the base model with Table 6 or
    Table 4 and on the as-flown model (tests/sim/test_sil.py holds it above the floor until it lands)."""
    moves = ([Move(0.0, "alt", 0.25, 2.0), Move(6.0, "alt", 1.2, 3.0)]
             + _steps("roll", [(10, 4), (12, -4), (14, 0)]) + _steps("pitch", [(16, 4), (18, -4), (20, 0)])
             + _steps("yaw", [(22, 60), (27, -60), (32, 0)])
             + [Move(35.0, "alt", 2.0, 2.0), Move(38.0, "alt", 0.8, 2.0), Move(42.0, "alt", 0.25, 2.0),
                Move(46.0, "alt", 0.0, 1.5)])
    return Plan(moves, 48.0, "excite", "low hover at 0.25 m, roll/pitch steps +-4 deg, yaw steps +-60 deg, "
                "climb to 2 m, a fast descent to 0.8 m, back to 0.25 m, land")


def hover_low() -> Plan:
    """Ground effect: take off to 0.2 m, hold, climb to 1 m, come back down to 0.2 m and land."""
    moves = [Move(0.0, "alt", 0.2, 2.0), Move(8.0, "alt", 1.0, 3.0), Move(14.0, "alt", 0.2, 3.0),
             Move(22.0, "alt", 0.0, 1.0)]
    return Plan(moves, 24.0, "hover_low", "hover low (0.2 m), climb to 1 m, back, land")


# Each call builds a fresh Plan (a Plan keeps the state of its setpoints).
PLANS: dict[str, Callable[[], Plan]] = {
    "hover": hover,
    "paper": paper,
    "step_alt": step_alt,
    "step_roll": lambda: _single("step_roll", "roll", 5.0, "figure 14"),
    "step_pitch": lambda: _single("step_pitch", "pitch", -5.0, "figure 15"),
    "step_yaw": step_yaw,
    "excite": excite,
    "hover_low": hover_low,
}


def load_plan(spec: str) -> Plan:
    """A plan file (`*.toml`, or any existing file; flightctl/plans/plan.py) or the name of a plan above."""
    path = Path(spec)
    if path.suffix == ".toml" or path.exists():
        return read_plan_file(path)
    if spec not in PLANS:
        raise InputError(f"plan {spec!r}: neither a plan file nor a named plan (named: {', '.join(PLANS)})")
    return check_plan(PLANS[spec]())
