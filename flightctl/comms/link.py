"""The hardware-in-the-loop link: framed binary messages between the Pi (flight side) and the PC (plant
side), over a serial line (pyserial), TCP, or an inherited file descriptor (a pty end). Both ends use
this module; docs/hil.md describes the wiring and the sizes.

A frame, little-endian:

    A5 5A | length (1 byte: type + seq + payload) | type (1) | seq (u16) | payload | CRC (u16)

The CRC is CRC-16/CCITT-FALSE (`binascii.crc_hqx`, initial value 0xFFFF) over length..payload. Each end
numbers its frames with one counter (mod 2^16). The `Decoder` resynchronises on the sync bytes: a frame
with a bad length or a bad CRC (corrupted, or truncated: its bytes then run into the next frame's) is
counted and dropped, the scan resumes one byte after its sync; a frame whose seq is not after the last
one (a duplicate or out of order) is counted and dropped; a gap in seq counts the frames lost. Nothing
a peer sends can raise.
"""
from __future__ import annotations

import binascii
import os
import select
import socket
import struct
from dataclasses import dataclass

SYNC = b"\xa5\x5a"
_HEAD = struct.Struct("<2sBBH")        # sync, length, type, seq
_CRC = struct.Struct("<H")
HEAD_LEN, CRC_LEN = _HEAD.size, _CRC.size
MAX_BODY = 255                         # length is one byte
MIN_BODY = 3                           # type + seq

# Frame types
COMMAND = 0x43    # Pi -> PC, every loop: ack u16, four PWM counts u16, flags u8
SENSORS = 0x53    # PC -> Pi, every loop: ack u16, tick u32, IMU burst bytes, INA219 words, echo edges
REQUEST = 0x52    # Pi -> PC, at setup: one register transfer (the drivers' start-up) or a GPIO watch
REPLY = 0x50      # PC -> Pi: the answer to a REQUEST
BYE = 0x42        # either way: the end of the session
TYPES = frozenset((COMMAND, SENSORS, REQUEST, REPLY, BYE))

# COMMAND payload
COMMAND_BODY = struct.Struct("<H4HB")
FLAG_ARMED, FLAG_TRIGGER = 0x01, 0x02
# SENSORS payload: ack, tick (the simulated GPIO's microsecond tick), the IMU's 21-byte burst from
# ACCEL_XOUT_H (mpu9250_regs.BURST_LEN), the INA219's BUS_VOLTAGE and SHUNT_VOLTAGE registers (wire order),
# the number of echo edges, then (pin, level, tick) per edge
SENSORS_HEAD = struct.Struct("<HI21s2HB")
EDGE = struct.Struct("<BBI")
MAX_EDGES = 8
# REQUEST payload: device, then its arguments
DEV_SPI, DEV_I2C_READ, DEV_I2C_WRITE, DEV_GPIO_WATCH = 0, 1, 2, 3


def crc(data: bytes) -> int:
    return binascii.crc_hqx(data, 0xFFFF)


class Encoder:
    """Frames with this end's sequence numbers."""

    def __init__(self):
        self.seq = 0
        self.sent = 0

    def frame(self, ftype: int, payload: bytes = b"") -> bytes:
        self.seq = (self.seq + 1) & 0xFFFF
        self.sent += 1
        body = _HEAD.pack(SYNC, MIN_BODY + len(payload), ftype, self.seq) + payload
        return body + _CRC.pack(crc(body[2:]))


@dataclass
class LinkStats:
    frames: int = 0          # frames accepted
    lost: int = 0            # frames missing (gaps in seq)
    bad_crc: int = 0         # corrupted or truncated
    bad_length: int = 0
    out_of_order: int = 0    # duplicates and frames older than the last accepted
    unknown_type: int = 0
    skipped_bytes: int = 0   # bytes between frames (noise, resynchronisation)

    @property
    def dropped(self) -> int:
        return self.bad_crc + self.bad_length + self.out_of_order + self.unknown_type

    def as_dict(self) -> dict:
        return {k: getattr(self, k) for k in ("frames", "lost", "bad_crc", "bad_length", "out_of_order",
                                              "unknown_type", "skipped_bytes")}


class Decoder:
    """Bytes in, checked frames out: `feed(data)` -> [(type, seq, payload), ...]."""

    def __init__(self):
        self.buf = bytearray()
        self.last_seq = 0            # the peer's first frame is seq 1: frames lost at the start count too
        self.stats = LinkStats()

    def feed(self, data: bytes) -> list[tuple[int, int, bytes]]:
        buf, st, out = self.buf, self.stats, []
        buf += data
        while True:
            i = buf.find(SYNC)
            if i < 0:
                keep = 1 if buf[-1:] == SYNC[:1] else 0
                st.skipped_bytes += len(buf) - keep
                del buf[:len(buf) - keep]
                return out
            if i:
                st.skipped_bytes += i
                del buf[:i]
            if len(buf) < HEAD_LEN:
                return out
            _, length, ftype, seq = _HEAD.unpack_from(buf)
            if length < MIN_BODY:
                st.bad_length += 1
                del buf[:1]
                continue
            end = 3 + length + CRC_LEN
            if len(buf) < end:
                return out
            if _CRC.unpack_from(buf, end - CRC_LEN)[0] != crc(bytes(buf[2:end - CRC_LEN])):
                st.bad_crc += 1
                del buf[:1]           # resume the scan inside: a truncated frame hides the next one
                continue
            payload = bytes(buf[HEAD_LEN:end - CRC_LEN])
            del buf[:end]
            if ftype not in TYPES:
                st.unknown_type += 1
                continue
            d = (seq - self.last_seq) & 0xFFFF
            if d == 0 or d >= 0x8000:
                st.out_of_order += 1
                continue
            st.lost += d - 1
            self.last_seq = seq
            st.frames += 1
            out.append((ftype, seq, payload))


