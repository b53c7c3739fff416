"""The onboard controller for the batched simulator: `flightctl.control.controller.FlightController`
(`step`, `on_range`, `arm`, `land`) with its `AttitudeEstimator` (both structures, the magnetometer's
eq. 35 included), the four `Pid`s of eq. 24, the `Mixer` of eq. 25 with eq. 26 inverted to PWM
counts, and the `Vertical` estimate and the `Landing` of flightctl/control/landing.py, written as
plain functions on one vehicle's state array `e` and constants `k`, so that numba compiles them
(sim/world/compiled.py `compiled_copy`) into the batch's per-vehicle loop (sim/sweeps/twin_loop.py).

A copy, because the onboard code stays plain Python on floats (it runs on the Pi, without numba),
where numba compiles functions, not objects. The copy is checked, not trusted:
tests/sim/sweeps/test_batch.py feeds the onboard controller and this one the same IMU samples, echoes and
setpoints, on the ground, in flight and landing, for vehicles with their own gains and filters: the
same PWM counts, count for count, and the same estimates. The equations it shares as plain functions
(eq. 26 inverted, the heading of eq. 32, eq. 30-31) are the onboard ones, compiled.
"""
from __future__ import annotations

from math import atan2, copysign, cos, exp, pi, sin, sqrt

from flightctl.control.controller import MAX_CORRECT_DT
from flightctl.control.estimator import heading_from_mag
from flightctl.control.landing import (ACCEL_TAU, FALLING_ACCEL, FALLING_SPEED, IMPACT, KI, KV, LANDED_ACCEL,
                                       LANDED_S, LANDED_THRUST, RAMP, RETRY_S, STALLED_S, STALLED_SPEED, TOUCH_ALT, W)
from flightctl.control.mixer import MIN_TILT_COSINE, count_from_thrust
from flightctl.physics import G
from flightctl.safety import LEFT_GROUND_ALT
from flightctl.sim.world.model import remainder

TWO_PI = 2.0 * pi

# e: one vehicle's controller state. The estimator (roll, pitch, yaw, their rates for the D terms, the
# filtered gyro, the in-flight gyro bias, the D path's EMA gain and its dt, in flight, the references
# of the calibration), the PIDs' integrals, u_z, the altitude task, the vertical estimate, the landing,
# the thrusts; the roll and pitch whose sines and cosines follow (`estimate_trig`).
(ROLL, PITCH, YAW, DROLL, DPITCH, DYAW, EP, EQ, ER, BX, BY, A_RATE, RATE_DT, IN_FLIGHT, ROLL_BIAS, PITCH_BIAS,
 YAW_BIAS, USE_MAG, I_Z, I_PHI, I_THETA, I_PSI, UZ, ALT, ALT_PREV, ALT_SP, ALT_T, VZ, VV, VB, VA, LANDING_ON,
 L_TRIM, L_UZ, L_SPEED, L_INTEGRAL, L_ALOW, L_TSTILL, L_TRETRY, L_VFEEL, L_TSTALLED, L_FEELING, L_LANDED,
 L_DESCENDING, F1, F2, F3, F4, T_ROLL, T_PITCH, SR, CR, SP, CP, N_E) = range(55)
# k: its constants: the gains of eq. 24 (kp, ki, kd per axis z, phi, theta, psi), Table 5's filters and
# the in-flight correction's, the D path's time constant, the structure (1: "paper"), the airframe's
# B (eq. 25), eq. 26's h1 and h2, the sonar's period, the landing's M / 4 and M G / 4
(KP_Z, KI_Z, KD_Z, KP_PHI, KI_PHI, KD_PHI, KP_THETA, KI_THETA, KD_THETA, KP_PSI, KI_PSI, KD_PSI, A_EMA, A_RP,
 A_YAW, K_AIR, KI_AIR, TAU_RATE, PAPER, B, H1, H2, SONAR_PERIOD, M4, LAND_B, N_K) = range(26)
GAINS = ("z", "phi", "theta", "psi")


