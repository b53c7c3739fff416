"""Benchmark (figures, not a test): how many times faster than real time `flightctl sim paper` flies,
on the base model and on the as-flown one (`--params paper-as-flown`: its effects make the forces
state-dependent), and what one control-loop iteration costs, decode to PWM counts, against the
2222 us loop period.

    python scripts/benchmark.py [--repeat N] [--markdown]

`--markdown` prints the README's block (scripts/docs.py writes it there): the date and the machine,
then one row per figure. The figures are this machine's on that day: tests/project/test_docs.py checks the
block's form, never its numbers.

The iteration is timed on the onboard code only (the fastest of many short runs): `Mpu9250.read` decoding a 22-byte burst (from a
fixed frame, so the simulated chip's cost is not counted), the calibration, the motor-loss check, the
estimator, the four PIDs, the mixer and eq. 26 inverted to counts. Targets: >= 30x real time, < 3 % of the period.

The paper flight is measured with the simulated world compiled by numba (the default install) and,
in a child process with FLIGHTCTL_JIT=0, as plain Python (a platform without numba's wheels: one run).

The batched simulator (sim/sweeps/batch.py): vehicle-steps per second (one loop period of one vehicle,
flown as the full path flies it: the plant, its chip and sonar, the onboard loop and the controller's
compiled copy) for N = 10,000 vehicles of the as-flown model, each with its own draw of the file's
ranges, from power-on through the calibration on the floor and the take-off's first second (3 s, two
thirds of it on the floor, where a step costs about a quarter of an airborne one), on one core and on
every core. Target: 2,000,000 per core at N = 10,000. Beside it, the rate of what a Monte Carlo flies:
N = 2,000 vehicles for 12 s (10 s after arming, mostly in the air), on one core.

The first call: what a fresh process pays before its first flight, beside the warm figures above: numba
loading the compiled world from its cache (every later process), and compiling it afresh (the first
run after installing or changing the plant's code: an empty cache folder), for the plant (one flight)
and for the batch's loop, each in a child process (its wall time).

And how long `flightctl diagnose` takes on real flight logs (the `logs` extra), each read and diagnosed
whole in a child process on one core (its CPU time, and how much of it was reading the log): the
Betaflight flights of tests/data/pid-analyzer (129.5 s at 1 kHz, 38.8 s at 2 kHz) and of
../shared/data/real/flights (btfl_002, 134 s at 500 Hz; LOG00037, 17 s at 1 kHz; INDIflight's LOG00230,
26 s at 500 Hz); then how the cost grows with the log's length, 15, 60, 150 and 600 s of the 1 kHz
flight. Target: a 150 s log at 1 kHz in under 60 s on one core.
"""
from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from pathlib import Path

from flightctl.control.controller import FlightController
from flightctl.control.estimator import Calibration
from flightctl.control.motor_loss import MotorLossDetector
from flightctl.drivers.mpu9250 import Mpu9250
from flightctl.hal import ImuSample
from flightctl.params import load
from flightctl.sim.world.devices import SensorNoise, World
from flightctl.sim.world.imu import SimMpu9250
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
    detector = MotorLossDetector(params)
    detector.lifted()                      # in the air: the check looks
    watch, f = detector.update, ctl.mixer.f
    best = float("inf")
    for _ in range(batches):
        start = time.perf_counter()
        for _ in range(n):
            read(sample)
            correct(sample)
            watch(sample, f, dt)           # the motor-loss check, on the thrusts of the loop before
            step(sample, dt, 0.01, -0.02, 0.1, 1.5)
        best = min(best, time.perf_counter() - start)
    return best / n * 1e6


def spin_costs(n: int = 1000, batches: int = 50) -> tuple[float, float, float]:
    """The motor-loss mode's costs: (s of CPU to build the as-flown file's gain schedule with no cache,
    s to read it from the disk cache, us per loop of the controller on two rotors)."""
    from flightctl.control import spin_design
    from flightctl.control.spin import SpinController
    params = load("paper-as-flown")
    d = spin_design.design_inputs(params)
    with tempfile.TemporaryDirectory() as tmp:
        old = os.environ.get("FLIGHTCTL_CACHE")
        os.environ["FLIGHTCTL_CACHE"] = tmp
        try:
            spin_design._MEMORY.clear()
            start = time.process_time()
            spin_design.load(d)
            cold = time.process_time() - start
            spin_design._MEMORY.clear()
            start = time.perf_counter()
            spin = SpinController(params)
            warm = time.perf_counter() - start
        finally:
            if old is None:
                del os.environ["FLIGHTCTL_CACHE"]
            else:
                os.environ["FLIGHTCTL_CACHE"] = old
    sample = ImuSample()
    sample.gx, sample.gy, sample.gz, sample.az = 0.1, -0.2, 20.0, 9.0
    a = params.airframe
    spin.start(2, 0.05, -0.03, 0.0, [a.B] * 4)
    F, dt, step = a.M * a.g, a.dt, spin.step
    best = float("inf")
    for _ in range(batches):
        start = time.perf_counter()
        for _ in range(n):
            step(sample, dt, F)
        best = min(best, time.perf_counter() - start)
    return cold, warm, best / n * 1e6


