"""Bad arguments across every command (issue 49): each is one line on stderr and exit 2, found in
argument checking before any flight, fit or spin, with nothing written in the output folder.

The unwritable folders and files run in a child process without the privilege to ignore permission
bits: as a plain user when the tests run as one; as root, root without CAP_DAC_OVERRIDE and
CAP_DAC_READ_SEARCH (setpriv), whom the kernel holds to the permission bits as any user (the
interpreter of a virtualenv under /root cannot be run by `nobody`). A root that keeps them would
write anywhere and prove nothing: the helper checks first that the child cannot write the folder."""
from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from flightctl.cli import main
from flightctl.logfile import FLIGHT_COLUMNS
from helpers.paths import DATA, ROOT

FOREIGN = DATA / "ardupilot" / "log171.bin"


def flight_log(path: Path) -> Path:
    """A short valid flight log (the contract's columns), as a reader would take it."""
    rows = [",".join(FLIGHT_COLUMNS)]
    for k in range(50):
        row = dict.fromkeys(FLIGHT_COLUMNS, "0")
        row.update(t=f"{k / 450:.6f}", acc_z="9.81", battery_v="16.2", range="")
        rows.append(",".join(row[c] for c in FLIGHT_COLUMNS))
    path.write_text("\n".join(rows) + "\n")
    return path


def one_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


