"""N vehicles at once: the model of sim/world/model.py integrated on arrays, flown by a vectorised copy of
the onboard controller (estimator, the four PIDs of eq. 24, the mixer of eq. 25, eq. 26 inverted to
PWM counts). For Monte Carlo over the model's ranges and for robust tuning: thousands of vehicles
per second of wall time where the full onboard path flies one.

- The plant is `Model(..., vector=True)`: the same `f` and the same effects' hooks as the single
  simulator (one copy of each equation), each state an array over the vehicles. An effect's
  parameter may be an array too (one value per vehicle): the hooks are plain arithmetic.
- `BatchController` is a copy of `flightctl.control.controller.FlightController.step` and
  `on_range` (with `AttitudeEstimator`, `Pid`, `Mixer`) in numpy, because the onboard code stays
  plain Python on floats. tests/test_batch.py holds it to the onboard code step for step: the same
  IMU samples, echoes and setpoints give the same PWM counts, within one count of rounding.
  What it leaves out: the magnetometer (yaw from the gyro alone), the landing and the vertical
  estimate that stands in for a lost echo (a lost echo holds the last altitude).
- The actuation delay (one per vehicle) is realised as the single plant realises it.
- The sensors are ideal: the IMU reads the true body rates and specific force, the sonar the true
  range along -z_b at `sonar_hz`. No floor: the vehicles start hovering; one that tilts past
  CRASH_TILT or sinks below the floor is frozen there and counted as crashed (flightctl/safety.py).
"""
from __future__ import annotations

import dataclasses
import math
from concurrent.futures import wait
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from flightctl.control.estimator import ESTIMATORS
from flightctl.control.mixer import MIN_TILT_COSINE, SCALE
from flightctl.params import Airframe, Gains, Params
from flightctl.plans.plan import Plan
from flightctl.safety import CRASH_TILT
from flightctl.drivers.hcsr04 import US_PER_M
from flightctl.sim.world.board import SIM_CALIBRATE_S
from flightctl.sim.world.model import N_RIGID, PHI, THETA, Z, Effect, Model, P, Q, R
from flightctl.sim.world.plant import delayed

TWO_PI = 2.0 * math.pi
TICK_STEPS = 45                 # loop periods between progress counts (0.1 s of flight)
GAINS = ("z", "phi", "theta", "psi")


def _column(values) -> np.ndarray:
    return np.asarray(values, dtype=float)


