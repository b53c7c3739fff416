"""The Pi 5's ESC dead-man: a small process beside the controller that puts the stop pulse on the ESCs
when the controller stops commanding them (drivers/pwm_sysfs.py starts it; docs/pi.md).

A kernel PWM channel keeps its last duty cycle after the process that wrote it dies, exactly as
pigpiod keeps sending a dead client's wave. On the Pi 3/4 a script inside pigpiod is the dead-man; the
kernel has nothing like it, so this process is. It holds open the four `duty_cycle` files (inherited
from the controller) and the read end of a pipe whose write end only the controller holds:

    a       armed: from now on, no message for TIMEOUT_MS puts the stop pulse on the ESCs
    h       heartbeat (the controller's write(), at every call while armed, before its duty writes)
    s       disarmed: no countdown (the controller has put the stop pulse itself)
    q       quit without writing (the controller is releasing the channels itself)
    EOF     the controller died (crash, SIGKILL, OOM): the stop pulse at once
    SIGTERM (`systemctl kill flightctl`, which signals every process of the unit): the stop pulse, then exit

When it has fired it closes its end of the pipe, writes the stop pulse and exits, and stays gone: the
controller's next heartbeat, which `write()` sends before any duty cycle, finds the pipe broken and stops
its loop (EscError) without putting a flight duty cycle back, as the pigpio driver does when its dead-man
fired. It must outlive the controller to fire on its death: the unit's KillMode=process leaves it alone
when the controller dies (systemd/flightctl.service; with KillMode=mixed systemd SIGKILLs it together with
a dead main process, a race with this stop pulse).
Only the standard library, and nothing but `os.pwrite` of one fixed, valid value once it has fired.

    python -m flightctl.drivers.pwm_deadman PIPE_FD READY_FD TIMEOUT_MS STOP_DUTY_NS FD [FD ...]
"""
from __future__ import annotations

import os
import select
import signal
import sys


def run(pipe: int, ready: int, timeout_ms: int, stop: bytes, fds: list[int]) -> str:
    """Serve the pipe until the controller quits, dies or stalls; returns why it ended."""
    def fire(*_):
        for fd in fds:
            try:
                os.pwrite(fd, stop, 0)
            except OSError:
                pass

    def on_term(signum, frame):
        fire()
        os._exit(0)

    signal.signal(signal.SIGTERM, on_term)
    signal.signal(signal.SIGINT, signal.SIG_IGN)    # a Ctrl-C reaches the controller, which stops itself
    os.write(ready, b"r")
    os.close(ready)
    armed = False
    poll = select.poll()
    poll.register(pipe, select.POLLIN)
    while True:
        if not poll.poll(timeout_ms if armed else None):
            os.close(pipe)      # first: the controller's next heartbeat fails (EPIPE) before its duty writes
            fire()
            return "fired: no command"
        data = os.read(pipe, 256)
        if not data:
            fire()
            return "fired: the controller is gone"
        last = data[-1:]
        if last == b"q":
            return "quit"
        if last in (b"a", b"h"):
            armed = True
        elif last == b"s":
            armed = False


def main(argv: list[str]) -> int:
    pipe, ready, timeout_ms = int(argv[0]), int(argv[1]), int(argv[2])
    stop = argv[3].encode() + b"\n"
    run(pipe, ready, timeout_ms, stop, [int(a) for a in argv[4:]])
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
