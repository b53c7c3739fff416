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
from flightctl.sim.diagnose import loops, predict
from flightctl.sim.logs import controller, frames
from helpers.paths import DATA


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


def _sample_by_sample(b, k, p, chain_hz, n):
    """The loop of predict.closed_loop with loops.py's parts, one loop period at a time: the vehicle
    omega[i + 1] = omega[i] + b T u[i - k]; the rate loop's target and error low-passes, FF, D on the (filtered)
    error or on the raw gyro; the attitude loop on the estimator's angle (the filtered gyro summed)."""
    from helpers.filters import DirectForm
    from flightctl.sim.diagnose.dataset import sensor_filters
    fs = p["loop_hz"]
    T = 1.0 / fs
    f = lambda kind, hz: DirectForm(sensor_filters(((kind, hz),), fs)) if hz else (lambda x: x)
    fg, fr = f("biquad", chain_hz), f("biquad", chain_hz)
    fd, ft = f(p["d_filter"], p["d_lowpass_hz"]), f("pt1", p["target_lowpass_hz"])
    fe, fe_d = f("pt1", p["error_lowpass_hz"]), f("pt1", p["error_lowpass_hz"])
    fema = f("pt1", p.get("tau_rate_hz", 0.0))
    omega, integ, prev, angle = 0.0, 0.0, 0.0, 0.0
    u = np.zeros(n + k + 1)
    out = np.zeros(n)
    for i in range(n):
        y = fg(omega)
        if p["loop"] == "attitude":
            out[i] = angle
            e = 1.0 - angle
            integ += p["ki"] * e * T
            u[i + k] = p["kp"] * e + integ - p["kd"] * fema(y)
            angle += T * y
        else:
            out[i] = fr(omega)
            rt = ft(1.0)
            e = fe(rt - y)
            integ += p["ki"] * e * T
            xd = fe_d(p["c"] * rt - (omega if p["d_on_raw_gyro"] else y))
            d = p["kd"] * fd((xd - prev) / T)
            prev = xd
            u[i + k] = p["kf"] * rt + p["kp"] * e + integ + d
        omega += b * T * u[i]
    return out


@pytest.mark.parametrize("seed", range(4))
def test_the_general_loop_is_the_loop_simulated(seed):
    """predict.closed_loop with ArduPilot's form (target and error low-passes, D on the error, FF), PX4's (D on the
    raw gyro's own low-pass) and flightctl's attitude loop: its step equals the loop simulated sample by sample
    (to 1e-3), with the vehicle, gains, filters and delay drawn."""
    rng = np.random.default_rng(100 + seed)
    fs = float(rng.choice([400.0, 450.0, 1000.0]))
    k = int(rng.integers(1, 12))
    chain_hz = float(rng.uniform(40, 90))
    base = {"c": 0.0, "kf": 0.0, "loop_hz": fs, "d_lowpass_hz": 0.0, "d_filter": "biquad", "p_lowpass_hz": 0.0,
            "target_lowpass_hz": 0.0, "error_lowpass_hz": 0.0, "d_on_raw_gyro": False, "loop": "rate"}
    forms = [
        ({"c": 1.0, "kf": rng.uniform(0.0, 0.05), "d_filter": "pt1", "d_lowpass_hz": rng.uniform(10, 40),
          "target_lowpass_hz": rng.uniform(10, 40), "error_lowpass_hz": float(rng.choice([0.0, rng.uniform(20, 60)])),
          "kp": rng.uniform(0.05, 0.2), "ki": rng.uniform(0.05, 0.2), "kd": rng.uniform(0.001, 0.006)},
         rng.uniform(150, 400)),
        ({"d_on_raw_gyro": True, "d_lowpass_hz": rng.uniform(20, 60), "kf": rng.uniform(0.0, 0.05),
          "kp": rng.uniform(0.1, 0.2), "ki": rng.uniform(0.1, 0.3), "kd": rng.uniform(0.001, 0.004)},
         rng.uniform(150, 400)),
        ({"loop": "attitude", "tau_rate_hz": float(rng.choice([0.0, rng.uniform(20, 60)])),
          "kp": rng.uniform(3.0, 6.0), "ki": rng.uniform(0.0, 0.5), "kd": rng.uniform(0.15, 0.3)},
         rng.uniform(25, 45)),
    ]
    n_seg = 16384
    f = np.fft.rfftfreq(n_seg, 1.0 / fs)
    for form, b in forms:
        p = {**base, **form}
        for _ in range(8):          # the drawn loop made stable: its effectiveness halved until it is
            sim = _sample_by_sample(b, k, p, chain_hz, 3000)
            if np.max(np.abs(sim)) < 3.0 and abs(sim[-200:].mean() - 1.0) < 0.05:
                break
            b *= 0.5
        assert np.max(np.abs(sim)) < 3.0 and abs(sim[-200:].mean() - 1.0) < 0.05, ("not a stable loop", p, b)
        H = predict.closed_loop(f, b, k / fs, p, f"biquad {chain_hz:g}", f"biquad {chain_hz:g}")
        step = np.cumsum(np.fft.irfft(H, n_seg))[:3000]
        assert np.max(np.abs(step - sim)) < 1e-3, (p["loop"], p["d_on_raw_gyro"], np.max(np.abs(step - sim)))


