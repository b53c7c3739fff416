"""The static tier (docs/diagnose.md, "Static tier") on this project's simulated flights written as
ArduCopter DataFlash at ArduPilot's default rates (IMU 25 Hz, RCOU, BAT and ATT 10 Hz; sim/logs/dfwrite.py,
read back through pymavlink): the dynamic tier refuses them for their rate, the static tier answers, with
effects drawn at random from seeded generators and not told to the diagnosis:

- a weak motor (which, and how weak: `flightctl sim --effect motor_weak`) is named as that motor with its
  thrust for its command within 3 % of the drawn scale;
- a centre of mass off the middle (`--effect com_offset`, direction and size) is named as one, at the drawn
  offset within 0.01 arm lengths, and not as a weak motor;
- an internal resistance hidden in the battery's voltage (V - R I on the logged current) is found on top of
  the simulated pack's own (SimBattery.R_INT) within 2 mOhm;
- nothing is named on the untouched flight (null test), whose pack resistance is the simulator's.

The flight is the paper's test flight (86 s: hover, steps, a climb and a descent: the current moves). The
current the log carries is the simulator's own definition (SimBattery: the rotors' torque times speed, eq.
27-28, over the voltage at its efficiency) computed from the logged commands through eq. 26.
"""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from flightctl.cli import main
from flightctl.logfile import read_flight_log
from flightctl.params import Airframe
from flightctl.sim.sweeps import fleet_flown
from flightctl.sim.sweeps.fleet_flown import AP_FROM_SIM, LOG_BITMASK, PWM
from flightctl.sim.world.power import SimBattery, power_of_commands
from flightctl.sim.logs.dfwrite import DataFlash

pytest.importorskip("pymavlink")
A = Airframe()
IMU_EVERY, SLOW_EVERY = 18, 45        # of the simulator's 450 Hz rows: 25 Hz and 10 Hz


def current(log) -> np.ndarray:
    """The pack's current (A) on each row: SimBattery's definition on the logged commands (eq. 26-28)."""
    return power_of_commands(np.vstack([log[f"P{i}"] for i in range(1, 5)]), A) / log["battery_v"]


def vibe(log) -> np.ndarray:
    """(3, n) ArduPilot's VIBE of the logged accelerometer (sim/sweeps/fleet_flown.py's)."""
    return fleet_flown.vibe(np.vstack([log[c] for c in ("acc_x", "acc_y", "acc_z")]), A.loop_hz)


def arducopter(log, path, r_hidden: float = 0.0, clips=None, baro=None, imu: bool = True):
    """The flight as an ArduCopter 4.x log at the default rates, the thrust curve declared as eq. 26
    (MOT_THST_EXPO 1 above MOT_SPIN_MIN = h2 / 255), the pack's voltage lowered by r_hidden I; with
    `clips` ((3, n) cumulative counts per IMU), VIBE at 10 Hz; with `baro` ((n,) m), BARO at 10 Hz;
    `imu` False: LOG_BITMASK without its IMU bit (7), no IMU messages."""
    f = DataFlash(without=() if imu else ("IMU",))
    f.add("MSG", 1000, "ArduCopter V4.5.7 (1a2b3c4d)")
    params = {"FRAME_CLASS": 1, "FRAME_TYPE": 0, "MOT_PWM_MIN": PWM[0], "MOT_PWM_MAX": PWM[1], "MOT_BAT_VOLT_MAX": 16.8,
              "MOT_THST_EXPO": 1.0, "MOT_SPIN_MIN": A.h2 / 255.0, "MOT_SPIN_MAX": 1.0,
              "LOG_BITMASK": LOG_BITMASK if imu else LOG_BITMASK & ~128}
    params.update({f"SERVO{m}_FUNCTION": 32 + m for m in range(1, 5)})
    for k, v in params.items():
        f.add("PARM", 1000, k, float(v))
    f.add("ARM", 2000, 1)
    cur = current(log)
    levels = vibe(log) if clips is not None else None
    for k in range(len(log)):
        if k % IMU_EVERY and k % SLOW_EVERY:
            continue
        us = int(round((10.0 + log["t"][k]) * 1e6))
        if k % IMU_EVERY == 0:
            f.add("IMU", us, 0, log["gyro_x"][k], -log["gyro_y"][k], -log["gyro_z"][k],
                  log["acc_x"][k], -log["acc_y"][k], -log["acc_z"][k])
        if k % SLOW_EVERY == 0:
            pwm = [int(round(PWM[0] + log[f"P{s}"][k] / 255.0 * (PWM[1] - PWM[0]))) for s in AP_FROM_SIM] + [0] * 10
            f.add("RCOU", us - 5, *pwm)
            f.add("BAT", us, 0, float(log["battery_v"][k] - r_hidden * cur[k]), float(cur[k]))
            f.add("ATT", us, 0.0, math.degrees(log["roll"][k]), 0.0, -math.degrees(log["pitch"][k]), 0.0,
                  -math.degrees(log["yaw"][k]) % 360.0)
            if baro is not None:
                f.add("BARO", us, 0, float(baro[k]))
            if clips is not None:
                f.add("VIBE", us, *(float(v) for v in levels[:, k]), *(int(c) for c in clips[:, k]))
    path.write_bytes(f.bytes())
    return path


