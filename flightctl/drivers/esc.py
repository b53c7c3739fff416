"""The four ESC signals on pigpio at 449 Hz, behind the `Motors` protocol, with a pigpiod-side dead-man.

Why a wave: pigpio's DMA PWM (`set_PWM_frequency`) offers only fixed frequencies and silently
returns the closest one: 449 Hz becomes 400 Hz, and since the ESCs read the on-time, every pulse
would be 12 % longer than the controller meant. Hardware PWM is exact but has two channels. So all
four signals come from one repeating DMA wave (`wave_add_generic` -> `wave_create` ->
`wave_send_using_mode(wid, WAVE_MODE_REPEAT_SYNC)`) whose period is round(1e6 / 449) = 2227 us
(449.03 Hz); pigpio times waves to 1 us. Every cycle raises the four outputs together at t = 0 and
drops each after its on-time.

Counts: `write(counts)` takes the paper's duty on 0..PWM_RANGE (40000) of the period, so the on-time is
`counts / 40000 * 2227 us` (conventions.md: count = P / 255 * 40000). On-times are clamped to
[stop_us, max_us]: below the ESC's stop pulse every command is zero thrust anyway (eq. 26's dead zone
h2 = 120 is 1048 us), and a signal that never goes high would look like a lost signal to the ESC.

Changing the command: a new wave is built and sent with REPEAT_SYNC, so pigpio switches at the end
of the running cycle and no pulse is ever cut. pigpio (gpioWaveTxSend) links the end of the wave
sent *last* to the new one, so a wave sent before its predecessor started would queue behind it for
a full cycle; the loop (450 Hz) is slightly faster than the ESC period (449.03 Hz), and such a queue
would grow by one period of lag every second. So a new wave is sent only once `wave_tx_at()` shows
the last one on the pins; otherwise the command waits for the next write (the ESC takes one command
per period anyway): at most one wave is ever queued, the lag stays under two periods. Replaced waves
are deleted once a later one is on the pins (deleting a wave still queued or running would hand its
DMA blocks to the next wave). A command equal to the last one (at 1 us resolution) sends nothing.
Cost per changed command: five pigpiod round trips (tx_at, delete, add, create, send).

Reading the frequency back (`arm()` refuses with `ArmingRefused` naming both frequencies): pigpio's own
account of the built wave (`wave_get_micros`) must equal the period, and the real output is measured
by pigpio edge callbacks on the four output pins for `measure_s`: the rising-edge period and the
stop-pulse width of every pin must match. The measurement catches what no configuration read can:
a wave clock running at the wrong rate (pigpio issue #331: waves at half speed on some Pi setups),
an output pin that does not toggle, a wiring mix-up in the board file.

The dead-man: pigpiod keeps sending the last wave when its client dies, so the motors would keep
spinning. While armed, a pigpio script runs inside pigpiod:

    tag 0  mils 10  dcr p0  jp 0  wvhlt  w <pin> 0 (x4)  wvtxr <stop wave>  halt

It counts p0 down every 10 ms; `write()` sets p0 back to deadman_ms / 10 (`update_script`, at most
every REFRESH_S). If the controller stops writing for `deadman_ms` (it crashed, hung, was killed with
SIGKILL, or lost its socket), the script halts the flight wave, drives the pins low and repeats the
stop wave: zero thrust within ~deadman_ms + one period, without the controller and without systemd.
`stop()` sends the stop wave and removes the script. `start()` (and `stop_motors`, the systemd
ExecStopPost) removes stale scripts left by a dead controller: pigpiod on the quadcopter is
flightctl's own, so every script in its 32 slots is ours. The systemd unit's ExecStopPost and its
watchdog are the second layer (docs/pi.md).

Only the flight controller commands the motors: the units keep every other process away
from pigpiod (systemd/, docs/pi.md), and the driver reads the output back in case something else got
through. `output_problems()` names what differs from what this driver sent: a wave pigpiod transmits
that is not ours (another client's), no wave at all, an ESC pin no longer an output, and with
`measure=True` the real pin output (edges) against the stop pulse. `arm()` refuses on any of them
before it touches the output; the service calls `check_output()` every few seconds while disarmed;
in flight `write()` reads back the transmitted wave every OUTPUT_CHECK_S and raises `EscError` (the
loop stops the motors: whoever else drives the pins, this driver cannot land the vehicle through
them). `stop()` always sends the stop wave, whatever it believes is on the pins.
"""
from __future__ import annotations

