"""The one place where a board is wired into a `Hal`: "sim" (the simulated quadcopter) or "pi"
(the quadcopter's drivers). No other module asks which board it runs on."""
from __future__ import annotations

from flightctl.drivers.hcsr04 import HcSr04
from flightctl.drivers.mpu9250 import Mpu9250
from flightctl.hal import Hal
from flightctl.params import Params

SONAR_TRIGGER_PIN, SONAR_ECHO_PIN = 23, 24


def sim_board(params: Params, effects=(), noise=None, seed: int = 0, substeps: int = 2):
    """The simulated quadcopter: the real MPU-9250 and HC-SR04 drivers on simulated chips and pins.
    Returns the Hal and the simulated world (for its true values)."""
    from flightctl.sim.devices import SensorNoise, SimClock, SimMotors, SimMpu9250, World

    world = World(params.airframe, tuple(effects), noise if noise is not None else SensorNoise(), seed, substeps)
    imu = Mpu9250(SimMpu9250(world), sleep=lambda s: None)
    sonar = HcSr04(world.gpio, SONAR_TRIGGER_PIN, SONAR_ECHO_PIN)
    hal = Hal(imu=imu, motors=SimMotors(world), rangefinder=sonar, power=world.battery, clock=SimClock(world))
    imu.start()
    sonar.start()
    return hal, world


def make_hal(board: str, params: Params, **options) -> Hal:
    if board == "sim":
        return sim_board(params, **options)[0]
    if board == "pi":
        from flightctl.pi import pi_board
        return pi_board(params, **options)
    raise ValueError(f"unknown board {board!r} (known: sim, pi)")
