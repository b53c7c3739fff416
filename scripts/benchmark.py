"""Benchmark (figures, not a test): how many times faster than real time `flightctl sim paper` flies,
on the base model and on the as-flown one (`--params paper-as-flown`: its effects make the forces
state-dependent), and what one control-loop iteration costs, decode to PWM counts, against the
2222 us loop period.

    python scripts/benchmark.py [--repeat N] [--markdown]

`--markdown` prints the README's block (scripts/docs.py writes it there): the date and the machine,
then one row per figure. The figures are this machine's on that day: tests/test_docs.py checks the
block's form, never its numbers.

The iteration is timed on the onboard code only (the fastest of many short runs): `Mpu9250.read` decoding a 22-byte burst (from a
fixed frame, so the simulated chip's cost is not counted), the calibration, the motor-loss check, the
estimator, the four PIDs, the mixer and eq. 26 inverted to counts. Targets: >= 30x real time, < 3 % of the period.

The batched simulator (sim/sweeps/batch.py): vehicle-steps per second (one loop period of one vehicle:
the vectorised controller and the plant) for N = 10,000 vehicles of the as-flown model, each with its
own draw of the file's ranges, on one core and on every core. Target: 1,000,000 at N = 10,000.

And how long `flightctl diagnose` takes on a real 500 Hz flight log (INDIflight's LOG00230, 26 s, from
../shared/data/real/flights, with the `logs` extra): the import, then the diagnosis (its base model
identified from the flight, every candidate, the chain). Target: a 30 s, 500 Hz log in under 60 s.
"""
from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from flightctl.control.controller import FlightController
from flightctl.control.estimator import Calibration
from flightctl.control.spin import MotorLossDetector
from flightctl.drivers.mpu9250 import Mpu9250
from flightctl.hal import ImuSample
from flightctl.params import load
from flightctl.sim.world.devices import SensorNoise, SimMpu9250, World
from flightctl.sim.flights.run import fly
from flightctl.sim.flights.scenarios import SCENARIOS


class FrozenSpi:
    """Answers every transfer with one burst captured from the simulated chip."""
    max_speed_hz = 0

    def __init__(self, frame):
        self.frame = frame

    def xfer2(self, data):
        return self.frame


def iteration_us(n: int = 1000, batches: int = 100) -> float:
    """us per control iteration: the fastest of `batches` runs of `n` iterations (this machine's
    neighbours slow some runs by up to 2x; the fastest is the code's own cost)."""
    params = load(None)
    chip = SimMpu9250(World(params.airframe, noise=SensorNoise()))
    imu = Mpu9250(chip, sleep=lambda s: None)
    imu.start()
    frame = chip.xfer2(list(imu._tx))
    imu.spi = FrozenSpi(frame)
    ctl = FlightController(params)
    cal = Calibration()
    sample = ImuSample()
    imu.read(sample)
    cal.add(sample)
    cal.apply(ctl.est)
    ctl.est.in_flight = True
    dt = params.airframe.dt
    read, correct, step = imu.read, cal.correct, ctl.step
    watch, f = MotorLossDetector(params).update, ctl.mixer.f
    best = float("inf")
    for _ in range(batches):
        start = time.perf_counter()
        for _ in range(n):
            read(sample)
            correct(sample)
            watch(sample, f, 1.5, dt)      # the motor-loss check, on the thrusts of the loop before
            step(sample, dt, 0.01, -0.02, 0.1, 1.5)
        best = min(best, time.perf_counter() - start)
    return best / n * 1e6


def batch_rate(n: int = 10000, seconds: float = 1.0, workers: int = 1) -> float:
    """Vehicle-steps per second of `sim.batch.simulate` (process start-up included)."""
    from flightctl.sim.sweeps.batch import simulate
    from flightctl.sim.sweeps.montecarlo import draw
    from flightctl.sim.flights.scenarios import SCENARIOS
    params = load("paper-as-flown")
    draws = draw(params, n, 0)
    plan = SCENARIOS["paper"]().plan
    start = time.perf_counter()
    flight = simulate(params, plan, 8.0, 8.0 + seconds, n, draws, workers=workers)
    return flight.vehicle_steps / (time.perf_counter() - start)


def split_us(name: str | None) -> tuple[float, float]:
    """Per loop period of `sim paper` (full onboard path): (us in the simulated world: the plant, the
    chip's SPI answers, the sonar's edges, the battery; us in the onboard loop and the log). The second
    bounds the simulator's speed whatever the plant costs: at most period / it times real time."""
    from flightctl.sim.world import devices
    spent = [0.0]

    def timed(cls, name):
        inner = getattr(cls, name)

        def wrapper(*a):
            t = time.perf_counter()
            r = inner(*a)
            spent[0] += time.perf_counter() - t
            return r
        return inner, wrapper
    patches = [(cls, attr, *timed(cls, attr)) for cls, attr in ((devices.World, "advance"), (devices.SimMpu9250, "xfer2"))]
    for cls, attr, _, wrapper in patches:
        setattr(cls, attr, wrapper)
    try:
        start = time.perf_counter()
        flight = fly(SCENARIOS["paper"](), load(name), Path(tempfile.mkdtemp()) / "paper.csv")
        wall = time.perf_counter() - start
    finally:
        for cls, attr, inner, _ in patches:
            setattr(cls, attr, inner)
    n = len(flight.log)
    return 1e6 * spent[0] / n, 1e6 * (wall - spent[0]) / n


