"""systemd's notify protocol against a local AF_UNIX datagram socket standing for $NOTIFY_SOCKET."""
from __future__ import annotations

import os
import socket

import pytest

from flightctl.service.sdnotify import DEFAULT_PING_S, Notifier


@pytest.fixture
def listener(tmp_path):
    path = str(tmp_path / "notify.sock")
    s = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    s.bind(path)
    s.settimeout(1.0)
    yield path, s
    s.close()


def received(s: socket.socket) -> list[str]:
    out = []
    s.settimeout(0.05)
    try:
        while True:
            out.append(s.recv(4096).decode())
    except (socket.timeout, BlockingIOError):
        pass
    return out


def test_ready_status_and_stopping_are_datagrams_of_key_value_lines(listener):
    path, s = listener
    n = Notifier(path)
    assert n.ready("disarmed")
    assert n.status("flying hover")
    assert n.stopping()
    assert received(s) == ["READY=1\nSTATUS=disarmed", "STATUS=flying hover", "STOPPING=1"]


def test_watchdog_pings_from_the_loop_are_rate_limited(listener):
    path, s = listener
    now = [0.0]
    n = Notifier(path, ping_s=0.5, clock=lambda: now[0])
    for i in range(450 * 2):          # two seconds of loop ticks at 450 Hz
        now[0] = i / 450
        n.tick(i)
    pings = received(s)
    assert pings == ["WATCHDOG=1"] * 4   # at 0, 0.5, 1.0, 1.5 s


def test_abstract_namespace_socket():
    name = f"flightctl-test-{os.getpid()}"
    s = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    s.bind("\0" + name)
    try:
        assert Notifier("@" + name).ready()
        s.settimeout(1.0)
        assert s.recv(100) == b"READY=1"
    finally:
        s.close()


def test_from_env_takes_half_the_watchdog_period(listener):
    path, _ = listener
    n = Notifier.from_env({"NOTIFY_SOCKET": path, "WATCHDOG_USEC": "400000", "WATCHDOG_PID": str(os.getpid())})
    assert n.enabled and n.ping_s == pytest.approx(0.2)
    n = Notifier.from_env({"NOTIFY_SOCKET": path, "WATCHDOG_USEC": "2000000", "WATCHDOG_PID": "1"})
    assert n.ping_s == DEFAULT_PING_S       # meant for another process
    n = Notifier.from_env({})
    assert not n.enabled and n.ready() is False and n.tick(1) is None


def test_a_vanished_socket_does_not_raise(tmp_path):
    n = Notifier(str(tmp_path / "gone.sock"))
    assert n.watchdog() is False and n.errors == 1
