"""`flightctl bench`: spin one motor at a time for identification (the paper's thrust stand, Fig. 3).

    flightctl bench --board sim|pi --motor N --steps P1,P2,... [--max P] [--ramp P_PER_S]
                    [--settle S] [--hold S] [--out bench.csv] [--ask]

For each command value P (0..255, the paper's scale): ramp the one motor from where it is to P at
`--ramp` P units per second, let it settle, then hold and average the supply voltage and current
(the power monitor) over `--hold` seconds, and write one `bench.csv` row
`motor, P, thrust, omega, voltage, current` (SI; the format of measured-data.md, which
`flightctl identify bench` fits). At the end the motor ramps down and stops.

Safety: the other three motors stay at the stop pulse throughout; no step may exceed `--max`
(default 200, above the 172 of hover); the ESC output is checked by `Motors.arm()` first (on the Pi:
the real 449 Hz, measured); Ctrl-C or SIGTERM stops the motor at once (zero thrust in `finally`),
keeping the rows written so far; exit status 130.

Thrust and propeller speed: on `--board sim` they are the simulator's truth for that motor (eq. 26
and 27 of the identified model, behind the same PWM counts). On the Pi the scale and the tachometer
are manual instruments, as in the paper: with `--ask` the operator types the scale reading (grams)
and the tachometer (RPM) at each step, converted to N and rad/s here, while the motor keeps spinning
(a thread keeps writing, so the ESC dead-man stays fed); without `--ask` those cells stay empty and a
`# note:` line says so, for the operator to fill in.
"""
from __future__ import annotations

import argparse
import csv
import math
import signal
import sys
import threading
from pathlib import Path
from typing import Callable

from flightctl import __version__
from flightctl.boards import Board, BoardOptions, BoardUnavailable, described, open_board
from flightctl.errors import InputError
from flightctl.hal import PWM_RANGE, Hal
from flightctl.logfile import BENCH_COLUMNS
from flightctl.params import Params, load
from flightctl.physics import G, rotor_speed
MAX_P = 200.0
RAMP_P_PER_S = 50.0
SETTLE_S = 2.0
HOLD_S = 2.0
POWER_EVERY_S = 0.1
HOLDER_PERIOD_S = 0.02
EXIT_UNAVAILABLE = 3          # the board cannot be opened (as `flightctl run`)
RPM_TO_RAD_S = 2.0 * math.pi / 60.0
MANUAL_NOTE = ("thrust and omega are manual instruments on the Pi (scale and tachometer, as in the paper): "
               "fill them in, thrust in N, omega in rad/s")


def counts_for(P: float) -> int:
    return int(round(P / 255.0 * PWM_RANGE))


def parse_steps(text: str, max_p: float) -> list[float]:
    try:
        steps = [float(s) for s in text.split(",") if s.strip()]
    except ValueError:
        raise InputError(f"--steps {text!r}: comma-separated command values (0..255) expected") from None
    if not steps:
        raise InputError("--steps: at least one command value needed")
    for P in steps:
        if not 0.0 <= P <= 255.0 or not math.isfinite(P):
            raise InputError(f"--steps: {P:g} is outside the command range 0..255")
        if P > max_p:
            raise InputError(f"--steps: {P:g} exceeds --max {max_p:g} (raise --max deliberately to go higher)")
    return steps


class SimStand:
    """The simulated vehicle bolted to a test stand: after every loop period the rigid body is put
    back at rest, so one spinning motor cannot lift or tip it; the rotor truth stays the model's."""

    def __init__(self, world, clock):
        self.world, self.inner = world, clock
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
        return t

    def truth(self, motor: int) -> tuple[float, float]:
        """Thrust (N) and propeller speed (rad/s) of motor 1..4 now."""
        plant = self.world.plant
        f, _, _, _ = plant.model.forces(plant.t, plant.x, plant.u)
        thrust = f[motor - 1]
        return thrust, rotor_speed(thrust, self.world.a.c1)   # eq. 27


