"""Losing a motor, measured (docs/safety.md, "Losing a motor"): every number of that section, and its
figure, from the onboard loop against the simulated quadcopter.

    python scripts/motor_loss.py                      # print the numbers, draw motor-loss.png here
    python scripts/motor_loss.py --doc docs/safety.md --out docs/motor-loss.png   # rewrite the docs
    python scripts/motor_loss.py --check docs/safety.md                           # exit 1 if they differ

The flights (seeded, so that the numbers reproduce to the digit): the figure's (the as-flown model in
the hover at 1.5 m, motor 2 stopped at 6.3 s); each motor lost at times drawn anywhere in the paper
flight, on both models and both gain sets, and during every yaw turn of it; the plant's Jp, gamma1 and
g1 at the ends of their ranges (the loop told the file's values); partial losses; and the detector's
largest missing share in flights without a loss (every plan, both models and gain sets, and draws of
the as-flown file's ranges). The equilibrium spin and the linearised loop's spectral radius come from
flightctl/control/spin_design.py, the computation the loop itself uses (its event text too).
"""
from __future__ import annotations

import argparse
import dataclasses
import math
import os
import random
import sys
from pathlib import Path

import numpy as np

from flightctl.control import motor_loss as ml
from flightctl.control import spin_design as sd
from flightctl.params import GAIN_SETS, load
from flightctl.sim import causes
from flightctl.sim.flights.run import fly
from flightctl.sim.flights.scenarios import SCENARIOS
from flightctl.sim.world import faults

BEGIN, END = "<!-- motor loss: begin (written by scripts/motor_loss.py) -->", "<!-- motor loss: end -->"
MODELS = (("base", None), ("as-flown", "paper-as-flown"))
DRAWS = 5                       # losses per model and gain set at random times of the paper flight
MARGIN_SEEDS = (1, 2, 3, 4)     # the seeds each plan is flown at in the false-alarm margins
MC_DRAWS = 4                    # draws of the as-flown ranges in the false-alarm margins (each: both gain sets)
# the gain sets that fly each model (Table 4 limit-cycles on the as-flown file: `limit_cycle`)
FLOWN = (("base", None, "table6"), ("base", None, "table4"), ("as-flown", "paper-as-flown", "table6"))
AIRBORNE = (1.0, 81.5)          # s: the paper flight is off the floor from 1 s to its touchdown at 81.7 s
TURNS = (40.1, 46.1, 52.1, 58.1)   # s: 0.1 s into each yaw step of the paper flight (2.3-2.6 rad/s)


def params_of(spec, gains="table6"):
    return dataclasses.replace(load(spec), gains=GAIN_SETS[gains])


def loss(plan: str, params, spec: str, plant: dict | None = None, seed: int = 0, tau: float | None = None,
         sensors: dict | None = None) -> dict:
    """One flight with the fault `spec`: outcome, naming, tilt, touchdown speed, drift, spin. `plant`:
    airframe values, `tau`: the motor time constant, `sensors`: the IMU's [sensors] values, of the
    simulated vehicle only (the loop is told the file's)."""
    fault = faults.parse(spec)
    airframe = dataclasses.replace(params.airframe, **plant) if plant else None
    effects = (causes.make("motor_dynamics", tau=tau, tau_down=tau),) if tau is not None else ()
    if sensors:                    # read by the simulated IMU only: the onboard code never reads [sensors]
        params = dataclasses.replace(params, sensors=dataclasses.replace(params.sensors, **sensors))
    fl = fly(SCENARIOS[plan](), params, os.devnull, faults=[fault], seed=seed, plant_airframe=airframe, effects=effects)
    L, at = fl.log, fault.at
    t = L["t"]
    after = t >= at
    named = next(((te, w) for te, w in fl.result.events if te >= at and (" lost (" in w or " weak (" in w)), None)
    tilt = np.degrees(np.arccos(np.clip(np.cos(L["true_roll"]) * np.cos(L["true_pitch"]), -1, 1)))
    i0 = int(np.flatnonzero(after)[0])
    i1 = max(i0 - 45, 0)                         # the velocity it had (0.1 s before): not the loss's
    x, y = L["true_x"], L["true_y"]
    v0 = ((x[i0] - x[i1]) / (t[i0] - t[i1]), (y[i0] - y[i1]) / (t[i0] - t[i1]))
    ts = t[after] - t[i0]
    drift = np.hypot(x[after] - x[i0] - v0[0] * ts, y[after] - y[i0] - v0[1] * ts)
    air = after & (L["true_z"] > 0.05)
    return {"outcome": fl.outcome, "ms": None if named is None else 1e3 * (named[0] - at),
            "what": "" if named is None else named[1], "tilt": float(tilt[after].max()),
            "touchdown": max((abs(v) for _, v in fl.touchdowns), default=math.nan),
            "drift": float(drift.max()), "r0": float(L["gyro_z"][i0]), "z0": float(L["true_z"][i0]),
            "spin": float(np.abs(L["gyro_z"][air]).max()) if air.any() else 0.0,
            "flight": fl, "at": at}


