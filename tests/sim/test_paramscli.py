"""`flightctl params show` and `flightctl params diff`: the full file with units and sources, a
valid parameter file itself, and the differences between two sets."""
from __future__ import annotations

import dataclasses
import tomllib

from flightctl.cli import main as cli
from flightctl.params import TABLE4, TABLE6, Airframe, from_dict, load


def run(capsys, *argv):
    code = cli(list(argv))
    out = capsys.readouterr()
    return code, out.out, out.err


def comment(text: str, key: str) -> str:
    line = next(l for l in text.splitlines() if l.startswith(f"{key} = "))
    return line.split("#", 1)[1].strip()


def test_show_defaults_every_key_with_unit_and_source(capsys):
    code, out, _ = run(capsys, "params", "show")
    assert code == 0
    assert from_dict(tomllib.loads(out)) == load(None)          # the output is the parameter file
    for f in dataclasses.fields(Airframe):
        unit, source = comment(out, f.name).split("; ", 1)
        assert unit == f.metadata["unit"]
        assert source == f"default: {f.metadata['source']}"


def test_show_a_shipped_vehicle_names_it_and_keeps_its_effects(capsys):
    code, out, _ = run(capsys, "params", "show", "paper-as-flown")
    assert code == 0
    shipped = load("paper-as-flown")
    assert from_dict(tomllib.loads(out)) == shipped
    assert len(shipped.effects) > 0
    assert comment(out, "tau_tilt_air").startswith("s; vehicle paper-as-flown")
    assert "not in the file" in comment(out, "kp_z")             # the vehicle file leaves gains to --gains


def test_show_a_file_marks_what_it_sets(tmp_path, capsys):
    f = tmp_path / "light.toml"
    f.write_text("M = 1.2  # kg; weighed on the kitchen scale\n[gains]\nkp_z = 3.0\n")
    code, out, _ = run(capsys, "params", "show", str(f))
    assert code == 0
    assert comment(out, "M") == f"kg; file {f}: weighed on the kitchen scale"
    assert comment(out, "kp_z") == f"N/m; file {f}"
    assert comment(out, "kp_phi").startswith("N/rad; default (not in the file): paper, Table 6")
    assert comment(out, "l").startswith("m; default (not in the file)")
    parsed = from_dict(tomllib.loads(out))
    assert parsed.airframe.M == 1.2 and parsed.gains.kp_z == 3.0 and parsed.gains.kp_phi == TABLE6.kp_phi


def test_gains_chosen_by_name_replace_the_files_and_say_so(tmp_path, capsys):
    """`--gains table4` wins over the file's [gains] whole; each gain's source says which table, and
    that it replaced the file's (a log header never labels Table 4's 17.1 as Table 6)."""
    f = tmp_path / "light.toml"
    f.write_text("M = 1.2\n[gains]\nkp_z = 3.0\n")
    code, out, _ = run(capsys, "params", "show", str(f), "--gains", "table4")
    assert code == 0
    assert comment(out, "kp_z") == f"N/m; paper, Table 4 (--gains table4, replacing the [gains] of file {f})"
    assert comment(out, "kp_phi").startswith("N/rad; paper, Table 4")
    parsed = from_dict(tomllib.loads(out))
    assert parsed.gains == TABLE4 and parsed.airframe.M == 1.2


def test_diff(tmp_path, capsys):
    a, b = tmp_path / "a.toml", tmp_path / "b.toml"
    a.write_text("M = 1.6\n")
    b.write_text('M = 2.0\n[gains]\nkd_z = 0.2\n[[effect]]\ncause = "motor_lag"\ntau = 0.05\n')
    code, out, _ = run(capsys, "params", "diff", str(a), str(b))
    assert code == 1
    lines = out.splitlines()
    assert "M: 1.6 -> 2.0 kg (+25.0%)" in lines
    assert any(l.startswith("gains.kd_z: 0.14 -> 0.2 N s/m") for l in lines)
    assert "+ effect motor_lag(tau=0.05)" in lines
    assert len([l for l in lines if ":" in l and not l.startswith(("---", "+++"))]) == 2   # l, g, ... unchanged
    code, out, _ = run(capsys, "params", "diff", str(a), str(a))
    assert code == 0 and "the same" in out
    code, out, _ = run(capsys, "params", "diff", "defaults", "paper-as-flown")
    assert code == 1 and "filters.tau_tilt_air: 0.0 ->" in out


def test_bad_input_is_one_line(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text("M = -3\n")
    for argv in (("params", "show", str(bad)), ("params", "diff", "defaults", str(tmp_path / "missing.toml")),
                 ("params", "frobnicate")):
        code, _, err = run(capsys, *argv)
        assert code == 2 and len(err.strip().splitlines()) == 1, argv