def batch_rate(n: int = 10000, seconds: float = 1.0, workers: int = 1) -> tuple[float, float]:
    """(vehicle-steps per second of wall time, per second of CPU) of `sim.batch.simulate`: n as-flown
    vehicles, each with its own draw of the file's ranges and its own seed, flown as the full path flies
    them (the chip, the sonar, the controller's compiled copy) from power-on through the calibration's
    2 s on the floor and `seconds` of the take-off; the set-up of every vehicle included."""
    from flightctl.sim.sweeps.batch import simulate
    from flightctl.sim.sweeps.twin_loop import compiled_fly
    from flightctl.sim.sweeps.montecarlo import draw
    from flightctl.sim.flights.scenarios import SCENARIOS
    params = load("paper-as-flown")
    draws = draw(params, n, 0)
    plan = SCENARIOS["paper"]().plan
    compiled_fly()                    # compiled, or loaded from numba's cache, before the clock starts
    if workers > 1:                   # the engine's workers started (and their numba cache loaded) before it too:
        simulate(params, plan, 2 * workers, {k: v[:2 * workers] for k, v in draws.items()}, until=0.01,
                 workers=workers)     # a command pays that once (the "first call" rows), not per batch
    start, cpu = time.perf_counter(), time.process_time()
    flight = simulate(params, plan, n, draws, until=seconds, workers=workers)
    wall, cpu = time.perf_counter() - start, time.process_time() - cpu
    return flight.vehicle_steps / wall, flight.vehicle_steps / cpu


def _child_s(code: str, env: dict[str, str] | None = None) -> tuple[float, ...]:
    """The numbers of the last line a child process prints: figures measured in a fresh interpreter."""
    import subprocess
    import sys
    r = subprocess.run([sys.executable, "-c", code], env={**os.environ, **(env or {})}, check=True,
                       stdout=subprocess.PIPE, text=True)
    return tuple(float(x) for x in r.stdout.strip().splitlines()[-1].split())


PAPER_RATIO = """
import tempfile, time
from pathlib import Path
from flightctl.params import load
from flightctl.sim.flights.run import fly
from flightctl.sim.flights.scenarios import SCENARIOS
start = time.perf_counter()
flight = fly(SCENARIOS["paper"](), load(None), Path(tempfile.mkdtemp()) / "paper.csv")
print(flight.log["t"][-1] / (time.perf_counter() - start))
"""


def plain_ratio() -> float:
    """Times faster than real time of `flightctl sim paper` (full onboard path, base model) with the
    world in plain Python (FLIGHTCTL_JIT=0), in a child process: one run."""
    return _child_s(PAPER_RATIO, {"FLIGHTCTL_JIT": "0"})[0]


FIRST_CALL = {   # what: (set-up, not timed; the timed first call)
    "plant": ("from flightctl.sim.world import compiled, imu", "compiled.functions()\nimu.chip_frame_compiled()"),
    "batch": ("from flightctl.params import load\nfrom flightctl.sim.flights.scenarios import SCENARIOS\n"
              "from flightctl.sim.sweeps.batch import simulate\nfrom flightctl.sim.sweeps.montecarlo import draw\n"
              "from flightctl.sim.world import compiled, imu\ncompiled.functions()\nimu.chip_frame_compiled()\n"
              "p = load('paper-as-flown')",
              "simulate(p, SCENARIOS['paper']().plan, 1, draw(p, 1, 0), until=0.01)"),
}


