"""The simulated board: the simulated world behind the real MPU-9250, HC-SR04 and INA219 drivers (SPI
register reads, GPIO edges with microsecond ticks, I2C register reads), the simulated motors (PWM counts).
Registered as "sim" in `flightctl.boards`.

`flightctl sim` and `flightctl bench --board sim` fly it lock-step (as fast as it computes);
`flightctl run --board sim` paces it by the wall clock (`BoardOptions.realtime`): the same service
path as on the quadcopter, in real time. The log gets the true state in `true_*` columns, which
diagnose never reads.
"""
from __future__ import annotations

import math

from flightctl.boards import MIN_BATTERY_V, Board, BoardOptions
from flightctl.clock import PacedClock
from flightctl.drivers.hcsr04 import HcSr04
from flightctl.drivers.ina219 import Ina219
from flightctl.drivers.mpu9250 import FROZEN_FRAMES, Mpu9250
from flightctl.hal import Hal
from flightctl.params import Params
from flightctl.sim import causes
from flightctl.sim.world.devices import SensorNoise, SimClock, SimMotors, World, vehicle_noise
from flightctl.sim.world.imu import SimMpu9250
from flightctl.sim.world.power import SimIna219, SimSMBus

TRUTH_COLUMNS = ("true_x", "true_y", "true_z", "true_roll", "true_pitch", "true_yaw")
SIM_CALIBRATE_S = 2.0   # s; the paper sat still for 60 s. 900 reads of the simulated gyro's white noise
#                         (sigma 0.17 deg/s, docs/estimator.md) average to a bias error near 0.006 deg/s;
#                         the die's warming and the bias walk go on after it, as on the vehicle
SONAR_TRIGGER_PIN, SONAR_ECHO_PIN = 23, 24   # pins of the simulated GPIO


def sim_board(params: Params, effects=(), noise=None, seed: int = 0, substeps: int | None = None,
              airframe=None) -> tuple[Hal, World]:
    """The Hal of the simulated quadcopter, and the simulated world (for its true values). The plant
    carries the parameter file's effects (docs/measured-data.md), then `effects` (`causes.combined`: an
    effect of a cause the file carries replaces it)."""
    noise = vehicle_noise(noise if noise is not None else SensorNoise(), params.sensors)   # the file's [sensors]
    world = World(airframe or params.airframe, causes.combined(params, effects), noise, seed, substeps)
    n = world.noise   # an ideal chip (no white noise) repeats its frames: no frozen-frame check
    imu = Mpu9250(SimMpu9250(world), sleep=lambda s: None,
                  frozen_frames=0 if n.gyro_density == 0.0 and n.accel_density == 0.0 else FROZEN_FRAMES)
    sonar = HcSr04(world.gpio, SONAR_TRIGGER_PIN, SONAR_ECHO_PIN)
    power = Ina219(SimSMBus(SimIna219(world)), bus_name="the simulated I2C bus")
    hal = Hal(imu=imu, motors=SimMotors(world), rangefinder=sonar, power=power, clock=SimClock(world))
    imu.start()
    sonar.start()
    power.start()
    return hal, world


def truth_row(world: World):
    """The values of TRUTH_COLUMNS now: position (m, NWU) and roll, pitch, yaw (rad, yaw wrapped)."""
    x = world.plant

    def row() -> tuple:
        s = x.x
        return s[0], s[1], s[2], s[6], s[7], (s[8] + math.pi) % (2 * math.pi) - math.pi
    return row


def open_board(params: Params, options: BoardOptions) -> Board:
    hal, world = sim_board(params, options.effects, options.noise, options.seed, options.substeps, options.airframe)
    meta = {"seed": str(options.seed), **hal.imu.filters()}
    if options.realtime:
        hal.clock = PacedClock(hal.clock)
        meta["clock"] = "simulator paced by the wall clock (real time)"
    return Board(hal, "sim", MIN_BATTERY_V, SIM_CALIBRATE_S, extra_columns=TRUTH_COLUMNS,
                 extra_row=truth_row(world), meta=meta, world=world)
