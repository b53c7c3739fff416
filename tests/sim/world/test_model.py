"""sim.model, sim.causes (the effects) and sim.plant against values worked out by hand from the paper's equations
(eq. 6-9, 26-28) and conventions.md. Every expected value is written out here from the formulas and
the reference-airframe numbers of conventions.md, never taken from the code under test.
"""
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from flightctl.errors import InputError
from flightctl.params import Airframe
from flightctl.sim import causes as fx
from flightctl.sim.world.model import Model, angular_acceleration, body_torques, rotation
from flightctl.sim.world.plant import Plant

# conventions.md, reference airframe (Table 2 and the plausible propeller defaults)
M, L, G = 1.645, 0.2475, 9.80665
JXX, JYY, JZZ, JP = 0.014002764, 0.014267729, 0.029487252, 2.66838e-4
GAMMA1, GAMMA2 = 4.86291e-4, 1.22958e-3
H1, H2, C1, G1, G2 = 1.49e-3, 120.0, 1.47e-5, 0.020, 0.002
ROTOR_R, V_NOM = 0.1524, 14.8

FH = M * G / 4                      # hover thrust per motor, N
D = math.sqrt(FH / H1)              # P - h2 at hover (eq. 26 inverted)
PH = H2 + D                         # hover command, about 172.03
TAU_H = G1 * FH + G2                # eq. 28 at hover
BATT = 16.0


def hover_u(dP=(0.0, 0.0, 0.0, 0.0), v=BATT):
    return (PH + dP[0], PH + dP[1], PH + dP[2], PH + dP[3], v)


def state(**kw):
    names = ["x", "y", "z", "vx", "vy", "vz", "phi", "theta", "psi", "p", "q", "r"]
    x = [0.0] * 12
    for k, v in kw.items():
        x[names.index(k)] = float(v)
    return x