class Holder(threading.Thread):
    """Keeps writing the same counts (the ESC dead-man needs them) while the main thread waits for
    the operator."""

    def __init__(self, motors, counts: list[int]):
        super().__init__(daemon=True, name="bench-holder")
        self.motors, self.counts = motors, counts
        self.done = threading.Event()
        self.error: BaseException | None = None

    def run(self) -> None:
        try:
            while not self.done.wait(HOLDER_PERIOD_S):
                self.motors.write(self.counts)
        except BaseException as e:     # reported by the main thread
            self.error = e

    def stop(self) -> None:
        self.done.set()
        self.join(timeout=1.0)


class Bench:
    def __init__(self, hal: Hal, motor: int, truth: Callable[[int], tuple[float, float]] | None = None,
                 ask: Callable[[int, float], tuple[float | None, float | None]] | None = None,
                 ramp: float = RAMP_P_PER_S, settle_s: float = SETTLE_S, hold_s: float = HOLD_S):
        if motor not in (1, 2, 3, 4):
            raise InputError(f"--motor {motor}: motors are numbered 1..4 (conventions.md)")
        self.hal, self.motor, self.truth, self.ask = hal, motor, truth, ask
        self.ramp_rate, self.settle_s, self.hold_s = ramp, settle_s, hold_s
        self.P = 0.0
        self.counts = [0, 0, 0, 0]
        self.last_counts: list[int] = [0, 0, 0, 0]

    def _write(self, P: float) -> None:
        c = self.counts
        c[self.motor - 1] = counts_for(P)
        self.hal.clock.wait_next()
        self.hal.motors.write(c)
        self.last_counts = list(c)
        self.P = P

    def ramp_to(self, target: float) -> None:
        dt = self.hal.clock.period
        step = self.ramp_rate * dt
        P = self.P
        while abs(target - P) > step:
            P += step if target > P else -step
            self._write(P)
        self._write(target)

    def hold(self, seconds: float, measure: bool) -> tuple[float, float, float, float]:
        """Hold the command; with `measure`, average (voltage, current, thrust, omega)."""
        dt = self.hal.clock.period
        every = max(1, round(POWER_EVERY_S / dt))
        n = max(1, round(seconds / dt))
        v = i = f = w = 0.0
        nv = nt = 0
        for k in range(n):
            self._write(self.P)
            if measure and k % every == 0:
                volts, amps = self.hal.power.read()
                v, i, nv = v + volts, i + amps, nv + 1
                if self.truth is not None:
                    tf, tw = self.truth(self.motor)
                    f, w, nt = f + tf, w + tw, nt + 1
        nan = math.nan
        return (v / nv if nv else nan, i / nv if nv else nan, f / nt if nt else nan, w / nt if nt else nan)

    def step(self, P: float) -> tuple:
        self.ramp_to(P)
        self.hold(self.settle_s, measure=False)
        volts, amps, thrust, omega = self.hold(self.hold_s, measure=True)
        if self.truth is None and self.ask is not None:
            holder = Holder(self.hal.motors, list(self.last_counts))
            holder.start()
            try:
                thrust, omega = self.ask(self.motor, P)
            finally:
                holder.stop()
            if holder.error is not None:
                raise holder.error
            thrust = math.nan if thrust is None else thrust
            omega = math.nan if omega is None else omega
        return (self.motor, P, thrust, omega, volts, amps)

    def finish(self) -> None:
        self.ramp_to(0.0)
        self.hal.motors.stop()


def ask_operator(motor: int, P: float, read: Callable[[str], str] = input) -> tuple[float | None, float | None]:
    """Scale reading in grams and tachometer in RPM (Enter skips) -> N and rad/s."""
    def number(prompt: str) -> float | None:
        while True:
            text = read(prompt).strip()
            if not text:
                return None
            try:
                return float(text)
            except ValueError:
                print(f"  {text!r} is not a number", file=sys.stderr)

    grams = number(f"motor {motor} at P = {P:g}: scale reading in g (Enter to skip): ")
    rpm = number(f"motor {motor} at P = {P:g}: tachometer in RPM (Enter to skip): ")
    return (None if grams is None else grams * 1e-3 * G, None if rpm is None else rpm * RPM_TO_RAD_S)


def _cell(v) -> str:
    if isinstance(v, float):
        return "" if math.isnan(v) else f"{v:.6g}"
    return str(v)


