"""Reading a flight log for diagnose: one file reduced to per-row arrays (commands, gyro,
accelerometer, battery, altitude, the attitude from the integrated gyro, or from the logged attitude in
a log without an IMU: `# imu: none`), the rotor layout and the
sensor filters the log declares, and the mask of its usable airborne rows (docs/diagnose.md, "Only
airborne data are used"; docs/real-flights.md for logs of other vehicles)."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from flightctl.logfile import IMU_COLUMNS, Table
from flightctl.params import Airframe
from flightctl.physics import G, thrust_from_command
from flightctl.sim.logs.columns import (FOREIGN_COLUMNS, IDLE_P, MAX_ROTORS, MIN_ROTORS, MOTOR_COLUMNS, OMEGA_COLUMNS,
                                        all_running, motor_columns)
from flightctl.sim.world.model import rotation

MIN_AIRBORNE_S = 1.0     # s of airborne data needed in total to judge anything
Z_AIRBORNE = 0.10        # m: below this the legs may touch and the range is near its 2 cm limit
EDGE_S = 0.1             # s trimmed at both ends of each airborne stretch
MIN_STRETCH_S = 0.5      # s: shorter airborne stretches are dropped
RANGE_GAP_S = 0.25       # s: a range older than this does not give the altitude
MOTOR_ON_MARGIN = 1.0    # P units above the dead zone h2 for a motor to count as running
# Logs of other vehicles (docs/real-flights.md): a motor runs above IDLE_P (sim/logs/columns.py); without a
# height above the ground, airborne needs the mean command at least THROTTLE_SHARE of its median while all
# four run (a vehicle on the ground idles far below it).
THROTTLE_SHARE = 0.5
# Without a height, the take-off and the landing: a vehicle can leave the ground only when its thrust is
# near its weight (in ground effect, 1 / (1 - (R / 4z)^2) <= 4/3 at z >= R/2, it needs 3/4 of it), which
# with f = h1 (P - h2)^2 and h2 >= 0 is a mean command of at least sqrt(3/4) = 0.87 of the hover's; and
# a slow take-off sits on its legs, thrust rising under an accelerometer that does not move, until
# nearly the hover's (px4/quadrotor_local.ulg: 10 s of ramp, off the ground at 0.9 of it). The rows
# before the mean command (averaged over SMOOTH_S) first reaches HOVER_SHARE of its median, and after it
# last does, are taken as on the ground: a second of flight lost at either end costs little; ground
# taken for flight, a thrust that moves nothing, leaves no effectiveness to identify.
HOVER_SHARE = 0.9
SMOOTH_S = 0.5
# A rotor's thrust is along the body's +z only, and a multirotor's drag is a small part of its weight at
# the speeds it flies: clear of the ground, the specific force along the body's z (the accelerometer's
# acc_z, z up) is the rotors' thrust over the mass, not below zero. Averaged over SMOOTH_S, one below
# zero is a contact force: the vehicle on its side (0) or its back (-g) with its motors running, as
# after a crash (tests/data/ardupilot/log171.bin: 14 s on its back at full command), not flight.
CONTACT_ACC_Z = 0.0
# On the ground the vehicle is held still whatever its motors do (a slow take-off's ramp, a vehicle
# stuck or tied down, one on its legs at full command): its gyro, averaged over SMOOTH_S, does not move
# by REST_RATE in REST_S and its specific force, so averaged, stays at g (within REST_G of it) and does
# not move by REST_ACC. Measured (docs/real-flights.md): px4/quadrotor_local.ulg on its legs while its
# motors ramp to 0.9 of the hover's command for 5 s moves 0.0012 rad/s and 0.022 m/s^2 at most; in the air
# no row of the shared logs or tests/data/ardupilot/log171.bin stays within both for REST_S (the steadiest
# hover's 5th percentile: 0.043 rad/s, 0.068 m/s^2).
# The gyro is weighed with the specific force: motors spinning on the ground shake the accelerometer
# more than the gyro (a Betaflight 4.4 quad on the ground with its motors up: the gyro moving under
# 0.0015 rad/s, a seventh of REST_RATE, the specific force 0.06-0.11 m/s^2), so a specific force moving
# past REST_ACC still says rest when the gyro moves less in proportion: gyro share (of REST_RATE) times
# specific force share (of REST_ACC, at least 1) below 1, the specific force at most REST_ACC_MAX. The
# air, whose gyro moves 0.043 rad/s or more, is never within it.
REST_S = 1.0
REST_RATE = 0.01         # rad/s
REST_ACC = 0.05          # m/s^2
REST_ACC_MAX = 0.25      # m/s^2: the gyro then under REST_RATE REST_ACC / REST_ACC_MAX = 0.002 rad/s
REST_G = 0.1             # share of g
# A barometer is too coarse to time a take-off (its noise and the rotors' wash move it by a few tenths
# of a metre), but one that never rose this far above its level at rest while the motors ran says that
# the vehicle may never have left the ground: said beside a refusal (basemodel._shown), never a verdict.
BARO_CLIMB_M = 0.5
# The autopilots' landing detectors hold their checks this long before they declare a landing: PX4's LNDMC_TRIG_TIME
# (default 1.0 s, its parameter reference), ArduCopter's LAND_DETECTOR_TRIGGER_SEC (1.0 s, ArduCopter/config.h)
LANDED_LAG_S = 1.0
HEIGHT_SOURCES = ("mocap", "rangefinder")   # heights good to a few cm: they also give the airborne test
FILTER_KINDS = ("pt1", "pt2", "pt3", "biquad")


@dataclass(frozen=True)
class Layout:
    """Where the rotors are and how they spin: positions in the body frame (x forward, y left; m, or
    arm lengths when the log gives no length) and the spin seen from above, +1 counter-clockwise and
    -1 clockwise (docs/measured-data.md's s_i); a rotor's reaction torque on the body is -s_i tau_i."""
    x: tuple[float, ...]
    y: tuple[float, ...]
    spin: tuple[float, ...]
    unit: str = "m"
    source: str = "docs/conventions.md"

    @classmethod
    def plus(cls, l: float) -> "Layout":
        """The paper's "+" layout (conventions.md, eq. 25): motor 1 North, 2 West, 3 South, 4 East;
        1 and 3 clockwise."""
        return cls((l, 0.0, -l, 0.0), (0.0, l, 0.0, -l), (-1.0, 1.0, -1.0, 1.0), "m",
                   "docs/conventions.md (the paper's + layout, eq. 25)")

    @classmethod
    def parse(cls, text: str, source: str, fail) -> "Layout":
        """`x1 y1 s1; x2 y2 s2; ...` (a log's `# rotors:` line, in arm lengths): MIN_ROTORS to MAX_ROTORS
        rotors (sim/logs/frames.py's layouts), half of them each way."""
        rotors = [r.split() for r in text.split(";") if r.strip()]
        if not MIN_ROTORS <= len(rotors) <= MAX_ROTORS:
            fail(f"# rotors: {len(rotors)} rotors; diagnose knows multirotors of {MIN_ROTORS} to {MAX_ROTORS}")
        try:
            x, y, s = (tuple(float(r[k]) for r in rotors) for k in range(3))
        except (ValueError, IndexError):
            fail(f"# rotors: {text!r} is not 'x y spin' for each rotor")
        if any(v not in (-1.0, 1.0) for v in s) or sum(s) != 0:
            fail(f"# rotors: spins {s}: each is +1 or -1, as many of each")
        if not all(math.isfinite(v) and abs(v) <= 10 for v in x + y):
            fail(f"# rotors: positions {x}, {y} are not arm lengths")
        return cls(x, y, s, "arm", source)


def parse_filters(text: str, fail) -> tuple[tuple[str, float], ...]:
    """A `# gyro_filter:` line: `none`, or `KIND HZ; KIND HZ` with KIND in FILTER_KINDS."""
    text = text.strip()
    if text in ("", "none"):
        return ()
    out = []
    for item in text.split(";"):
        parts = item.split()
        try:
            kind, hz = parts[0], float(parts[1])
        except (IndexError, ValueError):
            kind, hz = "", math.nan
        if kind not in FILTER_KINDS or not (0.0 < hz < 1e5) or len(parts) != 2:
            fail(f"filter {item.strip()!r}: expected one of {', '.join(FILTER_KINDS)} and a cut-off in Hz")
        out.append((kind, hz))
    return tuple(out)


@dataclass
class FileData:
    """One flight log reduced to what the fits need, every array over rows of the file."""
    path: str
    t: np.ndarray
    P: np.ndarray           # (4, n) commands
    gyro: np.ndarray        # (3, n)
    acc: np.ndarray         # (3, n)
    battery_v: np.ndarray   # (n,), NaN where unknown
    z: np.ndarray           # (n,) altitude above the ground, NaN where unknown
    Rm: np.ndarray          # (9, n) attitude from the integrated gyro (the logged attitude without an IMU)
    airborne: np.ndarray    # (n,) bool, for input rows k whose pair (k, k+1) is usable
    running: np.ndarray     # (n,) bool, every motor running
    layout: Layout
    foreign: bool = False   # a log of another vehicle (its `# vehicle: foreign`): the base model is identified
    gyro_filter: tuple = ()  # the causal filters between the sensor and the logged gyro (parse_filters)
    acc_filter: tuple = ()
    omega: np.ndarray | None = None   # (N, n) each motor's measured speed (rad/s) when logged
    battery_cells: int | None = None  # the pack's cell count when the log says it (`# battery_cells:`)
    notes: list[str] = field(default_factory=list)
    baro_climb: float | None = None   # m: how far a coarse height (a barometer) rose while the motors ran
    imu: bool = True                  # False: no gyro or accelerometer logged (`# imu: none ...`; NaN above)
    rates: np.ndarray | None = None   # (3, n) body rates: the gyro, or without one the attitude's (`attitude_rates`)
    height: np.ndarray | None = None  # (n,) a logged height above its level at rest (any source), NaN where unknown
    accel: bool = True                # False: no accelerometer (its columns absent, NaN or all zero: `has_accelerometer`)


def attitude_rates(t: np.ndarray, att: np.ndarray) -> np.ndarray:
    """(3, n) body rates p, q, r from logged Z-Y-X Euler angles (3, n: roll, pitch, yaw, rad) by their
    central differences, through the inverse of `model.euler_rates` (eq. 7's Z-Y-X Euler-angle kinematics): p = phi' -
    psi' sin(theta), q = theta' cos(phi) + psi' sin(phi) cos(theta), r = psi' cos(phi) cos(theta) - theta'
    sin(phi). At a 10 Hz attitude they are the rates averaged over 0.2 s: enough to tell a vehicle
    holding its attitude from one turning, not to follow the loop."""
    phi, theta, psi = att[0], att[1], np.unwrap(att[2])
    d_phi, d_theta, d_psi = (np.gradient(a, t) for a in (phi, theta, psi))
    sf, cf, st, ct = np.sin(phi), np.cos(phi), np.sin(theta), np.cos(theta)
    return np.vstack([d_phi - d_psi * st, d_theta * cf + d_psi * sf * ct, d_psi * cf * ct - d_theta * sf])


def _rotations(t, gyro, R0):
    """Integrate the gyro (body rates) into body-to-inertial rotations: R_{k+1} = R_k exp([w_k dt]x)."""
    n = t.size
    out = np.empty((9, n))
    r = [float(v) for v in R0.ravel()]
    dts = np.diff(t, append=t[-1])
    gx, gy, gz = gyro.tolist()
    dl = dts.tolist()
    o0, o1, o2, o3, o4, o5, o6, o7, o8 = ([0.0] * n for _ in range(9))
    cols = (o0, o1, o2, o3, o4, o5, o6, o7, o8)
    for k in range(n):
        for j in range(9):
            cols[j][k] = r[j]
        wx, wy, wz = gx[k] * dl[k], gy[k] * dl[k], gz[k] * dl[k]
        a2 = wx * wx + wy * wy + wz * wz
        if a2 < 1e-8:
            s, c = 1.0 - a2 / 6.0, 0.5 - a2 / 24.0
        else:
            a = math.sqrt(a2)
            s, c = math.sin(a) / a, (1.0 - math.cos(a)) / a2
        # Rodrigues: E = I + s W + c W^2, W = [w]x
        e00 = 1.0 - c * (wy * wy + wz * wz)
        e11 = 1.0 - c * (wx * wx + wz * wz)
        e22 = 1.0 - c * (wx * wx + wy * wy)
        e01 = -s * wz + c * wx * wy
        e10 = s * wz + c * wx * wy
        e02 = s * wy + c * wx * wz
        e20 = -s * wy + c * wx * wz
        e12 = -s * wx + c * wy * wz
        e21 = s * wx + c * wy * wz
        r = [r[0] * e00 + r[1] * e10 + r[2] * e20, r[0] * e01 + r[1] * e11 + r[2] * e21,
             r[0] * e02 + r[1] * e12 + r[2] * e22,
             r[3] * e00 + r[4] * e10 + r[5] * e20, r[3] * e01 + r[4] * e11 + r[5] * e21,
             r[3] * e02 + r[4] * e12 + r[5] * e22,
             r[6] * e00 + r[7] * e10 + r[8] * e20, r[6] * e01 + r[7] * e11 + r[8] * e21,
             r[6] * e02 + r[7] * e12 + r[8] * e22]
    for j in range(9):
        out[j] = cols[j]
    return out


def _tilt_rotation(acc_mean):
    """R = Ry(theta) Rx(phi) from the accelerometer at rest (eq. 30-31), yaw 0."""
    ax, ay, az = acc_mean
    phi, theta = math.atan2(ay, az), math.atan2(-ax, math.hypot(ay, az))
    cf, sf, ct, st = math.cos(phi), math.sin(phi), math.cos(theta), math.sin(theta)
    return np.array([[ct, st * sf, st * cf], [0.0, cf, -sf], [-st, ct * sf, ct * cf]])


def stretches(mask):
    """(start, stop) index pairs of the runs of True in a boolean array."""
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1)))


