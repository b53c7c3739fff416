"""The causes: every candidate extension of docs/measured-data.md, then the project's own (docs/diagnose.md,
"Causes beyond the contract"), one module each, holding side by side its plant effect (an `Effect` on
the seam of `flightctl.sim.world.model`; a sensor effect acts on the simulated IMU) and its diagnose
fit (a `Candidate` of `flightctl.sim.diagnose.candidate`).

`CAUSES` maps each name to its `Cause`: the effect class, the candidate class, the parameters with
their units, and a one-line description. `flightctl sim --effect` builds effects with `parse`, the
tests with `make`, and `flightctl diagnose` runs every candidate in this order.

Each module declares everything the rest reads of its cause: on its `Candidate`, its `twin` (the same
effect modelled another way), whether it `times_actuation` and its `lookalikes` (diagnose/verdict.py's
chain reads them through `twin`, `times_actuation` and `lookalikes` below); on its `Effect`, whether the
compiled plant carries it (`compiled`, its `compiled_hook` and `compiled_q`: sim/world/compiled.py reads
them).

Adding a cause: a module here with its `Effect` and its `Candidate` (whose `effect` names it), one
row in `_EXTENSION_FITS` below, the project's causes after the contract's `_FITS` (and the module on the
import line; or `register` for one defined elsewhere), a row in docs/diagnose.md's table of the causes
beyond the contract (the contract's table is docs/measured-data.md's; tests/sim/causes/test_causes.py
checks that the registry and the two tables agree), a unit test of the effect and a hidden-effect case
(`draw` in tests/helpers/diagnose_cases.py); docs/architecture.md, "Where to add".
Importing the registry costs no scipy (the fits import it when they run): `flightctl sim` starts fast.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from flightctl.errors import InputError
from flightctl.sim.causes import (actuation_delay, battery_sag, com_offset, ground_effect, gyro_lag, linear_yaw_drag,
                                  motor_dynamics, motor_lag, motor_weak, rotor_drag, rotor_inflow)
from flightctl.sim.diagnose.candidate import Candidate
from flightctl.sim.world.model import Effect, Parameter


@dataclass(frozen=True)
class Cause:
    name: str
    doc: str                           # one line: what the real vehicle does that the base model does not
    parameters: dict[str, Parameter]   # name -> (unit, lo, hi), in the order of docs/measured-data.md
    effect: type[Effect]
    candidate: type[Candidate]

    @classmethod
    def of(cls, candidate: type[Candidate]) -> "Cause":
        effect = candidate.effect
        doc = (effect.__doc__ or "").strip().splitlines()[0]
        return cls(effect.cause, doc, dict(effect.required), effect, candidate)


_FITS = (motor_lag.MotorLagFit, actuation_delay.ActuationDelayFit, ground_effect.GroundEffectFit,
         battery_sag.BatterySagFit, linear_yaw_drag.LinearYawDragFit, rotor_drag.RotorDragFit,
         com_offset.ComOffsetFit, motor_weak.MotorWeakFit, rotor_inflow.RotorInflowFit,
         motor_dynamics.MotorDynamicsFit)
# the project's own causes, after the contract's (docs/diagnose.md, "Causes beyond the contract")
_EXTENSION_FITS = (gyro_lag.GyroLagFit,)

CAUSES: dict[str, Cause] = {c.name: c for c in map(Cause.of, _FITS + _EXTENSION_FITS)}
EXTENSIONS: tuple[str, ...] = tuple(f.effect.cause for f in _EXTENSION_FITS)


def register(candidate: type[Candidate]) -> Cause:
    """Add the cause of `candidate` (its `effect` names it) to `CAUSES`, after the others."""
    cause = Cause.of(candidate)
    if cause.name in CAUSES:
        raise ValueError(f"cause {cause.name!r} is registered already")
    CAUSES[cause.name] = cause
    return cause


def twin(cause: str) -> str | None:
    """The cause that is the same physical effect as `cause` modelled another way, or None."""
    return CAUSES[cause].candidate.twin if cause in CAUSES else None


def times_actuation(cause: str) -> bool:
    """Whether `cause` times the actuation (a lag or a delay of the rotors)."""
    return cause in CAUSES and CAUSES[cause].candidate.times_actuation


def lookalikes(cause: str) -> tuple[str, ...]:
    """The causes that `cause` may be swapped with once the others are in the model, in their order."""
    return CAUSES[cause].candidate.lookalikes if cause in CAUSES else ()


def make(cause: str, **parameters: float) -> Effect:
    """The plant effect of `cause` with its parameters, each checked against its range."""
    if cause not in CAUSES:
        raise InputError(f"unknown effect {cause!r} (known: {', '.join(CAUSES)})")
    spec = CAUSES[cause].parameters
    optional = CAUSES[cause].effect.optional
    missing = set(spec) - set(parameters)
    unknown = set(parameters) - set(spec) - set(optional)
    if missing or unknown:
        raise InputError(f"{cause}: takes {', '.join(spec)}"
                         + (f" (and optionally {', '.join(optional)})" if optional else "")
                         + (f"; missing {', '.join(sorted(missing))}" if missing else "")
                         + (f"; unknown {', '.join(sorted(unknown))}" if unknown else ""))
    for name, p in {**spec, **{k: v for k, v in optional.items() if k in parameters}}.items():
        v = parameters[name]
        if not (math.isfinite(v) and p.lo <= v <= p.hi):
            raise InputError(f"{cause}: {name}={v:g} is out of range [{p.lo:g}, {p.hi:g}]")
    return CAUSES[cause].effect(**parameters)


def carried(params) -> tuple[Effect, ...]:
    """The plant effects a parameter file carries (`[[effect]]` tables, docs/measured-data.md)."""
    return tuple(make(e.cause, **dict(e.parameters)) for e in params.effects)


def combined(params, effects=()) -> tuple[Effect, ...]:
    """The plant's effects: the parameter file's, then `effects` (`--effect`). An added effect of a
    cause the file carries replaces it (one motor lag, one rotor inertia), never adds a second."""
    added = {e.cause for e in effects}
    return tuple(e for e in carried(params) if e.cause not in added) + tuple(effects)


def load_vehicle(spec, gains=None):
    """`flightctl.params.load`, then every `[[effect]]` built once, so that an unknown cause or a
    parameter out of its range is refused naming the file and the table, before anything flies."""
    from flightctl.params import load, resolve
    params = load(spec, gains)
    for k, e in enumerate(params.effects, start=1):
        try:
            make(e.cause, **dict(e.parameters))
            for name, lo, hi in e.ranges:           # the range's ends are effects of the cause too
                make(e.cause, **{**dict(e.parameters), name: lo})
                make(e.cause, **{**dict(e.parameters), name: hi})
        except InputError as err:
            raise InputError(f"{resolve(spec)}: [[effect]] {k}: {err}") from None
    return params


def parse(text: str) -> Effect:
    """`CAUSE:name=value,name=value`, as `flightctl sim --effect` takes it."""
    cause, colon, args = text.partition(":")
    if not colon and "=" in cause:          # `--effect tau=0.05`: the values without their cause
        cause, args = "", cause
    parameters = {}
    for item in filter(None, args.split(",")):
        name, sep, value = item.partition("=")
        if not sep:
            raise InputError(f"--effect {text!r}: expected CAUSE:name=value,... (bad item {item!r})")
        if name.strip() in parameters:
            raise InputError(f"--effect {text!r}: {name.strip()} given twice")
        try:
            parameters[name.strip()] = float(value)
        except ValueError:
            raise InputError(f"--effect {text!r}: {name.strip()} = {value.strip()!r} is not a number") from None
    if not cause.strip():
        raise InputError(f"--effect {text!r}: no cause before the values: expected CAUSE:name=value,... "
                         f"(causes: {', '.join(CAUSES)})")
    return make(cause.strip(), **parameters)