def noise_end(params, end: int) -> dict:
    """The [sensors] values at the bottom (end 0) or the top (end 1) of the file's ranges."""
    return {name: (lo, hi)[end] for table, name, lo, hi in params.table_ranges if table == "sensors"}


def margins() -> list[tuple[str, float, float]]:
    """The detector's largest missing share held for LOOPS and for WEAK_LOOPS loops in calm flight, in
    every plan without a loss (both models, both gain sets), and over draws of the as-flown ranges (the
    controller told each draw, as the Monte Carlo does), also with the IMU's noise at the top of its
    ranges."""
    from flightctl.loop import FlightLoop
    from flightctl.plans import PLANS
    from flightctl.sim.sweeps.montecarlo import draw, drawn_params, one_draw
    from flightctl.sim.world.board import SIM_CALIBRATE_S, sim_board
    import flightctl.loop as loop_module
    seen: list[float] = []

    class Watched(ml.MotorLossDetector):
        __slots__ = ()

        def update(self, s, f, dt, low=False):
            out = super().update(s, f, dt, low)
            seen.append(self.seen)
            return out

    def held(n):
        a = np.array(seen)
        return float(np.lib.stride_tricks.sliding_window_view(a, n).min(axis=1).max()) if len(a) >= n else 0.0

    def flight(params, effects, airframe, plan, seed):
        seen.clear()
        hal, world = sim_board(params, effects, seed=seed, airframe=airframe)
        FlightLoop(hal, params, PLANS[plan](), None, calibrate_s=SIM_CALIBRATE_S).run()
        return held(ml.LOOPS), held(ml.WEAK_LOOPS)

    rows = []
    inner = loop_module.MotorLossDetector
    loop_module.MotorLossDetector = Watched
    try:
        for name, spec in MODELS:
            for gains in GAIN_SETS:
                worst = [0.0, 0.0]
                for plan in PLANS:
                    for seed in MARGIN_SEEDS:
                        worst = np.maximum(worst, flight(params_of(spec, gains), (), None, plan, seed))
                rows.append((f"every plan at seeds {MARGIN_SEEDS[0]}-{MARGIN_SEEDS[-1]}, {name} model, {gains}", *worst))
        base = causes.load_vehicle("paper-as-flown")
        n = MC_DRAWS
        drawn = draw(base, n, 28)
        for top in (False, True):
            worst = [0.0, 0.0]
            for k in range(n):
                d = one_draw(drawn, k)
                for gains in GAIN_SETS:
                    params = drawn_params(causes.load_vehicle("paper-as-flown", GAIN_SETS[gains]), d)
                    if top:
                        params = dataclasses.replace(params, sensors=dataclasses.replace(params.sensors,
                                                                                         **noise_end(params, 1)))
                    effects = tuple(causes.make(e.cause, **dict(e.parameters)) for e in params.effects)
                    worst = np.maximum(worst, flight(params, effects, params.airframe, "paper", k))
            rows.append((f"the paper flight over {n} draws of the as-flown ranges, both gain sets"
                         + (", the IMU's noise and vibration at the top of their ranges" if top else ""), *worst))
    finally:
        loop_module.MotorLossDetector = inner
    return [(what, float(a), float(b)) for what, a, b in rows]