def motors_on(P: np.ndarray, a: Airframe) -> np.ndarray:
    """(n,) bool: some motor runs above its dead zone (eq. 26) on that row."""
    return (P > a.h2 + MOTOR_ON_MARGIN).any(axis=0)


def _check_columns(table: Table, P: np.ndarray, low: float, what: str) -> None:
    """Refuse what would give a confident verdict from no measurement: a log too short or idle to hold
    a flight (its motors ran for less than MIN_AIRBORNE_S: said first, since a sensor at rest can read
    one quantum on every row of a short snippet - Betaflight's gyro in whole deg/s - which is no dead
    sensor), a sensor column that never changes (a dead or unlogged sensor; a real IMU in flight always
    reads noise), and a motor whose command never leaves its lowest range while the others fly (the
    quadcopter cannot fly so: not logged)."""
    t = table["t"]
    dt = np.diff(t, append=t[-1])
    ran = float(dt[(P > low).any(axis=0)].sum())
    span = float(t[-1] - t[0])
    if ran == 0.0:
        table.fail(f"too short to judge: idle, no motor ran in its {span:.2g} s (every command at most {P.max():g}, "
                   f"{what}): no airborne data")
    if ran < MIN_AIRBORNE_S:
        table.fail(f"too short to judge: its motors ran for {ran:.2g} s ({what}), idle for the rest of its {span:.2g} s; "
                   f"at least {MIN_AIRBORNE_S:g} s of airborne data is needed")
    absent = () if has_accelerometer(np.vstack([table[c] for c in IMU_COLUMNS[3:]])) else IMU_COLUMNS[3:]
    for name in IMU_COLUMNS:
        x = table[name]
        if np.ptp(x) == 0 and name not in absent:     # (no accelerometer at all is judged on the gyro)
            table.fail(f"{x[0]:g} on every row: a dead or unlogged sensor cannot be judged", column=name)
    running = P > low
    for i in np.flatnonzero(~running.any(axis=1)):
        others = float(dt[np.delete(running, i, axis=0).all(axis=0)].sum())
        if others >= MIN_AIRBORNE_S:       # less is no flight: too short to judge, whatever the motor
            table.fail(f"motor {i + 1} never runs (P at most {P[i].max():g}, {what}) while the others ran "
                       f"for {others:.1f} s: a quadrotor cannot fly so; its command was not logged",
                       column=f"P{i + 1}")


