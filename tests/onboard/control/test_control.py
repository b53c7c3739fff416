"""PID (eq. 24), mixer (eq. 25, Table 3, eq. 26 inverted), estimator (eq. 30-39, Table 5) and the
flight controller's sign conventions, against values worked out by hand here."""
import math

import numpy as np
import pytest

from flightctl.control.controller import FlightController
from flightctl.control.estimator import AttitudeEstimator, Calibration, heading_from_mag, tilt_from_accel
from flightctl.control.mixer import Mixer
from flightctl.control.pid import Pid, wrap
from flightctl.hal import PWM_RANGE, ImuSample
from flightctl.params import Airframe, Filters, Params
from flightctl.sim.world.model import Model
from helpers.hand import R_hand

M, G, L = 1.645, 9.80665, 0.2475
H1, H2 = 1.49e-3, 120.0
B = M * G / 4                          # 4.0330 N
DT = 1 / 450
EARTH = np.array([20e-6, 0.0, -40e-6])  # N, W, Up
ALPHA_EMA = 1 - math.exp(-1 / 128)
ALPHA_RP, ALPHA_YAW = 128 / 129, 64 / 65


def counts_of(f):
    """eq. 26 inverted, then P (0..255) -> counts on 0..40000 (conventions.md)."""
    return round((H2 + math.sqrt(f / H1)) / 255 * 40000)


def sample(acc=(0.0, 0.0, G), gyro=(0.0, 0.0, 0.0), mag=None):
    s = ImuSample()
    s.ax, s.ay, s.az = acc
    s.gx, s.gy, s.gz = gyro
    if mag is not None:
        s.mx, s.my, s.mz = mag
        s.mag_fresh = True
    return s


def still_sample(phi, theta, psi, gyro=(0.0, 0.0, 0.0)):
    """What a perfect IMU reads at rest at this attitude: specific force R^T (0,0,g), field R^T B."""
    Rt = R_hand(phi, theta, psi).T
    return sample(tuple(Rt @ [0, 0, G]), gyro, tuple(Rt @ EARTH))


# --- PID -------------------------------------------------------------------------------------------

def test_pid_eq24_by_hand():
    pid = Pid(kp=2.0, ki=0.5, kd=0.3, limit=10.0)
    # e = 0.8, integral = 0.5 * 0.8 * 0.01, u = kp e - kd dy + integral
    assert pid.update(1.0, 0.2, 0.4, 0.01) == pytest.approx(2 * 0.8 - 0.3 * 0.4 + 0.5 * 0.8 * 0.01)
    # e = 0.7, integral grows by 0.5 * 0.7 * 0.02
    assert pid.update(1.0, 0.3, -0.1, 0.02) == pytest.approx(2 * 0.7 + 0.3 * 0.1 + 0.004 + 0.007)
    assert pid.integral == pytest.approx(0.011)
    pid.reset()
    assert pid.integral == 0.0


def test_pid_derivative_on_measurement_no_kick():
    # a setpoint step changes u by kp * step only: the D term sees dy, not de
    a = Pid(1.5, 0.0, 4.0, 100.0)
    b = Pid(1.5, 0.0, 4.0, 100.0)
    ua = a.update(0.0, 0.1, 0.2, DT)
    ub = b.update(1.0, 0.1, 0.2, DT)
    assert ua == pytest.approx(1.5 * -0.1 - 4.0 * 0.2)
    assert ub - ua == pytest.approx(1.5 * 1.0)


def test_pid_output_limit():
    pid = Pid(100.0, 0.0, 0.0, limit=B)
    assert pid.update(1.0, 0.0, 0.0, DT) == B
    assert pid.update(-1.0, 0.0, 0.0, DT) == -B
    assert pid.update(0.01, 0.0, 0.0, DT) == pytest.approx(1.0)


def test_pid_integral_clamped_anti_windup():
    pid = Pid(0.0, 1.0, 0.0, limit=2.0)
    for _ in range(10):                     # would wind up to 10 without the clamp
        u = pid.update(1.0, 0.0, 0.0, 1.0)
    assert u == 2.0 and pid.integral == 2.0
    # the error reverses: the output leaves the limit at once (2 - 0.5), not after unwinding 8
    assert pid.update(-0.5, 0.0, 0.0, 1.0) == pytest.approx(1.5)
    for _ in range(10):
        pid.update(-1.0, 0.0, 0.0, 1.0)
    assert pid.integral == -2.0