def limit_cycle() -> dict:
    """Table 4 on the as-flown file without a loss: the hover's roll and pitch peak-to-peak once at
    height, and the share of those loops in calm flight (where the detector looks)."""
    params = params_of("paper-as-flown", "table4")
    fl = fly(SCENARIOS["hover"](), params, os.devnull, seed=0)
    L = fl.log
    held = (L["t"] > 8.0) & (L["t"] < 20.0)
    ptp = max(float(np.ptp(L["true_roll"][held])), float(np.ptp(L["true_pitch"][held])))
    rates = np.abs(L["gyro_x"][held]) + np.abs(L["gyro_y"][held])
    k = ml.MotorLossDetector(params).kc      # the detector's own low-pass of |p| + |q| over CALM_S
    calm, c = [], 0.0
    for v in rates:
        c += k * (v - c)
        calm.append(c < ml.CALM)
    return {"ptp": math.degrees(ptp), "calm": float(np.mean(calm)), "outcome": fl.outcome}


def measure(quick: bool = False) -> dict:
    asf = params_of("paper-as-flown")
    d = sd.design_inputs(asf)
    out = {"design": d, "r_bar": sd.equilibrium_spin(d),
           "r_gamma_half": sd.equilibrium_spin(d._replace(gamma1=d.gamma1 / 2)),
           "r_gamma_twice": sd.equilibrium_spin(d._replace(gamma1=d.gamma1 * 2)),
           "r_g1_twice": sd.equilibrium_spin(d._replace(g1=d.g1 * 2)),
           "schedule": sd.load(d)}
    out["figure"] = loss("hover", asf, "motor_stop:motor=2,at=6.3")
    rng = random.Random(28)
    anywhere = []
    for name, spec, gains in FLOWN:
        for _ in range(1 if quick else DRAWS):
            m, at = rng.randint(1, 4), round(rng.uniform(*AIRBORNE), 2)
            anywhere.append((name, gains, m, at, loss("paper", params_of(spec, gains), f"motor_stop:motor={m},at={at}")))
    out["anywhere"] = anywhere
    out["limit_cycle"] = limit_cycle()
    # during the yaw turns: each motor, so that half the losses meet a yaw rate against the pair's spin
    out["turns"] = [(m, at, loss("paper", asf, f"motor_stop:motor={m},at={at}"))
                    for at in TURNS for m in ((1, 2) if quick else (1, 2, 3, 4))]
    a = asf.airframe
    lo, hi = noise_end(asf, 0), noise_end(asf, 1)
    out["ends"] = [(what, loss("hover", asf, "motor_stop:motor=2,at=8", **kw)) for what, kw in (
        (f"Jp = {d.Jp_lo:.3g}", {"plant": {"Jp": d.Jp_lo}}), (f"Jp = {d.Jp_hi:.3g}", {"plant": {"Jp": d.Jp_hi}}),
        (f"gamma1 = {a.gamma1 / 2:.3g}", {"plant": {"gamma1": a.gamma1 / 2}}),
        (f"gamma1 = {a.gamma1 * 2:.3g}", {"plant": {"gamma1": a.gamma1 * 2}}),
        (f"g1 = {a.g1 / 2:.3g}", {"plant": {"g1": a.g1 / 2}}), (f"g1 = {a.g1 * 2:.3g}", {"plant": {"g1": a.g1 * 2}}),
        (f"motor tau = {1e3 * d.tau_lo:.0f} ms", {"tau": d.tau_lo}),
        (f"motor tau = {1e3 * d.tau_hi:.0f} ms", {"tau": d.tau_hi}),
        (f"IMU noise at the bottom (gyro broadband {lo['gyro_broadband']:.3g} rad/s)", {"sensors": lo}),
        (f"IMU noise at the top (gyro broadband {hi['gyro_broadband']:.3g} rad/s)", {"sensors": hi}),
        (f"motor tau = {1e3 * d.tau_hi:.0f} ms, Jp = {d.Jp_lo:.3g}, IMU noise at the top",
         {"tau": d.tau_hi, "plant": {"Jp": d.Jp_lo}, "sensors": hi}))]
    out["partial"] = [(name, gains, share, loss("hover", params_of(spec, gains), f"motor_partial:motor=2,share={share},at=8"))
                      for name, spec, gains in (FLOWN[2], FLOWN[1]) for share in (0.1, 0.3, 0.5, 0.6, 0.7)]
    out["low"] = [(at, loss("paper", asf, f"motor_stop:motor=3,at={at}")) for at in (1.2, 1.6, 81.0)]
    out["margins"] = [] if quick else margins()
    return out