def first_call_s(what: str, fresh: bool) -> tuple[float, float]:
    """(wall s, CPU s) a fresh process spends making `what` ready (plant: the world's functions and the
    chip's registers; batch: the batch's loop, the plant already made) from numba's cache, or compiled
    into an empty cache folder (`fresh`). The imports are not counted; the CPU time is the one a busy
    machine does not inflate."""
    setup, timed = FIRST_CALL[what]
    code = (f"{setup}\nimport time\nstart, cpu = time.perf_counter(), time.process_time()\n{timed}\n"
            "print(time.perf_counter() - start, time.process_time() - cpu)\n")
    if not fresh:
        return _child_s(code)
    with tempfile.TemporaryDirectory(prefix="flightctl-numba-") as cache:
        return _child_s(code, {"NUMBA_CACHE_DIR": cache})


def split_us(name: str | None) -> tuple[float, float]:
    """Per loop period of `sim paper` (full onboard path): (us in the simulated world: the plant, the
    chip's SPI answers, the sonar's edges, the battery; us in the onboard loop and the log). The second
    bounds the simulator's speed whatever the plant costs: at most period / it times real time."""
    from flightctl.sim.world import devices, imu
    spent = [0.0]

    def timed(cls, name):
        inner = getattr(cls, name)

        def wrapper(*a):
            t = time.perf_counter()
            r = inner(*a)
            spent[0] += time.perf_counter() - t
            return r
        return inner, wrapper
    patches = [(cls, attr, *timed(cls, attr)) for cls, attr in ((devices.World, "advance"), (imu.SimMpu9250, "xfer2"))]
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


ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT / ".." / "shared" / "data" / "real" / "flights"
# Real logs, read and diagnosed whole: (path, its rate in words). The 1 and 2 kHz Betaflight flights of
# tests/data/pid-analyzer (a 2.5-inch quad: no public five-inch flight of two minutes at 1 kHz was found,
# its README says where we looked) and the shared data's.
DIAGNOSED = ((ROOT / "tests" / "data" / "pid-analyzer" / "better_tune.BBL", "1 kHz"),
             (ROOT / "tests" / "data" / "pid-analyzer" / "example_smooth_tune.BBL", "2 kHz"),
             (SHARED / "betaflight" / "btfl_002.bbl", "500 Hz"), (SHARED / "betaflight" / "LOG00037.BFL", "1 kHz"),
             (SHARED / "indiflight" / "LOG00230.BFL", "500 Hz"))
GROWTH_LOG = DIAGNOSED[0][0]
GROWTH_S = (15.0, 60.0, 150.0, 600.0)
# The growth table's parts end at this second of the flight: 15 s windows ending at 40, 50, 70 or 95 s
# move roll or pitch too little for diagnose to identify the vehicle (it refuses them), the one to 110 s
# does (tried on 2026-11-28); each longer part holds it.
GROWTH_END_AT_S = 110.0
TARGET = "< 60 s for 150 s at 1 kHz"


def _cpu(args: list[str], codes: tuple[int, ...] = (0,)) -> float:
    """CPU seconds (user + system) of a child Python process running `args` (its start-up included);
    the child starts no BLAS thread (`flightctl diagnose` sets one at its entry; the environment here
    says so for the reading alone too)."""
    import resource
    import subprocess
    import sys
    from flightctl.blas import ONE_THREAD
    env = {**os.environ, **ONE_THREAD}
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    code = subprocess.run([sys.executable, *args], env=env, stdout=subprocess.DEVNULL).returncode
    if code not in codes:
        raise SystemExit(f"benchmark: {' '.join(args[:4])} ... exited {code}")
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def diagnose_cost(logs: list[Path]) -> tuple[float, float]:
    """(CPU seconds to read the logs as diagnose reads them, CPU seconds to read and diagnose them
    jointly) in child processes on one core."""
    out = Path(tempfile.mkdtemp()) / "report.json"
    names = [str(p) for p in logs]
    read = _cpu(["-c", "import sys; from flightctl.sim.diagnose.cli import read_logs; "
                       "read_logs(sys.argv[1:], None, lambda *a: None)", *names])
    total = _cpu(["-m", "flightctl.cli", "diagnose", *names, "--json", str(out), "--quiet"])
    return read, total