class BatchController:
    """`FlightController` for N vehicles: one `Params` for all, or a sequence of N (each vehicle its
    own gains, filters and airframe constants). Every attribute is an (N,) array; `step` returns the
    PWM counts as an (4, N) integer array."""

    def __init__(self, params: Params | Sequence[Params], n: int | None = None, structure: str = "flight"):
        if structure not in ESTIMATORS:
            raise ValueError(f"unknown estimator {structure!r} (known: {', '.join(ESTIMATORS)})")
        ps = [params] * (n or 1) if isinstance(params, Params) else list(params)
        self.n = len(ps)

        def col(get):
            return _column([get(p) for p in ps])
        self.B = col(lambda p: p.airframe.B)
        self.fmax = 2.0 * self.B
        self.h1, self.h2 = col(lambda p: p.airframe.h1), col(lambda p: p.airframe.h2)
        self.sonar_period = col(lambda p: 1.0 / p.airframe.sonar_hz)
        # eq. 24, per axis: kp, ki, kd (Table 3: output and integral within [-B, B])
        self.kp = {a: col(lambda p, a=a: getattr(p.gains, "kp_" + a)) for a in GAINS}
        self.ki = {a: col(lambda p, a=a: getattr(p.gains, "ki_" + a)) for a in GAINS}
        self.kd = {a: col(lambda p, a=a: getattr(p.gains, "kd_" + a)) for a in GAINS}
        self.a_ema = col(lambda p: p.filters.alpha_ema)
        self.a_rp = col(lambda p: p.filters.alpha_roll_pitch)
        w = col(lambda p: 1.0 / p.filters.tau_tilt_air if p.filters.tau_tilt_air > 0.0 else 0.0)
        self.k_air, self.ki_air = 2.0 * w, w * w
        tau_rate = col(lambda p: p.filters.tau_rate)                 # the D path's EMA (0: none)
        self.rate_filtered = tau_rate > 0.0
        self.tau_rate = np.where(self.rate_filtered, tau_rate, 1.0)
        self.a_rate, self.rate_dt = np.ones(self.n), None
        self.paper = structure == "paper"
        self.in_flight = np.zeros(self.n, dtype=bool)
        self.tilt_bias = (np.zeros(self.n), np.zeros(self.n))
        z = np.zeros
        self.roll, self.pitch, self.yaw = z(self.n), z(self.n), z(self.n)
        self.p, self.q, self.r = z(self.n), z(self.n), z(self.n)
        self.droll, self.dpitch, self.dyaw = z(self.n), z(self.n), z(self.n)
        self.bx, self.by = z(self.n), z(self.n)
        self.integral = {a: z(self.n) for a in GAINS}
        self.uz = z(self.n)
        self.alt, self.alt_prev, self.alt_sp = z(self.n), z(self.n), z(self.n)
        self.alt_t = None
        self.f = z((4, self.n))

    def _pid(self, axis: str, setpoint, y, dy, dt: float, angle: bool = False):
        """Pid.update (eq. 24) on arrays."""
        e = setpoint - y
        if angle:
            e = (e + math.pi) % TWO_PI - math.pi
        lim = self.B
        i = self.integral[axis] + self.ki[axis] * e * dt
        self.integral[axis] = i = np.minimum(np.maximum(i, -lim), lim)   # NaN stays NaN, as onboard
        u = self.kp[axis] * e - self.kd[axis] * dy + i
        return np.minimum(np.maximum(u, -lim), lim)

    def _estimate(self, gx, gy, gz, ax, ay, az, dt: float) -> None:
        """AttitudeEstimator.update on arrays (no magnetometer)."""
        roll, pitch, yaw = self.roll, self.pitch, self.yaw
        sr, cr, sp, cp = np.sin(roll), np.cos(roll), np.sin(pitch), np.cos(pitch)
        if self.paper:
            a = self.a_ema
            b = 1.0 - a
            p = self.p = a * gx + b * self.p      # eq. 36-38
            q = self.q = a * gy + b * self.q
            r = self.r = a * gz + b * self.r
        else:
            p, q, r = gx - self.bx, gy - self.by, gz
        w = q * sr + r * cr
        droll, dpitch, dyaw = p + w * sp / cp, q * cr - r * sr, w / cp
        rate_roll, rate_pitch, rate_yaw = droll, dpitch, dyaw
        if not self.paper and self.rate_filtered.any():   # the D term's rates through their EMA
            if dt != self.rate_dt:
                self.rate_dt = dt
                self.a_rate = np.where(self.rate_filtered, 1.0 - np.exp(-dt / self.tau_rate), 1.0)
            a = self.a_rate
            b = 1.0 - a
            fp = self.p = a * p + b * self.p
            fq = self.q = a * q + b * self.q
            fr = self.r = a * r + b * self.r
            fw = fq * sr + fr * cr
            rate_roll, rate_pitch, rate_yaw = fp + fw * sp / cp, fq * cr - fr * sr, fw / cp
        roll_g, pitch_g, yaw_g = roll + droll * dt, pitch + dpitch * dt, yaw + dyaw * dt
        acc_roll = np.arctan2(ay, az) - self.tilt_bias[0]
        acc_pitch = np.arctan2(-ax, np.sqrt(ay * ay + az * az)) - self.tilt_bias[1]
        air = self.in_flight
        everyone = (not self.paper) and bool(air.all())        # all in flight: no ground branch to compute
        if not everyone:
            a = self.a_rp
            ground_roll = a * roll_g + (1.0 - a) * acc_roll    # eq. 30-31, 33-34, Table 5's alpha
            ground_pitch = a * pitch_g + (1.0 - a) * acc_pitch
        if self.paper:
            roll_g, pitch_g = ground_roll, ground_pitch
        else:                                                  # the in-flight PI correction
            er = acc_roll - roll_g
            ep = acc_pitch - pitch_g
            k = self.k_air * dt
            ki = self.ki_air * dt
            if everyone:
                roll_g, pitch_g = roll_g + k * er, pitch_g + k * ep
                self.bx, self.by = self.bx - ki * er, self.by - ki * (ep * cr)
            else:
                roll_g = np.where(air, roll_g + k * er, ground_roll)
                pitch_g = np.where(air, pitch_g + k * ep, ground_pitch)
                self.bx = np.where(air, self.bx - ki * er, self.bx)
                self.by = np.where(air, self.by - ki * (ep * cr), self.by)
        yaw_g = (yaw_g + math.pi) % TWO_PI - math.pi
        if self.paper:   # eq. 24 literally: the difference quotient of the fused angles
            rate_roll, rate_pitch = (roll_g - roll) / dt, (pitch_g - pitch) / dt
            rate_yaw = ((yaw_g - yaw + math.pi) % TWO_PI - math.pi) / dt
        self.droll, self.dpitch, self.dyaw = rate_roll, rate_pitch, rate_yaw
        self.roll, self.pitch, self.yaw = roll_g, pitch_g, yaw_g

    def on_range(self, distance, t: float, ready=None) -> None:
        """FlightController.on_range for the echoes of the vehicles `ready` (all when None) at time t
        (NaN: a failed measurement, which holds the last altitude)."""
        if self.alt_t is None:
            self.alt_t = np.full(self.n, t - self.sonar_period)
        ready = np.ones(self.n, dtype=bool) if ready is None else ready
        dt = t - self.alt_t
        self.alt_t = np.where(ready, t, self.alt_t)
        alt = np.where(ready & (distance == distance), distance * np.cos(self.roll) * np.cos(self.pitch), self.alt)
        ok = ready & (dt > 0.0)
        integral = self.integral["z"]
        uz = self._pid("z", self.alt_sp, alt, (alt - self.alt_prev) / np.where(ok, dt, 1.0), np.where(ok, dt, 0.0))
        self.integral["z"] = np.where(ok, self.integral["z"], integral)
        self.alt = alt
        self.uz = np.where(ok, uz, self.uz)
        self.alt_prev = np.where(ok, alt, self.alt_prev)

    def step(self, gx, gy, gz, ax, ay, az, dt: float, roll_sp, pitch_sp, yaw_sp, alt_sp) -> np.ndarray:
        """FlightController.step: calibrated IMU arrays (rad/s, m/s^2) and setpoints -> counts (4, N)."""
        self._estimate(gx, gy, gz, ax, ay, az, dt)
        self.alt_sp = alt_sp
        roll, pitch = self.roll, self.pitch
        uphi = self._pid("phi", roll_sp, roll, self.droll, dt)
        utheta = self._pid("theta", pitch_sp, pitch, self.dpitch, dt)
        upsi = self._pid("psi", yaw_sp, self.yaw, self.dyaw, dt, angle=True)
        # Mixer.mix: eq. 25, f within [0, 2B] (NaN -> 0), then count_from_thrust (eq. 26 inverted)
        c = np.cos(roll) * np.cos(pitch)
        base = self.B + self.uz / np.where(c > MIN_TILT_COSINE, c, MIN_TILT_COSINE)
        f = self.f
        f[0] = base - utheta + upsi
        f[1] = base + uphi - upsi
        f[2] = base + utheta + upsi
        f[3] = base - uphi - upsi
        fmax = self.fmax
        np.copyto(f, np.where(f > fmax, fmax, np.where(f > 0.0, f, 0.0)))
        P = self.h2 + np.sqrt(f / self.h1)
        return (SCALE * np.where(P < 255.0, P, 255.0) + 0.5).astype(np.int64)


