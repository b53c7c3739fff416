"""`flightctl bench`: spin the four motors in turn on a thrust stand and write one bench.csv (the
paper's propeller identification, sec. 4.1, Fig. 3), which `flightctl identify bench` fits as it is.

    flightctl bench [--board pi|sim] [--instruments pty|serial:PATH[,BAUD]|rcbenchmark:PATH[,BAUD]]
                    [--motors 1,2,3,4] [--profile staircase|step|both] [--steps P1,P2,...]
                    [--settle S] [--hold S] [--step P0,P1 --record S] [--max P] [--max-rpm RPM]
                    [--step-timeout S] [--silent S] [--ramp P_PER_S] [--clamped]
                    [--out bench.csv] [--raw bench-raw.csv] [--plot bench.png|--no-plot]
                    [--write-params P.toml]

Profiles, per motor, one motor at a time (the other three at the stop pulse):
- staircase: for each P of --steps, ramp to it, wait --settle, then average the instruments over
  --hold; if the speed is still changing, average again, up to --step-timeout. One bench.csv row
  `motor, P, thrust, omega, voltage, current` per step (SI, docs/measured-data.md).
- step: settle at P0, jump to P1, record the speed for --record s and fit a first-order response
  `omega(t) = w1 + (w0 - w1) exp(-(t - t0) / tau)` (the motor_dynamics cause); the two steady points
  are bench.csv rows too. `--write-params P.toml` writes the motors' mean tau as an
  `[[effect]] cause = "motor_dynamics"` into P.toml (created from --params if missing).
Every instrument sample is kept, timestamped, in the raw file (bench-raw.csv beside --out).

Instruments (hil/instruments.py, docs/hil.md "Bench instruments"): a microcontroller speaking the
line protocol (`serial:`), an RCbenchmark stand's CSV stream (`rcbenchmark:`, one motor per run: the
stand holds one), or on `--board sim` the simulated load cell and tachometer behind a pseudo-terminal
(`pty`, the default there), read through pyserial like the real ones. Voltage and current come
from the line if it carries them, else from the onboard INA219.

Safety: on hardware the vehicle must be confirmed clamped (`--clamped`, or typed at the prompt); P
never exceeds --max; every time and rate is bounded (MAX_SETTLE_S and its siblings, with their reasons:
nan, inf and negatives refused); a step, every phase of it (ramp, settle, holds, the step profile's
record), that takes longer than --step-timeout, an instrument silent for
--silent s, a speed above the propeller's limit (--max-rpm, default APC's for its diameter) or a
thrust that falls while P rises stops the bench (exit 1); Ctrl-C and SIGTERM stop it (exit 130).
Whatever happens the motor returns to the stop pulse, and the rows measured so far are kept.
"""
from __future__ import annotations

import argparse
import csv
import math
import signal
import sys
import time
import tomllib
from dataclasses import dataclass, replace
from pathlib import Path

from flightctl import __version__
from flightctl.cli import interrupted
from flightctl.boards import Board, BoardOptions, BoardUnavailable, check_options, described, open_board
from flightctl.errors import InputError, Parser, seed
from flightctl.files import output_file, write_atomic
from flightctl.hal import PWM_RANGE
from flightctl.hil import instruments as ins
from flightctl.logfile import BENCH_COLUMNS
from flightctl.params import EffectSpec, Params, dumps, load
from flightctl.sim import causes
from flightctl.sim.progress import Progress

