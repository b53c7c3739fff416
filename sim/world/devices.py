"""The simulated world and its devices, each at the lowest boundary it can emulate:

- `World`: the plant, the battery, the true values, and the random numbers every device draws from;
- `SimMpu9250` (in `flightctl.sim.world.imu`): answers SPI transfers like the chip, with the noise
  `SensorNoise` sizes here;
- `SimGpio`: the pigpio calls the HC-SR04 driver makes, producing echo edges with 32-bit microsecond
  ticks (which wrap) and watchdog timeouts;
- `SimMotors`: takes PWM counts on the 0..40000 range;
- `SimBattery`, `SimIna219` on a `SimSMBus` (in `flightctl.sim.world.power`): a discharging 4S LiPo and the
  power monitor's registers behind the smbus2 calls of the INA219 driver;
- `SimClock`: lock-step: waiting for the next tick advances the world by one loop period.

Noise and bias can be switched off (`SensorNoise.off()`); true values stay on `World`.
"""
from __future__ import annotations

import heapq
import math
import random
from dataclasses import dataclass, fields, replace

import numpy as np

from flightctl.drivers.hcsr04 import US_PER_M
from flightctl.hal import LEVEL_TIMEOUT, PWM_RANGE
from flightctl.params import Airframe
from flightctl.physics import G
from flightctl.sim.world.model import Effect, Model, euler_rates, rotation
from flightctl.sim.world.plant import SUBSTEPS, Plant
from flightctl.sim.world.power import SimBattery

EARTH_FIELD_T = (20e-6, 0.0, -40e-6)  # North, West, Up: a mid-latitude field, dipping down