def _row(r: dict) -> str:
    return (f"{r['outcome']} | {r['ms']:.0f} | {r['tilt']:.0f} | {r['touchdown']:.2f} | {r['drift']:.1f}"
            if r["ms"] is not None else f"{r['outcome']} | not named | {r['tilt']:.0f} | {r['touchdown']:.2f} | {r['drift']:.1f}")


def markdown(m: dict, figure: str) -> str:
    f = m["figure"]
    d = m["design"]
    trims = {g: next((k / 100 for k in range(100) if ml.flown_on_four(params_of("paper-as-flown", g), 2, k / 100)), None)
             for g in GAIN_SETS}
    coupling = d.Jzz - d.Jyy
    r_s = {name: J * sd.pair_speed(d) / coupling for name, J in (("the bottom of the as-flown Jp range", d.Jp_lo),
                                                                ("the as-flown Jp", d.Jp), ("Table 2's Jp", d.Jp_hi))}
    lines = [f"`python scripts/motor_loss.py` measured everything in this block (seeded flights, the "
             f"onboard loop against the simulated quadcopter).", "",
             "**The rule's edge**: the smallest share a motor on the roll axis may give and be flown on four: "
             + ", ".join(f"{g} {v:.2f}" for g, v in trims.items()) + ".", "",
             "**Where the coupling vanishes** (pair 1-3 at its hover speed): r_s = "
             + ", ".join(f"{v:.1f} rad/s with {k} ({J:.3g})" for (k, v), J in zip(r_s.items(), (d.Jp_lo, d.Jp, d.Jp_hi)))
             + ".", "",
             f"**The spin.** The pair's reaction torques balance eq. 6's yaw drag at **{m['r_bar']:.1f} rad/s** on "
             f"the reference airframe (the loop's own event text says it); {m['r_gamma_half']:.1f} rad/s at half the "
             f"identified gamma1 and {m['r_g1_twice']:.1f} at twice g1 (beyond the gyro's {sd.GYRO_MAX:.1f} rad/s once "
             f"the spin settles, which a landing from a few metres does not wait for), {m['r_gamma_twice']:.1f} at "
             f"twice gamma1.", "",
             f"![A landing on two rotors]({figure})", "",
             f"The figure: the as-flown model in the hover at 1.5 m, motor 2 stopped at {f['at']:g} s. The loop names "
             f"it {f['ms']:.0f} ms later; the thrust axis tilts to {f['tilt']:.0f} degrees while the spin builds; the "
             f"spin reaches {f['spin']:.1f} rad/s before touchdown; the touchdown is at {f['touchdown']:.2f} m/s; the "
             f"vehicle drifts {f['drift']:.1f} m from where the loss found it (beyond the velocity it had).", "",
             "**Anywhere in the paper flight** (each motor at times drawn from a seeded generator while it is off "
             "the floor; each gain set on the models it flies):", "",
             "| model | gains | motor | at (s) | outcome | named after (ms) | largest tilt (deg) | touchdown (m/s) | drift (m) |",
             "|---|---|---|---|---|---|---|---|---|"]
    for name, gains, mot, at, r in m["anywhere"]:
        lines.append(f"| {name} | {gains} | {mot} | {at:g} | {_row(r)} |")
    lc = m["limit_cycle"]
    lines += ["", f"Table 4 on the as-flown file is left out: without any loss its hover limit-cycles at "
              f"{lc['ptp']:.0f} degrees peak-to-peak ({lc['outcome']}), and only {100 * lc['calm']:.0f} % of its loops "
              f"at height are calm flight, where the detector looks (docs/as-flown.md: Table 4 flies in part of the "
              f"file's ranges, not at its nominal point)."]
    lines += ["", "**During the yaw turns** (as-flown, Table 6; 0.1 s into each yaw step: the pair left after "
              "motor 1 or 3 spins the body at negative r, after 2 or 4 at positive r, so a yaw rate of the "
              "other sign is a turn against the pair's spin):", "",
              "| motor | at (s) | yaw rate then (rad/s) | outcome | named after (ms) | largest tilt (deg) | touchdown (m/s) | drift (m) |",
              "|---|---|---|---|---|---|---|---|"]
    for mot, at, r in m["turns"]:
        lines.append(f"| {mot} | {at:g} | {r['r0']:+.2f} | {_row(r)} |")
    lines += ["", "**The plant at the ends of its ranges** (as-flown, hover, motor 2 at 8 s; the loop told the "
              "file's values; Jp's, the motor time constant's and the IMU's ranges are the file's (the motor's top "
              "at the file's Jp), gamma1 and g1 halved and doubled):", "",
              "| plant | outcome | named after (ms) | largest tilt (deg) | touchdown (m/s) | drift (m) | largest spin (rad/s) |",
              "|---|---|---|---|---|---|---|"]
    for what, r in m["ends"]:
        lines.append(f"| {what} | {_row(r)} | {r['spin']:.1f} |")
    lines += ["", "**Partial losses** (hover, motor 2 giving a share of its commanded thrust from 8 s; each gain "
              "set on a model it flies; the loop's answer by the rule above):", "",
              "| model | gains | share given | outcome | named after (ms) | largest tilt (deg) | touchdown (m/s) | drift (m) "
              "| the loop's words |",
              "|---|---|---|---|---|---|---|---|---|"]
    for name, gains, share, r in m["partial"]:
        words = r["what"].split(":")[0] if r["what"] else "-"
        lines.append(f"| {name} | {gains} | {share:g} | {_row(r)} | {words} |")
    lines += ["", "**Near the floor** (as-flown, Table 6, motor 3, in the paper flight's take-off and landing):", "",
              "| at (s) | height then (m) | outcome | named after (ms) | largest tilt (deg) | touchdown (m/s) | drift (m) |",
              "|---|---|---|---|---|---|---|"]
    for at, r in m["low"]:
        lines.append(f"| {at:g} | {r['z0']:.2f} | {_row(r)} |")
    if m["margins"]:
        lines += ["", f"**False alarms.** The detector's largest missing share held for {ml.LOOPS} loops and for "
                  f"{ml.WEAK_LOOPS} loops in calm flight without a loss, against THRESHOLD {ml.THRESHOLD} and WEAK "
                  f"{ml.WEAK} (at or above either, a motor can be named that was not lost):", "",
                  f"| flights | held {ml.LOOPS} loops | held {ml.WEAK_LOOPS} loops | a false alarm possible |",
                  "|---|---|---|---|"]
        for what, a, b in m["margins"]:
            lines.append(f"| {what} | {a:.3f} | {b:.3f} | {'yes' if a >= ml.THRESHOLD or b >= ml.WEAK else 'no'} |")
    s = m["schedule"]
    rates = s["rates"]
    show = [k for k, r in enumerate(rates) if r in (-8.0, -4.0, 0.0, 2.0, 4.0, 8.0, 12.0, 16.0, 20.0, 24.0, 28.0, 32.0)]
    lines += ["", f"**The linearised loop** (spin_design.py: eq. 7 about the spin, the pair's torque through the "
              f"motor time constant and the delay chain, held over one loop, the rate filter around eq. 7's "
              f"prediction): the spectral radius of the loop closed by the scheduled gains, the worst over "
              f"{len(sd.plants(d))} vehicles across the as-flown file's ranges (Jp {d.Jp_lo:.2g} to {d.Jp_hi:.2g} kg m^2, "
              f"the motor time constant {1e3 * d.tau_lo:.0f} to {1e3 * d.tau_hi:.0f} ms, the delay chain "
              f"{1e3 * d.delay_lo:.1f} to {1e3 * d.delay_hi:.1f} ms), pair 1-3, at "
              f"spin rates r (in the pair's direction) and the pair's rotor speed as a share of its hover one. Below 1 "
              f"the loop is stable. At r = 0 the axis along the pair is not turned (1: marginal; -: no gain solves "
              f"there, the nearest point's stand in): the spin must build.", "",
              "| rotor speed | " + " | ".join(f"r = {rates[k]:g}" for k in show) + " |",
              "|---" * (len(show) + 1) + "|"]
    for j, row in enumerate(s["radius"]["0,2"]):
        share = sd.OMEGA_TOP * j / sd.OMEGA_STEPS
        lines.append(f"| {share:.2f} | " + " | ".join("-" if not math.isfinite(row[k]) else f"{row[k]:.4f}"
                                                       for k in show) + " |")
    return "\n".join(lines) + "\n"


