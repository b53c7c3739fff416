"""flightctl.physics, the one copy of the paper's propeller and yaw-drag equations (eq. 6, 26-28),
against values worked out by hand from the formulas and the reference airframe of conventions.md.
Each function must take floats (giving plain floats: no numpy in the 450 Hz loop) and numpy arrays."""
import math

import numpy as np
import pytest

from flightctl.physics import (G, command_from_thrust, rotor_speed, rotor_torque, thrust_from_command,
                               thrust_from_speed, yaw_drag)

# conventions.md, reference airframe (Table 2 and the plausible propeller defaults)
M = 1.645
GAMMA1, GAMMA2 = 4.86291e-4, 1.22958e-3
H1, H2, C1, G1, G2 = 1.49e-3, 120.0, 1.47e-5, 0.020, 0.002

FH = M * 9.80665 / 4                # hover thrust per motor, N
PH = H2 + math.sqrt(FH / H1)        # hover command, about 172.03


def test_standard_gravity():
    assert G == 9.80665             # conventions.md, paper Table 2


# --- propeller: eq. 26-28 ------------------------------------------------------------------------

def test_thrust_from_command_eq26_floats():
    assert thrust_from_command(130.0, H1, H2) == pytest.approx(1.49e-3 * 10.0 ** 2)
    assert thrust_from_command(255.0, H1, H2) == pytest.approx(1.49e-3 * 135.0 ** 2)   # 27.15 N
    assert thrust_from_command(PH, H1, H2) == pytest.approx(FH, rel=1e-12)
    # dead zone: no thrust at or below h2, never negative (the parabola would rise again)
    assert thrust_from_command(120.0, H1, H2) == 0.0
    assert thrust_from_command(100.0, H1, H2) == 0.0
    assert thrust_from_command(0.0, H1, H2) == 0.0
    assert type(thrust_from_command(130.0, H1, H2)) is float


def test_thrust_from_command_eq26_arrays():
    P = np.array([0.0, 100.0, 120.0, 121.0, 130.0, 255.0])
    want = np.array([0.0, 0.0, 0.0, 1.49e-3 * 1.0, 1.49e-3 * 100.0, 1.49e-3 * 135.0 ** 2])
    got = thrust_from_command(P, H1, H2)
    assert isinstance(got, np.ndarray)
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=0)


def test_command_from_thrust_inverts_eq26():
    assert command_from_thrust(4.0, H1, H2) == pytest.approx(120.0 + math.sqrt(4.0 / 1.49e-3))
    assert command_from_thrust(FH, H1, H2) == pytest.approx(PH)
    for f in (0.01, 1.0, 4.0, 8.0, 20.0):
        assert thrust_from_command(command_from_thrust(f, H1, H2), H1, H2) == pytest.approx(f, rel=1e-12)
    assert thrust_from_command(command_from_thrust(0.0, H1, H2), H1, H2) == 0.0


def test_command_from_thrust_is_continuous_at_zero_thrust():
    """Zero thrust is the edge of the dead zone, P = h2: a small thrust is a small step from there."""
    assert command_from_thrust(0.0, H1, H2) == H2
    assert command_from_thrust(1e-6, H1, H2) - H2 == pytest.approx(math.sqrt(1e-6 / 1.49e-3))


def test_thrust_from_speed_eq27():
    assert thrust_from_speed(100.0, C1) == pytest.approx(1.47e-5 * 100.0 ** 2)
    np.testing.assert_allclose(thrust_from_speed(np.array([0.0, -100.0, 200.0]), C1),
                               [0.0, 0.147, 0.588], rtol=1e-12)


def test_rotor_speed_eq27():
    assert rotor_speed(4.0, C1) == pytest.approx(math.sqrt(4.0 / 1.47e-5))
    # conventions.md: hover near 5000 RPM
    assert rotor_speed(FH, C1) * 60 / (2 * math.pi) == pytest.approx(5000, rel=0.01)
    np.testing.assert_allclose(rotor_speed(np.array([0.0, 1.47e-5 * 100 ** 2]), C1), [0.0, 100.0])
    assert rotor_speed(thrust_from_speed(523.0, C1), C1) == pytest.approx(523.0, rel=1e-12)
    assert rotor_speed(-1e-9, C1) == 0.0          # never a complex speed from a rounding error
    assert type(rotor_speed(4.0, C1)) is float


def test_rotor_torque_eq28():
    assert rotor_torque(2.0, G1, G2) == pytest.approx(0.020 * 2.0 + 0.002)
    assert rotor_torque(FH, G1, G2) == pytest.approx(0.020 * FH + 0.002)
    assert rotor_torque(0.0, G1, G2) == 0.0      # sgn(0) = 0: a stopped rotor has no torque
    got = rotor_torque(np.array([0.0, 1.0, 5.0]), G1, G2)
    np.testing.assert_allclose(got, [0.0, 0.022, 0.102], rtol=1e-12)
    assert type(rotor_torque(2.0, G1, G2)) is float


def test_yaw_drag_eq6():
    assert yaw_drag(2.0, GAMMA1, GAMMA2) == pytest.approx(4.86291e-4 * 4.0 + 1.22958e-3)
    assert yaw_drag(-2.0, GAMMA1, GAMMA2) == pytest.approx(-(4.86291e-4 * 4.0 + 1.22958e-3))
    assert yaw_drag(0.0, GAMMA1, GAMMA2) == 0.0
    assert yaw_drag(3.0, GAMMA1, 0.0) == pytest.approx(4.86291e-4 * 9.0)
    np.testing.assert_allclose(yaw_drag(np.array([-1.0, 0.0, 1.0]), GAMMA1, GAMMA2),
                               [-(GAMMA1 + GAMMA2), 0.0, GAMMA1 + GAMMA2])
    assert type(yaw_drag(-2.0, GAMMA1, GAMMA2)) is float