MAX_P = 200.0
RAMP_P_PER_S = 50.0
SETTLE_S = 2.0
HOLD_S = 2.0
STEP_TIMEOUT_S = 30.0
SILENT_S = 0.5
STEPS = "130,140,150,160,170,180,190"
STEP = "140,180"
RECORD_S = 1.0
POWER_EVERY_S = 0.1
MIN_SAMPLES = 3                 # instrument samples an average needs
STEADY_REL, STEADY_ABS = 0.01, 1.0   # the two halves of a window agree to 1 % (or 1 rad/s): steady
FALL_REL, FALL_ABS = 0.05, 0.05      # thrust may fall this much (noise) while P rises, no more
APC_MR_RPM_INCH = 105000.0      # APC's speed limit for its multirotor propellers: 105,000 RPM / diameter (in)
EXIT_STOPPED, EXIT_UNAVAILABLE, EXIT_INTERRUPTED = 1, 3, 130
RAW_COLUMNS = ("t", "motor", "P", "phase", "thrust", "omega", "voltage", "current")
PROFILES = ("staircase", "step", "both")
# The largest value of each time and rate the bench takes, so that no mistyped value keeps a motor
# spinning: the step timeout bounds every phase of a step (ramp, settle, hold, the holds again, the
# step profile's record) and must take the longest ramp, the settle and one hold (parse_args).
MAX_SETTLE_S = 60.0             # a minute at one command: the motor's speed settles in 5 tau (under 1 s,
#                                 motor_dynamics' 20-192 ms) and its temperature in tens of seconds
MAX_HOLD_S = 60.0               # a minute of averaging: the load cell's 80 Hz gives thousands of samples
MAX_RECORD_S = 10.0             # 50 time constants of the slowest motor (192 ms, motor_dynamics)
MAX_STEP_TIMEOUT_S = 300.0      # 5 minutes of one motor at one step, its ramps, holds and record
MAX_SILENT_S = 10.0             # instruments silent longer: the motor spins unwatched
RAMP_RANGE = (1.0, 500.0)       # P/s: from 0 to 255 in 255 s at the slowest; 500 P/s: half a second


class BenchStop(Exception):
    """A safety stop: the motor goes to the stop pulse, the rows so far are kept."""


def counts_for(P: float) -> int:
    return int(round(P / 255.0 * PWM_RANGE))


def parse_values(option: str, text: str, max_p: float) -> list[float]:
    try:
        values = [float(s) for s in text.split(",") if s.strip()]
    except ValueError:
        raise InputError(f"{option} {text!r}: comma-separated command values (0..255) expected") from None
    if not values:
        raise InputError(f"{option}: at least one command value needed")
    for P in values:
        if not 0.0 <= P <= 255.0 or not math.isfinite(P):
            raise InputError(f"{option}: {P:g} is outside the command range 0..255")
        if P > max_p:
            raise InputError(f"{option}: {P:g} exceeds --max {max_p:g} (raise --max deliberately to go higher)")
    return values


def parse_steps(text: str, max_p: float) -> list[float]:
    return parse_values("--steps", text, max_p)


def parse_motors(text: str) -> list[int]:
    motors = [s.strip() for s in text.split(",") if s.strip()]
    if not motors or any(m not in ("1", "2", "3", "4") for m in motors) or len(set(motors)) != len(motors):
        raise InputError(f"--motors {text!r}: motors are numbered 1..4 (docs/conventions.md), each once")
    return [int(m) for m in motors]


def prop_limit(params: Params) -> float:
    """rad/s: the propeller's speed limit by APC's rule, from its diameter."""
    return APC_MR_RPM_INCH / (2.0 * params.airframe.rotor_radius / 0.0254) * ins.RPM


class SimStand:
    """The simulated vehicle clamped to a test stand: after every loop period the rigid body is put
    back at rest, so one spinning motor cannot lift or tip it (the rotors' states are left alone);
    then the simulated instrument takes its turn."""

    def __init__(self, world, clock, instrument=None):
        self.world, self.inner, self.instrument = world, clock, instrument
        self.period = clock.period

    def now(self) -> float:
        return self.inner.now()

    def wait_next(self) -> float:
        t = self.inner.wait_next()
        plant = self.world.plant
        for i in range(12):
            if i != 8:          # keep the heading, zero position, velocity, tilt and rates
                plant.x[i] = 0.0
        plant.on_ground = True
        if self.instrument is not None:
            self.instrument.tick(t)
        return t


