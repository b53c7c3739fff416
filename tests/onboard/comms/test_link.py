"""The HIL frame codec (flightctl/comms/link.py): frames survive the byte stream intact, and random, mutated,
truncated or out-of-order bytes are counted and dropped, never raised."""
from __future__ import annotations

import os
import socket
import time
import types

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from flightctl.comms import link as lk

payloads = st.lists(st.binary(min_size=0, max_size=60), min_size=1, max_size=8)


def encode(bodies, ftype=lk.SENSORS):
    enc = lk.Encoder()
    return [enc.frame(ftype, b) for b in bodies]


@given(payloads, st.integers(1, 7))
def test_frames_come_through_whatever_the_chunking(bodies, chunk):
    stream = b"".join(encode(bodies))
    dec = lk.Decoder()
    out = []
    for i in range(0, len(stream), chunk):
        out += dec.feed(stream[i:i + chunk])
    assert [p for _, _, p in out] == bodies
    assert [s for _, s, _ in out] == list(range(1, len(bodies) + 1))
    assert dec.stats.dropped == dec.stats.lost == 0


@settings(max_examples=300)
@given(st.binary(max_size=400))
def test_random_bytes_never_raise_and_yield_only_checked_frames(noise):
    dec = lk.Decoder()
    for ftype, seq, payload in dec.feed(noise):       # a frame in noise needs sync, length and CRC to agree
        assert ftype in lk.TYPES
    assert len(dec.buf) < len(noise) + 1


@settings(max_examples=300)
@given(payloads, st.data())
def test_a_mutated_frame_is_dropped_and_the_next_ones_recovered(bodies, data):
    frames = encode(bodies + [b"after"])
    k = data.draw(st.integers(0, len(frames) - 2))
    bad = bytearray(frames[k])
    i = data.draw(st.integers(0, len(bad) - 1))
    bad[i] ^= data.draw(st.integers(1, 255))
    dec = lk.Decoder()
    out = dec.feed(b"".join(frames[:k]) + bytes(bad) + b"".join(frames[k + 1:]))
    out += dec.feed(bytes(lk.MAX_BODY + 5))          # the stream goes on (a corrupted length waits for bytes)
    assert [p for _, _, p in out] == bodies[:k] + bodies[k + 1:] + [b"after"]   # CRC-16 sees any 1-byte error
    assert dec.stats.lost == 1
    assert dec.stats.bad_crc + dec.stats.bad_length + dec.stats.skipped_bytes > 0


@settings(max_examples=200)
@given(payloads, st.data())
def test_a_truncated_frame_is_counted_and_the_next_ones_recovered(bodies, data):
    frames = encode(bodies + [b"next"])
    k = data.draw(st.integers(0, len(frames) - 2))
    cut = data.draw(st.integers(1, len(frames[k]) - 1))
    dec = lk.Decoder()
    out = dec.feed(b"".join(frames[:k]) + frames[k][:cut] + b"".join(frames[k + 1:]))
    out += dec.feed(bytes(lk.MAX_BODY + 5))
    assert [p for _, _, p in out] == bodies[:k] + bodies[k + 1:] + [b"next"]
    assert dec.stats.lost == 1                         # the truncated frame's seq is missing
    assert dec.stats.bad_crc + dec.stats.bad_length + dec.stats.skipped_bytes > 0


def test_out_of_order_and_duplicate_frames_are_dropped():
    f = encode([b"a", b"b", b"c", b"d"])
    dec = lk.Decoder()
    out = dec.feed(f[0] + f[2] + f[1] + f[2] + f[3])
    assert [p for _, _, p in out] == [b"a", b"c", b"d"]
    assert dec.stats.out_of_order == 2 and dec.stats.lost == 1


def test_the_sequence_number_wraps():
    enc = lk.Encoder()
    enc.seq = 0xFFFE
    dec = lk.Decoder()
    dec.last_seq = 0xFFFE
    out = dec.feed(b"".join(enc.frame(lk.COMMAND, bytes([i])) for i in range(3)))
    assert [s for _, s, _ in out] == [0xFFFF, 0, 1] and dec.stats.out_of_order == 0


