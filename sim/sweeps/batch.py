"""N vehicles at once, each flown as `flightctl sim` flies it: from power-on, the calibration on the floor,
arming, the take-off, the plan, the landing, through the compiled per-vehicle loop of
sim/sweeps/twin_loop.py (the plant of sim/world/compiled.py, the chip of sim/world/imu.py, the sonar and
the power monitor's draws, the onboard loop's rules, and the onboard controller's compiled copy,
sim/sweeps/twin_controller.py). For Monte Carlo over the model's ranges and for robust tuning.

A vehicle here is the vehicle the full onboard path flies with the same draw and seed: the same
airframe and effects (the draws), the same chip die and the same random numbers (`_Vehicles`: its
`World.rng` and `NoisePool` streams reproduced), so that its flight is the full path's to rounding
(tests/sim/sweeps/test_batch.py). This module sets the vehicles up and runs `flight.fly` over them, period chunk
by period chunk (a few hundred vehicles at a time, so that their arrays stay small), and judges each
flight as sim/flights/run.py's `judge` does (flightctl/safety.py's crash rules).
"""
from __future__ import annotations

import dataclasses
import functools
import gc
import math
import random
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from flightctl.params import Gains, Params
from flightctl.sim import engine
from flightctl.plans.plan import Plan
from flightctl.sim.sweeps import twin_loop as fl
from flightctl.sim.sweeps import twin_world as tw
from flightctl.sim.sweeps import twin_controller as ob
from flightctl.sim.world.board import SIM_CALIBRATE_S

GROUP = 256          # vehicles whose arrays are set up and flown together
TASKS = 4            # the engine's tasks per worker (each several groups): few, so that the scheduler's round
                     # trips and the jobs' pickling are few, enough that a worker slow to start is evened out
CHUNK = 225          # loop periods flown per call of the compiled loop (the uniforms refilled between)
SPARE = 8            # chunks' worth of uniforms each vehicle holds (refilled when less than one is left)
WIDE = ("P1", "P2", "P3", "P4", "acc_x", "acc_y", "acc_z", "gyro_x", "gyro_y", "gyro_z", "alt")  # tw.N_WIDE's
LAND_MARGIN_S = 45.0   # s past the plan's end a loop's own landing may take (its ramp and slack)


@dataclass
class BatchFlight:
    """The outcome of `simulate`, per vehicle: `outcome` as sim/flights/run.py names it, `crashed`,
    `flew` (left the ground), `flies` (flew, no crash, landed upright), and the judged record `log`
    (t since arming; true_roll, true_pitch, true_yaw, roll, pitch, yaw as (rows, N) columns) over
    `record`; `vehicle_steps` the loop periods flown."""
    outcome: list
    crashed: np.ndarray
    flew: np.ndarray
    log: dict
    vehicle_steps: int
    seconds: np.ndarray       # s of the loop per vehicle, from power-on to its end

    @property
    def flies(self) -> np.ndarray:
        return np.array([o == "landed upright" for o in self.outcome]) & self.flew & ~self.crashed


@functools.cache
def _template(params: Params) -> dict:
    """What every vehicle's set-up takes from one board built as `flightctl sim` builds it
    (sim/world/board.py `sim_board`): the driver's scales and limits, the chip's registered constants,
    the draws of `World.rng` the power monitor takes at its start and per read (counted on the real
    objects: their number, not their values, matters here)."""
    from flightctl.sim.world.board import sim_board
    from flightctl.sim.world.imu import chip_die
    hal, world = sim_board(params, seed=0)
    imu = hal.imu

    def gauss_calls(before: random.Random, after: random.Random) -> int:
        for k in range(64):
            if before.getstate() == after.getstate():
                return k
            before.gauss(0.0, 1.0)
        raise RuntimeError("the power monitor draws from World.rng in a way the batch does not follow")
    r = random.Random(0)
    r.randrange(1 << 32)
    chip_die(world.noise, world.a, r)
    hal.power.read()                                   # the loop's first read, before its first period
    start = gauss_calls(r, world.rng)
    hal.power.read()
    per_read = gauss_calls(r, world.rng)
    if world.normal._i != 0:
        raise RuntimeError("the board's set-up drew from the chip's noise: the batch does not follow")
    from flightctl.sim.world.imu import _C_A_DELAY, _C_A_LSB, _C_G_DELAY, _C_G_LSB, _C_PERIOD, _C_SA, _C_SG, _C_TC2, _C_TCG2
    registered = [_C_A_LSB, _C_G_LSB, _C_SA, _C_SG, _C_TC2, _C_PERIOD, _C_A_DELAY, _C_TCG2, _C_G_DELAY]
    chip = imu.spi
    return {"start_draws": start, "per_read": per_read, "a": imu._a, "g": imu._g, "jump": np.array(imu._jump, float),
            "temp": imu._temp_lsb, "registered": registered, "values": np.asarray(chip._c, float)[registered],
            "frozen": imu.frozen_frames}