# (argv with {o} the output folder and {f} a flight log, what the line says)
CASES = [
    (["sim", "hover"], "required: --log"),
    (["sim", "hover", "--log", "{o}/x.csv", "--substeps", "0"], "--substeps 0"),
    (["sim", "nowhere", "--log", "{o}/x.csv"], "invalid choice"),
    (["sim", "hover", "--log", "{o}/no/x.csv"], "does not exist"),
    (["sim", "hover", "--log", "{o}"], "is a directory"),
    (["sim", "hover", "--log", "{o}/x.csv", "--plot", "{o}/x.jpg"], "should end in .png"),
    (["sim", "hover", "--log", "{o}/x.csv", "--seed", "-1"], "--seed -1"),
    (["sim", "hover", "--log", "{o}/x.csv", "--fault", "gremlin"], "gremlin"),
    (["sim", "paper", "--monte-carlo", "0"], "--monte-carlo 0"),
    (["sim", "paper", "--monte-carlo", "4", "--json", "{o}/no/mc.json"], "does not exist"),
    (["sim", "faults", "--json", "{o}/no/m.json"], "does not exist"),
    (["identify", "bench", "{o}/none.csv", "--json", "{o}/fit.json"], "none.csv"),
    (["identify", "bench", "{f}", "--json", "{o}/no/fit.json"], "does not exist"),
    (["diagnose", "{f}", "--json", "{o}/no/r.json"], "does not exist"),
    (["diagnose", "--corpus", "{o}", "--table", "{o}/no/t.md"], "does not exist"),
    (["log", "export", "{o}/none.csv", "{o}/x.ulg"], "none.csv"),
    (["log", "export", "{f}", "{o}/x.txt"], "should end in .ulg"),
    (["log", "import", "{o}/none.ulg", "{o}/x.csv"], "none.ulg"),
    (["log", "import", str(FOREIGN), "{o}/x.csv", "--plot", "{o}/no/p.png"], "does not exist"),
    (["run", "--board", "sim", "--plan", "hover", "--log", "{o}", "--min-battery-v", "-5"], "--min-battery-v -5"),
    (["run", "--board", "sim", "--plan", "hover", "--log", "{o}", "--min-battery-v", "nan"], "--min-battery-v nan"),
    (["run", "--board", "sim", "--plan", "hover", "--log", "{o}", "--calibrate", "-1"], "--calibrate -1"),
    (["run", "--board", "sim", "--plan", "hover", "--log", "{o}", "--plan-max-age", "inf"], "--plan-max-age inf"),
    (["run", "--frob"], "unrecognized arguments: --frob"),
    (["bench", "--board", "sim", "--settle", "1e300", "--out", "{o}/b.csv"], "--settle 1e+300"),
    (["bench", "--board", "sim", "--hold", "1e300", "--out", "{o}/b.csv"], "--hold 1e+300"),
    (["bench", "--board", "sim", "--step-timeout", "nan", "--out", "{o}/b.csv"], "--step-timeout nan"),
    (["bench", "--board", "sim", "--out", "{o}/no/b.csv"], "does not exist"),
    (["tune", "--out", "{o}/g.txt"], "should end in .toml"),
    (["tune", "--out", "{o}/g.toml", "--plot", "{o}/no/t.png"], "does not exist"),
    (["analyze", "--json", "{o}"], "is a directory"),
    (["hil", "demo", "--seconds", "-1", "--json", "{o}/h.json"], "--seconds -1"),
    (["hil", "demo", "--calibrate", "nan", "--json", "{o}/h.json"], "--calibrate nan"),
    (["hil", "demo", "--cut", "1", "inf", "--json", "{o}/h.json"], "--cut 1 inf"),
    (["hil", "demo", "--json", "{o}/no/h.json"], "does not exist"),
    (["params", "show", "no-such-vehicle"], "no-such-vehicle"),
    # the review's tries that were not clean (issue 49): wrong suffixes, conflicting or ignored options, a
    # key given twice, a board's options on a board without them
    (["sim", "hover", "--log", "{o}/x.txt"], "should end in .csv"),
    (["sim", "hover", "--log", "{o}/x.csv", "--json", "{o}/m.txt"], "should end in .json"),
    (["sim", "hover", "--log", "{o}/x.csv", "--plot", "{o}/x.png", "--no-plot"], "exclude each other"),
    (["sim", "hover", "--log", "{o}/x.csv", "--effect", "motor_lag:tau=0.1,tau=0.2"], "tau given twice"),
    (["sim", "hover", "--log", "{o}/x.csv", "--effect", "gremlin:k=1"], "gremlin"),
    (["sim", "hover", "--log", "{o}/x.csv", "--effect", "motor_lag:tau"], "bad item"),
    (["sim", "hover", "--log", "{o}/x.csv", "--effect", "motor_lag:tau=nan"], "tau"),
    (["sim", "hover", "--log", "{o}/x.csv", "--fault", "motor_stop:at=soon"], "not a number"),
    (["sim", "hover", "--log", "{o}/x.csv", "--gains", "table5"], "invalid choice"),
    (["sim", "faults", "--json", "{o}/m.txt"], "should end in .json"),
    (["run", "--board", "sim", "--plan", "hover", "--log", "{f}"], "not a directory"),
    (["run", "--board", "sim", "--plan", "hover", "--log", "{o}", "--board-file", "{f}"], "no wiring file"),
    (["run", "--board", "pi", "--plan", "hover", "--log", "{o}", "--board-file", "{o}/none.toml"], "no such file"),
    (["run", "--board", "hil", "--plan", "hover", "--log", "{o}"], "needs --link"),
    (["run", "--board", "hil", "--link", "nonsense", "--plan", "hover", "--log", "{o}"], "expected"),
    (["run", "--board", "sim", "--link", "tcp:1:2", "--plan", "hover", "--log", "{o}"], "no link"),
    (["run", "--board", "sim", "--plan-queue", "{f}", "--log", "{o}"], "not a directory"),
    (["bench", "--board", "nosuch", "--out", "{o}/b.csv"], "unknown board"),
    (["bench", "--board", "sim", "--out", "{o}/b.txt"], "should end in .csv"),
    (["bench", "--board", "sim", "--out", "{o}/b.csv", "--raw", "{o}/b.csv"], "the same file as --out"),
    (["bench", "--board", "sim", "--out", "{o}/b.csv", "--plot", "{o}/b.png", "--no-plot"], "exclude each other"),
    (["bench", "--board", "sim", "--out", "{o}/b.csv", "--board-file", "{f}"], "no wiring file"),
    (["bench", "--board", "sim", "--ramp", "1e9", "--out", "{o}/b.csv"], "--ramp 1e+09"),
    (["hil", "serve", "--link", "tcp:0", "--json", "{o}/h.txt"], "should end in .json"),
    (["hil", "demo", "--json", "{o}/h.txt"], "should end in .json"),
    (["analyze", "--json", "{o}/a.txt"], "should end in .json"),
    (["analyze", "--plot", "{o}/"], "a file-name prefix is needed"),
    (["analyze", "--alt", "nan"], "--alt nan"),
    (["diagnose", "{f}", "--json", "{o}/r.txt"], "should end in .json"),
    (["diagnose", "{f}", "--json", "{o}/r.json", "--plot", "{o}/"], "a file-name prefix is needed"),
    (["diagnose", "{f}", "--json", "{o}/r.json", "--steps", "{o}/s.jpg"], "should end in .png"),
    (["diagnose", "--corpus", "{o}", "--table", "{o}/t.txt"], "should end in .md"),
    (["diagnose", "--corpus", "{o}", "--json", "{o}/c.json", "--results", "{o}/r.txt"], "should end in .jsonl"),
    (["identify", "bench", "{f}", "--json", "{o}/fit.txt"], "should end in .json"),
    (["identify", "rcbenchmark", "{f}", "--out", "{o}/b.txt"], "should end in .csv"),
    (["tune", "--out", "{o}/g.toml", "--json", "{o}/t.txt"], "should end in .json"),
]