import time
from typing import Callable, Sequence

import pigpio

from flightctl.drivers.pulses import (DEADMAN_MS, FREQUENCY_HZ, MAX_US, OUTPUT_CHECK_S, REFRESH_S, STOP_US,  # noqa: F401
                                      EscError, on_time_us)
from flightctl.hal import PWM_RANGE, ArmingRefused

# The defaults of the driver, and of the board file's [esc] keys (flightctl/boards/pi.py): the ESC
# signal's own in drivers/pulses.py (both Pi boards), pigpio's here.
DEADMAN_TICK_MS = 10        # the script's countdown step
FREQUENCY_TOLERANCE_HZ = 0.5
WIDTH_TOLERANCE_US = 12.0   # pigpio samples edges every 5 us by default
MEASURE_S = 0.15            # ~67 periods per pin
MIN_PERIODS = 10
STUCK_S = 0.05              # a wave sent this long ago and still not on the pins: output stuck
CHECK_MEASURE_S = 0.03      # disarmed read-back: edges measured this long (~13 periods per pin)
SCRIPT_SLOTS = 32           # pigpiod's script table


def period_us(frequency_hz: float) -> int:
    return int(round(1e6 / frequency_hz))


def wave_pulses(pins: Sequence[int], on_us: Sequence[int], period: int) -> list[pigpio.pulse]:
    """One cycle: all pins high at t = 0, each low after its on-time, the cycle `period` us long."""
    if not all(0 < t < period for t in on_us):
        raise ValueError(f"on-times {list(on_us)} must lie inside the {period} us period")
    times = sorted(set(on_us))
    pulses = [pigpio.pulse(sum(1 << p for p in pins), 0, times[0])]
    for k, t in enumerate(times):
        off = sum(1 << p for p, u in zip(pins, on_us) if u == t)
        end = times[k + 1] if k + 1 < len(times) else period
        pulses.append(pigpio.pulse(0, off, end - t))
    return pulses


def deadman_script(pins: Sequence[int], stop_wid: int, tick_ms: int = DEADMAN_TICK_MS) -> str:
    lows = " ".join(f"w {p} 0" for p in pins)
    return f"tag 0 mils {tick_ms} dcr p0 jp 0 wvhlt {lows} wvtxr {stop_wid} halt"