def test_frame_sizes_fit_the_link_budget():
    """docs/hil.md: the sensor frame and the command frame at 450 Hz fit 921600 baud with margin."""
    sensors = len(lk.Encoder().frame(lk.SENSORS, bytes(lk.SENSORS_HEAD.size + 2 * lk.EDGE.size)))
    command = len(lk.Encoder().frame(lk.COMMAND, bytes(lk.COMMAND_BODY.size)))
    assert (sensors, command) == (52, 19)
    assert sensors * 10 * 450 < 0.5 * 921600          # 8N1: 10 bits per byte


@pytest.mark.parametrize("spec, parsed", [
    ("serial:/dev/ttyUSB0,921600", ("serial", "/dev/ttyUSB0", 921600)),
    ("serial:/dev/serial0", ("serial", "/dev/serial0", lk.DEFAULT_BAUD)),
    ("tcp:5760", ("tcp", "127.0.0.1", 5760)),
    ("tcp:pc.local:5760", ("tcp", "pc.local", 5760))])
def test_link_specs(spec, parsed):
    assert lk.parse_link(spec) == parsed


@pytest.mark.parametrize("spec", ["", "serial:", "tcp:x", "udp:5", "serial:/dev/x,fast", "tcp:70000"])
def test_bad_link_specs_are_refused(spec):
    with pytest.raises(ValueError):
        lk.parse_link(spec)


def test_frames_cross_a_pty_pair_through_pyserial():
    master, slave = os.openpty()
    try:
        port = lk.SerialPort(os.ttyname(slave), 921600)
        other = lk.FdPort(master)
        frames = encode([bytes(range(40)), b"\x0d\x0a\x11\x13\x03"])   # CR, LF, XON, XOFF, ^C: raw mode
        other.write(b"".join(frames))
        dec, out = lk.Decoder(), []
        while len(out) < 2:
            out += dec.feed(port.read(1.0))
        assert [p for _, _, p in out] == [bytes(range(40)), b"\x0d\x0a\x11\x13\x03"]
        port.write(frames[0])
        assert lk.Decoder().feed(other.read(1.0))[0][2] == bytes(range(40))
        port.close()
    finally:
        os.close(master)
        os.close(slave)


def test_a_pc_side_on_this_machine_is_recognised():
    """A pty or a loopback address: the PC side runs on this machine, and the hil board's clock sleeps
    to each deadline instead of busy-waiting its last 0.2 ms (which takes the CPU the PC side needs for
    the answer: docs/hil.md); a real UART keeps the busy-wait."""
    from flightctl.boards.hil import HilClock, peer_is_local

    master, slave = os.openpty()
    srv = socket.create_server(("127.0.0.1", 0))
    try:
        pty = lk.SerialPort(os.ttyname(slave), 921600)
        tcp = lk.connect(f"tcp:127.0.0.1:{srv.getsockname()[1]}")
        assert peer_is_local(pty) and peer_is_local(tcp) and peer_is_local(lk.FdPort(master))
        uart = object.__new__(lk.SerialPort)                 # a Pi's /dev/serial0, not opened here
        uart.ser = types.SimpleNamespace(port="/dev/serial0")
        assert not peer_is_local(uart)
        assert HilClock(None, 1 / 450, 0.0).wall.spin_s == 0.0
        pty.close()
        tcp.close()
    finally:
        srv.close()
        os.close(master)
        os.close(slave)


def test_every_answered_command_counts_once_in_the_latency_however_late():
    """The latency is the time from a command to the first sensor frame acknowledging it: an answer
    arriving 300 commands later (a stalled PC side) is counted, a second frame with the same ack is not."""
    from flightctl.boards.hil import HilLink

    a, b = socket.socketpair()
    try:
        link = HilLink(lk.FdPort(a.detach()))              # the link closes the descriptor
        for _ in range(300):
            link.send_command()
            b.recv(64)                                       # the PC side takes the command, answers none
        pc = lk.Encoder()

        def answer(ack: int) -> bytes:
            return pc.frame(lk.SENSORS, lk.SENSORS_HEAD.pack(ack, 0, bytes(21), 0, 0, 0))
        b.sendall(answer(1) + answer(300) + answer(300))
        deadline = time.monotonic() + 5.0
        while link.dec.stats.frames < 3 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert link.dec.stats.frames == 3 and len(link.latencies) == 2
        assert link.latencies[0] > link.latencies[1] > 0
        link.close(wait_s=0.05)
    finally:
        b.close()
