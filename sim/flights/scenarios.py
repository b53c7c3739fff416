"""Scenarios: a flight plan plus the steps whose responses are measured (the paper's figures).

The plans are the onboard registry `flightctl.plans.PLANS`; what the simulator adds is the
measurement: every step of a plan (a move with no ramp) is measured from its time until the plan's
next move, or its end. A step to altitude 0 is a landing, not a response (the loop disarms on
touchdown), and ramps are not steps. `SCENARIOS` has the same names as `PLANS`.
"""
from __future__ import annotations

from dataclasses import dataclass

from flightctl.plans.plan import Plan
from flightctl.plans import PLANS


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


def measured_steps(plan: Plan) -> tuple[Step, ...]:
    """The steps of `plan`, each from the channel's previous target (0 before any move)."""
    target = {}
    times = sorted({m.t for m in plan.moves} | {plan.duration})
    steps = []
    for m in plan.moves:
        start = target.get(m.channel, 0.0)
        target[m.channel] = m.value
        if m.ramp > 0.0 or (m.channel == "alt" and m.value <= 0.0):
            continue
        until = next(t for t in times if t > m.t) if m.t < plan.duration else m.t
        steps.append(Step(m.channel, m.t, start, m.value, until - m.t))
    return tuple(steps)


def scenario(plan: Plan) -> Scenario:
    """Any plan (named or from a file) with its measured steps."""
    return Scenario(plan.name, plan, measured_steps(plan), plan.doc)


SCENARIOS = {name: (lambda make=make: scenario(make())) for name, make in PLANS.items()}