def draw_figure(m: dict, out: str) -> None:
    from flightctl.sim.plots import figure, legend, save
    f = m["figure"]
    L, at, r_bar = f["flight"].log, f["at"], m["r_bar"]
    t = L["t"]
    tilt = np.degrees(np.arccos(np.clip(np.cos(L["true_roll"]) * np.cos(L["true_pitch"]), -1, 1)))
    fig, ax = figure(4, 1, size=(9.0, 10.0), sharex="col")
    ax[0, 0].plot(t, L["true_z"], label="true altitude")
    ax[0, 0].plot(t, L["alt"], lw=0.8, label="estimate")
    ax[0, 0].set_ylabel("altitude (m)")
    ax[1, 0].plot(t, np.abs(L["gyro_z"]), label="|r| (gyro)")
    for value, what, style in ((r_bar, "balance, gamma1", "-"), (m["r_gamma_half"], "gamma1 / 2", ":"),
                               (m["r_gamma_twice"], "2 gamma1", "--")):
        ax[1, 0].axhline(value, color="0.3", ls=style, lw=0.9, label=f"{what}: {value:.1f} rad/s")
    ax[1, 0].axhline(sd.GYRO_MAX, color="tab:red", lw=0.8, label="gyro full scale (2000 deg/s)")
    ax[1, 0].set_ylabel("spin rate (rad/s)")
    ax[2, 0].plot(t, tilt, label="true tilt of the thrust axis")
    ax[2, 0].set_ylabel("tilt (deg)")
    for i in range(1, 5):
        ax[3, 0].plot(t, L[f"P{i}"], lw=0.9, label=f"P{i}")
    ax[3, 0].set_ylabel("command P (0-255)")
    ax[3, 0].set_xlabel("time since arming (s)")
    for row in ax[:, 0]:
        row.axvline(at, color="k", ls=":", lw=0.8)
        row.grid(alpha=0.3)
        legend(row)
    fig.suptitle(f"as-flown model, hover at 1.5 m: motor 2 stops at {at:g} s; {f['flight'].outcome}")
    save(fig, out)


