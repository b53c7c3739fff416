"""The batched simulator's world, one vehicle's period as `flightctl sim`'s simulated board advances it
(sim/sweeps/twin_loop.py flies the loop's phases around it; sim/sweeps/batch.py sets the arrays up): the
state arrays' layout (w: the world and the loop, k: the constants), the Mersenne Twister's uniforms and
Python's gauss on them, the sonar's echo edges and trigger, the plant's period (the actuation delay's ring,
the floor, one RK4 step), the chip's burst decoded as the driver decodes it, the chip's normals (PCG64).
Plain Python on arrays: sim/world/compiled.py compiles each function (`twin_loop.compiled_fly` binds them)."""
from __future__ import annotations

from math import copysign, cos, inf, log, nan, pi, sin, sqrt


from flightctl.drivers import mpu9250_regs as reg
from flightctl.drivers.hcsr04 import MAX_RANGE_M, MIN_RANGE_M, US_PER_M, WATCHDOG_MS
from flightctl.loop import PHASES
from flightctl.sim.world.devices import EARTH_FIELD_T, NoisePool, SimGpio
from flightctl.sim.world.imu import _BURST, _C_BBA, _C_BBQ, _C_KA, _C_KG, SimMpu9250, _i16, chip_frame, read_gains
from flightctl.sim.world.compiled import attitude_trig, commanded, forces, rebound, rk4
from flightctl.sim.world.model import N_RIGID, P, PHI, PSI, Q, R, THETA, VX, VY, VZ, Z, rotation_from_trig
from flightctl.sim.world.compiled import _B, _L, _RIGID
from flightctl.sim.world.plant import CONTACT_S, floor_brake, floor_spin, time_weighted

ECHO_DELAY_S, NO_ECHO_S = SimGpio.ECHO_DELAY_S, SimGpio.NO_ECHO_S
WATCHDOG_S = WATCHDOG_MS / 1000.0
MAG_EVERY = SimMpu9250.MAG_EVERY
NOISE_BLOCK = NoisePool.BLOCK
TWOPI = 2.0 * pi
BN, BW, BU = EARTH_FIELD_T
AK_LSB = 1.0 / reg.AK_TESLA_PER_LSB

# w: one vehicle's world and loop state. The plant's floor (on the floor, the last contact's time and
# vertical speed), the command the motors hold and the head of its ring of delayed commands; the chip's
# last read, the read interval of its DLPF gains, its reads so far, the magnetometer's words; the
# driver's last accepted and last words, the bad frames in a row; the sample (accelerometer, gyro less
# the calibration's bias, field); the sonar (an echo under way, its rise and fall, the driver's rise
# tick, the last edge, the trigger's tick, a result); the Mersenne Twister's position and Python's
# cached gauss; the loop (armed, flying, landing, blind, the last valid echo, the touchdown's start on
# the sonar, the highest altitude, the calibration's sums and count, the gyro bias, the loop's landing
# plan: its start, the setpoints then, its ramp; the plan's end, why it stopped); the judge's figures
# (the largest true tilt, the fastest touchdown, the highest and the last true altitude, the log's rows);
# the command the plant applies (after the delay), its thrusts and speeds (`commanded`), and the rotors'
# vertical force at the state now for the command it was found with (the chip's read: the floor's test);
# on the floor, whether the rotor states are the fixed point of the held command's step (`plant_period`)
# and whether the rotors' thrusts and speeds kept for the chip (W_FW: f, then w) are at this state; the
# chip's position in its `NoisePool` block.
(W_GROUND, W_T_STOP, W_VZ_STOP, W_NEXT, W_HEAD, W_T_LAST, W_KDT, W_READS, W_MAG, W_GOOD, W_PREV, W_HAS_GOOD,
 W_HAS_PREV, W_BAD, W_S, W_WAITING, W_RISE_T, W_FALL_T, W_RISE, W_LAST_EDGE, W_TRIGGER, W_RESULT, W_HAS_RESULT,
 W_U, W_GAUSS, W_HAS_GAUSS, W_PHASE, W_BLIND, W_LAST_ECHO, W_T_TOUCH, W_MAX_ALT, W_CAL, W_CAL_N, W_CAL_MAG,
 W_GYRO_BIAS, W_LAND_T, W_LAND_SP, W_LAND_RAMP, W_DURATION, W_REASON, W_DONE, W_TILT, W_TOUCHDOWN, W_Z_MAX,
 W_Z_END, W_ROWS, W_UAPP, W_CMD, W_LIFT, W_LIFT_AT, W_STILL, W_FSTILL, W_FW, W_POOL, N_W) = \
    (0, 1, 2, 3, 7, 8, 9, 10, 11, 14, 21, 28, 29, 30, 31, 40, 41, 42, 43, 44, 45, 46, 47, 48, 49, 50, 51, 52,
     53, 54, 55, 56, 63, 64, 65, 68, 69, 73, 74, 75, 76, 77, 78, 79, 80, 81, 82, 86, 94, 95, 99, 100, 101,
     109, 110)