class BatchPlant:
    """`Plant` (sim/world/plant.py) for N vehicles in the air: fixed-step RK4, `substeps` per loop period,
    the input held over the period. Vehicles that crash (tilt past CRASH_TILT, below the floor, or a
    state no longer finite) are frozen and marked in `crashed`."""

    def __init__(self, airframe: Airframe, effects: tuple[Effect, ...], n: int, substeps: int = 1,
                 battery_v: float | None = None):
        self.model = Model(airframe, effects, vector=True)
        self.a, self.n = airframe, n
        self.dt = airframe.dt
        self.substeps = substeps
        self.h = self.dt / substeps
        self.battery_v = np.full(n, airframe.battery_nominal_v if battery_v is None else battery_v)
        self.x = np.zeros((self.model.n, n))
        self.t = 0.0
        self.crashed = np.zeros(n, dtype=bool)
        self.crash_t = np.full(n, np.nan)
        # the actuation delay, per vehicle, as the single plant realises it (sim/world/plant.py `delayed`): a
        # ring of the last whole + 2 inputs, the delayed one and the one before it averaged over the period
        periods = np.broadcast_to(np.asarray(self.model.delay, dtype=float), (n,)) / self.dt
        self._whole = np.floor(periods + 1e-9).astype(int)
        self._frac = np.where(periods - self._whole > 1e-9, periods - self._whole, 0.0)
        self._ring = np.zeros((int(self._whole.max()) + 2, 5, n))
        self._head = 0
        self._cols = np.arange(n)

    def hover(self, z: float) -> None:
        """Every vehicle level at altitude z, at rest, its rotors at the hover command."""
        a = self.a
        P = a.h2 + np.sqrt(a.B / np.asarray(a.h1))   # eq. 26 inverted at f = B (h1, h2 drawn per vehicle)
        u = self.input(np.broadcast_to(P, (4, self.n)).copy())
        f_cmd = self.model._commanded(u)
        x = np.zeros((self.model.n, self.n))
        x[Z] = z
        for e in self.model.effects:
            if e.n_states:
                x[e.offset:e.offset + e.n_states] = e.initial_states(f_cmd)
        self.x = x
        self._ring[:] = np.array(u)
        self.u = u

    def input(self, P: np.ndarray) -> tuple:
        """The model's input u from command values P (4, N): a new tuple (a new input)."""
        return (P[0], P[1], P[2], P[3], self.battery_v)

    def _rk4(self, x, t, u, h):
        """Plant._rk4 on arrays, its sums in place."""
        f, hh = self.model.f, 0.5 * h
        k1 = np.array(f(t, x, u))
        k2 = np.array(f(t + hh, x + hh * k1, u))
        k3 = np.array(f(t + hh, x + hh * k2, u))
        k4 = np.array(f(t + h, x + h * k3, u))
        k2 += k3
        k2 *= 2.0
        k2 += k1
        k2 += k4
        k2 *= h / 6.0
        k2 += x
        return k2

    def advance(self, counts: np.ndarray) -> None:
        """One loop period with the PWM counts (4, N) held."""
        u = self.input(counts * (1.0 / SCALE))
        if self._ring.shape[0] > 2 or self._frac.any():
            ring = self._ring
            self._head = head = (self._head + 1) % ring.shape[0]
            ring[head] = u
            cols = self._cols
            before = ring[(head - self._whole - 1) % ring.shape[0], :, cols].T
            now = ring[(head - self._whole) % ring.shape[0], :, cols].T
            u = delayed(before, now, self._frac)
        self.u = u
        with np.errstate(all="ignore"):
            x = self.x
            for j in range(self.substeps):
                x = self._rk4(x, self.t + j * self.h, u, self.h)
            self.t += self.dt
            total = x.sum(axis=0)
            bad = ~(total - total == 0.0) | (x[Z] < 0.0) | (np.abs(x[PHI]) > CRASH_TILT) | (np.abs(x[THETA]) > CRASH_TILT)
            if bad.any() or self.crashed.any():   # (a NaN or an infinity anywhere makes the sum's difference NaN)
                new = bad & ~self.crashed
                self.crash_t[new] = self.t
                self.crashed |= bad
                x = np.where(self.crashed, self.x, x)
            self.x = x


