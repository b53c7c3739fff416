"""predict.py: the rate loop closed around the base model, and the CS110 cross-prediction (docs/steps.md,
"Predicted and measured")."""
import math

import numpy as np
import pytest

from flightctl.sim.diagnose import predict, steps
from flightctl.sim.diagnose.dataset import sensor_filters
from helpers.paths import DATA
from helpers.filters import DirectForm


def _simulated_step(b, k, parts, gyro_hz, n):
    """The loop's unit step, sample by sample: the firmware's PID (P and I on the error, D on c r - y through its
    biquad) on a pt1-filtered gyro, the vehicle omega[i + 1] = omega[i] + b T u[i - k]."""
    fs = parts["loop_hz"]
    T = 1.0 / fs
    fg = DirectForm(sensor_filters((("pt1", gyro_hz),), fs))
    fr = DirectForm(sensor_filters((("pt1", gyro_hz),), fs))
    fd = DirectForm(sensor_filters((("biquad", parts["d_lowpass_hz"]),), fs))
    omega, integ, prev = 0.0, 0.0, 0.0
    u = np.zeros(n + k + 1)
    out = np.zeros(n)
    for i in range(n):
        out[i] = fr(omega)
        y = fg(omega)
        e = 1.0 - y
        integ += parts["ki"] * e * T
        rd = parts["c"] * 1.0 - y
        d = parts["kd"] * fd((rd - prev) / T)
        prev = rd
        u[i + k] = parts["kp"] * e + integ + d
        omega += b * T * u[i]
    return out


@pytest.mark.parametrize("seed", range(4))
def test_closed_loop_is_the_loop_simulated(seed):
    """The frequency response closed_loop gives is the loop's: its step (the inverse FFT's running sum) equals a
    sample-by-sample simulation of the same loop, with the vehicle, the gains and the delay drawn."""
    rng = np.random.default_rng(seed)
    fs = 2000.0
    b = rng.uniform(300.0, 1500.0)                 # rad/s^2 per share
    k = int(rng.integers(2, 30))                   # the delay in loop periods
    parts = {"kp": rng.uniform(0.01, 0.03), "ki": rng.uniform(0.05, 0.3), "kd": rng.uniform(1e-4, 6e-4),
             "c": float(rng.choice([0.0, 0.6, 1.0])), "loop_hz": fs, "d_lowpass_hz": rng.uniform(60, 150),
             "p_lowpass_hz": 0.0}
    gyro_hz = rng.uniform(60, 120)
    n_seg = 16384
    f = np.fft.rfftfreq(n_seg, 1.0 / fs)
    H = predict.closed_loop(f, b, k / fs, parts, f"pt1 {gyro_hz:g}", f"pt1 {gyro_hz:g}")
    step = np.cumsum(np.fft.irfft(H, n_seg))[:4000]
    sim = _simulated_step(b, k, parts, gyro_hz, 4000)
    assert np.max(np.abs(sim)) < 3.0 and abs(sim[-200:].mean() - 1.0) < 0.05, "the drawn loop is not a stable one"
    assert np.max(np.abs(step - sim)) < 1e-3


def test_points_to_names_the_part():
    """A prediction slower in delay and rise alike is the effectiveness; a delay alone, the timing; an overshoot, the damping."""
    def entry(delay, rise, over):
        m = {"delay_s": (0.010, [0.009, 0.011]), "rise_s": (0.020, [0.018, 0.022]), "overshoot": (0.05, [0.03, 0.07])}
        out = {k: {"predicted": p, "measured": v, "spread": s} for (k, (v, s)), p in zip(m.items(), (delay, rise, over))}
        excess = {k: max(d["spread"][0] - d["predicted"], d["predicted"] - d["spread"][1], 0.0) /
                  (d["spread"][1] - d["spread"][0]) for k, d in out.items()}
        return predict._points_to(out, excess)
    assert entry(0.030, 0.060, 0.05) == "rise_s"
    assert entry(0.030, 0.021, 0.05) == "delay_s"
    assert entry(0.010, 0.020, 0.40) == "overshoot"
    assert entry(0.0101, 0.0199, 0.06) is None


CS110 = DATA / "pid-analyzer"


@pytest.fixture(scope="module")
def cs110():
    """PID-Analyzer's CS110 flown with two tunes (Betaflight 3.1.5: no setpoint[] logged, bfrates.py gives it)."""
    pytest.importorskip("orangebox")
    from flightctl.sim.logs import read_foreign
    return {name: read_foreign(str(CS110 / f"{name}.BBL"))[0] for name in ("example_smooth_tune", "better_tune")}


