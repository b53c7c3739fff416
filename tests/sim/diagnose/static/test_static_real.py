"""The static tier (docs/diagnose.md, "Static tier") on real flight logs of other vehicles
(../shared/data/real/flights, tests/helpers/real.py), with effects hidden in them, drawn from seeded generators and
not told to the diagnosis, at the log's full rate (the static tier's own function on the imported table)
and decimated to ArduPilot's default rates (gyro and accelerometer 25 Hz, motors and battery 10 Hz, held:
`flightctl diagnose`, which reaches the static tier only). A real vehicle carries its own imbalance, so
each finding is judged against the untouched log's own finding plus what was hidden:

- a motor made weaker (scale 0.75-0.92): its command raised so that its thrust, through the thrust curve
  the log declares (drawn at random too: ArduPilot's MOT_THST_EXPO form), is unchanged; its thrust for its
  command against the others' comes out at the drawn scale within 0.02 (0.03 decimated);
- a centre of mass moved (0.04-0.10 arm lengths, any direction): the thrusts redistributed so that the
  torques about the new centre are the logged ones (the roll and pitch rows of eq. 25, yaw and total kept);
  the centre of mass moves by the drawn offset within 0.01 arm lengths;
- an internal resistance (10-50 mOhm): the voltage lowered by R I; found on top of the pack's own
  within 2 mOhm;
- the same rewriting with nothing hidden changes nothing (the null test);
- where the log has rotor speeds (INDIflight's ESC telemetry) a hidden weak motor is called a weak motor
  by them (it turns slower for its command than the others), with its size, also when a centre of mass
  moved away from it takes its share in hover back to the mean's;
- the hover figures on the shipped log that vibrates most (LOG00230) are those of its accelerometer
  low-passed, and a vibration of drawn size added does not move them (ratios of means);
- a yaw split beyond a trim is "not physical" inside a mix of causes too;
- a logged current that does not follow the throttle is no current sensor (no resistance fitted);
- an ArduCopter quad V (log171.bin with its FRAME set to 2) gets both tiers, its frame said, the static
  figures those of its positions.
"""
from __future__ import annotations

import json

import numpy as np
import pytest

from flightctl.cli import main
from flightctl.logfile import read_flight_log
from flightctl.params import Airframe
from flightctl.sim.diagnose.data import FOREIGN_COLUMNS, load_file
from flightctl.sim.diagnose.static import STATIC_COLUMNS, static_tier
from flightctl.sim.diagnose.static.curve import parse
from helpers.real import FLIGHTS, need, rows_and_header, write

LOGS = {"LOG00037": "betaflight/LOG00037.BFL", "LOG00230": "indiflight/LOG00230.BFL",
        "btfl_002": "betaflight/btfl_002.bbl"}
WITH_CURRENT = {"LOG00037"}
_cache: dict = {}


@pytest.fixture(scope="module")
def tmp(tmp_path_factory):
    return tmp_path_factory.mktemp("static_real")


def imported(name: str, tmp, rng) -> tuple:
    """(metadata with a thrust curve drawn from `rng` declared, header, rows) of the log imported as CSV."""
    if name not in _cache:
        csv = tmp / f"{name}.csv"
        assert main(["log", "import", str(need(FLIGHTS / LOGS[name])), str(csv), "--quiet"]) == 0
        _cache[name] = csv.read_text()
    meta, names, rows = rows_and_header(_cache[name])
    curve = f"expo {rng.uniform(0.5, 1.0):.3f} spin {rng.uniform(0.0, 0.1):.3f} 1"
    return meta + [f"# thrust_curve: {curve}"], names, rows


def columns(names, rows, cols) -> np.ndarray:
    j = [names.index(c) for c in cols]
    return np.array([[float(r[k]) if r[k] not in ("", "nan") else np.nan for k in j] for r in rows]).T