def test_px4_mix_is_what_the_real_allocator_did():
    """quadrotor_local.ulg (PX4 on an FMU-v6C, CA_ROTOR* quad X): each logged actuator_motors.control[i],
    regressed on the torque and thrust setpoints of the same allocation cycle (their timestamp_sample), has
    the module's mix of the log's own rotors as its torque slopes (FRD to the project's frame: roll as it is,
    pitch and yaw reversed), within 0.03, R^2 over 0.999: the allocation's normalisation as it flew."""
    pyulog = pytest.importorskip("pyulog")
    from helpers.real import FLIGHTS, need
    from flightctl.sim.logs import read_foreign
    path = str(need(FLIGHTS / "px4" / "quadrotor_local.ulg"))
    table = read_foreign(path)[0]
    rot = [tuple(float(v) for v in r.split()) for r in table.meta["rotors"].split(";")]
    layout = frames.Frame("log", tuple(r[0] for r in rot), tuple(r[1] for r in rot), tuple(r[2] for r in rot),
                          tuple(r[2] for r in rot), table.meta["rotors_source"])
    c = controller.of_table(table)
    mix = {a: np.array(predict.loop_parts(c, table.meta, a, layout)[0]["mix"]) for a in "xyz"}
    d = {x.name: x.data for x in pyulog.ULog(path).data_list if x.multi_id == 0}
    tq, th, am = d["vehicle_torque_setpoint"], d["vehicle_thrust_setpoint"], d["actuator_motors"]
    index = {s: i for i, s in enumerate(tq["timestamp_sample"])}
    j = np.array([index.get(s, -1) for s in am["timestamp_sample"]])
    same = j >= 0
    assert same.mean() > 0.95
    j = j[same]
    X = np.column_stack([tq["xyz[0]"][j], tq["xyz[1]"][j], tq["xyz[2]"][j], th["xyz[2]"][j], np.ones(j.size)])
    for i in range(4):
        y = am[f"control[{i}]"][same]
        run = y > 0.05                                  # armed and spinning
        co, *_ = np.linalg.lstsq(X[run], y[run], rcond=None)
        r2 = 1.0 - np.var(y[run] - X[run] @ co) / np.var(y[run])
        assert r2 > 0.999, (i, r2)
        assert np.allclose(co[:3], [mix["x"][i], -mix["y"][i], -mix["z"][i]], atol=0.03), (i, co, mix)


def test_real_px4_and_inav_logs_get_their_loop_or_the_datas_reason():
    """quadrotor_local.ulg's measured rate steps get a prediction entry whose reason is the data's (its motor
    commands at 10 Hz, the base model's timing needs 48 Hz), no longer an unread mix; INAV's 10-inch log's loop is
    formed (its gains in shares of the motor range, quad X +-1, its loop rate): the prediction waits on a step."""
    pytest.importorskip("orangebox")
    from helpers.real import FLIGHTS, need
    from flightctl.sim.logs import read_foreign
    px4 = read_foreign(str(need(FLIGHTS / "px4" / "quadrotor_local.ulg")))[0]
    out, drawn = predict.held_out(px4, controller.of_table(px4), Params().airframe)
    for ax in "xy":
        assert out[ax]["why"].startswith("the motor outputs logged at 10.0 Hz"), out[ax]
    assert not drawn
    inav = read_foreign(str(need(FLIGHTS / "inav" / "blackbox_log_2026-02-21_145057.TXT")))[1]
    c = controller.of_table(inav)
    layout = frames.betaflight(4, "INAV", None, _fail)
    for ax in "xyz":
        p, missing = predict.loop_parts(c, inav.meta, ax, layout)
        assert p is not None and np.allclose(np.abs(p["mix"]), 1.0) and p["R"] == 255.0, (ax, missing)
        assert p["kp"] == c["axes"][ax]["kp"]["value"] > 0 and p["loop_hz"] == c["loop_hz"]["value"]
        assert any("feed-forward" in m for m in missing)


def test_diagnose_predicts_a_sim_flights_held_out_attitude_steps(tmp_path, capsys):
    """`flightctl diagnose LOG --json` on a flight of roll and pitch steps in both its halves
    (tests/data/plans/steps-both-halves.toml): REPORT.json's steps[0].attitude.<axis>.predicted, the first
    half's model flying the log's eq. 24 PIDs on the second half, agrees with the measured step on roll and
    pitch (step error under 0.08, delay within 10 %, `agrees`), with the effectiveness 2 l / J within 5 %."""
    plan = DATA / "plans" / "steps-both-halves.toml"
    log, out = tmp_path / "both.csv", tmp_path / "r.json"
    assert main(["sim", "--plan", str(plan), "--log", str(log), "--no-plot", "--quiet"]) == 0
    assert main(["diagnose", str(log), "--json", str(out), "--quiet"]) in (0, 1)
    capsys.readouterr()
    att = json.loads(out.read_text())["steps"][0]["attitude"]
    a = Params().airframe
    for ax, J in (("x", a.Jxx), ("y", a.Jyy)):
        p = att[ax]["predicted"]
        assert p["identified_on"].endswith("before 23.0 s") and p["checked_on"].endswith("from 23.0 s"), p
        assert p["step_error"] < 0.08 and p["agrees"], (ax, p)
        assert abs(p["delay_s"]["predicted"] / p["delay_s"]["measured"] - 1.0) < 0.10, (ax, p["delay_s"])
        assert abs(p["effectiveness"]["value"] / (2.0 * a.l / J) - 1.0) < 0.05, (ax, p["effectiveness"])
