"""Bad input to `flightctl identify`: exit status 2, one line on stderr naming the file and the row or
column, and nothing written (no JSON, no parameter file, no PNG)."""
import pytest

from flightctl.cli import main
from helpers.identify_rows import HEADER, PENDULUM, ROTOR, bench_rows, yaw_rows

def replace(rows, index, column, value):
    """rows with one cell changed; row `index` is file line index + 2."""
    rows = list(rows)
    cells = rows[index].split(",")
    cells[column] = value
    rows[index] = ",".join(cells)
    return rows


CASES = {  # name: (kind, header, rows, what the message must name)
    "missing column": ("bench", "motor,P,thrust,omega,voltage", bench_rows(), ["missing column 'current'"]),
    "non-numeric cell": ("bench", None, replace(bench_rows(), 1, 2, "abc"), ["row 3", "'thrust'", "'abc'"]),
    "empty cell": ("bench", None, replace(bench_rows(), 4, 5, ""), ["row 6", "'current'", "empty"]),
    "too few points": ("bench", None, bench_rows()[:3], ["motor 1", "too few points", "h1, h2"]),
    "negative speed": ("bench", None, replace(bench_rows(), 2, 3, "-5"), ["row 4", "'omega'", "negative"]),
    "motor 5": ("bench", None, replace(bench_rows(), 0, 0, "5"), ["row 2", "'motor'", "1 to 4"]),
    "motor 1.5": ("bench", None, replace(bench_rows(), 3, 0, "1.5"), ["row 5", "'motor'"]),
    "command above 255": ("bench", None, replace(bench_rows(), 7, 1, "300"), ["row 9", "'P'"]),
    "zero voltage": ("bench", None, replace(bench_rows(), 0, 4, "0"), ["row 2", "'voltage'"]),
    "thrust falling with P": ("bench", None, [f"1,{p},{f},100,14.8,1" for p, f in zip(range(130, 210, 10), range(8, 0, -1))],
                              ["motor 1", "does not rise with P", "eq. 26"]),
    "one P value": ("bench", None, [f"1,150,{f},100,14.8,1" for f in range(1, 9)], ["motor 1", "distinct P"]),
    "zero yaw rate": ("yaw-drag", None, replace(yaw_rows(), 2, 1, "0"), ["row 4", "'yaw_rate'"]),
    "yaw rates cannot separate gamma1 from gamma2": ("yaw-drag", None, yaw_rows(rates=(-1, -1, -1, 1, 1, 1)),
                                                     ["do not determine gamma1, gamma2"]),
    "too few spins": ("yaw-drag", None, yaw_rows(rates=(-1, 1, 2)), ["too few points", "at least 4"]),
    "unknown axis": ("pendulum", None, replace(PENDULUM, 2, 0, "w"), ["row 4", "'axis'", "'w'"]),
    "negative period": ("pendulum", None, replace(PENDULUM, 1, 2, "-1.1"), ["row 3", "'period'"]),
    "period too short": ("pendulum", None, replace(PENDULUM, 5, 2, "0.5"), ["row 7", "'period'", "negative inertia"]),
    "negative pivot distance": ("pendulum", None, replace(PENDULUM, 0, 1, "-0.2"), ["row 2", "'pivot_distance'"]),
    "one trial on an axis": ("pendulum", None, PENDULUM[:5], ["axis z", "at least 2"]),
    "unknown part": ("rotor", None, replace(ROTOR, 1, 1, "prop"), ["row 3", "'part'", "'prop'"]),
    "negative mass": ("rotor", None, replace(ROTOR, 2, 2, "-0.013"), ["row 4", "'mass'"]),
    "rotor 7": ("rotor", None, replace(ROTOR, 3, 0, "7"), ["row 5", "'rotor'"]),
    "rotor without motor": ("rotor", None, ROTOR[:3], ["rotor 2", "no motor"]),
    "one rotor": ("rotor", None, ROTOR[:2], ["1 rotor", "at least 2"]),
}


def outputs(tmp_path):
    return {"--json": tmp_path / "out.json", "--write-params": tmp_path / "out.toml", "--plot": tmp_path / "out.png"}


def run(capsys, argv):
    code = main(argv)
    out, err = capsys.readouterr()
    return code, err


def assert_refused(code, err, tmp_path, must_name):
    assert code == 2
    assert err.endswith("\n") and err.count("\n") == 1, err
    for text in must_name:
        assert text in err, (text, err)
    assert not any(p.exists() for p in outputs(tmp_path).values()), "something was written"


@pytest.mark.parametrize("case", CASES)
def test_bad_file_is_refused_with_one_line_and_nothing_written(case, tmp_path, capsys):
    kind, header, rows, must_name = CASES[case]
    csv = tmp_path / f"{kind}.csv"
    csv.write_text((header or HEADER[kind]) + "\n" + "\n".join(rows) + "\n")
    argv = ["identify", kind, str(csv)] + [str(x) for kv in outputs(tmp_path).items() for x in kv]
    code, err = run(capsys, argv)
    assert_refused(code, err, tmp_path, [str(csv), *must_name])


def test_missing_file_is_refused(tmp_path, capsys):
    csv = tmp_path / "nope.csv"
    code, err = run(capsys, ["identify", "bench", str(csv), "--json", str(tmp_path / "out.json")])
    assert_refused(code, err, tmp_path, [str(csv), "cannot read"])


def test_fitted_values_outside_the_schema_write_nothing(tmp_path, capsys):
    """gamma2 < 0 fits the file but the parameter schema's physical range refuses it, with or without
    --write-params: not even the JSON is written."""
    csv = tmp_path / "yaw.csv"
    csv.write_text(HEADER["yaw-drag"] + "\n" + "\n".join(yaw_rows(gamma2=-1e-3)) + "\n")
    argv = ["identify", "yaw-drag", str(csv)] + [str(x) for kv in outputs(tmp_path).items() for x in kv]
    code, err = run(capsys, argv)
    assert_refused(code, err, tmp_path, [str(csv), "gamma2", "outside its physical range"])


def test_unreadable_parameter_files_are_named_and_left_alone(tmp_path, capsys):
    csv = tmp_path / "yaw.csv"
    csv.write_text(HEADER["yaw-drag"] + "\n" + "\n".join(yaw_rows()) + "\n")
    bad = tmp_path / "bad.toml"
    bad.write_text("M = [\n")
    code, err = run(capsys, ["identify", "yaw-drag", str(csv), "--json", str(tmp_path / "out.json"), "--params", str(bad)])
    assert_refused(code, err, tmp_path, [str(bad), "not valid TOML"])
    code, err = run(capsys, ["identify", "yaw-drag", str(csv), "--json", str(tmp_path / "out.json"),
                             "--write-params", str(bad)])
    assert_refused(code, err, tmp_path, [str(bad), "not valid TOML"])
    assert bad.read_text() == "M = [\n"


def test_missing_output_directory_and_missing_flag(tmp_path, capsys):
    csv = tmp_path / "yaw.csv"
    csv.write_text(HEADER["yaw-drag"] + "\n" + "\n".join(yaw_rows()) + "\n")
    code, err = run(capsys, ["identify", "yaw-drag", str(csv), "--json", str(tmp_path / "out.json"),
                             "--plot", str(tmp_path / "no" / "such" / "dir.png")])
    assert_refused(code, err, tmp_path, ["--plot", "does not exist"])
    code, err = run(capsys, ["identify", "yaw-drag", str(csv)])
    assert_refused(code, err, tmp_path, ["--json"])