def diagnose_seconds() -> tuple[float, float, float] | None:
    """(seconds of log, seconds to read it, seconds to diagnose it), or None without the shared data."""
    import contextlib
    import io
    import json

    from flightctl.cli import main as flightctl
    from flightctl.sim.logs import read_foreign
    log = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "real" / "flights" / "indiflight" / "LOG00230.BFL"
    if not log.exists():
        return None
    start = time.perf_counter()
    (table,) = read_foreign(str(log))
    read = time.perf_counter() - start
    out = Path(tempfile.mkdtemp()) / "report.json"
    start = time.perf_counter()
    with contextlib.redirect_stdout(io.StringIO()):
        assert flightctl(["diagnose", str(log), "--json", str(out), "--quiet"]) == 0
    total = time.perf_counter() - start
    json.loads(out.read_text())
    return float(table["t"][-1]), read, total


HEADER = ("| what | figure | target |", "|---|---|---|")
STAMP = "Measured by `python scripts/benchmark.py --markdown` on {date}: {machine}."


def machine() -> str:
    """This machine, as the figures need it said: OS, CPU count, Python, whether numba compiles."""
    import os
    import platform
    from flightctl.sim.world import compiled
    world = ("the simulated world compiled by numba" if compiled.model_period() is not None
             else "the simulated world in plain Python (numba absent or FLIGHTCTL_JIT=0)")
    load = f", load average {os.getloadavg()[0]:.1f} when it began" if hasattr(os, "getloadavg") else ""
    return (f"{platform.system()} {platform.machine()}, {os.cpu_count()} cores{load}, Python "
            f"{platform.python_version()}, {world}")


def figures(repeat: int) -> list[tuple[str, str, str]]:
    """(what, figure, target) rows: every figure this script measures."""
    import os
    params = load(None)
    out = Path(tempfile.mkdtemp())
    rows = []
    for label, name, kw, target in (("full onboard path", None, {}, ">= 30x (goal 100x)"),
                                    ("perfect state feedback", None, {"truth": True}, ">= 30x"),
                                    ("full onboard path, --params paper-as-flown", "paper-as-flown", {},
                                     ">= 30x (goal 60x)")):
        ratios = []
        for _ in range(repeat):
            start = time.perf_counter()
            flight = fly(SCENARIOS["paper"](), load(name), out / "paper.csv", **kw)
            wall = time.perf_counter() - start
            ratios.append(flight.log["t"][-1] / wall)
        rows.append((f"`flightctl sim paper`, {label}", f"{statistics.median(ratios):.1f}x real time (median of "
                     f"{repeat}; {min(ratios):.1f}x to {max(ratios):.1f}x)", target))
    period_us = 1e6 * params.airframe.dt
    for label, name in (("base model", None), ("paper-as-flown", "paper-as-flown")):
        world, onboard = min((split_us(name) for _ in range(repeat)), key=sum)
        rows.append((f"one loop period of `flightctl sim paper`, {label}",
                     f"{world:.0f} us in the simulated world, {onboard:.0f} us in the onboard loop and the log "
                     f"(which alone caps the simulator at {period_us / onboard:.0f}x)", "-"))
    us = min(iteration_us() for _ in range(repeat))
    rows.append(("one control iteration (decode to PWM counts, the motor-loss check included)",
                 f"{us:.1f} us = {100 * us / period_us:.2f} % of the {period_us:.0f} us period "
                 f"(fastest of {100 * repeat} runs of 1000)", "< 3 % and < 8 us"))
    for workers in sorted({1, os.cpu_count() or 1}):
        rate = max(batch_rate(workers=workers) for _ in range(repeat))
        rows.append((f"batched simulator, 10,000 as-flown vehicles on {workers} core{'s' if workers > 1 else ''}",
                     f"{rate / 1e6:.2f} M vehicle-steps/s (best of {repeat})", ">= 1.0 M"))
    timed = diagnose_seconds()
    if timed is None:
        rows.append(("`flightctl diagnose` of a real log", "not measured: ../shared/data/real/flights is not here",
                     "< 60 s for 30 s of log"))
    else:
        span, read, total = timed
        rows.append((f"`flightctl diagnose` of LOG00230.BFL ({span:.0f} s at 500 Hz, real)",
                     f"{total:.1f} s in all, {read:.1f} s of it reading the blackbox", "< 60 s for 30 s of log"))
    return rows


def markdown(rows: list[tuple[str, str, str]], date: str, where: str) -> str:
    """The README's speed block: when and where it was measured, then the table."""
    return "\n".join([STAMP.format(date=date, machine=where), "", *HEADER,
                      *(f"| {what} | {figure} | {target} |" for what, figure, target in rows)])


def main() -> None:
    import datetime
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeat", type=int, default=3, help="runs of each figure (default 3)")
    ap.add_argument("--markdown", action="store_true", help="print the README's block: the date, the machine, a table")
    args = ap.parse_args()
    if args.repeat < 1:
        ap.error("--repeat: at least 1")
    where = machine()
    rows = figures(args.repeat)
    if args.markdown:
        print(markdown(rows, datetime.date.today().isoformat(), where))
        return
    print(where)
    for what, figure, target in rows:
        print(f"{what}: {figure}" + (f", target {target}" if target != "-" else ""))


if __name__ == "__main__":
    main()