def growth_logs(entry, seconds: float, folder: Path) -> tuple[list[Path], float]:
    """(`seconds` of a log's flight (`flightctl.sim.logs.LogEntry`) as flight-log CSVs, `flightctl log
    import`'s, and the flight's length): the `seconds` that end at GROWTH_END_AT_S of it, or, longer
    than the flight, the whole flight as often as it fits and then such a part: several flights of one
    vehicle, diagnosed jointly."""
    import numpy as np
    lines = entry.text.splitlines(keepends=True)
    head = next(i for i, line in enumerate(lines) if not line.startswith("#")) + 1
    t = entry.table["t"]
    span = float(t[-1] - t[0])
    whole, part = divmod(seconds, span)
    paths = [folder / f"flight{k + 1}.csv" for k in range(int(whole))]
    for path in paths:
        path.write_text("".join(lines))
    if part > 0:
        end = t[0] + GROWTH_END_AT_S
        i0, i1 = np.searchsorted(t, [max(t[0], end - part), end])
        paths.append(folder / "part.csv")
        paths[-1].write_text("".join(lines[:head] + lines[head + int(i0):head + int(i1)]))
    return paths, span


def diagnose_rows() -> list[tuple[str, str, str]]:
    """The rows of `flightctl diagnose`: each real log of DIAGNOSED read and diagnosed whole, then the
    growth of the cost with the log's length (GROWTH_S, from GROWTH_LOG's flight as CSVs)."""
    from flightctl.sim.logs import read_foreign
    rows = []
    for log, rate in DIAGNOSED:
        if not log.exists():
            rows.append((f"`flightctl diagnose` of {log.name}", f"not measured: {log.parent} is not here", "-"))
            continue
        read, total = diagnose_cost([log])
        span = sum(float(t["t"][-1] - t["t"][0]) for t in read_foreign(str(log)))
        rows.append((f"`flightctl diagnose` of {log.name} ({span:.0f} s at {rate}, real, whole)",
                     f"{total:.1f} s of CPU on one core, {read:.1f} s of it reading the log: {total / span:.2f} s per "
                     "second of log", TARGET if rate == "1 kHz" and span > 100 else "-"))
    if not GROWTH_LOG.exists():
        return rows
    from flightctl.sim.logs import each_log
    (entry,) = each_log(str(GROWTH_LOG))
    for seconds in GROWTH_S:
        logs, span = growth_logs(entry, seconds, Path(tempfile.mkdtemp()))
        read, total = diagnose_cost(logs)
        whole, part = divmod(seconds, span)
        times = {1: "once", 2: "twice"}.get(int(whole), f"{whole:.0f} times")
        how = (f"{len(logs)} files: the whole {span:.1f} s flight {times}, then " if whole else "") + \
            (f"the {part:.1f} s up to its {GROWTH_END_AT_S:g}th second" if part else "")
        rows.append((f"growth with the log's length: `flightctl diagnose` of {seconds:.0f} s of {GROWTH_LOG.name}'s 1 kHz "
                     f"flight ({how}, as CSV)",
                     f"{total:.1f} s of CPU on one core, {read:.1f} s of it reading: {total / seconds:.2f} s per second "
                     "of log", TARGET if seconds == 150.0 else "-"))
    return rows


def from_log_row() -> tuple[str, str, str]:
    """`flightctl tune --from-log` of a real 2-minute log (issue 43: to recommended gains in under two minutes on
    two cores): its CPU on one core (start-up, reading, the base model on the first half, the check on the second,
    the drawn models and the search) and its wall time."""
    log = DIAGNOSED[0][0]
    if not log.exists():
        return ("`flightctl tune --from-log` of a 2-minute log", f"not measured: {log} is not here", "-")
    from flightctl.sim.logs import read_foreign
    span = sum(float(t["t"][-1] - t["t"][0]) for t in read_foreign(str(log)))
    out = Path(tempfile.mkdtemp())
    start = time.perf_counter()
    cpu = _cpu(["-m", "flightctl.cli", "tune", "--from-log", str(log), "--json", str(out / "r.json"),
                "--out", str(out / "lines.txt")], codes=(0, 1))      # 1: every axis refused, the report written
    wall = time.perf_counter() - start
    return (f"`flightctl tune --from-log` of {log.name} ({span:.0f} s at 1 kHz, real): the model on its first half, "
            "the check on the rest, 48 drawn models an axis and the search", f"{cpu:.1f} s of CPU on one core, "
            f"{wall:.1f} s wall", "< 120 s on two cores")