@pytest.mark.parametrize("argv, says", CASES, ids=[" ".join(a[:3]) + " " + s for a, s in CASES])
def test_a_bad_argument_is_one_line_exit_2_and_nothing_written(tmp_path, monkeypatch, capsys, argv, says):
    out = tmp_path / "out"
    out.mkdir()
    log = flight_log(tmp_path / "f.csv")
    monkeypatch.chdir(tmp_path)
    assert main([a.format(o=out, f=log) for a in argv]) == 2
    line = one_line(capsys.readouterr().err)
    assert line.startswith(f"flightctl {argv[0]}") and says in line, line
    assert list(out.iterdir()) == []


@pytest.mark.parametrize("argv", [["nosuch"], ["--frob"]])
def test_an_unknown_command_is_one_line(capsys, argv):
    """It printed the whole usage block (21 lines) after its line."""
    assert main(argv) == 2
    line = one_line(capsys.readouterr().err)
    assert line.startswith(f"flightctl: unknown command {argv[0]!r}") and "sim, identify" in line, line


# --- as a user without the privilege to write anywhere -----------------------------------------------
def _unprivileged() -> list[str] | None:
    """The command prefix that runs a child held to the permission bits, or None."""
    if os.geteuid() != 0:
        return []
    setpriv = shutil.which("setpriv")
    if setpriv is None:
        return None
    return [setpriv, "--bounding-set=-dac_override,-dac_read_search", "--inh-caps=-dac_override,-dac_read_search"]


def _flightctl(prefix, argv, cwd):
    return subprocess.run([*prefix, sys.executable, "-m", "flightctl.cli", *argv], cwd=cwd, capture_output=True,
                          text=True, timeout=120, env={**os.environ, "PYTHONUNBUFFERED": "1"})


@pytest.fixture
def unwritable(tmp_path):
    """(prefix, tmp_path, ro): `ro` a folder of mode 555 with a file `old.csv` of mode 444 in `tmp_path`."""
    prefix = _unprivileged()
    if prefix is None:
        pytest.skip("running as root without setpriv: no way to hold a child to the permission bits")
    ro = tmp_path / "ro"
    ro.mkdir()
    (tmp_path / "old.csv").write_text("kept\n")
    (tmp_path / "old.csv").chmod(0o444)
    ro.chmod(0o555)
    probe = subprocess.run([*prefix, sys.executable, "-c", f"import os; print(os.access({str(ro)!r}, os.W_OK))"],
                           capture_output=True, text=True, timeout=60)
    if probe.stdout.strip() != "False":
        ro.chmod(0o755)
        pytest.skip(f"the child could still write a folder of mode 555 ({probe.stdout.strip()} {probe.stderr.strip()})")
    yield prefix, tmp_path, ro
    ro.chmod(0o755)