def Rx(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def Ry(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def Rz(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def R_hand(phi, theta, psi):
    return Rz(psi) @ Ry(theta) @ Rx(phi)


def test_hover_command_is_about_172():
    # conventions.md: h1, h2 give hover at P ~ 172
    assert PH == pytest.approx(172.03, abs=0.01)


def test_body_torques_plus_configuration():
    tp, tt, ty = body_torques(1.0, 2.0, 3.0, 4.0, 0.1, 0.2, 0.3, 0.4, L)
    assert tp == pytest.approx(0.2475 * (2.0 - 4.0))     # l (f2 - f4)
    assert tt == pytest.approx(0.2475 * (3.0 - 1.0))     # l (f3 - f1)
    assert ty == pytest.approx(0.1 - 0.2 + 0.3 - 0.4)    # tau1 - tau2 + tau3 - tau4


def test_body_torques_match_r_cross_f():
    # the conventions.md motor positions, torque = sum r_i x (0, 0, f_i)
    pos = [(L, 0, 0), (0, L, 0), (-L, 0, 0), (0, -L, 0)]
    f = [1.3, 2.9, 3.7, 0.4]
    tau = sum(np.cross(p, (0, 0, fi)) for p, fi in zip(pos, f))
    tp, tt, _ = body_torques(*f, 0, 0, 0, 0, L)
    assert (tp, tt) == pytest.approx((tau[0], tau[1]))
    assert tau[2] == pytest.approx(0.0)


# --- eq. 7 and the errata for eq. 8 ---------------------------------------------------------------

def test_angular_acceleration_eq7_by_hand_with_errata():
    a = Airframe()
    p, q, r = 0.5, -0.7, 1.1
    tp, tt, ty, Om, td = 0.01, -0.02, 0.005, 30.0, 0.001
    dp, dq, dr = angular_acceleration(p, q, r, tp, tt, ty, Om, td, a.Jxx, a.Jyy, a.Jzz, a.Jp)
    # eq. 8 rows, with the q row as corrected in conventions.md
    want_dp = tp / JXX - (JZZ - JYY) / JXX * q * r - JP / JXX * q * Om
    want_dq = tt / JYY - (JXX - JZZ) / JYY * p * r + JP / JYY * p * Om
    want_dr = ty / JZZ - (JYY - JXX) / JZZ * p * q - td / JZZ
    assert dp == pytest.approx(want_dp, rel=1e-12)
    assert dq == pytest.approx(want_dq, rel=1e-12)
    assert dr == pytest.approx(want_dr, rel=1e-12)
    # the q row as printed in eq. 8 (-Jp/Jxx p Omega) is NOT what is implemented
    printed_dq = tt / JYY - (JXX - JZZ) / JYY * p * r - JP / JXX * p * Om
    assert dq - printed_dq == pytest.approx(JP * p * Om * (1 / JYY + 1 / JXX), rel=1e-9)
    assert dq - printed_dq > 0.5


def test_angular_acceleration_matches_vector_form_cross_product():
    a = Airframe()
    J = np.diag([JXX, JYY, JZZ])
    rng = np.random.default_rng(1)
    for _ in range(20):
        w = rng.uniform(-3, 3, 3)
        tau = rng.uniform(-0.5, 0.5, 3)
        Om, td = rng.uniform(-200, 200), rng.uniform(-0.01, 0.01)
        # eq. 7: J dw/dt = tau - w x (J w + Jp Omega z_b) - tau_d z_b
        want = np.linalg.solve(J, tau - np.cross(w, J @ w + JP * Om * np.array([0, 0, 1.0]))
                               - td * np.array([0, 0, 1.0]))
        got = angular_acceleration(*w, *tau, Om, td, a.Jxx, a.Jyy, a.Jzz, a.Jp)
        np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-12)


def test_angular_acceleration_on_arrays():
    a = Airframe()
    p = np.array([0.0, 1.0])
    z = np.zeros(2)
    dp, dq, dr = angular_acceleration(p, z, z, z, z, z, np.array([10.0, 10.0]), z, a.Jxx, a.Jyy, a.Jzz, a.Jp)
    np.testing.assert_allclose(dq, [0.0, JP * 1.0 * 10.0 / JYY])


# --- rotation ------------------------------------------------------------------------------------

@pytest.mark.parametrize("phi,theta,psi", [(0.0, 0.0, 0.0), (0.3, -0.2, 1.0), (-1.2, 0.7, -2.9),
                                           (2.0, 1.4, 3.1)])
def test_rotation_is_rz_ry_rx(phi, theta, psi):
    Rm = np.array(rotation(phi, theta, psi)).reshape(3, 3)
    np.testing.assert_allclose(Rm, R_hand(phi, theta, psi), atol=1e-15)
    np.testing.assert_allclose(Rm @ Rm.T, np.eye(3), atol=1e-14)
    assert np.linalg.det(Rm) == pytest.approx(1.0, abs=1e-14)


def test_rotation_specific_cases():
    def R(*e):
        return np.array(rotation(*e)).reshape(3, 3)
    # yaw 90 deg: the nose (x_b, motor 1) points West (+y inertial)
    np.testing.assert_allclose(R(0, 0, math.pi / 2) @ [1, 0, 0], [0, 1, 0], atol=1e-15)
    # roll 90 deg: the left arm (y_b, motor 2) points up
    np.testing.assert_allclose(R(math.pi / 2, 0, 0) @ [0, 1, 0], [0, 0, 1], atol=1e-15)
    # pitch +90 deg about y_b (West): the nose goes down
    np.testing.assert_allclose(R(0, math.pi / 2, 0) @ [1, 0, 0], [0, 0, -1], atol=1e-15)
    # a small roll tilts the thrust axis toward -y (East): (0, -sin phi, cos phi)
    np.testing.assert_allclose(R(0.1, 0, 0) @ [0, 0, 1], [0, -math.sin(0.1), math.cos(0.1)], atol=1e-15)


def test_rotation_on_arrays():
    phi = np.array([0.0, 0.3])
    th = np.array([0.0, -0.2])
    ps = np.array([0.0, 1.0])
    got = np.array(rotation(phi, th, ps))            # 9 x 2
    np.testing.assert_allclose(got[:, 1], R_hand(0.3, -0.2, 1.0).ravel(), atol=1e-15)
    np.testing.assert_allclose(got[:, 0], np.eye(3).ravel(), atol=1e-15)


# --- Model.f --------------------------------------------------------------------------------------

def test_hover_equilibrium():
    m = Model(Airframe())
    xd = m.f(0.0, state(z=3.0), hover_u())
    assert xd[:3] == [0.0, 0.0, 0.0]
    np.testing.assert_allclose(xd[3:12], 0.0, atol=1e-12)


def test_roll_motor2_more_than_motor4():
    m = Model(Airframe())
    xd = m.f(0.0, state(z=3.0), hover_u((0, +4, 0, -4)))
    # f2 - f4 = h1 ((D + 4)^2 - (D - 4)^2) = 16 h1 D
    f2, f4 = H1 * (D + 4) ** 2, H1 * (D - 4) ** 2
    assert xd[9] == pytest.approx(L * (f2 - f4) / JXX, rel=1e-12)
    assert xd[9] == pytest.approx(L * 16 * H1 * D / JXX, rel=1e-12)
    assert xd[9] > 20.0                  # about 21.9 rad/s^2: positive roll
    assert xd[10] == pytest.approx(0.0, abs=1e-12)
    # the two counter-clockwise rotors now make f2 + f4 = 2 FH + 32 h1: net reaction torque -32 g1 h1
    assert xd[11] == pytest.approx(-32 * G1 * H1 / JZZ, rel=1e-9)
    assert xd[5] == pytest.approx(32 * H1 / M, rel=1e-9)


def test_pitch_motor3_more_than_motor1():
    m = Model(Airframe())
    xd = m.f(0.0, state(z=3.0), hover_u((-4, 0, +4, 0)))
    assert xd[10] == pytest.approx(L * 16 * H1 * D / JYY, rel=1e-12)
    assert xd[10] > 20.0
    assert xd[9] == pytest.approx(0.0, abs=1e-12)
    assert xd[11] == pytest.approx(+32 * G1 * H1 / JZZ, rel=1e-9)


def test_yaw_motors13_more_than_24():
    m = Model(Airframe())
    xd = m.f(0.0, state(z=3.0), hover_u((+4, -4, +4, -4)))
    # tau1 - tau2 + tau3 - tau4 = g1 (f1 + f3 - f2 - f4) = g1 h1 (2 (D+4)^2 - 2 (D-4)^2) = 32 g1 h1 D
    assert xd[11] == pytest.approx(32 * G1 * H1 * D / JZZ, rel=1e-12)
    assert xd[11] > 0.0
    assert xd[9] == pytest.approx(0.0, abs=1e-12)
    assert xd[10] == pytest.approx(0.0, abs=1e-12)


def test_rotor_momentum_sign_eq9():
    """Omega = -w1 + w2 - w3 + w4: with motors 2 and 4 faster, Omega > 0, so a roll rate p gives
    q-dot = +Jp p Omega / Jyy (eq. 7), and a pitch rate q gives p-dot = -Jp q Omega / Jxx."""
    m = Model(Airframe())
    u = hover_u((0, +6, 0, +6))
    f_hi = H1 * (D + 6) ** 2
    Om = 2 * (math.sqrt(f_hi / C1) - math.sqrt(FH / C1))
    assert Om > 0
    xd = m.f(0.0, state(z=3.0, p=1.0), u)
    assert xd[10] == pytest.approx(JP * 1.0 * Om / JYY, rel=1e-9)
    assert xd[9] == pytest.approx(0.0, abs=1e-12)
    xd = m.f(0.0, state(z=3.0, q=1.0), u)
    assert xd[9] == pytest.approx(-JP * 1.0 * Om / JXX, rel=1e-9)
    # the clockwise pair faster: Omega < 0, the sign flips
    xd = m.f(0.0, state(z=3.0, p=1.0), hover_u((+6, 0, +6, 0)))
    assert xd[10] == pytest.approx(-JP * 1.0 * Om / JYY, rel=1e-9)


def test_inertia_coupling_in_model():
    # equal rotors (Omega = 0): only the (J..-J..) terms; q-dot = -(Jxx - Jzz)/Jyy p r
    m = Model(Airframe())
    xd = m.f(0.0, state(z=3.0, p=0.5, r=2.0), hover_u())
    assert xd[10] == pytest.approx(-(JXX - JZZ) / JYY * 0.5 * 2.0, rel=1e-9)
    assert xd[10] > 0


def test_yaw_drag_zero_gamma2_in_flight_and_used_on_bearing():
    a = Airframe()
    xd = Model(a).f(0.0, state(z=3.0, r=2.0), hover_u())
    assert xd[11] == pytest.approx(-(GAMMA1 * 2.0 ** 2) / JZZ, rel=1e-12)
    xd = Model(a, bearing=False).f(0.0, state(z=3.0, r=-2.0), hover_u())
    assert xd[11] == pytest.approx(+(GAMMA1 * 2.0 ** 2) / JZZ, rel=1e-12)
    xd = Model(a, bearing=True).f(0.0, state(z=3.0, r=2.0), hover_u())
    assert xd[11] == pytest.approx(-(GAMMA1 * 2.0 ** 2 + GAMMA2) / JZZ, rel=1e-12)
    xd = Model(a, bearing=True).f(0.0, state(z=3.0, r=-0.5), hover_u())
    assert xd[11] == pytest.approx(+(GAMMA1 * 0.25 + GAMMA2) / JZZ, rel=1e-12)
    xd = Model(a, bearing=True).f(0.0, state(z=3.0), hover_u())
    assert xd[11] == pytest.approx(0.0, abs=1e-12)   # no friction at rest


def skew(w):
    return np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])


