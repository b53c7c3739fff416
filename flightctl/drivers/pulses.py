"""The ESC signal, whichever driver makes it (pigpio waves on a Pi 3/4, drivers/esc.py; the RP1's PWM
through the kernel on a Pi 5, drivers/pwm_sysfs.py): its frequency, its pulse limits and the one
conversion from the paper's PWM count to an on-time. No Pi library is imported here.

Counts: the paper's duty on 0..PWM_RANGE (40000) of the ESC period (conventions.md: count = P / 255 *
40000), so the on-time is `counts / 40000 * period`. On-times are clamped to [stop_us, max_us]: below the
ESC's stop pulse every command is zero thrust anyway (eq. 26's dead zone h2 = 120 is 1048 us), and a
signal that never goes high would look like a lost signal to the ESC. Both drivers round the on-time
to 1 us (pigpio times waves to 1 us), so both boards put the same pulse on the ESCs for a command.
"""
from __future__ import annotations

from flightctl.params import Airframe

FREQUENCY_HZ = Airframe.esc_pwm_hz  # the parameter's default: paper, section 4.4.1 (E600 ESCs: 30..450 Hz)
STOP_US = 1000              # the ESC stop / arming pulse (zero thrust)
MAX_US = 2100               # no ESC reads more; well inside the 2227 us period
DEADMAN_MS = 100            # motors stop this long after the last write (0: no dead-man)
REFRESH_S = 0.02            # how often write() re-arms the dead-man's countdown
OUTPUT_CHECK_S = 0.1        # in flight, write() reads the output back this often


class EscError(Exception):
    """The ESC output was refused, lost, or changed by another process."""


def on_time_us(count: float, us_per_count: float, stop_us: int, max_us: int) -> int:
    """The on-time in whole us of a PWM count, clamped to [stop_us, max_us]."""
    return min(max(int(count * us_per_count + 0.5), stop_us), max_us)