def put(names, rows, cols, values) -> None:
    for c, v in zip(cols, values):
        k = names.index(c)
        for r, x in zip(rows, v):
            if np.isfinite(x):
                r[k] = f"{x:.7g}"


MOTORS = ("P1", "P2", "P3", "P4")


def curve_of(meta):
    return parse(next(m for m in meta if m.startswith("# thrust_curve:")).split(":", 1)[1].strip(), "test", None)


def weaken(meta, names, rows, motor: int, scale: float) -> None:
    """Motor `motor` gives `scale` of the thrust its command asks for: its command asks for 1/scale of it."""
    c = curve_of(meta)
    P = columns(names, rows, [f"P{motor}"])[0]
    on = P > 0
    P[on] = np.minimum(255.0, c.command(c.thrust(P[on]) / scale))
    put(names, rows, [f"P{motor}"], [np.where(on, P, np.nan)])


def speed_line(meta, names, rows):
    """The log's own rotors' speed per command (`curve.speed_curve` on its airborne rows, as the static tier
    finds it), or None without rotor speeds."""
    if "omega1" not in names:
        return None
    import tempfile
    from pathlib import Path
    from flightctl.sim.diagnose.static.curve import speed_curve
    with tempfile.TemporaryDirectory() as d:
        table = read_flight_log(write(meta, names, rows, Path(d) / "line.csv"), extra=FOREIGN_COLUMNS)
        return speed_curve([load_file(table, Airframe())])


def move_com(meta, names, rows, dx: float, dy: float) -> None:
    """The centre of mass at (dx, dy) arm lengths: sum_i (y_i - dy) f'_i = sum_i y_i f_i and the same in x,
    the yaw torque and the total thrust kept; the rotors' speeds follow their commands on the log's own
    speed-per-command line (eq. 26 and 27, `speed_line`)."""
    c = curve_of(meta)
    rotors = next(m for m in meta if m.startswith("# rotors:")).split(":", 1)[1]
    x, y, s = (np.array(v, float) for v in zip(*[r.split() for r in rotors.split(";")]))
    B_inv = np.linalg.inv(np.vstack([y, x, s, np.ones(4)]))
    P = columns(names, rows, MOTORS)
    on = (P > 2.55).all(axis=0)
    f = c.thrust(P[:, on])
    W = f.sum(axis=0)
    f2 = np.maximum(f + B_inv @ np.vstack([dy * W, dx * W, 0 * W, 0 * W]), 0.0)
    P2 = np.full(P.shape, np.nan)
    P2[:, on] = np.minimum(255.0, c.command(f2))
    put(names, rows, MOTORS, P2)
    if (line := speed_line(meta, names, rows)) is not None:
        w = columns(names, rows, ("omega1", "omega2", "omega3", "omega4"))
        ratio = np.full(P.shape, np.nan)
        ratio[:, on] = line.speed(P2[:, on]) / line.speed(P[:, on])
        put(names, rows, ("omega1", "omega2", "omega3", "omega4"), w * ratio)


def resist(names, rows, R: float) -> None:
    V, I = columns(names, rows, ("battery_v", "current"))
    put(names, rows, ["battery_v"], [V - R * I])


def decimated(meta, names, rows, path):
    """The log as ArduPilot's default logging gives it: rows at 25 Hz; the motors, voltage and current
    sampled at 10 Hz and held."""
    t = columns(names, rows, ["t"])[0]
    fs = 1.0 / float(np.median(np.diff(t)))
    keep = np.arange(0, len(rows), max(1, int(round(fs / 25.0))))
    slow = np.floor(t / 0.1)
    first = np.concatenate([[True], slow[1:] != slow[:-1]])
    held = np.maximum.accumulate(np.where(first, np.arange(t.size), 0))
    cols = [c for c in MOTORS + ("battery_v", "current") if c in names]
    j = [names.index(c) for c in cols]
    out = []
    for k in keep:
        r = list(rows[k])
        for c in j:
            r[c] = rows[held[k]][c]
        out.append(r)
    m = [x for x in meta if not x.startswith(("# rate_hz:", "# motor_rate_hz:"))]
    m += [f"# rate_hz: {fs / max(1, int(round(fs / 25.0))):.1f}", "# motor_rate_hz: 10.0"]
    return write(m, names, out, path)


