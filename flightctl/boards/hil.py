"""The "hil" board: the flight code on the Pi (its real loop, scheduling and wall-clock timing) flying a
plant simulated on a PC, over the framed link of `flightctl.comms.link` (docs/hil.md).

    flightctl run --board hil --link serial:/dev/serial0,921600 --plan hover     (on the Pi)
    flightctl hil serve --link serial:/dev/ttyUSB0,921600                        (on the PC)

The real drivers stay in the loop, behind link-backed devices at their lowest boundary:
- the MPU-9250 driver reads `LinkSpi`: every loop the PC sends the chip's 21 raw burst bytes (from
  ACCEL_XOUT_H), which the driver decodes as on the bus; its start-up register writes and reads go
  to the PC's simulated chip as REQUEST frames;
- the HC-SR04 driver gets its echo edges (level, microsecond tick) from `LinkGpio`: its trigger rides on
  the next command, the PC's simulated module answers with edges;
- the INA219 driver reads the BUS_VOLTAGE and SHUNT_VOLTAGE registers of each frame (`LinkSMBus`);
- `HilMotors` sends the four PWM counts; `HilClock` keeps the loop's wall-clock deadlines and, once per
  tick, sends the command and takes the newest sensor frame.

A reader thread timestamps the frames as they arrive: latency is the time from a command to the sensor
frame that answers it. Link loss (no frame for LINK_LOST_S) is a failsafe: the sonar gets no more echoes
and the IMU registers hold their last sample, so the loop's altitude-lost check lands the vehicle (an
open-loop descent, then a normal landing if the link comes back); on the ground `arm()` refuses.
"""
from __future__ import annotations

import ipaddress
import os
import queue
import struct
import sys
import threading
import time

from flightctl.comms import link as lk
from flightctl.boards import MIN_BATTERY_V, Board, BoardOptions, BoardUnavailable
from flightctl.clock import SPIN_S, WallClock
from flightctl.drivers import ina219_regs as ina
from flightctl.drivers import mpu9250_regs as reg
from flightctl.drivers.hcsr04 import HcSr04
from flightctl.drivers.ina219 import Ina219
from flightctl.drivers.mpu9250 import Mpu9250
from flightctl.hal import PWM_RANGE, ArmingRefused, Hal
from flightctl.params import Params

LINK_LOST_S = 0.1          # no sensor frame for this long: the link is lost
REQUEST_TIMEOUT_S = 1.0    # one start-up register transfer
FIRST_CONTACT_S = 15.0     # the PC side may still be starting
HIL_CALIBRATE_S = 2.0
SONAR_TRIGGER_PIN, SONAR_ECHO_PIN = 23, 24
_BURST_CMD = reg.READ | reg.ACCEL_XOUT_H
_U16 = struct.Struct("<H")