def test_pid_angle_wrap():
    pid = Pid(1.0, 0.0, 0.0, limit=10.0, angle=True)
    # 3.1 - (-3.1) = 6.2 rad is really -0.083 rad the short way round
    assert pid.update(3.1, -3.1, 0.0, DT) == pytest.approx(6.2 - 2 * math.pi)
    assert pid.update(-3.1, 3.1, 0.0, DT) == pytest.approx(2 * math.pi - 6.2)
    assert pid.update(0.5, 0.2, 0.0, DT) == pytest.approx(0.3)
    plain = Pid(1.0, 0.0, 0.0, limit=10.0)
    assert plain.update(3.1, -3.1, 0.0, DT) == pytest.approx(6.2)


def test_wrap():
    assert wrap(0.0) == 0.0
    assert wrap(math.pi) == pytest.approx(-math.pi)          # [-pi, pi)
    assert wrap(-math.pi) == pytest.approx(-math.pi)
    assert wrap(1.5 * math.pi) == pytest.approx(-0.5 * math.pi)
    assert wrap(-1.5 * math.pi) == pytest.approx(0.5 * math.pi)
    assert wrap(7.0) == pytest.approx(7.0 - 2 * math.pi)
    assert wrap(-20.0) == pytest.approx(-20.0 + 6 * math.pi)


# --- mixer -----------------------------------------------------------------------------------------

def test_mixer_level_hover():
    mx = Mixer(Airframe())
    c = [0, 0, 0, 0]
    mx.mix(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, c)
    assert mx.f == pytest.approx([B] * 4, rel=1e-12)
    # P = 120 + sqrt(4.033 / 1.49e-3) = 172.03 -> 26985 counts
    assert c == [counts_of(B)] * 4
    assert c[0] == round((120 + math.sqrt(M * G / 4 / 1.49e-3)) * 40000 / 255)
    assert all(type(v) is int for v in c)


def test_mixer_eq25_by_hand():
    mx = Mixer(Airframe())
    c = [0, 0, 0, 0]
    uz, up, ut, uy, roll, pitch = 0.5, 0.3, -0.2, 0.1, 0.1, -0.2
    mx.mix(uz, up, ut, uy, roll, pitch, c)
    base = B + 0.5 / (math.cos(0.1) * math.cos(-0.2))
    want = [base + 0.2 + 0.1, base + 0.3 - 0.1, base - 0.2 + 0.1, base - 0.3 - 0.1]
    assert mx.f == pytest.approx(want, rel=1e-12)
    assert c == [counts_of(f) for f in want]


def test_mixer_table3_limits():
    mx = Mixer(Airframe())
    c = [0, 0, 0, 0]
    # f2 = B + B + B = 3B -> 2B; f4 = B + B - B = B; f1 = f3 = 2B
    mx.mix(B, B, 0.0, 0.0, 0.0, 0.0, c)
    assert mx.f == pytest.approx([2 * B, 2 * B, 2 * B, B])
    assert c[1] == round((120 + math.sqrt(2 * B / 1.49e-3)) * 40000 / 255)   # P = 193.57
    # f1 = 0 - B -> 0, P = h2: 120 / 255 * 40000 = 18823.5 -> 18824
    mx.mix(-B, 0.0, B, 0.0, 0.0, 0.0, c)
    assert mx.f == pytest.approx([0.0, 0.0, B, 0.0])
    assert c[0] == 18824 and c[1] == 18824 and c[3] == 18824
    for f in mx.f:
        assert 0.0 <= f <= 2 * B


def test_mixer_tilt_correction_held_beyond_60_degrees():
    mx = Mixer(Airframe())
    c = [0, 0, 0, 0]
    mx.mix(0.4, 0.0, 0.0, 0.0, 1.2, 0.0, c)          # cos 1.2 = 0.36 < 0.5
    assert mx.f == pytest.approx([B + 0.4 / 0.5] * 4)
    mx.mix(0.4, 0.0, 0.0, 0.0, 0.5, 0.5, c)          # cos^2 0.5 = 0.77
    assert mx.f == pytest.approx([B + 0.4 / math.cos(0.5) ** 2] * 4)