@dataclass
class Limits:
    max_p: float = MAX_P
    max_omega: float = math.inf     # rad/s
    step_timeout: float = STEP_TIMEOUT_S
    silent: float = SILENT_S


class Bench:
    """One motor at a time through the Hal, the instruments polled every loop period. Every sample
    goes to `raw` (a csv writer or None); a safety check that fails raises BenchStop."""

    def __init__(self, hal, instruments: ins.Instruments, limits: Limits, ramp: float = RAMP_P_PER_S, raw=None):
        self.hal, self.inst, self.limits, self.ramp_rate, self.raw = hal, instruments, limits, ramp, raw
        self.motor, self.P = 1, 0.0
        self.deadline = math.inf    # bench time by which the step under way must be done (begin_step)
        self.counts = [0, 0, 0, 0]
        self.volts = self.amps = math.nan
        self.next_power = -math.inf
        self.since = None           # bench time from which silence counts

    def tick(self, phase: str) -> list[tuple[float, ins.Sample]]:
        clock = self.hal.clock
        clock.wait_next()
        self.hal.motors.write(self.counts)
        now = clock.now()
        if now >= self.next_power:
            self.next_power = now + POWER_EVERY_S
            self.volts, self.amps = self.hal.power.read()
        got = self.inst.poll(now)
        if self.since is None:
            self.since = now
        last = self.inst.last_at if self.inst.last_at is not None else self.since
        if now > self.deadline:
            raise BenchStop(f"motor {self.motor} at P {self.P:g}: the step took longer than --step-timeout "
                            f"{self.limits.step_timeout:g} s (in its {phase})")
        if now - max(last, self.since) > self.limits.silent:
            raise BenchStop(f"the instruments ({self.inst.name}) went silent: nothing for {now - last:.2f} s"
                            + (f"; last bad line: {self.inst.last_bad}" if self.inst.last_bad else ""))
        out = []
        for t, s in got:
            if math.isnan(s.voltage):
                s = replace(s, voltage=self.volts, current=self.amps)
            if self.raw is not None:
                self.raw.writerow([f"{t:.4f}", self.motor, f"{self.P:g}", phase, f"{s.thrust:.5g}", f"{s.omega:.5g}",
                                   f"{s.voltage:.5g}", f"{s.current:.5g}"])
            if s.omega > self.limits.max_omega:
                raise BenchStop(f"motor {self.motor}: speed {s.omega:.0f} rad/s is beyond the propeller's limit "
                                f"{self.limits.max_omega:.0f} rad/s")
            out.append((t, s))
        return out

    def set(self, P: float) -> None:
        if P > self.limits.max_p:       # parse_values refuses these; the bench never sends one
            raise BenchStop(f"P {P:g} above --max {self.limits.max_p:g}")
        self.counts[self.motor - 1] = counts_for(P)
        self.P = P

    def ramp_to(self, target: float) -> None:
        step = self.ramp_rate * self.hal.clock.period
        P = self.P
        while abs(target - P) > step:
            P += step if target > P else -step
            self.set(P)
            self.tick("ramp")
        self.set(target)
        self.tick("ramp")

    def run_for(self, seconds: float, phase: str) -> list[tuple[float, ins.Sample]]:
        samples = []
        for _ in range(max(1, round(seconds / self.hal.clock.period))):
            samples += self.tick(phase)
        return samples

    def command(self, cmd: str) -> None:
        """Send an instrument command and keep the loop going until it is acknowledged."""
        self.inst.send(cmd)
        deadline = time.monotonic() + ins.ACK_TIMEOUT_S
        while not self.inst.done(cmd):
            if time.monotonic() > deadline:
                raise BenchStop(f"the instruments ({self.inst.name}) did not acknowledge {cmd!r}")
            self.tick("command")

    def start_motor(self, motor: int) -> None:
        """Aim the tachometer at `motor` and tare the load cell, every motor stopped (no step under way:
        the commands have their own timeout)."""
        self.deadline = math.inf
        self.counts = [0, 0, 0, 0]
        self.P, self.motor = 0.0, motor
        self.command(f"M{motor}")
        self.run_for(0.1, "tare")
        self.command("Z")

    def begin_step(self) -> None:
        """A step starts: it must be done, every phase of it, within --step-timeout (`tick` stops it)."""
        self.deadline = self.hal.clock.now() + self.limits.step_timeout

    def steady(self, P: float, settle: float, hold: float) -> tuple:
        """Ramp to P, settle, and average over `hold` until the speed is steady: one bench.csv row."""
        self.begin_step()
        self.ramp_to(P)
        self.run_for(settle, "settle")
        while True:
            window = self.run_for(hold, "hold")
            if len(window) < MIN_SAMPLES:
                raise BenchStop(f"motor {self.motor} at P {P:g}: {len(window)} instrument samples in {hold:g} s")
            w = [s.omega for _, s in window]
            half = len(w) // 2
            a, b = sum(w[:half]) / half, sum(w[half:]) / (len(w) - half)
            if abs(b - a) <= STEADY_REL * abs(b) + STEADY_ABS:
                break
            if self.hal.clock.now() + hold > self.deadline:
                raise BenchStop(f"motor {self.motor} at P {P:g}: the speed did not settle within --step-timeout "
                                f"{self.limits.step_timeout:g} s ({a:.1f} -> {b:.1f} rad/s)")

        def mean(k):
            return sum(getattr(s, k) for _, s in window) / len(window)
        return (self.motor, P, mean("thrust"), mean("omega"), mean("voltage"), mean("current"))

    def step_response(self, P0: float, P1: float, record: float) -> tuple[float, list[tuple[float, float]]]:
        """Jump from P0 (steady) to P1 at once: (t0, [(t, omega)]) for `record` seconds after it."""
        self.begin_step()
        self.set(P1)
        self.tick("step")
        t0 = self.hal.clock.now()      # the new counts went out with that tick
        samples = self.run_for(record, "step")
        return t0, [(t, s.omega) for t, s in samples]

    def finish(self) -> None:
        self.begin_step()
        self.ramp_to(0.0)
        self.deadline = math.inf
        self.counts = [0, 0, 0, 0]
        self.hal.motors.stop()