@dataclass
class BatchFlight:
    """The outcome of `fly`: per vehicle, whether it crashed (and when), and the recorded states."""
    t: np.ndarray             # (k,) s, the recorded instants
    states: np.ndarray        # (k, n_states, N) the plant's state at those instants
    crashed: np.ndarray       # (N,) bool
    crash_t: np.ndarray       # (N,) s since the start, NaN if it did not crash
    vehicle_steps: int


def fly(plant: BatchPlant, controller: BatchController, setpoints: Callable[[float], tuple], duration: float,
        record_every: int = 9, t0: float = 0.0, imu=None, sonar: Sonar | None = None,
        powered: float = SIM_CALIBRATE_S, tick: Callable[[int], None] | None = None) -> BatchFlight:
    """Fly N vehicles from hover: each loop period the IMU (`imu`, a calibrated
    sim/sweeps/batch_imu.py `BatchImu`: the simulated chip's readings; None: the true rates and
    specific force) and the sonar's echoes (`sonar`: each echo after its flight time, jittered, or
    lost; None: the true range along -z_b at each trigger) go to the controller; its counts drive
    the plant. `setpoints(t) -> (roll, pitch, yaw, alt)`, scalars or (N,) arrays; t runs from t0
    (since arming), the chip's clock from `powered` s before arming (the calibration's). `tick(steps)`:
    the vehicle-steps flown since the last call, every TICK_STEPS loop periods (progress)."""
    a = plant.a
    dt = a.dt
    controller.in_flight[:] = True
    every = max(1, round(a.loop_hz / a.sonar_hz))
    steps = int(round(duration / dt))
    ts, states = [], []
    model = plant.model
    controller.alt = controller.alt_prev = plant.x[Z].copy()   # in the air: no derivative kick at the first echo
    for k in range(steps):
        t = t0 + k * dt
        x = plant.x
        distance = x[Z] / (np.cos(x[PHI]) * np.cos(x[THETA]))   # along -z_b
        if sonar is None:
            if k % every == 0:
                controller.on_range(distance, t)
        else:
            if k % every == 0:
                sonar.trigger(distance, t)
            due = sonar.due(t)
            if due is not None:
                controller.on_range(sonar.value, t, due)
        forces = model.forces(t, x, plant.u)
        fx, fy, fz = model.specific_force(t, x, plant.u, forces)
        if imu is None:
            gx, gy, gz, ax, ay, az = x[P], x[Q], x[R], fx, fy, fz
        else:
            ax, ay, az, gx, gy, gz = imu.read(t + powered, fx, fy, fz, x[P], x[Q], x[R], np.array(forces.f),
                                              np.array(forces.w))
        roll_sp, pitch_sp, yaw_sp, alt_sp = setpoints(t)
        counts = controller.step(gx, gy, gz, ax, ay, az, dt, roll_sp, pitch_sp, yaw_sp, alt_sp)
        plant.advance(counts)
        if k % record_every == 0:
            ts.append(t)
            states.append(np.concatenate([x[:N_RIGID], [controller.roll, controller.pitch, controller.yaw]]))
        if tick is not None and (k + 1) % TICK_STEPS == 0:
            tick(TICK_STEPS * plant.n)
    return BatchFlight(np.array(ts), np.array(states), plant.crashed.copy(), plant.crash_t.copy(), steps * plant.n)