@pytest.mark.parametrize("att,rates", [((0.1, 0.2, 0.3), (0.3, -0.4, 0.5)),
                                       ((-0.8, 0.6, 2.5), (-1.0, 0.7, 0.2)),
                                       ((0.0, 0.0, 0.0), (0.4, 0.5, 0.6))])
def test_euler_kinematics_agree_with_rotation(att, rates):
    """dR/dt = R [w]x for body rates w: differentiate the hand-built R along the model's Euler rates."""
    m = Model(Airframe())
    x = state(z=3.0, phi=att[0], theta=att[1], psi=att[2], p=rates[0], q=rates[1], r=rates[2])
    eta_dot = np.array(m.f(0.0, x, hover_u())[6:9])
    eta = np.array(att)
    eps = 1e-6
    dR = (R_hand(*(eta + eps * eta_dot)) - R_hand(*(eta - eps * eta_dot))) / (2 * eps)
    np.testing.assert_allclose(R_hand(*eta).T @ dR, skew(rates), atol=1e-8)
    # the level case is the identity map
    if att == (0.0, 0.0, 0.0):
        np.testing.assert_allclose(eta_dot, rates, atol=1e-15)


def test_translation_with_tilt():
    phi, theta, psi = 0.2, -0.1, 0.7
    m = Model(Airframe())
    x = state(z=3.0, phi=phi, theta=theta, psi=psi, vx=1.0, vy=-2.0, vz=0.5)
    xd = m.f(0.0, x, hover_u())
    # total thrust M g along z_b: a = g R[:, 2] - (0, 0, g)
    sf, cf, st, ct, sp, cp = (math.sin(phi), math.cos(phi), math.sin(theta), math.cos(theta),
                              math.sin(psi), math.cos(psi))
    want = (G * (cp * st * cf + sp * sf), G * (sp * st * cf - cp * sf), G * ct * cf - G)
    assert xd[3:6] == pytest.approx(want, rel=1e-12, abs=1e-12)
    assert xd[0:3] == [1.0, -2.0, 0.5]


def test_specific_force_without_effects():
    m = Model(Airframe())
    u = (130.0, 140.0, 150.0, 110.0, BATT)
    total = H1 * (10 ** 2 + 20 ** 2 + 30 ** 2 + 0)
    x = state(z=3.0, phi=0.4, theta=-0.3, psi=1.0, p=1.0, vx=3.0)
    sfx, sfy, sfz = m.specific_force(0.0, x, u)
    assert (sfx, sfy) == (0.0, 0.0)
    assert sfz == pytest.approx(total / M, rel=1e-12)


def test_model_f_accepts_a_numpy_state():
    """solve_ivp (and any vectorised caller) hands f an ndarray: its entries are numpy scalars."""
    m = Model(Airframe())
    x = np.array(state(z=3.0, r=2.0))
    xd = m.f(0.0, x, hover_u())
    assert xd[11] == pytest.approx(-(GAMMA1 * 4.0) / JZZ, rel=1e-12)


