"""The PC side of hardware-in-the-loop: the simulated plant and its sensors answering the flight side
over the link (flightctl/comms/link.py, docs/hil.md).

The sensors are the simulator's register-level devices (`flightctl.sim.world.devices`): every loop the
simulated MPU-9250 is burst-read from ACCEL_XOUT_H and its 21 raw bytes go out, with the simulated
INA219's two voltage registers and the simulated HC-SR04's echo edges (level and microsecond tick).
The flight side's start-up transfers (REQUEST frames) are done on the same simulated chips.

Modes: `lockstep` steps the plant one loop period per command received (the PC waits for each command:
simulated time follows the flight loop exactly); `free` steps it on the PC's own wall clock at the loop
rate with the newest command (a late command is simply missed, as a real plant would).
"""
from __future__ import annotations

import math
import struct
import time
from dataclasses import dataclass, field

from flightctl.comms import link as lk
from flightctl.drivers import ina219_regs as ina
from flightctl.drivers import mpu9250_regs as reg
from flightctl.hal import PWM_RANGE
from flightctl.boards.hil import SONAR_TRIGGER_PIN
from flightctl.params import Params
from flightctl.sim import causes
from flightctl.sim.world.devices import SensorNoise, SimClock, SimMotors, World
from flightctl.sim.world.imu import SimMpu9250
from flightctl.sim.world.power import SimIna219, SimSMBus

IDLE_S = 3.0            # no frame for this long once flying: the flight side is gone
CRASH_TILT = math.radians(60)
_U16 = struct.Struct("<H")


class HilPlant:
    """The simulated quadcopter at its devices' boundary."""

    def __init__(self, params: Params, seed: int = 0, noise: SensorNoise | None = None, substeps: int | None = None):
        carried = causes.carried(params)
        self.world = w = World(params.airframe, carried, noise if noise is not None else SensorNoise(), seed, substeps)
        self.imu = SimMpu9250(w)
        self.bus = SimSMBus(SimIna219(w))
        self.motors = SimMotors(w)
        self.clock = SimClock(w)
        self.edges: list[tuple[int, int, int]] = []
        self._burst = [reg.READ | reg.ACCEL_XOUT_H] + [0] * reg.BURST_LEN
        self.max_alt = 0.0
        self.crashed = False

    def request(self, payload: bytes) -> bytes:
        """One start-up transfer of the flight side's drivers; a failed I2C transfer answers b"\\x01"."""
        if not payload:
            return b""
        dev, data = payload[0], payload[1:]
        try:
            if dev == lk.DEV_SPI and data:
                return bytes(self.imu.xfer2(list(data)))
            if dev == lk.DEV_I2C_READ and len(data) == 3:
                return bytes(self.bus.read_i2c_block_data(data[0], data[1], data[2]))
            if dev == lk.DEV_I2C_WRITE and len(data) >= 2:
                self.bus.write_i2c_block_data(data[0], data[1], list(data[2:]))
                return b""
            if dev == lk.DEV_GPIO_WATCH and len(data) == 3:
                pin, ms = data[0], _U16.unpack_from(data, 1)[0]
                if pin:
                    gpio = self.world.gpio
                    if pin not in gpio.callbacks:
                        gpio.callback(pin, 2, self._edge)
                    gpio.set_watchdog(pin, ms)
                return b""
        except OSError:
            return b"\x01"
        return b"\x01"

    def _edge(self, pin: int, level: int, tick: int) -> None:
        self.edges.append((pin, level, tick))

    def step(self, counts, trigger: bool) -> None:
        self.motors.write(counts)
        if trigger:
            self.world.gpio.gpio_trigger(SONAR_TRIGGER_PIN, 10, 1)
        self.clock.wait_next()
        x = self.world.plant.x
        self.max_alt = max(self.max_alt, x[2])
        if not (abs(x[6]) <= CRASH_TILT and abs(x[7]) <= CRASH_TILT):
            self.crashed = True

    def sensors(self, ack: int) -> bytes:
        burst = bytes(self.imu.xfer2(self._burst)[1:])
        bus = self.bus.read_i2c_block_data(ina.DEFAULT_ADDRESS, ina.BUS_VOLTAGE, 2)
        shunt = self.bus.read_i2c_block_data(ina.DEFAULT_ADDRESS, ina.SHUNT_VOLTAGE, 2)
        edges, self.edges = self.edges[:lk.MAX_EDGES], self.edges[lk.MAX_EDGES:]
        head = lk.SENSORS_HEAD.pack(ack, self.world.gpio.get_current_tick(), burst, bus[0] << 8 | bus[1],
                                    shunt[0] << 8 | shunt[1], len(edges))
        return head + b"".join(lk.EDGE.pack(*e) for e in edges)


@dataclass
class Cut:
    """A pulled cable, for testing the failsafe: from `at` s after the first command, for `length` s,
    nothing is received or sent."""
    at: float
    length: float

    def active(self, t: float) -> bool:
        return self.at <= t < self.at + self.length