def static_full(meta, names, rows, path) -> dict:
    """The static tier's findings on the log at its full rate (its own function on the table)."""
    write(meta, names, rows, path)
    table = read_flight_log(path, extra=FOREIGN_COLUMNS + STATIC_COLUMNS)
    st = static_tier([table], [load_file(table, Airframe())], Airframe())
    assert st is not None
    return st


def static_default(meta, names, rows, path) -> dict:
    """`flightctl diagnose` on the log decimated to ArduPilot's default rates: the static tier's report."""
    decimated(meta, names, rows, path)
    out = path.with_suffix(".json")
    assert main(["diagnose", str(path), "--json", str(out), "--quiet"]) == 0
    rep = json.loads(out.read_text())
    assert rep["tier"] == "static" and rep["cause"] == "none", rep["tier_why"]
    return rep["static"]


RATES = {"full": static_full, "default": static_default}


def case(name, rate, seed, slow=False):
    return pytest.param(name, rate, seed, marks=pytest.mark.slow) if slow else (name, rate, seed)


def hidden(tmp, name: str, rate: str, rng, hide, tag: str) -> tuple[dict, dict]:
    """(the untouched log's findings, the findings with `hide(meta, names, rows)` applied), at `rate`."""
    meta, names, rows = imported(name, tmp, rng)
    before = RATES[rate](meta, names, [list(r) for r in rows], tmp / f"{name}-{rate}-{tag}-plain.csv")
    hide(meta, names, rows)
    return before, RATES[rate](meta, names, rows, tmp / f"{name}-{rate}-{tag}.csv")


def scale_of(st0: dict, st: dict, motor: int) -> float:
    """The hidden motor's thrust for its command against the others', from the change of its share."""
    def own(st):
        s = np.array(st["motors"]["share"])
        return s[motor - 1] / np.mean(np.delete(s, motor - 1))
    return own(st0) / own(st)


@pytest.mark.parametrize("name, rate, seed", [case("LOG00037", "full", 1), case("LOG00037", "default", 2),
                                              case("LOG00230", "full", 3), case("btfl_002", "default", 4)])
def test_a_weak_motor_hidden_in_a_real_log_is_found_with_its_size(tmp, name, rate, seed):
    rng = np.random.default_rng(4100 + seed)
    motor, scale = int(rng.integers(1, 5)), float(rng.uniform(0.75, 0.92))
    before, after = hidden(tmp, name, rate, rng, lambda m, n, r: weaken(m, n, r, motor, scale), "weak")
    tol = 0.02 if rate == "full" else 0.03
    assert scale_of(before, after, motor) == pytest.approx(scale, abs=tol), (motor, scale, before["motors"], after["motors"])
    change = np.array(after["motors"]["share"]) - np.array(before["motors"]["share"])
    assert int(np.argmax(change)) == motor - 1, (motor, change)
    speeds = after["pattern"]["rotor_speeds"]
    if speeds is not None:             # a weak motor turns slower for its command: the speeds name it
        assert "weak motor" in speeds["verdict"] and f"motor {motor} " in speeds["why"], (motor, speeds)


@pytest.mark.parametrize("name, rate, seed", [case("LOG00037", "full", 1), case("LOG00037", "default", 2),
                                              case("LOG00230", "default", 3), case("btfl_002", "default", 4)])
