"""A simulated fleet: vehicles flown many times each by the batched simulator (sim/sweeps/batch.py, the
compiled full path: the onboard loop, the chip, the sonar; `wide` records a log's columns), each flight
written as the log its autopilot would keep, with two hidden effects drawn from a seeded generator
(`simulate_fleet`'s truth; a flight whose loop stopped before logging a row has no log, None in it):

- **a motor that loses efficiency**: on one vehicle, one motor gives a drawn fraction of its thrust and
  torque (`motor_weak`, sim/causes/motor_weak.py) from a drawn flight on. The fraction is drawn in
  WEAK_SCALE: a worn bearing, a nicked or bent propeller, a motor whose magnets weaken with heat lose
  thrust for the same command by some percent to some tens of percent; the project's own bound for a
  motor that still hovers is motor_weak.SCALE_RANGE (half its siblings' thrust).
- **a battery whose internal resistance grows**: on another vehicle, the pack's resistance rises linearly
  from a drawn flight on, to a drawn multiple (AGED_FACTOR) of its new value by the last flight. A
  lithium cell's resistance rises with its cycles; a pack whose resistance has doubled is at the end of
  its life (Battery University, BU-802a "How does Rising Internal Resistance affect Performance?",
  https://batteryuniversity.com/article/bu-802a-how-does-rising-internal-resistance-affect-performance).

The other vehicles change nothing but what changes between any two flights: the pack's charge at
take-off, its resistance by the temperature (a few %: R_JITTER), the sensors' noise (each flight its own
seed). Each vehicle's packs start at a new pack's resistance drawn in R_NEW (per pack, its leads and
connector: SimBattery.R_INT's 25 mOhm of a 4S 4000 mAh pack in the middle).

The battery is SimBattery's (sim/world/power.py: open-circuit voltage linear in the charge, the current
the rotors' torque times speed over the voltage at its efficiency, eq. 26-28 on the logged commands,
behind the resistance), computed on the flown commands (the batched simulator holds the thrust at a
fixed voltage: the pack's sag does not change the flight unless a `battery_sag` effect says so).

Formats: ArduCopter DataFlash (`.BIN`, sim/logs/dfwrite.py) at ArduPilot's default logging rates (IMU
25 Hz; RCOU, BAT, ATT and VIBE 10 Hz; GPS 5 Hz), the vehicle named the way ArduPilot does (the board's
name and its three 32-bit UID words in a MSG line at boot, as `Pixhawk4 0047002B 34385105 36363539` in
tests/data/ardupilot/backend_log_80k.bin) and the flight's start in its GPS time (GWk, GMS: GPS time,
UTC + 18 s since 2017); or PX4 ULog (`.ulg`, through the project's exporter sim/logs/export.py) at
ULOG_HZ, the board's UID as `sys_uuid` and the start as vehicle_gps_position's UTC. No blackbox: the
project has no blackbox writer. `simulate_fleet` is the API (the hidden-effect test and the scale
measurement call it).
"""
from __future__ import annotations

import dataclasses
import datetime as dt
import math
from pathlib import Path

import numpy as np

from flightctl.params import EffectSpec, Params, load
from flightctl.plans.plan import Move, Plan
from flightctl.sim.world.devices import SensorNoise
from flightctl.sim.world.power import SimBattery, power_of_commands