def block_of(text: str) -> str:
    from flightctl.sim.docs import block
    body = block(text, BEGIN, END)
    if body is None:
        raise SystemExit(f"the markers {BEGIN} ... {END} are not in the document")
    return body.strip("\n") + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0].replace("\n", " "))
    ap.add_argument("--out", default="motor-loss.png", help="the figure (PNG; default ./motor-loss.png)")
    ap.add_argument("--doc", help="rewrite the block between the markers of this document")
    ap.add_argument("--check", help="compare the block of this document with a fresh one: exit 1 if they differ")
    ap.add_argument("--quick", action="store_true", help="fewer flights (a trial; not for the docs)")
    args = ap.parse_args(argv)
    m = measure(args.quick)
    figure = "motor-loss.png"
    text = markdown(m, figure)
    if args.check:
        old = block_of(Path(args.check).read_text(encoding="utf-8"))
        if old != text:
            import difflib
            sys.stdout.writelines(difflib.unified_diff(old.splitlines(True), text.splitlines(True), "docs", "fresh"))
            return 1
        print(f"{args.check}: the motor-loss block is what the flights give")
        return 0
    print(text)
    draw_figure(m, args.out)
    print(f"figure -> {args.out}")
    if args.doc:
        from flightctl.sim.docs import write_or_exit
        write_or_exit(args.doc, BEGIN, END, text)
        print(f"{args.doc}: the motor-loss block rewritten")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