class Sonar:
    """The HC-SR04 of each vehicle (sim/world/devices.py `SimGpio`'s echo): a trigger's echo arrives
    after its flight time (the echo's rise ECHO_DELAY_S after the 10 us trigger, then the width of the
    distance), its width jittered by `sigma_us`; out of range (past 4.5 m) or lost (`dropout`) it is
    the module's 38 ms no-echo, a failed measurement (NaN). `due(t)`: the vehicles whose echo the
    driver has by t (None when none), their values in `value`."""

    def __init__(self, n: int, sigma_us: float, dropout: float, seed: int = 0):
        from flightctl.sim.world.devices import SimGpio
        self.rng = np.random.default_rng(seed)
        self.sigma_us, self.dropout = sigma_us, dropout
        self.at = np.full(n, np.inf)
        self.value = np.full(n, np.nan)
        self._delay, self._no_echo = 10e-6 + SimGpio.ECHO_DELAY_S, SimGpio.NO_ECHO_S

    def trigger(self, distance, t: float) -> None:
        n = self.at.size
        lost = (distance > 4.5) | ~(distance == distance)
        if self.dropout:
            lost |= self.rng.random(n) < self.dropout
        width = np.maximum(distance * US_PER_M + self.sigma_us * self.rng.standard_normal(n), 0.0) * 1e-6
        self.at = t + self._delay + np.where(lost, self._no_echo, width)
        self.value = np.where(lost, np.nan, width * 1e6 / US_PER_M)

    def due(self, t: float):
        ready = self.at <= t
        if not ready.any():
            return None
        self.at = np.where(ready, np.inf, self.at)
        return ready


def with_draws(params: Params, draws: dict[tuple[str, str], np.ndarray] | None = None) -> tuple[Effect, ...]:
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


