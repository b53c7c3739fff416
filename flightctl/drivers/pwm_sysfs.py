"""The four ESC signals from a hardware PWM through the kernel's sysfs interface (the Raspberry Pi 5's
RP1 PWM0: four channels, 50 MHz, docs/pi.md), behind the `Motors` protocol.

    /sys/class/pwm/pwmchipN/export        write a channel number: creates pwmC/ (EBUSY if taken)
    /sys/class/pwm/pwmchipN/pwmC/period   ns; then duty_cycle (ns, <= period), polarity, enable

The kernel numbers its PWM chips as they probe (the RP1's PWM0 was pwmchip2 on 6.6 kernels and is
pwmchip0 on 6.12), so the chip is found by its device (`1f00098000.pwm`, the `device` link of each
pwmchipN) or named outright (`pwmchip2`); at boot it is waited for (CHIP_WAIT_S), as is udev giving its
export file to group gpio. The kernel checks every write, and a freshly exported channel is not fresh:
it keeps whatever its last user left (the RP1's driver has no .get_state), so `start()` reads that state
and orders its writes so that each is accepted by 6.6's rule and by the later ones (`_take`). Every OSError of
the set-up is one `EscError` naming the file. The root is a parameter (the tests give a fake tree), and
so are the system calls that reach it (`fs`: open, pwrite, pread, close; the `os` module on the
vehicle, the fake kernel's in the tests).

The period is round(1e9 / 449) = 2227171 ns; the RP1 counts it in 20 ns ticks (111359 ticks, 449.000 Hz).
Each loop `write(counts)` writes the on-time (rounded to 1 us, drivers/pulses.py) of each motor whose
command changed: one `pwrite` of pre-built bytes on a pre-opened `duty_cycle` file, no allocation. The
RP1 takes a new duty cycle at the end of the running period, so no pulse is ever cut.

Only the flight controller commands the motors (docs/pi.md). At start-up a channel that is already
exported belongs to someone else (a kernel driver, another process, or a controller that died
without its ExecStopPost): the start is refused, naming it. While it runs, the driver reads back
period, duty cycle, polarity and enable of every channel (`output_problems`): `arm()` refuses on any
difference, the service checks every 2 s while disarmed, and in flight `write()` checks every
OUTPUT_CHECK_S and raises `EscError` (the loop stops the motors). What sysfs shows is the state the
kernel last applied, not a measurement of the pin: a process with /dev/mem (root) could reprogram the
RP1 behind the kernel's back, or switch the pins' function with pinctrl; the service runs without root.

The dead-man (drivers/pwm_deadman.py, a process of its own): the kernel keeps a channel's last duty
cycle when the controller dies, as pigpiod keeps a dead client's wave. While armed, no command for
`deadman_ms` (a stalled loop), or the controller's death (SIGKILL included: the pipe closes), puts the
stop pulse on the ESCs; systemd's watchdog and the unit's ExecStopPost (`--stop-motors`, below) follow.
`write()` sends its heartbeat before its duty writes: after the dead-man fired, no flight duty comes back.
`close()` puts the stop pulse, disables and unexports the channels: the lines go low, which the ESCs
take as no signal (zero thrust); the next start finds them free.
"""
from __future__ import annotations

import errno
import os
import select
import subprocess
import sys
import time
from typing import Callable, Sequence

from flightctl.drivers.pulses import (DEADMAN_MS, FREQUENCY_HZ, MAX_US, OUTPUT_CHECK_S, STOP_US,
                                      EscError, on_time_us)
from flightctl.hal import PWM_RANGE, ArmingRefused

SYSFS_PWM = "/sys/class/pwm"
EXPORT_WAIT_S = 2.0         # udev gives the new pwmC/ files to group gpio a few ms after the export
CHIP_WAIT_S = 10.0          # at boot: the PWM chip's driver probing, udev giving its export file to group gpio
POLL_S = 0.1
DEADMAN_START_S = 5.0       # the dead-man process says it is ready within this


def _read(fs, path: str) -> bytes:
    fd = fs.open(path, os.O_RDONLY | os.O_CLOEXEC)
    try:
        return fs.pread(fd, 64, 0).strip()
    finally:
        fs.close(fd)


def _store(fs, path: str, value: bytes) -> None:
    """One sysfs store: a write of the whole value on a fresh descriptor."""
    fd = fs.open(path, os.O_WRONLY | os.O_CLOEXEC)
    try:
        fs.pwrite(fd, value, 0)
    finally:
        fs.close(fd)


def period_ns(frequency_hz: float) -> int:
    return int(round(1e9 / frequency_hz))