def test_a_centre_of_mass_moved_in_a_real_log_is_found_on_top_of_its_own(tmp, name, rate, seed):
    rng = np.random.default_rng(4200 + seed)
    r, a = float(rng.uniform(0.04, 0.10)), float(rng.uniform(0.0, 2.0 * np.pi))
    dx, dy = r * np.cos(a), r * np.sin(a)
    before, after = hidden(tmp, name, rate, rng, lambda m, n, rows: move_com(m, n, rows, dx, dy), "com")
    got = np.array([after["pattern"]["com"]["dx"] - before["pattern"]["com"]["dx"],
                    after["pattern"]["com"]["dy"] - before["pattern"]["com"]["dy"]])
    assert np.allclose(got, [dx, dy], atol=0.01), ((dx, dy), got)
    speeds = after["pattern"]["rotor_speeds"]
    if speeds is not None:
        assert "weak motor" not in speeds["verdict"], speeds


@pytest.mark.parametrize("rate, seed", [("full", 1), ("default", 2)])
def test_an_internal_resistance_hidden_in_a_real_log_is_found_on_top_of_the_packs(tmp, rate, seed):
    rng = np.random.default_rng(4300 + seed)
    R = float(rng.uniform(0.01, 0.05))
    before, after = hidden(tmp, "LOG00037", rate, rng, lambda m, n, rows: resist(n, rows, R), "R")
    r0, r1 = before["battery"]["resistance"], after["battery"]["resistance"]
    assert r0["passed"] and r1["passed"], (r0["check"], r1["check"])
    assert r1["ohm"] - r0["ohm"] == pytest.approx(R, abs=0.002), (R, r0, r1)


@pytest.mark.parametrize("name", ["LOG00037", "LOG00230"])
def test_the_same_rewriting_with_nothing_hidden_changes_nothing(tmp, name):
    rng = np.random.default_rng(4400)
    meta, names, rows = imported(name, tmp, rng)
    before = static_full(meta, names, [list(r) for r in rows], tmp / f"{name}-same0.csv")
    weaken(meta, names, rows, 1, 1.0)
    move_com(meta, names, rows, 0.0, 0.0)
    if name in WITH_CURRENT:
        resist(names, rows, 0.0)
    after = static_full(meta, names, rows, tmp / f"{name}-same1.csv")
    assert np.allclose(after["motors"]["share"], before["motors"]["share"], atol=1e-4)
    assert after["pattern"]["verdict"] == before["pattern"]["verdict"]
    if name in WITH_CURRENT:
        assert after["battery"]["resistance"]["ohm"] == pytest.approx(before["battery"]["resistance"]["ohm"], abs=1e-5)


# The shipped high-rate log whose accelerometer shakes most in hover: INDIflight's LOG00230 (accUnfiltered at
# 500 Hz, acc_z's spread 7.1 m/s^2 about 9.9 in hover; LOG00258 4.3, the Betaflight logs 0.8-1.8), where the
# mean of the rows' g / acc_z is 2.4 times g over their mean.
VIBRATING = "LOG00230"
ACC = ("acc_x", "acc_y", "acc_z")


def _hover_figures(st: dict) -> tuple[float, float, float, float]:
    h = st["hover"]
    return h["thrust_share"], h["thrust_share_stderr"], h["thrust_to_weight"], h["thrust_to_weight_stderr"]


def _agree(a: dict, b: dict, k: float = 2.0) -> None:
    share0, sd0, tw0, twsd0 = _hover_figures(a)
    share1, sd1, tw1, twsd1 = _hover_figures(b)
    assert abs(share1 - share0) <= k * np.hypot(sd0, sd1), (a["hover"], b["hover"])
    assert abs(tw1 - tw0) <= k * np.hypot(twsd0, twsd1), (a["hover"], b["hover"])