class HilLink:
    """The flight side's end of the link."""

    def __init__(self, port: lk.Port, now=time.perf_counter):
        self.port, self.now = port, now
        self.enc, self.dec = lk.Encoder(), lk.Decoder()
        self._lock = threading.Lock()
        self._latest: bytes | None = None
        self._edges: list[tuple[int, int, int]] = []
        self._replies: queue.Queue = queue.Queue()
        self._sent_at: list[float | None] = [None] * 0x10000   # seq (u16) -> send time, for the latency;
        #                                       an answer however late (a stalled end) is counted, once
        self.latencies: list[float] = []           # s, one per answered command
        self.last_rx = now()
        self.counts = [0, 0, 0, 0]
        self.flags = 0
        self.sent_this_tick = False
        self.streaming = False                     # the loop ticks: burst and power reads come from frames
        self.imu = bytes(reg.BURST_LEN)
        self.power = (0, 0)
        self.tick = 0
        self.lost = False
        self.events: list[tuple[float, str]] = []
        self.stale_ticks = 0                       # ticks without a new frame
        self.peer_done = threading.Event()
        self.callbacks: dict[int, list] = {}
        self._closed = False
        self._thread = threading.Thread(target=self._read, daemon=True, name="hil-link")
        self._thread.start()

    # --- the reader thread ---------------------------------------------------------------------
    def _read(self) -> None:
        port, dec = self.port, self.dec
        while not self._closed:
            try:
                data = port.read(0.05)
            except (EOFError, OSError):
                self.peer_done.set()
                return
            if not data:
                continue
            t = self.now()
            for ftype, seq, payload in dec.feed(data):
                if ftype == lk.SENSORS and len(payload) >= lk.SENSORS_HEAD.size:
                    ack = _U16.unpack_from(payload)[0]
                    ts = self._sent_at[ack]
                    if ts is not None:                # the first frame answering this command
                        self.latencies.append(t - ts)
                        self._sent_at[ack] = None
                    edges = _edges(payload)
                    with self._lock:
                        self._latest = payload
                        self._edges.extend(edges)
                    self.last_rx = t
                elif ftype == lk.REPLY:
                    self.last_rx = t
                    self._replies.put(payload)
                elif ftype == lk.BYE:
                    self.peer_done.set()

    # --- the loop's side -----------------------------------------------------------------------
    def send_command(self) -> None:
        c = self.counts
        f = self.enc.frame(lk.COMMAND, lk.COMMAND_BODY.pack(self.dec.last_seq, c[0], c[1], c[2], c[3], self.flags))
        seq = self.enc.seq
        self._sent_at[seq] = self.now()
        self.flags &= ~lk.FLAG_TRIGGER
        self.sent_this_tick = True
        try:
            self.port.write(f)
        except OSError:
            pass                      # a dead link shows as no frames: the failsafe handles it

    def take(self, t: float) -> None:
        """At the tick: the newest sensor frame into the devices, its echo edges to the sonar."""
        with self._lock:
            frame, self._latest = self._latest, None
            edges, self._edges = self._edges, []
        self.streaming = True
        if frame is None:
            self.stale_ticks += 1
            if not self.lost and self.now() - self.last_rx > LINK_LOST_S:
                self.lost = True
                self.events.append((t, "link lost"))
            return
        if self.lost:
            self.lost = False
            self.events.append((t, "link restored"))
        _, self.tick, self.imu, bus, shunt, _ = lk.SENSORS_HEAD.unpack_from(frame)
        self.power = (bus, shunt)
        for pin, level, tick in edges:
            for func in self.callbacks.get(pin, ()):
                func(pin, level, tick)

    def request(self, device: int, data: bytes, timeout: float = REQUEST_TIMEOUT_S) -> bytes:
        """One start-up transfer on the PC's simulated device, answered before the next."""
        while not self._replies.empty():
            self._replies.get_nowait()
        self.port.write(self.enc.frame(lk.REQUEST, bytes((device,)) + data))
        try:
            return self._replies.get(timeout=timeout)
        except queue.Empty:
            raise lk.LinkError(f"the PC side did not answer within {timeout:g} s") from None

    def contact(self, timeout: float = FIRST_CONTACT_S) -> None:
        """Wait until the PC side answers (it may still be starting)."""
        deadline = self.now() + timeout
        while True:
            try:
                self.request(lk.DEV_GPIO_WATCH, bytes((0, 0, 0)), timeout=0.2)
                return
            except lk.LinkError:
                if self.now() > deadline or self.peer_done.is_set():
                    raise lk.LinkError(f"no answer from the PC side within {timeout:g} s "
                                       "(is `flightctl hil serve` running on the other end?)") from None

    def summary(self) -> dict:
        lat = sorted(self.latencies)

        def pct(p: float) -> float:
            return 1e3 * lat[min(len(lat) - 1, int(p / 100.0 * len(lat)))] if lat else float("nan")
        mean = sum(lat) / len(lat) if lat else float("nan")
        jitter = (sum((x - mean) ** 2 for x in lat) / len(lat)) ** 0.5 * 1e3 if lat else float("nan")
        return {"commands_sent": self.enc.sent, **{f"rx_{k}": v for k, v in self.dec.stats.as_dict().items()},
                "stale_ticks": self.stale_ticks, "latency_p50_ms": pct(50), "latency_p99_ms": pct(99),
                "latency_max_ms": 1e3 * lat[-1] if lat else float("nan"), "jitter_ms": jitter,
                "events": [f"{t:.3f} s: {what}" for t, what in self.events]}

    def close(self, wait_s: float = 2.0) -> None:
        if self._closed:
            return
        try:
            self.port.write(self.enc.frame(lk.BYE))
            self.peer_done.wait(wait_s)       # the PC answers BYE once every frame before it is answered
        except OSError:
            pass
        self._closed = True
        self._thread.join(timeout=1.0)
        self.port.close()