def test_model_f_is_a_function_of_its_arguments():
    """The same list object with new values must give the new answer (f(t, x, u) is pure)."""
    m = Model(Airframe())
    u = list(hover_u())
    xd0 = m.f(0.0, state(z=3.0), u)
    assert xd0[9] == pytest.approx(0.0, abs=1e-12)
    u[1] = PH + 4.0
    u[3] = PH - 4.0
    xd1 = m.f(0.0, state(z=3.0), u)
    assert xd1[9] == pytest.approx(L * 16 * H1 * D / JXX, rel=1e-12)


# --- effects --------------------------------------------------------------------------------------

def test_effect_rotor_drag():
    m = Model(Airframe(), (fx.make("rotor_drag", k=0.3),))
    # yawed 90 deg (nose West), moving North at 2 m/s: the body sees (0, -2, 0), drag (0, +0.6, 0) N,
    # which in the inertial frame is (-0.6, 0, 0): against the motion (four rotors at hover thrust)
    x = state(z=3.0, psi=math.pi / 2, vx=2.0)
    u = hover_u()
    xd = m.f(0.0, x, u)
    assert xd[3] == pytest.approx(-0.3 * 2.0 / M, rel=1e-12)
    assert xd[4] == pytest.approx(0.0, abs=1e-12)
    assert xd[5] == pytest.approx(0.0, abs=1e-9)
    assert m.specific_force(0.0, x, u) == pytest.approx((0.0, 0.3 * 2.0 / M, G), abs=1e-9)
    # no torque from it without a yaw rate
    assert xd[9:12] == pytest.approx([0.0, 0.0, 0.0], abs=1e-12)
    # a yaw rate moves each rotor sideways at r l: the optional yaw term damps it, -yaw r, and nothing
    # else changes; without it (a yaw drag identified with the rotors running holds it) none
    free = Model(Airframe()).f(0.0, state(z=3.0, r=2.0), u)
    assert m.f(0.0, state(z=3.0, r=2.0), u)[11] == pytest.approx(free[11], rel=1e-12)
    yawing = Model(Airframe(), (fx.make("rotor_drag", k=0.3, yaw=0.3 * L * L),))
    xr = yawing.f(0.0, state(z=3.0, r=2.0), u)
    assert xr[11] - free[11] == pytest.approx(-0.3 * L * L * 2.0 / JZZ, rel=1e-12)
    assert xr[3:5] == pytest.approx([0.0, 0.0], abs=1e-12) and xr[9:11] == pytest.approx(free[9:11], abs=1e-12)


@pytest.mark.parametrize("stopped", [(), (1, 3), (0,), (0, 1, 2, 3)])
def test_the_airflow_terms_scale_with_the_rotors_that_run(stopped):
    """rotor_drag's force and yaw damping and rotor_inflow's hub moment come from the air the rotors
    move: a stopped rotor (command below the dead zone, eq. 26) adds none. The force is k/4 per rotor;
    the yaw term holds the rotors beyond the two whose share eq. 6's gamma1 holds (the rig's pair), so
    it is yaw (n - 2) / 2 for n rotors running, none below two; the hub moment hub/4 per rotor. A rotor
    between (a quarter of hover thrust) shares by its induced velocity, sqrt(f / (B/4))."""
    k, yaw, hub, r, p, vx = 1.2, 0.05, 0.024, 3.0, 1.5, 2.0
    run = 4 - len(stopped)
    u = list(hover_u())
    for i in stopped:
        u[i] = H2 - 5.0                        # below the dead zone: no thrust, no airflow
    u = tuple(u)
    x = state(z=3.0, vx=vx, r=r, p=p)
    plain = Model(Airframe()).f(0.0, x, u)
    drag = Model(Airframe(), (fx.make("rotor_drag", k=k, yaw=yaw),)).f(0.0, x, u)
    assert drag[3] - plain[3] == pytest.approx(-k * run / 4 * vx / M, rel=1e-12, abs=1e-12)
    assert drag[11] - plain[11] == pytest.approx(-yaw * max(run - 2, 0) / 2 * r / JZZ, rel=1e-12, abs=1e-12)
    inflow = Model(Airframe(), (fx.make("rotor_inflow", k=0.0, hub=hub),)).f(0.0, x, u)
    assert inflow[9] - plain[9] == pytest.approx(-hub * run / 4 * p / JXX, rel=1e-12, abs=1e-12)
    # one rotor at a ninth of hover thrust (1/9 B < B/4): its share is sqrt(4/9) = 2/3
    P_ninth = H2 + D / 3.0
    u3 = (PH, PH, PH, P_ninth, BATT)
    assert (Model(Airframe(), (fx.make("rotor_inflow", k=0.0, hub=hub),)).f(0.0, x, u3)[9]
            - Model(Airframe()).f(0.0, x, u3)[9]) == pytest.approx(-hub * (3 + 2 / 3) / 4 * p / JXX, rel=1e-9)


