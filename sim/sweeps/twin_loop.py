"""One vehicle's whole flight, as `flightctl sim` flies it, in one compiled loop: the batched simulator's
inner loop (sim/sweeps/batch.py sets it up and calls it over every vehicle).

Each loop period, in the order of `flightctl.loop.FlightLoop` against the simulated board
(sim/world/board.py, sim/flights/run.py):

- the world advances one period: the plant (sim/world/plant.py `Plant.advance`: the actuation delay's
  ring of commands, the floor until the thrust lifts the vehicle, a touchdown stopping it and its
  speed recorded; one RK4 step of sim/world/compiled.py's `rk4`), then the sonar's echo edges
  (sim/world/devices.py `SimGpio`: the echo's rise 10 us + ECHO_DELAY_S after the trigger, its width
  the distance's, jittered, or the module's no-echo; the driver's watchdog);
- the chip's burst (`imu.chip_frame`, compiled; the magnetometer every MAG_EVERY reads) decoded and
  checked as `Mpu9250.read` does it (a refused frame holds the last sample; more than
  MAX_BAD_IMU_FRAMES stop the motors), the calibration's gyro bias subtracted;
- the power monitor every tenth of a second (its random numbers only: the battery of a flight of
  minutes stays far above the low-battery landing), the sonar's trigger every tenth period
  (`HcSr04.trigger`: not while an echo is under way) and its result (`HcSr04`: 2 cm to 4 m, else NaN);
- then the loop's phase (w[W_PHASE], flightctl/loop.py's PHASES), each a function named as the loop's
  method: on the floor before arming, the calibration (section 4.4.4: `Calibration.add`), then `apply` and
  `arm`; after it the plan's setpoints, the echo to the altitude task, the controller
  (sim/sweeps/twin_controller.py, the onboard one's compiled copy), the crash check on the estimate
  (flightctl/safety.py CRASH_TILT), the altitude lost (descend on the accelerometer), the plan's own
  landing (touchdown on the sonar) or the loop's (`FlightLoop._land`: level, descend at LAND_SPEED,
  the accelerometer confirms the floor), the plan's end; the motors take the counts while flying.

Random numbers: each vehicle's chip draws its normals from the same generator, in the same order, as
the single simulator's `NoisePool` of the same seed (`normals`, in the loop), and its sonar and power monitor from
the same Mersenne Twister as its `World.rng` (`uniforms`, Python's `random.gauss` on them): a vehicle
flown here with seed s is the vehicle `flightctl sim` flies with seed s (tests/sim/sweeps/test_batch.py).
Left out: the motor-loss detector (a healthy vehicle), a low battery or a reading no pack gives
(flightctl/battery.py), the stalls and the log's and
ground station's events.

The world's side of each period (the state arrays' layout, the plant's period, the sonar's edges, the chip's
burst and normals, the uniforms and gauss) is sim/sweeps/twin_world.py; the loop's phases are here.
Plain Python on arrays: sim/world/compiled.py compiles it (`compiled_fly`), or it runs as it is.
"""
from __future__ import annotations

import functools
from math import atan2, cos, exp, inf, nan, pi, sin

import numpy as np

from flightctl.control.estimator import tilt_from_accel
from flightctl.loop import LAND_LEVEL_S, LAND_SLACK_S, LAND_SPEED, LOST_ALT_S, MAX_BAD_IMU_FRAMES, TOUCHDOWN_ALT, TOUCHDOWN_S
from flightctl.safety import CRASH_TILT, LEFT_GROUND_ALT
from flightctl.sim.sweeps import twin_controller as ob
from flightctl.sim.world.imu import _C_PERIOD, AMBIENT_C, normals_per_read, read_gains
from flightctl.sim.world.compiled import work
from flightctl.sim.world.model import PHI, PSI, THETA, Z
from flightctl.sim.world.plant import floor_brake, floor_spin, time_weighted
from flightctl.sim.sweeps.twin_world import (CRASH, DIVERGED, DONE, DT, DURATION, ENDED, FLYING, GROUND, IMU_BAD,
                                          INA_DRAWS, LANDING, LANDS, MAG_EVERY, NEVER_LEFT, NO_TOUCHDOWN, N_REC,
                                          N_WIDE, POWER_EVERY, RUNNING, SONAR_EVERY, TWOPI, T_ARM, WARM_RISE,
                                          WARM_TAU, W_BAD, W_BLIND, W_CAL, W_CAL_MAG, W_CAL_N, W_DONE, W_DURATION,
                                          W_GROUND, W_GYRO_BIAS, W_HAS_RESULT, W_LAND_RAMP, W_LAND_SP, W_LAND_T,
                                          W_LAST_ECHO, W_MAX_ALT, W_NEXT, W_PHASE, W_REASON, W_RESULT, W_ROWS, W_S,
                                          W_TILT, W_T_TOUCH, W_Z_END, W_Z_MAX, chip_read, gauss, held_command, i16,
                                          normals, plant_period, put_word, sonar_edges, sonar_trigger, uniform)