def _levelled_range(t, rng, Rm):
    """The altitude from a downward range (along -z_b, levelled by cos(phi) cos(theta)), interpolated
    between readings and NaN across gaps longer than RANGE_GAP_S."""
    n = t.size
    have = np.isfinite(rng)
    z = np.full(n, np.nan)
    if have.sum() >= 2:
        tr = t[have]
        z = np.interp(t, tr, rng[have] * Rm[8, have])
        idx = np.clip(np.searchsorted(tr, t), 1, tr.size - 1)
        gap = np.minimum(np.abs(t - tr[idx - 1]), np.abs(tr[idx] - t))
        z[gap > RANGE_GAP_S] = np.nan
    return z


def at_rest(t: np.ndarray, gyro: np.ndarray, acc: np.ndarray) -> np.ndarray:
    """(n,) bool: the rows where the IMU says the vehicle is held still (on the ground, REST_S): the gyro
    (3, n) averaged over SMOOTH_S moves by less than REST_RATE on every axis within REST_S around the
    row, and the specific force's magnitude (acc, 3, n) so averaged stays within REST_G g of g and moves
    by less than REST_ACC, or up to REST_ACC_MAX where the gyro moves less in proportion (the gyro
    weighed with the specific force: their shares' product below 1). A vehicle in the air is never so
    still: the loop moves it all the time."""
    from scipy.ndimage import maximum_filter1d, minimum_filter1d
    if t.size < 2:
        return np.zeros(t.size, bool)
    width = max(1, int(round(REST_S / float(np.median(np.diff(t))))))

    def moved(x):
        m = _smoothed(t, x)
        return maximum_filter1d(m, width, mode="nearest") - minimum_filter1d(m, width, mode="nearest")

    rate = np.max([moved(gyro[k]) for k in range(3)], axis=0) / REST_RATE
    force = np.sqrt((acc * acc).sum(axis=0))
    shake = moved(force) / REST_ACC
    return ((rate * np.maximum(shake, 1.0) < 1.0) & (shake < REST_ACC_MAX / REST_ACC)
            & (np.abs(_smoothed(t, force) - G) < REST_G * G))