def constants(params, structure: str = "flight") -> list[float]:
    """k of one vehicle's `Params` (its gains, filters and airframe)."""
    g, f, a = params.gains, params.filters, params.airframe
    k = [0.0] * N_K
    for i, axis in enumerate(GAINS):
        k[KP_Z + 3 * i], k[KI_Z + 3 * i], k[KD_Z + 3 * i] = (getattr(g, "kp_" + axis), getattr(g, "ki_" + axis),
                                                            getattr(g, "kd_" + axis))
    w = 1.0 / f.tau_tilt_air if f.tau_tilt_air > 0.0 else 0.0
    k[A_EMA], k[A_RP], k[A_YAW], k[K_AIR], k[KI_AIR] = f.alpha_ema, f.alpha_roll_pitch, f.alpha_yaw, 2.0 * w, w * w
    k[TAU_RATE], k[PAPER] = f.tau_rate, 1.0 if structure == "paper" else 0.0
    k[B], k[H1], k[H2], k[SONAR_PERIOD] = a.B, a.h1, a.h2, 1.0 / a.sonar_hz
    k[M4], k[LAND_B] = a.M / 4.0, a.M * G / 4.0
    return k


def estimate_trig(e):
    """(sin, cos) of the estimate's roll and pitch: `step` finds them for its new estimate, and the next
    `on_range` and `estimate` ask for the same angles (remembered, the sign of a zero included; a cosine
    of 0, which no float angle has, says none are: a state of zeros)."""
    roll, pitch = e[ROLL], e[PITCH]
    if not (e[CR] != 0.0 and roll == e[T_ROLL] and pitch == e[T_PITCH]
            and copysign(1.0, roll) == copysign(1.0, e[T_ROLL]) and copysign(1.0, pitch) == copysign(1.0, e[T_PITCH])):
        e[T_ROLL], e[T_PITCH] = roll, pitch
        e[SR], e[CR], e[SP], e[CP] = sin(roll), cos(roll), sin(pitch), cos(pitch)
    return e[SR], e[CR], e[SP], e[CP]


def set_reference(e, roll_bias: float, pitch_bias: float, yaw_bias: float, use_mag: bool) -> None:
    """`AttitudeEstimator.set_reference`: the calibration's biases and heading; the estimate restarts."""
    e[ROLL_BIAS], e[PITCH_BIAS], e[YAW_BIAS], e[USE_MAG] = roll_bias, pitch_bias, yaw_bias, 1.0 if use_mag else 0.0
    for i in (ROLL, PITCH, YAW, EP, EQ, ER, DROLL, DPITCH, DYAW, BX, BY):
        e[i] = 0.0


def arm(e, az: float) -> None:
    """`FlightController.arm`: `Vertical.reset` on the floor; the estimator in flight."""
    e[VZ] = e[VV] = e[VA] = 0.0
    e[VB] = az - G
    e[IN_FLIGHT] = 1.0


def touchdown(e) -> None:
    """`FlightController.touchdown`: the estimator's ground filter again."""
    e[IN_FLIGHT] = 0.0


def pid(e, k, at: int, setpoint: float, y: float, dy: float, dt: float, angle: bool) -> float:
    """`Pid.update` (eq. 24) of the axis whose kp is k[at] and integral e[at - KP_Z + I_Z]."""
    err = setpoint - y
    if angle:
        err = remainder(err + pi, TWO_PI) - pi
    lim = k[B]
    slot = I_Z + (at - KP_Z) // 3
    i = e[slot] + k[at + 1] * err * dt
    e[slot] = i = lim if i > lim else -lim if i < -lim else i
    u = k[at] * err - k[at + 2] * dy + i
    return lim if u > lim else -lim if u < -lim else u