def chip_generators(seeds) -> list | np.ndarray:
    """The vehicles' chips' generators, each `NoisePool`'s `np.random.default_rng(seed)`: compiled, as
    the four uint64 words of its PCG64 (sim/sweeps/pcg64.py, whose normals are NumPy's), else the
    generators themselves."""
    if compiled_fly() is None:
        return [np.random.default_rng(s) for s in seeds]
    from flightctl.sim.sweeps import pcg64
    return pcg64.seeded(seeds)


def land(w, e, sp, t_plan: float, alt: float) -> None:
    """`FlightLoop._land` at plan time t_plan: the landing's thrust from now on; roll and pitch back to
    level over LAND_LEVEL_S, the altitude's ramp to 0 at LAND_SPEED (the log's setpoint), a new end."""
    ob_landing_start(e, LAND_SPEED)
    w[W_PHASE] = LANDING
    w[W_LAND_T] = t_plan
    for j in range(4):
        w[W_LAND_SP + j] = sp[j]
    ramp = (alt if alt > 0.0 else 0.0) / LAND_SPEED
    w[W_LAND_RAMP] = ramp
    w[W_DURATION] = t_plan + ramp + LAND_SLACK_S


def landing_setpoint(w, t_plan: float, j: int) -> float:
    """`Plan._value` of the loop's landing plan: channel j's raised-cosine ramp to 0 from its value at
    the landing's start (yaw held there)."""
    start, t0 = w[W_LAND_SP + j], w[W_LAND_T]
    if j == 2:
        return start
    ramp = LAND_LEVEL_S if j < 2 else w[W_LAND_RAMP]
    if ramp <= 0.0 or t_plan >= t0 + ramp:
        return 0.0
    s = (t_plan - t0) / ramp
    return start + (0.0 - start) * 0.5 * (1.0 - cos(pi * s))


