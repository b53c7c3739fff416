"""Yaw drag of section 3.2.3: eq. 6, `tau_d = (gamma1 r^2 + gamma2) sgn(r)`, from steady spins on the
bearing, where the applied propeller torque equals the drag torque. Linear least squares in gamma1, gamma2."""
from __future__ import annotations

import numpy as np

from flightctl.sim.identify.fits import Identified, linear_fit, require, within


def identify(table, airframe) -> Identified:
    r, tau = table["yaw_rate"], table["torque"]
    require(table, "yaw_rate", r != 0, "the yaw rate must not be 0 (one row per steady spin)")
    within(table, "yaw_rate", -1e3, 1e3, "rad/s")
    within(table, "torque", -100.0, 100.0, "N m")
    # eq. 6 (flightctl.physics.yaw_drag) is linear in gamma1, gamma2: columns r |r| and sgn(r)
    fit = linear_fit(np.column_stack([r * np.abs(r), np.sign(r)]), tau, ("gamma1", "gamma2"))
    report = {"kind": "yaw-drag", "file": table.path, **fit.params(),
              "residual_rms": {"torque": fit.rms}, "r2": {"torque": fit.r2},
              "spins": {"positive": int(np.sum(r > 0)), "negative": int(np.sum(r < 0))}}
    lines = [f"yaw-drag {table.path}: {len(r)} steady spins (eq. 6)",
             f"  gamma1 = {fit['gamma1']:.4g} ± {fit.error('gamma1'):.2g} N m/(rad/s)^2, "
             f"gamma2 = {fit['gamma2']:.4g} ± {fit.error('gamma2'):.2g} N m; "
             f"rms {fit.rms:.3g} N m, R^2 {fit.r2:.4f}"]
    return Identified(report, lines, {"gamma1": fit["gamma1"], "gamma2": fit["gamma2"]}, (r, tau, fit))