@dataclass(frozen=True)
class SensorNoise:
    """What the simulated sensors add to the truth. MPU-9250 values from its Product Specification
    (PS-MPU-9250A-01 rev 1.1, section 3.1 gyroscope, 3.2 accelerometer) and Register Map (RM-MPU-9250A-00
    rev 1.6, registers 26 and 29: the DLPF bandwidths); where the datasheet is silent, a plausible value
    with its reason. `off()` gives the truth; `steady()` keeps white noise and a fixed offset only."""
    # MPU-9250 gyroscope
    gyro_density: float = math.radians(0.01)     # rad/s/rtHz: rate noise spectral density (PS 3.1)
    gyro_bias: float = 0.05            # rad/s, spread of the zero-rate offset per axis: initial ZRO tolerance
    #                                    +-5 deg/s (PS 3.1) taken as about 1.7 sigma
    gyro_bias_walk: float = 1.6e-5     # rad/s/rts, the bias random walk K. The datasheet is silent; MEMS gyros
    #   of this class show an in-run bias instability B (the Allan-deviation minimum) of a few to tens of
    #   deg/h (AirSim's MPU-6000 model, after Greenheck 2009: 4.6 deg/h). We take B = 10 deg/h and size K so
    #   that the Allan deviation of the white noise, N = density / sqrt 2 for a one-sided density, plus this
    #   walk, sqrt(N^2/tau + K^2 tau/3), has its minimum sqrt(2 N K / sqrt 3) at B: K = sqrt(3) B^2 / (2 N)
    #   = 1.6e-5 rad/s/rts, the minimum at tau = 13 s; the offset then wanders 0.016 deg/s in 5 minutes.
    gyro_temp_coeff: float = math.radians(0.02)  # rad/s/degC, spread per axis of the ZRO temperature slope.
    #   The datasheet bounds the ZRO variation by +-30 deg/s over -40..85 degC (PS 3.1), a worst case of
    #   0.24 deg/s/degC, and gives no typical slope: 0.02 deg/s/degC is a plausible typical value, an order
    #   of magnitude under that bound (the 5 degC warm-up below then moves each axis by ~0.1 deg/s).
    # MPU-9250 accelerometer
    accel_density: float = 300e-6 * G  # m/s^2/rtHz: noise power spectral density 300 ug/rtHz (PS 3.2)
    accel_bias: float = 0.05           # m/s^2 per axis (zero-g offset +-60 mg x, y and +-80 mg z, PS 3.2, are
    #                                    bounds; the paper's calibration removes the offset on the floor)
    accel_temp_coeff: float = 1.5e-3 * G   # m/s^2/degC per axis: zero-g change +-1.5 mg/degC (PS 3.2)
    # The die temperature after power-on: T = T_ambient + rise (1 - exp(-t / tau)). The datasheet gives no
    # figure. Plausible: the chip itself dissipates ~10 mW (a few mA at 3.3 V), a breakout board's regulator
    # and the Raspberry Pi beside it add more, and a board's thermal time constant is minutes: a rise of
    # 5 degC with a 2 min time constant.
    warmup_rise: float = 5.0           # degC
    warmup_tau: float = 120.0          # s
    # Vibration (the vehicle's, `Sensors` of its parameter file, flightctl/params.py: `vehicle_noise` puts them
    # here). Each rotor's residual imbalance U (kg m) is a force U w^2 rotating at its speed w (1/rev):
    # proportional to its thrust, since f = c1 w^2 (eq. 27). `vibration` is the specific force per rotor and
    # axis at hover thrust, before the DLPF. A balanced 12-inch propeller with its motor bell keeps U near 3 g mm;
    # at hover (w = 524 rad/s) that is U w^2 / M = 0.5 m/s^2 on the 1.645 kg frame, about 0.7 m/s^2 rms per
    # axis from four rotors of random phase. The arms bend under the rotating load and couple it into z;
    # multirotor logs show z vibration of the same order as x and y, so z gets the same amplitude.
    vibration: float = 0.5             # m/s^2, the accelerometer's 1/rev per rotor at hover thrust
    gyro_vibration: float = 0.0        # rad/s, the roll and pitch rates' 1/rev per rotor at hover thrust
    harmonic2: float = 0.0             # the 2/rev and 3/rev lines over the 1/rev, both sensors
    harmonic3: float = 0.0
    gyro_broadband: float = 0.0        # rad/s rms per read at hover thrust, roll and pitch (frame and airflow)
    yaw_share: float = 0.6             # the yaw rate's broadband noise over roll's and pitch's
    yaw_lines: float = 2.94            # the yaw rate's rotor lines over roll's and pitch's (a rigid frame)
    from_vehicle: bool = True          # `vehicle_noise` replaces the vibration terms by the vehicle file's
    mag_sigma: float = 0.3e-6          # T
    sonar_sigma_us: float = 15.0       # echo width jitter
    sonar_dropout: float = 0.0         # probability that an echo does not come back
    battery_sigma: float = 0.01        # V

    @staticmethod
    def off() -> "SensorNoise":
        return SensorNoise(**{f.name: 0.0 for f in fields(SensorNoise)})

    def steady(self) -> "SensorNoise":
        """Without what wanders: no bias random walk, no warm-up drift, no vibration."""
        return replace(self, gyro_bias_walk=0.0, warmup_rise=0.0, vibration=0.0, gyro_vibration=0.0,
                       gyro_broadband=0.0, from_vehicle=False)


def vehicle_noise(noise: SensorNoise, sensors) -> SensorNoise:
    """The chip's noise with the vehicle's vibration (`flightctl.params.Sensors`: a parameter file's
    [sensors]), unless the noise was set term by term (`off`, `steady`, or `from_vehicle=False`)."""
    if not noise.from_vehicle:
        return noise
    return replace(noise, vibration=sensors.accel_vibration, gyro_vibration=sensors.gyro_vibration,
                   harmonic2=sensors.harmonic2, harmonic3=sensors.harmonic3,
                   gyro_broadband=sensors.gyro_broadband, yaw_share=sensors.yaw_share,
                   yaw_lines=sensors.yaw_lines)


class NoisePool:
    """Standard normal numbers drawn in blocks by numpy: the per-sample cost of `next()` is an index."""
    BLOCK = 1 << 16

    def __init__(self, seed: int, block: int = BLOCK):
        self._gen = np.random.default_rng(seed)
        self._block = block
        self._refill()

    def _refill(self) -> None:
        self.array = self._gen.standard_normal(self._block)
        self.values = self.array.tolist()
        self._i = 0

    def take(self, n: int) -> list[float]:
        i = self.index(n)
        return self.values[i:i + n]

    def index(self, n: int) -> int:
        """Where the next n numbers start in the block (`array`, the list `values`), taken."""
        if self._i + n > self._block:
            self._refill()
        i = self._i
        self._i = i + n
        return i


