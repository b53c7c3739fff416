"""A fake `pigpiod` on loopback that speaks the real socket protocol, for the real `pigpio` client.

Protocol (pigpio.py, pigpiod's command.c): a request is 16 bytes `struct('IIII')` = (cmd, p1, p2, p3);
for the commands in EXT_CMDS, p3 is the length of extension bytes that follow. The reply is 16 bytes
(cmd, p1, p2, res) with `res` a signed result; `PROCP` (script status) follows its reply with `res`
bytes of data. A connection that sends `NOIB` becomes a notification stream: from then on the daemon
writes 12-byte reports `struct('HHII')` = (seqno, flags, tick, level bits) to it; `flags` 0 is a level
change, `NTFY_FLAGS_WDOG | gpio` a watchdog timeout. The client closes it by sending `NC` on it.

What it emulates, in fake time `t` (microseconds of `time.monotonic` since start; the 32-bit tick
starts near its wrap so tests cross it):
- waves: `WVAG` merges pulses, `WVSM` reports the length being built, `WVCRE` stores a wave at the
  lowest free id, `WVTXM` with the SYNC modes switches at the end of the running cycle (a wave queued
  while another is queued plays one cycle first, as pigpio chains them), `WVTAT`, `WVHLT`, `WVDEL`;
  `wave_clock_scale` stretches the real timing of every wave (2.0 is pigpio issue #331: waves at half
  speed) while `WVSM` still reports the nominal length, as pigpio would;
- edges: level changes of waves, `WRITE` and `TRIG` pulses, an HC-SR04 on (trigger, echo) pins with
  modes "echo" (rise 450 us after the trigger, high distance * 5831 us), "none" (no echo) and "stuck"
  (the echo rises and never falls), reported to the notification handles that watch the pins;
  watchdogs (`WDOG`) repeat a timeout report every period without an edge;
- scripts: `PROC` parses the subset of pigpio's script language used here (tags, mils, counters and
  jumps, w, wvhlt, wvtxr, wvtxm, halt) and runs it in a thread on `PROCR`; `PROCU`, `PROCP`, `PROCS`, `PROCD`;
- DMA PWM: `PFS` answers the closest of pigpio's fixed frequencies (449 -> 400), `PFG` reads it back.

Misuse a real daemon would not report but that would break the outputs is recorded in `errors`:
deleting a wave that is on the pins or queued, clearing waves while one is transmitting, unknown
commands. The fake stops by itself after `lifetime_s`; all its loops are bounded.
"""
from __future__ import annotations

import heapq
import math
import socket
import struct
import threading
import time
from dataclasses import dataclass, field

import pigpio

from helpers.fakes import HCSR04_ECHO_DELAY_US, HCSR04_US_PER_M

CMD = struct.Struct("IIII")
REPORT = struct.Struct("HHII")
MAX_WAVES = 250
MAX_SCRIPTS = 32
MAX_HANDLES = 32

C = {name[8:]: value for name, value in vars(pigpio).items() if name.startswith("_PI_CMD_")}
EXT_CMDS = {C["WVAG"], C["WVAS"], C["TRIG"], C["PROC"], C["PROCR"], C["PROCU"], C["HP"], C["WVCHA"]}
# pigpio's DMA PWM frequencies at the default 5 us sample rate
PWM_FREQUENCIES = (8000, 4000, 2000, 1600, 1000, 800, 500, 400, 320, 250, 200, 160, 100, 80, 50, 40, 20, 10)

# script language: op -> number of arguments; kinds: n = value, t = tag, x = variable/parameter
SCRIPT_OPS = {"tag": "t", "mils": "n", "mics": "n", "dcr": "x", "inr": "x", "jp": "t", "jm": "t", "jz": "t",
              "jnz": "t", "jmp": "t", "ld": "xn", "lda": "n", "sta": "x", "cmp": "n", "add": "n", "sub": "n",
              "w": "nn", "wvhlt": "", "wvtxr": "n", "wvtxm": "nn", "wvtx": "n", "halt": "", "nop": ""}