def test_mixer_never_commands_beyond_the_escs_range():
    """A heavy airframe's 2B maps past P = 255 through eq. 26: the counts stop at the range's end."""
    heavy = Airframe(M=50.0)
    mx = Mixer(heavy)
    c = [0, 0, 0, 0]
    mx.mix(heavy.B, 0.0, 0.0, 0.0, 0.0, 0.0, c)      # full thrust asked
    assert all(count == PWM_RANGE for count in c)
    mx.mix(-heavy.B, 0.0, 0.0, 0.0, 0.0, 0.0, c)
    assert all(0 <= count < PWM_RANGE for count in c)


# --- estimator -------------------------------------------------------------------------------------

@pytest.mark.parametrize("phi,theta", [(0.0, 0.0), (0.3, -0.2), (-0.5, 0.4), (2.5, 0.1)])
def test_tilt_from_accel_eq30_31(phi, theta):
    # at rest the accelerometer reads R^T (0, 0, g) = g (-sin th, cos th sin phi, cos th cos phi)
    ax, ay, az = -G * math.sin(theta), G * math.cos(theta) * math.sin(phi), G * math.cos(theta) * math.cos(phi)
    assert tilt_from_accel(ax, ay, az) == pytest.approx((phi, theta), abs=1e-12)


@pytest.mark.parametrize("phi,theta,psi", [(0.0, 0.0, 0.0), (0.0, 0.0, 1.0), (0.2, -0.3, 1.0),
                                           (-0.4, 0.3, -2.0), (0.1, 0.1, 3.0), (0.3, 0.2, -3.1)])
def test_heading_from_mag(phi, theta, psi):
    bx, by, bz = R_hand(phi, theta, psi).T @ EARTH
    assert wrap(heading_from_mag(bx, by, bz, phi, theta) - psi) == pytest.approx(0.0, abs=1e-12)


def test_heading_from_mag_level_by_hand():
    # yaw 90 deg, level: the nose points West, North is on the right (-y_b): body field (0, -20e-6, -40e-6)
    assert heading_from_mag(0.0, -20e-6, -40e-6, 0.0, 0.0) == pytest.approx(math.pi / 2)
    assert heading_from_mag(20e-6, 0.0, -40e-6, 0.0, 0.0) == pytest.approx(0.0)


def test_table5_values():
    f = Filters()
    assert f.alpha_ema == pytest.approx(0.007782062, abs=5e-10)
    assert f.alpha_roll_pitch == pytest.approx(0.992248062, abs=5e-10)
    assert f.alpha_yaw == pytest.approx(0.984615385, abs=5e-10)


def test_ema_step_response_eq36_39():
    est = AttitudeEstimator(Filters(), "paper")
    s = sample(gyro=(1.0, -2.0, 0.5))
    est.update(s, DT)
    assert est.p == pytest.approx(ALPHA_EMA * 1.0, rel=1e-12)
    for _ in range(127):
        est.update(s, DT)
    # 128 samples = tau_EMA: 1 - (1 - alpha)^128 = 1 - 1/e = 63.2 %
    assert est.p == pytest.approx(1 - math.exp(-1), rel=1e-9)
    assert est.q == pytest.approx(-2.0 * (1 - math.exp(-1)), rel=1e-9)
    assert est.r == pytest.approx(0.5 * (1 - math.exp(-1)), rel=1e-9)


@pytest.mark.parametrize("structure", ["flight", "paper"])
def test_complementary_filter_time_constant(structure):
    """Accelerometer tilt held at (0.1, -0.05), zero gyro: the estimate approaches it as 1 - alpha^n,
    alpha = 128/129 (tau = alpha dt / (1 - alpha) = 128 dt)."""
    est = AttitudeEstimator(Filters(), structure)
    phi0, th0 = 0.1, -0.05
    s = still_sample(phi0, th0, 0.0)
    s.mag_fresh = False
    for n in range(1, 301):
        est.update(s, DT)
        if n in (1, 10, 128, 300):
            assert est.roll == pytest.approx(phi0 * (1 - ALPHA_RP ** n), rel=1e-9)
            assert est.pitch == pytest.approx(th0 * (1 - ALPHA_RP ** n), rel=1e-9)
    assert ALPHA_RP * DT / (1 - ALPHA_RP) == pytest.approx(128 * DT)