def find_chip(root: str, chip: str) -> str:
    """The directory of PWM chip `chip` under `root`: `pwmchipN` itself, or the one whose `device`
    link names the device `chip` (e.g. 1f00098000.pwm); `EscError` naming what is there otherwise."""
    try:
        names = sorted(n for n in os.listdir(root) if n.startswith("pwmchip"))
    except OSError as e:
        raise EscError(f"no PWM chips: cannot list {root} ({e.strerror}); is the PWM overlay loaded "
                       "(docs/pi.md, \"Raspberry Pi 5\")?") from None
    if chip.startswith("pwmchip"):
        if chip in names:
            return os.path.join(root, chip)
    else:
        for n in names:
            if os.path.basename(os.path.realpath(os.path.join(root, n, "device"))) == chip:
                return os.path.join(root, n)
    seen = ", ".join(f"{n} ({os.path.basename(os.path.realpath(os.path.join(root, n, 'device')))})"
                     for n in names) or "none"
    raise EscError(f"PWM chip {chip} not found under {root} (there: {seen}); is the PWM overlay loaded "
                   "(docs/pi.md, \"Raspberry Pi 5\")?")


class SysfsPwmEsc:
    """`Motors` on four channels (motor 1..4 in conventions.md order) of a kernel PWM chip."""

    def __init__(self, chip: str, channels: Sequence[int], frequency_hz: float = FREQUENCY_HZ,
                 stop_us: int = STOP_US, max_us: int = MAX_US, deadman_ms: int = DEADMAN_MS, *,
                 pins: Sequence[int] | None = None, root: str = SYSFS_PWM, fs=os,
                 clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep):
        channels = tuple(int(c) for c in channels)
        if len(channels) != 4 or len(set(channels)) != 4 or min(channels) < 0:
            raise ValueError(f"ESC channels: four different PWM channels needed, got {list(channels)}")
        self.chip, self.channels, self.root, self.fs = chip, channels, root, fs
        self.pins = tuple(pins) if pins is not None else None
        self.frequency_hz = frequency_hz
        self.period_ns = period_ns(frequency_hz)
        if not 0 < stop_us < max_us < self.period_ns // 1000:
            raise ValueError(f"ESC pulses: need 0 < stop_us ({stop_us}) < max_us ({max_us}) < period "
                             f"({self.period_ns} ns at {frequency_hz:g} Hz)")
        self.stop_us, self.max_us = int(stop_us), int(max_us)
        self.deadman_ms = int(deadman_ms)
        self._clock, self._sleep = clock, sleep
        self._us_per_count = self.period_ns / 1000.0 / PWM_RANGE
        # the duty_cycle bytes of every on-time the driver can send, built once: write() allocates nothing
        self._duty = [b"%d\n" % (us * 1000) for us in range(self.stop_us, self.max_us + 1)]
        self._stop_bytes = self._duty[0]
        self._period_bytes = b"%d\n" % self.period_ns
        self.dir: str | None = None              # the chip's directory
        self._fds: list[dict[str, int]] = []     # per channel: period, duty_cycle, enable, polarity
        self._duty_fd = [-1, -1, -1, -1]
        self._on = [0, 0, 0, 0]                  # on-times (us) last written
        self._exported: list[int] = []           # channels this driver exported (unexported at close)
        self._deadman: subprocess.Popen | None = None
        self._beat = -1                          # write end of the dead-man's pipe
        self._last_check = 0.0
        self._boot_end = 0.0
        self.armed = False
        self.writes = 0                          # duty_cycle writes so far

    # --- naming ------------------------------------------------------------------------------
    def _name(self, i: int) -> str:
        pin = f"GPIO {self.pins[i]}, " if self.pins else ""
        return f"motor {i + 1} ({pin}{os.path.basename(self.dir or self.chip)} channel {self.channels[i]})"

    # --- lifecycle ---------------------------------------------------------------------------
    def start(self) -> None:
        """Export the four channels (refusing any already exported), take each from whatever state its
        last user left to the stop pulse, start the dead-man. Every failure is one `EscError` naming the
        file; what was exported is released again."""
        self._boot_end = self._clock() + CHIP_WAIT_S      # one bound for the chip and udev's permission
        self.dir = self._wait_for_chip()
        npwm = int(self._setup(_read, os.path.join(self.dir, "npwm")))
        for i, c in enumerate(self.channels):
            if c >= npwm:
                raise EscError(f"{self._name(i)}: {os.path.basename(self.dir)} has {npwm} channels (0..{npwm - 1})")
        try:
            for i, c in enumerate(self.channels):
                self._export(i, c)
            for i, c in enumerate(self.channels):
                fds = self._open_channel(c)
                self._fds.append(fds)
                self._duty_fd[i] = fds["duty_cycle"]
                self._take(i, fds)
            if self.deadman_ms > 0:
                self._start_deadman()
        except BaseException:
            self.close()
            raise

    def _setup(self, call, path: str, *args):
        """A system call of the set-up; its OSError as one `EscError` naming the file."""
        try:
            return call(self.fs, path, *args)
        except OSError as e:
            raise EscError(f"{path}: {e.strerror or e} (errno {e.errno}) while setting up the ESC output") from None

    def _wait_for_chip(self) -> str:
        """The chip's directory, waited for up to CHIP_WAIT_S: at boot the RP1's PWM driver may probe
        after the service started."""
        while True:
            try:
                return find_chip(self.root, self.chip)
            except EscError as e:
                if self._clock() > self._boot_end:
                    raise EscError(f"{e} (waited {CHIP_WAIT_S:g} s)") from None
            self._sleep(POLL_S)

    def _export(self, i: int, c: int) -> None:
        if os.path.isdir(os.path.join(self.dir, f"pwm{c}")):
            raise EscError(f"{self._name(i)} is already exported: another process drives it (or a "
                           "controller died without its ExecStopPost; `flightctl run --board pi5 "
                           "--stop-motors` releases it)")
        path = os.path.join(self.dir, "export")
        while True:
            try:
                _store(self.fs, path, b"%d\n" % c)
                break
            except OSError as e:
                if e.errno == errno.EBUSY:
                    raise EscError(f"{self._name(i)} is held by a kernel driver (EBUSY on export): "
                                   "this channel is not free for the ESCs") from None
                if e.errno in (errno.EACCES, errno.EPERM) and self._clock() <= self._boot_end:
                    self._sleep(POLL_S)         # at boot udev may not yet have given the chip to group gpio
                    continue
                raise EscError(f"{self._name(i)} cannot be exported: {path}: {e.strerror}: is the user in group "
                               "gpio and the udev rule installed (docs/pi.md)?") from None
        self._exported.append(c)

    def _take(self, i: int, fds: dict[str, int]) -> None:
        """From the state the channel's last user left to the stop pulse at our period, each write a state
        the kernel accepts. pwm-rp1 has no .get_state and unexport does not reset a channel, so it keeps
        its last user's period, duty cycle, enable and polarity (tests/helpers/fakes/sysfs_pwm.py, from the
        Raspberry Pi kernel's sysfs.c, core.c and pwm-rp1.c). 6.6 refuses any state with period 0 or
        duty_cycle > period, enabled or not; from 6.11 an invalid state may follow an invalid one, and
        which states count as invalid was inverted until the fix in 6.16 (and its stable backports): 6.11
        checks disabled states only, 6.16 enabled ones only. So, with every intermediate state having a
        period and a duty cycle no longer than it wherever the held state allows:
        - disabled first (unless it is off already: disabling a channel that never had a period is EINVAL
          on 6.6); then the period before the duty cycle if the held duty cycle fits our period, else the
          duty cycle first (the held period is then at least as long, or the state was invalid anyway);
        - an enabled state without a valid period and duty cycle (only 6.11 leaves one) is mended while
          enabled, where 6.11 checks nothing (disabling it there would be EINVAL): the stop pulse's duty
          cycle, then the period;
        then polarity, and enabled last."""
        held = {}
        for name, fd in fds.items():
            try:
                held[name] = self.fs.pread(fd, 64, 0).strip()
            except OSError as e:
                raise EscError(f"{self._channel_file(i, name)}: cannot be read ({e.strerror}) while setting up "
                               "the ESC output") from None
        try:
            duty, enabled = int(held["duty_cycle"]), held["enable"] == b"1"
        except ValueError:
            raise EscError(f"{self._channel_file(i, 'duty_cycle')}: reads {held['duty_cycle']!r}, not a number") from None
        try:
            period = int(held["period"])
        except ValueError:
            raise EscError(f"{self._channel_file(i, 'period')}: reads {held['period']!r}, not a number") from None
        order = (("period", self._period_bytes), ("duty_cycle", self._stop_bytes))
        if enabled and not 0 < period >= duty:
            steps = list(order[::-1])
        else:
            steps = [("enable", b"0\n")] if enabled else []
            steps += order if duty <= self.period_ns else order[::-1]
        steps += [("polarity", b"normal\n"), ("enable", b"1\n")]
        for name, value in steps:
            try:
                self.fs.pwrite(fds[name], value, 0)
            except OSError as e:
                raise EscError(f"{self._channel_file(i, name)}: writing {value.decode().strip()} failed "
                               f"({e.strerror}); the channel held period {held['period'].decode()}, duty_cycle "
                               f"{held['duty_cycle'].decode()}, enable {held['enable'].decode()}, polarity "
                               f"{held['polarity'].decode()}") from None
        self._on[i] = self.stop_us

    def _channel_file(self, i: int, name: str) -> str:
        return os.path.join(self.dir, f"pwm{self.channels[i]}", name)

    def _open_channel(self, c: int) -> dict[str, int]:
        """Open the channel's files; udev makes them writable for group gpio shortly after the export."""
        d = os.path.join(self.dir, f"pwm{c}")
        end = self._clock() + EXPORT_WAIT_S
        while True:
            out = {}
            try:
                for name in ("period", "duty_cycle", "enable", "polarity"):
                    out[name] = self.fs.open(os.path.join(d, name), os.O_RDWR | os.O_CLOEXEC)
                return out
            except OSError as e:
                for fd in out.values():
                    self.fs.close(fd)
                if not isinstance(e, (PermissionError, FileNotFoundError)):
                    raise EscError(f"cannot open {e.filename or d} ({e.strerror}) while setting up the ESC output") from None
                if self._clock() > end:
                    raise EscError(f"cannot open {d}/{e.filename and os.path.basename(e.filename)} ({e.strerror}): "
                                   "is the user in group gpio and the udev rule installed (docs/pi.md)?") from None
                self._sleep(0.01)

    def _start_deadman(self) -> None:
        r, w = os.pipe()
        ready_r, ready_w = os.pipe()
        fds = list(self._duty_fd)
        try:
            self._deadman = subprocess.Popen(
                [sys.executable, "-m", "flightctl.drivers.pwm_deadman", str(r), str(ready_w), str(self.deadman_ms),
                 str(self.stop_us * 1000)] + [str(fd) for fd in fds],
                pass_fds=[r, ready_w] + fds, stdin=subprocess.DEVNULL, start_new_session=False)
        except OSError as e:
            for fd in (w, ready_r):
                os.close(fd)
            raise EscError(f"{sys.executable}: the ESC dead-man process cannot be started ({e.strerror})") from None
        finally:
            os.close(r)
            os.close(ready_w)
        try:
            ready = os.read(ready_r, 1) if self._wait_readable(ready_r, DEADMAN_START_S) else b""
        finally:
            os.close(ready_r)
        if ready != b"r":
            os.close(w)
            raise EscError("the ESC dead-man process did not start")
        os.set_blocking(w, False)
        self._beat = w

    @staticmethod
    def _wait_readable(fd: int, timeout: float) -> bool:
        return bool(select.select([fd], [], [], timeout)[0])

    def _tell(self, what: bytes) -> None:
        if self._beat < 0:
            if self.armed and self.deadman_ms > 0:
                raise self._fired()             # it fired before: never a flight duty cycle again
            return
        try:
            os.write(self._beat, what)
        except BlockingIOError:
            pass
        except BrokenPipeError:
            os.close(self._beat)
            self._beat = -1
            raise self._fired() from None

    def _fired(self) -> EscError:
        return EscError(f"the ESC dead-man stopped the motors: no command reached it for {self.deadman_ms} ms "
                        "(the loop stalled)")

    def _lost(self, problems: list[str]) -> EscError:
        """What the read-back differences mean: the dead-man's stop pulse (it has fired and exited), or
        another process."""
        if self.armed and self._deadman is not None:
            try:
                self._deadman.wait(0.05)
            except subprocess.TimeoutExpired:
                pass
            if self._deadman.poll() is not None:
                return self._fired()
        return EscError("ESC output: " + "; ".join(problems))

    def arm(self) -> None:
        if self.dir is None:
            self.start()
        problems = self.output_problems()
        if self.deadman_ms > 0 and (self._deadman is None or self._deadman.poll() is not None):
            problems.append("the ESC dead-man process is not running")
        if problems:
            raise ArmingRefused("ESC output: " + "; ".join(problems))
        self.stop()
        self._tell(b"a")
        self.armed = True

    def write(self, counts: list[int]) -> None:
        """The on-times of the commands whose value changed. While armed the heartbeat comes first, at
        every call: once the dead-man has fired (and closed its end of the pipe) the write fails with
        EPIPE and this raises before any flight duty cycle could replace its stop pulse."""
        if self.armed:
            self._tell(b"h")
        k, lo, hi, on, fds, pwrite, duty = self._us_per_count, self.stop_us, self.max_us, self._on, \
            self._duty_fd, self.fs.pwrite, self._duty
        for i in (0, 1, 2, 3):
            us = on_time_us(counts[i], k, lo, hi)
            if us != on[i]:
                pwrite(fds[i], duty[us - lo], 0)
                on[i] = us
                self.writes += 1
        now = self._clock()
        if now - self._last_check >= OUTPUT_CHECK_S:
            self._last_check = now
            problems = self.output_problems()
            if problems:
                raise self._lost(problems)

    def stop(self) -> None:
        """The stop pulse on every channel, always written (another process may have changed it); the
        dead-man's countdown off."""
        if self.dir is None:
            self.start()
        for i in range(len(self._fds)):
            self.fs.pwrite(self._duty_fd[i], self._stop_bytes, 0)
            self._on[i] = self.stop_us
        if self.armed:
            self.armed = False
            try:
                self._tell(b"s")
            except EscError:
                pass

    def close(self) -> None:
        """The stop pulse, then the channels disabled and unexported (lines low: no signal, zero thrust),
        the dead-man ended. Safe to call twice."""
        fs = self.fs
        for fds in self._fds:
            for what, value in (("duty_cycle", self._stop_bytes), ("enable", b"0\n")):
                try:
                    fs.pwrite(fds[what], value, 0)
                except OSError:
                    pass
        self.armed = False
        if self._beat >= 0:
            try:
                os.write(self._beat, b"q")
            except OSError:
                pass
            os.close(self._beat)
            self._beat = -1
        if self._deadman is not None:
            try:
                self._deadman.wait(2.0)
            except subprocess.TimeoutExpired:
                self._deadman.kill()
                self._deadman.wait()
            self._deadman = None
        for fds in self._fds:
            for fd in fds.values():
                fs.close(fd)
        self._fds, self._duty_fd = [], [-1, -1, -1, -1]
        while self._exported:
            c = self._exported.pop()
            try:
                _store(self.fs, os.path.join(self.dir, "unexport"), b"%d\n" % c)
            except OSError:
                pass

    # --- read-back -----------------------------------------------------------------------------
    def output_problems(self) -> list[str]:
        """What the kernel reports on the ESC channels that this driver did not write (empty: nothing)."""
        if self.dir is None:
            return []
        problems = []
        pread = self.fs.pread
        for i, fds in enumerate(self._fds):
            try:
                seen = {k: pread(fd, 64, 0).strip() for k, fd in fds.items()}
            except OSError as e:
                problems.append(f"{self._name(i)} cannot be read back ({e.strerror}): unexported by another process?")
                continue
            want = {"period": self._period_bytes.strip(), "duty_cycle": b"%d" % (self._on[i] * 1000),
                    "enable": b"1", "polarity": b"normal"}
            for k, v in want.items():
                if seen[k] != v:
                    problems.append(f"{self._name(i)}: {k} reads {seen[k].decode(errors='replace')}, not the "
                                    f"{v.decode()} this controller wrote: another process writes this channel")
        return problems

    def check_output(self) -> None:
        """While disarmed: raise `EscError` naming what another process changed, after putting the stop
        pulse back."""
        problems = self.output_problems()
        if problems:
            self.stop()
            raise EscError("ESC output changed while disarmed: " + "; ".join(problems))

    def check_frequency(self) -> float:
        """The frequency the kernel applied (period read back), in Hz; `ArmingRefused` if it is not ours."""
        problems = self.output_problems()
        if problems:
            raise ArmingRefused("ESC output: " + "; ".join(problems))
        return 1e9 / self.period_ns

    def on_times_us(self) -> list[int]:
        return list(self._on)


def release(root: str, chip: str, channels: Sequence[int], stop_us: int = STOP_US, fs=os) -> list[str]:
    """Whatever a dead controller left on the ESC channels: the stop pulse, then disabled and unexported
    (the systemd ExecStopPost, `flightctl run --board pi5 --stop-motors`). Returns what was done."""
    d = find_chip(root, chip)
    done = []
    for c in channels:
        ch = os.path.join(d, f"pwm{c}")
        if not os.path.isdir(ch):
            continue
        for name, value in (("duty_cycle", b"%d\n" % (stop_us * 1000)), ("enable", b"0\n")):
            try:
                _store(fs, os.path.join(ch, name), value)
            except OSError:
                pass        # a period shorter than the stop pulse (not ours): disable and unexport anyway
        _store(fs, os.path.join(d, "unexport"), b"%d\n" % c)
        done.append(f"pwm{c}")
    return done