def fly(tmp, name: str, *effects: str):
    csv = tmp / f"{name}.csv"
    args = ["sim", "paper", "--log", str(csv), "--no-plot", "--quiet", "--seed", "5"]
    for e in effects:
        args += ["--effect", e]
    assert main(args) == 0
    return read_flight_log(csv)


def diagnose(path, tmp) -> dict:
    out = tmp / (path.stem + ".json")
    assert main(["diagnose", str(path), "--json", str(out), "--quiet"]) == 0
    return json.loads(out.read_text())


@pytest.fixture(scope="module")
def tmp(tmp_path_factory):
    return tmp_path_factory.mktemp("static_sim")


@pytest.fixture(scope="module")
def untouched(tmp):
    log = fly(tmp, "plain")
    return log, diagnose(arducopter(log, tmp / "plain.bin"), tmp)


def test_a_default_rate_log_gets_the_static_tier_and_keeps_the_advice(untouched):
    _, rep = untouched
    assert rep["tier"] == "static" and rep["cause"] == "none" and rep["parameters"] == {} and rep["candidates"] == []
    assert "25.0 Hz: too slow" in rep["tier_why"] and "IMU_FAST" in rep["tier_why"]
    st = rep["static"]
    assert st["rates"]["sensors_hz"] == pytest.approx(25, abs=1) and st["rates"]["motors_hz"] == pytest.approx(10, abs=1)
    assert "MOT_THST_EXPO 1" in st["thrust_curve"]
    # eq. 26 at the simulator's own hover command (h1, h2 of the airframe): the thrust asked for against full
    P_hover = A.h2 + math.sqrt(A.M * A.g / 4.0 / A.h1)
    expected = ((P_hover - A.h2) / (255.0 - A.h2)) ** 2
    h = st["hover"]
    assert h["passed"] and h["thrust_share"] == pytest.approx(expected, rel=0.05), (h, expected)


def test_nothing_is_named_on_the_untouched_flight_and_its_pack_is_the_simulators(untouched):
    st = untouched[1]["static"]
    assert st["pattern"]["verdict"] == "none", st["pattern"]
    assert st["motors"]["drifting"] == [] and np.allclose(st["motors"]["share"], 1.0, atol=0.03)
    r = st["battery"]["resistance"]
    assert r["passed"], r["check"]
    assert abs(r["ohm"] - SimBattery.R_INT) <= 0.003 + 2 * r["stderr"], r


@pytest.mark.parametrize("seed", [1, 2])
def test_a_weak_motor_flown_in_the_simulator_is_named_with_its_size(tmp, seed):
    rng = np.random.default_rng(3500 + seed)
    motor, scale = int(rng.integers(1, 5)), float(rng.uniform(0.75, 0.92))
    log = fly(tmp, f"weak{seed}", f"motor_weak:motor={motor},scale={scale:.4f}")
    st = diagnose(arducopter(log, tmp / f"weak{seed}.bin"), tmp)["static"]
    ap = AP_FROM_SIM.index(motor) + 1                       # the weak motor's number in the ArduPilot log
    p = st["pattern"]
    assert p["verdict"] == f"weak motor {ap}", (motor, ap, scale, p)
    fit = next(f for f in p["hypotheses"] if f["hypothesis"] == f"weak motor {ap}")
    assert fit["thrust_scale"] == pytest.approx(scale, abs=0.03), (scale, fit)


