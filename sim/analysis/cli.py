"""`flightctl analyze`: linear analysis of each loop (roll, pitch, yaw, altitude) about hover.

The plant is linearised through the model seam with the effects the simulator would fly; each loop
is the PID of eq. 24, the mixer of eq. 25, eq. 26 inverted, the 450 Hz sample-and-hold (and the 45 Hz
sonar for altitude) and the onboard estimator as it runs (or perfect state feedback, `truth`).
Prints per loop the gain and phase margins, the crossover, the damping of the dominant closed-loop
mode and the step response's rise time, overshoot and settling time; `--json` writes them and
`--plot PREFIX` draws PREFIX-bode.png and PREFIX-step.png. See docs/analyze.md.
"""
from __future__ import annotations

import argparse
import inspect
import json
import math
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from flightctl.control.controller import FlightController
from flightctl.control.estimator import ESTIMATORS
from flightctl.errors import InputError, Parser
from flightctl.files import output_file, output_prefix, write_atomic
from flightctl.sim.flights.run import gains_label
from flightctl.params import GAIN_SETS, Params
from flightctl.plans import HOVER_ALT
from flightctl.sim import causes
from flightctl.sim.world.model import Model

if TYPE_CHECKING:
    from flightctl.sim.analysis.linear import LinearPlant
    from flightctl.sim.analysis.loops import Loop

DEFAULT_ESTIMATOR = inspect.signature(FlightController).parameters["structure"].default   # what flies
TRUTH = "truth"


@dataclass
class Analysis:
    params: Params
    effects: tuple
    plant: LinearPlant
    loops: dict[str, dict[str, Loop]]   # estimator -> channel -> loop


def analyse(params: Params, effects=(), estimators=(TRUTH, DEFAULT_ESTIMATOR), alt: float = HOVER_ALT,
            horizon: float | None = None, channels=None) -> Analysis:
    """Every loop for each estimator: 'truth' (perfect state feedback), a name of ESTIMATORS, or a
    function making an estimator from the parameters. The model carries the parameter file's
    effects and then `effects`, as the simulated board builds it (`flightctl.sim.world.board`), so that
    their terms and states are in the linearisation."""
    # here, not at the top: `flightctl analyze` checks its arguments before scipy and python-control load
    from flightctl.sim.analysis.linear import linearise
    from flightctl.sim.analysis.loops import CHANNELS, build, hover_responses
    channels = CHANNELS if channels is None else channels
    a = params.airframe
    effects = causes.combined(params, effects)
    plant = linearise(Model(a, effects), alt, a.battery_nominal_v)
    loops = {}
    for est in estimators:
        Y = None if est == TRUTH else hover_responses(params, plant, est)
        name = est if isinstance(est, str) else getattr(est, "__name__", "custom")
        loops[name] = {ch: build(params, plant, est, ch, Y, horizon) for ch in channels}
    return Analysis(params, effects, plant, loops)


COLUMNS = (("GM dB", "gain_margin_db", 1.0, "7.1f"), ("PM deg", "phase_margin_deg", 1.0, "7.1f"),
           ("wc rad/s", "crossover_rad_s", 1.0, "8.2f"), ("zeta", "damping", 1.0, "6.3f"),
           ("wn rad/s", "natural_rad_s", 1.0, "8.2f"), ("rise s", "rise_s", 1.0, "7.3f"),
           ("overshoot %", "overshoot", 100.0, "11.1f"), ("settling s", "settling_s", 1.0, "10.2f"))


def table(an: Analysis) -> str:
    """The printed table: one block per estimator, one row per loop."""
    lines = []
    for est, loops in an.loops.items():
        what = "perfect state feedback" if est == TRUTH else f"{est} estimator, full onboard path"
        lines.append(f"\n{est} ({what})")
        lines.append(f"{'loop':<6}" + "".join(f"{h:>{int(fmt.split('.')[0]) + 1}}" for h, _, _, fmt in COLUMNS)
                     + "  note")
        for ch, loop in loops.items():
            f = loop.figures
            row = f"{ch:<6}" + "".join(f" {f[key] * k:{fmt}}" for _, key, k, fmt in COLUMNS)
            note = "" if f["stable"] else ("drifts: the true output creeps from a held setpoint"
                                           if f["drift"] else "UNSTABLE")
            lines.append(row + ("  " + note if note else ""))
    return "\n".join(lines)


def report(an: Analysis, gains: str) -> dict:
    """The JSON document: the hover trim and every loop's figures (infinite or undefined as null)."""
    def clean(v):
        return None if isinstance(v, float) and not math.isfinite(v) else v

    a = an.params.airframe
    return {
        "gains": gains,
        "effects": [repr(e) for e in an.effects],
        "hover": {"alt_m": float(an.plant.x0[2]), "command_P": [float(v) for v in an.plant.u0[:4]],
                  "loop_hz": a.loop_hz, "sonar_hz": a.sonar_hz},
        "loops": {est: {ch: {k: clean(v) for k, v in loop.figures.items()} | {"period_s": loop.period}
                        for ch, loop in loops.items()} for est, loops in an.loops.items()},
    }


UNITS = {"roll": "roll", "pitch": "pitch", "yaw": "yaw", "alt": "altitude"}


