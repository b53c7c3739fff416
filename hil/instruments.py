"""The bench's instruments over serial (docs/hil.md, "Bench instruments"): thrust and propeller speed
streamed by a microcontroller (a load cell and optical tachometers) in a small line protocol, or by an
RCbenchmark stand as its CSV stream; both read through pyserial. Voltage and current come over the
same line when the instrument has them, else from the onboard INA219 (the bench reads it).

The line protocol (ASCII lines, `\\n`-terminated, 115200 baud 8N1):

    instrument -> host   $FCB,<ms>,<grams>,<rpm>[,<volts>,<amps>]*<XX>   one sample
                         #<text>                                       information, ignored
                         #ok <command>                                 a command was done
    host -> instrument   M<n>   aim the tachometer at motor n (1..4)
                         Z      tare the load cell (the motors stopped)

`ms` is the instrument's clock (milliseconds, whole or decimal), `grams` the load cell (gram-force:
the whole clamped vehicle stands on it), `rpm` the tachometer (revolutions of the propeller per
minute), `volts` and `amps` the supply if the instrument measures it (empty fields: it does not).
`XX` is the NMEA checksum: the XOR of the characters between `$` and `*`, two hex digits. A line
with a bad checksum or a bad field is counted and dropped.

Conversions to SI happen here, at the edge: gram-force -> N (G / 1000), RPM -> rad/s.
"""
from __future__ import annotations

import math
import os
import random
import select
import time
import tty
from collections import deque
from dataclasses import dataclass
from functools import reduce
from typing import Callable

from flightctl.errors import InputError
from flightctl.physics import G, rotor_speed
from flightctl.sim.identify.realdata import RCB

GF = G * 1e-3                       # N per gram-force
RPM = 2.0 * math.pi / 60.0          # rad/s per rev/min
DEFAULT_BAUD = 115200
ACK_TIMEOUT_S = 2.0                 # wall-clock time an instrument has to answer a command
RCB_OPTICAL = "Motor Optical Speed (RPM)"


@dataclass(frozen=True)
class Sample:
    """One instrument sample in SI units. `t` is the instrument's clock (s), None if it has none;
    voltage and current are NaN when the instrument does not measure them."""
    t: float | None
    thrust: float
    omega: float
    voltage: float = math.nan
    current: float = math.nan


def checksum(body: str) -> str:
    return f"{reduce(lambda a, c: a ^ ord(c), body, 0):02X}"


def encode(ms: float, grams: float, rpm: float, volts: float | None = None, amps: float | None = None) -> str:
    """One sample line of the protocol (what the microcontroller's firmware prints)."""
    body = f"FCB,{ms:.1f},{grams:.1f},{rpm:.0f}"
    if volts is not None:
        body += f",{volts:.3f},{amps:.3f}"
    return f"${body}*{checksum(body)}\n"


def parse_fcb(line: str) -> Sample | None:
    """A protocol line -> Sample, None for an information line; ValueError for a bad line."""
    line = line.strip()
    if not line or line.startswith("#"):
        return None
    body, star, given = line[1:].partition("*")
    if not line.startswith("$") or not star or given.upper() != checksum(body):
        raise ValueError(f"bad checksum or framing: {line!r}")
    fields = body.split(",")
    if fields[0] != "FCB" or len(fields) not in (4, 6):
        raise ValueError(f"expected $FCB,ms,grams,rpm[,volts,amps]: {line!r}")
    ms, grams, rpm = (float(x) for x in fields[1:4])
    volts = amps = math.nan
    if len(fields) == 6 and fields[4] and fields[5]:
        volts, amps = float(fields[4]), float(fields[5])
    values = (ms, grams, rpm, volts, amps)
    if any(math.isinf(v) for v in values) or math.isnan(ms) or rpm < 0:
        raise ValueError(f"out-of-range field: {line!r}")
    return Sample(ms * 1e-3, grams * GF, rpm * RPM, volts, amps)


class RcbenchmarkParser:
    """The RCbenchmark stand's CSV stream (the columns of its log files, sim/identify/realdata.py's
    RCB): the header line names the columns, each further line is one sample. The stand's software
    drives its own clock, so samples carry no instrument time (the host's receipt time is used);
    speed from the optical probe when it reads, else the ESC's electrical speed (in mechanical RPM,
    as the software reports it)."""

    def __init__(self):
        self.index: dict[str, int] | None = None

    def __call__(self, line: str) -> Sample | None:
        cells = [c.strip() for c in line.lstrip("\ufeff").rstrip("\r\n").split(",")]
        if self.index is None:
            if RCB["thrust"] not in cells:
                return None                       # before the header
            self.index = {name: i for i, name in enumerate(cells)}
            missing = [c for c in (RCB["thrust"], RCB["rpm"], RCB["voltage"], RCB["current"]) if c not in self.index]
            if missing:
                self.index = None
                raise ValueError(f"RCbenchmark header without {', '.join(missing)}")
            return None
        if RCB["thrust"] in cells:
            return None                           # the header again (a new recording)
        ix = self.index

        def cell(name: str) -> float:
            i = ix.get(name)
            text = cells[i] if i is not None and i < len(cells) else ""
            return float(text) if text else math.nan

        rpm = cell(RCB_OPTICAL)
        if not rpm > 0:
            rpm = cell(RCB["rpm"])
        thrust = cell(RCB["thrust"])
        if math.isnan(thrust) or math.isnan(rpm):
            raise ValueError(f"RCbenchmark row without thrust or speed: {line.strip()!r}")
        return Sample(None, thrust * GF, rpm * RPM, cell(RCB["voltage"]), cell(RCB["current"]))