def test_effect_rotor_inflow_hub_damping():
    """The optional hub moment: -hub (p, q) on roll and pitch, on top of the inflow's -2 k l^2 p."""
    k, hub = 0.3, 0.024
    with_hub = Model(Airframe(), (fx.make("rotor_inflow", k=k, hub=hub),))
    without = Model(Airframe(), (fx.make("rotor_inflow", k=k),))
    x = state(z=3.0, p=1.5, q=-0.5)
    a, b = with_hub.f(0.0, x, hover_u()), without.f(0.0, x, hover_u())
    assert a[9] - b[9] == pytest.approx(-hub * 1.5 / JXX, rel=1e-9)
    assert a[10] - b[10] == pytest.approx(hub * 0.5 / JYY, rel=1e-9)
    assert a[11] == pytest.approx(b[11], abs=1e-12) and a[5] == pytest.approx(b[5], abs=1e-12)


def test_effect_com_offset():
    m = Model(Airframe(), (fx.make("com_offset", dx=0.01, dy=-0.02),))
    xd = m.f(0.0, state(z=3.0), hover_u())
    F = 4 * FH  # = M g
    assert xd[9] == pytest.approx(-(-0.02) * F / JXX, rel=1e-12)   # +0.02 F about x_b
    assert xd[10] == pytest.approx(0.01 * F / JYY, rel=1e-12)
    assert xd[9] == pytest.approx(0.02 * M * G / JXX, rel=1e-12)   # about 23 rad/s^2
    assert xd[11] == pytest.approx(0.0, abs=1e-12)
    np.testing.assert_allclose(xd[3:6], 0.0, atol=1e-12)


def test_effect_motor_weak():
    m = Model(Airframe(), (fx.make("motor_weak", motor=2, scale=0.5),))
    xd = m.f(0.0, state(z=3.0), hover_u())
    assert xd[9] == pytest.approx(L * (0.5 * FH - FH) / JXX, rel=1e-12)      # motor 2 weaker: roll -
    assert xd[10] == pytest.approx(0.0, abs=1e-12)
    # its reaction torque is halved too: tau1 - tau2/2 + tau3 - tau4 = tau_h / 2
    assert xd[11] == pytest.approx(0.5 * TAU_H / JZZ, rel=1e-12)
    assert xd[5] == pytest.approx(3.5 * FH / M - G, rel=1e-12)             # = -g/8
    assert xd[5] == pytest.approx(-G / 8, rel=1e-12)


def test_effect_battery_sag():
    m = Model(Airframe(), (fx.make("battery_sag", v_nominal=14.8),))
    k = (12.0 / 14.8) ** 2
    xd = m.f(0.0, state(z=3.0), hover_u(v=12.0))
    assert xd[5] == pytest.approx(k * 4 * FH / M - G, rel=1e-12)
    assert xd[5] == pytest.approx(G * (k - 1), rel=1e-12)
    xd = m.f(0.0, state(z=3.0), hover_u(v=14.8))
    assert xd[5] == pytest.approx(0.0, abs=1e-12)


def test_effect_ground_effect():
    m = Model(Airframe(), (fx.make("ground_effect", rotor_radius=ROTOR_R),))
    for z in (0.5, 0.2, 2.0):
        k = 1.0 / (1.0 - (ROTOR_R / (4 * z)) ** 2)
        xd = m.f(0.0, state(z=z), hover_u())
        assert xd[5] == pytest.approx(G * (k - 1), rel=1e-10)
    # below z = R/2 it is held at 1/(1 - 1/4) = 4/3
    xd = m.f(0.0, state(z=0.01), hover_u())
    assert xd[5] == pytest.approx(G * (4 / 3 - 1), rel=1e-10)
    # far from the ground, nothing
    xd = m.f(0.0, state(z=100.0), hover_u())
    assert xd[5] == pytest.approx(G * (1 / (1 - (ROTOR_R / 400) ** 2) - 1), rel=1e-6)


def test_effect_linear_yaw_drag():
    m = Model(Airframe(), (fx.make("linear_yaw_drag", gamma0=0.01),))
    xd = m.f(0.0, state(z=3.0, r=2.0), hover_u())
    assert xd[11] == pytest.approx((-0.01 * 2.0 - GAMMA1 * 4.0) / JZZ, rel=1e-12)
    xd = m.f(0.0, state(z=3.0, r=-1.0), hover_u())
    assert xd[11] == pytest.approx((+0.01 * 1.0 + GAMMA1 * 1.0) / JZZ, rel=1e-12)


def test_effect_motor_lag():
    e = fx.make("motor_lag", tau=0.05)
    m = Model(Airframe(), (e,))
    assert m.n == 16 and e.offset == 12
    # initial rotor states are the commanded thrusts
    assert m.initial_state(hover_u())[12:] == pytest.approx([FH] * 4, rel=1e-12)
    x = state(z=3.0) + [1.0, 2.0, 3.0, 4.0]
    xd = m.f(0.0, x, hover_u())
    assert xd[12:16] == pytest.approx([(FH - 1.0) / 0.05, (FH - 2.0) / 0.05,
                                       (FH - 3.0) / 0.05, (FH - 4.0) / 0.05], rel=1e-12)
    # the thrusts acting are the lagged ones
    assert xd[5] == pytest.approx((1.0 + 2.0 + 3.0 + 4.0) / M - G, rel=1e-12)
    assert xd[9] == pytest.approx(L * (2.0 - 4.0) / JXX, rel=1e-12)
    assert xd[10] == pytest.approx(L * (3.0 - 1.0) / JYY, rel=1e-12)