_FLOWN = None        # a worker's shared count of vehicle-steps flown (`simulate`'s progress)


def _count_in(counter) -> None:
    global _FLOWN
    _FLOWN = counter


def _add_flown(steps: int) -> None:
    with _FLOWN.get_lock():
        _FLOWN.value += steps


def _chunk(job, tick=None) -> BatchFlight:
    """One worker's share of `simulate`."""
    params, n, draws, gains, plan, start, end, record_every, sensors, seed = job
    from flightctl.sim.sweeps.montecarlo import drawn_airframe, drawn_params
    from flightctl.sim.world.devices import SensorNoise
    plant = BatchPlant(drawn_airframe(params.airframe, draws), with_draws(params, draws), n)
    plan.restart()
    plant.hover(plan.at(start)[3])
    # each vehicle's controller: its draw of the constants it knows (eq. 26's h1, h2, its rate filter)
    vehicles = [drawn_params(params, {k: float(v[i]) for k, v in draws.items()}) for i in range(n)] if draws else [params] * n
    ctl = BatchController([p if gains is None else dataclasses.replace(p, gains=gains[i]) for i, p in enumerate(vehicles)])
    imu = sonar = None
    if sensors:
        from flightctl.sim.sweeps.batch_imu import BatchImu
        a = params.airframe
        noise = SensorNoise()
        imu = BatchImu(a, params.sensors, n, {name: v for (c, name), v in draws.items() if c == "sensors"}, seed)
        imu.calibrate(SIM_CALIBRATE_S, a.dt, a.g)
        ctl.tilt_bias = imu.tilt_bias
        sonar = Sonar(n, noise.sonar_sigma_us, noise.sonar_dropout, seed)
    return fly(plant, ctl, plan.at, end - start, record_every, t0=start, imu=imu, sonar=sonar,
               tick=tick if tick is not None else _add_flown if _FLOWN is not None else None)


def simulate(params: Params, plan: Plan, start: float, end: float, n: int,
             draws: dict[tuple[str, str], np.ndarray] | None = None, gains: Sequence[Gains] | None = None,
             workers: int = 1, record_every: int = 9, sensors: bool = True, seed: int = 0,
             progress: Callable[[float], None] | None = None) -> BatchFlight:
    """Fly `plan` from `start` to `end` (s since arming) with n vehicles, each started hovering at the
    plan's altitude at `start`, each with its own draws of the parameters ((N,) arrays) and its own
    gains (None: the file's). `sensors`: the simulated chip and sonar (`fly`), each vehicle's chip
    calibrated on the floor first; else ideal. `workers` processes share the vehicles.
    `progress(fraction)`: the share of the vehicle-steps flown, called here about once a second of
    wall time."""
    draws = {k: np.broadcast_to(np.asarray(v, dtype=float), (n,)) for k, v in (draws or {}).items()}
    if gains is not None and len(gains) != n:
        raise ValueError(f"{len(gains)} gain sets for {n} vehicles")
    cuts = np.linspace(0, n, max(1, min(workers, n)) + 1).astype(int)
    jobs = [(params, int(b - a), {k: v[a:b] for k, v in draws.items()}, None if gains is None else list(gains[a:b]),
             plan, start, end, record_every, sensors, seed * 1000 + j) for j, (a, b) in enumerate(zip(cuts[:-1], cuts[1:]))]
    total = max(1, int(round((end - start) / params.airframe.dt)) * n)
    if len(jobs) == 1:
        flown = [0]

        def tick(steps: int) -> None:
            flown[0] += steps
            progress(flown[0] / total)
        parts = [_chunk(jobs[0], tick if progress is not None else None)]
    else:
        import multiprocessing

        from flightctl.sim.pool import workers as pool_of
        counter = multiprocessing.Value("q", 0)
        with pool_of(len(jobs), _count_in, (counter,)) as pool:
            futures = [pool.submit(_chunk, job) for job in jobs]
            while wait(futures, timeout=1.0).not_done:
                if progress is not None:
                    progress(counter.value / total)
            parts = [f.result() for f in futures]
    return BatchFlight(parts[0].t, np.concatenate([p.states for p in parts], axis=2),
                       np.concatenate([p.crashed for p in parts]), np.concatenate([p.crash_t for p in parts]),
                       sum(p.vehicle_steps for p in parts))