WEAK_SCALE = (0.80, 0.92)      # the weak motor's thrust for its command, drawn in this range
R_NEW = (0.020, 0.030)         # ohm: a new pack's internal resistance with its leads, drawn per vehicle
AGED_FACTOR = (1.8, 2.5)       # the aging pack's resistance at the last flight over its new value
R_JITTER = 0.03                # the resistance's spread from flight to flight (temperature), relative
SOC = (0.85, 1.0)              # the pack's charge at take-off
MOTOR_SPREAD = 0.02            # each vehicle's motors differ by this much thrust (one motor_weak each)
CHUNK = 40                     # flights flown at once by the batched simulator
ONSET_MARGIN = 6               # an effect starts no earlier than this flight and this many before the last
#                                (a third of the flights, at least 2, on a fleet of fewer than 18: the middle of a short series)
EPOCH_UTC = dt.datetime(2026, 3, 2, 8, 0, tzinfo=dt.timezone.utc)
GPS_EPOCH = dt.datetime(1980, 1, 6, tzinfo=dt.timezone.utc)
GPS_LEAP_S = 18                # GPS time ahead of UTC (since 2017-01-01)
BOARDS = ("CubeOrange", "Pixhawk4", "CubeBlack", "MatekH743")
FIRMWARE = "ArduCopter V4.5.7 (1a2b3c4d)"
# ArduPilot's QUAD/PLUS (AP_MotorsMatrix): motor 1 right CCW, 2 left CCW, 3 front CW, 4 back CW; the
# paper's + layout (conventions.md): 1 North (front) CW, 2 West (left) CCW, 3 South CW, 4 East CCW.
AP_FROM_SIM = (4, 2, 1, 3)     # ArduPilot motor m is the simulator's motor AP_FROM_SIM[m - 1]
PWM = (1000.0, 2000.0)
IMU_HZ, SLOW_HZ, GPS_HZ = 25.0, 10.0, 5.0
ULOG_HZ = 150.0                # the ULog's rows (every topic): PX4 logs its IMU topic at this order of rate
AMPS_PER_VOLT_LSB = 10e-6 / 0.002 / 0.004    # the INA219's current noise per volt of its bus noise: as many
#                              LSBs (4 mV on the bus, 10 uV over the 2 mOhm shunt: sim/world/power.py)
SUFFIX = {"dataflash": ".BIN", "ulog": ".ulg"}
# ArduCopter's default LOG_BITMASK (config.h): ATTITUDE_MED, GPS, PM, CTUN, NTUN, RCIN, IMU (bit 7), CMD,
# CURRENT, RCOUT, OPTFLOW, COMPASS, CAMERA, MOTBATT (defines.h's MASK_LOG_ bits 1-11, 13, 15, 17)
LOG_BITMASK = sum(1 << b for b in (1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 13, 15, 17))


def plan(seconds: float) -> Plan:
    """A short flight whose current moves (the resistance needs it): take off to 1.5 m, hold, climb to
    2.5 m and back, hold, land; `seconds` (at least 22) from arming to the plan's end."""
    if seconds < 22.0:
        raise ValueError(f"a fleet flight of {seconds:g} s: at least 22 s")
    land = seconds - 6.0
    return Plan([Move(0.0, "alt", 1.5, 4.0), Move(9.0, "alt", 2.5, 1.5), Move(13.0, "alt", 1.5, 1.5),
                 Move(land, "alt", 0.0, 4.0)], seconds, "fleet",
                "take off to 1.5 m, climb to 2.5 m and back, hold, land")


def battery(t: np.ndarray, P: np.ndarray, a, soc: float, ohm: float) -> tuple[np.ndarray, np.ndarray]:
    """(terminal voltage, current) of SimBattery (its open-circuit voltage at the charge left by the
    current) behind `ohm`, on the flown commands: V = E - R I with I = power / V solved per row."""
    power = power_of_commands(P, a)
    step = np.diff(t, prepend=t[0])
    E = np.full(t.size, SimBattery.open_circuit(soc))
    for _ in range(3):                   # the charge drawn by the current of the last pass
        V = 0.5 * (E + np.sqrt(np.maximum(E * E - 4.0 * ohm * power, 0.0)))
        current = power / V
        E = SimBattery.open_circuit(soc - np.cumsum(current * step) / SimBattery.CAPACITY_C)
    return V, current


def vibe(acc: np.ndarray, hz: float) -> np.ndarray:
    """(3, n) ArduPilot's VIBE of the accelerometer (AP_InertialSensor::calc_vibration_and_clipping: the
    square root of the low-passed (2 Hz) square of the accelerometer less its 5 Hz low-pass; moving means
    of 0.2 s and 0.5 s stand for the two low-passes), m/s^2."""
    def mean(x, seconds):
        k = np.ones(max(1, int(round(seconds * hz))))
        k /= k.size
        return np.vstack([np.convolve(v, k, mode="same") for v in x])
    return np.sqrt(mean((acc - mean(acc, 0.2)) ** 2, 0.5))