# --- transports ----------------------------------------------------------------------------------
class Port:
    """What both ends need of a byte stream: `read(timeout)` -> the bytes available (b"" on timeout,
    EOFError when the peer is gone), `write(data)`, `close()`."""

    def read(self, timeout: float) -> bytes: ...
    def write(self, data: bytes) -> None: ...
    def close(self) -> None: ...


class FdPort(Port):
    """A file descriptor: a pty end, or a connected socket's fd."""

    def __init__(self, fd: int):
        self.fd = fd

    def read(self, timeout: float) -> bytes:
        r, _, _ = select.select([self.fd], [], [], timeout)
        if not r:
            return b""
        try:
            data = os.read(self.fd, 4096)
        except OSError:               # the pty's other end closed (EIO)
            raise EOFError from None
        if not data:
            raise EOFError
        return data

    def write(self, data: bytes) -> None:
        view = memoryview(data)
        while view:
            view = view[os.write(self.fd, view):]

    def close(self) -> None:
        try:
            os.close(self.fd)
        except OSError:
            pass


class SocketPort(FdPort):
    def __init__(self, sock: socket.socket):
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.sock = sock
        super().__init__(sock.fileno())

    def write(self, data: bytes) -> None:
        self.sock.sendall(data)

    def close(self) -> None:
        self.sock.close()


class SerialPort(Port):
    """A UART through pyserial (the Pi's /dev/serial0, a PC's USB-serial adapter, a pty's slave end)."""

    def __init__(self, path: str, baud: int):
        try:
            import serial
        except ModuleNotFoundError:
            raise LinkError("a serial link needs pyserial (pip install pyserial: it comes with pip install . from the checkout)") from None
        try:
            self.ser = serial.Serial(path, baud, timeout=0)
        except (serial.SerialException, OSError) as e:
            raise LinkError(f"cannot open the serial port {path}: {e}") from None
        self.fd = self.ser.fileno()

    def read(self, timeout: float) -> bytes:
        r, _, _ = select.select([self.fd], [], [], timeout)
        if not r:
            return b""
        try:
            data = self.ser.read(self.ser.in_waiting or 1)
        except Exception:              # serial.SerialException: the device went away
            raise EOFError from None
        return data

    def write(self, data: bytes) -> None:
        self.ser.write(data)

    def close(self) -> None:
        self.ser.close()


class LinkError(Exception):
    """The link cannot be opened or the peer does not answer."""


DEFAULT_BAUD = 921600


def parse_link(spec: str) -> tuple[str, str, int]:
    """`serial:PATH[,BAUD]`, `tcp:[HOST:]PORT` or `fd:N` -> (kind, where, number). ValueError on
    anything else (the commands turn it into an InputError)."""
    kind, sep, rest = spec.partition(":")
    if not sep or not rest:
        raise ValueError(f"--link {spec!r}: serial:/dev/ttyUSB0,921600, tcp:PORT, tcp:HOST:PORT expected")
    if kind == "serial":
        path, _, baud = rest.partition(",")
        if not baud.strip():
            return kind, path, DEFAULT_BAUD
        if not baud.isdigit() or int(baud) <= 0:
            raise ValueError(f"--link {spec!r}: the baud rate must be a positive whole number")
        return kind, path, int(baud)
    if kind == "tcp":
        host, _, port = rest.rpartition(":")
        if not port.isdigit() or int(port) > 65535:
            raise ValueError(f"--link {spec!r}: the TCP port must be 0..65535")
        return kind, host or "127.0.0.1", int(port)
    if kind == "fd" and rest.isdigit():
        return kind, "", int(rest)
    raise ValueError(f"--link {spec!r}: serial:/dev/ttyUSB0,921600, tcp:PORT, tcp:HOST:PORT expected")


def connect(spec: str, timeout: float = 10.0) -> Port:
    """The flight side's end: open the serial port, or connect to the PC's TCP port."""
    kind, where, n = parse_link(spec)
    if kind == "serial":
        return SerialPort(where, n)
    if kind == "fd":
        return FdPort(n)
    try:
        sock = socket.create_connection((where, n), timeout=timeout)
    except OSError as e:
        raise LinkError(f"cannot connect to {where}:{n}: {e.strerror or e}") from None
    sock.settimeout(None)
    return SocketPort(sock)