def gravity_at_rest(t: np.ndarray, gyro: np.ndarray, acc: np.ndarray, first_on: int) -> tuple[np.ndarray | None, str]:
    """(the mean specific force (3,) where the vehicle is still before it flies, which rows those are):
    the rows `at_rest` (told by the magnitude of the specific force, whatever its sign or axis) before the
    motors first run, else its first stretch at rest (not a rest after a crash, on its back), else the
    rows before the motors first run whose magnitude is g within REST_G (a vehicle held in a hand); None
    when none has 20 rows."""
    rest = at_rest(t, gyro, acc)
    before = rest.copy()
    before[first_on:] = False
    if before.sum() < 20 and rest.any():
        i0, i1 = stretches(rest)[0]
        before[i0:i1] = True
    if before.sum() >= 20:
        return acc[:, before].mean(axis=1), f"{before.sum() * float(np.median(np.diff(t))):.1f} s at rest"
    before = np.zeros(t.size, bool)
    before[:first_on] = np.abs(np.sqrt((acc[:, :first_on] ** 2).sum(axis=0)) - G) < REST_G * G
    if before.sum() >= 20:
        return acc[:, before].mean(axis=1), f"{before.sum()} rows before the motors start"
    return None, ""


def _accelerometer_frame(table: Table, t, gyro, acc, first_on: int, notes: list[str]) -> np.ndarray:
    """The accelerometer of a foreign log checked against gravity's direction when still (eq. 30-31: at
    rest the specific force is +g along the body's z, z up, on a level vehicle): within 45 degrees of +z
    it is taken as logged; within 45 degrees of -z its z is reversed (an accelerometer logged z down:
    the rest tells the sign of z alone, x and y are kept as logged), said in a note; along x or y the log
    is refused, its accelerometer not in the body frame. Without a rest (none still, none before the
    motors) it is taken as logged, said."""
    g, where = gravity_at_rest(t, gyro, acc, first_on)
    if g is None:
        notes.append("the accelerometer's frame not checked: no rest in the log (no row still, none before the "
                     "motors start)")
        return acc
    up = float(g[2] / np.linalg.norm(g))
    if up >= math.sqrt(0.5):
        return acc
    found = f"the mean specific force {', '.join(f'{v:.2f}' for v in g)} m/s^2 (x, y, z) over {where}"
    if up <= -math.sqrt(0.5):
        notes.append(f"the accelerometer reads gravity's -z when still ({found}): its z taken as reversed "
                     "(logged z down); x and y as logged")
        out = acc.copy()
        out[2] = -acc[2]
        return out
    table.fail(f"the accelerometer is not in the body frame: {found}, {math.degrees(math.acos(max(-1.0, min(1.0, up)))):.0f} "
               "deg from +z, where a vehicle at rest reads g", column="acc_z")