@dataclass
class ServeResult:
    reason: str = ""
    frames_sent: int = 0
    rx: dict = field(default_factory=dict)
    sim_s: float = 0.0
    commands: int = 0
    max_alt: float = 0.0
    final_alt: float = 0.0
    crashed: bool = False
    turnaround: list = field(default_factory=list)   # s: a command read (free: the step's wake-up)
    #                                                  -> its sensor frame ready to write

    def as_dict(self) -> dict:
        return {"reason": self.reason, "frames_sent": self.frames_sent, "rx": self.rx, "sim_s": self.sim_s,
                "commands": self.commands, "max_alt_m": self.max_alt, "final_alt_m": self.final_alt,
                "crashed": self.crashed, **percentiles("turnaround", self.turnaround)}


def percentiles(name: str, values: list) -> dict:
    """`name`_p50_ms, _p99_ms and _max_ms of durations in seconds (NaN when there are none)."""
    v = sorted(values)

    def pct(p: float) -> float:
        return 1e3 * v[min(len(v) - 1, int(p / 100.0 * len(v)))] if v else float("nan")
    return {f"{name}_p50_ms": pct(50), f"{name}_p99_ms": pct(99), f"{name}_max_ms": 1e3 * v[-1] if v else float("nan")}


def serve(port: lk.Port, plant: HilPlant, mode: str = "lockstep", seconds: float | None = None,
          cut: Cut | None = None, idle_s: float = IDLE_S, now=time.perf_counter) -> ServeResult:
    """Answer the flight side until it says BYE, goes silent, or `seconds` of simulated time pass."""
    enc, dec = lk.Encoder(), lk.Decoder()
    period = plant.world.dt
    counts, trigger, cmd_seq = [0, 0, 0, 0], False, 0
    t_first = None
    last_rx = now()
    k_step = None                       # free mode: index of the next step on the wall-clock grid
    res = ServeResult()
    unpack = lk.COMMAND_BODY.unpack_from

    def send(ftype: int, payload: bytes = b"") -> None:
        port.write(enc.frame(ftype, payload))

    def advance(t_read: float) -> None:
        nonlocal trigger
        plant.step(counts, trigger)
        trigger = False
        frame = enc.frame(lk.SENSORS, plant.sensors(cmd_seq))
        res.turnaround.append(now() - t_read)
        port.write(frame)

    try:
        while True:
            t = now()
            cutting = cut is not None and t_first is not None and cut.active(t - t_first)
            if k_step is not None and not cutting:
                timeout = max(0.0, t_first + k_step * period - t)
            else:
                timeout = 0.05
            data = port.read(timeout)
            t = now()
            if cut is not None and t_first is not None and cut.active(t - t_first):
                data, last_rx = b"", t               # the cable is out: nothing in, nothing out
                cutting = True
            for ftype, seq, payload in dec.feed(data) if data else ():
                last_rx = t
                if ftype == lk.COMMAND and len(payload) >= lk.COMMAND_BODY.size:
                    _, c1, c2, c3, c4, flags = unpack(payload)
                    counts = [min(c, PWM_RANGE) for c in (c1, c2, c3, c4)]
                    cmd_seq = seq
                    trigger = trigger or bool(flags & lk.FLAG_TRIGGER)
                    res.commands += 1
                    if t_first is None:
                        t_first = t
                        if mode == "free":
                            k_step = 0
                    if mode == "lockstep":
                        advance(t)
                elif ftype == lk.REQUEST:
                    send(lk.REPLY, plant.request(payload))
                elif ftype == lk.BYE:
                    send(lk.BYE)
                    res.reason = "the flight side ended the session"
                    _linger(port, now)
                    return res
            if k_step is not None and not cutting and t >= t_first + k_step * period:
                advance(t)
                k_step = max(k_step + 1, int((t - t_first) / period))   # late: whole periods are skipped
            if seconds is not None and plant.world.t >= seconds:
                send(lk.BYE)
                res.reason = f"{seconds:g} s simulated"
                return res
            if t_first is not None and not cutting and t - last_rx > idle_s:
                res.reason = f"link lost: no frame for {idle_s:g} s"
                return res
    except EOFError:
        res.reason = "link closed by the flight side"
        return res
    finally:
        res.frames_sent = enc.sent
        res.rx = dec.stats.as_dict()
        res.sim_s = plant.world.t
        res.max_alt, res.final_alt = plant.max_alt, float(plant.world.plant.x[2])
        res.crashed = plant.crashed


def _linger(port: lk.Port, now, seconds: float = 1.0) -> None:
    """Keep our end open until the flight side has read the last frames and closed its end (closing a
    pty's master end first would discard what the slave end has not read yet)."""
    end = now() + seconds
    try:
        while now() < end:
            port.read(0.05)
    except (EOFError, OSError):
        pass