@dataclass
class Wave:
    events: list[tuple[int, int, int]]   # (t within the cycle in us, gpios on, gpios off)
    length: int                          # us

    @property
    def mask(self) -> int:
        m = 0
        for _, on, off in self.events:
            m |= on | off
        return m

    def on_times(self) -> dict[int, int]:
        """High time per gpio in one cycle of the repeating wave (steady state)."""
        out = {}
        for g in range(32):
            if not self.mask >> g & 1:
                continue
            level, t_prev, high = 0, 0, 0
            for cycle in range(2):
                for t, on, off in self.events:
                    if cycle:
                        high += level * (t - t_prev)
                    t_prev = t
                    if on >> g & 1:
                        level = 1
                    if off >> g & 1:
                        level = 0
                if cycle:
                    high += level * (self.length - t_prev)
                t_prev = 0
            out[g] = high
        return out


@dataclass
class Script:
    code: list[tuple[str, list]]
    tags: dict[int, int]
    text: str
    status: int = pigpio.PI_SCRIPT_INITING
    ready_at: float = 0.0
    params: list[int] = field(default_factory=lambda: [0] * 10)
    variables: list[int] = field(default_factory=lambda: [0] * 150)
    thread: threading.Thread | None = None
    halt: threading.Event = field(default_factory=threading.Event)


@dataclass
class Handle:
    sock: socket.socket
    mask: int = 0
    seq: int = 0


@dataclass
class Sonar:
    trigger: int
    echo: int
    distance_m: float = 1.0
    mode: str = "echo"     # "echo", "none", "stuck"


