"""systemd's notify protocol, implemented here (no dependency): datagrams of `KEY=VALUE` lines sent to
the AF_UNIX socket named by `$NOTIFY_SOCKET` ('@' at its start means the abstract namespace).

`READY=1` once the service is up (disarmed, pre-arm checks passed), `WATCHDOG=1` from the loop
(rate-limited: `tick(i)` is cheap enough for every loop iteration), `STOPPING=1` on the way out,
`STATUS=...` for `systemctl status`. Without `$NOTIFY_SOCKET` (not under systemd) every call is a
no-op that returns False.
"""
from __future__ import annotations

import os
import socket
import time
from typing import Callable

DEFAULT_PING_S = 0.5


class Notifier:
    def __init__(self, address: str | None = None, ping_s: float = DEFAULT_PING_S,
                 clock: Callable[[], float] = time.monotonic):
        self.address = address
        self.ping_s = ping_s
        self._clock = clock
        self._next_ping = 0.0
        self.sent = 0
        self.errors = 0
        self._sock = None
        if address:
            self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM | socket.SOCK_CLOEXEC)
            self._sock.setblocking(False)
            self._addr = "\0" + address[1:] if address.startswith("@") else address

    @classmethod
    def from_env(cls, environ=None, clock: Callable[[], float] = time.monotonic) -> "Notifier":
        """From `$NOTIFY_SOCKET`; the watchdog ping interval is half of `$WATCHDOG_USEC` (when it is
        meant for this process, `$WATCHDOG_PID`), at most DEFAULT_PING_S."""
        env = os.environ if environ is None else environ
        ping = DEFAULT_PING_S
        usec = env.get("WATCHDOG_USEC")
        pid = env.get("WATCHDOG_PID")
        if usec and (not pid or pid == str(os.getpid())):
            try:
                ping = min(ping, int(usec) / 2e6)
            except ValueError:
                pass
        return cls(env.get("NOTIFY_SOCKET") or None, ping, clock)

    @property
    def enabled(self) -> bool:
        return self._sock is not None

    def notify(self, *lines: str) -> bool:
        if self._sock is None:
            return False
        try:
            self._sock.sendto("\n".join(lines).encode(), self._addr)
        except OSError:
            self.errors += 1
            return False
        self.sent += 1
        return True

    def ready(self, status: str | None = None) -> bool:
        return self.notify("READY=1", *([f"STATUS={status}"] if status else []))

    def status(self, text: str) -> bool:
        return self.notify(f"STATUS={text}")

    def stopping(self, status: str | None = None) -> bool:
        return self.notify("STOPPING=1", *([f"STATUS={status}"] if status else []))

    def watchdog(self) -> bool:
        """WATCHDOG=1 now, unconditionally."""
        self._next_ping = self._clock() + self.ping_s
        return self.notify("WATCHDOG=1")

    def tick(self, i: int = 0) -> bool | None:
        """The loop's `on_tick` hook: a WATCHDOG=1 at most every `ping_s`. False when a ping could
        not be sent (the socket is gone: systemd will kill the process; the loop lands on it), else None."""
        if self._sock is not None and self._clock() >= self._next_ping and not self.watchdog():
            return False
        return None

    def close(self) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None