def fly(X, W, E, KC, Q, codes, RING, NRING, FRAC, WORDS, CS, CC, GEN, UNI, SP, REC, k, jump, i0: int, n: int,
        i_arm: int, rec0: int) -> None:
    """Loop periods i0 + 1 .. i0 + n of every vehicle (rows of the arrays): X the plants' states, W the
    world's and loop's (`w`), E and KC the controllers' (sim/sweeps/twin_controller.py), Q the plants' constants
    (sim/world/compiled.py `layout_rows`), RING and NRING, FRAC the delayed commands, WORDS, CS, CC the
    chips' burst words (`put_word`), state and constants, GEN their generators (`chip_generators`), UNI the Mersenne
    Twisters' uniforms, SP the plan's setpoints per period from i0 + 1, REC the judged record (rows
    from period rec0 on: true and estimated roll, pitch, yaw), k the shared constants (`N_WORLD`), jump the
    driver's limits per word. The loop arms at period i_arm."""
    dt, t_arm = k[DT], k[T_ARM]
    cnt = np.zeros(4, dtype=np.int64)
    wk = work(X.shape[1])
    e9 = np.empty(15)                        # a read's normals: the chip's nine or twelve, the magnetometer's three
    held, temp = np.empty(n), np.empty(n)    # each period's, the same for every vehicle: found once
    gains = np.empty((n, 5))                 # each period's interval and its `read_gains`
    power, sonar = np.empty(n, dtype=np.bool_), np.empty(n, dtype=np.bool_)   # the periods of their reads
    for step in range(n):
        power[step] = (i0 + step + 1) % int(k[POWER_EVERY]) == 0
        sonar[step] = (i0 + step + 1) % int(k[SONAR_EVERY]) == 0
        t = (i0 + step + 1) * dt
        held[step] = t % CC[0, _C_PERIOD]
        h = t - (i0 + step) * dt
        gains[step, 0] = h
        gains[step, 1], gains[step, 2], gains[step, 3], gains[step, 4] = read_gains(CC[0], h)
        rise = k[WARM_RISE]
        temp[step] = AMBIENT_C if rise == 0.0 else AMBIENT_C + rise * (1.0 - exp((0.0 - t) / k[WARM_TAU]))
    for v in range(X.shape[0]):
        x, w, e, kc, q, ring, burst, cs, cc = X[v], W[v], E[v], KC[v], Q[v], RING[v], WORDS[v], CS[v], CC[v]
        uni, gen = UNI[v], GEN[v]
        nring, frac = NRING[v], FRAC[v]
        nn = normals_per_read(cc)
        for step in range(n):
            if w[W_DONE] != 0.0:
                break
            i = i0 + step + 1
            t = i * dt
            if not plant_period(x, w, ring, q, codes, nring, frac, i, k, wk):
                w[W_REASON], w[W_DONE] = DIVERGED, 1.0
                break
            sonar_edges(w, t)
            if not sense(x, w, q, codes, burst, cs, cc, e9, nn, jump, k, t, held[step], temp[step], gains[step], wk,
                         gen, uni, i, power[step], sonar[step]):
                w[W_REASON], w[W_DONE] = IMU_BAD, 1.0
                break
            has_echo = w[W_HAS_RESULT] != 0.0
            echo = w[W_RESULT]
            w[W_HAS_RESULT] = 0.0
            write = finished = False
            if w[W_PHASE] == GROUND:
                calibrate_and_arm(w, e, i >= i_arm, t, k)
            else:
                tp = t - t_arm
                sp = setpoint(w, SP, step, tp)
                why, write, finished = armed(w, e, kc, k, sp, t, tp, has_echo, echo, dt, cnt)
                if why == RUNNING:            # (the loop skips it on a touchdown that ends the flight: here
                    why = plan_end(w, e, sp, tp)  # that period's row is left out when the plan's time is up)
                if why != RUNNING:
                    w[W_REASON], w[W_DONE] = why, 1.0
                    break
            if write and w[W_PHASE] != DONE:                 # `SimMotors.write`
                for j in range(4):
                    w[W_NEXT + j] = cnt[j] * (255.0 / 40000.0)
            if w[W_PHASE] != GROUND:                         # the log's row: the judge's figures
                row(x, w, e, REC, v, i - rec0)
            if finished or (w[W_PHASE] == DONE and w[W_GROUND] != 0.0):
                # the loop's own landing ends the flight; after the plan's, nothing moves on the floor
                # to the plan's end but the estimate: the judged record holds the last row
                for r in range(max(i - rec0 + 1, 0), REC.shape[1]):
                    for j in range(N_REC):
                        REC[v, r, j] = REC[v, r - 1, j] if r > 0 else nan
                w[W_REASON], w[W_DONE] = ENDED, 1.0
                break


def sense(x, w, q, codes, burst, cs, cc, e9, nn: int, jump, k, t: float, held: float, temp: float, gains, wk, gen,
          uni, i: int, power_now: bool, sonar_now: bool) -> bool:
    """`FlightLoop._sense`: the chip's frame (its normals, the magnetometer's every MAG_EVERY reads;
    a refused one holds the last sample; False: more than MAX_BAD_IMU_FRAMES in a row), the power
    monitor's read (its random numbers only), the sonar's trigger."""
    normals(gen, w, e9, 0, nn)
    if i % MAG_EVERY == 1 % MAG_EVERY:      # read i's magnetometer sample (`chip_read`)
        normals(gen, w, e9, nn, 3)
    if chip_read(x, w, q, codes, burst, cs, cc, e9, 0, nn, jump, k, t, held, temp, gains, wk):
        w[W_BAD] = 0.0
    else:
        w[W_BAD] += 1.0
        if w[W_BAD] > MAX_BAD_IMU_FRAMES:
            return False
    if power_now:                                    # the power monitor's read
        for _ in range(int(k[INA_DRAWS])):
            gauss(w, uni, 0.0, 1.0)
    if sonar_now:
        sonar_trigger(w, x, uni, k, t)
    return True


def calibrate_and_arm(w, e, arm: bool, t: float, k) -> None:
    """`FlightLoop._ground`: `Calibration.add` (section 4.4.4, eq. 30-31); at the arming period `apply`
    and `FlightController.arm`, into FLYING."""
    s = W_S
    ax, ay, az, gx, gy, gz, mx, my, mz = w[s], w[s + 1], w[s + 2], w[s + 3], w[s + 4], w[s + 5], w[s + 6], \
        w[s + 7], w[s + 8]
    roll, pitch = tilt_from_accel(ax, ay, az)
    c = W_CAL
    w[c] += gx
    w[c + 1] += gy
    w[c + 2] += gz
    w[c + 3] += roll
    w[c + 4] += pitch
    h = ob_heading(mx, my, mz, roll, pitch)
    w[W_CAL_MAG] += 1.0
    w[c + 5] += cos(h)
    w[c + 6] += sin(h)
    w[W_CAL_N] += 1.0
    if arm:
        nc = w[W_CAL_N]
        w[W_GYRO_BIAS], w[W_GYRO_BIAS + 1], w[W_GYRO_BIAS + 2] = w[c] / nc, w[c + 1] / nc, w[c + 2] / nc
        ob_set_reference(e, w[c + 3] / nc, w[c + 4] / nc, atan2(w[c + 6], w[c + 5]), True)
        ob_arm(e, az)
        w[W_PHASE] = FLYING
        w[W_LAST_ECHO] = t
        w[W_DURATION] = k[DURATION]