def gps_time(when: dt.datetime) -> tuple[int, int]:
    """(GPS week, ms of the week) of a UTC time."""
    s = (when - GPS_EPOCH).total_seconds() + GPS_LEAP_S
    week = int(s // (7 * 86400))
    return week, int(round((s - week * 7 * 86400) * 1000.0))


def write_dataflash(path: Path, cols: dict, a, uid: str, start: dt.datetime, rng: np.random.Generator) -> None:
    """One flight as ArduCopter 4.5 logs it at the default rates (the module's docstring): the board's
    UID line, the parameters, ARM, then IMU, RCOU, BAT, ATT, VIBE and GPS in time order; the voltage
    and current with the power monitor's noise (SensorNoise.battery_sigma on the voltage, as many of the
    INA219's LSBs on the current: sim/world/power.py)."""
    from flightctl.sim.logs.dfwrite import DataFlash
    t = cols["t"]
    hz = 1.0 / float(np.median(np.diff(t)))
    f = DataFlash()
    boot = 5.0 + float(rng.uniform(0.0, 20.0))              # s from the board's boot to arming
    f.add("MSG", 200_000, FIRMWARE)
    f.add("MSG", 210_000, uid)
    f.add("MSG", 220_000, "Frame: QUAD/PLUS")
    params = {"FRAME_CLASS": 1, "FRAME_TYPE": 0, "MOT_PWM_MIN": PWM[0], "MOT_PWM_MAX": PWM[1], "MOT_BAT_VOLT_MAX": 16.8,
              "MOT_THST_EXPO": 1.0, "MOT_SPIN_MIN": a.h2 / 255.0, "MOT_SPIN_MAX": 1.0, "LOG_BITMASK": LOG_BITMASK,
              "BRD_SERIAL_NUM": 0.0}
    params.update({f"SERVO{m}_FUNCTION": 32 + m for m in range(1, 5)})
    for k, v in params.items():
        f.add("PARM", 300_000, k, float(v))
    f.add("ARM", int(boot * 1e6) - 1000, 1)
    sigma = SensorNoise().battery_sigma
    amp_sigma = sigma * AMPS_PER_VOLT_LSB
    levels = vibe(np.vstack([cols["acc_x"], cols["acc_y"], cols["acc_z"]]), hz)
    every = {n: max(1, int(round(hz / r))) for n, r in (("imu", IMU_HZ), ("slow", SLOW_HZ), ("gps", GPS_HZ))}
    lat0, lng0 = 52.4556 + rng.uniform(-0.01, 0.01), 10.5586 + rng.uniform(-0.01, 0.01)
    for k in range(t.size):
        us = int(round((boot + t[k]) * 1e6))
        if k % every["imu"] == 0:
            f.add("IMU", us, 0, cols["gyro_x"][k], -cols["gyro_y"][k], -cols["gyro_z"][k],
                  cols["acc_x"][k], -cols["acc_y"][k], -cols["acc_z"][k])
        if k % every["slow"] == 0:
            pwm = [int(round(PWM[0] + cols[f"P{s}"][k] / 255.0 * (PWM[1] - PWM[0]))) for s in AP_FROM_SIM] + [0] * 10
            f.add("RCOU", us - 5, *pwm)
            f.add("BAT", us, 0, float(cols["battery_v"][k] + rng.normal(0.0, sigma)),
                  float(cols["current"][k] + rng.normal(0.0, amp_sigma)))
            f.add("ATT", us, 0.0, math.degrees(cols["roll"][k]), 0.0, -math.degrees(cols["pitch"][k]), 0.0,
                  -math.degrees(cols["yaw"][k]) % 360.0)
            f.add("VIBE", us, *(float(v) for v in levels[:, k]), 0, 0, 0)
        if k % every["gps"] == 0:
            week, ms = gps_time(start + dt.timedelta(seconds=float(t[k])))
            f.add("GPS", us, 0, 3, ms, week, 12, 0.8, int(lat0 * 1e7), int(lng0 * 1e7), 60.0 + float(cols["alt"][k]),
                  0.0, 0.0, 0.0)
    path.write_bytes(f.bytes())


def write_ulog(path: Path, cols: dict, a, uuid: str, start: dt.datetime, rng: np.random.Generator, flight: Plan) -> None:
    """One flight as PX4's ULog through the project's exporter (sim/logs/export.py: PX4's topics and frames),
    every topic at ULOG_HZ (a third of the loop's rows), the board's UUID as `sys_uuid` and the start as
    the GPS topic's UTC; the voltage and current with the power monitor's noise (`write_dataflash`)."""
    from flightctl.logfile import FLIGHT_COLUMNS
    from flightctl.sim.logs.export import export
    every = max(1, int(round(1.0 / float(np.median(np.diff(cols["t"]))) / ULOG_HZ)))
    rows = np.arange(0, cols["t"].size, every)
    sigma = SensorNoise().battery_sigma
    flight.restart()
    sp = np.array([flight.at(float(t))[:] for t in cols["t"][rows]])     # roll, pitch, yaw, alt setpoints
    out = {"t": cols["t"][rows], "range": np.full(rows.size, np.nan), "roll_sp": sp[:, 0], "pitch_sp": sp[:, 1],
           "yaw_sp": sp[:, 2], "alt_sp": sp[:, 3],
           "battery_v": cols["battery_v"][rows] + rng.normal(0.0, sigma, rows.size),
           "current": cols["current"][rows] + rng.normal(0.0, sigma * AMPS_PER_VOLT_LSB, rows.size)}
    for c in FLIGHT_COLUMNS:
        if c not in out:
            out[c] = cols[c][rows]
    names = list(FLIGHT_COLUMNS) + ["current"]
    head = [f"# vehicle_id: {uuid}", f"# start_utc: {start.isoformat()}", "# calibrate_s: 0", ",".join(names)]
    table = np.column_stack([out[c] for c in names])
    body = "\n".join(",".join("" if v != v else f"{v:.6g}" for v in row) for row in table)
    csv = path.with_suffix(".csv")
    csv.write_text("\n".join(head) + "\n" + body + "\n")
    try:
        export(csv, path, px4_only=True)          # another vehicle's PX4 log, not flightctl's own
    finally:
        csv.unlink()


def _uid(rng: np.random.Generator) -> str:
    words = rng.integers(0, 1 << 32, 3, dtype=np.uint64)
    return f"{BOARDS[int(rng.integers(len(BOARDS)))]} " + " ".join(f"{int(w):08X}" for w in words)


def onset_margin(flights: int) -> int:
    """The fewest flights before an effect's onset and from it to the last (ONSET_MARGIN)."""
    return min(ONSET_MARGIN, max(2, flights // 3))


def _draw_effects(rng, vehicles: int, flights: int, weak: bool, aging: bool, fmt: str,
                  weak_scale: tuple[float, float] = WEAK_SCALE) -> dict:
    margin = onset_margin(flights)
    lo, hi = margin, flights - margin
    if hi <= lo and (weak or aging):
        raise ValueError(f"{flights} flights: at least 3 for an effect's onset")
    if vehicles < (2 if weak and aging else 1):
        raise ValueError(f"{vehicles} vehicles: the weak motor and the aging pack are on two")
    who = rng.permutation(vehicles)
    out = {}
    if weak:
        sim_motor = int(rng.integers(1, 5))
        motor = AP_FROM_SIM.index(sim_motor) + 1 if fmt == "dataflash" else sim_motor    # as the log numbers it
        out["weak"] = {"vehicle": int(who[0]), "motor": motor, "sim_motor": sim_motor,
                       "scale": round(float(rng.uniform(*weak_scale)), 4), "onset": int(rng.integers(lo, hi))}
    if aging:
        out["battery"] = {"vehicle": int(who[1 if weak and vehicles > 1 else 0]), "onset": int(rng.integers(lo, hi)),
                          "factor": round(float(rng.uniform(*AGED_FACTOR)), 3)}
    return out


def simulate_fleet(folder: str | Path, rng: np.random.Generator, vehicles: int = 4, flights: int = 40,
                   seconds: float = 30.0, weak: bool = True, aging: bool = True, layout: str = "flat",
                   fmt: str = "dataflash", params: Params | None = None, progress=None,
                   weak_scale: tuple[float, float] = WEAK_SCALE) -> dict:
    """Fly `vehicles` x `flights` and write each flight into `folder` as an ArduCopter DataFlash log (`fmt`
    "dataflash") or a PX4 ULog ("ulog"; the module's docstring); returns the truth, which the code under test is never told:
    {"vehicles": [{"uid", "logs": [file names in flight order], "start_utc": [...], "ohm": [...],
    "motor_scale": [[4 per flight, in the log's motor order]]}], "weak": {vehicle, motor (as the log numbers
    it: ArduPilot's, or the simulator's in a ULog), sim_motor, scale, onset (0-based flight index)} and "battery":
    {vehicle, onset, factor}, each present when drawn (`weak`, `aging`).
    `layout`: "flat", every log in `folder` under a name that says nothing of its vehicle or order (as
    logs pooled from many SD cards and numbered), or "folders", one folder per vehicle with
    ArduPilot's numbered names in flight order. `progress(text)`: told as each vehicle is flown."""
    from flightctl.sim.sweeps.batch import simulate
    if fmt not in SUFFIX:
        raise ValueError(f"fmt {fmt!r}: one of {', '.join(SUFFIX)}")
    if layout not in ("flat", "folders"):
        raise ValueError(f"layout {layout!r}: flat or folders")
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    params = params or load(None)
    a = params.airframe
    truth = _draw_effects(rng, vehicles, flights, weak, aging, fmt, weak_scale)
    total = vehicles * flights
    names = rng.permutation(total) + 1
    out = []
    for v in range(vehicles):
        uid = _uid(rng)
        spread = 1.0 + rng.uniform(-MOTOR_SPREAD, MOTOR_SPREAD)
        base_motor = int(rng.integers(1, 5))
        w = truth.get("weak")
        motor = w["sim_motor"] if w and w["vehicle"] == v else base_motor
        scale = np.full(flights, spread)
        if w and w["vehicle"] == v:
            scale[w["onset"]:] *= w["scale"]
        r_new = float(rng.uniform(*R_NEW))
        ohm = r_new * np.ones(flights)
        b = truth.get("battery")
        if b and b["vehicle"] == v:
            ramp = np.clip((np.arange(flights) - b["onset"] + 1) / (flights - b["onset"]), 0.0, 1.0)
            ohm = r_new * (1.0 + (b["factor"] - 1.0) * ramp)
        ohm = ohm * (1.0 + R_JITTER * rng.standard_normal(flights))
        soc = rng.uniform(*SOC, flights)
        gaps = rng.uniform(0.3, 3.0, flights)                  # days between flights
        start = [EPOCH_UTC + dt.timedelta(days=float(d), seconds=float(rng.uniform(0, 36000)))
                 for d in np.cumsum(gaps)]
        p = dataclasses.replace(params, effects=params.effects + (
            EffectSpec("motor_weak", (("motor", float(motor)), ("scale", 1.0))),))
        seeds = [int(s) for s in rng.integers(0, 2 ** 31, flights)]
        logs, outcomes = [], []
        motor_scale = np.ones((flights, 4))
        motor_scale[:, AP_FROM_SIM.index(motor) if fmt == "dataflash" else motor - 1] = scale
        for j in range(flights):
            if j % CHUNK == 0:        # a few tens of flights at a time: the wide record is ~2 MB a flight
                part = slice(j, min(j + CHUNK, flights))
                fl = simulate(p, plan(seconds), len(seeds[part]), draws={("motor_weak", "scale"): scale[part]},
                              seeds=seeds[part], record=(0.0, seconds + 10.0), wide=True)
                outcomes += fl.outcome
            cols = {c: fl.log[c][:, j % CHUNK] for c in fl.log if c != "t"}
            logged = np.flatnonzero(np.isfinite(cols["P1"]))
            if logged.size < 2:              # the loop stopped before a row (the outcome says why): no log
                logs.append(None)
                continue
            n = int(logged[-1]) + 1
            cols = {c: x[:n] for c, x in cols.items()}
            cols["t"] = fl.log["t"][:n]
            P = np.vstack([cols[f"P{i}"] for i in range(1, 5)])
            cols["battery_v"], cols["current"] = battery(cols["t"], P, a, float(soc[j]), float(ohm[j]))
            if layout == "folders":
                name = f"vehicle{v + 1}/{j + 1:08d}{SUFFIX[fmt]}"
            else:
                name = f"{int(names[v * flights + j]):08d}{SUFFIX[fmt]}"
            (folder / name).parent.mkdir(parents=True, exist_ok=True)
            if fmt == "ulog":
                write_ulog(folder / name, cols, a, uid, start[j], rng, plan(seconds))
            else:
                write_dataflash(folder / name, cols, a, uid, start[j], rng)
            logs.append(name)
        out.append({"uid": uid, "logs": logs, "outcomes": outcomes,
                    "start_utc": [s.isoformat() for s in start], "ohm": [round(float(x), 5) for x in ohm],
                    "motor_scale": motor_scale.round(4).tolist()})
        if progress:
            progress(f"vehicle {v + 1} of {vehicles}: {flights} flights ({uid})")
    truth["vehicles"] = out
    return truth
