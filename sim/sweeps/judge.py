"""What the paper judged of its real flights (sec. 4.4.5, figures 17-20), measured on a flight's true
response, and the paired verdict of one draw flown with both gain sets.

Per attitude step (the banks of figures 18-19, the turns of figure 20), from RING_AFTER_S after the
step to the next step:
- ringing: the peak-to-peak of the true angle (deg): how much it still swings once it has arrived;
- damping: the damping ratio of a second-order response with the step's true overshoot,
  zeta = -ln(OS) / sqrt(pi^2 + ln(OS)^2) (1 without overshoot, 0 from an overshoot of 100 %: a
  response that swings past twice its step is no damped second-order one);
- held error: what the controller held, the mean of its own estimate less the command over the
  step's last second (what the paper's figures show: they plot the vehicle's own estimate), apart
  from the estimator's bias there, the mean of the true angle less the estimate; the true held error
  is their sum. Both gain sets share the bias, so a band on the true error judges the estimator, not
  the gains. Its cause in a held bank (tests/sim/flights/test_estimator_bias.py, docs/as-flown.md): the
  accelerometer reads the bank's tilt only as the rotor drag builds up over M/k, and the in-flight
  correction pulls the estimate towards it, about 2 phi (M/k) (1 - exp(-t k/M)) / tau_tilt_air:
  0.5 degree at the momentum drag, 1.3 at the range's weak end, for a 5 degree bank held 5 s; on top
  of it the broadband gyro noise's random walk through that correction, and the chip's drift.

The verdict of a draw: each gain set flies when it left the ground, did not crash and landed
upright, and holds (`bounded`) when it also rings by at most RING_BOUND_DEG in every bank and turn
(the size of sec. 3.3's tuning steps) and holds its own estimate within SETTLED_DEG (1 degree for a
bank, 3 for a turn); its score is the worst ringing over the steps, each in its channel's band.
Table 6 beats Table 4 when it holds and Table 4 does not, or both hold and Table 6's score is lower.
The paper's account holds when Table 4 holds and Table 6 holds and beats it (sec. 4.4.5: the
simulation's gains "worked", the retuned ones "improved" it). The full path and the batched
simulator judge alike: their landings by sim/flights/run.py's `judge_figures`, their verdicts here,
from the same `summary` (sim/sweeps/montecarlo.py's `_result`). The true columns may be (rows, N),
N vehicles of the batched simulator: every figure is then an (N,) array.
"""
from __future__ import annotations

import math

import numpy as np

from flightctl.control.pid import wrap
from flightctl.sim.flights.metrics import SETTLED_DEG, TRUE

RING_AFTER_S = 1.0     # s after the step: the step's own rise and first overshoot are over
HELD_S = 1.0           # s: the held error over the step's last second
# The pilot's bound on the ringing (peak-to-peak, from RING_AFTER_S on), from the paper's own tuning
# criteria (sec. 3.3): its steps were +-5 degrees of roll and pitch and +-30 of yaw, "a single initial
# overshoot in y(t) is allowed", kd raised "until no oscillation remains", within a settling period of
# 3 s. A swing still as large as the tuning step once the step has arrived is a second overshoot, and
# one that lasts to the next step an oscillation that remained: the loosest reading of the criteria
# (their 0.1 degree of allowable error is the simulation's, below any real gyro's noise).
RING_BOUND_DEG = {"roll": 5.0, "pitch": 5.0, "yaw": 30.0}


def step_figures(log, steps, t_arm: float) -> list[dict]:
    """Per attitude step: channel, ringing (deg), damping ratio, held error and the estimator's bias
    (deg); inf ringing (and NaN others) for a step the flight did not cover."""
    t = log["t"] - t_arm
    out = []
    for s in steps:
        if s.channel == "alt":
            continue
        true, est = log[TRUE[s.channel]], log[s.channel]
        ring = (t >= s.t + RING_AFTER_S - 1e-6) & (t <= s.t + s.window)
        whole = (t >= s.t) & (t <= s.t + s.window)
        last = (t >= s.t + s.window - HELD_S - 1e-6) & (t <= s.t + s.window)
        shape = () if true.ndim == 1 else true.shape[1:]
        if not (ring.any() and t[-1] >= s.t + s.window - 1e-6):
            out.append({"channel": s.channel, "ringing": np.full(shape, math.inf), "damping": np.full(shape, math.nan),
                        "held": np.full(shape, math.nan), "bias": np.full(shape, math.nan)})
            continue
        e = wrap(true[ring] - s.end)
        change = s.end - s.start
        progress = wrap(true[whole] - s.start) / change
        overshoot = np.maximum(np.max(progress, axis=0) - 1.0, 0.0)
        with np.errstate(divide="ignore", invalid="ignore"):
            ln = np.log(np.where(overshoot > 0, overshoot, 1.0))
            zeta = np.where(overshoot > 0, np.maximum(-ln / np.sqrt(np.pi ** 2 + ln ** 2), 0.0), 1.0)
        out.append({"channel": s.channel, "ringing": np.degrees(np.ptp(e, axis=0)), "damping": zeta,
                    "held": np.degrees(np.mean(wrap(est[last] - s.end), axis=0)),
                    "bias": np.degrees(np.mean(wrap(true[last] - est[last]), axis=0))})
    return out