def fit_time_constant(t0: float, samples: list[tuple[float, float]], w0: float) -> tuple[float, float, float]:
    """The first-order response omega(t) = w1 + (w0 - w1) exp(-(t - t0) / tau) (the motor_dynamics
    cause's lag) fitted to the speed samples after a step at t0, from the steady speed w0 before it:
    (tau s, w0, w1 rad/s). A response already complete at the first sample has no measurable tau
    (a motor without lag, as on the base model): refused, never a tau fitted to the noise."""
    import numpy as np
    from scipy.optimize import curve_fit
    t = np.array([s[0] for s in samples if s[0] >= t0]) - t0
    w = np.array([s[1] for s in samples if s[0] >= t0])
    if len(t) < 6:
        raise BenchStop("the step response has too few samples to fit a time constant")
    w_end = float(w[-len(w) // 4:].mean())
    noise = float(np.std(w[-len(w) // 4:]))
    if abs(w_end - w0) < max(1.0, 5 * noise):
        raise BenchStop(f"the speed did not change ({w0:.0f} -> {w_end:.0f} rad/s) to fit a time constant")
    done = (w[0] - w0) / (w_end - w0)
    if done > 0.9 and abs(w[0] - w_end) < 3 * noise + 1.0:
        bound = t[0] / np.log(10.0)
        raise BenchStop(f"the speed was at its new value ({w0:.0f} -> {w_end:.0f} rad/s) already at the first "
                        f"sample, {t[0] * 1e3:.1f} ms after the step: the motor is faster than this tachometer "
                        f"resolves (tau < {bound * 1e3:.1f} ms), no time constant fitted (the base model has "
                        "no motor lag: --params paper-as-flown has one)")

    def model(t, tau, w1):
        return w1 + (w0 - w1) * np.exp(-t / tau)
    try:
        (tau, w1), _ = curve_fit(model, t, w, p0=(0.05, w_end), bounds=((1e-4, 0.0), (5.0, np.inf)))
    except (RuntimeError, ValueError) as e:
        raise BenchStop(f"the first-order fit of the step response failed: {e}") from None
    return float(tau), float(w0), float(w1)


def write_tau(path: str | Path, base: Params, tau: float, source: str) -> None:
    """Put `[[effect]] cause = "motor_dynamics"` with `tau` into a parameter file (replacing one)."""
    causes.make("motor_dynamics", tau=tau)     # the registry checks the name and the range
    path = Path(path)
    params, tables = base, ("filters",)
    if path.exists():
        params = load(path)
        if "gains" in tomllib.loads(path.read_text()):
            tables = ("gains", "filters")
    effects = tuple(e for e in params.effects if e.cause != "motor_dynamics")
    effects += (EffectSpec("motor_dynamics", (("tau", round(tau, 5)),), source),)
    write_atomic(path, dumps(replace(params, effects=effects), tables=tables))


@dataclass
class Rig:
    board: Board
    instruments: ins.Instruments
    sim: ins.SimInstrument | None = None     # the simulated instrument (tests make it fail)


def open_bench(args, params: Params) -> Rig:
    """The board from the registry and the instruments; a simulated vehicle is clamped to a
    simulated stand whose instrument speaks the line protocol on a pty."""
    kind = ins.parse_spec(args.instruments)[0]
    board = open_board(args.board, params, BoardOptions(board_file=args.board_file, seed=args.seed,
                                                        realtime=args.realtime))
    try:
        if board.world is None:
            return Rig(board, ins.open_instruments(args.instruments))
        if kind != "pty":
            raise InputError(f"--instruments {args.instruments}: a simulated board has simulated instruments (pty)")
        sim, port = ins.sim_pty(board.world, seed=args.seed)
        board.hal.clock = SimStand(board.world, board.hal.clock, sim)
        board.meta = {**board.meta, "board": f"{board.name} (vehicle clamped to a test stand)"}
        return Rig(board, port, sim)
    except BaseException:
        board.close()
        raise


def confirm_clamped(args, board: Board, read=input) -> None:
    if board.world is not None or args.clamped:
        return
    if not sys.stdin.isatty():
        raise InputError("bench: confirm that the vehicle is clamped to the stand with --clamped "
                         "(there is no terminal to ask on)")
    if read("Is the vehicle clamped to the stand, propellers clear of everything? Type 'clamped': ").strip() != "clamped":
        raise InputError("bench: not confirmed clamped; nothing was spun")


def parse_args(argv: list[str]) -> argparse.Namespace:
    p = Parser(prog="flightctl bench", description=__doc__.split("\n\n")[0])
    p.add_argument("--board", default="auto", help=f"the board (default auto: pi5 on a Raspberry Pi 5, else pi): {described('hil')}")
    p.add_argument("--instruments", help="pty (simulated; the default on --board sim), serial:PATH[,BAUD] "
                   "(the line protocol; the default on hardware: serial:/dev/ttyACM0,115200), rcbenchmark:PATH[,BAUD]")
    p.add_argument("--motors", "--motor", default="1,2,3,4", help="motors in turn, e.g. 1,2,3,4 (the default) or 3")
    p.add_argument("--profile", choices=PROFILES, default="staircase",
                   help="staircase: steady points for eq. 26; step: the motor's time constant; both (default staircase)")
    p.add_argument("--steps", default=STEPS, help=f"staircase command values P (0..255), default {STEPS}")
    p.add_argument("--settle", type=float, default=SETTLE_S, help=f"seconds at each P before averaging (0 to {MAX_SETTLE_S:g})")
    p.add_argument("--hold", type=float, default=HOLD_S, help=f"seconds of averaging at each P (at most {MAX_HOLD_S:g})")
    p.add_argument("--step", default=STEP, help=f"step profile: P0,P1 (default {STEP})")
    p.add_argument("--record", type=float, default=RECORD_S, 
                   help=f"step profile: seconds recorded after the jump (at most {MAX_RECORD_S:g})")
    p.add_argument("--max", type=float, default=MAX_P, help=f"largest P allowed (default {MAX_P:g})")
    p.add_argument("--max-rpm", type=float, help="speed limit of the propeller (default and most: APC's, from its diameter)")
    p.add_argument("--step-timeout", type=float, default=STEP_TIMEOUT_S,
                   help=f"seconds a step may take, every phase of it: ramp, settle, holds, record (at most "
                        f"{MAX_STEP_TIMEOUT_S:g}; at least the longest ramp, --settle and --hold)")
    p.add_argument("--silent", type=float, default=SILENT_S,
                   help=f"stop if the instruments say nothing this long (at most {MAX_SILENT_S:g} s)")
    p.add_argument("--ramp", type=float, default=RAMP_P_PER_S,
                   help=f"ramp rate, P units per second ({RAMP_RANGE[0]:g} to {RAMP_RANGE[1]:g})")
    p.add_argument("--clamped", action="store_true", help="confirm that the vehicle is clamped (no prompt)")
    p.add_argument("--out", default="bench.csv", help="bench log to write (default bench.csv)")
    p.add_argument("--raw", help="raw samples (default: OUT's name with -raw)")
    p.add_argument("--plot", help="figure at the end (default: OUT's name with .png)")
    p.add_argument("--no-plot", action="store_true", help="write no figure")
    p.add_argument("--write-params", metavar="P.toml", help="step profile: write the fitted tau (motor_dynamics)")
    p.add_argument("--params", help="parameter file (TOML) or a vehicle name")
    p.add_argument("--board-file", help="pi board wiring (TOML)")
    p.add_argument("--realtime", action="store_true", help="on a simulated board: pace it in real time")
    p.add_argument("--seed", type=seed, default=0, help="on a simulated board: seed of the sensor noise (from 0)")
    args = p.parse_args(argv)
    if args.board == "hil":
        p.error("--board hil: the bench spins motors on a thrust stand (pi) or a simulated one (sim); "
                "the hil board's motors drive a model on a PC")
    # every time and rate bounded (a nan compares false: refused too), so no value keeps a motor spinning
    for flag, value, lo, hi, unit in (("--ramp", args.ramp, *RAMP_RANGE, "P/s"),
                                      ("--settle", args.settle, 0.0, MAX_SETTLE_S, "s"),
                                      ("--hold", args.hold, 0.0, MAX_HOLD_S, "s"),
                                      ("--record", args.record, 0.0, MAX_RECORD_S, "s"),
                                      ("--step-timeout", args.step_timeout, 0.0, MAX_STEP_TIMEOUT_S, "s"),
                                      ("--silent", args.silent, 0.0, MAX_SILENT_S, "s")):
        closed = flag in ("--ramp", "--settle")      # the others must be above 0
        if not (lo <= value <= hi if closed else lo < value <= hi):
            p.error(f"{flag} {value:g}: {'from' if closed else 'above'} {lo:g} to {hi:g} {unit}")
    if not 0.0 < args.max <= 255.0:
        p.error(f"--max {args.max:g}: above 0 to 255 (the command range)")
    if args.max_rpm is not None and not 0.0 < args.max_rpm < math.inf:
        p.error(f"--max-rpm {args.max_rpm:g}: a speed above 0 is needed")
    check_options(args.board, args.board_file)
    if args.instruments is None:
        args.instruments = "pty" if args.board == "sim" else "serial:/dev/ttyACM0,115200"
    if args.write_params and args.profile == "staircase":
        p.error("--write-params needs the step profile (--profile step or both)")
    return args


def _cell(v) -> str:
    if isinstance(v, float):
        return "" if math.isnan(v) else f"{v:.6g}"
    return str(v)


def run_profile(bench: Bench, args, motors, steps, step, writer, flush, progress) -> list[float]:
    """The chosen profile on each motor in turn; returns the fitted time constants."""
    taus, fitted = [], []
    for m in motors:
        bench.start_motor(m)
        prev = None
        if args.profile in ("staircase", "both"):
            for P in steps:
                row = bench.steady(P, args.settle, args.hold)
                writer.writerow([_cell(v) for v in row])
                flush()
                progress.step(f"motor {m} P {P:g}: " + ", ".join(
                    f"{n} {_cell(v) or '-'}" for n, v in zip(BENCH_COLUMNS[2:], row[2:])))
                if prev is not None and P > prev[1] and row[2] < prev[2] - max(FALL_ABS, FALL_REL * prev[2]):
                    raise BenchStop(f"motor {m}: thrust fell from {prev[2]:.3g} N to {row[2]:.3g} N while P rose "
                                    f"from {prev[1]:g} to {P:g} (a loose propeller or load cell?)")
                prev = row
        if args.profile in ("step", "both"):
            rows = [bench.steady(step[0], args.settle, args.hold)]
            t0, samples = bench.step_response(step[0], step[1], args.record)
            rows.append(bench.steady(step[1], 0.0, args.hold))
            for row in rows:
                writer.writerow([_cell(v) for v in row])
            flush()
            tau, w0, w1 = fit_time_constant(t0, samples, rows[0][BENCH_COLUMNS.index("omega")])
            taus.append(tau)
            fitted.append((m, t0, samples, tau, w0, w1))
            progress.step(f"motor {m} step {step[0]:g} -> {step[1]:g}: tau {tau * 1e3:.1f} ms "
                          f"({w0:.0f} -> {w1:.0f} rad/s)")
        bench.finish()
    bench.step_fits = fitted
    return taus


def main(argv: list[str] | None = None) -> int:
    args = parse_args(list(sys.argv[1:] if argv is None else argv))
    steps = parse_steps(args.steps, args.max)
    step = parse_values("--step", args.step, args.max)
    if len(step) != 2 or step[1] == step[0]:
        raise InputError(f"--step {args.step!r}: two different command values P0,P1 expected")
    motors = parse_motors(args.motors)
    # a step's ramp (from the stop pulse: each motor starts at P = 0), settle and first hold, and the
    # step profile's record, each within --step-timeout: a timeout shorter stops every step, a wasted run
    longest = max(steps + step) / args.ramp + args.settle + args.hold
    if max(longest, args.record) > args.step_timeout:
        raise InputError(f"--step-timeout {args.step_timeout:g}: shorter than one step ({max(steps + step):g} / "
                         f"--ramp {args.ramp:g} + --settle {args.settle:g} + --hold {args.hold:g} = {longest:.3g} s"
                         + (f"; --record {args.record:g} s" if args.record > longest else "") + ")")
    kind = ins.parse_spec(args.instruments)[0]
    if kind == "rcbenchmark" and len(motors) > 1:
        raise InputError("--instruments rcbenchmark: the stand holds one motor; run one motor at a time (--motors N)")
    params = load(args.params)
    if args.max_rpm is not None and args.max_rpm * ins.RPM > prop_limit(params):
        raise InputError(f"--max-rpm {args.max_rpm:g}: above the propeller's own limit, "
                         f"{prop_limit(params) / ins.RPM:.0f} RPM (APC's {APC_MR_RPM_INCH:.0f} RPM-inch over its "
                         "diameter, from the parameter file's rotor_radius): --max-rpm lowers it, never raises it")
    limits = Limits(args.max, prop_limit(params) if args.max_rpm is None else args.max_rpm * ins.RPM,
                    args.step_timeout, args.silent)
    # every output checked before a motor turns: a run's measurements are never lost at the end
    out = output_file(args.out, "--out", ".csv")
    raw_path = output_file(args.raw if args.raw else out.with_name(f"{out.stem}-raw.csv"), "--raw", ".csv")
    if raw_path.resolve() == out.resolve():
        raise InputError(f"--raw {raw_path}: the same file as --out: the raw samples would overwrite the bench log")
    if args.plot and args.no_plot:
        raise InputError("--plot and --no-plot exclude each other")
    if not args.no_plot:
        output_file(args.plot or out.with_suffix(".png"), "--plot", ".png")
    if args.write_params:
        output_file(args.write_params, "--write-params", ".toml")

    def on_term(signum, frame):
        raise KeyboardInterrupt

    try:
        rig = open_bench(args, params)
    except BoardUnavailable as e:
        print(f"flightctl bench: cannot open the {args.board} board: {e}", file=sys.stderr)
        return EXIT_UNAVAILABLE
    board, hal = rig.board, rig.board.hal
    previous = signal.signal(signal.SIGTERM, on_term)
    status, taus = 0, []
    meta = {"board": board.name, **board.meta, "instruments": rig.instruments.name, "motors": args.motors,
            "profile": args.profile, "steps": ",".join(f"{P:g}" for P in steps), "settle_s": args.settle,
            "hold_s": args.hold, "max_P": args.max, "max_omega_rad_s": f"{limits.max_omega:.1f}"}
    try:
        confirm_clamped(args, board)
        with open(out, "w", newline="") as f, open(raw_path, "w", newline="") as fr:
            for fh in (f, fr):
                fh.write(f"# software: flightctl {__version__}\n")
                fh.writelines(f"# {k}: {v}\n" for k, v in meta.items())
            writer, raw = csv.writer(f), csv.writer(fr)
            writer.writerow(BENCH_COLUMNS)
            raw.writerow(RAW_COLUMNS)
            bench = Bench(hal, rig.instruments, limits, args.ramp, raw)
            total = len(motors) * ((len(steps) if args.profile != "step" else 0) + (args.profile != "staircase"))
            try:
                hal.motors.stop()
                hal.motors.arm()
                taus = run_profile(bench, args, motors, steps, step, writer,
                                   lambda: (f.flush(), fr.flush()), Progress(total, "bench "))
            except (KeyboardInterrupt, SystemError) as e:   # (numba reports Ctrl-C as a SystemError)
                if not interrupted(e):
                    raise
                hal.motors.stop()
                print(f"bench: interrupted: motor {bench.motor} at the stop pulse", file=sys.stderr)
                status = EXIT_INTERRUPTED
                for fh in (f, fr):
                    fh.write(f"# partial: interrupted on motor {bench.motor}\n")
            except BenchStop as e:
                hal.motors.stop()
                print(f"bench: stopped: {e}; motor {bench.motor} at the stop pulse", file=sys.stderr)
                status = EXIT_STOPPED
                for fh in (f, fr):
                    fh.write(f"# partial: stopped: {' '.join(str(e).split())}\n")
            finally:
                hal.motors.stop()
    finally:
        rig.instruments.close()
        board.close()
        signal.signal(signal.SIGTERM, previous)
    if taus and args.write_params:
        tau = sum(taus) / len(taus)
        write_tau(args.write_params, params, tau, f"flightctl bench step profile {step[0]:g} -> {step[1]:g}, "
                  f"motors {args.motors}: tau {', '.join(f'{t * 1e3:.1f}' for t in taus)} ms, mean")
        print(f"bench: motor_dynamics tau = {tau * 1e3:.1f} ms written to {args.write_params}", file=sys.stderr)
    if not args.no_plot and out.exists():
        from flightctl.hil.benchplot import plot_bench
        try:
            plot_bench(out, raw_path, getattr(bench, "step_fits", []), args.plot or out.with_suffix(".png"))
        except InputError as e:                  # stopped before the first row
            print(f"bench: no figure ({e})", file=sys.stderr)
    print(f"bench: {out} (raw samples: {raw_path})", file=sys.stderr)
    return status


if __name__ == "__main__":
    sys.exit(main())
