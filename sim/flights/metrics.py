"""Step-response metrics of a flight, on the true response (what the vehicle did) and on the
controller's own estimate (what it believed): rise time, overshoot, settling time, steady error and
cross-coupling into the other channels."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from flightctl.logfile import Table
from flightctl.sim.flights.scenarios import Step

TRUE = {"roll": "true_roll", "pitch": "true_pitch", "yaw": "true_yaw", "alt": "true_z"}
ANGLES = ("roll", "pitch", "yaw")
SETTLING_BAND = 0.05      # of the step size
STEADY_WINDOW_S = 1.0     # the last second of the step's window


@dataclass
class StepMetrics:
    step: Step
    rise_s: float           # 10 % to 90 % of the change
    overshoot: float        # fraction of the change beyond the target
    settling_s: float       # last exit from the +-5 % band, after the step; inf: still outside it at the end
    steady_error: float     # mean error over the last second (rad or m)
    coupling: dict[str, float]   # largest departure of each other channel from its setpoint
    flown_s: float = 0.0    # how much of the step's window the flight covered (it may end first)
    why: str = "the flight ended before this step"   # why it was not flown (whole or in part)

    @property
    def flown(self) -> bool:
        return self.flown_s >= self.step.window - 1e-6

    def row(self) -> str:
        s = self.step
        unit, k = ("deg", 180 / math.pi) if s.channel in ANGLES else ("m", 1.0)
        head = f"{s.channel:>5} {s.start * k:+6.1f} -> {s.end * k:+6.1f} {unit:<3}  "
        if self.flown_s <= 0.0:
            return head + f"not flown: {self.why}"
        couple = ", ".join(f"{c} {v * (180 / math.pi if c in ANGLES else 1):.2f}"
                           for c, v in self.coupling.items())
        settling = (f"{self.settling_s:5.2f} s" if math.isfinite(self.settling_s)
                    else f"not settled in {self.step.window:.1f} s")
        cut = "" if self.flown else f"  ({self.why} {self.flown_s:.1f} s into its {self.step.window:.1f} s)"
        return (head + f"rise {self.rise_s:5.2f} s  overshoot {100 * self.overshoot:5.1f} %  settling {settling}  "
                f"steady error {self.steady_error * k:+7.3f} {unit}  coupling: {couple}{cut}")


LEGEND = (f"  (settling: the last time outside +-{100 * SETTLING_BAND:g} % of the step's change; coupling: the "
          "largest departure of each other channel from its setpoint in the step's window, true values)")


def _error(channel: str, y: np.ndarray, target) -> np.ndarray:
    e = y - target
    return (e + np.pi) % (2 * np.pi) - np.pi if channel == "yaw" else e


def interruption(events) -> tuple[float, str] | None:
    """(time since arming, why) of the loop's first landing that replaced the rest of the plan (a lost
    motor, a low battery, ...; flightctl/loop.py's events ending in ": landing"), or None."""
    for t, what in events:
        if what.endswith(": landing"):
            return t, what[:-len(": landing")].split(" (")[0].split(":")[0]
    return None