def plot(an: Analysis, prefix: str, title: str) -> list[Path]:
    """PREFIX-bode.png (|L| and its phase per loop, each estimator a line) and PREFIX-step.png."""
    import control

    from flightctl.sim.analysis.loops import CHANNELS
    from flightctl.sim.plots import figure, figure_legend, save

    fig, axes = figure(2, len(CHANNELS), size=(14, 6.5), sharex="col")
    for j, ch in enumerate(CHANNELS):
        for est, loops in an.loops.items():
            L = loops[ch].L
            w = np.logspace(-1.0, math.log10(0.999 * math.pi / L.dt), 300)
            resp = control.frequency_response(L, w)
            mag = 20.0 * np.log10(np.abs(resp.magnitude).ravel())
            phase = np.degrees(np.unwrap(np.asarray(resp.phase).ravel()))
            phase -= 360.0 * math.ceil(phase[0] / 360.0)   # start in (-360, 0]
            line, = axes[0, j].semilogx(w, mag, label=est)
            axes[1, j].semilogx(w, phase, color=line.get_color(), label=est)
        axes[0, j].axhline(0.0, color="0.4", lw=0.8)
        axes[1, j].axhline(-180.0, color="0.4", lw=0.8)
        axes[0, j].set_title(f"{UNITS[ch]} loop")
        axes[0, j].set_ylabel("|L| (dB)")
        axes[1, j].set_ylabel("phase of L (deg)")
        axes[1, j].set_xlabel("frequency (rad/s)")
        for ax in axes[:, j]:
            ax.grid(alpha=0.3)
    fig.suptitle(f"{title}: each loop broken at the plant input")
    figure_legend(fig, axes[0, 0], len(an.loops))
    bode = Path(f"{prefix}-bode.png")
    save(fig, bode)

    fig, axes = figure(2, 2, size=(11, 7))
    for ax, ch in zip(axes.ravel(), CHANNELS):
        end = 0.0                                        # each loop on its own time axis
        for est, loops in an.loops.items():
            loop = loops[ch]
            y = loop.y.copy()
            out = np.flatnonzero(np.abs(y) > 3.0)
            if out.size:                                 # an unstable response ends where it leaves the axes
                y[out[0]:] = np.nan
            every = max(1, loop.t.size // 2000)          # a screen's worth of points
            ax.plot(loop.t[::every], y[::every], label=est)
            away = np.flatnonzero(~(np.abs(y - 1.0) <= 0.02))    # outside 2 %, or gone
            end = max(end, loop.t[-1] if out.size or away.size == 0 or away[-1] == y.size - 1
                      else min(loop.t[-1], 1.5 * loop.t[away[-1]]))
        ax.axhline(1.0, color="0.4", lw=0.8)
        ax.set_xlim(0.0, max(end, 0.5))
        ax.set_ylim(-1.0, 3.0)
        ax.set_title(f"{UNITS[ch]}: the true response to a setpoint step")
        ax.set_xlabel("time (s)")
        ax.set_ylabel("response / step (ratio)")
        ax.grid(alpha=0.3)
    fig.suptitle(title)
    figure_legend(fig, axes[0, 0], len(an.loops))
    step = Path(f"{prefix}-step.png")
    save(fig, step)
    return [bode, step]


def parser() -> argparse.ArgumentParser:
    p = Parser(prog="flightctl analyze", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--params", help="parameter file (TOML); default: the reference airframe")
    p.add_argument("--gains", choices=sorted(GAIN_SETS),
                   help="gain set by name, which replaces the parameter file's [gains] (default: the file's, else table6)")
    p.add_argument("--estimator", action="append", choices=(TRUTH,) + tuple(ESTIMATORS),
                   help=f"the measurement the PIDs read: {TRUTH} (perfect state feedback) or an onboard "
                        f"estimator structure; repeatable (default: {TRUTH} and {DEFAULT_ESTIMATOR})")
    p.add_argument("--effect", action="append", default=[], metavar="CAUSE:name=value,...",
                   help=f"add an extension to the plant ({', '.join(causes.CAUSES)}); repeatable")
    p.add_argument("--alt", type=float, default=HOVER_ALT, help=f"hover altitude, m (default {HOVER_ALT:g})")
    p.add_argument("--json", help="write the figures of every loop to this JSON file")
    p.add_argument("--plot", metavar="PREFIX", help="draw PREFIX-bode.png and PREFIX-step.png")
    return p


def main(argv: list[str]) -> int:
    args = parser().parse_args(argv)
    if not (0.05 <= args.alt <= 4.0) or not math.isfinite(args.alt):
        raise InputError(f"--alt {args.alt:g}: the sonar reads 0.05 to 4 m")
    if args.json:
        output_file(args.json, "--json", ".json")
    if args.plot:
        for kind in ("bode", "step"):
            output_file(f"{output_prefix(args.plot)}-{kind}.png", "--plot")
    params = causes.load_vehicle(args.params, GAIN_SETS[args.gains] if args.gains else None)
    gains = gains_label(args, params)
    effects = tuple(causes.parse(e) for e in args.effect)
    estimators = tuple(dict.fromkeys(args.estimator or (TRUTH, DEFAULT_ESTIMATOR)))
    an = analyse(params, effects, estimators, args.alt)
    P = an.plant.u0[:4]
    title = f"{gains} gains, {args.params or 'reference airframe'}, hover at {args.alt:g} m"
    print(f"flightctl analyze: {title} (P = {np.mean(P):.2f}); plant: "
          + (", ".join(map(repr, an.effects)) or "base model"))
    print(table(an))
    if args.json:
        write_atomic(args.json, json.dumps(report(an, gains), indent=2) + "\n")
        print(f"\nfigures -> {args.json}")
    if args.plot:
        for path in plot(an, args.plot, f"flightctl analyze: {title}"):
            print(f"plot -> {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