def test_effect_rotor_inflow_climb_loses_heave_thrust():
    k = 0.32
    m = Model(Airframe(), (fx.make("rotor_inflow", k=k),))
    # level, climbing at 0.5 m/s with hover thrust on every rotor: each loses k sqrt(FH / B) 0.5 = k 0.5
    xd = m.f(0.0, state(z=3.0, vz=0.5), hover_u())
    assert xd[5] == pytest.approx((4 * FH - 4 * k * 0.5) / M - G, rel=1e-12)
    assert xd[5] == pytest.approx(-4 * k * 0.5 / M, rel=1e-9)        # -0.39 m/s^2: heave damping 4 k
    assert xd[9:12] == pytest.approx([0.0, 0.0, 0.0], abs=1e-12)
    assert m.specific_force(0.0, state(z=3.0, vz=0.5), hover_u())[2] == pytest.approx(G - 2 * k / M, rel=1e-12)
    # descending gains thrust; hovering changes nothing
    assert m.f(0.0, state(z=3.0, vz=-0.5), hover_u())[5] == pytest.approx(+4 * k * 0.5 / M, rel=1e-9)
    assert m.f(0.0, state(z=3.0), hover_u())[5] == pytest.approx(0.0, abs=1e-12)
    # the loss goes as sqrt(f / B): at a quarter of the hover thrust per rotor, half of it
    d = math.sqrt(FH / 4 / H1)
    u = (H2 + d,) * 4 + (BATT,)
    assert m.f(0.0, state(z=3.0, vz=1.0), u)[5] == pytest.approx((FH - 4 * k * 0.5 * 1.0) / M - G, rel=1e-9)


def test_effect_rotor_inflow_damps_roll_and_pitch():
    k = 0.32
    m = Model(Airframe(), (fx.make("rotor_inflow", k=k),))
    # rolling at p = 1 rad/s: rotor 2 at (0, +l) rises at l p and loses k l p, rotor 4 gains it
    xd = m.f(0.0, state(z=3.0, p=1.0), hover_u())
    assert xd[9] == pytest.approx(-2 * k * L * L * 1.0 / JXX, rel=1e-12)    # -2.8 rad/s^2: damping
    assert xd[5] == pytest.approx(0.0, abs=1e-12)                             # no net heave change
    # pitching at q = 1 rad/s: rotor 1 at (+l, 0) falls (w - q l), gains thrust; rotor 3 loses it
    xd = m.f(0.0, state(z=3.0, q=1.0), hover_u())
    assert xd[10] == pytest.approx(-2 * k * L * L * 1.0 / JYY, rel=1e-12)
    # the axial speed is along z_b: a vehicle rolled by 90 deg moving up has none
    xd = m.f(0.0, state(z=3.0, vz=1.0, phi=math.pi / 2), hover_u())
    assert xd[9:11] == pytest.approx([0.0, 0.0], abs=1e-12)
    assert xd[4] == pytest.approx(-4 * FH / M, rel=1e-9)    # the whole thrust along -y, none lost


def test_effect_motor_dynamics_ccw_speed_up_yaws_clockwise():
    tau = 0.04
    e = fx.make("motor_dynamics", tau=tau)
    m = Model(Airframe(), (e,))
    W = math.sqrt(FH / C1)                       # hover speed, eq. 27: about 524 rad/s
    assert m.n == 16 and m.initial_state(hover_u())[12:] == pytest.approx([W] * 4, rel=1e-12)
    # in hover, the counter-clockwise rotors 2 and 4 are commanded 4 P units more
    u = hover_u((0.0, 4.0, 0.0, 4.0))
    Wc = math.sqrt(H1 * (D + 4.0) ** 2 / C1)      # eq. 26 and 27: the commanded speed
    xd = m.f(0.0, state(z=3.0) + [W] * 4, u)
    assert xd[12:16] == pytest.approx([0.0, (Wc - W) / tau, 0.0, (Wc - W) / tau], rel=1e-12, abs=1e-9)
    # the speeds, so the thrusts and drag torques, have not changed yet; the body takes the reaction
    # -Jp (dW2 + dW4) about z_b: clockwise seen from above (r decreasing), the same way as the
    # drag torque -tau_2 - tau_4 of those rotors will turn it once they are faster (conventions.md)
    assert xd[11] == pytest.approx(-JP * 2 * (Wc - W) / tau / JZZ, rel=1e-9)
    assert xd[11] < 0
    assert xd[5] == pytest.approx(0.0, abs=1e-12) and xd[9:11] == pytest.approx([0.0, 0.0], abs=1e-12)
    # motor_lag in the same state: no yaw at all until the thrusts move
    lag = Model(Airframe(), (fx.make("motor_lag", tau=tau),))
    assert lag.f(0.0, state(z=3.0) + [FH] * 4, u)[11] == pytest.approx(0.0, abs=1e-12)


def test_effect_motor_dynamics_thrust_torque_and_momentum_follow_the_lagged_speeds():
    m = Model(Airframe(), (fx.make("motor_dynamics", tau=0.05),))
    W = [500.0, 510.0, 520.0, 530.0]
    u = hover_u()
    Wc = math.sqrt(FH / C1)
    xd = m.f(0.0, state(z=3.0, q=1.0) + W, u)
    f = [C1 * w * w for w in W]                                    # eq. 27
    tq = [G1 * fi + G2 for fi in f]                                # eq. 28
    Omega = -W[0] + W[1] - W[2] + W[3]                             # eq. 9 with the lagged speeds
    spin_up = sum(s * (Wc - w) / 0.05 for s, w in zip((-1, 1, -1, 1), W))
    assert xd[5] == pytest.approx(sum(f) / M - G, rel=1e-12)
    assert xd[9] == pytest.approx((L * (f[1] - f[3]) - 1.0 * JP * Omega) / JXX, rel=1e-12)   # q hz, r = 0
    assert xd[10] == pytest.approx(L * (f[2] - f[0]) / JYY, rel=1e-12)
    assert xd[11] == pytest.approx((tq[0] - tq[1] + tq[2] - tq[3] - JP * spin_up) / JZZ, rel=1e-12)


