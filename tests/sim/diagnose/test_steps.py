"""The measured step response (sim/diagnose/steps.py, docs/steps.md): a known discrete rate loop
whose delay, natural frequency and damping are drawn from a seeded generator, driven by a stick-like
setpoint, is recovered within stated tolerances; a hover without stick input, a response the setpoint
does not drive and a log without a setpoint get the gate's reason; real Betaflight and PX4 logs get
plausible steps, ArduPilot's and INAV's shipped logs the precise reason they cannot show one; and the
command refuses a bad figure path before any work (tests/sim/diagnose/test_diagnose_errors.py draws one).
The attitude loop of this project's own `excite` flight matches the direct step of `step_roll`."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy import signal

from flightctl.cli import main
from flightctl.logfile import Table
from flightctl.sim.diagnose import steps
from helpers.real import FLIGHTS, need
from helpers.paths import DATA

FS = 500.0          # Hz: a Betaflight log's rows
SECONDS = 60.0
# What the deconvolution must recover of the drawn loop (its own step, computed here from its difference
# equation): the delay to 50 % within 2 ms (one row), the overshoot within 0.04, the rise within 10 %.
DELAY_TOL_S = 0.002
OVERSHOOT_TOL = 0.04
RISE_TOL = 0.10


def stick(rng, n: int) -> np.ndarray:
    """A pilot's rate setpoint (rad/s): holds of 0.1-0.6 s at random rates (a third of them centred), sent in
    RC frames of 100 Hz (held for 5 rows), as Betaflight logs setpoint[]."""
    u = np.zeros(n)
    k = 0
    while k < n:
        hold = int(rng.uniform(0.1, 0.6) * FS)
        u[k:k + hold] = rng.normal(0.0, 2.0) if rng.random() < 0.67 else 0.0
        k += hold
    return u[(np.arange(n) // 5) * 5]


def loop(rng):
    """A second-order rate loop with a dead time, all drawn: (b, a) of its zero-order-hold discretisation and
    the delay in rows."""
    wn = 2.0 * math.pi * rng.uniform(8.0, 15.0)
    zeta = rng.uniform(0.4, 0.8)
    b, a, _ = signal.cont2discrete(([wn * wn], [1.0, 2.0 * zeta * wn, wn * wn]), 1.0 / FS, "zoh")
    return np.ravel(b), a, int(round(rng.uniform(0.005, 0.030) * FS))


def respond(b, a, d: int, u: np.ndarray) -> np.ndarray:
    return signal.lfilter(b, a, np.concatenate([np.zeros(d), u[:u.size - d]]))


def table(t, sp, gyro, motors=True) -> Table:
    n = t.size
    cols = {"t": t}
    for i in range(1, 5):
        cols[f"P{i}"] = np.full(n, 120.0 if motors else 0.0)
    for j, ax in enumerate("xyz"):
        cols[f"setpoint_{ax}"] = sp[j]
        cols[f"gyro_{ax}"] = gyro[j]
    return Table("synthetic.csv", cols, {"format": "betaflight blackbox"}, np.arange(n) + 2)


def truth(b, a, d: int) -> dict:
    """The drawn loop's own step: delay to 50 %, rise 10-90 %, overshoot, from its difference equation
    (written here, apart from steps.metrics)."""
    n = int(0.5 * FS)
    s = respond(b, a, d, np.ones(n))
    final = s[-1]
    t = np.arange(n) / FS

    def cross(level):
        k = int(np.flatnonzero(s >= level * final)[0])
        return t[k - 1] + (level * final - s[k - 1]) / (s[k] - s[k - 1]) / FS

    return {"delay_s": cross(0.5), "rise_s": cross(0.9) - cross(0.1), "overshoot": s.max() / final - 1.0}


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_drawn_rate_loop_is_recovered_from_stick_inputs(seed):
    rng = np.random.default_rng(seed)
    n = int(SECONDS * FS)
    t = np.arange(n) / FS
    systems = [loop(rng) for _ in range(3)]
    sp = [stick(rng, n) for _ in range(3)]
    gyro = [respond(b, a, d, u) + rng.normal(0.0, 0.05, n) for (b, a, d), u in zip(systems, sp)]
    report, curves = steps.measure(table(t, sp, gyro))
    for ax, (b, a, d) in zip("xyz", systems):
        got, want = report["rate"][ax], truth(b, a, d)
        assert abs(got["delay_s"]["value"] - want["delay_s"]) < DELAY_TOL_S, (ax, got, want, d)
        assert abs(got["overshoot"]["value"] - want["overshoot"]) < OVERSHOOT_TOL, (ax, got, want)
        assert abs(got["rise_s"]["value"] / want["rise_s"] - 1.0) < RISE_TOL, (ax, got, want)
        lo, hi = got["delay_s"]["spread"]
        assert lo <= hi and got["windows"] >= 20 and abs(got["final"] - 1.0) < 0.05 and not got["limited_by_band"]
    assert "attitude" not in report and len(curves) == 3


def test_a_hover_without_stick_input_gets_the_excitation_gate():
    rng = np.random.default_rng(7)
    n = int(SECONDS * FS)
    t = np.arange(n) / FS
    b, a, d = loop(rng)
    sp = [rng.normal(0.0, 0.01, n) for _ in range(3)]       # a held hover: the setpoint barely moves
    gyro = [respond(b, a, d, u) + rng.normal(0.0, 0.05, n) for u in sp]
    report, curves = steps.measure(table(t, sp, gyro))
    for ax, name in zip("xyz", ("roll", "pitch", "yaw")):
        why = report["rate"][ax]["why"]
        assert why.startswith("0 of ") and "setpoint varying by" in why and f"stick inputs on {name}" in why, why
    assert not curves


def test_a_response_the_setpoint_does_not_drive_gets_the_coherence_gate():
    rng = np.random.default_rng(8)
    n = int(SECONDS * FS)
    t = np.arange(n) / FS
    sp = [stick(rng, n) for _ in range(3)]
    gyro = [signal.lfilter([0.05], [1.0, -0.95], rng.normal(0.0, 1.0, n)) for _ in range(3)]   # wind alone
    report, _ = steps.measure(table(t, sp, gyro))
    for ax in "xyz":
        assert "explains the response only below" in report["rate"][ax]["why"], report["rate"][ax]


def test_motors_off_and_no_setpoint_are_named():
    rng = np.random.default_rng(9)
    n = int(10 * FS)
    t = np.arange(n) / FS
    sp = [stick(rng, n) for _ in range(3)]
    report, _ = steps.measure(table(t, sp, sp, motors=False))
    assert "no 2.0 s window in the air" in report["rate"]["x"]["why"]
    cols = {k: v for k, v in table(t, sp, sp).columns.items() if not k.startswith("setpoint_")}
    report, _ = steps.measure(Table("no_sp.csv", cols, {"format": "px4 ulog"}, np.arange(n) + 2))
    assert report["rate"]["why"] == "no rate setpoint in the log: log " + steps.RATE_SETPOINT["px4 ulog"]


def _read(rel: str, index: int = 0):
    """A shipped real log's table (the `logs` extra: pyulog, pymavlink, orangebox)."""
    for module in ("pyulog", "pymavlink", "orangebox"):
        pytest.importorskip(module)
    from flightctl.sim.logs import read_foreign
    return read_foreign(str(need(FLIGHTS / rel)))[index]      # FLIGHTS / an absolute path is that path


