"""rotor_inflow's climb speed (sim/causes/rotor_inflow.py, `climb_speed`) against the simulator's truth.

Issue 49: on the 48 s `excite` plan the reconstructed body-z speed was off by 0.085 m/s rms and by
0.19 m/s at the take-off and the landing: its correction to the range took the accelerometer's bias
as constant, and the simulated chip's bias drifts as it warms up (sim/world/devices.py, SensorNoise).
A large hidden k then left an acc_z residual at the low heights that diagnose named ground_effect
(the slow sweep's seed 119). The size of k and the flight's seed are drawn; the test never tells
diagnose what was hidden."""
from __future__ import annotations

import csv

import numpy as np

from flightctl.cli import main
from flightctl.logfile import read_flight_log
from flightctl.params import load
from flightctl.sim.causes.ground_effect import GE_MAX_Z
from flightctl.sim.causes.rotor_inflow import climb_speed
from flightctl.sim.diagnose.data import load_file
from flightctl.sim.diagnose.dataset import DataSet, Vehicle

from helpers.diagnose_cases import draw


def truth_columns(path) -> dict[str, np.ndarray]:
    """The simulator's true_* columns (the flight-log reader keeps the contract's columns only)."""
    with open(path, newline="") as fh:
        rows = list(csv.reader(line for line in fh if not line.startswith("#")))
    head = rows[0]
    return {c: np.array([float(r[head.index(c)]) for r in rows[1:]])
            for c in ("t", "true_x", "true_y", "true_z", "true_roll", "true_pitch", "true_yaw")}


def true_w(log, t):
    """The body-z speed z_b . v from the logged truth (position differenced, attitude ZYX)."""
    tl = log["t"]
    vx, vy, vz = (np.gradient(log[c], tl) for c in ("true_x", "true_y", "true_z"))
    f, th, ps = log["true_roll"], log["true_pitch"], log["true_yaw"]
    w = ((np.cos(ps) * np.sin(th) * np.cos(f) + np.sin(ps) * np.sin(f)) * vx
         + (np.sin(ps) * np.sin(th) * np.cos(f) - np.cos(ps) * np.sin(f)) * vy + np.cos(th) * np.cos(f) * vz)
    return np.interp(t, tl, w)


def test_climb_speed_follows_the_truth_through_a_whole_excite_flight(tmp_path):
    rng = np.random.default_rng(4919)
    cause, truth = draw(rng, "rotor_inflow")
    seed = int(rng.integers(1000))
    path = tmp_path / "inflow.csv"
    assert main(["sim", "excite", "--log", str(path), "--seed", str(seed), "--no-plot", "--quiet",
                 "--effect", f"rotor_inflow:k={truth['k']!r}"]) == 0
    table = read_flight_log(path)
    a = load(None).airframe
    fd = load_file(table, a)
    ds = DataSet([fd], Vehicle.known(a, fd.layout))
    w = climb_speed(ds)[0]
    (i, s0, s1), = ds.stretches
    t = fd.t[s0:s1 + 1]
    ref = true_w(truth_columns(path), t)
    err = w[s0:s1] - 0.5 * (ref[:-1] + ref[1:])
    # near the floor, where ground_effect is judged: the vehicle is level there, and the speed is the
    # vertical part (the horizontal part drifts with the gyro's offset, which no range corrects)
    low = np.isfinite(fd.z[s0:s1]) & (fd.z[s0:s1] < GE_MAX_Z)
    rms = float(np.sqrt(np.mean(err[low] ** 2)))
    assert rms < 0.02, f"climb speed below {GE_MAX_Z} m off by {rms:.3f} m/s rms (k {truth['k']:.3f}, seed {seed})"
    ends = np.abs(err[[0, -1]])
    assert ends.max() < 0.04, f"at the take-off and the landing, off by {ends} m/s"