UNWRITABLE = [
    (["sim", "hover", "--log", "ro/x.csv"], "--log ro/x.csv"),
    (["sim", "hover", "--log", "old.csv"], "--log old.csv: the file exists and is not writable"),
    (["sim", "paper", "--params", "paper-as-flown", "--monte-carlo", "4", "--json", "ro/mc.json"], "--json ro/mc.json"),
    (["sim", "paper", "--params", "paper-as-flown", "--monte-carlo", "4", "--plot", "ro/mc.png"], "--plot ro/mc.png"),
    (["log", "export", "f.csv", "ro/f.ulg"], "ro/f.ulg"),
    (["log", "import", str(FOREIGN), "ro/f.csv"], "ro/f.csv"),
    (["bench", "--board", "sim", "--out", "ro/b.csv"], "--out ro/b.csv"),
    (["tune", "--out", "ro/g.toml"], "--out ro/g.toml"),
    (["tune", "--out", "g.toml", "--plot", "ro/t.png"], "--plot ro/t.png"),
    (["hil", "demo", "--json", "ro/h.json"], "--json ro/h.json"),
    (["diagnose", "f.csv", "--json", "ro/r.json"], "--json ro/r.json"),
    (["diagnose", "--corpus", ".", "--table", "ro/t.md"], "--table ro/t.md"),
    (["identify", "yaw-drag", "f.csv", "--json", "ro/fit.json"], "--json ro/fit.json"),
    (["analyze", "--json", "ro/a.json"], "--json ro/a.json"),
]


@pytest.mark.parametrize("argv, says", UNWRITABLE, ids=[" ".join(a[:2]) + " " + s for a, s in UNWRITABLE])
def test_an_unwritable_output_is_refused_before_any_work(unwritable, argv, says):
    prefix, folder, ro = unwritable
    flight_log(folder / "f.csv")
    before = sorted(p.name for p in folder.iterdir())
    r = _flightctl(prefix, argv, folder)
    assert r.returncode == 2, r.stderr
    line = one_line(r.stderr)
    assert line.startswith(f"flightctl {argv[0]}") and says in line and "not writable by this user" in line, line
    assert list(ro.iterdir()) == [] and sorted(p.name for p in folder.iterdir()) == before
    assert (folder / "old.csv").read_text() == "kept\n"


def test_run_refuses_an_unwritable_log_folder_before_ready(unwritable):
    """run's own contract: nothing can fly is exit 3, one line in the journal, decided before READY=1."""
    prefix, folder, ro = unwritable
    r = _flightctl(prefix, ["run", "--board", "sim", "--plan", "hover", "--log", "ro/logs"], folder)
    assert r.returncode == 3, r.stderr
    assert "not writable by this user" in one_line(r.stderr)
    assert list(ro.iterdir()) == []


def test_a_home_that_cannot_be_written_adds_no_line(unwritable):
    """A service user's HOME=/nonexistent: matplotlib's config folder said nothing of (python-control
    imports it in analyze); the command's own output only."""
    prefix, folder, ro = unwritable
    env = {**os.environ, "HOME": str(ro / "home")}
    for var in ("MPLCONFIGDIR", "XDG_CONFIG_HOME", "XDG_CACHE_HOME"):
        env.pop(var, None)
    r = subprocess.run([*prefix, sys.executable, "-m", "flightctl.cli", "analyze", "--plot", "a"], cwd=folder,
                       capture_output=True, text=True, timeout=300, env=env)
    assert r.returncode == 0 and r.stderr == "", r.stderr
    assert (folder / "a-step.png").stat().st_size > 0 and list(ro.iterdir()) == []


@pytest.mark.parametrize("argv", [["--help"], ["--version"], ["params", "show"], ["sim", "--help"]])
def test_a_closed_stdout_is_silent(argv):
    """`flightctl --help | head -1`: the reader gone before the first write (a pipe whose read end is
    closed: every write fails, as PYTHONUNBUFFERED=1 makes the help's print fail); no traceback."""
    read, write = os.pipe()
    os.close(read)
    try:
        r = subprocess.run([sys.executable, "-P", "-m", "flightctl.cli", *argv], stdout=write, stderr=subprocess.PIPE,
                           text=True, timeout=120, env={**os.environ, "PYTHONUNBUFFERED": "1"})
    finally:
        os.close(write)
    assert r.returncode == 0 and r.stderr == "", r.stderr


