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


def imu_at_rest(config) -> None:
    """Two seconds of frames with the vehicle still: 1 g, and the gyro's offset and noise."""
    from flightctl.boards.boardfile import open_spi
    from flightctl.drivers.mpu9250 import Mpu9250
    from flightctl.hal import ImuSample

    spi = open_spi(config.imu)
    try:
        imu = Mpu9250(spi)
        imu.start()
        s, rows = ImuSample(), []
        for _ in range(450 * 2):
            if imu.read(s):
                rows.append((s.ax, s.ay, s.az, s.gx, s.gy, s.gz))
            time.sleep(1 / 450)
    finally:
        spi.close()
    from flightctl.params import load

    if not rows:
        step("IMU at rest", "no frame in 2 s", False, "check the SPI wiring (CE0, mode 3), dtparam=spi=on, "
             "and that the chip answers WHO_AM_I 0x71 (MPU-9250)")
    a = statistics.mean(math.sqrt(r[0] ** 2 + r[1] ** 2 + r[2] ** 2) for r in rows) / load(None).airframe.g
    rates = [math.degrees(statistics.mean(r[i] for r in rows)) for i in (3, 4, 5)]
    noise = [math.degrees(statistics.pstdev(r[i] for r in rows)) for i in (3, 4, 5)]
    step("IMU at rest", f"{len(rows)} frames in 2 s, |a| {a:.3f} g, gyro mean {rates[0]:+.2f} {rates[1]:+.2f} "
         f"{rates[2]:+.2f} deg/s, noise {noise[0]:.2f} {noise[1]:.2f} {noise[2]:.2f} deg/s",
         len(rows) > 800 and 0.95 < a < 1.05 and max(map(abs, rates)) < 5.0,
         "keep the vehicle still and level; a dead or wrong chip: check the SPI wiring (CE0, mode 3) and "
         "WHO_AM_I; a gyro offset above 5 deg/s: replace the IMU")


def battery(config) -> None:
    """The INA219: the battery's voltage and current, in range."""
    import smbus2

    from flightctl.drivers.ina219 import Ina219

    bus = smbus2.SMBus(config.power.i2c_bus)
    try:
        ina = Ina219(bus, config.power.address, config.power.shunt_ohm, config.power.max_current_a)
        ina.start()
        v, i = ina.read()
    finally:
        bus.close()
    step("battery", f"{v:.2f} V, {i:+.2f} A (board file: {config.checks.min_battery_v:.2f} V to arm)",
         5.0 < v < 26.0 and abs(i) < config.power.max_current_a and v >= config.checks.min_battery_v,
         "below the arming threshold: charge the battery; no reading: check the INA219's address "
         "(i2cdetect -y 1), its shunt in the battery lead and [power] in the board file")


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