class Instruments:
    """Samples from a line stream through pyserial. `poll(now)` reads what has arrived (never blocks,
    except in lock-step with a simulated instrument: then it waits for every line that instrument
    wrote) and returns the new samples with their time on the bench clock: the instrument's clock
    plus the smallest offset seen (the least-delayed line), or the receipt time if it has no clock."""

    def __init__(self, ser, parse: Callable[[str], Sample | None], name: str, commands: bool,
                 lockstep: Callable[[], int] | None = None):
        self.ser, self.parse, self.name, self.commands, self.lockstep = ser, parse, name, commands, lockstep
        self.buffer = b""
        self.lines = 0            # lines received (samples, information, bad)
        self.bad = 0              # lines dropped: checksum, framing, fields
        self.last_bad = ""
        self.offset = math.inf    # bench clock - instrument clock (s)
        self.last_at: float | None = None   # bench time of the last sample
        self.acks: list[str] = []

    def _read(self) -> None:
        waiting = self.ser.in_waiting
        if waiting:
            self.buffer += self.ser.read(waiting)

    def poll(self, now: float) -> list[tuple[float, Sample]]:
        self._read()
        if self.lockstep is not None:
            deadline = time.monotonic() + ACK_TIMEOUT_S
            while self.lines + self.buffer.count(b"\n") < self.lockstep() and time.monotonic() < deadline:
                select.select([self.ser.fileno()], [], [], 0.05)
                self._read()
        out = []
        *lines, self.buffer = self.buffer.split(b"\n")
        for raw in lines:
            self.lines += 1
            text = raw.decode("ascii", "replace")
            if text.startswith("#ok "):
                self.acks.append(text[4:].strip())
                continue
            try:
                s = self.parse(text)
            except ValueError as e:
                self.bad += 1
                self.last_bad = str(e)
                continue
            if s is None:
                continue
            if s.t is None:
                t = now
            else:
                self.offset = min(self.offset, now - s.t)
                t = s.t + self.offset
            self.last_at = now
            out.append((t, s))
        return out

    def send(self, command: str) -> None:
        if self.commands:
            self.ser.write(command.encode("ascii") + b"\n")

    def done(self, command: str) -> bool:
        """True once the instrument acknowledged `command` (always, for one that takes none)."""
        if not self.commands:
            return True
        if command in self.acks:
            self.acks.remove(command)
            return True
        return False

    def close(self) -> None:
        self.ser.close()


def open_serial(path: str, baud: int):
    try:
        import serial
    except ModuleNotFoundError:
        raise InputError("serial instruments need pyserial (pip install pyserial: it comes with pip install . from the checkout)") from None
    try:
        return serial.Serial(path, baud, timeout=0)
    except (serial.SerialException, OSError) as e:
        raise InputError(f"--instruments: cannot open the serial port {path}: {e}") from None


def parse_spec(spec: str) -> tuple[str, str, int]:
    """`pty`, `serial:PATH[,BAUD]` or `rcbenchmark:PATH[,BAUD]` -> (kind, path, baud)."""
    kind, sep, rest = spec.partition(":")
    if kind == "pty" and not sep:
        return kind, "", DEFAULT_BAUD
    if kind in ("serial", "rcbenchmark") and rest:
        path, _, baud = rest.partition(",")
        if baud and (not baud.isdigit() or int(baud) <= 0):
            raise InputError(f"--instruments {spec!r}: the baud rate must be a positive whole number")
        return kind, path, int(baud) if baud else DEFAULT_BAUD
    raise InputError(f"--instruments {spec!r}: pty, serial:/dev/ttyACM0[,115200] or rcbenchmark:/dev/ttyUSB0[,BAUD] "
                     "expected")


@dataclass
class InstrumentNoise:
    """The simulated instrument's errors: an HX711 load-cell amplifier at 80 samples/s (a 5 kg cell
    reads to about 1 g rms) and an optical tachometer timing blade passes (0.2 % rms), plus the load
    cell's offset before the tare (the clamp and the frame on it)."""
    thrust_sigma: float = 1.0 * GF      # N
    speed_rel_sigma: float = 2e-3       # relative
    offset: float = 1.8 * G             # N on the load cell before the tare
    load_cell_hz: float = 80.0          # HX711 RATE pin high
    line_hz: float = 200.0              # the firmware's sample lines (the tachometer's gate)

    @staticmethod
    def off() -> "InstrumentNoise":
        return InstrumentNoise(0.0, 0.0, 0.0)


