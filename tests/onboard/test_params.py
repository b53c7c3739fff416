"""flightctl.params: the shipped defaults are conventions.md's, and every bad input is refused with
a message naming the key."""
import dataclasses
import math
import tomllib

import pytest

from flightctl import params
from flightctl.errors import InputError
from flightctl.params import Airframe, Filters, Gains, Params, dumps, from_dict, load, update_file

CONVENTIONS = dict(M=1.645, l=0.2475, g=9.80665, Jxx=0.014002764, Jyy=0.014267729, Jzz=0.029487252,
                   Jp=2.66838e-4, gamma1=4.86291e-4, gamma2=1.22958e-3, h1=1.49e-3, h2=120.0,
                   c1=1.47e-5, g1=0.020, g2=0.002, rotor_radius=0.1524, battery_nominal_v=14.8,
                   loop_hz=450.0, esc_pwm_hz=449.0, sonar_hz=45.0)
TABLE6 = dict(kp_z=2.4, ki_z=0.0, kd_z=0.14, kp_phi=4.48, ki_phi=0.0045, kd_phi=0.221,
              kp_theta=4.12, ki_theta=0.0045, kd_theta=0.13, kp_psi=7.55, ki_psi=0.0, kd_psi=0.248)
TABLE4 = dict(kp_z=1.9, ki_z=0.0, kd_z=1.6, kp_phi=17.1, ki_phi=0.0, kd_phi=1.3,
              kp_theta=17.2, ki_theta=0.0, kd_theta=1.3, kp_psi=7.7, ki_psi=0.0, kd_psi=2.7)


def test_load_none_gives_conventions_values():
    p = load(None)
    for k, v in CONVENTIONS.items():
        assert getattr(p.airframe, k) == v, k
    for k, v in TABLE6.items():
        assert getattr(p.gains, k) == v, k
    assert p.filters.alpha_ema == 1 - math.exp(-1 / 128)
    assert p.filters.alpha_roll_pitch == 128 / 129
    assert p.filters.alpha_yaw == 64 / 65
    assert p.airframe.B == pytest.approx(1.645 * 9.80665 / 4)
    assert p.airframe.dt == pytest.approx(1 / 450)


def test_every_airframe_field_is_in_conventions():
    assert {f.name for f in dataclasses.fields(Airframe)} == set(CONVENTIONS)
    assert {f.name for f in dataclasses.fields(Gains)} == set(TABLE6)


def test_table4_preset():
    p = from_dict({"gains": {"preset": "table4"}})
    for k, v in TABLE4.items():
        assert getattr(p.gains, k) == v, k
    # a preset with overrides on top
    p = from_dict({"gains": {"preset": "table4", "kd_z": 1.0}})
    assert p.gains.kd_z == 1.0 and p.gains.kp_z == 1.9


def test_from_dict_does_not_consume_its_input():
    data = {"M": 1.7, "gains": {"preset": "table4"}}
    first = from_dict(data)
    assert data == {"M": 1.7, "gains": {"preset": "table4"}}
    second = from_dict(data)
    assert second == first
    assert second.gains.kp_phi == 17.1


def test_values_override_defaults():
    p = from_dict({"M": 1.8, "h2": 110, "gains": {"kp_z": 3.0}, "filters": {"alpha_yaw": 0.99}})
    assert p.airframe.M == 1.8
    assert p.airframe.h2 == 110.0 and isinstance(p.airframe.h2, float)
    assert p.airframe.l == 0.2475
    assert p.gains.kp_z == 3.0 and p.gains.kd_z == 0.14
    assert p.filters.alpha_yaw == 0.99