def test_effect_motor_dynamics_slows_down_with_tau_down():
    """An ESC that does not brake: rotors below their command speed up with tau, rotors above it
    slow down with tau_down; without tau_down both ways take tau. The speeds in the plant decay as
    exp(-t / tau_down) after a step down."""
    W = math.sqrt(FH / C1)
    u = hover_u()
    m = Model(Airframe(), (fx.make("motor_dynamics", tau=0.03, tau_down=0.2),))
    speeds = [W - 20.0, W + 20.0, W - 20.0, W + 20.0]
    xd = m.f(0.0, state(z=3.0) + speeds, u)
    assert xd[12:16] == pytest.approx([20.0 / 0.03, -20.0 / 0.2, 20.0 / 0.03, -20.0 / 0.2], rel=1e-12)
    sym = Model(Airframe(), (fx.make("motor_dynamics", tau=0.03),))
    assert sym.f(0.0, state(z=3.0) + speeds, u)[12:16] == pytest.approx([20.0 / 0.03, -20.0 / 0.03] * 2, rel=1e-12)
    plant = Plant(Model(Airframe(), (fx.make("motor_dynamics", tau=0.03, tau_down=0.2),)), 1 / 450)
    plant.command(*hover_u((10.0,) * 4))
    for _ in range(450):
        plant.advance(1 / 450)
    high = plant.x[12]
    plant.command(*u)
    for _ in range(90):             # 0.2 s = tau_down after the step down
        plant.advance(1 / 450)
    assert (plant.x[12] - W) / (high - W) == pytest.approx(math.exp(-1.0), rel=1e-3)
    with pytest.raises(InputError, match="tau_down=9 is out of range"):
        fx.make("motor_dynamics", tau=0.03, tau_down=9.0)


def test_parse_effect():
    e = fx.parse("motor_lag:tau=0.05")
    assert e.cause == "motor_lag" and e.parameters == {"tau": 0.05}
    e = fx.parse(" com_offset : dx=0.01 , dy=-0.02")
    assert e.cause == "com_offset" and e.parameters == {"dx": 0.01, "dy": -0.02}
    e = fx.parse("actuation_delay:delay=0.02")
    assert e.delay == 0.02
    assert Model(Airframe(), (e,)).delay == 0.02


@pytest.mark.parametrize("text,words", [
    ("warp_drive:k=1", ["unknown effect", "warp_drive"]),
    ("motor_lag", ["motor_lag", "missing tau"]),
    ("motor_lag:tau=0.05,k=1", ["unknown k"]),
    ("motor_lag:tau=10", ["tau=10", "out of range"]),
    ("motor_lag:tau=-1", ["out of range"]),
    ("motor_lag:tau=nan", ["out of range"]),
    ("motor_lag:tau", ["bad item", "'tau'"]),
    ("motor_lag:tau=fast", ["tau = 'fast' is not a number"]),
    ("tau=abc", ["tau = 'abc' is not a number"]),
    ("tau=0.05", ["no cause before the values", "motor_lag"]),
    ("motor_weak:motor=2.5,scale=0.5", ["motor must be"]),
    ("motor_weak:motor=5,scale=0.5", ["motor=5", "out of range"]),
])
def test_parse_effect_errors(text, words):
    with pytest.raises(InputError) as e:
        fx.parse(text)
    for w in words:
        assert w in str(e.value)


# --- plant: RK4, floor, delay ---------------------------------------------------------------------

def open_loop_input(k, dt):
    t = k * dt
    d = 1.5 * math.sin(2 * math.pi * 2.0 * t)
    e = 1.0 * math.cos(2 * math.pi * 1.3 * t)
    return (PH + 1 + e, PH + d, PH - e + 1.5, PH - d, BATT)


def test_rk4_against_solve_ivp():
    """Fixed-step RK4 against an accurate reference (DOP853, rtol 1e-10) for the same zero-order-hold
    input, over 1 s airborne, at h = dt and dt/2.

    Error bound: RK4 matches the Taylor series through h^4, so the local error per step is about
    h^5 |x^(5)| / 120 and over T/h steps the global error is about T h^4 |x^(5)| / 120. Here the
    input is constant within a step and the fastest motion is the rotation: velocity is thrust/M
    (about g) turned by the attitude, whose rate of change is bounded by Lam = max|w| + sqrt(max|dw/dt|),
    so |x^(5)| <~ g Lam^4, and err <= T g Lam^4 h^4 / 120. Halving h must divide it by 2^4 = 16.
    """
    a = Airframe()
    dt, T = 0.01, 1.0
    N = round(T / dt)
    m = Model(a)
    x = np.array(state(z=5.0))
    ref = [x.copy()]
    wmax = amax = 0.0
    for k in range(N):
        u = open_loop_input(k, dt)
        s = solve_ivp(lambda t, y: m.f(t, y.tolist(), u), (k * dt, (k + 1) * dt), x, method="DOP853",
                      rtol=1e-10, atol=1e-12)
        x = s.y[:, -1]
        ref.append(x.copy())
        wmax = max(wmax, np.abs(x[9:12]).max())
        amax = max(amax, np.abs(m.f(0.0, x.tolist(), u)[9:12]).max())
    ref = np.array(ref)
    assert ref[:, 2].min() > 1.0       # airborne throughout
    assert np.abs(ref[-1, 6:9]).max() > 0.1   # and it really turned (the test is not trivial)
    lam = wmax + math.sqrt(amax)
    errs = {}
    for sub in (1, 2):
        plant = Plant(Model(a), dt, sub)
        plant.on_ground = False
        plant.x[2] = 5.0
        got = [list(plant.x)]
        for k in range(N):
            plant.command(*open_loop_input(k, dt))
            plant.advance(dt)
            got.append(list(plant.x))
        h = dt / sub
        err = np.abs(np.array(got) - ref).max()
        bound = T * G * lam ** 4 * h ** 4 / 120
        assert err < bound, (sub, err, bound)
        errs[sub] = err
        assert plant.t == pytest.approx(T)
        assert not plant.touchdowns
    assert 16 / 1.5 < errs[1] / errs[2] < 16 * 1.5