class SimInstrument:
    """The bench microcontroller on the simulated stand, behind the master end of a pty: at its line
    rate it prints the protocol line of the load cell (the sum of the four rotors' thrusts, the
    simulated world's truth, plus its offset and noise, updated at the HX711's rate) and of the
    tachometer aimed at one rotor; it obeys M<n> and Z. `tick()` runs once per simulated loop period.
    `fault`: None or 'silent' (it stops printing samples); `thrust_gain` below 1: the load cell slips."""

    def __init__(self, world, fd: int, noise: InstrumentNoise | None = None, seed: int = 0):
        self.world, self.fd = world, fd
        self.noise = noise if noise is not None else InstrumentNoise()
        self.rng = random.Random(seed ^ 0xBE5C)
        self.motor = 1
        self.tare = 0.0
        self.load = self.noise.offset
        self.recent = deque([self.load], maxlen=10)
        self.next_line = self.next_load = 0.0
        self.sent = 0
        self.fault: str | None = None
        self.thrust_gain = 1.0            # a load cell slipping in its mount: tests set it below 1
        self._inbox = b""
        os.set_blocking(fd, False)

    def truth(self) -> tuple[float, float]:
        """(load on the cell: the sum of the rotors' thrusts, N; the aimed rotor's speed, rad/s)."""
        plant = self.world.plant
        f = plant.model.forces(plant.t, plant.x, plant.u)[0]
        return sum(f), rotor_speed(f[self.motor - 1], self.world.a.c1)   # eq. 27

    def _commands(self) -> None:
        try:
            self._inbox += os.read(self.fd, 256)
        except (BlockingIOError, OSError):
            return
        *cmds, self._inbox = self._inbox.split(b"\n")
        for raw in cmds:
            cmd = raw.decode("ascii", "replace").strip()
            if cmd == "Z":                   # tare on the mean of the last readings (HX711 libraries' tare(10))
                self.tare = sum(self.recent) / len(self.recent)
            elif cmd[:1] == "M" and cmd[1:] in ("1", "2", "3", "4"):
                self.motor = int(cmd[1:])
            else:
                self._write(f"#unknown command {cmd!r}\n")
                continue
            self._write(f"#ok {cmd}\n")

    def _write(self, line: str) -> None:
        try:
            os.write(self.fd, line.encode("ascii"))
            self.sent += 1
        except BlockingIOError:
            pass                            # the host does not read: lines are lost, as on a UART

    def tick(self, t: float) -> None:
        self._commands()
        n, g = self.noise, self.rng.gauss
        if t + 1e-9 < self.next_line or self.fault == "silent":
            return
        self.next_line = t + 1.0 / n.line_hz
        load, omega = self.truth()
        if t + 1e-9 >= self.next_load:
            self.next_load = t + 1.0 / n.load_cell_hz
            self.load = load * self.thrust_gain + n.offset + g(0.0, n.thrust_sigma)
            self.recent.append(self.load)
        omega *= 1.0 + g(0.0, n.speed_rel_sigma)
        self._write(encode(t * 1e3, (self.load - self.tare) / GF, max(omega, 0.0) / RPM))


def sim_pty(world, noise: InstrumentNoise | None = None, seed: int = 0) -> tuple[SimInstrument, Instruments]:
    """A simulated instrument on a pty's master end, and the bench's side on its slave end through
    pyserial, in lock-step (the bench waits for each line the simulated instrument wrote)."""
    master, slave = os.openpty()
    tty.setraw(slave)                       # no echo, no line editing, before anything is written
    sim = SimInstrument(world, master, noise, seed)
    ser = open_serial(os.ttyname(slave), DEFAULT_BAUD)
    os.close(slave)                         # pyserial holds its own descriptor
    port = Instruments(ser, parse_fcb, "simulated load cell and tachometer (pty)", True, lockstep=lambda: sim.sent)
    real_close = port.close

    def close() -> None:
        real_close()
        os.close(master)
    port.close = close
    return sim, port


def open_instruments(spec: str) -> Instruments:
    """The instruments of a real bench: `serial:` speaks the line protocol, `rcbenchmark:` is the stand's CSV."""
    kind, path, baud = parse_spec(spec)
    if kind == "pty":
        raise InputError("--instruments pty: simulated instruments need a simulated board (--board sim)")
    if kind == "serial":
        return Instruments(open_serial(path, baud), parse_fcb, f"line protocol on {path}", True)
    return Instruments(open_serial(path, baud), RcbenchmarkParser(), f"RCbenchmark stream on {path}", False)