class FakePigpiod:
    def __init__(self, tick0: int = (1 << 32) - 300_000, wave_clock_scale: float = 1.0,
                 lifetime_s: float = 60.0, step_s: float = 0.001):
        self.tick0 = tick0
        self.wave_clock_scale = wave_clock_scale
        self.lifetime_s = lifetime_s
        self.step_s = step_s
        self.lock = threading.RLock()
        self.errors: list[str] = []
        self.counts: dict[int, int] = {}
        self.history: list[tuple[float, int, int]] = []   # (t us, wid, mode) when a wave got on the pins
        self.waves: dict[int, Wave] = {}
        self.scripts: dict[int, Script] = {}
        self.handles: dict[int, Handle] = {}
        self.sonar: Sonar | None = None
        self.levels = 0
        self.modes: dict[int, int] = {}
        self.pwm_freq: dict[int, int] = {}
        self.watchdogs: dict[int, list[float]] = {}        # gpio -> [timeout us, last activity us]
        self._building: list[tuple[int, int, int]] = []
        self._building_len = 0
        self._high_micros = 0
        self._tx: list | None = None                       # [wid, start us, mode]
        self._queue: list[tuple[int, int, float]] = []     # (wid, mode, queued at us)
        self._heap: list[tuple[float, int, int, int]] = []  # (t us, seq, gpio, level)
        self._seq = 0
        self._t_done = 0.0
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._conns: list[socket.socket] = []
        self._orphans: list[socket.socket] = []
        self._server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self._server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self._server.bind(("127.0.0.1", 0))
        self.host, self.port = self._server.getsockname()
        self._t0 = time.monotonic()

    # --- lifecycle -------------------------------------------------------------------------------
    def start(self) -> "FakePigpiod":
        self._server.listen(8)
        self._server.settimeout(0.1)
        for target in (self._accept_loop, self._engine_loop):
            th = threading.Thread(target=target, daemon=True, name=f"fake-pigpiod-{target.__name__}")
            th.start()
            self._threads.append(th)
        return self

    def stop(self) -> None:
        if self._stop.is_set():
            return
        self._stop.set()
        with self.lock:
            for s in self.scripts.values():
                s.halt.set()
        for th in self._threads:
            if th is not threading.current_thread():
                th.join(timeout=2.0)
        self._server.close()
        for c in self._conns:
            try:
                c.close()
            except OSError:
                pass
        # notification sockets stay open (held here): a closed one would make the client's
        # notification thread spin on recv() returning b"" until its pi.stop()
        self._orphans.extend(h.sock for h in self.handles.values())

    def __enter__(self) -> "FakePigpiod":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    # --- time ------------------------------------------------------------------------------------
    def now_us(self) -> float:
        return (time.monotonic() - self._t0) * 1e6

    def tick(self, t_us: float) -> int:
        return (self.tick0 + int(t_us)) & 0xFFFFFFFF

    # --- test-facing views -----------------------------------------------------------------------
    def attach_sonar(self, trigger: int, echo: int, distance_m: float = 1.0, mode: str = "echo") -> Sonar:
        with self.lock:
            self.sonar = Sonar(trigger, echo, distance_m, mode)
            return self.sonar

    def live_wave_id(self) -> int | None:
        with self.lock:
            self._process(self.now_us())
            return None if self._tx is None else self._tx[0]

    def live_wave(self) -> Wave | None:
        with self.lock:
            wid = self.live_wave_id()
            return None if wid is None else self.waves.get(wid)

    def count(self, name: str) -> int:
        return self.counts.get(C[name], 0)

    def script_running(self) -> bool:
        with self.lock:
            return any(s.status in (pigpio.PI_SCRIPT_RUNNING, pigpio.PI_SCRIPT_WAITING) for s in self.scripts.values())

    # --- sockets ---------------------------------------------------------------------------------
    def _accept_loop(self) -> None:
        while not self._stop.is_set():
            if self.now_us() > self.lifetime_s * 1e6:
                threading.Thread(target=self.stop, daemon=True).start()
                return
            try:
                conn, _ = self._server.accept()
            except (socket.timeout, OSError):
                continue
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self._conns.append(conn)
            th = threading.Thread(target=self._serve, args=(conn,), daemon=True, name="fake-pigpiod-conn")
            th.start()
            self._threads.append(th)

    @staticmethod
    def _recv_exact(conn: socket.socket, n: int) -> bytes | None:
        buf = b""
        while len(buf) < n:
            try:
                chunk = conn.recv(n - len(buf))
            except OSError:
                return None
            if not chunk:
                return None
            buf += chunk
        return buf

    def _serve(self, conn: socket.socket) -> None:
        notify_handle = None
        while not self._stop.is_set():
            head = self._recv_exact(conn, 16)
            if head is None:
                break
            cmd, p1, p2, p3 = CMD.unpack(head)
            ext = b""
            if cmd in EXT_CMDS and p3:
                ext = self._recv_exact(conn, p3)
                if ext is None:
                    break
            if notify_handle is not None:      # only NC arrives on a notification stream
                if cmd == C["NC"]:
                    with self.lock:
                        self.handles.pop(notify_handle, None)
                    break
                continue
            if cmd == C["NOIB"]:
                with self.lock:
                    h = next((i for i in range(MAX_HANDLES) if i not in self.handles), None)
                    if h is None:
                        res = pigpio.PI_NO_HANDLE
                    else:
                        self.handles[h] = Handle(conn)
                        res = h
                    conn.sendall(CMD.pack(cmd, p1, p2, res & 0xFFFFFFFF))
                notify_handle = h
                continue
            with self.lock:
                self.counts[cmd] = self.counts.get(cmd, 0) + 1
                self._process(self.now_us())
                try:
                    res, extra = self._execute(cmd, p1, p2, p3, ext)
                except Exception as e:   # a bug in the fake must fail the test, not hang the client
                    self.errors.append(f"fake pigpiod: command {cmd} raised {e!r}")
                    res, extra = pigpio.PI_UNKNOWN_COMMAND, b""
            try:
                conn.sendall(CMD.pack(cmd, p1, p2, res & 0xFFFFFFFF) + extra)
            except OSError:
                break
        try:
            conn.close()
        except OSError:
            pass

    # --- commands --------------------------------------------------------------------------------
    def _execute(self, cmd: int, p1: int, p2: int, p3: int, ext: bytes) -> tuple[int, bytes]:
        now = self.now_us()
        if cmd == C["MODES"]:
            self.modes[p1] = p2
            return 0, b""
        if cmd == C["MODEG"]:
            return self.modes.get(p1, 0), b""
        if cmd == C["WRITE"]:
            self._push(now, p1, p2 & 1)
            self._process(now + 1)
            return 0, b""
        if cmd == C["READ"]:
            return self.levels >> p1 & 1, b""
        if cmd == C["BR1"]:
            return self.levels, b""
        if cmd == C["TICK"]:
            return self.tick(now), b""
        if cmd == C["HWVER"]:
            return 0xA02082, b""
        if cmd == C["PIGPV"]:
            return 79, b""
        if cmd == C["WDOG"]:
            if p2 > 60000:
                return pigpio.PI_BAD_WDOG_TIMEOUT, b""
            if p2:
                self.watchdogs[p1] = [p2 * 1000.0, now]
            else:
                self.watchdogs.pop(p1, None)
            return 0, b""
        if cmd == C["NB"]:
            if p1 not in self.handles:
                return pigpio.PI_BAD_HANDLE, b""
            self.handles[p1].mask = p2
            return 0, b""
        if cmd == C["NC"]:
            h = self.handles.pop(p1, None)
            return (0 if h else pigpio.PI_BAD_HANDLE), b""
        if cmd == C["TRIG"]:
            if not 1 <= p2 <= 100:
                return pigpio.PI_BAD_PULSELEN, b""
            level = struct.unpack("I", ext)[0] & 1
            self._push(now, p1, level)
            self._push(now + p2, p1, 1 - level)
            s = self.sonar
            if s is not None and p1 == s.trigger:
                rise = now + p2 + HCSR04_ECHO_DELAY_US
                if s.mode == "echo":
                    self._push(rise, s.echo, 1)
                    self._push(rise + s.distance_m * HCSR04_US_PER_M, s.echo, 0)
                elif s.mode == "stuck" and not self.levels >> s.echo & 1:
                    self._push(rise, s.echo, 1)
            return 0, b""
        if cmd == C["PFS"]:
            self.pwm_freq[p1] = min(PWM_FREQUENCIES, key=lambda f: abs(f - p2))
            return self.pwm_freq[p1], b""
        if cmd == C["PFG"]:
            return self.pwm_freq.get(p1, 800), b""
        if cmd in (C["WVCLR"], C["WVNEW"]):
            if cmd == C["WVCLR"]:
                if self._tx is not None:
                    self.errors.append(f"wave_clear while wave {self._tx[0]} is on the pins")
                self.waves.clear()
            self._building, self._building_len = [], 0
            return 0, b""
        if cmd == C["WVAG"]:
            return self._wave_add(ext), b""
        if cmd == C["WVSM"]:
            return {0: self._building_len, 1: self._high_micros, 2: 1_800_000_000}.get(p1, -1), b""
        if cmd == C["WVCRE"]:
            if not self._building:
                return pigpio.PI_EMPTY_WAVEFORM, b""
            wid = next((i for i in range(MAX_WAVES) if i not in self.waves), None)
            if wid is None:
                return pigpio.PI_NO_WAVEFORM_ID, b""
            self.waves[wid] = Wave(self._building, self._building_len)
            self._building, self._building_len = [], 0
            return wid, b""
        if cmd == C["WVDEL"]:
            if p1 not in self.waves:
                return pigpio.PI_BAD_WAVE_ID, b""
            if self._tx is not None and self._tx[0] == p1:
                self.errors.append(f"wave_delete({p1}) while it is on the pins")
            if any(q[0] == p1 for q in self._queue):
                self.errors.append(f"wave_delete({p1}) while it is queued")
            del self.waves[p1]
            return 0, b""
        if cmd == C["WVTX"]:
            return self._wave_send(p1, pigpio.WAVE_MODE_ONE_SHOT, now), b""
        if cmd == C["WVTXR"]:
            return self._wave_send(p1, pigpio.WAVE_MODE_REPEAT, now), b""
        if cmd == C["WVTXM"]:
            return self._wave_send(p1, p2, now), b""
        if cmd == C["WVTAT"]:
            if self._tx is None:
                return pigpio.NO_TX_WAVE, b""
            return (self._tx[0] if self._tx[0] in self.waves else pigpio.WAVE_NOT_FOUND), b""
        if cmd == C["WVBSY"]:
            return int(self._tx is not None), b""
        if cmd == C["WVHLT"]:
            self._tx, self._queue = None, []
            return 0, b""
        if cmd == C["PROC"]:
            return self._script_store(ext.decode(errors="replace")), b""
        if cmd == C["PROCR"]:
            return self._script_run(p1, ext), b""
        if cmd == C["PROCU"]:
            s = self.scripts.get(p1)
            if s is None:
                return pigpio.PI_BAD_SCRIPT_ID, b""
            for i, v in enumerate(struct.unpack(f"{len(ext) // 4}i", ext)):
                s.params[i] = v
            return 0, b""
        if cmd == C["PROCP"]:
            s = self.scripts.get(p1)
            if s is None:
                return pigpio.PI_BAD_SCRIPT_ID, b""
            if s.status == pigpio.PI_SCRIPT_INITING and time.monotonic() >= s.ready_at:
                s.status = pigpio.PI_SCRIPT_HALTED
            return 44, struct.pack("11i", s.status, *s.params)
        if cmd == C["PROCS"]:
            s = self.scripts.get(p1)
            if s is None:
                return pigpio.PI_BAD_SCRIPT_ID, b""
            s.halt.set()
            s.status = pigpio.PI_SCRIPT_HALTED
            return 0, b""
        if cmd == C["PROCD"]:
            s = self.scripts.pop(p1, None)
            if s is None:
                return pigpio.PI_BAD_SCRIPT_ID, b""
            s.halt.set()
            return 0, b""
        self.errors.append(f"unknown command {cmd} ({p1}, {p2}, {p3})")
        return pigpio.PI_UNKNOWN_COMMAND, b""

    # --- waves -----------------------------------------------------------------------------------
    def _wave_add(self, ext: bytes) -> int:
        n = len(ext) // 12
        pulses = [struct.unpack_from("III", ext, 12 * i) for i in range(n)]
        t, new = 0, []
        for on, off, delay in pulses:
            new.append((t, on, off))
            t += delay
        merged: dict[int, list[int]] = {}
        for tt, on, off in self._building + new:
            m = merged.setdefault(tt, [0, 0])
            m[0] |= on
            m[1] |= off
        self._building = sorted((tt, on, off) for tt, (on, off) in merged.items())
        self._building_len = max(self._building_len, t)
        self._high_micros = max(self._high_micros, self._building_len)
        return len(self._building)

    def _wave_send(self, wid: int, mode: int, now: float) -> int:
        if wid not in self.waves:
            return pigpio.PI_BAD_WAVE_ID
        if mode not in (0, 1, 2, 3):
            return pigpio.PI_BAD_WAVE_MODE
        if mode & 2 and self._tx is not None:   # SYNC: after the running cycle (chained)
            self._queue.append((wid, mode, now))
        else:
            self._tx, self._queue = [wid, now, mode], []
            self.history.append((now, wid, mode))
        return 0

    def _cycle_us(self, wid: int) -> float:
        w = self.waves.get(wid)
        return (w.length if w is not None else 1) * self.wave_clock_scale

    def _segments(self, t_end: float) -> list[tuple[int, float, int, float]]:
        """Walk the transmissions up to t_end: (wid, start, mode, end) segments, state advanced."""
        segs = []
        while self._tx is not None:
            wid, start, mode = self._tx
            L = self._cycle_us(wid)
            if self._queue:
                q = self._queue[0][2]
                switch = start + max(1, math.ceil((q - start) / L)) * L if mode & 1 else start + L
            elif not mode & 1:
                switch = start + L
            else:
                switch = math.inf
            segs.append((wid, start, mode, min(switch, t_end)))
            if switch > t_end:
                break
            if self._queue:
                nwid, nmode, _ = self._queue.pop(0)
                self._tx = [nwid, switch, nmode]
                self.history.append((switch, nwid, nmode))
            else:
                self._tx = None
        return segs

    # --- edges, reports, watchdogs ---------------------------------------------------------------
    def _push(self, t: float, gpio: int, level: int) -> None:
        self._seq += 1
        heapq.heappush(self._heap, (t, self._seq, gpio, level))

    def _process(self, t_now: float) -> None:
        """Everything that happened in [t_done, t_now): wave edges, scheduled edges, watchdogs."""
        t_a = self._t_done
        if t_now <= t_a:
            return
        watched = 0
        for h in self.handles.values():
            watched |= h.mask
        events: list[tuple[float, int, int]] = []   # (t, on mask, off mask)
        for wid, start, mode, end in self._segments(t_now):
            w = self.waves.get(wid)
            if w is None or not (w.mask & watched):
                continue
            s = self.wave_clock_scale
            L = w.length * s
            lo = max(t_a, start)
            k = max(0, int((lo - start) // L))
            while True:
                c0 = start + k * L
                if c0 >= end or (k and not mode & 1):
                    break
                for tr, on, off in w.events:
                    te = c0 + tr * s
                    if lo <= te < end:
                        events.append((te, on, off))
                k += 1
        heap = self._heap
        while heap and heap[0][0] < t_now:
            te, _, g, level = heapq.heappop(heap)
            events.append((te, 1 << g if level else 0, 0 if level else 1 << g))
        events.sort(key=lambda e: e[0])
        out: dict[int, list[bytes]] = {}
        for te, on, off in events:
            self._fire_watchdogs(te, out)
            old = self.levels
            self.levels = (old | on) & ~off
            changed = old ^ self.levels
            if not changed:
                continue
            for g, wd in self.watchdogs.items():
                if changed >> g & 1:
                    wd[1] = te
            for hid, h in self.handles.items():
                if h.mask & changed:
                    out.setdefault(hid, []).append(self._report(h, 0, te))
        self._fire_watchdogs(t_now, out)
        self._t_done = t_now
        for hid, reports in out.items():
            h = self.handles.get(hid)
            if h is None:
                continue
            try:
                h.sock.sendall(b"".join(reports))
            except OSError:
                self.handles.pop(hid, None)

    def _fire_watchdogs(self, t: float, out: dict[int, list[bytes]]) -> None:
        for g, wd in self.watchdogs.items():
            timeout = wd[0]
            while wd[1] + timeout <= t:
                wd[1] += timeout
                for hid, h in self.handles.items():
                    if h.mask >> g & 1:
                        out.setdefault(hid, []).append(self._report(h, pigpio.NTFY_FLAGS_WDOG | g, wd[1]))

    def _report(self, h: Handle, flags: int, t: float) -> bytes:
        h.seq = (h.seq + 1) & 0xFFFF
        return REPORT.pack(h.seq, flags, self.tick(t), self.levels)

    def _engine_loop(self) -> None:
        while not self._stop.wait(self.step_s):
            if self.now_us() > self.lifetime_s * 1e6:
                threading.Thread(target=self.stop, daemon=True).start()
                return
            with self.lock:
                try:
                    self._process(self.now_us())
                except Exception as e:
                    self.errors.append(f"fake pigpiod engine: {e!r}")
                    return

    # --- scripts ---------------------------------------------------------------------------------
    def _script_store(self, text: str) -> int:
        tokens = text.split()
        code, tags, i = [], {}, 0
        while i < len(tokens):
            op = tokens[i].lower()
            kinds = SCRIPT_OPS.get(op)
            if kinds is None:
                return pigpio.PI_BAD_SCRIPT_CMD
            args = tokens[i + 1:i + 1 + len(kinds)]
            if len(args) != len(kinds):
                return pigpio.PI_BAD_SCRIPT
            parsed = []
            for kind, a in zip(kinds, args):
                v = self._parse_arg(kind, a)
                if v is None:
                    return pigpio.PI_BAD_SCRIPT
                parsed.append(v)
            if op == "tag":
                if parsed[0] in tags:
                    return pigpio.PI_DUP_TAG
                tags[parsed[0]] = len(code)
            code.append((op, parsed))
            i += 1 + len(kinds)
        for op, args in code:
            if SCRIPT_OPS[op] == "t" and op != "tag" and args[0] not in tags:
                return pigpio.PI_BAD_TAG
        sid = next((k for k in range(MAX_SCRIPTS) if k not in self.scripts), None)
        if sid is None:
            return pigpio.PI_NO_SCRIPT_ROOM
        self.scripts[sid] = Script(code, tags, text, ready_at=time.monotonic() + 0.002)
        return sid

    @staticmethod
    def _parse_arg(kind: str, a: str):
        a = a.lower()
        if a[:1] in ("p", "v") and a[1:].isdigit():
            n = int(a[1:])
            if (a[0] == "p" and n > 9) or (a[0] == "v" and n > 149):
                return None
            return (a[0], n)
        if kind == "x":
            return None
        try:
            return int(a, 0)
        except ValueError:
            return None

    def _script_run(self, sid: int, ext: bytes) -> int:
        s = self.scripts.get(sid)
        if s is None:
            return pigpio.PI_BAD_SCRIPT_ID
        if s.status == pigpio.PI_SCRIPT_INITING and time.monotonic() >= s.ready_at:
            s.status = pigpio.PI_SCRIPT_HALTED
        if s.status != pigpio.PI_SCRIPT_HALTED:
            return pigpio.PI_SCRIPT_NOT_READY
        for i, v in enumerate(struct.unpack(f"{len(ext) // 4}i", ext)):
            s.params[i] = v
        s.halt = threading.Event()
        s.status = pigpio.PI_SCRIPT_RUNNING
        s.thread = threading.Thread(target=self._script_loop, args=(s,), daemon=True, name=f"fake-pigpiod-script-{sid}")
        s.thread.start()
        return 0

    def _script_loop(self, s: Script) -> None:
        pc, A, F = 0, 0, 0

        def val(a):
            if isinstance(a, tuple):
                return s.params[a[1]] if a[0] == "p" else s.variables[a[1]]
            return a

        def put(a, v):
            if a[0] == "p":
                s.params[a[1]] = v
            else:
                s.variables[a[1]] = v

        while not s.halt.is_set() and not self._stop.is_set():
            if pc >= len(s.code):
                break
            op, args = s.code[pc]
            pc += 1
            if op == "mils":
                if s.halt.wait(val(args[0]) / 1000.0):
                    return
                continue
            if op == "mics":
                if s.halt.wait(val(args[0]) / 1e6):
                    return
                continue
            with self.lock:
                if s.halt.is_set():
                    return
                now = self.now_us()
                self._process(now)
                if op in ("dcr", "inr"):
                    v = val(args[0]) + (1 if op == "inr" else -1)
                    put(args[0], v)
                    F = v
                elif op in ("jp", "jm", "jz", "jnz", "jmp"):
                    take = {"jp": F >= 0, "jm": F < 0, "jz": F == 0, "jnz": F != 0, "jmp": True}[op]
                    if take:
                        pc = s.tags[args[0]]
                elif op == "ld":
                    put(args[0], val(args[1]))
                elif op == "lda":
                    A = F = val(args[0])
                elif op == "sta":
                    put(args[0], A)
                elif op == "cmp":
                    F = A - val(args[0])
                elif op in ("add", "sub"):
                    A = F = A + val(args[0]) * (1 if op == "add" else -1)
                elif op == "w":
                    self._push(now, val(args[0]), val(args[1]) & 1)
                    self._process(now + 1)
                elif op == "wvhlt":
                    self._tx, self._queue = None, []
                elif op in ("wvtxr", "wvtxm", "wvtx"):
                    mode = {"wvtxr": 1, "wvtx": 0}.get(op, val(args[1]) if len(args) > 1 else 1)
                    if self._wave_send(val(args[0]), mode, now) < 0:
                        s.status = pigpio.PI_SCRIPT_FAILED
                        self.errors.append(f"script: {op} {val(args[0])} failed (no such wave)")
                        return
                elif op == "halt":
                    break
        with self.lock:
            if s.status == pigpio.PI_SCRIPT_RUNNING:
                s.status = pigpio.PI_SCRIPT_HALTED


class running:
    """`with running(**fake_options) as (fake, pi):` a started fake and a real `pigpio.pi` on it;
    the client is stopped before the fake (a client whose daemon vanished busy-waits)."""

    def __init__(self, **options):
        self.fake = FakePigpiod(**options)
        self.clients: list = []

    def connect(self):
        pi = pigpio.pi(self.fake.host, self.fake.port, show_errors=False)
        assert pi.connected, "the real pigpio client could not connect to the fake pigpiod"
        self.clients.append(pi)
        return pi

    def __enter__(self):
        self.fake.start()
        return self.fake, self.connect()

    def __exit__(self, *exc) -> None:
        for pi in self.clients:
            if pi.connected:
                pi.stop()
        self.fake.stop()