def test_the_hover_figures_of_the_most_vibrating_log_are_those_of_its_low_passed_accelerometer(tmp):
    """The thrust share and thrust-to-weight from the raw rows agree, within their uncertainty, with the same
    figures from the accelerometer averaged over 0.1 s (its vibration gone, its mean kept): a ratio of means."""
    rng = np.random.default_rng(4500)
    meta, names, rows = imported(VIBRATING, tmp, rng)
    raw = static_full(meta, names, [list(r) for r in rows], tmp / "vib-raw.csv")
    t, *acc = columns(names, rows, ("t",) + ACC)
    width = int(round(0.1 / float(np.median(np.diff(t)))))
    smooth = [np.convolve(a, np.ones(width) / width, mode="same") for a in acc]
    assert np.std(acc[2] - smooth[2]) > 3.0          # the log does vibrate: the low-pass takes metres per s^2 off
    put(names, rows, ACC, smooth)
    _agree(raw, static_full(meta, names, rows, tmp / "vib-smooth.csv"))


@pytest.mark.parametrize("seed", [1, 2])
def test_a_vibration_added_to_a_real_log_does_not_move_its_hover_figures(tmp, seed):
    """A vibration of drawn size (a tone of 60-240 Hz, 2-8 m/s^2 on z, half that across, and white noise of
    1-4 m/s^2) added to the accelerometer of the real log, never told: the hover figures stay within their
    uncertainty of the untouched log's."""
    rng = np.random.default_rng(4510 + seed)
    meta, names, rows = imported(VIBRATING, tmp, rng)
    before = static_full(meta, names, [list(r) for r in rows], tmp / f"vib{seed}-plain.csv")
    t, *acc = columns(names, rows, ("t",) + ACC)
    hz, amp, noise = rng.uniform(60.0, 240.0), rng.uniform(2.0, 8.0), rng.uniform(1.0, 4.0)
    phase = rng.uniform(0.0, 2.0 * np.pi, 3)
    shaken = [a + amp * (1.0 if k == 2 else 0.5) * np.sin(2.0 * np.pi * hz * t + phase[k])
              + noise * rng.standard_normal(t.size) for k, a in enumerate(acc)]
    put(names, rows, ACC, shaken)
    _agree(before, static_full(meta, names, rows, tmp / f"vib{seed}.csv"))


def split_pairs(meta, names, rows, a: float) -> None:
    """The counter-clockwise pair gives a share `a` more thrust than the clockwise one for the same
    torques (each motor's thrust times 1 + spin a / 2, through the declared curve)."""
    c = curve_of(meta)
    rotors = next(m for m in meta if m.startswith("# rotors:")).split(":", 1)[1]
    spin = np.array([float(r.split()[2]) for r in rotors.split(";")])
    P = columns(names, rows, MOTORS)
    on = (P > 2.55).all(axis=0)
    P2 = np.full(P.shape, np.nan)
    P2[:, on] = np.minimum(255.0, c.command(c.thrust(P[:, on]) * (1.0 + 0.5 * a * spin[:, None])))
    put(names, rows, MOTORS, P2)


@pytest.mark.parametrize("seed", [1, 2])
def test_a_yaw_split_beyond_a_trim_is_not_physical_inside_a_mix_too(tmp, seed):
    """The spin pairs driven apart by a drawn 40-80 % (more than a trim's 30 %) on top of a centre of mass
    moved by a drawn 0.04-0.10 arm lengths in LOG00037 (its own centre of mass beside): whatever mix the
    pattern is read as, the yaw figure is beyond its bound and the verdict is "not physical"."""
    rng = np.random.default_rng(4600 + seed)
    a = float(rng.uniform(0.4, 0.8)) * rng.choice([-1.0, 1.0])
    r, ang = float(rng.uniform(0.04, 0.10)), float(rng.uniform(0.0, 2.0 * np.pi))

    def hide(meta, names, rows):
        move_com(meta, names, rows, r * np.cos(ang), r * np.sin(ang))
        split_pairs(meta, names, rows, a)
    before, after = hidden(tmp, "LOG00037", "full", rng, hide, f"split{seed}")
    p = after["pattern"]
    assert p["yaw_trim"]["ccw_minus_cw"] - before["pattern"]["yaw_trim"]["ccw_minus_cw"] == pytest.approx(a, abs=0.05)
    assert p["verdict"] == "not physical" and "spin pairs" in p["why"], p