def setpoint(w, SP, step: int, tp: float) -> tuple:
    """`FlightLoop._setpoint`: the plan's setpoints at plan time tp, or the loop's landing plan's."""
    if w[W_PHASE] == LANDING:
        return (landing_setpoint(w, tp, 0), landing_setpoint(w, tp, 1), landing_setpoint(w, tp, 2),
                landing_setpoint(w, tp, 3))
    return (SP[step, 0], SP[step, 1], SP[step, 2], SP[step, 3])


def armed(w, e, kc, k, sp, t: float, tp: float, has_echo: bool, echo: float, dt: float, cnt) -> tuple:
    """`FlightLoop._armed`: the echo to the altitude task; in the air the controller (its counts in
    cnt), the checks and the touchdown, on the floor after the flight the estimate alone. (why the
    loop stops or RUNNING, the motors take cnt, the flight ends after this period's row)."""
    s = W_S
    ax, ay, az, gx, gy, gz, mx, my, mz = w[s], w[s + 1], w[s + 2], w[s + 3], w[s + 4], w[s + 5], w[s + 6], \
        w[s + 7], w[s + 8]
    in_air = w[W_PHASE] != DONE
    if has_echo:
        if echo == echo:
            w[W_LAST_ECHO] = t
        if in_air:
            ob_on_range(e, kc, echo, t)
    if not in_air:
        ob_step(e, kc, gx, gy, gz, ax, ay, az, mx, my, mz, True, dt, 0.0, 0.0, e[ob.YAW], 0.0, cnt)
        return RUNNING, False, False
    ob_step(e, kc, gx, gy, gz, ax, ay, az, mx, my, mz, True, dt, sp[0], sp[1], sp[2], sp[3], cnt)
    if not checks(w, e, sp, t, tp):
        return CRASH, False, False
    return touchdown(w, e, k, sp, t, tp)


def checks(w, e, sp, t: float, tp: float) -> bool:
    """`FlightLoop._checks` that a healthy vehicle meets: the crash (False), the highest altitude, the
    altitude lost (descend on the accelerometer: `land`)."""
    if not (abs(e[ob.ROLL]) <= CRASH_TILT and abs(e[ob.PITCH]) <= CRASH_TILT):
        return False
    alt = e[ob.ALT]
    if alt > w[W_MAX_ALT]:
        w[W_MAX_ALT] = alt
    if w[W_BLIND] == 0.0 and t - w[W_LAST_ECHO] > LOST_ALT_S and alt > TOUCHDOWN_ALT:
        w[W_BLIND] = 1.0
        if w[W_PHASE] == FLYING:
            land(w, e, sp, tp, e[ob.VZ])
    return True


def touchdown(w, e, k, sp, t: float, tp: float) -> tuple:
    """`FlightLoop._touchdown`: in the loop's own landing the accelerometer confirms the floor, in the
    plan's the sonar reads it for TOUCHDOWN_S; then the motors stop (DONE). (RUNNING, the motors take
    the counts, the flight ends after this row: the loop's own landing)."""
    if w[W_PHASE] != FLYING:
        touched = e[ob.L_LANDED] != 0.0
    else:
        if sp[3] <= 0.0 and e[ob.ALT] < TOUCHDOWN_ALT and k[LANDS] != 0.0:
            if w[W_T_TOUCH] < 0.0:
                w[W_T_TOUCH] = t
        else:
            w[W_T_TOUCH] = -1.0
        touched = w[W_T_TOUCH] >= 0.0 and t - w[W_T_TOUCH] > TOUCHDOWN_S
    if not touched:
        return RUNNING, True, False
    own = w[W_PHASE] != FLYING
    w[W_PHASE] = DONE
    ob_touchdown(e)
    for j in range(4):
        w[W_NEXT + j] = 0.0               # `SimMotors.stop`
    return RUNNING, False, own