class World:
    """The plant, its environment and the true sensor values."""

    def __init__(self, airframe: Airframe, effects: tuple[Effect, ...] = (), noise: SensorNoise = SensorNoise(),
                 seed: int = 0, substeps: int | None = None, battery_soc: float = 0.9):
        self.a = airframe
        self.dt = airframe.dt
        self.seed = seed
        self.rng = random.Random(seed)
        self.normal = NoisePool(seed)
        self.noise = noise
        self.battery = SimBattery(self, battery_soc)
        self.plant = Plant(Model(airframe, effects), self.dt, substeps or SUBSTEPS, self.battery.voltage)
        self.gpio = SimGpio(self)

    @property
    def t(self) -> float:
        return self.plant.t

    def advance(self, dt: float) -> None:
        """To the end of this loop period (of `dt`; the rest of it after `advance_part`)."""
        rest = 1.0 - self.plant.into
        self.plant.advance(dt)
        self.battery.advance(dt if rest == 1.0 else rest * dt)
        self.gpio.advance_to(self.plant.t)

    def advance_part(self, frac: float) -> None:
        """To `frac` of this loop period: where a late loop tick reads its sensors (sim/world/lateness.py)."""
        before = self.plant.into
        self.plant.advance_part(frac)
        self.battery.advance((frac - before) * self.dt)
        self.gpio.advance_to(self.plant.t)

    def range_along_body_z(self) -> float:
        """Distance from the sonar along -z_b to the floor plane (infinite if tilted past 60 deg)."""
        x = self.plant.x
        c = math.cos(x[6]) * math.cos(x[7])
        return x[2] / c if c > 0.5 else math.inf

    def magnetic_field_body(self) -> tuple[float, float, float]:
        Rm = rotation(*self.plant.attitude)
        bn, bw, bu = EARTH_FIELD_T
        return (Rm[0] * bn + Rm[3] * bw + Rm[6] * bu, Rm[1] * bn + Rm[4] * bw + Rm[7] * bu,
                Rm[2] * bn + Rm[5] * bw + Rm[8] * bu)


class _Callback:
    def __init__(self, gpio: "SimGpio", pin: int, func):
        self._gpio, self.pin, self.func = gpio, pin, func

    def cancel(self) -> None:
        self._gpio.callbacks.get(self.pin, []).remove(self)


class SimGpio:
    """The pigpio calls of the HC-SR04 driver. A trigger schedules the echo edges the module would
    produce for the true distance: the echo rises about 450 us after the trigger and stays high for
    distance * 5831 us; with no echo (out of range, dropout) a module holds it high for 38 ms."""
    ECHO_DELAY_S = 450e-6
    NO_ECHO_S = 0.038

    def __init__(self, world: World, tick0: int | None = None):
        self.world = world
        # start the 32-bit microsecond counter at a random place, so the wrap is met in long runs
        self.tick0 = world.rng.randrange(1 << 32) if tick0 is None else tick0
        self.callbacks: dict[int, list[_Callback]] = {}
        self.watchdogs: dict[int, float] = {}
        self.last_edge: dict[int, float] = {}
        self.stuck_high = False
        self._events: list[tuple[float, int, int]] = []
        self._echo_pin = None
        self._quiet_until = -math.inf   # before this time no edge is due and no watchdog can time out

    def tick(self, t: float) -> int:
        return (self.tick0 + int(round(t * 1e6))) & 0xFFFFFFFF

    def get_current_tick(self) -> int:
        return self.tick(self.world.t)

    def set_mode(self, gpio: int, mode: int) -> int:
        return 0

    def callback(self, user_gpio: int, edge: int, func) -> _Callback:
        cb = _Callback(self, user_gpio, func)
        self.callbacks.setdefault(user_gpio, []).append(cb)
        self._echo_pin = user_gpio
        return cb

    def set_watchdog(self, user_gpio: int, wdog_timeout: int) -> int:
        if wdog_timeout:
            self.watchdogs[user_gpio] = wdog_timeout / 1000.0
            self.last_edge[user_gpio] = self.world.t
        else:
            self.watchdogs.pop(user_gpio, None)
        self._quiet_until = -math.inf
        return 0

    def gpio_trigger(self, user_gpio: int, pulse_len: int = 10, level: int = 1) -> int:
        w, pin = self.world, self._echo_pin
        if pin is None or self.stuck_high:
            return 0
        t = w.t + pulse_len * 1e-6 + self.ECHO_DELAY_S
        d = w.range_along_body_z()
        n = w.noise
        if d > 4.5 or (n.sonar_dropout and w.rng.random() < n.sonar_dropout):
            width = self.NO_ECHO_S
        else:
            width = max(d * US_PER_M + w.rng.gauss(0.0, n.sonar_sigma_us), 0.0) * 1e-6
        heapq.heappush(self._events, (t, pin, 1))
        heapq.heappush(self._events, (t + width, pin, 0))
        self._quiet_until = -math.inf
        return 0

    def stick_echo_high(self) -> None:
        """A fault seen in clones: the echo line goes high and stays there."""
        self._events.clear()
        self._fire(self._echo_pin, 1, self.world.t)
        self.stuck_high = True
        self._quiet_until = -math.inf

    def advance_to(self, t: float) -> None:
        if t < self._quiet_until:       # (most loop periods)
            return
        events = self._events
        while events and events[0][0] <= t:
            te, pin, level = heapq.heappop(events)
            self._fire(pin, level, te)
        quiet = events[0][0] if events else math.inf
        for pin, timeout in self.watchdogs.items():
            last = self.last_edge.get(pin, 0.0)
            while t - last >= timeout:   # pigpio repeats the timeout report while no edge comes
                last += timeout
                self._fire(pin, LEVEL_TIMEOUT, last)
            quiet = min(quiet, self.last_edge.get(pin, 0.0) + timeout - 1e-9)   # (short of the rounding)
        self._quiet_until = quiet

    def _fire(self, pin: int, level: int, t: float) -> None:
        self.last_edge[pin] = t
        tick = self.tick(t)
        for cb in list(self.callbacks.get(pin, ())):
            cb.func(pin, level, tick)