def estimate(e, k, gx, gy, gz, ax, ay, az, mx, my, mz, mag_fresh: bool, dt: float) -> None:
    """`AttitudeEstimator.update`."""
    roll, pitch, yaw = e[ROLL], e[PITCH], e[YAW]
    sr, cr, sp, cp = estimate_trig(e)
    paper = k[PAPER] != 0.0
    if paper:
        a = k[A_EMA]
        b = 1.0 - a
        p = e[EP] = a * gx + b * e[EP]      # eq. 36-38
        q = e[EQ] = a * gy + b * e[EQ]
        r = e[ER] = a * gz + b * e[ER]
    else:
        p, q, r = gx - e[BX], gy - e[BY], gz
    w = q * sr + r * cr
    droll, dpitch, dyaw = p + w * sp / cp, q * cr - r * sr, w / cp
    if not paper and k[TAU_RATE] > 0.0:
        if dt != e[RATE_DT]:
            e[RATE_DT], e[A_RATE] = dt, 1.0 - exp(-dt / k[TAU_RATE])
        a = e[A_RATE]
        b = 1.0 - a
        fp = e[EP] = a * p + b * e[EP]
        fq = e[EQ] = a * q + b * e[EQ]
        fr = e[ER] = a * r + b * e[ER]
        fw = fq * sr + fr * cr
        rate_roll, rate_pitch, rate_yaw = fp + fw * sp / cp, fq * cr - fr * sr, fw / cp
    else:
        rate_roll, rate_pitch, rate_yaw = droll, dpitch, dyaw
    roll_g, pitch_g, yaw_g = roll + droll * dt, pitch + dpitch * dt, yaw + dyaw * dt
    if paper or e[IN_FLIGHT] == 0.0:
        a = k[A_RP]
        roll_g = a * roll_g + (1.0 - a) * (atan2(ay, az) - e[ROLL_BIAS])
        pitch_g = a * pitch_g + (1.0 - a) * (atan2(-ax, sqrt(ay * ay + az * az)) - e[PITCH_BIAS])
    else:
        er = atan2(ay, az) - e[ROLL_BIAS] - roll_g
        ep = atan2(-ax, sqrt(ay * ay + az * az)) - e[PITCH_BIAS] - pitch_g
        kk = k[K_AIR] * dt
        roll_g += kk * er
        pitch_g += kk * ep
        ki = k[KI_AIR] * dt
        e[BX] -= ki * er
        e[BY] -= ki * (ep * cr)
    if e[USE_MAG] != 0.0 and mag_fresh:
        yaw_mag = heading_from_mag(mx, my, mz, roll_g + e[ROLL_BIAS], pitch_g + e[PITCH_BIAS]) - e[YAW_BIAS]
        yaw_g += (1.0 - k[A_YAW]) * (remainder(yaw_mag - yaw_g + pi, TWO_PI) - pi)
    yaw_g = remainder(yaw_g + pi, TWO_PI) - pi
    if paper:
        rate_roll, rate_pitch = (roll_g - roll) / dt, (pitch_g - pitch) / dt
        rate_yaw = (remainder(yaw_g - yaw + pi, TWO_PI) - pi) / dt
    e[DROLL], e[DPITCH], e[DYAW] = rate_roll, rate_pitch, rate_yaw
    e[ROLL], e[PITCH], e[YAW] = roll_g, pitch_g, yaw_g


def landing_start(e, speed: float) -> None:
    """`FlightController.land`: `Landing.start` from the altitude PID's integral."""
    e[L_TRIM] = e[L_UZ] = e[I_Z]
    e[L_SPEED] = speed
    for i in (L_INTEGRAL, L_ALOW, L_TSTILL, L_TRETRY, L_VFEEL, L_TSTALLED, L_FEELING, L_LANDED, L_DESCENDING):
        e[i] = 0.0
    e[LANDING_ON] = 1.0


def landing_step(e, k, dt: float) -> float:
    """`Landing.step`: u_z of the descent and the touchdown test."""
    b = k[LAND_B]
    hover = b + e[L_TRIM]
    e[L_ALOW] += (e[VA] - e[L_ALOW]) * (dt / ACCEL_TAU)
    if e[L_FEELING] == 0.0:
        v = e[VV]
        err = -e[L_SPEED] - v
        e[L_INTEGRAL] += KI * err * dt
        uz = e[L_TRIM] + k[M4] * (KV * err + e[L_INTEGRAL])
        if v < -0.5 * e[L_SPEED]:
            e[L_DESCENDING] = 1.0
        e[L_TSTALLED] = e[L_TSTALLED] + dt if e[L_DESCENDING] != 0.0 and v > -STALLED_SPEED else 0.0
        if e[L_TRETRY] > 0.0:
            e[L_TRETRY] -= dt
        elif e[VZ] < TOUCH_ALT or e[L_TSTALLED] > STALLED_S:
            e[L_FEELING], e[L_TSTILL], e[L_VFEEL] = 1.0, 0.0, v
    else:
        uz = e[L_UZ] - RAMP * hover * dt
        if e[L_ALOW] < -FALLING_ACCEL or e[VV] - e[L_VFEEL] < -FALLING_SPEED:
            e[L_FEELING], e[L_TRETRY] = 0.0, RETRY_S
            e[L_DESCENDING], e[L_TSTALLED] = 0.0, 0.0
            e[L_INTEGRAL] = 0.0
            uz = e[L_UZ]
        elif b + uz < LANDED_THRUST * hover and -LANDED_ACCEL < e[L_ALOW] < LANDED_ACCEL:
            e[L_TSTILL] += dt
            e[L_LANDED] = 1.0 if e[L_TSTILL] >= LANDED_S else 0.0
        else:
            e[L_TSTILL] = 0.0
    uz = b if uz > b else -b if uz < -b else uz
    e[L_UZ] = uz
    return uz