def _edges(payload: bytes) -> list[tuple[int, int, int]]:
    n = min(payload[lk.SENSORS_HEAD.size - 1], lk.MAX_EDGES)
    off = lk.SENSORS_HEAD.size
    if len(payload) < off + n * lk.EDGE.size:
        return []
    return [lk.EDGE.unpack_from(payload, off + k * lk.EDGE.size) for k in range(n)]


class LinkSpi:
    """The SPI bus of the MPU-9250 driver: the loop's burst read answered from the newest frame, every
    other transfer (start-up) done on the PC's simulated chip."""

    def __init__(self, link: HilLink):
        self.link = link
        self.max_speed_hz = 0

    def xfer2(self, data: list[int]) -> list[int]:
        link = self.link
        if link.streaming and data[0] == _BURST_CMD and len(data) == reg.BURST_LEN + 1:
            return [0, *link.imu]
        return list(link.request(lk.DEV_SPI, bytes(data)))


class LinkSMBus:
    """The I2C bus of the INA219 driver: the voltage registers from the frames, the rest on the PC."""
    _FROM_FRAME = {ina.BUS_VOLTAGE: 0, ina.SHUNT_VOLTAGE: 1}

    def __init__(self, link: HilLink):
        self.link = link

    def read_i2c_block_data(self, addr: int, register: int, length: int, force=None) -> list[int]:
        link = self.link
        k = self._FROM_FRAME.get(register)
        if link.streaming and k is not None and length == 2:
            word = link.power[k]
            return [word >> 8, word & 0xFF]
        return list(link.request(lk.DEV_I2C_READ, bytes((addr, register, length))))

    def write_i2c_block_data(self, addr: int, register: int, data: list[int], force=None) -> None:
        reply = self.link.request(lk.DEV_I2C_WRITE, bytes((addr, register, *data)))
        if reply:
            raise OSError(121, "Remote I/O error (on the PC's simulated bus)")

    def close(self) -> None:
        pass


class LinkGpio:
    """The pigpio calls of the HC-SR04 driver: the trigger rides on the next command, the edges come
    back in the frames with the simulated module's microsecond ticks."""

    def __init__(self, link: HilLink):
        self.link = link

    def set_mode(self, gpio: int, mode: int) -> int:
        return 0

    def gpio_trigger(self, user_gpio: int, pulse_len: int = 10, level: int = 1) -> int:
        self.link.flags |= lk.FLAG_TRIGGER
        return 0

    def callback(self, user_gpio: int, edge: int, func):
        link = self.link
        link.callbacks.setdefault(user_gpio, []).append(func)

        class _Cb:
            def cancel(self) -> None:
                link.callbacks.get(user_gpio, []).remove(func)
        return _Cb()

    def set_watchdog(self, user_gpio: int, wdog_timeout: int) -> int:
        self.link.request(lk.DEV_GPIO_WATCH, bytes((user_gpio,)) + _U16.pack(wdog_timeout))
        return 0

    def get_current_tick(self) -> int:
        return self.link.tick


class HilMotors:
    def __init__(self, link: HilLink):
        self.link = link
        self.armed = False

    def arm(self) -> None:
        link = self.link
        if link.lost or link.peer_done.is_set():
            raise ArmingRefused("HIL link lost: no sensor frame from the PC side")
        self.armed = True
        link.flags |= lk.FLAG_ARMED

    def write(self, counts: list[int]) -> None:
        c = self.link.counts
        for i in range(4):
            v = counts[i]
            c[i] = 0 if v < 0 else PWM_RANGE if v > PWM_RANGE else v

    def stop(self) -> None:
        link = self.link
        link.counts[:] = (0, 0, 0, 0)
        link.flags &= ~lk.FLAG_ARMED
        self.armed = False
        link.send_command()          # at once, whatever the loop does next