class SimMotors:
    """Four ESC outputs taking PWM counts; the command value P = counts / 40000 * 255 drives eq. 26."""

    def __init__(self, world: World):
        self.world = world
        self.armed = False
        self.counts = [0, 0, 0, 0]

    def arm(self) -> None:
        self.armed = True   # the simulated output runs at exactly the configured ESC frequency

    def write(self, counts: list[int]) -> None:
        c = self.counts
        c[0], c[1], c[2], c[3] = counts
        k = 255.0 / PWM_RANGE
        self.world.plant.command(c[0] * k, c[1] * k, c[2] * k, c[3] * k, self.world.battery.voltage)

    def stop(self) -> None:
        self.write([0, 0, 0, 0])
        self.armed = False


class SimClock:
    """Lock-step with the plant: no sleeping. Its time is the plant's whole loop periods times the
    period (`Plant.periods`, an integer), never a sum: the same at any substep count."""

    def __init__(self, world: World):
        self.world = world
        self.period = world.dt

    def now(self) -> float:
        return self.world.t

    def wait_next(self) -> float:
        self.world.advance(self.period)
        return self.world.t


class TruthEstimator:
    """Perfect state feedback: the controller sees the true attitude (for the paper's comparison)."""
    __slots__ = ("plant", "roll", "pitch", "yaw", "droll", "dpitch", "dyaw", "in_flight")

    def __init__(self, world: World):
        self.plant = world.plant
        self.roll = self.pitch = self.yaw = self.droll = self.dpitch = self.dyaw = 0.0
        self.in_flight = False

    def set_reference(self, tilt_bias, yaw_bias, use_mag) -> None:
        pass

    def update(self, s, dt: float) -> None:
        x = self.plant.x
        self.roll, self.pitch = phi, theta = x[6], x[7]
        self.yaw = (x[8] + math.pi) % (2 * math.pi) - math.pi
        self.droll, self.dpitch, self.dyaw = euler_rates(math.sin(phi), math.cos(phi), math.sin(theta), math.cos(theta),
                                                         x[9], x[10], x[11])


class TruthRangefinder:
    """Perfect altitude at every loop iteration (the altitude task then runs at the loop rate)."""

    def __init__(self, world: World):
        self.world = world

    def trigger(self) -> None:
        pass

    def poll(self) -> float:
        return self.world.range_along_body_z()