def fleet_rate(workers: int, logs: int = 6) -> float:
    """Logs per hour of `flightctl diagnose --corpus` on `workers` of the engine's local workers
    (sim/engine.py, Dask; in this process without it): `logs` simulated 21 s flights (the tests' quick
    plan, tests/helpers/diagnose_cases.py, each its own seed), diagnosed end to end, the engine's start
    and each worker's imports included (docs/fleet.md)."""
    import contextlib
    import io
    import sys
    from flightctl.cli import main as cli
    from flightctl.sim import engine
    from flightctl.sim.diagnose.corpus import corpus
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    from helpers.diagnose_cases import quick_plan
    tmp = Path(tempfile.mkdtemp())
    folder = tmp / "logs"
    folder.mkdir()
    plan = quick_plan(tmp)
    with contextlib.redirect_stdout(io.StringIO()):
        for k in range(logs):
            cli(["sim", "--plan", str(plan), "--log", str(folder / f"flight{k:02d}.csv"), "--seed", str(k),
                 "--no-plot", "--quiet"])
    engine.use(None, quiet=True)
    engine.close()
    start = time.perf_counter()
    rows = corpus(folder, workers, results=tmp / f"r{workers}.jsonl")
    wall = time.perf_counter() - start
    engine.close()
    assert len(rows) == logs
    return logs / wall * 3600.0


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
    from flightctl.sim.world import compiled
    if compiled.enabled():
        rows.append(("`flightctl sim paper`, full onboard path, the world in plain Python (FLIGHTCTL_JIT=0: "
                     "no numba)", f"{plain_ratio():.1f}x real time (one run)", "- (the fallback)"))
        for what, label in (("plant", "the simulated world (a flight's first call)"),
                            ("batch", "the batched simulator's loop (a batch's first call)")):
            (cached, cached_cpu), (fresh, fresh_cpu) = first_call_s(what, False), first_call_s(what, True)
            rows.append((f"first call: {label}", f"{cached:.1f} s loading numba's cache ({cached_cpu:.1f} s of CPU), "
                         f"{fresh:.0f} s compiling afresh into an empty cache ({fresh_cpu:.0f} s of CPU)", "-"))
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
    cold, warm, us_spin = spin_costs()
    rows.append(("the motor-loss gain schedule (as-flown, judged over its Jp, motor time constant and delay ranges)",
                 f"{cold:.1f} s of CPU to build, {1e3 * warm:.0f} ms to read back from the disk cache", "-"))
    rows.append(("one loop of the two-rotor controller (after a lost motor)", f"{us_spin:.1f} us", "-"))
    one_core = None
    for workers in sorted({1, os.cpu_count() or 1}):
        rates = [batch_rate(workers=workers) for _ in range(repeat)]
        rate, cpu = max(r[0] for r in rates), max(r[1] for r in rates)
        one_core = one_core or rate
        rows.append((f"batched simulator, 10,000 as-flown vehicles on {workers} core{'s' if workers > 1 else ''}, each "
                     "flown as the full path flies it (the chip, the sonar, the calibration, the take-off)"
                     + ("; the engine's workers started before the clock" if workers > 1 else ""),
                     f"{rate / 1e6:.2f} M vehicle-steps/s (best of {repeat}; {rate / workers / 1e6:.2f} M per core"
                     + (f", {cpu / 1e6:.2f} M per s of this process's CPU)" if workers == 1 else
                        f", {rate / one_core:.2f}x one core)"),
                     ">= 2.0 M per core" + (f"; >= {0.9 * workers:.1f}x one core" if workers > 1 else "")))
    airborne = max(batch_rate(n=2000, seconds=10.0)[0] for _ in range(repeat))
    rows.append(("batched simulator, 2,000 as-flown vehicles for 12 s on 1 core (10 s after arming: mostly in the "
                 "air, as a Monte Carlo flies)", f"{airborne / 1e6:.2f} M vehicle-steps/s (best of {repeat})", "-"))
    rows += diagnose_rows()            # before the engine's workers: their CPU is reaped into this process's children
    rows.append(from_log_row())
    from flightctl.sim import engine
    what = ("`flightctl diagnose --corpus` of 6 simulated 21 s flights (sim/engine.py: Dask's local workers, "
            "start-up included)")
    if engine.available():
        rates = {w: fleet_rate(w) for w in (1, 2)}
        rows.append((what, f"{rates[1]:.0f} logs/h on 1 worker, {rates[2]:.0f} on 2 ({rates[2] / rates[1]:.2f}x)", "-"))
    else:
        rows.append((what, "not measured: the fleet extra (Dask) is not installed", "-"))
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