def _world_constants(params: Params, plan: Plan, template: dict, dt: float) -> np.ndarray:
    from flightctl.sim.world.devices import SensorNoise
    noise, a = SensorNoise(), params.airframe
    k = np.zeros(tw.N_WORLD)
    k[tw.G_], k[tw.M_] = a.g, a.M
    k[tw.SONAR_SIGMA], k[tw.DROPOUT], k[tw.MAG_SIGMA] = noise.sonar_sigma_us, noise.sonar_dropout, noise.mag_sigma
    k[tw.A_SCALE], k[tw.G_SCALE] = template["a"], template["g"]
    k[tw.WARM_RISE], k[tw.WARM_TAU] = noise.warmup_rise, noise.warmup_tau
    k[tw.LANDS], k[tw.DURATION], k[tw.INA_DRAWS] = float(plan.lands()), plan.duration, template["per_read"]
    k[tw.DT], k[tw.T_ARM] = dt, SIM_CALIBRATE_S
    k[tw.TEMP_LO], k[tw.TEMP_HI] = template["temp"]
    k[tw.POWER_EVERY], k[tw.SONAR_EVERY] = max(1, round(a.loop_hz / 10.0)), max(1, round(a.loop_hz / a.sonar_hz))
    return k


class _Vehicles:
    """The arrays of `flight.fly` for vehicles with their parameters, draws and seeds, at power-on."""

    def __init__(self, params: Params, draws: dict, gains, seeds, template: dict, structure: str, most: int):
        from flightctl.sim.sweeps.montecarlo import drawn_airframe, drawn_params
        from flightctl.sim.world import compiled
        from flightctl.sim.world.devices import SensorNoise, vehicle_noise
        from flightctl.sim.world.imu import N_CHIP_CONST, N_CHIP_STATE, chip_die, vibration_constants
        from flightctl.sim.world.model import Model
        n = len(seeds)
        self.n = n
        a = params.airframe
        model = Model(drawn_airframe(a, draws), with_draws(params, draws))
        laid = compiled.layout_rows(model, n)
        if laid is None:
            raise ValueError("the batched simulator flies the plants sim/world/compiled.py carries "
                             f"({', '.join(compiled.COMPILED_CAUSES)})")
        self.codes, self.q = laid[0], np.ascontiguousarray(laid[1])
        periods = np.broadcast_to(np.asarray(model.delay, dtype=float), (n,)) / a.dt
        whole = (periods + 1e-9).astype(np.int64)
        self.frac = np.where(periods - whole > 1e-9, periods - whole, 0.0)
        self.nring = whole + 2
        self.ring = np.zeros((n, int(self.nring.max()), 4))
        x0 = Model(a, with_draws(params, {})).initial_state((0.0, 0.0, 0.0, 0.0, a.battery_nominal_v))
        self.x = np.tile(np.asarray(x0, dtype=float), (n, 1))
        self.w = np.zeros((n, tw.N_W))
        self.w[:, tw.W_GROUND] = 1.0
        self.w[:, [tw.W_T_STOP, tw.W_RISE, tw.W_T_TOUCH]] = -1.0
        self.w[:, [tw.W_RISE_T, tw.W_FALL_T]] = np.inf
        self.w[:, tw.W_Z_MAX] = -np.inf
        self.w[:, tw.W_UAPP:tw.W_UAPP + 4] = np.nan       # no command applied yet
        self.w[:, tw.W_LIFT_AT:tw.W_LIFT_AT + 4] = np.nan
        self.e = np.zeros((n, ob.N_E))
        self.e[:, ob.ALT_T] = -1.0
        self.kc = np.zeros((n, ob.N_K))
        self.words = np.zeros((n, 7))             # each chip's burst, as the driver decodes it (`flight.put_word`)
        self.cs, self.cc = np.zeros((n, N_CHIP_STATE)), np.zeros((n, N_CHIP_CONST))
        self.normal = fl.chip_generators(seeds)     # each chip's `NoisePool`
        self.rng = []             # each vehicle's `World.rng`, whose `random()`s the loop takes from uni
        self.most = most          # the most uniforms a vehicle takes in a chunk
        # the vehicles' parameters at once, each drawn value an (n,) array (elementwise arithmetic, as a
        # float's): the controllers' constants and the chips' vibration, a column each
        p = drawn_params(params, draws, effects=False)
        if gains is not None:
            p = dataclasses.replace(p, gains=Gains(**{f.name: np.array([getattr(g, f.name) for g in gains])
                                                      for f in dataclasses.fields(Gains)}))
        for j, value in enumerate(ob.constants(p, structure)):
            self.kc[:, j] = value
        noise = SensorNoise()
        dies, kept, raw, spare = [], np.full(n, np.nan), [], SPARE * most
        for v, seed in enumerate(seeds):
            r = random.Random(seed)                 # `World.rng`: the sonar's tick, the chip's die, the power monitor
            r.randrange(1 << 32)
            dies.append(chip_die(noise, a, r))      # (its draws take nothing of the vehicle's values)
            for _ in range(template["start_draws"]):
                r.gauss(0.0, 1.0)
            if r.gauss_next is not None:            # `random.gauss`'s second number, kept for its next call
                kept[v] = r.gauss_next
            self.rng.append(r)
            raw.append(random_bits(r, spare))
        self.uni = uniforms_of(b"".join(raw), n, spare)
        self.cs[:], self.cc[:] = [d[0] for d in dies], [d[1] for d in dies]
        has = ~np.isnan(kept)                      # the vehicles whose gauss kept a second number
        self.w[has, tw.W_GAUSS], self.w[has, tw.W_HAS_GAUSS] = kept[has], 1.0
        vibration_constants(self.cc.T, vehicle_noise(noise, p.sensors), p.airframe)
        self.cc[:, template["registered"]] = template["values"]

    def refill(self) -> None:
        """For each vehicle with less than a chunk's uniforms left, those it used drawn anew behind the
        ones left."""
        used = self.w[:, tw.W_U].astype(np.int64)
        m = self.uni.shape[1]
        if used.max() > m:
            raise RuntimeError("a vehicle drew more random numbers than the batch holds for it")
        for v in np.nonzero(m - used < self.most)[0]:
            u = used[v]
            self.uni[v, :m - u] = self.uni[v, u:].copy()
            self.uni[v, m - u:] = uniforms(self.rng[v], u)
            self.w[v, tw.W_U] = 0.0


