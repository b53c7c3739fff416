"""sim/logs/frames.py, the one table of multirotor layouts the readers use: each ArduPilot matrix balanced
as a mixer must be (as many rotors each way, no roll or pitch from the throttle), positions where
AP_MotorsMatrix's own comments and diagrams put them, PX4's CA_ROTOR* rotors drawn at random read back
(FRD to ours), Betaflight's hexa X, and the `# rotors:` line of any of them parsed back by diagnose."""
from __future__ import annotations

import math

import numpy as np
import pytest

from flightctl.errors import InputError
from flightctl.sim.diagnose.data import Layout
from flightctl.sim.logs import frames


def fail(what):
    raise InputError(what)


@pytest.mark.parametrize("key", sorted(frames.ARDUPILOT))
def test_every_ardupilot_matrix_is_a_balanced_mixer(key):
    f = frames.ardupilot(*key, fail)
    n = {1: 4, 2: 6, 3: 8, 4: 8}[key[0]]
    assert f.count == n and sum(f.spin) == 0                              # as many clockwise as not
    assert abs(sum(f.x)) < 0.1 and abs(sum(f.y)) < 0.1                    # the throttle rolls and pitches nothing
    assert max(math.hypot(x, y) for x, y in zip(f.x, f.y)) == pytest.approx(1.0)
    assert "AP_MotorsMatrix.cpp, AP_MotorsMatrix::setup_motors" in f.source
    lay = Layout.parse(f.rotors(), f.source, fail)                        # what diagnose reads back
    assert np.allclose(lay.x, f.x, atol=1e-4) and np.allclose(lay.y, f.y, atol=1e-4) and lay.spin == f.spin


def test_the_positions_are_where_ardupilot_puts_them():
    # AP_MotorsMatrix's diagrams: hexa X motor 1 right (90 deg) CW, 2 left CCW; octo X motor 1 at 22.5 deg
    # right of the nose CW; the quad V's yaw factors 0.7981 and 1 ("unequal: the spins are their signs")
    hexa = frames.ardupilot(2, 1, fail)
    assert (hexa.x[0], hexa.y[0], hexa.spin[0]) == pytest.approx((0.0, -1.0, -1.0), abs=1e-9)
    assert (hexa.x[1], hexa.y[1], hexa.spin[1]) == pytest.approx((0.0, 1.0, 1.0), abs=1e-9)
    octo = frames.ardupilot(3, 1, fail)
    assert (octo.x[0], octo.y[0]) == pytest.approx((math.cos(math.radians(22.5)), -math.sin(math.radians(22.5))))
    v = frames.ardupilot(1, 2, fail)
    assert v.yaw_factor == (0.7981, 1.0, -0.7981, -1.0) and v.spin == (1.0, 1.0, -1.0, -1.0)
    assert "QUAD/V" in v.source and "unequal" in v.source


@pytest.mark.parametrize("key, words", [((1, 4), "V-tail"), ((5, 10), "Y6B"), ((2, 3), "(H)")])
def test_a_frame_not_in_the_table_is_refused_by_name(key, words):
    with pytest.raises(InputError, match="does not take") as e:
        frames.ardupilot(*key, fail)
    assert words in str(e.value)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_px4_rotors_drawn_at_random_come_back_in_our_frame(seed):
    rng = np.random.default_rng(4700 + seed)
    n = int(rng.choice([4, 6, 8]))
    spins = rng.permutation([1.0] * (n // 2) + [-1.0] * (n // 2))
    px, py = rng.uniform(-0.4, 0.4, n), rng.uniform(-0.4, 0.4, n)
    p = {"CA_ROTOR_COUNT": n}
    for i in range(n):
        p.update({f"CA_ROTOR{i}_PX": px[i], f"CA_ROTOR{i}_PY": py[i], f"CA_ROTOR{i}_KM": 0.05 * spins[i]})
    f = frames.px4(p, fail)
    arm = np.hypot(px, py).max()
    assert np.allclose(f.x, px / arm) and np.allclose(f.y, -py / arm) and f.spin == tuple(spins)
    p["CA_ROTOR0_AZ"] = -0.7                                              # a tilted rotor
    with pytest.raises(InputError, match="tilt"):
        frames.px4(p, fail)


def test_betaflights_hexa_x_and_a_plane():
    f = frames.betaflight(6, "Betaflight", None, fail)
    assert (f.x[4], f.y[4]) == pytest.approx((0.0, -1.0)) and (f.x[5], f.y[5]) == pytest.approx((0.0, 1.0))
    assert f.spin == (1.0, 1.0, -1.0, -1.0, -1.0, 1.0) and "mixerHex6X" in f.source
    assert frames.betaflight(6, "Betaflight", 1, fail).spin == tuple(-s for s in f.spin)
    with pytest.raises(InputError, match=frames.NOT_MULTIROTOR):
        frames.betaflight(1, "INAV", None, fail)
    with pytest.raises(InputError, match="tricopter"):
        frames.betaflight(3, "Betaflight", None, fail)


def test_betaflights_octocopter_is_refused_by_the_mixers_it_could_be():
    """Eight motors are four Betaflight mixers (mixer_init.c's mixers[]: OCTOX8, OCTOX8P, OCTOFLATP,
    OCTOFLATX) with other positions and spins, and the blackbox header names none of them: refused by
    name, not read as any one; six motors read as hexa X, the header's silence on HEX6, HEX6H and Y6 said."""
    with pytest.raises(InputError) as e:
        frames.betaflight(8, "Betaflight", None, fail)
    for name in ("OCTOX8", "OCTOX8P", "OCTOFLATP", "OCTOFLATX", "mixer_type"):
        assert name in str(e.value), (name, str(e.value))
    assert "HEX6H" in frames.betaflight(6, "Betaflight", None, fail).source


def test_betaflights_erpm_of_a_hexacopter_is_read_for_its_six_motors():
    """Betaflight's blackbox.c logs eRPM[0..7], one per motor (eRPM / 100): a hexacopter's six are read as
    omega1..6 (rpm = 100 eRPM / (motor_poles / 2)); they were read for quads only. Speeds drawn at random."""
    from flightctl.sim.logs.bbfields import _rotor_speeds
    from flightctl.sim.logs.common import Imported, Stream
    rng = np.random.default_rng(4546)
    n, rows, poles = 6, 50, 14.0
    erpm = rng.integers(100, 400, size=(rows, n)).astype(float)
    names = [f"eRPM[{i}]" for i in range(n)]
    col = {c: i for i, c in enumerate(names)}
    t = np.arange(rows) * 0.002
    imp = Imported("hexa.bbl", {"motors": Stream("motor[]", t, np.zeros((n, rows)))}, {}, [])

    def field(prefix, k, cols=None):
        return np.vstack([erpm[:, col[f"{prefix}[{i}]"]] if f"{prefix}[{i}]" in col else np.full(rows, np.nan)
                          for i in (cols or range(k))])

    _rotor_speeds(imp, {"motor_poles": poles}, erpm, col, t, field, 0, "betaflight")
    w = imp.streams["omega"].values
    assert w.shape == (n, rows) and "eRPM[0..5]" in imp.meta["omega_source"]
    assert np.allclose(w, erpm.T * 100.0 / (poles / 2.0) * 2.0 * math.pi / 60.0)