def score(figures: list[dict]):
    """The worst ringing of the steps, each in its channel's band (1: at the band)."""
    worst = None
    for f in figures:
        v = f["ringing"] / SETTLED_DEG[f["channel"]]
        worst = v if worst is None else np.maximum(worst, v)
    return worst


def holds(figures: list[dict], flies):
    """It flies (left the ground, no crash, landed upright) and every attitude step rings and holds
    within its channel's band (SETTLED_DEG: 1 degree for a bank, 3 for a turn): the true angle's
    peak-to-peak once the step has arrived, and the controller's own held error, both apart from the
    estimator's bias. `flies` a bool or an (N,) array (the batched simulator's vehicles)."""
    ok = np.asarray(flies, dtype=bool)
    for f in figures:
        band = SETTLED_DEG[f["channel"]]
        ok = ok & (f["ringing"] <= band) & (np.abs(f["held"]) <= band)
    return ok


def summary(figures: list[dict]) -> dict:
    """JSON-ready figures of one flight (one vehicle): the score, and per channel the worst ringing,
    the lowest damping, the largest held error as the vehicle's own estimate saw it (`held_deg`: what
    the paper's figures show), the largest estimator bias and the largest true held error (the sum of
    the two, step by step)."""
    out = {"score": _num(score(figures))}
    for ch in ("roll", "pitch", "yaw"):
        fs = [f for f in figures if f["channel"] == ch]
        if fs:
            out[ch] = {"ringing_deg": _num(max(float(f["ringing"]) for f in fs)),
                       "damping": _num(min(float(f["damping"]) for f in fs)),
                       "held_deg": _num(max(abs(float(f["held"])) for f in fs)),
                       "bias_deg": _num(max(abs(float(f["bias"])) for f in fs)),
                       "true_held_deg": _num(max(abs(float(f["held"] + f["bias"])) for f in fs))}
    return out


def _num(v) -> float | None:
    v = float(v)
    return v if math.isfinite(v) else None


def bounded(flight: dict, scale: float = 1.0) -> bool:
    """The pilot's verdict of one flight from its `summary` and {"flies": bool}: it flies (left the
    ground, no crash, landed upright) and holds every bank and turn, its worst ringing within `scale`
    x RING_BOUND_DEG (sec. 3.3's tuning steps) and its own held error within SETTLED_DEG (what the
    paper's figures 18-20 show, by the vehicle's own estimate)."""
    if not flight["flies"]:
        return False
    for ch, bound in RING_BOUND_DEG.items():
        f = flight.get(ch)
        if f is None or f["ringing_deg"] is None or f["ringing_deg"] > scale * bound \
                or f["held_deg"] is None or f["held_deg"] > SETTLED_DEG[ch]:
            return False
    return True


def verdict(t4: dict, t6: dict, scale: float = 1.0) -> dict:
    """The paired verdict of one draw from each gain set's {"flies": bool, "score": float or None, and
    `summary`'s channels}. Table 6 beats Table 4 when it holds within the bound (`bounded`) and Table 4
    does not, or both do and Table 6's score is lower; the paper's account holds when both hold within
    the bound and Table 6 beats Table 4. "landing only": the same with "flies" for "holds within the
    bound" (the judgement before the bound)."""
    s4, s6 = t4.get("score"), t6.get("score")
    s4 = math.inf if s4 is None else s4
    s6 = math.inf if s6 is None else s6
    b4, b6 = bounded(t4, scale), bounded(t6, scale)
    beats = bool(b6 and (not b4 or s6 < s4))
    landing = bool(t4["flies"] and t6["flies"] and s6 < s4)
    return {"table6 beats table4": beats, "paper's account": bool(b4 and b6 and beats),
            "paper's account, landing only": landing}