def uniforms(r: random.Random, k: int) -> np.ndarray:
    """The next k numbers of `r.random()`, at once (`uniforms_of`); r's state moves on as k calls of
    `random()` move it (tests/sim/sweeps/test_batch.py)."""
    return uniforms_of(random_bits(r, k), 1, k)[0]


def random_bits(r: random.Random, k: int) -> bytes:
    """The Mersenne Twister's next 2 k 32-bit outputs, in order, as little-endian bytes: `getrandbits(64 k)`
    holds them from its lowest 32 bits up."""
    return r.getrandbits(64 * k).to_bytes(8 * k, "little")


def uniforms_of(raw: bytes, n: int, k: int) -> np.ndarray:
    """(n, k) numbers of `random()` from n generators' `random_bits(r, k)` one after another: CPython's
    `random()` takes two 32-bit outputs a, b and returns ((a >> 5) 2^26 + (b >> 6)) / 2^53 (each step
    exact in doubles); all of the vehicles' at once, in one pass of numpy's."""
    words = np.frombuffer(raw, dtype="<u4").reshape(n, 2 * k)
    return ((words[:, 0::2] >> 5) * 67108864.0 + (words[:, 1::2] >> 6)) * (1.0 / 9007199254740992.0)


def _judge(w: np.ndarray, g: float) -> tuple[str, bool, bool]:
    """sim/flights/run.py's `judge` on the loop's figures: (outcome, crashed, flew)."""
    from flightctl.sim.flights.run import judge_figures
    if w[tw.W_ROWS] == 0:
        return "never armed", False, False
    stopped = f"tilt past {math.degrees(fl.CRASH_TILT):.0f} degrees" if w[tw.W_REASON] == tw.CRASH else None
    return judge_figures(float(w[tw.W_Z_END]), float(w[tw.W_Z_MAX]), float(w[tw.W_TILT]), float(w[tw.W_TOUCHDOWN]),
                         stopped, g)