@pytest.mark.parametrize("seed", [1, 2])
def test_a_centre_of_mass_off_the_middle_is_sized_and_not_called_a_weak_motor(tmp, seed):
    rng = np.random.default_rng(3600 + seed)
    r, a = float(rng.uniform(0.04, 0.10)), float(rng.uniform(0.0, 2.0 * np.pi))
    dx, dy = r * math.cos(a), r * math.sin(a)               # arm lengths
    log = fly(tmp, f"com{seed}", f"com_offset:dx={dx * A.l:.5f},dy={dy * A.l:.5f}")
    st = diagnose(arducopter(log, tmp / f"com{seed}.bin"), tmp)["static"]
    p = st["pattern"]
    assert p["verdict"] == "centre of mass", p
    assert np.allclose([p["com"]["dx"], p["com"]["dy"]], [dx, dy], atol=0.01), ((dx, dy), p["com"])


def test_an_internal_resistance_hidden_in_the_voltage_is_found_on_top_of_the_packs(tmp, untouched):
    log, rep = untouched
    R = float(np.random.default_rng(3700).uniform(0.01, 0.05))
    st = diagnose(arducopter(log, tmp / "resistance.bin", r_hidden=R), tmp)["static"]
    before, after = rep["static"]["battery"]["resistance"], st["battery"]["resistance"]
    assert after["passed"], after["check"]
    assert after["ohm"] - before["ohm"] == pytest.approx(R, abs=0.002), (R, before, after)


def test_vibe_and_its_clip_counts_are_reported_against_ardupilots_guidance(tmp, untouched):
    log, _ = untouched
    rng = np.random.default_rng(3800)
    n = len(log)
    clips = np.zeros((3, n), int)
    for i in range(3):                          # clip events at random rows of each IMU, drawn
        events = rng.integers(0, n, int(rng.integers(0, 150)))
        clips[i] = np.cumsum(np.bincount(events, minlength=n))
    st = diagnose(arducopter(log, tmp / "vibe.bin", clips=clips), tmp)["static"]
    v = st["vibration"]
    assert v["source"].startswith("VIBE") and v["physical"].endswith("passed")
    total = int(clips[:, -1].sum() - clips[:, 0].sum())
    assert v["clips"] == total
    levels = vibe(log)
    t = log["t"]
    flying = (t > 5.0) & (t < 75.0)             # well inside the airborne part of the paper's flight
    for j, a in enumerate("xyz"):
        assert v["mean"][a] == pytest.approx(float(levels[j, flying].mean()), rel=0.15), (a, v)
    assert v["acceptable"] == (max(v["p95"].values()) < 60.0 and total < 100)


def test_a_static_only_log_plots_what_was_read_and_no_residuals(tmp, untouched):
    log, _ = untouched
    path = arducopter(log, tmp / "plot.bin")
    prefix = tmp / "p"
    assert main(["diagnose", str(path), "--json", str(tmp / "plot.json"), "--plot", str(prefix), "--quiet"]) == 0
    assert (tmp / "p-read-1.png").read_bytes().startswith(b"\x89PNG")
    assert not (tmp / "p-residuals.png").exists() and not (tmp / "p-explained.png").exists()
    # --validate predicts with the dynamic tier's model, which a static-only log has not: refused, nothing written
    assert main(["diagnose", str(path), "--json", str(tmp / "v.json"), "--validate", str(path), "--quiet"]) == 2
    assert not (tmp / "v.json").exists()


@pytest.mark.parametrize("line", ["expo 2 spin 0 1", "expo 0.5 spin 0.4 0.2", "curve 1 2 3"])
def test_a_thrust_curve_that_is_not_one_is_refused_in_one_line_before_any_work(tmp, untouched, capsys, line):
    log, _ = untouched
    text = (tmp / "plain.csv").read_text()
    bad = tmp / "badcurve.csv"
    bad.write_text(f"# thrust_curve: {line}\n" + text)
    capsys.readouterr()
    assert main(["diagnose", str(bad), "--json", str(tmp / "bad.json")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "thrust_curve" in err and "badcurve.csv" in err, err
    assert not (tmp / "bad.json").exists()


def test_the_projects_own_log_reads_the_same_hover_through_eq_26(tmp, untouched):
    """The simulator's own CSV (this project's vehicle: eq. 26 with the airframe's h2, the paper's + layout)
    at its 450 Hz gives the hover and shares the default-rate ArduCopter log of the same flight gives."""
    from flightctl.sim.diagnose.data import load_file
    from flightctl.sim.diagnose.static import static_tier
    log, rep = untouched
    st = static_tier([log], [load_file(log, A)], A)
    assert st["thrust_curve"].startswith("eq. 26 with the airframe's h2")
    assert st["hover"]["thrust_share"] == pytest.approx(rep["static"]["hover"]["thrust_share"], rel=0.02)
    assert st["pattern"]["verdict"] == "none" and st["pattern"]["com"]["unit"] == "m"