@pytest.mark.parametrize("data,words", [
    ({"mass": 1.6}, ["mass", "unknown parameter"]),
    ({"gains": {"kp_x": 1.0}}, ["gains.kp_x", "unknown"]),
    ({"filters": {"alpha": 0.5}}, ["filters.alpha", "unknown"]),
    ({"filters": {"preset": "table4"}}, ["filters.preset", "unknown"]),
    ({"M": "1.6"}, ["M", "expected a number", "str"]),
    ({"M": True}, ["M", "expected a number", "bool"]),
    ({"gains": {"kp_z": False}}, ["gains.kp_z", "bool"]),
    ({"gains": {"kp_z": [1.0]}}, ["gains.kp_z", "expected a number"]),
    ({"M": 0.0}, ["M", "out of range"]),
    ({"M": 51}, ["M", "out of range"]),
    ({"g": 10.5}, ["g", "out of range"]),
    ({"gains": {"kp_z": -1.0}}, ["gains.kp_z", "out of range"]),
    ({"filters": {"alpha_ema": 1.5}}, ["filters.alpha_ema", "out of range"]),
    ({"M": math.nan}, ["M", "out of range"]),
    ({"M": math.inf}, ["M", "out of range"]),
    ({"gains": 3}, ["gains", "table"]),
    ({"gains": {"preset": "table5"}}, ["gains.preset", "table5"]),
    ({"gains": {"preset": ["table4"]}}, ["gains.preset"]),
])
def test_from_dict_errors_name_the_key(data, words):
    with pytest.raises(InputError) as e:
        from_dict(data)
    for w in words:
        assert w in str(e.value)


def test_non_physical_inertia():
    # Jzz may exceed Jxx + Jyy by 10 % (Table 2 itself is 4.3 % over); beyond that it is refused
    jxx, jyy = 0.014002764, 0.014267729
    assert 0.029487252 / (jxx + jyy) == pytest.approx(1.043, abs=0.001)
    ok = from_dict({"Jzz": 1.09 * (jxx + jyy)})
    assert ok.airframe.Jzz == pytest.approx(1.09 * (jxx + jyy))
    with pytest.raises(InputError, match="Jzz"):
        from_dict({"Jzz": 1.11 * (jxx + jyy)})
    with pytest.raises(InputError, match="Jxx"):
        from_dict({"Jxx": 0.05})      # > 1.1 (Jyy + Jzz) = 0.048
    with pytest.raises(InputError, match="Jyy"):
        from_dict({"Jyy": 0.05, "Jxx": 0.01})


def test_esc_frequency_above_loop_rate_refused():
    with pytest.raises(InputError, match="esc_pwm_hz"):
        from_dict({"loop_hz": 400.0})      # the ESC runs at 449 Hz


def test_dumps_round_trip():
    p = from_dict({"M": 1.7123456789, "c1": 1.234e-5, "gains": {"preset": "table4", "ki_phi": 0.003},
                   "filters": {"alpha_yaw": 0.98}})
    text = dumps(p)
    back = from_dict(tomllib.loads(text))
    assert back == p
    assert from_dict(tomllib.loads(dumps(Params()))) == Params()
    # unit and source are written as comments
    assert "M = 1.7123456789  # kg" in text


def test_load_path(tmp_path):
    f = tmp_path / "quad.toml"
    f.write_text("M = 1.7\nl = 0.25\n[gains]\npreset = 'table4'\n")
    p = load(f)
    assert p.airframe.M == 1.7 and p.airframe.l == 0.25 and p.gains.kp_z == 1.9


@pytest.mark.parametrize("text,words", [
    ("M = 'heavy'\n", ["M", "expected a number"]),
    ("M = 1.6\nwings = 2\n", ["wings", "unknown"]),
    ("M = = 1\n", ["not valid TOML"]),
    ("[gains]\nkp_z = -3\n", ["gains.kp_z", "out of range"]),
])
def test_load_bad_file_prefixes_path(tmp_path, text, words):
    f = tmp_path / "bad.toml"
    f.write_text(text)
    with pytest.raises(InputError) as e:
        load(f)
    msg = str(e.value)
    assert msg.startswith(f"{f}: ")
    for w in words:
        assert w in msg


def test_load_missing_file(tmp_path):
    with pytest.raises(InputError) as e:
        load(tmp_path / "nope.toml")
    assert str(tmp_path / "nope.toml") in str(e.value) and "neither a parameter file nor a shipped vehicle" in str(e.value)


