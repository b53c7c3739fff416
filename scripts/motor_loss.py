"""A landing after a lost motor (docs/safety.md, "Losing a motor"): the as-flown model hovers at
1.5 m through the full onboard path, motor 2 stops at 6.3 s after arming (`--fault motor_stop`), the
loop names it, flies on motors 1 and 3 spinning, and lands. Draws altitude, spin rate, the tilt of the
thrust axis and the four commands, with the spin rate the model predicts at equilibrium
(flightctl/control/spin.py: gamma1 r^2 = 2 (g1 f + g2), f = M g / 2) for the identified gamma1 and for
half and twice it, and prints the figures.

    python scripts/motor_loss.py [--out docs/motor-loss.png] [--motor 2] [--at 6.3]
"""
from __future__ import annotations

import argparse
import math
import tempfile
from pathlib import Path

import numpy as np

from flightctl.control.spin import SpinController
from flightctl.params import load
from flightctl.sim.world import faults
from flightctl.sim.plots import figure, legend, save
from flightctl.sim.flights.run import fly
from flightctl.sim.flights.scenarios import SCENARIOS


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0].replace("\n", " "))
    ap.add_argument("--out", default="docs/motor-loss.png", help="the figure (PNG)")
    ap.add_argument("--motor", type=int, default=2, help="the motor that stops (1-4, default 2)")
    ap.add_argument("--at", type=float, default=6.3, help="when, s after arming (default 6.3)")
    args = ap.parse_args(argv)
    params = load("paper-as-flown")
    a = params.airframe
    with tempfile.TemporaryDirectory() as tmp:
        flight = fly(SCENARIOS["hover"](), params, Path(tmp) / "f.csv",
                     faults=[faults.parse(f"motor_stop:motor={args.motor},at={args.at}")])
    L = flight.log
    t = L["t"]
    spin = SpinController(params)
    r_bar = spin.r_bar
    air = (t > args.at) & (L["true_z"] > 0.05)
    r_end = float(np.median(np.abs(L["gyro_z"][air][-450:]))) if air.any() else math.nan
    tilt = np.degrees(np.arccos(np.clip(np.cos(L["true_roll"]) * np.cos(L["true_pitch"]), -1, 1)))
    lost = next((te for te, what in flight.result.events if "lost" in what), math.nan)
    print(f"motor {args.motor} stopped at {args.at:g} s, named at {lost:.3f} s ({1e3 * (lost - args.at):.0f} ms); "
          f"{flight.outcome}, touchdown at {max(abs(v) for _, v in flight.touchdowns):.2f} m/s")
    print(f"spin: {r_end:.1f} rad/s in the last second before touchdown; predicted at equilibrium "
          f"{r_bar:.1f} rad/s (gamma1 = {a.gamma1:.3g}), {r_bar * math.sqrt(2):.1f} (gamma1 / 2), "
          f"{r_bar / math.sqrt(2):.1f} (2 gamma1); the gyro reads up to {math.radians(2000):.1f} rad/s")
    print(f"largest tilt of the thrust axis after the loss: {float(np.max(tilt[t > args.at])):.0f} deg")
    fig, ax = figure(4, 1, size=(9.0, 10.0), sharex="col")
    ax[0, 0].plot(t, L["true_z"], label="true altitude")
    ax[0, 0].plot(t, L["alt"], lw=0.8, label="estimate")
    ax[0, 0].set_ylabel("altitude (m)")
    ax[1, 0].plot(t, np.abs(L["gyro_z"]), label="|r| (gyro)")
    for value, what, style in ((r_bar, "predicted, gamma1", "-"), (r_bar * math.sqrt(2), "gamma1 / 2", ":"),
                               (r_bar / math.sqrt(2), "2 gamma1", "--")):
        ax[1, 0].axhline(value, color="0.3", ls=style, lw=0.9, label=f"{what}: {value:.1f} rad/s")
    ax[1, 0].axhline(math.radians(2000), color="tab:red", lw=0.8, label="gyro full scale (2000 deg/s)")
    ax[1, 0].set_ylabel("spin rate (rad/s)")
    ax[2, 0].plot(t, tilt, label="true tilt of the thrust axis")
    ax[2, 0].set_ylabel("tilt (deg)")
    for i in range(1, 5):
        ax[3, 0].plot(t, L[f"P{i}"], lw=0.9, label=f"P{i}")
    ax[3, 0].set_ylabel("command P (0-255)")
    ax[3, 0].set_xlabel("time since arming (s)")
    for row in ax[:, 0]:
        row.axvline(args.at, color="k", ls=":", lw=0.8)
        row.grid(alpha=0.3)
        legend(row)
    fig.suptitle(f"as-flown model, hover at 1.5 m: motor {args.motor} stops at {args.at:g} s; "
                 f"{flight.outcome}")
    save(fig, args.out)
    print(f"figure -> {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
