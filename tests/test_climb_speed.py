"""`rotor_inflow`'s climb speed (sim/causes/rotor_inflow.py, `climb_speed`): the body-z velocity that
diagnose rebuilds from a log, against the simulator's truth (positions and attitude in the log's
truth columns). A vehicle whose centre of mass is off drifts at metres per second with tens of
degrees of tilt; there most of w_b is the horizontal velocity's part along z_b, which the
reconstruction must include."""
from __future__ import annotations

import numpy as np

from flightctl.cli import main
from flightctl.logfile import MAG_COLUMNS, read_flight_log
from flightctl.params import load
from flightctl.sim.world.board import TRUTH_COLUMNS
from flightctl.sim.causes.rotor_inflow import climb_speed
from flightctl.sim.identify.diagnose.cli import FOREIGN_COLUMNS
from flightctl.sim.identify.diagnose.data import load_file
from flightctl.sim.identify.diagnose.dataset import DataSet, Vehicle
from flightctl.sim.world.model import rotation
from test_diagnose_cases import quick_plan


def test_the_climb_speed_includes_the_drift_along_the_tilted_body_axis(tmp_path):
    rng = np.random.default_rng(23)
    d, angle = rng.uniform(0.006, 0.01), rng.uniform(0.0, 2.0 * np.pi)
    dx, dy = float(d * np.cos(angle)), float(d * np.sin(angle))
    log = tmp_path / "drift.csv"
    main(["sim", "--plan", str(quick_plan(tmp_path)), "--log", str(log), "--seed", "3", "--no-plot", "--quiet",
          "--effect", f"com_offset:dx={dx!r},dy={dy!r}"])     # its fast steps end in a hard touchdown
    a = load(None).airframe
    fd = load_file(read_flight_log(log, min_seconds=1, min_rows=10, extra=FOREIGN_COLUMNS), a)
    ds = DataSet([fd], Vehicle.known(a, fd.layout))
    (w,) = climb_speed(ds)
    truth = read_flight_log(log, extra=MAG_COLUMNS + TRUTH_COLUMNS)
    t = truth["t"]
    v = np.vstack([np.gradient(truth[c], t) for c in ("true_x", "true_y", "true_z")])
    R = np.array(rotation(truth["true_roll"], truth["true_pitch"], truth["true_yaw"]))
    w_true = R[2] * v[0] + R[5] * v[1] + R[8] * v[2]                  # z_b . v
    w_true = 0.5 * (w_true[:-1] + w_true[1:])                        # over each period, as `climb_speed`
    _, s0, s1 = ds.stretches[0]                                      # from the take-off, at rest
    rows = np.arange(s0 + 450, s1)                                   # past its first second
    horizontal = np.hypot(v[0], v[1])[rows]
    assert np.percentile(horizontal, 95) > 2.0                       # it drifted
    vertical_only = (R[8] * v[2])[rows]                              # what the vertical speed alone gives
    err = w[rows] - w_true[rows]
    assert np.sqrt(np.mean(err ** 2)) < 0.25 * np.sqrt(np.mean((vertical_only - w_true[rows]) ** 2))
    assert np.sqrt(np.mean(err ** 2)) < 0.3                           # m/s
