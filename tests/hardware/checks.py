"""What the hardware tests of both Pi boards check the same way (tests/hardware/test_on_pi.py with pigpio,
test_on_pi5.py with the kernel's PWM and GPIO): a sonar that answers, and the loop's I/O at 450 Hz."""
from __future__ import annotations

import math
import statistics
import time


def sonar_answers(sonar) -> None:
    """Ten measurements, 50 ms apart: at least one real range among them."""
    results = []
    for _ in range(10):
        sonar.trigger()
        time.sleep(0.05)
        r = sonar.poll()
        if r is not None:
            results.append(r)
    assert results and any(not math.isnan(r) for r in results), results


def loop_io(config, write, command, what: str) -> None:
    """3 s of the inner loop's I/O at 450 Hz: an IMU burst read and `write(command(k))` each tick; prints
    the lateness and the cost of the writes, and fails past 1 % overruns."""
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
        lates, costs = [], []
        for k in range(450 * 3):
            t = clock.wait_next()
            lates.append(clock.now() - t)
            imu.read(s)
            t0 = time.perf_counter()
            write(command(k))
            costs.append(time.perf_counter() - t0)
        lates.sort()
        print(f"\nloop: {clock.overruns} overruns in {len(lates)} ticks, p99 lateness "
              f"{lates[int(0.99 * len(lates))] * 1e3:.3f} ms, median {statistics.median(lates) * 1e3:.3f} ms; "
              f"{what}: median {statistics.median(costs) * 1e6:.1f} us, max {max(costs) * 1e6:.1f} us")
        assert clock.overruns < 0.01 * len(lates)
    finally:
        spi.close()