def _no_hover(names, rows) -> None:
    """Every running motor's command squeezed into 250-255 (at full command: no hover rows, so no hover and no
    accelerometer spread to judge), in the same order as flown (the throttle's rise and fall kept)."""
    P = columns(names, rows, MOTORS)
    put(names, rows, MOTORS, np.where(P > 0, 250.0 + 5.0 * P / 255.0, np.nan))


def _static(meta, names, rows, path):
    write(meta, names, rows, path)
    table = read_flight_log(path, extra=FOREIGN_COLUMNS + STATIC_COLUMNS)
    return static_tier([table], [load_file(table, Airframe())], Airframe())


@pytest.mark.parametrize("seed", [1, 2])
def test_a_current_that_is_no_sensor_gives_no_resistance(tmp, seed):
    """LOG00037's current replaced by what a board without a sensor logs (a drawn constant of 0.2-0.5 A and a
    drawn noise of 0.01-0.15 A, nothing of the throttle): the battery says "no current sensor" and fits no
    resistance, with its hover and vibration taken away too (its battery then its only finding, the
    voltage's range), while the same log with its real current still gets its resistance."""
    rng = np.random.default_rng(4700 + seed)
    meta, names, rows = imported("LOG00037", tmp, rng)
    real = [list(r) for r in rows]
    n = len(rows)
    fake = rng.uniform(0.2, 0.5) + rng.uniform(0.01, 0.15) * rng.standard_normal(n)
    put(names, rows, ["current"], [np.round(fake, 2)])
    st = static_full(meta, names, rows, tmp / f"nocur{seed}.csv")
    assert st["battery"]["resistance"] is None and st["battery"]["without_current"].startswith("no current sensor")
    assert abs(st["battery"]["current_throttle"]["r"]) < 0.25 or st["battery"]["current_throttle"]["amps"] < 0.1
    _no_hover(names, rows)
    st = _static(meta, names, rows, tmp / f"nocur{seed}-nohover.csv")
    assert "hover" not in st and "vibration" not in st and st["battery"]["resistance"] is None, st
    _no_hover(names, real)
    st = _static(meta, names, real, tmp / f"cur{seed}-nohover.csv")
    assert "hover" not in st and "vibration" not in st and st["battery"]["resistance"] is not None, st["not_judged"]