# why the loop stopped (w[W_REASON]): still flying, the plan's end (landed or not), a crash by the estimate,
# the IMU's frames bad, no touchdown by the landing's end, never left the ground, the plant diverged
RUNNING, ENDED, CRASH, IMU_BAD, NO_TOUCHDOWN, NEVER_LEFT, DIVERGED = range(7)
# the loop's phase (w[W_PHASE]): flightctl/loop.py's PHASES by their index (TWO_ROTORS is never met here:
# the twin flies no motor loss)
GROUND, FLYING, LANDING, TWO_ROTORS, DONE = (float(j) for j in range(len(PHASES)))
# k: the world's constants shared by the vehicles: g, M (the plant's), the sonar's jitter (us) and dropout,
# the magnetometer's noise (T), the driver's m/s^2 and rad/s per LSB, the die's warming (degC, s), the
# plan lands, its duration, the power monitor's gaussian draws per read, the loop's dt, t_arm, the
# driver's temperature range (LSB), the periods between the power monitor's reads and the sonar's triggers
(G_, M_, SONAR_SIGMA, DROPOUT, MAG_SIGMA, A_SCALE, G_SCALE, WARM_RISE, WARM_TAU, LANDS, DURATION, INA_DRAWS, DT,
 T_ARM, TEMP_LO, TEMP_HI, POWER_EVERY, SONAR_EVERY, N_WORLD) = range(19)
# rows of the judged record: the true roll, pitch and yaw (wrapped), and the estimate's
N_REC = 6
# a wide record (a log's columns, sim/sweeps/fleet_flown.py) adds: the commands P1..P4 the motors took, the
# sample (acc_x..z, gyro_x..z: the driver's, less the calibration's gyro bias), the altitude estimate
N_WIDE = N_REC + 11


def uniform(w, uni) -> float:
    """The next `random.random()` of the vehicle's Mersenne Twister (its stream in uni)."""
    j = int(w[W_U])
    w[W_U] = j + 1
    return uni[j]


def gauss(w, uni, mu: float, sigma: float) -> float:
    """`random.gauss`, as CPython computes it, on that stream."""
    if w[W_HAS_GAUSS] != 0.0:
        z = w[W_GAUSS]
        w[W_HAS_GAUSS] = 0.0
    else:
        x2pi = uniform(w, uni) * TWOPI
        g2rad = sqrt(-2.0 * log(1.0 - uniform(w, uni)))
        z = cos(x2pi) * g2rad
        w[W_GAUSS] = sin(x2pi) * g2rad
        w[W_HAS_GAUSS] = 1.0
    return mu + z * sigma


def sonar_edges(w, t: float) -> None:
    """`SimGpio.advance_to(t)` for the echo pin, each edge and watchdog report into `HcSr04._edge`. The
    edges fire in the order of SimGpio's heap, (time, pin, level): a fall at its rise's instant (a
    width of 0: a jitter below the floor's range) fires first, and the driver, with no rise yet,
    ignores it; the rise then waits for the watchdog."""
    while True:
        rise, fall = w[W_RISE_T], w[W_FALL_T]
        if fall <= t and fall <= rise:
            w[W_FALL_T] = inf
            w[W_LAST_EDGE] = fall
            if w[W_RISE] >= 0.0:
                width_us = round(fall * 1e6) - w[W_RISE]
                w[W_RISE] = -1.0
                w[W_WAITING] = 0.0
                d = width_us / US_PER_M
                w[W_RESULT] = d if MIN_RANGE_M <= d <= MAX_RANGE_M else nan
                w[W_HAS_RESULT] = 1.0
        elif rise <= t:
            w[W_RISE_T] = inf
            w[W_LAST_EDGE] = rise
            w[W_RISE] = round(rise * 1e6)
        else:
            break
    last = w[W_LAST_EDGE]
    while t - last >= WATCHDOG_S:    # pigpio repeats the report while no edge comes
        last += WATCHDOG_S
        w[W_LAST_EDGE] = last
        if w[W_WAITING] != 0.0 and (w[W_RISE] >= 0.0 or round(last * 1e6) - w[W_TRIGGER] >= 1000 * WATCHDOG_MS):
            w[W_RISE] = -1.0
            w[W_WAITING] = 0.0
            w[W_RESULT] = nan
            w[W_HAS_RESULT] = 1.0