def test_update_file_creates_and_keeps_other_values(tmp_path):
    f = tmp_path / "quad.toml"
    p = update_file(f, {"h1": 1.6e-3, "h2": 118.0}, "bench fit 2024-05-01")
    assert p.airframe.h1 == 1.6e-3 and p.airframe.h2 == 118.0
    back = load(f)
    assert back == p
    assert "bench fit 2024-05-01" in f.read_text()
    # a second update keeps the first one's values and the file's gains
    text = f.read_text().replace("kp_z = 2.4", "kp_z = 3.3")
    f.write_text(text)
    p2 = update_file(f, {"c1": 1.5e-5}, "rpm fit")
    assert p2.airframe.h1 == 1.6e-3 and p2.airframe.c1 == 1.5e-5 and p2.gains.kp_z == 3.3
    assert load(f) == p2


def test_update_file_refuses_bad_values_without_writing(tmp_path):
    f = tmp_path / "quad.toml"
    f.write_text("M = 1.7\n")
    with pytest.raises(InputError, match="h1"):
        update_file(f, {"h1": 5.0}, "bad fit")
    assert f.read_text() == "M = 1.7\n"


def test_schema_metadata():
    for f in params.schema(Airframe) + params.schema(Gains) + params.schema(Filters):
        lo, hi = f.metadata["lo"], f.metadata["hi"]
        assert lo <= f.default <= hi, f.name
        assert f.metadata["unit"] and f.metadata["source"]


def test_every_as_flown_term_carries_a_range_and_its_provenance():
    """Issue 17: each term of the as-flown file is a range with its source, not a tuned point; the
    file's text round-trips through the writer."""
    p = load("paper-as-flown")
    # the ESC's full throttle is the RC input's 2.0 ms, not a span: the thrust ceiling there is ranged
    # through h1 and h2 (issue 37)
    fixed = {("motor_dynamics", "p_full")}
    for e in p.effects:
        spans = {name: (lo, hi) for name, lo, hi in e.ranges}
        assert set(spans) == {name for name, _ in e.parameters if (e.cause, name) not in fixed}, e.cause
        for name, value in e.parameters:
            if (e.cause, name) in fixed:
                continue
            lo, hi = spans[name]
            assert lo <= value <= hi and lo < hi
        assert "range" in e.source or "Range" in e.source
    assert from_dict(tomllib.loads(dumps(p))).effects == p.effects
    # the rotor inertia and eq. 26-28's constants, each drawn too
    assert [name for name, _, _ in p.ranges] == ["Jp", "h1", "h2", "c1", "g1", "g2"]
    assert {f"{t}.{name}" for t, name, _, _ in p.table_ranges} == {
        "filters.tau_rate", "sensors.accel_vibration", "sensors.gyro_vibration", "sensors.harmonic2",
        "sensors.harmonic3", "sensors.gyro_broadband"}
    assert from_dict(tomllib.loads(dumps(p))).table_ranges == p.table_ranges
    assert from_dict(tomllib.loads(dumps(p))).ranges == p.ranges


@pytest.mark.parametrize("span,needle", [("[0.05, 0.1]", "around the value of tau"), ("0.02", "expected [lo, hi]"),
                                         ("[0.01, 0.2]", None)])
def test_an_effect_range_must_hold_its_value(tmp_path, span, needle):
    f = tmp_path / "p.toml"
    f.write_text(f'[[effect]]\ncause = "motor_dynamics"\ntau = 0.035\nrange.tau = {span}\n')
    if needle is None:
        assert load(f).effects[0].ranges == (("tau", 0.01, 0.2),)
    else:
        with pytest.raises(InputError) as e:
            load(f)
        assert needle in str(e.value) and str(f) in str(e.value)


@pytest.mark.parametrize("line,needle", [("range.Jp = [2e-4, 3e-4]", "around the value of Jp"),
                                         ("range.Jp = [0.0, 0.5]", "around the value of Jp"),   # past the schema's 0.1
                                         ("range.Jq = [0.0, 1e-3]", "unknown parameter"),
                                         ("range.Jp = [5e-5, 3e-4]", None)])
def test_an_airframe_range_must_hold_its_value_within_the_schema(tmp_path, line, needle):
    f = tmp_path / "p.toml"
    f.write_text(f"Jp = 1e-4\n{line}\n")
    if needle is None:
        assert load(f).ranges == (("Jp", 5e-5, 3e-4),)
    else:
        with pytest.raises(InputError) as e:
            load(f)
        assert needle in str(e.value) and str(f) in str(e.value)