def step_metrics(log: Table, step: Step, t_arm: float, source: str = "true", events=()) -> StepMetrics:
    """The step's response; `events`: the loop's (FlightResult.events), from which a landing that
    replaced the plan cuts the window (`interruption`): a step after it was not flown."""
    t = log["t"] - t_arm
    cut = interruption(events)
    end = step.t + step.window
    if cut is not None and cut[0] < end:
        if cut[0] <= step.t:
            return StepMetrics(step, math.nan, math.nan, math.nan, math.nan, {}, 0.0, f"{cut[1]}")
        end = cut[0]
    sel = (t >= step.t) & (t < end)      # the next move starts at the window's end
    ts = t[sel] - step.t
    col = TRUE[step.channel] if source == "true" else step.channel
    y = log[col][sel]
    change = step.end - step.start
    progress = _error(step.channel, y, step.start) / change          # 0 at the start, 1 at the target

    def first(cond):
        idx = np.flatnonzero(cond)
        return ts[idx[0]] if idx.size else math.nan

    rise = first(progress >= 0.9) - first(progress >= 0.1)
    overshoot = max(float(np.max(progress)) - 1.0, 0.0) if progress.size else math.nan
    outside = np.flatnonzero(np.abs(progress - 1.0) > SETTLING_BAND)
    settling = ts[outside[-1]] if outside.size else 0.0
    if outside.size and outside[-1] == len(ts) - 1:
        settling = math.inf   # never settled within the window
    last = ts >= step.window - STEADY_WINDOW_S
    steady = float(np.mean(_error(step.channel, y[last], step.end))) if last.any() else math.nan
    coupling = {}
    for other in ("roll", "pitch", "yaw", "alt"):
        if other == step.channel:
            continue
        col = TRUE[other] if source == "true" else other
        err = np.abs(_error(other, log[col][sel], log[f"{other}_sp"][sel]))
        coupling[other] = float(np.max(err)) if err.size else math.nan
    flown = float(min(t[-1], end) - step.t) if t.size else 0.0
    why = f"{cut[1]}" if cut is not None and end < step.t + step.window else "the flight ended"
    return StepMetrics(step, rise, overshoot, settling, steady, coupling, max(flown, 0.0), why)


def hold_metrics(log: Table, last_s: float = 10.0, until: float | None = None) -> dict[str, float] | None:
    """Over the last `last_s` seconds before `until` (the plan's end; default: the log's end, which
    after a plan that ends in the air is the landing): the largest altitude error (m) and tilt (rad),
    true values. None when the flight did not last until then (a fault landed it, a crash)."""
    end = log["t"][-1] if until is None else until
    if log["t"][-1] < end - 1e-6:
        return None
    sel = (log["t"] >= end - last_s) & (log["t"] <= end)
    return {"alt_error": float(np.max(np.abs(log["true_z"][sel] - log["alt_sp"][sel]))),
            "tilt": float(np.max(np.maximum(np.abs(log["true_roll"][sel]), np.abs(log["true_pitch"][sel]))))}


SETTLE_AFTER_S = 3.0                                   # the paper's "quick stabilization", read as 3 s
SETTLED_DEG = {"roll": 1.0, "pitch": 1.0, "yaw": 3.0}  # and "settle around the command values"


def settled_errors(log: Table, steps, t_arm: float) -> list[tuple[str, float]]:
    """Per attitude step: the largest true error (deg) from SETTLE_AFTER_S after the step to the next
    step: the paper's real-flight facts as the tests and the Monte Carlo read them (a step not flown
    that long counts as never settled, inf). The true columns may be (rows, N), N vehicles of the
    batched simulator (sim/sweeps/batch.py): each error is then an (N,) array."""
    t = log["t"] - t_arm
    out = []
    for s in steps:
        if s.channel == "alt":
            continue
        sel = (t >= s.t + SETTLE_AFTER_S - 1e-6) & (t <= s.t + s.window)
        e = (log[TRUE[s.channel]][sel] - s.end + np.pi) % (2 * np.pi) - np.pi
        if not (e.shape[0] and t[-1] >= s.t + s.window - 1e-6):
            out.append((s.channel, math.inf if e.ndim == 1 else np.full(e.shape[1], math.inf)))
        elif e.ndim == 1:
            out.append((s.channel, math.degrees(float(np.max(np.abs(e))))))
        else:
            out.append((s.channel, np.degrees(np.max(np.abs(e), axis=0))))
    return out


def settles(log: Table, steps, t_arm: float):
    """Every attitude step within SETTLED_DEG of its command from SETTLE_AFTER_S on (an (N,) bool
    array for the columns of N vehicles)."""
    out = True
    for ch, err in settled_errors(log, steps, t_arm):
        out = out & (err < SETTLED_DEG[ch])
    return out