@pytest.mark.slow
def test_cs110_setpoint_is_the_one_the_pid_took(cs110):
    """The setpoint computed from rcCommand through 3.1's rate curve is the PID's: the logged P term (axisP over
    the mixer's 1000, pid.c:248 of v3.1.5: Kp (setpoint - gyro)) regressed on the setpoint and the gyro apart
    has the setpoint's coefficient equal and opposite to the gyro's, on roll and pitch (yaw's P goes through a
    pt1), and the two explain it. (Their common slope is 0.93-0.97 of the header's P in physical units on these
    two logs, below the TPA breakpoint: not this test's question.)"""
    for name, tab in cs110.items():
        low = tab["rc_throttle"] < 0.5
        for ax in "xy":
            X = np.column_stack([tab[f"setpoint_{ax}"][low], tab[f"gyro_{ax}"][low]])
            p = tab[f"pid_p_{ax}"][low]
            (ks, kg), *_ = np.linalg.lstsq(X, p, rcond=None)
            r2 = 1.0 - float(np.sum((p - X @ [ks, kg]) ** 2) / np.sum((p - p.mean()) ** 2))
            assert ks == pytest.approx(-kg, rel=0.02), (name, ax, ks, kg)
            assert r2 > 0.95, (name, ax, r2)


@pytest.mark.slow
def test_cs110_cross_prediction(cs110, capsys):
    """Identified on the smooth tune's log, the better tune's steps predicted with its own gains: each roll and pitch
    prediction beside its measured step with its figures, and its own gains predict its steps at least as well
    as the other tune's gains would, its delay better (the gains are what differs between the two flights). The model's effectiveness is
    the loop fit's on the smooth log's own steps (loopfit.py): the prediction agrees within the step error
    AGREE_ERROR on roll and pitch (0.07 and 0.12 measured), and the fitted effectiveness is several times the
    direct regression's (1.8x roll, 5.2x pitch on this log: the closed loop's bias)."""
    from flightctl import params as paramfile
    from flightctl.sim.logs import controller
    a = paramfile.load(None).airframe
    smooth, better = cs110["example_smooth_tune"], cs110["better_tune"]
    model, own, _ = predict.cross_model(smooth, better, controller.of_table(better), a)
    assert not isinstance(model, str), model
    other, _ = predict.predict(model, controller.of_table(smooth), better, smooth.path, better.path)
    with capsys.disabled():
        for ax in steps.AXES:
            print(f"\nCS110 {steps.NAMES[ax]}: " + steps.prediction_text(own[ax]))
    for ax in ("x", "y"):
        e = own[ax]
        assert "why" not in e, e
        assert math.isfinite(e["step_error"]) and e["controller"]["kp"] == controller.of_table(better)["axes"][ax]["kp"]["value"]
        # the gains move the delay most (own 9.5/10.2 ms, the other tune's 11.4/12.5, measured 6.4/7.4): its own
        # gains' delay is the nearer, and its step error no worse (0.069 against 0.073 roll, 0.115 both pitch)
        near = lambda x: abs(x["delay_s"]["predicted"] - x["delay_s"]["measured"])
        assert near(e) < near(other[ax]), (ax, e["delay_s"], other[ax]["delay_s"])
        assert e["step_error"] <= other[ax]["step_error"] + 0.005, (ax, e["step_error"], other[ax]["step_error"])
        assert e["step_error"] < predict.AGREE_ERROR, (ax, e["step_error"])
        assert e["effectiveness"]["closed_loop_factor"] > 1.3, (ax, e["effectiveness"])
        for k in ("delay_s", "rise_s", "overshoot"):
            assert e[k]["predicted"] is not None and e[k]["measured"] is not None
    assert own["z"].get("why") or math.isfinite(own["z"]["step_error"])


@pytest.mark.slow
def test_diagnose_reports_and_draws_the_prediction(cs110, tmp_path):
    """`flightctl diagnose LOG --json --steps` on the smooth tune's log: each rate axis with a measured step has its
    `predicted` entry (the first half's model on the second half, its agreement figures) and the figure is written."""
    import json

    from flightctl.cli import main
    out, fig = tmp_path / "r.json", tmp_path / "s.png"
    assert main(["diagnose", str(CS110 / "example_smooth_tune.BBL"), "--json", str(out), "--steps", str(fig),
                 "--quiet"]) == 0
    rate = json.loads(out.read_text())["steps"][0]["rate"]
    t = cs110["example_smooth_tune"]["t"]
    cut = f"{t[0] + predict.SPLIT * (t[-1] - t[0]):.1f} s"
    for ax in ("x", "y"):
        p = rate[ax]["predicted"]
        assert p["checked_on"].endswith(f"from {cut}") and p["identified_on"].endswith(f"before {cut}")
        assert p["step_error"] > 0 and p["delay_s"]["measured"] is not None and "agrees" in p
    assert fig.stat().st_size > 10_000