def on_range(e, k, distance: float, t: float) -> None:
    """`FlightController.on_range` (NaN: a failed measurement), with `Vertical.correct`."""
    dt = t - e[ALT_T] if e[ALT_T] >= 0.0 else k[SONAR_PERIOD]
    e[ALT_T] = t
    if distance == distance:
        _, cr, _, cp = estimate_trig(e)
        e[ALT] = alt = distance * cr * cp
        if dt > 0.0:
            h = dt if dt < MAX_CORRECT_DT else MAX_CORRECT_DT
            r = alt - e[VZ]
            e[VZ] += 3.0 * W * h * r       # (s + W)^3: k1, k2, k3 of `Vertical`
            e[VV] += 3.0 * W * W * h * r
            e[VB] -= W * W * W * h * r
    elif e[ALT] > LEFT_GROUND_ALT:
        e[ALT] = e[VZ]
    if e[LANDING_ON] != 0.0:
        return
    if dt > 0.0:
        e[UZ] = pid(e, k, KP_Z, e[ALT_SP], e[ALT], (e[ALT] - e[ALT_PREV]) / dt, dt, False)
        e[ALT_PREV] = e[ALT]


def step(e, k, gx, gy, gz, ax, ay, az, mx, my, mz, mag_fresh: bool, dt: float, roll_sp: float, pitch_sp: float,
         yaw_sp: float, alt_sp: float, counts) -> None:
    """`FlightController.step`: the PWM counts into counts[0:4] (and the thrusts into e[F1:F4 + 1])."""
    estimate(e, k, gx, gy, gz, ax, ay, az, mx, my, mz, mag_fresh, dt)
    e[ALT_SP] = alt_sp
    roll, pitch = e[ROLL], e[PITCH]
    sr, cr, sp, cp = estimate_trig(e)   # `Vertical.predict`
    a = e[VA] = -sp * ax + sr * cp * ay + cr * cp * az - G - e[VB]
    if a > IMPACT:
        e[VZ] = e[VV] = 0.0
    else:
        e[VZ] += (e[VV] + 0.5 * a * dt) * dt
        e[VV] += a * dt
    if e[LANDING_ON] != 0.0:
        e[UZ] = landing_step(e, k, dt)
        e[ALT] = e[VZ]
    uphi = pid(e, k, KP_PHI, roll_sp, roll, e[DROLL], dt, False)
    utheta = pid(e, k, KP_THETA, pitch_sp, pitch, e[DPITCH], dt, False)
    upsi = pid(e, k, KP_PSI, yaw_sp, e[YAW], e[DYAW], dt, True)
    c = cr * cp                         # `Mixer.mix`: eq. 25, each f within [0, 2B], eq. 26 inverted
    base = k[B] + e[UZ] / (c if c > MIN_TILT_COSINE else MIN_TILT_COSINE)
    fmax, h1, h2 = 2.0 * k[B], k[H1], k[H2]
    for i in range(4):
        if i == 0:
            fi = base - utheta + upsi
        elif i == 1:
            fi = base + uphi - upsi
        elif i == 2:
            fi = base + utheta + upsi
        else:
            fi = base - uphi - upsi
        e[F1 + i] = fi = fmax if fi > fmax else fi if fi > 0.0 else 0.0
        counts[i] = count_from_thrust(fi, h1, h2)


def compiled_functions(cc):
    """The functions above compiled with `cc` (`compiled.compiled_copy`), each call bound to a compiled
    copy; the onboard functions they call (eq. 26 inverted, eq. 30-32) compiled from their one source."""
    from flightctl import physics
    from flightctl.control import estimator, mixer
    count = cc(mixer.count_from_thrust, command_from_thrust=cc(physics.command_from_thrust))
    heading = cc(estimator.heading_from_mag)
    rem = cc(remainder)
    pid_c = cc(pid, remainder=rem)
    land = cc(landing_step)
    trig = cc(estimate_trig)
    est = cc(estimate, heading_from_mag=heading, remainder=rem, estimate_trig=trig)
    return {"step": cc(step, estimate=est, pid=pid_c, landing_step=land, count_from_thrust=count, estimate_trig=trig),
            "on_range": cc(on_range, pid=pid_c, estimate_trig=trig),
            "tilt": cc(estimator.tilt_from_accel),
            "heading": heading, "set_reference": cc(set_reference), "arm": cc(arm),
            "touchdown": cc(touchdown),
            "landing_start": cc(landing_start)}