def sonar_trigger(w, x, uni, k, t: float) -> None:
    """`HcSr04.trigger` and `SimGpio.gpio_trigger`: the echo's edges for the range along -z_b now."""
    if w[W_WAITING] != 0.0:
        return
    w[W_WAITING] = 1.0
    w[W_TRIGGER] = round(t * 1e6)
    te = t + 10 * 1e-6 + ECHO_DELAY_S
    c = cos(x[PHI]) * cos(x[THETA])
    d = x[Z] / c if c > 0.5 else inf
    if d > 4.5 or (k[DROPOUT] != 0.0 and uniform(w, uni) < k[DROPOUT]):
        width = NO_ECHO_S
    else:
        width = max(d * US_PER_M + gauss(w, uni, 0.0, k[SONAR_SIGMA]), 0.0) * 1e-6
    w[W_RISE_T] = te
    w[W_FALL_T] = te + width


def plant_period(x, w, ring, q, codes, nring: int, frac: float, i: int, k, wk) -> bool:
    """`Plant.advance` over the loop period ending at i dt: the delayed command, the floor, one RK4 step,
    a touchdown. False if the state is no longer finite (`Diverged`)."""
    head = int(w[W_HEAD]) + 1                # the ring's indices mod nring (>= 2), without a division
    head = head - nring if head >= nring else head
    w[W_HEAD] = head
    for j in range(4):
        ring[head, j] = w[W_NEXT + j]
    old = head + 1 - nring if head + 1 >= nring else head + 1
    new = old + 1 - nring if old + 1 >= nring else old + 1
    if frac != 0.0:
        u1, u2 = time_weighted(ring[old, 0], ring[new, 0], frac), time_weighted(ring[old, 1], ring[new, 1], frac)
        u3, u4 = time_weighted(ring[old, 2], ring[new, 2], frac), time_weighted(ring[old, 3], ring[new, 3], frac)
    else:
        u1, u2, u3, u4 = ring[new, 0], ring[new, 1], ring[new, 2], ring[new, 3]
    if not (u1 == w[W_UAPP] and u2 == w[W_UAPP + 1] and u3 == w[W_UAPP + 2] and u4 == w[W_UAPP + 3]):
        cmd = commanded(u1, u2, u3, u4, q)      # (a pure function of the command: found once for each)
        for j in range(8):
            w[W_CMD + j] = cmd[j]
        w[W_UAPP], w[W_UAPP + 1], w[W_UAPP + 2], w[W_UAPP + 3] = u1, u2, u3, u4
        w[W_STILL] = w[W_FSTILL] = 0.0
    cmd = held_command(w)
    dt = k[DT]
    t_end = (i - 1) * dt + dt                # `Plant.advance`'s t0 + j h, at one substep
    ground = False
    if w[W_GROUND] != 0.0:
        if u1 == w[W_LIFT_AT] and u2 == w[W_LIFT_AT + 1] and u3 == w[W_LIFT_AT + 2] and u4 == w[W_LIFT_AT + 3]:
            lift = w[W_LIFT]                      # the chip's read found it at this state and command
        else:
            f, _, force, _, _ = forces(x, cmd, codes, q, wk)
            lift = force[2] + f[0] + f[1] + f[2] + f[3]
        ground = not lift / k[M_] > k[G_]
    if not (ground and (x.shape[0] == N_RIGID or w[W_STILL] != 0.0)):
        rk4(x, cmd, codes, q, dt, wk, ground)
        y = 4 * x.shape[0]                   # where `rk4` leaves the new state
        if ground:                           # a step that gives the rotor states back gives them every time
            still = True
            for j in range(N_RIGID, x.shape[0]):
                if not (wk[y + j] == x[j] and copysign(1.0, wk[y + j]) == copysign(1.0, x[j])):
                    still = False
            w[W_STILL] = 1.0 if still else 0.0
        for j in range(N_RIGID if ground else 0, x.shape[0]):
            x[j] = wk[y + j]
        if not ground:
            w[W_GROUND] = w[W_STILL] = w[W_FSTILL] = 0.0
            s = 0.0
            for j in range(x.shape[0]):
                s += x[j]
            if s - s != 0.0:
                return False
            if x[Z] < 0.0:                   # `Plant._touch_down`
                vz = x[VZ]
                if vz < -0.01 and -vz > w[W_TOUCHDOWN]:
                    w[W_TOUCHDOWN] = -vz
                w[W_T_STOP], w[W_VZ_STOP] = t_end, vz
                for j in (Z, VX, VY, VZ, PHI, THETA, P, Q):
                    x[j] = 0.0
                w[W_GROUND] = 1.0
    if w[W_GROUND] != 0.0 and x[R] != 0.0:   # a spin it landed with, braked by its feet (`Plant.advance`)
        x[R], turned = floor_spin(x[R], dt, floor_brake(4.0 * q[_B], q[_L], q[_RIGID + 2]))
        x[PSI] += turned
    return True