def plan_end(w, e, sp, tp: float) -> float:
    """`FlightLoop._plan_end`: the plan's time up, on the floor the flight ended, in the loop's landing
    no touchdown, never off the floor (the motors stopped), or in the air the loop's landing begins."""
    if tp < w[W_DURATION]:
        return RUNNING
    if w[W_PHASE] == DONE:
        return ENDED
    if w[W_PHASE] != FLYING:
        return NO_TOUCHDOWN
    if w[W_MAX_ALT] < LEFT_GROUND_ALT:
        for j in range(4):
            w[W_NEXT + j] = 0.0
        return NEVER_LEFT
    if w[W_T_TOUCH] < 0.0:
        land(w, e, sp, tp, e[ob.ALT])
    return RUNNING


def row(x, w, e, REC, v: int, r: int) -> None:
    """`FlightLoop._row` as the judge reads it: the largest true tilt, the highest and last true
    altitude, the log's rows; the judged record's row r (true and estimated attitude, wide: the
    commands, the sample, the altitude estimate)."""
    tilt = abs(x[PHI]) if abs(x[PHI]) > abs(x[THETA]) else abs(x[THETA])
    if not tilt <= w[W_TILT]:
        w[W_TILT] = tilt if tilt == tilt else inf
    if x[Z] > w[W_Z_MAX]:
        w[W_Z_MAX] = x[Z]
    w[W_Z_END] = x[Z]
    if 0 <= r < REC.shape[1]:
        REC[v, r, 0], REC[v, r, 1] = x[PHI], x[THETA]
        REC[v, r, 2] = (x[PSI] + pi) % TWOPI - pi
        REC[v, r, 3], REC[v, r, 4], REC[v, r, 5] = e[ob.ROLL], e[ob.PITCH], e[ob.YAW]
        if REC.shape[2] == N_WIDE:
            for j in range(4):
                REC[v, r, N_REC + j] = w[W_NEXT + j]
            for j in range(6):
                REC[v, r, N_REC + 4 + j] = w[W_S + j]
            REC[v, r, N_REC + 10] = e[ob.ALT]
    w[W_ROWS] += 1.0


# the onboard controller's functions (sim/sweeps/twin_controller.py), bound to their compiled copies by `compiled_fly`
ob_step, ob_on_range, ob_heading, ob_set_reference, ob_arm, ob_touchdown, ob_landing_start = (
    ob.step, ob.on_range, ob.heading_from_mag, ob.set_reference, ob.arm, ob.touchdown, ob.landing_start)


@functools.cache
def compiled_fly():
    """`fly` compiled (numba), every call bound to a compiled copy of its one plain source, or None."""
    from flightctl.sim.sweeps import pcg64
    from flightctl.sim.world import compiled, imu
    if not compiled.enabled():
        return None
    cc = compiled.compiled_copy
    plant = compiled.functions()
    o = ob.compiled_functions(cc)
    u = cc(uniform)
    g = cc(gauss, uniform=u)
    at = plant["forces"]
    held = cc(held_command)
    landed = cc(land, ob_landing_start=o["landing_start"])
    gains = cc(imu.read_gains, broadband_gains=cc(imu.broadband_gains))
    read = cc(chip_read, forces=at, held_command=held, chip_words=imu.chip_frame_compiled(put_word), read_gains=gains,
              rotation_from_trig=plant["rotation_from_trig"], attitude_trig=plant["attitude_trig"],
              i16=cc(i16, _i16=cc(imu._i16)))
    sensed = cc(sense, normals=cc(normals, standard_normal=pcg64.compiled_normal(cc)), chip_read=read, gauss=g,
                sonar_trigger=cc(sonar_trigger, uniform=u, gauss=g))
    flown = cc(armed, ob_step=o["step"], ob_on_range=o["on_range"], checks=cc(checks, land=landed),
               touchdown=cc(touchdown, ob_touchdown=o["touchdown"]))
    return cc(fly, allocates=True, work=plant["work"], normals_per_read=cc(imu.normals_per_read), read_gains=gains,
              plant_period=cc(plant_period, forces=at, rk4=plant["rk4"], commanded=plant["commanded"], held_command=held,
                              time_weighted=cc(time_weighted), floor_spin=cc(floor_spin), floor_brake=cc(floor_brake)),
              sonar_edges=cc(sonar_edges), sense=sensed,
              calibrate_and_arm=cc(calibrate_and_arm, tilt_from_accel=o["tilt"], ob_heading=o["heading"],
                                   ob_set_reference=o["set_reference"], ob_arm=o["arm"]),
              setpoint=cc(setpoint, landing_setpoint=cc(landing_setpoint)), armed=flown,
              plan_end=cc(plan_end, land=landed), row=cc(row))
