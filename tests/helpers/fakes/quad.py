"""The simulated quadcopter behind a Pi board's fakes, so that `flightctl run --board pi` and `--board pi5`
fly the simulator through their real drivers and client libraries:

- the MPU-9250 (SPI register reads) and the INA219 (I2C registers) are the simulator's chips, as on
  the `sim` board;
- the ESC outputs are read where the ESCs would read them: the on-time of the wave pigpiod transmits
  on each ESC pin (fake pigpiod, the real pigpio client), or of each RP1 PWM channel (the fake sysfs
  tree); the command value the plant gets is P = on-time / period * 255 (conventions.md), 0 without
  pulses;
- the HC-SR04 of the fake (fake pigpiod's, or the fake GPIO chip's) is told the simulated distance
  along -z_b each period, and answers the trigger pulses the driver sends with edges in real time;
- the loop's clock advances the world by one period at each deadline, paced by the wall clock (the
  `run --board sim` clock): the world reads the outputs as they are at that deadline.

    with FakeQuad(params, "pi5", tmp_path) as quad:
        main([... "--board", "pi5" ...], devices=quad.devices)
"""
from __future__ import annotations

import math
from pathlib import Path

from flightctl.clock import PacedClock
from flightctl.params import Params
from flightctl.sim.world.devices import SensorNoise, World
from flightctl.sim.world.imu import SimMpu9250
from flightctl.sim.world.power import SimIna219, SimSMBus

PI_PINS = (17, 27, 22, 25)          # flightctl/boards/pi.toml
PI5_CHANNELS = (0, 1, 2, 3)         # flightctl/boards/pi5.toml
TRIGGER, ECHO = 23, 24
SONAR_LIMIT_M = 4.5                 # beyond it the module gets no echo


class _ESCs:
    """The lock-step clock of the world, reading the ESC outputs each period."""

    def __init__(self, quad: "FakeQuad"):
        self.quad = quad
        self.world = quad.world
        self.period = self.world.dt
        self.steps = 0

    def now(self) -> float:
        return self.world.t

    def wait_next(self) -> float:
        q, w = self.quad, self.world
        P = [0.0 if on is None else 255.0 * on / period for on, period in q.outputs()]
        w.plant.command(P[0], P[1], P[2], P[3], w.battery.voltage)
        w.advance(self.period)
        d = w.range_along_body_z()
        q.sonar.distance_m = d if d < SONAR_LIMIT_M else 1.0
        q.sonar.mode = "echo" if d < SONAR_LIMIT_M else "none"
        self.steps += 1
        return w.t


class FakeQuad:
    def __init__(self, params: Params, board: str, base: Path, seed: int = 0, noise: SensorNoise | None = None):
        self.params, self.board = params, board
        self.world = World(params.airframe, noise=noise if noise is not None else SensorNoise(), seed=seed)
        self.spi, self.smbus = SimMpu9250(self.world), SimSMBus(SimIna219(self.world))
        self.base = Path(base)
        self.clock = PacedClock(_ESCs(self))
        self._ctx = None

    def __enter__(self) -> "FakeQuad":
        if self.board == "pi":
            from helpers.fakes.pigpiod import running

            self._ctx = running()
            self.fake, pi = self._ctx.__enter__()
            self.sonar = self.fake.attach_sonar(TRIGGER, ECHO, 1.0)
            self.devices = dict(pi=pi, spi=self.spi, smbus=self.smbus, clock=self.clock)
        else:
            from helpers.fakes.gpiochip import FakeGpioDevice
            from helpers.fakes.sysfs_pwm import FakePwmSysfs

            self.fake = FakePwmSysfs(self.base / "sysfs")
            self.gpio = FakeGpioDevice()
            self.sonar = self.gpio.attach_sonar(TRIGGER, ECHO, 1.0)
            self.devices = dict(pwm_root=str(self.fake.root), pwm_fs=self.fake, gpio_chip=self.gpio.chip(),
                                spi=self.spi, smbus=self.smbus, clock=self.clock)
        return self

    def __exit__(self, *exc) -> None:
        if self._ctx is not None:
            self._ctx.__exit__(*exc)
        else:
            self.gpio.close()

    def outputs(self) -> list[tuple[float | None, float]]:
        """Per motor: (on-time, period) in us of what the ESC pin carries; on-time None without pulses."""
        if self.board == "pi":
            wave = self.fake.live_wave()
            on = wave.on_times() if wave is not None else {}
            period = wave.length * self.fake.wave_clock_scale if wave is not None else math.nan
            return [(on.get(p), period) for p in PI_PINS]
        out = []
        for c in PI5_CHANNELS:
            o = self.fake.output("1f00098000.pwm", c)
            out.append((None, math.nan) if o is None else (o[1] * 1e6, o[0] * 1e6))
        return out