class HilClock:
    """The loop's wall-clock deadlines; one command out per tick (the loop writes the motors only in
    flight, and the PC's lock-step plant steps on every command), the newest frame in.

    `spin_s` is the wall clock's busy-wait before each deadline (flightctl/clock.py). When the PC side
    runs on this machine (`hil demo`, or `hil serve` beside `run --board hil`: a pty or a loopback
    address), the clock only sleeps: the busy-wait is a third of the flight side's CPU time, taken
    every period from the PC side that must answer (docs/hil.md, "The flight side's busy-wait"; the link's
    latency as measured: its "hil latency" block). The Pi flying
    a PC's plant keeps the busy-wait and its deadline precision."""

    def __init__(self, link: HilLink, period: float, spin_s: float = SPIN_S):
        self.link, self.period = link, period
        self.wall = WallClock(period, spin_s)

    @property
    def overruns(self) -> int:
        return self.wall.overruns

    def now(self) -> float:
        return self.wall.now()

    def wait_next(self) -> float:
        link = self.link
        if not link.sent_this_tick:
            link.send_command()
        t = self.wall.wait_next()
        link.sent_this_tick = False
        link.take(t)
        return t


def peer_is_local(port: lk.Port) -> bool:
    """Whether the link's other end runs on this machine: a pseudo-terminal (its slave end /dev/pts/N,
    possibly behind a symbolic link), an inherited descriptor, or a loopback address."""
    if isinstance(port, lk.SocketPort):
        try:
            return ipaddress.ip_address(port.sock.getpeername()[0]).is_loopback
        except (OSError, ValueError, IndexError):
            return False
    if isinstance(port, lk.SerialPort):
        return os.path.realpath(port.ser.port or "").startswith("/dev/pts/")
    return isinstance(port, lk.FdPort)


def open_board(params: Params, options: BoardOptions) -> Board:
    if not options.link:
        raise BoardUnavailable("the hil board needs --link serial:/dev/serial0,921600 or tcp:HOST:PORT")
    try:
        port = lk.connect(options.link)
    except ValueError as e:
        raise BoardUnavailable(str(e)) from None
    except lk.LinkError as e:
        raise BoardUnavailable(str(e)) from None
    link = HilLink(port)
    try:
        link.contact()
        # The link hands the driver the last frame again on a tick where no new one has arrived (a
        # loaded PC, a lost link), so a repeat is the link's staleness, not a frozen chip: the frozen
        # check is off here and link loss is judged by the link (no echoes -> altitude lost -> land).
        imu = Mpu9250(LinkSpi(link), frozen_frames=0)
        sonar = HcSr04(LinkGpio(link), SONAR_TRIGGER_PIN, SONAR_ECHO_PIN)
        power = Ina219(LinkSMBus(link), bus_name="the HIL link")
        imu.start()
        sonar.start()
        power.start()
    except Exception as e:
        link.close(wait_s=0.2)
        raise BoardUnavailable(f"HIL link {options.link}: {e}") from None
    clock = HilClock(link, params.airframe.dt, 0.0 if peer_is_local(port) else SPIN_S)
    hal = Hal(imu=imu, motors=HilMotors(link), rangefinder=sonar, power=power, clock=clock)

    def close() -> None:
        hal.motors.stop()
        link.close()
        s = link.summary()
        print(f"hil: {s['commands_sent']} commands sent, {s['rx_frames']} frames received, {s['rx_lost']} lost, "
              f"{s['rx_bad_crc'] + s['rx_bad_length'] + s['rx_out_of_order']} dropped; latency p50 "
              f"{s['latency_p50_ms']:.2f} ms, p99 {s['latency_p99_ms']:.2f} ms, jitter {s['jitter_ms']:.2f} ms; "
              f"{clock.overruns} overruns", file=sys.stderr)
    return Board(hal, "hil", MIN_BATTERY_V, HIL_CALIBRATE_S, close=close,
                 meta={"link": options.link, "clock": "wall clock (the plant runs on the PC side)"})