def fresh_plant(effects=(), dt=1 / 450, substeps=2):   # 2: the floor tests below time contacts within dt / 2
    return Plant(Model(Airframe(), effects), dt, substeps)


def test_floor_holds_below_hover_and_lifts_above():
    dt = 1 / 450
    plant = fresh_plant(dt=dt)
    for _ in range(45):             # 0.1 % short of the weight: 4 h1 (D - 0.02)^2 = 0.9992 M g
        plant.command(*hover_u((-0.02,) * 4))
        plant.advance(dt)
    assert plant.on_ground
    assert not plant.touchdowns     # it never left the floor
    assert plant.x == [0.0] * 12
    assert plant.t == pytest.approx(45 * dt)
    assert plant.specific_force() == (0.0, 0.0, G)
    # 0.1 % above the weight: constant acceleration a from the first substep, z = a t^2 / 2 (RK4 is
    # exact for a quadratic)
    n = 90
    for _ in range(n):
        plant.command(*hover_u((0.02,) * 4))
        plant.advance(dt)
    acc = 4 * H1 * (D + 0.02) ** 2 / M - G
    assert 0.007 < acc < 0.008
    assert not plant.on_ground
    assert plant.x[2] == pytest.approx(acc * (n * dt) ** 2 / 2, rel=1e-9)
    assert plant.x[5] == pytest.approx(acc * n * dt, rel=1e-9)


def test_touchdown_recorded():
    dt = 1 / 450
    plant = fresh_plant(dt=dt)
    plant.on_ground = False
    plant.x[2] = 0.1
    plant.x[8] = 0.4          # heading is kept through a touchdown
    for _ in range(90):       # 0.2 s, motors off: free fall from 0.1 m
        plant.command(0.0, 0.0, 0.0, 0.0, BATT)
        plant.advance(dt)
    t_hit = math.sqrt(2 * 0.1 / G)       # 0.1428 s
    v_hit = math.sqrt(2 * G * 0.1)       # 1.40 m/s
    h = dt / 2
    assert len(plant.touchdowns) == 1
    t, vz = plant.touchdowns[0]
    assert t_hit <= t <= t_hit + h + 1e-12
    assert -v_hit - G * h - 1e-9 <= vz <= -v_hit
    assert plant.on_ground
    assert plant.x[2] == 0.0 and plant.x[5] == 0.0
    assert plant.x[8] == 0.4
    assert plant.specific_force() == (0.0, 0.0, G)


def test_motor_lag_vehicle_can_take_off():
    """With rotor states, the floor must still let the rotors spin up: a command well above hover
    lifts the vehicle once the lagged thrust exceeds the weight (here after -0.05 ln(1 - FH / h1 (D + 10)^2) = 0.061 s)."""
    dt = 1 / 450
    plant = fresh_plant((fx.make("motor_lag", tau=0.05),), dt=dt)
    for _ in range(225):      # 0.5 s
        plant.command(*hover_u((10.0,) * 4))
        plant.advance(dt)
    assert not plant.on_ground
    assert plant.x[2] > 0.0


def test_actuation_delay_is_exact_at_any_value():
    """A delay of whole periods shifts the response by those periods exactly; a delay of 7 ms = 3.15
    periods lies between 3 and 4 periods' shifts, at 0.15 of the way (to first order), at 1 and at 3
    substeps alike (the plant splits the period where the delayed command changes)."""
    dt = 1 / 450

    def run(delay, sub=1):
        plant = fresh_plant((fx.make("actuation_delay", delay=delay),) if delay else (), dt=dt, substeps=sub)
        zs, ps = [], []   # on the floor at hover thrust until the step lifts it
        for k in range(60):
            u = hover_u((0.0,) * 4) if k < 10 else hover_u((3.0, 5.0, 3.0, 1.0))
            plant.command(*u)
            plant.advance(dt)
            zs.append(plant.x[2])
            ps.append(plant.x[9])
        return np.array(zs), np.array(ps)
    z0, p0 = run(0.0)
    z3, p3 = run(3 * dt)
    assert z0[9] == 0.0 and z0[10] > 0.0 and z3[12] == 0.0 and z3[13] > 0.0   # lifts three periods later
    assert z3[3:] == pytest.approx(z0[:-3], rel=1e-12, abs=1e-15)
    assert p3[3:] == pytest.approx(p0[:-3], rel=1e-12, abs=1e-15)
    z4, _ = run(4 * dt)
    for sub in (1, 3):
        z7, p7 = run(0.007, sub)
        frac = (z3[20:40] - z7[20:40]) / (z3[20:40] - z4[20:40])
        assert frac == pytest.approx(0.15, abs=0.02)
    assert p0[20] > 0.0                              # and it rolls (f2 > f4)