class PigpioEsc:
    """`Motors` on four GPIOs (motor 1..4 in conventions.md order) of a `pigpio.pi`."""

    def __init__(self, pi, pins: Sequence[int], frequency_hz: float = FREQUENCY_HZ, stop_us: int = STOP_US,
                 max_us: int = MAX_US, deadman_ms: int = DEADMAN_MS,
                 tolerance_hz: float = FREQUENCY_TOLERANCE_HZ, measure_s: float = MEASURE_S,
                 clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep):
        pins = tuple(int(p) for p in pins)
        if len(pins) != 4 or len(set(pins)) != 4 or not all(0 <= p <= 31 for p in pins):
            raise ValueError(f"ESC pins: four different user GPIOs 0..31 needed, got {list(pins)}")
        self.pi, self.pins = pi, pins
        self.frequency_hz = frequency_hz
        self.period_us = period_us(frequency_hz)
        if not 0 < stop_us < max_us < self.period_us:
            raise ValueError(f"ESC pulses: need 0 < stop_us ({stop_us}) < max_us ({max_us}) < period "
                             f"({self.period_us} us at {frequency_hz:g} Hz)")
        self.stop_us, self.max_us = int(stop_us), int(max_us)
        self.deadman_ms = int(deadman_ms)
        self.tolerance_hz, self.measure_s = tolerance_hz, measure_s
        self._clock, self._sleep = clock, sleep
        self._us_per_count = self.period_us / PWM_RANGE
        self._countdown = max(2, -(-self.deadman_ms // DEADMAN_TICK_MS))
        self._started = False
        self._stop_wid: int | None = None
        self._current: int | None = None    # the wave last sent
        self._retired: list[int] = []       # replaced waves, in the order sent, not yet deleted
        self._on: list[int] | None = None   # on-times (us) of the wave last sent
        self._t_sent = 0.0                  # when the wave last sent was sent
        self.deferred = 0                   # writes deferred so far (one per second at 450 Hz is normal)
        self._sid: int | None = None        # the dead-man script while armed
        self._last_refresh = 0.0
        self.built_period_us: int | None = None
        self.measured: dict[int, tuple[float, float, int]] = {}
        self.armed = False
        self.waves_sent = 0
        self._last_check = 0.0

    # --- lifecycle ---------------------------------------------------------------------------
    def start(self) -> None:
        """Take over pigpiod's wave engine: remove stale dead-man scripts, clear old waves, and put the
        stop pulse on all four outputs."""
        pi = self.pi
        self.remove_scripts()
        pi.wave_tx_stop()
        pi.wave_clear()
        for p in self.pins:
            pi.set_mode(p, pigpio.OUTPUT)
            pi.write(p, 0)
        pi.wave_add_new()
        pi.wave_add_generic(wave_pulses(self.pins, [self.stop_us] * 4, self.period_us))
        self.built_period_us = pi.wave_get_micros()
        self._stop_wid = pi.wave_create()
        pi.wave_send_using_mode(self._stop_wid, pigpio.WAVE_MODE_REPEAT_SYNC)
        self._current, self._retired, self._on = self._stop_wid, [], [self.stop_us] * 4
        self._t_sent = self._clock()
        self._started = True
        self.waves_sent += 1

    def remove_scripts(self) -> int:
        """Stop and delete every script stored in pigpiod (stale dead-men); returns how many."""
        removed = 0
        for sid in range(SCRIPT_SLOTS):
            status, _ = self.pi.script_status(sid)
            if status < 0:
                continue
            try:
                self.pi.stop_script(sid)
            except pigpio.error:
                pass
            self.pi.delete_script(sid)
            removed += 1
        return removed

    def arm(self) -> None:
        if not self._started:
            self.start()
        problems = self.output_problems()
        if problems:
            raise ArmingRefused("ESC output: " + "; ".join(problems))
        self.stop()
        self.check_frequency()
        self._start_deadman()
        self.armed = True

    def write(self, counts: list[int]) -> None:
        k, lo, hi = self._us_per_count, self.stop_us, self.max_us
        on = [on_time_us(c, k, lo, hi) for c in counts]
        if on != self._on:
            self._send(on)
        now = self._clock()
        if self._sid is not None and now - self._last_refresh >= REFRESH_S:
            self.pi.update_script(self._sid, [self._countdown])
            self._last_refresh = now
        if now - self._last_check >= OUTPUT_CHECK_S:
            self._last_check = now
            at = self.pi.wave_tx_at()
            if not self._ours(at):
                raise EscError("ESC output: " + self._foreign(at))

    def stop(self) -> None:
        """The stop pulse on every output (at the end of the running cycle), then the dead-man removed.
        Always sent: another client may have replaced it (a wave sent again is only queued behind itself)."""
        if not self._started:
            self.start()
        else:
            self.pi.wave_send_using_mode(self._stop_wid, pigpio.WAVE_MODE_REPEAT_SYNC)
            if self._current != self._stop_wid:
                self._retired.append(self._current)
            self._current, self._on = self._stop_wid, [self.stop_us] * 4
            self._t_sent = self._clock()
            self.waves_sent += 1
        if self._sid is not None:
            sid, self._sid = self._sid, None
            try:
                self.pi.stop_script(sid)
            except pigpio.error:
                pass
            self.pi.delete_script(sid)
        self.armed = False

    def close(self) -> None:
        """Leave the stop pulse running in pigpiod (the safe state) and forget the output."""
        self.stop()

    # --- waves ---------------------------------------------------------------------------------
    def on_times_us(self) -> list[int] | None:
        """The on-times of the wave last sent."""
        return None if self._on is None else list(self._on)

    def _send(self, on: list[int]) -> None:
        pi = self.pi
        at = pi.wave_tx_at()
        if at != self._current:          # the wave sent last is still queued: this command waits
            self.deferred += 1
            waited = self._clock() - self._t_sent
            if (at == self._stop_wid and self._sid is not None and self._current != self._stop_wid
                    and waited > 2e-6 * self.period_us):
                raise EscError(f"the pigpiod dead-man stopped the motors: no command reached it for "
                               f"{self.deadman_ms} ms (the loop stalled)")
            if waited > STUCK_S:
                raise EscError(f"ESC output stuck: pigpiod transmits wave {at}, not wave {self._current} "
                               f"sent {waited * 1e3:.0f} ms ago")
            return
        for wid in self._retired:        # all sent before the one now on the pins: finished
            pi.wave_delete(wid)
        self._retired.clear()
        pi.wave_add_generic(wave_pulses(self.pins, on, self.period_us))
        wid = pi.wave_create()
        pi.wave_send_using_mode(wid, pigpio.WAVE_MODE_REPEAT_SYNC)
        if self._current != self._stop_wid:
            self._retired.append(self._current)
        self._current, self._on = wid, on
        self._t_sent = self._clock()
        self.waves_sent += 1

    # --- checks ----------------------------------------------------------------------------------
    def _ours(self, at: int) -> bool:
        """Is `at` (wave_tx_at) a wave this driver sent: the last one, one it replaced that is still
        finishing its cycle, or the stop wave (ours, sent by the dead-man too)?"""
        return at == self._current or at == self._stop_wid or at in self._retired

    def _foreign(self, at: int) -> str:
        if at in (pigpio.NO_TX_WAVE, pigpio.WAVE_NOT_FOUND):
            return f"no wave on the ESC pins (pigpiod reports {at}): another pigpiod client stopped or deleted it"
        return f"pigpiod transmits wave {at}, not this controller's wave {self._current}: another pigpiod client"

    def output_problems(self, measure: bool = False) -> list[str]:
        """What differs on the ESC pins from what this driver sent (empty: nothing), read back from
        pigpiod: the wave transmitted, the pins' modes, and with `measure` the real output (edges)."""
        if not self._started:
            return []
        problems = []
        at = self.pi.wave_tx_at()
        if not self._ours(at):
            problems.append(self._foreign(at))
        for motor, p in enumerate(self.pins, start=1):
            mode = self.pi.get_mode(p)
            if mode != pigpio.OUTPUT:
                kind = "an input" if mode == pigpio.INPUT else f"mode {mode}"
                problems.append(f"motor {motor} (GPIO {p}) is {kind}, not an output: another pigpiod client")
        if measure and self._current == self._stop_wid:
            measured = self.measure(CHECK_MEASURE_S)
            for motor, p in enumerate(self.pins, start=1):
                _, high, n = measured[p]
                if n and abs(high - self.stop_us) > WIDTH_TOLERANCE_US:
                    problems.append(f"motor {motor} (GPIO {p}) outputs {high:.0f} us pulses, not the "
                                    f"{self.stop_us} us stop pulse: another pigpiod client")
        return problems

    def check_output(self) -> None:
        """While disarmed: raise `EscError` naming what another process changed on the ESC pins, and
        put the stop wave back (the stop pulse: zero thrust)."""
        problems = self.output_problems(measure=True)
        if problems:
            self.stop()
            raise EscError("ESC output changed while disarmed: " + "; ".join(problems))

    def measure(self, duration: float | None = None) -> dict[int, tuple[float, float, int]]:
        """Per pin: (frequency Hz, mean high time us, periods seen) from pigpio edge callbacks."""
        duration = self.measure_s if duration is None else duration
        edges: dict[int, list[tuple[int, int]]] = {p: [] for p in self.pins}

        def record(gpio: int, level: int, tick: int) -> None:
            edges[gpio].append((level, tick))

        callbacks = [self.pi.callback(p, pigpio.EITHER_EDGE, record) for p in self.pins]
        try:
            self._sleep(duration)
        finally:
            for cb in callbacks:
                cb.cancel()
        out = {}
        for p, seen in edges.items():
            rises = [t for level, t in seen if level == 1]
            n = len(rises) - 1
            freq = 1e6 * n / pigpio.tickDiff(rises[0], rises[-1]) if n > 0 else 0.0
            highs, rise = [], None
            for level, t in seen:
                if level == 1:
                    rise = t
                elif level == 0 and rise is not None:
                    highs.append(pigpio.tickDiff(rise, t))
                    rise = None
            out[p] = (freq, sum(highs) / len(highs) if highs else 0.0, max(n, 0))
        self.measured = out
        return out

    def check_frequency(self) -> float:
        """Raise `ArmingRefused` unless the outputs really run at the ESC frequency with the stop
        pulse on them; return the mean measured frequency in Hz. The stop wave must be on the pins."""
        want, tol = self.frequency_hz, self.tolerance_hz
        problems = []
        if self.built_period_us != self.period_us:
            problems.append(f"pigpio built a {self.built_period_us} us wave, not the {self.period_us} us "
                            f"period of {want:g} Hz")
        measured = self.measure()
        for motor, p in enumerate(self.pins, start=1):
            freq, high, n = measured[p]
            if n < MIN_PERIODS:
                problems.append(f"motor {motor} (GPIO {p}): {n} periods seen in {self.measure_s:g} s, the output "
                                "does not toggle")
            elif abs(freq - want) > tol:
                problems.append(f"motor {motor} (GPIO {p}) runs at {freq:.1f} Hz, the ESCs need {want:g} Hz "
                                f"(period {self.period_us} us)")
            elif abs(high - self.stop_us) > WIDTH_TOLERANCE_US:
                problems.append(f"motor {motor} (GPIO {p}): stop pulse {high:.0f} us, expected {self.stop_us} us")
        if problems:
            raise ArmingRefused("ESC output: " + "; ".join(problems))
        return sum(f for f, _, _ in measured.values()) / len(measured)

    def _start_deadman(self) -> None:
        if self.deadman_ms <= 0:
            return
        pi = self.pi
        sid = pi.store_script(deadman_script(self.pins, self._stop_wid).encode())
        status = self._wait_status(sid, (pigpio.PI_SCRIPT_INITING,))
        if status != pigpio.PI_SCRIPT_HALTED:
            pi.delete_script(sid)
            raise ArmingRefused(f"ESC dead-man: pigpiod did not accept the script (status {status})")
        pi.run_script(sid, [self._countdown])
        self._sid = sid
        self._last_refresh = self._clock()
        status = self._wait_status(sid, (pigpio.PI_SCRIPT_HALTED,))
        if status not in (pigpio.PI_SCRIPT_RUNNING, pigpio.PI_SCRIPT_WAITING):
            self._sid = None
            pi.delete_script(sid)
            raise ArmingRefused(f"ESC dead-man: the script does not run in pigpiod (status {status})")

    def _wait_status(self, sid: int, leave: tuple[int, ...], timeout: float = 1.0) -> int:
        end = self._clock() + timeout
        while True:
            status, _ = self.pi.script_status(sid)
            if status not in leave or self._clock() > end:
                return status
            self._sleep(0.005)


def stop_motors(pi, pins: Sequence[int], frequency_hz: float = FREQUENCY_HZ, stop_us: int = STOP_US) -> PigpioEsc:
    """The stop pulse on every ESC output, whatever state the last controller left pigpiod in (the
    systemd ExecStopPost, `flightctl run --stop-motors`)."""
    esc = PigpioEsc(pi, pins, frequency_hz, stop_us, deadman_ms=0)
    esc.start()
    return esc
