"""A fleet's per-flight rows drawn without flying: the motor shares (with their standard errors) of each
flight as `flightctl diagnose --corpus` writes them into the results table (sim/diagnose/fleet/followed.py),
for measuring the fleet report's change test over many fleets (scripts/fleet_detection.py) at a cost a
flown fleet (sim/sweeps/fleet_flown.py) cannot have.

The draw is the flown fleet's, row for row: each vehicle's motors differ as simulate_fleet's do (one motor
off by up to MOTOR_SPREAD of its thrust); on the changed vehicle, one drawn motor gives `1 - size` of its
thrust from a drawn onset on (fleet.onset_margin, as the flown fleet draws it). A motor giving k_j of its
thrust is commanded 1/k_j of it in hover, so the command's thrust share of motor j is (1/k_j) / mean(1/k)
(report.share_scale); each flight's measured share is that plus a spread between flights (`Noise.tau`: a
pack's temperature, the wind, the load) and its own error, drawn with the standard error the row reports
(log-normal over flights: `Noise.se_log_mean`, `Noise.se_log_sd`), the four then put back to mean one as
the static tier's are (static/hover.py). `Noise` is calibrated on flown and diagnosed flights by the
script. The truth (which vehicle, motor, onset, scale) is returned beside the rows, never in them."""
from __future__ import annotations

import datetime as dt
from dataclasses import dataclass

import numpy as np

from flightctl.sim.sweeps.fleet_flown import EPOCH_UTC, MOTOR_SPREAD, onset_margin
from flightctl.sim.diagnose.fleet.followed import SERIES


@dataclass(frozen=True)
class Noise:
    se_log_mean: float        # the mean of log(standard error) of a flight's share
    se_log_sd: float          # its spread over flights
    tau: float                # the spread between flights that no flight's error holds (share units)


def draw_fleet(rng: np.random.Generator, vehicles: int, flights: int, size: float, noise: Noise) -> tuple[list[dict], dict | None]:
    """(the results table's rows, the truth) of `vehicles` x `flights`; one vehicle's motor loses `size` of
    its thrust (0: none changes, truth None)."""
    changed = int(rng.integers(vehicles)) if size > 0 else None
    truth = None
    rows = []
    for v in range(vehicles):
        uid = f"drawn-{v + 1}-{int(rng.integers(1 << 32)):08X}"
        k = np.ones((flights, 4))
        k[:, int(rng.integers(4))] *= 1.0 + rng.uniform(-MOTOR_SPREAD, MOTOR_SPREAD)
        if v == changed:
            m, margin = int(rng.integers(4)), onset_margin(flights)
            onset = int(rng.integers(margin, flights - margin))
            k[onset:, m] *= 1.0 - size
            truth = {"vehicle": uid, "motor": m + 1, "onset": onset, "scale": 1.0 - size}
        g = 1.0 / k
        share = g / g.mean(axis=1, keepdims=True)
        se = np.exp(noise.se_log_mean + noise.se_log_sd * rng.standard_normal((flights, 4)))
        y = share + noise.tau * rng.standard_normal((flights, 4)) + se * rng.standard_normal((flights, 4))
        y /= y.mean(axis=1, keepdims=True)
        for j in range(flights):
            figures = {s: None for s in SERIES}
            figures.update({f"share_{i + 1}": [float(y[j, i]), float(se[j, i])] for i in range(4)})
            figures.update(rates=None, tier="static", timing_needs=None, named=[])
            start = EPOCH_UTC + dt.timedelta(days=j)
            rows.append({"log": f"{uid}/{j + 1:08d}.BIN", "path": f"{uid}/{j + 1:08d}.BIN", "index": None,
                         "status": "diagnosed", "figures": figures,
                         "meta": {"vehicle_id": uid, "vehicle_id_source": "drawn", "start_utc": start.isoformat(),
                                  "start_source": "drawn"}})
    return rows, truth


def judge(rep: dict, truth: dict | None) -> dict:
    """What the report (report.build of the rows) said of the drawn fleet: whether the change was found (its
    vehicle and motor named, the onset within a flight), and how many healthy vehicles had a motor named."""
    motors = [c for c in rep["changes"] if c["what"].startswith("motor")]
    found = truth is not None and any(c["vehicle"] == truth["vehicle"] and c["what"] == f"motor {truth['motor']}"
                                      and abs(c["onset_flight"] - truth["onset"]) <= 1 for c in motors)
    healthy = [v["vehicle"] for v in rep["vehicles"] if truth is None or v["vehicle"] != truth["vehicle"]]
    false = sum(any(c["vehicle"] == h for c in motors) for h in healthy)
    return {"found": found, "healthy": len(healthy), "false": false}