def test_yaw_complementary_filter_with_magnetometer():
    est = AttitudeEstimator(Filters())
    est.set_reference((0.0, 0.0), 0.0, True)
    psi0 = 0.5
    s = still_sample(0.0, 0.0, psi0)
    for n in range(1, 201):
        est.update(s, DT)
        if n in (1, 64, 200):
            assert est.yaw == pytest.approx(psi0 * (1 - ALPHA_YAW ** n), rel=1e-9)


def test_yaw_estimate_crosses_pi_the_short_way():
    est = AttitudeEstimator(Filters())
    est.set_reference((0.0, 0.0), 0.0, True)
    s = still_sample(0.0, 0.0, math.pi - 0.05)
    est.yaw = -math.pi + 0.05       # 0.1 rad away across +-pi
    est.update(s, DT)
    # moves by (1 - alpha_yaw) * (-0.1) from -pi + 0.05, wrapped into [-pi, pi)
    want = wrap(-math.pi + 0.05 - (1 - ALPHA_YAW) * 0.1)
    assert est.yaw == pytest.approx(want, abs=1e-12)
    assert est.yaw < -math.pi + 0.05     # it moved through -pi, not the long way toward 0


def test_flight_structure_corrects_tilt_in_flight_slowly_with_a_pi_filter():
    """In flight the accelerometer pulls the estimate with the PI law of docs/estimator.md:
    both poles at -1/tau_tilt_air, so for a held accelerometer tilt the first step moves the estimate
    by 2 dt / tau of the error, and the bias estimate by dt^2 / tau^2 of it (here the gyro is zero)."""
    s = still_sample(0.1, -0.05, 0.0)
    s.mag_fresh = False
    tau = 8192 / 450.0
    flight = AttitudeEstimator(Filters(tau_tilt_air=tau), "flight")
    paper = AttitudeEstimator(Filters(), "paper")
    flight.in_flight = paper.in_flight = True
    flight.update(s, DT)
    assert flight.roll == pytest.approx(0.1 * 2 * DT / tau, rel=1e-9)
    assert flight.bx == pytest.approx(-0.1 * DT / tau ** 2, rel=1e-9)
    for _ in range(49):
        flight.update(s, DT)
        paper.update(s, DT)
    paper.update(s, DT)
    assert paper.roll == pytest.approx(0.1 * (1 - ALPHA_RP ** 50), rel=1e-9)   # Table 5's 0.284 s
    assert 0.0 < flight.roll < 0.1 * 100 * DT / tau                            # 50 loops: a few %
    # after 3 tau the estimate holds the accelerometer's tilt (critically damped: 1 - 4 e^-3 = 80 %)
    for _ in range(int(3 * tau / DT)):
        flight.update(s, DT)
    assert flight.roll == pytest.approx(0.1, rel=0.25)
    flight.in_flight = False          # back on the ground: Table 5's filter again
    before = flight.roll
    flight.update(s, DT)
    assert flight.roll == pytest.approx(ALPHA_RP * (before + DT * (-flight.bx)) + (1 - ALPHA_RP) * 0.1, rel=1e-6)


def test_flight_structure_learns_a_gyro_bias_in_flight():
    """A constant gyro bias after calibration: the in-flight integral term takes it out, so the
    estimate stays at the accelerometer's level instead of drifting at the bias rate."""
    bias = math.radians(0.5)            # deg/s: a warm-up drift far beyond the datasheet's in-run wander
    s = still_sample(0.0, 0.0, 0.0, gyro=(bias, 0.0, 0.0))
    s.mag_fresh = False
    tau = 8192 / 450.0
    est = AttitudeEstimator(Filters(tau_tilt_air=tau), "flight")
    est.in_flight = True
    for _ in range(int(8 * tau / DT)):
        est.update(s, DT)
    assert est.bx == pytest.approx(bias, rel=0.02)
    assert abs(est.roll) < 0.05 * bias * tau      # a P-only filter would hold bias * tau / 2 off


def test_flight_structure_without_rotor_drag_ignores_the_accelerometer_in_flight():
    s = still_sample(0.1, -0.05, 0.0)
    est = AttitudeEstimator(Filters(), "flight")     # the base model's default: tau_tilt_air = 0
    est.in_flight = True
    for _ in range(50):
        est.update(s, DT)
    assert est.roll == 0.0 and est.pitch == 0.0 and est.bx == 0.0