def _foreign(table: Table, P: np.ndarray, Rm: np.ndarray, gyro: np.ndarray, acc: np.ndarray, notes: list[str],
             imu: bool = True):
    """A log of another vehicle (docs/real-flights.md): its rotor layout from the metadata, its height
    above the ground (a precise logged height, else a downward range levelled), and its airborne rows:
    all four motors running, the mean command at least THROTTLE_SHARE of its median while they run,
    above Z_AIRBORNE when the height is known, not on its side or back (`acc_z`, the body-z specific
    force, averaged over SMOOTH_S at least CONTACT_ACC_Z), and not held still (`at_rest`: on the ground
    whatever the motors do). Without an IMU (`imu` False) neither of the last two can be asked: the
    ground is told by a logged height instead (`_off_the_ground`)."""
    acc_z = acc[2]
    meta = table.meta
    if "rotors" not in meta:
        table.fail("# vehicle: foreign without a '# rotors:' line: the rotor layout is unknown")
    layout = Layout.parse(meta["rotors"], meta.get("rotors_source", "the log's '# rotors:' line"), table.fail)
    if len(layout.x) != P.shape[0]:
        table.fail(f"# rotors: {len(layout.x)} rotors, but the log has the commands of {P.shape[0]} motors "
                   f"({', '.join(motor_columns(table))})")
    running = all_running(P)
    if "height" in table and meta.get("height_source", "") in HEIGHT_SOURCES and np.isfinite(table["height"]).any():
        h = table["height"]
        z = h - np.nanpercentile(h, 1)
    else:
        z = _levelled_range(table["t"], table["range"], Rm)
    mean_p = P.mean(axis=0)
    rest = at_rest(table["t"], gyro, acc) if imu else np.zeros(P.shape[1], bool)
    dt = float(np.median(np.diff(table["t"])))
    if (running & rest).any():
        notes.append(f"{(running & rest).sum() * dt:.1f} s with the motors running and the IMU held still (the gyro, "
                     f"averaged over {SMOOTH_S:g} s, moving less than {REST_RATE:g} rad/s in {REST_S:g} s and the specific "
                     f"force at g within {REST_ACC:g} m/s^2, or within {REST_ACC_MAX:g} m/s^2 with the gyro stiller "
                     "in proportion): on the ground, not airborne")
    flown = running & ~rest
    hover = float(np.median(mean_p[flown])) if flown.any() else 0.0
    high = running & (mean_p >= THROTTLE_SHARE * hover)
    up = high & ~rest
    contact = (_smoothed(table["t"], acc_z) < CONTACT_ACC_Z) if imu else rest
    if (high & contact).any():         # (counted whether or not the IMU is also held still there)
        notes.append(f"{(high & contact).sum() * dt:.1f} s with the motors running and the body-z specific force "
                     f"(acc_z, averaged over {SMOOTH_S:g} s) below {CONTACT_ACC_Z:g} m/s^2, which the rotors cannot "
                     f"give: on its side or its back (a contact force), not airborne")
        up &= ~contact
    if np.isfinite(z).any():
        up &= np.nan_to_num(z, nan=-1.0) > Z_AIRBORNE
    elif up.any():
        up &= _between_take_off_and_landing(table["t"], np.where(contact | rest, 0.0, mean_p), HOVER_SHARE * hover)
        notes.append(f"no precise height: airborne taken as all motors running with the mean command at least "
                     f"{THROTTLE_SHARE:g} of its median, from the first time it reaches {HOVER_SHARE:g} of it "
                     f"(averaged over {SMOOTH_S:g} s: the take-off) to the last (the landing)")
    _landing_detector(table, up, dt, notes)
    omega = None
    baro = None
    height = None
    if "height" in table and np.isfinite(table["height"]).any() and running.any():
        h = table["height"]
        rest = h[:int(np.argmax(running))]
        rest = rest[np.isfinite(rest)]
        flying = h[running & np.isfinite(h)]
        level = (float(np.median(rest)) if rest.size else float(np.percentile(flying, 2)) if flying.size
                 else float(np.nanpercentile(h, 2)))
        height = h - level            # above its level at rest
        if meta.get("height_source", "") not in HEIGHT_SOURCES and flying.size:
            baro = float(np.percentile(flying, 95)) - level
        if not imu and not np.isfinite(z).any():
            up &= _off_the_ground(table["t"], height, up, notes)
    if all(f"omega{i}" in table for i in range(1, P.shape[0] + 1)):      # one speed per motor, as the commands
        omega = np.vstack([table[f"omega{i}"] for i in range(1, P.shape[0] + 1)])
    return layout, up, z, omega, baro, height