@pytest.mark.parametrize("rel, axes", [("betaflight/LOG00037.BFL", "xyz"), ("px4/quadrotor_local.ulg", "xy")])
def test_real_rate_loops_have_plausible_steps(rel, axes):
    """A five-inch Betaflight quad and a PX4 quadrotor: delays (to 50 %) of 5-80 ms and rises of 5-150 ms, as
    multirotor rate loops have; the spread brackets the windows, and the band says how fast a rise it shows."""
    report, _ = steps.measure(_read(rel))
    for ax in axes:
        e = report["rate"][ax]
        assert 0.005 < e["delay_s"]["value"] < 0.08 and 0.005 < e["rise_s"]["value"] < 0.15, (ax, e)
        assert 0.5 <= e["final"] < 1.5 and e["overshoot"]["value"] < 1.0 and e["windows"] >= 3, (ax, e)
        assert e["coherent_to_hz"] >= 5.0 and e["fastest_rise_shown_s"] == pytest.approx(0.35 / e["coherent_to_hz"], rel=0.01)
    if rel.startswith("betaflight"):    # its 1 kHz punch-outs resolve the roll and pitch rises; the yaw's is the band's
        assert not report["rate"]["x"]["limited_by_band"] and not report["rate"]["y"]["limited_by_band"]


def test_real_logs_that_cannot_show_a_step_say_why():
    """ArduCopter's log171.bin logs RATE at 10 Hz (a rate loop's step needs 40); INAV's 16 s log sits on the
    ground (no window in the air)."""
    rate = steps.measure(_read(str(DATA / "ardupilot" / "log171.bin")))[0]["rate"]
    for ax in "xyz":
        assert rate[ax]["why"].startswith("the setpoint logged at 9.9 Hz: a rate loop's step needs 40 Hz"), rate[ax]
    inav = steps.measure(_read("inav/blackbox_log_2026-02-21_145057.TXT", 1))[0]["rate"]
    for ax in "xyz":
        assert inav[ax]["why"].startswith("no 2.1 s window in the air"), inav[ax]


def test_a_bad_steps_path_is_refused_before_any_work(tmp_path, capsys):
    out = tmp_path / "r.json"
    bad = tmp_path / "missing" / "s.png"
    log = DATA / "ardupilot" / "log171.bin"
    assert main(["diagnose", str(log), "--json", str(out), "--steps", str(bad), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--steps" in err and not out.exists(), err
    assert main(["diagnose", "--corpus", str(tmp_path), "--steps", str(tmp_path / "s.png"), "--quiet"]) == 2
    assert "--steps" in capsys.readouterr().err


def test_this_projects_attitude_loop_from_an_excite_flight_matches_its_direct_step(tmp_path, capsys):
    """The roll loop (eq. 24 on the angles) deconvolved from the logged setpoint and estimate of the `excite`
    flight, whose roll steps are a few among its other moves, against the `step_roll` flight's own step of the
    same vehicle and gains (sim/flights/metrics.py, the true state): the same rise (10-90 %) within 15 %, the
    same overshoot within 0.08 and settling (5 %) within 20 %."""
    from flightctl.logfile import read_flight_log
    log, step = tmp_path / "excite.csv", tmp_path / "step.json"
    assert main(["sim", "excite", "--log", str(log), "--no-plot", "--quiet"]) in (0, 1)   # 1: a fast touchdown
    assert main(["sim", "step_roll", "--log", str(tmp_path / "s.csv"), "--no-plot", "--quiet", "--json", str(step)]) == 0
    capsys.readouterr()
    direct = json.loads(step.read_text())["steps"][0]
    got = steps.measure(read_flight_log(log, min_rows=10))[0]["attitude"]["x"]
    assert abs(got["rise_s"]["value"] / direct["rise_s"] - 1.0) < 0.15, (got, direct)
    assert abs(got["overshoot"]["value"] - direct["overshoot"]) < 0.08, (got, direct)
    assert abs(got["settling_s"]["value"] / direct["settling_s"] - 1.0) < 0.20, (got, direct)