def test_gyro_propagation_flight_vs_paper():
    s = sample(gyro=(0.5, 0.0, 0.0))
    flight = AttitudeEstimator(Filters(), "flight")
    paper = AttitudeEstimator(Filters(), "paper")
    flight.update(s, DT)
    paper.update(s, DT)
    # flight: the raw rate is integrated and is the D term's measured rate (no EMA in the loop)
    assert flight.roll == pytest.approx(ALPHA_RP * 0.5 * DT, rel=1e-12)
    assert flight.droll == pytest.approx(0.5, rel=1e-12)
    # paper: the EMA-filtered rate is integrated; the D term is the difference quotient of the angle
    assert paper.roll == pytest.approx(ALPHA_RP * ALPHA_EMA * 0.5 * DT, rel=1e-12)
    assert paper.droll == pytest.approx(paper.roll / DT, rel=1e-12)


def test_calibration_removes_gyro_bias_and_tilt_bias():
    bias = (0.01, -0.02, 0.03)
    cal = Calibration()
    for _ in range(100):
        cal.add(still_sample(0.0, 0.0, 0.0, gyro=bias))
    s_acc = sample(acc=(-G * math.sin(-0.01), G * math.cos(-0.01) * math.sin(0.02),
                        G * math.cos(-0.01) * math.cos(0.02)), gyro=bias)
    cal2 = Calibration()
    for _ in range(50):
        cal2.add(s_acc)
    est = AttitudeEstimator(Filters())
    cal2.apply(est)
    assert cal2.gyro_bias == pytest.approx(bias, rel=1e-12)
    assert est.tilt_bias == pytest.approx((0.02, -0.01), abs=1e-12)
    assert est.use_mag is False
    s = sample(acc=(s_acc.ax, s_acc.ay, s_acc.az), gyro=bias)
    cal2.correct(s)
    assert (s.gx, s.gy, s.gz) == pytest.approx((0.0, 0.0, 0.0), abs=1e-15)
    for _ in range(200):             # the accelerometer bias is subtracted before fusion
        est.update(s, DT)
    assert est.roll == pytest.approx(0.0, abs=1e-12)
    assert est.pitch == pytest.approx(0.0, abs=1e-12)
    cal.apply(AttitudeEstimator(Filters()))
    assert cal.gyro_bias == pytest.approx(bias, rel=1e-12)


def test_calibration_heading_reference():
    cal = Calibration()
    for _ in range(20):
        cal.add(still_sample(0.0, 0.0, 0.7))
    est = AttitudeEstimator(Filters())
    cal.apply(est)
    assert est.use_mag is True
    assert est.yaw_bias == pytest.approx(0.7, abs=1e-12)
    for _ in range(100):
        est.update(still_sample(0.0, 0.0, 0.7), DT)
    assert est.yaw == pytest.approx(0.0, abs=1e-12)
    # turned by 0.3 rad: the estimate moves toward 0.3 at the yaw filter's rate
    est.update(still_sample(0.0, 0.0, 1.0), DT)
    assert est.yaw == pytest.approx((1 - ALPHA_YAW) * 0.3, rel=1e-9)


def test_calibration_on_a_tilted_chip_keeps_yaw_at_zero():
    """Sitting still where the chip reads a tilt of (0.03, -0.02) (the tilt bias of section 4.4.4):
    after calibration the estimator, fed the same still samples, must read roll, pitch AND yaw 0."""
    cal = Calibration()
    s = still_sample(0.03, -0.02, 0.7)
    for _ in range(20):
        cal.add(s)
    est = AttitudeEstimator(Filters())
    cal.apply(est)
    for _ in range(500):
        est.update(still_sample(0.03, -0.02, 0.7), DT)
    assert est.roll == pytest.approx(0.0, abs=1e-9)
    assert est.pitch == pytest.approx(0.0, abs=1e-9)
    assert est.yaw == pytest.approx(0.0, abs=1e-3)


def test_calibration_without_samples_refused():
    with pytest.raises(RuntimeError):
        Calibration().apply(AttitudeEstimator(Filters()))