def _landing_detector(table: Table, up: np.ndarray, dt: float, notes: list[str]) -> None:
    """The autopilot's own landing detector (`landed`, 1 landed: PX4's vehicle_land_detected, ArduCopter's
    EV NOT_LANDED / LAND_COMPLETE) against the rows taken as airborne, said. It declares a landing after its
    checks have held LANDED_LAG_S, so rows within that (and a row's period: the state is sampled) of its
    flying are not counted against it; airborne rows further from its flying are a disagreement."""
    if "landed" not in table or not np.isfinite(table["landed"]).any():
        return
    t = table["t"]
    landed = np.nan_to_num(table["landed"], nan=0.0) > 0.5
    source = table.meta.get("landed_source", "the log")
    fly_t = t[~landed & np.isfinite(table["landed"])]
    if fly_t.size:
        j = np.clip(np.searchsorted(fly_t, t), 1, max(1, fly_t.size - 1))
        near = np.minimum(np.abs(t - fly_t[j - 1]), np.abs(t - fly_t[np.minimum(j, fly_t.size - 1)])) <= LANDED_LAG_S + dt
    else:
        near = np.zeros(t.size, bool)
    both = up & landed & ~near
    if both.any():
        notes.append(f"the landing detector and the IMU disagree: {both.sum() * dt:.1f} s taken as airborne where the "
                     f"autopilot's landing detector ({source}) says landed, more than {LANDED_LAG_S:g} s from its flying")
    else:
        notes.append(f"the landing detector agrees: {up.sum() * dt:.1f} s taken as airborne, within the "
                     f"{fly_t.size * dt:.1f} s it says flying and its {LANDED_LAG_S:g} s lag ({source})")