def held_command(w):
    """The commanded thrusts and speeds of the command the plant applies (`commanded`, kept in w)."""
    c = W_CMD
    return w[c], w[c + 1], w[c + 2], w[c + 3], w[c + 4], w[c + 5], w[c + 6], w[c + 7]


def chip_read(x, w, q, codes, burst, cs, cc, e, ie: int, im: int, jump, k, t: float, held: float, temp: float,
              gains, wk) -> bool:
    """`SimMpu9250._sample` at t (the plant's specific force, rates, rotors) and `Mpu9250.read` of the
    burst, with the chip's normals e[ie:] (`normals_per_read`) and the magnetometer's three e[im:im + 3], `held`
    = t % the chip's output period, the die's temperature at t and `gains` (the read interval from the
    last period and the DLPF stage's gains for it), the same for every vehicle: `fly` finds them once a
    period; the sample in w[W_S:], the gyro less the calibration's bias. False: the frame is refused."""
    if w[W_FSTILL] != 0.0:               # on the floor, at the state and command of the last read
        c = W_FW
        f, rw = (w[c], w[c + 1], w[c + 2], w[c + 3]), (w[c + 4], w[c + 5], w[c + 6], w[c + 7])
        force = (0.0, 0.0, 0.0)
    else:
        f, _, force, _, rw = forces(x, held_command(w), codes, q, wk)
        w[W_LIFT] = force[2] + f[0] + f[1] + f[2] + f[3]    # the floor's test at this state, for this command
        for j in range(4):
            w[W_LIFT_AT + j] = w[W_UAPP + j]
            w[W_FW + j], w[W_FW + 4 + j] = f[j], rw[j]
        if w[W_GROUND] != 0.0 and w[W_STILL] != 0.0:
            w[W_FSTILL] = 1.0                 # nothing moves until the command changes
    t_stop, vz = w[W_T_STOP], w[W_VZ_STOP]
    stopping = -vz / CONTACT_S if 0.0 <= t - t_stop < CONTACT_S else 0.0
    if w[W_GROUND] != 0.0:
        fx, fy, fz = 0.0, 0.0, k[G_] + stopping
    else:
        m = k[M_]
        fx, fy, fz = force[0] / m, force[1] / m, (force[2] + f[0] + f[1] + f[2] + f[3]) / m + stopping
    dt = t - w[W_T_LAST]
    w[W_T_LAST] = t
    if dt > 0.0 and dt != w[W_KDT]:
        w[W_KDT] = dt
        if dt == gains[0]:                # the period's interval, whose gains `fly` found for every vehicle
            cc[_C_KA], cc[_C_KG], cc[_C_BBA], cc[_C_BBQ] = gains[1], gains[2], gains[3], gains[4]
        else:
            cc[_C_KA], cc[_C_KG], cc[_C_BBA], cc[_C_BBQ] = read_gains(cc, dt)
    chip_words(burst, cs, cc, e, ie, fx, fy, fz, x[P], x[Q], x[R], f[0], f[1], f[2], f[3], rw[0], rw[1], rw[2], rw[3],
               held, dt, temp, w[W_READS] > 0.0)
    w[W_READS] += 1.0
    if int(w[W_READS]) % MAG_EVERY == 1 % MAG_EVERY:   # reads 1, 5, 9...: the AK8963's sample
        rm = rotation_from_trig(*attitude_trig(x, 0, wk))   # the attitude's, remembered by `forces` above
        bx = rm[0] * BN + rm[3] * BW + rm[6] * BU
        by = rm[1] * BN + rm[4] * BW + rm[7] * BU
        bz = rm[2] * BN + rm[5] * BW + rm[8] * BU
        sm = k[MAG_SIGMA]
        w[W_MAG] = i16((by + sm * e[im]) * AK_LSB)
        w[W_MAG + 1] = i16((bx + sm * e[im + 1]) * AK_LSB)
        w[W_MAG + 2] = i16(-(bz + sm * e[im + 2]) * AK_LSB)
    words = (burst[0], burst[1], burst[2], burst[3], burst[4], burst[5], burst[6])
    had_prev = w[W_HAS_PREV] != 0.0
    jumps_prev = False
    if had_prev:
        for j in range(7):
            if abs(w[W_PREV + j] - words[j]) > jump[j]:
                jumps_prev = True
    for j in range(7):
        w[W_PREV + j] = words[j]
    w[W_HAS_PREV] = 1.0
    if not k[TEMP_LO] <= words[3] <= k[TEMP_HI]:
        return False
    if w[W_HAS_GOOD] != 0.0:
        jumps_good = False
        for j in range(7):
            if abs(w[W_GOOD + j] - words[j]) > jump[j]:
                jumps_good = True
        if jumps_good and (not had_prev or jumps_prev):
            return False
    for j in range(7):
        w[W_GOOD + j] = words[j]
    w[W_HAS_GOOD] = 1.0
    a, g = k[A_SCALE], k[G_SCALE]
    s = W_S
    w[s], w[s + 1], w[s + 2] = words[0] * a, words[1] * a, words[2] * a
    w[s + 3] = words[4] * g - w[W_GYRO_BIAS]      # `Calibration.correct`
    w[s + 4] = words[5] * g - w[W_GYRO_BIAS + 1]
    w[s + 5] = words[6] * g - w[W_GYRO_BIAS + 2]
    m = reg.AK_TESLA_PER_LSB
    w[s + 6], w[s + 7], w[s + 8] = w[W_MAG + 1] * m, w[W_MAG] * m, -w[W_MAG + 2] * m   # AK8963 -> body axes
    return True