@pytest.mark.parametrize("seed", [1, 2])
def test_a_weak_motor_masked_by_a_centre_of_mass_is_named_by_its_speed_per_command(tmp, seed):
    """INDIflight's LOG00230 (ESC telemetry): a motor drawn at random made weaker by a drawn 0.75-0.90 (its
    command raised for the same thrust through eq. 26 with the h2 the log's own speeds give: its speed, the
    thrust's, unchanged), and the centre of mass moved away from it by what brings its hover share back to
    the mean's (0.8-1.2 of it, drawn): its hover gain says nothing, its speed per command names it and its
    size, against the untouched log's own."""
    from flightctl.sim.diagnose.static.curve import Curve
    rng = np.random.default_rng(4800 + seed)
    motor, scale = int(rng.integers(1, 5)), float(rng.uniform(0.75, 0.90))
    meta, names, rows = imported("LOG00230", tmp, rng)
    plain = [list(r) for r in rows]
    before = static_full(meta, names, plain, tmp / f"wm{seed}-plain.csv")
    h2 = speed_line(meta, names, rows).h2
    rotors = next(m for m in meta if m.startswith("# rotors:")).split(":", 1)[1]
    x, y = (np.array(v, float) for v in list(zip(*[r.split() for r in rotors.split(";")]))[:2])
    away = -np.array([x[motor - 1], y[motor - 1]]) / np.hypot(x[motor - 1], y[motor - 1])
    speeds_curve = Curve(1.0, h2 / 255.0, 1.0, "the log's speeds", True)
    raised = lambda P: np.minimum(255.0, speeds_curve.command(speeds_curve.thrust(P) / scale))
    # what the raised command asks for through the curve the shares are read through (the declared one):
    # its share rises by 3/4 of (that ratio - 1), which a centre of mass d away from it takes back (quad X:
    # a share moves by 2 r . d)
    c, P = curve_of(meta), columns(names, rows, [f"P{motor}"])[0]
    busy = P > 0.1 * 255.0
    ratio = float(np.median(c.thrust(raised(P[busy])) / c.thrust(P[busy])))
    d = 0.375 * (ratio - 1.0) * rng.uniform(0.8, 1.2) * away
    move_com(meta, names, rows, *d)
    P = columns(names, rows, [f"P{motor}"])[0]
    on = P > 0
    P[on] = raised(P[on])
    put(names, rows, [f"P{motor}"], [np.where(on, P, np.nan)])
    after = static_full(meta, names, rows, tmp / f"wm{seed}.csv")
    g0, g = before["pattern"]["gains"][motor - 1], after["pattern"]["gains"][motor - 1]
    assert g - g0 > -0.03, (g0, g)       # its hover gain does not fall by the 3 % a weak motor's must
    speeds = after["pattern"]["rotor_speeds"]
    assert "weak motor" in speeds["verdict"] and f"motor {motor} " in speeds["why"], (motor, scale, speeds)
    q0 = np.array(before["pattern"]["rotor_speeds"]["speed_thrust_gain"])
    own = q0[motor - 1] / np.mean(np.delete(q0, motor - 1))
    w = speeds["weak_motor"]
    assert w["motor"] == motor
    assert w["thrust_scale"] / own == pytest.approx(scale, abs=max(0.03, 3 * w["stderr"])), (scale, own, w)


def test_a_quad_v_is_diagnosed_by_both_tiers_its_frame_said_and_its_static_figures_those_of_its_positions(tmp):
    """ArduCopter's quad V (FRAME 2: X's positions, AP_MotorsMatrix's yaw factors +-0.7981 and +-1) was refused
    whole as a geometry not taken (issue 45). log171.bin (QUAD/X, FRAME 1) with its FRAME set to 2: both tiers
    answer, the report says the V and its yaw factors, and the static tier's shares and pattern are the X's
    (they need no yaw factor: the rotors' positions and spins are the same)."""
    import struct
    from helpers.paths import DATA
    from flightctl.sim.logs import read_foreign
    src = DATA / "ardupilot" / "log171.bin"
    data = src.read_bytes()
    k = data.find(b"FRAME".ljust(16, b"\0"))
    assert k > 0 and struct.unpack_from("<f", data, k + 16)[0] == 1.0
    v = tmp / "quad_v.bin"
    v.write_bytes(data[:k + 16] + struct.pack("<f", 2.0) + data[k + 20:])
    static = []
    for path in (src, v):
        (table,) = read_foreign(str(path))
        static.append(static_tier([table], [load_file(table, Airframe())], Airframe()))
    x_st, v_st = static
    assert "QUAD/X" in x_st["layout"]["source"] and "QUAD/V" in v_st["layout"]["source"], v_st["layout"]["source"]
    assert "+0.7981" in v_st["layout"]["source"] and v_st["layout"]["spin"] == x_st["layout"]["spin"]
    assert v_st["motors"] == x_st["motors"] and v_st["pattern"] == x_st["pattern"] and v_st["hover"] == x_st["hover"]
    out = tmp / "quad_v.json"
    assert main(["diagnose", str(v), "--json", str(out), "--quiet"]) == 0
    rep = json.loads(out.read_text())
    assert rep["tier"] == "dynamic" and rep["base_model"]["identified"] and rep["static"] == v_st, rep["tier_why"]
    assert "QUAD/V" in rep["base_model"]["layout"]["source"]