def _off_the_ground(t: np.ndarray, height: np.ndarray, up: np.ndarray, notes: list[str]) -> np.ndarray:
    """(n,) bool, for a log without an IMU (no `at_rest`, no contact test): the rows from the first time
    its logged height (above its level at rest, averaged over SMOOTH_S) is BARO_CLIMB_M up to the last
    time it is, within the command's take-off and landing (`up`): a barometer cannot time a take-off to
    the tenth of a second, but a vehicle on its legs, whatever its motors do, does not rise half a metre."""
    h = np.where(np.isfinite(height), height, 0.0)
    high = np.flatnonzero(up & (_smoothed(t, h) >= BARO_CLIMB_M))
    out = np.zeros(t.size, bool)
    if high.size:
        out[high[0]:high[-1] + 1] = True
    notes.append(f"no IMU: the ground is told by the logged height (airborne from the first time it is {BARO_CLIMB_M:g} m "
                 f"above its level at rest, averaged over {SMOOTH_S:g} s, to the last), not by a gyro at rest")
    return out


def _smoothed(t: np.ndarray, x: np.ndarray) -> np.ndarray:
    """x averaged over SMOOTH_S (a centred moving mean of the rows; of all of them in a shorter log)."""
    width = min(t.size, max(1, int(round(SMOOTH_S / float(np.median(np.diff(t))))))) if t.size > 1 else 1
    return np.convolve(np.nan_to_num(x), np.ones(width) / width, mode="same")


def _between_take_off_and_landing(t: np.ndarray, mean_p: np.ndarray, level: float) -> np.ndarray:
    """(n,) bool: the rows from the first time the mean command, averaged over SMOOTH_S, reaches `level`
    to the last time it does (HOVER_SHARE: before and after, the vehicle is taken as on the ground)."""
    n = t.size
    high = np.flatnonzero(_smoothed(t, mean_p) >= level)
    out = np.zeros(n, bool)
    if high.size:
        out[high[0]:high[-1] + 1] = True
    return out


def _cells(table: Table) -> int | None:
    """The pack's cell count of a `# battery_cells:` line (a positive integer), else None."""
    text = table.meta.get("battery_cells", "").strip()
    try:
        n = int(text)
    except ValueError:
        return None
    return n if 1 <= n <= 24 else None


def has_accelerometer(acc: np.ndarray) -> bool:
    """Whether a log's accelerometer columns (3, n) hold a measurement: a Betaflight 3.x racer with the
    accelerometer switched off (`feature -ACC`) logs none, or zeros; a working one never reads exactly zero
    on all three axes throughout (gravity alone is 9.8 m/s^2)."""
    return bool(np.nan_to_num(acc).any())


NO_ACCELEROMETER = ("no accelerometer in the log (its columns absent or zero: switched off on the vehicle): the dynamic "
                    "tier is judged on the gyro and the motors (roll, pitch and yaw effectiveness, the timing, the "
                    "steps); what needs the specific force is not answered (the thrust's effectiveness, the hover's "
                    "share of the full thrust, the drag on the accelerometer, the battery's sag on the thrust)")