# --- a disk without room for the flight's log ---------------------------------------------------------
def _disk_with(monkeypatch, folder: Path, free: int) -> None:
    """The OS's answer for `folder`'s disk: `free` bytes left (statvfs, what a full card answers)."""
    real = os.statvfs

    def statvfs(path):
        st = real(path)
        if Path(path).resolve() != folder.resolve():
            return st
        return os.statvfs_result((4096, 4096, st.f_blocks, free // 4096, free // 4096, *tuple(st)[5:]))
    monkeypatch.setattr(os, "statvfs", statvfs)


def test_a_disk_too_full_for_the_flight_log_is_found_before_flying(tmp_path, monkeypatch, capsys):
    """A hover's log takes about 4 MB (20 s hold, 450 rows a second); the free space is drawn below that."""
    import random
    free = random.Random(491).randrange(100_000, 3_000_000)
    _disk_with(monkeypatch, tmp_path, free)
    assert main(["sim", "hover", "--log", str(tmp_path / "h.csv"), "--no-plot"]) == 2
    line = one_line(capsys.readouterr().err)
    assert f"{free / 1e6:.1f} MB free on its disk" in line and "--log" in line, line
    assert list(tmp_path.iterdir()) == []


def test_run_refuses_a_plan_whose_log_has_no_room_before_ready(tmp_path, monkeypatch, caplog):
    """run's contract: a pre-arm refusal, exit 3, one line in the journal (its logger)."""
    import random
    free = random.Random(492).randrange(100_000, 3_000_000)
    logs = tmp_path / "logs"
    logs.mkdir()
    _disk_with(monkeypatch, logs, free)
    monkeypatch.delenv("NOTIFY_SOCKET", raising=False)
    assert main(["run", "--board", "sim", "--plan", "hover", "--log", str(logs), "--calibrate", "0.2"]) == 3
    refused = [r.getMessage() for r in caplog.records if r.levelname == "ERROR"]
    assert len(refused) == 1 and "not flying" in refused[0], refused
    assert f"{free / 1e6:.1f} MB free on its disk" in refused[0]
    assert list(logs.iterdir()) == []


def test_a_corpus_whose_reports_have_no_room_is_refused_before_the_first_log(tmp_path, monkeypatch, capsys):
    import random
    logs = tmp_path / "logs"
    logs.mkdir()
    n = random.Random(493).randrange(2, 6)
    for k in range(n):
        flight_log(logs / f"f{k}.csv")
    out = tmp_path / "out"
    out.mkdir()
    free = random.Random(494).randrange(0, n * 60_000)          # below n reports of 64 kB
    _disk_with(monkeypatch, out, free)
    assert main(["diagnose", "--corpus", str(logs), "--json", str(out / "c.json"), "--quiet"]) == 2
    line = one_line(capsys.readouterr().err)
    assert f"{free / 1e6:.1f} MB free on its disk" in line and f"{n} logs' reports" in line, line
    assert list(out.iterdir()) == []


def test_a_fault_matrix_whose_logs_have_no_room_is_refused_before_the_first_flight(tmp_path, monkeypatch, capsys):
    import random
    free = random.Random(495).randrange(100_000, 10_000_000)     # the matrix's logs take tens of MB
    _disk_with(monkeypatch, tmp_path, free)
    assert main(["sim", "faults", "--json", str(tmp_path / "m.json")]) == 2
    line = one_line(capsys.readouterr().err)
    assert line.startswith("flightctl sim: error: --logs") and f"{free / 1e6:.1f} MB free on its disk" in line, line
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow
def test_every_try_of_the_review_list_is_clean():
    """scripts/bad_args.py's 289 tries over every command (about 2 min on one core): each one line on
    stderr, exit 2, no traceback, nothing written, but the few marked `kept:` with their reason."""
    done = subprocess.run([sys.executable, str(ROOT / "scripts" / "bad_args.py")],
                          capture_output=True, text=True, timeout=1200)
    assert done.returncode == 0, [line for line in done.stdout.splitlines() if line.startswith("BAD")]
    assert re.search(r"(\d+) of (\d+) tries clean, (\d+) kept on purpose, 0 not clean", done.stdout)