@pytest.mark.slow
def test_the_linearised_effectiveness_is_what_a_plain_regression_sees(cs110):
    """The effectiveness the loop takes (the base model linearised through the mix, b per share of the mixer) is
    the slope an independent regression finds, per P unit of the mix's sum of the commands (sum_i m_i P_i, which
    a share u moves by 4 R u: b / (4 R)): the angular acceleration (12 Hz low-pass, differentiated) on that sum
    at its best delay, on the smooth tune's first half (roll, pitch)."""
    from scipy import signal

    from flightctl import params as paramfile
    first, _, _ = predict.halves(cs110["example_smooth_tune"])
    vehicle, declared = predict.base_model(first, paramfile.load(None).airframe)
    t = first["t"]
    fs = 1.0 / float(np.median(np.diff(t)))
    P = np.vstack([first[f"P{i}"] for i in range(1, 5)])
    run = (P > 10).all(axis=0)
    b, a = signal.butter(2, 12.0, fs=fs)
    x, y = np.array(declared.x), np.array(declared.y)
    for ax, mix in (("x", y / np.abs(y).max()), ("y", -x / np.abs(x).max())):
        wd = np.gradient(signal.filtfilt(b, a, first[f"gyro_{ax}"]), t)[run]
        drive = signal.filtfilt(b, a, mix @ P)
        fits = []
        for d in range(0, int(0.06 * fs), max(1, int(0.0025 * fs))):
            X = np.column_stack([np.roll(drive, d)[run], np.ones(run.sum())])
            co, res, *_ = np.linalg.lstsq(X, wd, rcond=None)
            fits.append((float(res[0]), float(co[0])))
        slope = min(fits)[1]
        model = predict.effectiveness(vehicle, declared, ax) / (4 * predict.P_RANGE)   # per P unit of the mix's sum
        assert model == pytest.approx(slope, rel=0.15), (ax, model, slope)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_log_that_ends_in_a_crash_is_taken_to_before_it(seed):
    """A flight whose attitude swings ever wider (an unstable loop) until it tilts past the crash limit at a time
    drawn at random, on roll or on pitch: the rows kept end CRASH_MARGIN_S before the first row past the limit,
    the crash's time is that row's; a flight that never passes the limit is kept whole."""
    from flightctl.logfile import Table
    rng = np.random.default_rng(seed)
    fs, t_c = 450.0, rng.uniform(5.0, 40.0)
    t = np.arange(0.0, t_c + 3.0, 1.0 / fs)
    grow = np.exp((t - t_c) * rng.uniform(0.5, 2.0))               # the swing's envelope: 1 at t_c
    swing = predict.CRASH_TILT * grow * np.sin(2 * np.pi * rng.uniform(2.0, 8.0) * t)
    axis, other = ("roll", "pitch") if rng.random() < 0.5 else ("pitch", "roll")
    cols = {"t": t, axis: swing, other: 0.1 * rng.standard_normal(t.size)}
    table = Table("f.csv", cols, {}, np.arange(t.size) + 10)
    kept, crash = predict.before_crash(table)
    first = t[np.flatnonzero(np.abs(swing) > predict.CRASH_TILT)[0]]
    assert crash == first and t_c - 0.5 < crash <= t[-1]
    assert kept["t"][-1] < crash - predict.CRASH_MARGIN_S <= kept["t"][-1] + 1.0 / fs + 1e-9
    assert len(kept) == kept["t"].size and np.array_equal(kept[axis], swing[: kept["t"].size])
    calm = Table("g.csv", {"t": t, "roll": 0.5 * swing / grow, "pitch": cols[other]}, {}, np.arange(t.size))
    assert predict.before_crash(calm) == (calm, None)
    stop = np.flatnonzero(np.abs(swing) > predict.CRASH_TILT)[0]          # a loop that stops itself at the limit
    cut = Table("h.csv", {k: v[:stop] for k, v in cols.items()}, {}, np.arange(stop))
    assert abs(swing[stop - 1]) > 0.5 * predict.CRASH_TILT                # its last row tilted: it ended over
    kept, crash = predict.before_crash(cut)
    assert crash == t[stop - 1] and kept["t"][-1] < crash - predict.CRASH_MARGIN_S
    level = Table("l.csv", {k: v[:stop] * (0.4 if k == axis else 1.0) for k, v in cols.items()}, {}, np.arange(stop))
    assert predict.before_crash(level)[1] is None                         # under half the limit: landed or flying