def load_file(table: Table, a: Airframe) -> FileData:
    """The arrays of one flight log (already read and checked by `flightctl.logfile`). A log of this
    project's vehicle has the paper's + layout with the arm of `a`; a foreign one (`# vehicle:
    foreign`) says its layout in its metadata. Either may declare its sensor filters."""
    t = table["t"]
    n = t.size
    P = np.vstack([table[c] for c in motor_columns(table)])
    gyro = np.vstack([table[c] for c in ("gyro_x", "gyro_y", "gyro_z")])
    acc = np.vstack([table[c] for c in ("acc_x", "acc_y", "acc_z")])
    notes = [f"damaged: {table.meta['damaged']}"] if table.meta.get("damaged") else []   # (a reader's `# damaged:`)
    foreign = table.meta.get("vehicle") == "foreign"
    accel = has_accelerometer(acc)
    if not accel:
        acc = np.zeros_like(acc)
        notes.append(NO_ACCELEROMETER)
    gyro_filter, acc_filter = (parse_filters(table.meta.get(k, "none"), lambda w, k=k: table.fail(f"# {k}: {w}"))
                               for k in ("gyro_filter", "acc_filter"))
    if foreign:
        _check_columns(table, P, IDLE_P, "1 % of the command range")
        on = all_running(P)
    else:
        _check_columns(table, P, a.h2 + MOTOR_ON_MARGIN, f"its dead zone h2 = {a.h2:g}")
        on = motors_on(P, a)
    # at rest before the first take-off: the initial tilt
    first_on = int(np.argmax(on)) if on.any() else n
    if foreign and accel:
        acc = _accelerometer_frame(table, t, gyro, acc, first_on, notes)
    still = slice(0, first_on)
    imu = not np.isnan(gyro).all()
    if not imu:        # no IMU (`# imu: none`): the attitude the autopilot logged, its rates for the gyro's
        Rm, rates = _logged_attitude(table)
    elif first_on >= 20 and accel:
        # the gyro is calibrated by contract (bias removed): only the initial tilt is taken here
        R0 = _tilt_rotation(acc[:, still].mean(axis=1))
    else:
        notes.append("no rest before the motors start: initial tilt taken as zero" if accel
                     else "no accelerometer: the initial tilt taken as zero")
        R0 = np.eye(3)
    if imu:   # attitude: the gyro integrated from the first motor start (at rest before it: R0)
        rates = gyro
        Rm = np.empty((9, n))
        Rm[:, :first_on] = R0.reshape(9, 1)
        if first_on < n:
            Rm[:, first_on:] = _rotations(t[first_on:], gyro[:, first_on:], R0)
    bv = table["battery_v"].copy()
    if np.isfinite(bv).sum() >= 2:
        ok = np.isfinite(bv)
        bv = np.interp(t, t[ok], bv[ok])
    if foreign:
        layout, up, z, omega, baro, height = _foreign(table, P, Rm, gyro, acc, notes, imu)
    else:
        layout, omega, baro, height = Layout.plus(a.l), None, None, None
        z = _levelled_range(t, table["range"], Rm)
        if np.isfinite(z).any():
            up = on & (np.nan_to_num(z, nan=-1.0) > Z_AIRBORNE)
        else:
            notes.append("no range readings: airborne taken as motors running with thrust above 90 % of the weight")
            f = thrust_from_command(P, a.h1, a.h2).sum(axis=0)
            up = on & (f > 0.9 * a.M * a.g)
    # a usable input row k needs rows k and k+1 airborne; trim the stretch edges; drop short ones
    pair = np.zeros(n, bool)
    pair[:-1] = up[:-1] & up[1:]
    dt_nom = float(np.median(np.diff(t)))
    edge = int(round(EDGE_S / dt_nom))
    keep = np.zeros(n, bool)
    for i0, i1 in stretches(pair):
        i0, i1 = i0 + edge, i1 - edge
        if (i1 - i0) * dt_nom >= MIN_STRETCH_S:
            keep[i0:i1] = True
    return FileData(table.path, t, P, gyro, acc, bv, z, Rm, keep, on, layout, foreign, gyro_filter, acc_filter,
                    omega, _cells(table), notes, baro, imu, rates, height, accel)


def _logged_attitude(table: Table) -> tuple[np.ndarray, np.ndarray]:
    """(Rm (9, n), body rates (3, n)) of a log without an IMU from its logged attitude (roll, pitch, yaw:
    the autopilot's estimate; `attitude_rates`); a log with neither is refused."""
    if not all(c in table and np.isfinite(table[c]).all() for c in ("roll", "pitch", "yaw")):
        table.fail("no gyro or accelerometer and no attitude on every row: nothing says how the vehicle moved")
    att = np.vstack([table["roll"], table["pitch"], table["yaw"]])
    return np.vstack(rotation(att[0], att[1], att[2])), attitude_rates(table["t"], att)