def open_bench(args, params: Params) -> tuple[Board, Callable[[int], tuple[float, float]] | None]:
    """The board from the registry, and the instruments: a simulated vehicle is bolted to a test stand
    and its rotors' truth is read; on hardware the scale and the tachometer are the operator's (None)."""
    board = open_board(args.board, params, BoardOptions(board_file=args.board_file, seed=args.seed,
                                                        realtime=args.realtime))
    if board.world is None:
        return board, None
    stand = SimStand(board.world, board.hal.clock)
    board.hal.clock = stand
    board.meta = {**board.meta, "board": f"{board.name} (vehicle on a test stand)"}
    return board, stand.truth


def parse_args(argv: list[str]) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="flightctl bench", description=__doc__.split("\n\n")[0])
    p.add_argument("--board", default="pi", help=f"the board (default pi): {described()}")
    p.add_argument("--motor", type=int, required=True, help="1..4 (conventions.md numbering)")
    p.add_argument("--steps", required=True, help="command values P (0..255), e.g. 130,150,170")
    p.add_argument("--max", type=float, default=MAX_P, help=f"largest P allowed (default {MAX_P:g})")
    p.add_argument("--ramp", type=float, default=RAMP_P_PER_S, help="ramp rate, P units per second")
    p.add_argument("--settle", type=float, default=SETTLE_S, help="seconds at each P before measuring")
    p.add_argument("--hold", type=float, default=HOLD_S, help="seconds of averaging at each P")
    p.add_argument("--out", default="bench.csv", help="bench log to write (default bench.csv)")
    p.add_argument("--params", help="parameter file (TOML)")
    p.add_argument("--board-file", help="pi board wiring (TOML)")
    p.add_argument("--ask", action="store_true", help="on the Pi: ask for the scale and tachometer readings")
    p.add_argument("--realtime", action="store_true", help="on a simulated board: pace it in real time")
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args(argv)
    if not 0 < args.ramp <= 500:
        p.error("--ramp: 0 < P/s <= 500")
    if args.settle < 0 or args.hold <= 0:
        p.error("--settle must be >= 0 and --hold > 0")
    return args


def main(argv: list[str] | None = None) -> int:
    args = parse_args(list(sys.argv[1:] if argv is None else argv))
    steps = parse_steps(args.steps, args.max)
    params = load(args.params)
    if args.motor not in (1, 2, 3, 4):     # before touching any hardware
        raise InputError(f"--motor {args.motor}: motors are numbered 1..4 (conventions.md)")

    def on_term(signum, frame):
        raise KeyboardInterrupt

    try:
        board, truth = open_bench(args, params)
    except BoardUnavailable as e:
        print(f"flightctl bench: cannot open the {args.board} board: {e}", file=sys.stderr)
        return EXIT_UNAVAILABLE
    previous = signal.signal(signal.SIGTERM, on_term)
    hal, meta = board.hal, {"board": board.name, **board.meta}
    ask = ask_operator if (truth is None and args.ask) else None
    bench = Bench(hal, args.motor, truth, ask, args.ramp, args.settle, args.hold)
    out = Path(args.out)
    status = 0
    try:
        with open(out, "w", newline="") as f:
            f.write(f"# software: flightctl {__version__}\n")
            for key, value in meta.items():
                f.write(f"# {key}: {value}\n")
            f.write(f"# motor: {args.motor}\n# steps: {','.join(f'{P:g}' for P in steps)}\n")
            if truth is None and ask is None:
                f.write(f"# note: {MANUAL_NOTE}\n")
            writer = csv.writer(f)
            writer.writerow(BENCH_COLUMNS)
            f.flush()
            try:
                hal.motors.stop()
                hal.motors.arm()
                for P in steps:
                    row = bench.step(P)
                    writer.writerow([_cell(v) for v in row])
                    f.flush()
                    print(f"motor {args.motor}  P {P:6.1f}  " + "  ".join(
                        f"{name} {_cell(v) or '-'}" for name, v in zip(BENCH_COLUMNS[2:], row[2:])), file=sys.stderr)
                bench.finish()
            except KeyboardInterrupt:
                print("bench: interrupted: motors stopped", file=sys.stderr)
                status = 130
            finally:
                hal.motors.stop()
    finally:
        board.close()
        signal.signal(signal.SIGTERM, previous)
    print(f"bench: {out}", file=sys.stderr)
    return status


if __name__ == "__main__":
    sys.exit(main())