def _fly_group(job) -> tuple:
    """One group of vehicles flown to their ends (or to `until`, s of plan), without the cyclic garbage
    collector: the set-up makes thousands of short-lived objects, and each of the collector's passes
    it sets off walks numba's and numpy's long-lived ones, for nothing (nothing here makes a cycle)."""
    collecting = gc.isenabled()
    gc.disable()
    try:
        return _fly_group_now(job)
    finally:
        if collecting:
            gc.enable()


def _fly_groups(jobs: list) -> list:
    """`_fly_group` of each job in turn: one of the engine's tasks."""
    return [_fly_group(job) for job in jobs]


def _arm_and_record(dt: float, record: tuple[float, float] | None) -> tuple[int, int]:
    """(the loop period that arms, after the calibration's SIM_CALIBRATE_S on the floor; the first
    period of the judged record over `record`, s since arming, 0 without one)."""
    i_arm = next(i for i in range(1, 10 ** 7) if i * dt >= SIM_CALIBRATE_S)
    return i_arm, (i_arm + int(round(record[0] / dt)) if record else 0)


def _fly_group_now(job) -> tuple:
    params, plan, draws, gains, seeds, record, until, structure, wide = job
    a = params.airframe
    dt = a.dt
    template = _template(params)
    k = _world_constants(params, plan, template, dt)
    i_arm, rec0 = _arm_and_record(dt, record)
    end_s = plan.duration + LAND_MARGIN_S if until is None else until
    i_end = i_arm + int(math.ceil(end_s / dt)) + 1
    # the most uniforms a vehicle takes in a chunk: the sonar's dropout and jitter at each trigger (a
    # gauss takes two), the power monitor's gausses at each read
    most = 3 * -(-CHUNK // int(k[tw.SONAR_EVERY])) + 2 * template["per_read"] * -(-CHUNK // int(k[tw.POWER_EVERY])) + 2
    veh = _Vehicles(params, draws, gains, seeds, template, structure, most)
    plan.restart()
    sp = np.zeros((i_end + 1, 4))
    for i in range(i_arm + 1, i_end + 1):
        t = i * dt - SIM_CALIBRATE_S
        sp[i] = plan.at(t) if t <= plan.duration else plan.at(plan.duration)
    rows = int(round((record[1] - record[0]) / dt)) + 1 if record else 0
    rec = np.full((veh.n, rows, tw.N_WIDE if wide else tw.N_REC), np.nan)
    run = fl.compiled_fly() or fl.fly
    i0 = 0
    while i0 < i_end and not veh.w[:, tw.W_DONE].all():
        n = min(CHUNK, i_end - i0)
        run(veh.x, veh.w, veh.e, veh.kc, veh.q, veh.codes, veh.ring, veh.nring, veh.frac, veh.words, veh.cs, veh.cc,
            veh.normal, veh.uni, np.ascontiguousarray(sp[i0 + 1:i0 + 1 + n]), rec, k, template["jump"],
            i0, n, i_arm, rec0)
        veh.refill()
        i0 += n
    seconds = np.where(veh.w[:, tw.W_DONE] != 0.0, veh.w[:, tw.W_ROWS] * dt + i_arm * dt, i0 * dt)
    judged = [_judge(w, a.g) if w[tw.W_DONE] != 0.0 else ("in the air", False, True) for w in veh.w]
    steps = int(np.sum(np.minimum(seconds / dt, i0)))
    return judged, rec, steps, seconds


def with_draws(params: Params, draws: dict[tuple[str, str], np.ndarray] | None = None):
    """The parameter file's effects with some parameters drawn per vehicle: draws maps (cause,
    parameter) to an (N,) array, which the effect then holds in place of its value."""
    from flightctl.sim import causes
    from flightctl.sim.sweeps.montecarlo import AIRFRAME, TABLES
    effects = causes.combined(params, ())
    for (cause, name), values in (draws or {}).items():
        if cause == AIRFRAME or cause in TABLES:   # the airframe (`drawn_airframe`), the controller's and sensors' tables
            continue
        effect = next((e for e in effects if e.cause == cause), None)
        if effect is None or name not in effect.parameters:
            raise ValueError(f"no parameter {cause}.{name} in the parameter file's effects")
        effect.parameters[name] = np.asarray(values, dtype=float)
    return effects


def simulate(params: Params, plan: Plan, n: int, draws: dict[tuple[str, str], np.ndarray] | None = None,
             gains: Sequence[Gains] | None = None, seeds: Sequence[int] | None = None,
             record: tuple[float, float] | None = None, workers: int = 1, until: float | None = None,
             structure: str = "flight", progress: Callable[[float], None] | None = None,
             wide: bool = False) -> BatchFlight:
    """Fly `plan` with n vehicles from power-on, each with its own draws of the parameters ((N,)
    arrays), its own gains (None: the file's) and its own seed (None: 0 .. n-1; the seed of
    `flightctl sim --seed`), to its end (or to `until` s after arming). `record`: the span (s since
    arming) of the judged record. `workers` processes share the vehicles (sim/engine.py: Ctrl-C ends
    them at once). `progress(fraction)`: the share of the vehicles flown, as each group of them lands.
    `wide`: the record holds a log's columns too (WIDE; NaN where the vehicle's loop had ended)."""
    draws = {key: np.broadcast_to(np.asarray(v, dtype=float), (n,)) for key, v in (draws or {}).items()}
    seeds = list(range(n)) if seeds is None else [int(s) for s in seeds]
    if gains is not None and len(gains) != n:
        raise ValueError(f"{len(gains)} gain sets for {n} vehicles")
    if len(seeds) != n:
        raise ValueError(f"{len(seeds)} seeds for {n} vehicles")
    groups = max(1, min(n, max(workers, math.ceil(n / GROUP))))
    cuts = np.linspace(0, n, groups + 1).astype(int)
    jobs = [(params, plan, {key: v[a:b] for key, v in draws.items()}, None if gains is None else list(gains[a:b]),
             seeds[a:b], record, until, structure, wide) for a, b in zip(cuts[:-1], cuts[1:])]
    flown = [0]
    if workers <= 1 or len(jobs) == 1:
        parts = []
        for job in jobs:
            parts.append(_fly_group(job))
            flown[0] += len(job[4])
            if progress is not None:
                progress(flown[0] / n)
    else:
        cut = np.linspace(0, len(jobs), min(len(jobs), workers * TASKS) + 1).astype(int)
        tasks = [jobs[a:b] for a, b in zip(cut[:-1], cut[1:])]

        def done(k: int, part) -> None:
            flown[0] += sum(len(job[4]) for job in tasks[k])
            if progress is not None:
                progress(flown[0] / n)
        parts = [part for task in engine.run(_fly_groups, tasks, workers, done) for part in task]
    judged = [j for part in parts for j in part[0]]
    rec = np.concatenate([part[1] for part in parts], axis=0)
    dt = params.airframe.dt
    _, rec0 = _arm_and_record(dt, record)
    t = (rec0 + np.arange(rec.shape[1])) * dt - SIM_CALIBRATE_S if record else np.zeros(0)
    names = ("true_roll", "true_pitch", "true_yaw", "roll", "pitch", "yaw") + (WIDE if wide else ())
    log = {"t": t, **{name: np.ascontiguousarray(rec[:, :, j].T) for j, name in enumerate(names)}}
    return BatchFlight([j[0] for j in judged], np.array([j[1] for j in judged]), np.array([j[2] for j in judged]),
                       log, sum(part[2] for part in parts), np.concatenate([part[3] for part in parts]))
