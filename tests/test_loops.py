"""loops.py: each firmware's mix from its controller's output to the motors (PX4's normalised pseudo-inverse,
ArduPilot's factors of magnitude 0.5, INAV's and Betaflight's +-1), and the truth test of the loop's
construction: a flightctl sim flight's base model, identified on one flight, flying the paper's attitude
PIDs (eq. 24) predicts the steps another flight of the same vehicle measures (docs/steps.md)."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from flightctl.cli import main
from flightctl.logfile import read_flight_log
from flightctl.params import Params
from flightctl.sim.identify.diagnose import loops, predict
from flightctl.sim.logs import controller, frames


def _fail(msg):
    raise AssertionError(msg)


def test_px4_mix_is_the_normalised_pseudo_inverse():
    """PX4's quad X: the pseudo-inverse's roll and pitch columns, over their common scale sqrt(|col|^2 / 2),
    are +-1/sqrt(2); its yaw column over its largest entry +-1; each column moves its own axis only."""
    quad = frames.px4_quad(4001)
    for axis, size in (("x", 1 / math.sqrt(2)), ("y", 1 / math.sqrt(2)), ("z", 1.0)):
        m = loops.px4_mix(quad, axis)
        assert np.allclose(np.abs(m), size, atol=1e-6), (axis, m)
        d = {a: loops._direction(quad, a) for a in "xyz"}
        assert m @ d[axis] > 0 and all(abs(m @ d[o]) < 1e-9 for o in "xyz" if o != axis)
    # a frame twice as wide as long: roll and pitch share one scale (the larger, pitch's), so the roll column,
    # on the longer lever, is half the pitch one (scaled apart, both would be 1/sqrt(2))
    rect = frames.Frame("rect", (0.5, -0.5, 0.5, -0.5), (-1.0, 1.0, 1.0, -1.0), (1.0, 1.0, -1.0, -1.0),
                        (1.0, 1.0, -1.0, -1.0), "drawn")
    roll, pitch = (np.max(np.abs(loops.px4_mix(rect, a))) for a in "xy")
    assert pitch == pytest.approx(1 / math.sqrt(2)) and roll == pytest.approx(pitch / 2)


def test_ardupilot_and_betaflight_mixes():
    """ArduPilot's quad X: roll, pitch and yaw factors of magnitude 0.5 (normalise_rpy_factors); its quad V's
    unequal yaw factors keep their ratio; Betaflight's and INAV's quad X +-1."""
    x = frames.ardupilot(1, 1, _fail)
    for a in "xyz":
        assert np.allclose(np.abs(loops.ardupilot_mix(x, a)), 0.5)
        assert np.allclose(np.abs(loops.bf_mix(frames.betaflight(4, "Betaflight", False, _fail), a)), 1.0)
    v = frames.ardupilot(1, 2, _fail)
    yaw = np.abs(loops.ardupilot_mix(v, "z"))
    assert yaw.max() == pytest.approx(0.5) and sorted(set(np.round(yaw / yaw.max(), 4))) == sorted(
        set(np.round(np.abs(v.yaw_factor) / np.max(np.abs(v.yaw_factor)), 4)))


def test_a_firmware_whose_mix_is_not_read_is_named():
    parts, why = loops.parts({"firmware": "indiflight", "axes": {"x": {k: {"value": 1.0} for k in ("kp", "ki", "kd")}},
                              "loop_hz": {"value": 1000.0}}, {}, "x", None)
    assert parts is None and "not read here" in why[0]
    parts, why = loops.parts({"firmware": "px4", "axes": {"x": {k: {"value": 1.0} for k in ("kp", "ki", "kd")}},
                              "loop_hz": {"value": 1000.0}, "rotors_from_ca": False}, {}, "x", None)
    assert parts is None and "CA_ROTOR" in why[0]


def test_a_sim_flights_model_predicts_another_flights_attitude_steps(tmp_path, capsys):
    """Two `excite` flights of the paper's vehicle (seeds 0 and 1): the base model identified on the first, its
    roll and pitch effectiveness within 5 % of eq. 25's 2 l / J (the truth), flying the log's own eq. 24 PIDs,
    predicts the second flight's measured attitude steps: step error under 0.08, delay and rise within 10 %."""
    logs = [tmp_path / f"excite{s}.csv" for s in (0, 1)]
    for seed, log in enumerate(logs):
        assert main(["sim", "excite", "--seed", str(seed), "--log", str(log), "--no-plot", "--quiet"]) in (0, 1)
    capsys.readouterr()
    A, B = (read_flight_log(p, min_rows=10) for p in logs)
    out, drawn = predict.cross(A, B, controller.of_table(B), Params().airframe)
    a = Params().airframe
    truth = {"x": 2.0 * a.l / a.Jxx, "y": 2.0 * a.l / a.Jyy}
    for ax in "xy":
        e = out[ax]
        assert "why" not in e, e
        assert abs(e["effectiveness"]["value"] / truth[ax] - 1.0) < 0.05, (ax, e["effectiveness"], truth[ax])
        assert e["step_error"] < 0.08, (ax, e)
        for k in ("delay_s", "rise_s"):
            assert abs(e[k]["predicted"] / e[k]["measured"] - 1.0) < 0.10, (ax, k, e[k])
        assert ax in drawn
    assert json.loads(json.dumps(out)) == out