def put_word(words, at: int, v: float) -> None:
    """`imu.put16` of the register pair at `at` as the driver reads it back (the big-endian int16 of
    its two bytes, `>h`: `_i16(v)`), kept as a float in words[(at - _BURST) // 2], without the bytes."""
    words[(at - _BURST) >> 1] = _i16(v)


# `imu.chip_frame` writing the burst's seven words with `put_word` (its compiled copy in `compiled_fly`)
chip_words = rebound(chip_frame, put16=put_word)


def i16(v: float) -> float:
    """`imu._i16` as a float."""
    return float(_i16(v))


def standard_normal(gen) -> float:
    """The chip's next normal: `Generator.standard_normal` (compiled: `pcg64.standard_normal` on its words)."""
    return gen.standard_normal()


def normals(gen, w, e, at: int, count: int) -> None:
    """`NoisePool.index(count)` of the vehicle's chip and its numbers into e[at:at + count], drawn here
    from the vehicle's own generator (`standard_normal`: NumPy's, number for number): a read
    whose numbers would cross the pool's block skips the block's rest, drawn and unused, as the pool's
    next block starts where the last one ended. w[W_POOL]: the position in the block."""
    i = int(w[W_POOL])
    if i + count > NOISE_BLOCK:
        for _ in range(NOISE_BLOCK - i):
            standard_normal(gen)
        i = 0
    for j in range(count):
        e[at + j] = standard_normal(gen)
    w[W_POOL] = i + count