def test_unknown_estimator_structure():
    with pytest.raises(ValueError):
        AttitudeEstimator(Filters(), "kalman")


# --- controller: signs end to end ------------------------------------------------------------------

def controller_step(roll_sp=0.0, pitch_sp=0.0, yaw_sp=0.0):
    ctl = FlightController(Params())
    counts = list(ctl.step(sample(), DT, roll_sp, pitch_sp, yaw_sp, 0.0))
    return ctl, counts


def test_controller_roll_error_drives_f2_over_f4():
    ctl, counts = controller_step(roll_sp=0.1)
    # level estimate, zero rates: u_phi = kp e + ki e dt (Table 6: kp 4.48, ki 0.0045)
    u = 4.48 * 0.1 + 0.0045 * 0.1 * DT
    assert ctl.mixer.f == pytest.approx([B, B + u, B, B - u], rel=1e-12)
    assert counts == [counts_of(B), counts_of(B + u), counts_of(B), counts_of(B - u)]
    assert counts[1] > counts[0] == counts[2] > counts[3]


def test_controller_pitch_error_drives_f3_over_f1():
    ctl, counts = controller_step(pitch_sp=0.1)
    u = 4.12 * 0.1 + 0.0045 * 0.1 * DT
    assert ctl.mixer.f == pytest.approx([B - u, B, B + u, B], rel=1e-12)
    assert counts[2] > counts[1] == counts[3] > counts[0]


def test_controller_yaw_error_drives_clockwise_pair():
    ctl, counts = controller_step(yaw_sp=0.2)
    u = 7.55 * 0.2
    assert ctl.mixer.f == pytest.approx([B + u, B - u, B + u, B - u], rel=1e-12)
    assert counts[0] == counts[2] > counts[1] == counts[3]


@pytest.mark.parametrize("sp,axis", [((0.1, 0, 0), 9), ((0, 0.1, 0), 10), ((0, 0, 0.2), 11)])
def test_controller_counts_turn_the_model_toward_the_setpoint(sp, axis):
    """The full sign chain: a positive setpoint error -> counts -> P -> model -> positive acceleration
    about that axis, and nothing about the others."""
    _, counts = controller_step(*sp)
    u = tuple(c * 255 / 40000 for c in counts) + (16.0,)
    x = [0.0] * 12
    x[2] = 2.0
    xd = Model(Airframe()).f(0.0, x, u)
    assert xd[axis] > 0.5
    for other in {9, 10} - {axis}:
        assert abs(xd[other]) < 1e-3 * xd[axis]


def test_controller_altitude_task():
    ctl = FlightController(Params())
    ctl.step(sample(), DT, 0.0, 0.0, 0.0, 1.5)          # sets the altitude setpoint
    ctl.on_range(0.5, 10.0)
    # first echo: dt is the sonar period 1/45; from alt 0 to 0.5: u_z = kp e - kd dy (Table 6)
    assert ctl.alt == pytest.approx(0.5)
    assert ctl.uz == pytest.approx(2.4 * 1.0 - 0.14 * (0.5 / (1 / 45)))
    ctl.on_range(0.6, 10.03)
    assert ctl.uz == pytest.approx(2.4 * 0.9 - 0.14 * (0.1 / 0.03))
    ctl.on_range(math.nan, 10.06)          # failed echo in the air: the vertical estimate stands in
    z = ctl.vert.z
    assert ctl.alt == z and abs(z - 0.6) > 1e-3
    assert ctl.uz == pytest.approx(min(B, 2.4 * (1.5 - z) - 0.14 * (z - 0.6) / 0.03))
    uz = ctl.uz
    ctl.step(sample(), DT, 0.0, 0.0, 0.0, 1.5)
    assert ctl.mixer.f == pytest.approx([B + uz] * 4, rel=1e-9)
    low = FlightController(Params())
    low.on_range(0.05, 10.0)
    low.on_range(math.nan, 10.03)          # near the floor (a lost echo is the floor's): held
    assert low.alt == pytest.approx(0.05)


def test_controller_altitude_levelled_by_tilt():
    ctl = FlightController(Params())
    ctl.est.roll, ctl.est.pitch = 0.2, -0.1
    ctl.on_range(1.0, 0.0)
    assert ctl.alt == pytest.approx(math.cos(0.2) * math.cos(-0.1))
