"""What the hardware tests of both Pi boards check the same way (tests/hardware/test_on_pi.py with pigpio,
test_on_pi5.py with the kernel's PWM and GPIO): a sonar that answers, and the loop's I/O at 450 Hz. The two
files are the first-flight checklist (docs/pi.md, "First flight checklist"): every step prints what it
measured and, when it fails, what to do (`step`)."""
from __future__ import annotations

import math
import os
import statistics
import time

LOOP_S = float(os.environ.get("FLIGHTCTL_LOOP_S", "60"))     # the loop's timing is judged over a minute


def step(name: str, measured: str, ok: bool, fix: str) -> None:
    """One checklist step: what was measured, and what to do if it is not right."""
    print(f"\n[{'ok' if ok else 'FAILED'}] {name}: {measured}" + ("" if ok else f"\n    what to do: {fix}"))
    assert ok, f"{name}: {measured}; what to do: {fix}"


def sonar_answers(sonar) -> None:
    """Ten measurements, 50 ms apart: at least one real range among them; prints the echo times."""
    results = []
    for _ in range(10):
        sonar.trigger()
        time.sleep(0.05)
        r = sonar.poll()
        if r is not None:
            results.append(r)
    good = [r for r in results if not math.isnan(r)]
    echoes = ", ".join(f"{r * 5831:.0f} us ({r:.3f} m)" for r in good) or "none"
    step("sonar", f"{len(good)} of 10 pings answered; echo times {echoes}", bool(good),
         "check the HC-SR04's 5 V and ground, the trigger and echo pins against the board file, and the "
         "echo's 5 V -> 3.3 V divider; point it at a surface 0.3-3 m away")


def loop_io(config, write, command, what: str, seconds: float = LOOP_S) -> None:
    """`seconds` (a minute) of the inner loop's I/O at 450 Hz: an IMU burst read and `write(command(k))`
    each tick; prints the loop's period, its worst lateness and the cost of the writes, and fails past
    1 % overruns."""
    from flightctl.boards.boardfile import open_spi
    from flightctl.clock import WallClock
    from flightctl.drivers.mpu9250 import Mpu9250
    from flightctl.hal import ImuSample

    spi = open_spi(config.imu)
    try:
        imu = Mpu9250(spi)
        imu.start()
        s = ImuSample()
        clock = WallClock(1 / 450)
        lates, costs, starts = [], [], []
        for k in range(int(450 * seconds)):
            t = clock.wait_next()
            starts.append(clock.now())
            lates.append(clock.now() - t)
            imu.read(s)
            t0 = time.perf_counter()
            write(command(k))
            costs.append(time.perf_counter() - t0)
        period = (starts[-1] - starts[0]) / (len(starts) - 1)
        lates.sort()
        step(f"loop at 450 Hz for {seconds:g} s",
             f"period {period * 1e3:.4f} ms (2.2222 wanted), {clock.overruns} overruns in {len(lates)} ticks, "
             f"lateness p99 {lates[int(0.99 * len(lates))] * 1e3:.3f} ms, worst {lates[-1] * 1e3:.3f} ms; "
             f"{what}: median {statistics.median(costs) * 1e6:.1f} us, worst {max(costs) * 1e6:.1f} us",
             clock.overruns < 0.01 * len(lates),
             "stop whatever else runs on the Pi (desktop, other services), check the CPU governor "
             "(performance) and the temperature (vcgencmd measure_temp: throttled above 80 C); the service "
             "runs under SCHED_FIFO, this test does not")
    finally:
        spi.close()
