"""The bad arguments a reviewer tries (scripts/bad_args.txt), each run as a user runs it in a fresh folder
holding a flight log, empty, malformed and foreign files: a try is clean when it prints one line on
stderr, exits 2, shows no traceback and writes nothing (issue 49). Prints one line a try and the count;
exit 1 if a try not marked `kept:` is unclean.

    python scripts/bad_args.py [CASES.txt] [--timeout S]
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "tests"), str(ROOT / "tests" / "onboard")]   # helpers/ and tests/onboard/test_cli_bad_args.py
from test_cli_bad_args import FOREIGN, flight_log  # noqa: E402  (the tests' own flight log and foreign log)


def setup(d: Path) -> None:
    flight_log(d / "f.csv")
    (d / "empty.csv").write_text("")
    (d / "empty.toml").write_text("")
    (d / "bad.toml").write_text("[gains\nx = ")
    (d / "junk.csv").write_text("hello,world\n1,2\n")
    (d / "dir").mkdir()
    (d / "out").mkdir()
    (d / "f.txt").write_text("t,P1\n0,0\n")
    (d / "plan.toml").write_text('name = "p"\nduration = 10\n[[move]]\nt = 0\nchannel = "alt"\nvalue = 1e9\n')
    (d / "nanplan.toml").write_text('name = "p"\nduration = nan\n[[move]]\nt = 0\nchannel = "alt"\nvalue = 1\n')
    (d / "map.csv").write_text("log,vehicle\n")


def tree(d: Path) -> list:
    return sorted((str(p.relative_to(d)), p.stat().st_size if p.is_file() else -1) for p in d.rglob("*"))


def one(argv: list[str], timeout: float) -> tuple[list[str], str, float]:
    """The problems of one try (none: clean), its stderr and its time."""
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        setup(d)
        before, t0 = tree(d), time.perf_counter()
        try:
            r = subprocess.run([sys.executable, "-m", "flightctl.cli", *argv], cwd=d, capture_output=True, text=True,
                               timeout=timeout, stdin=subprocess.DEVNULL)
            rc, err = r.returncode, r.stderr
        except subprocess.TimeoutExpired as e:
            rc, err = "a timeout", e.stderr.decode() if isinstance(e.stderr, bytes) else (e.stderr or "")
        dt, after = time.perf_counter() - t0, tree(d)
    lines = err.strip().splitlines()
    problems = [f"exit {rc}"] if rc != 2 else []
    problems += [f"{len(lines)} lines"] if len(lines) != 1 else []
    problems += ["a traceback"] if "Traceback" in err else []
    problems += [f"wrote {sorted(set(after) - set(before))}"] if after != before else []
    return problems, err.strip(), dt


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("cases", nargs="?", default=str(Path(__file__).with_suffix(".txt")))
    ap.add_argument("--timeout", type=float, default=40.0)
    a = ap.parse_args(argv)
    bad = clean = kept = 0
    for line in Path(a.cases).read_text().splitlines():
        if not line.strip() or line.startswith("#"):
            continue
        cmd, _, why = line.partition("\tkept: ")
        args = [w.replace("{FOREIGN}", str(FOREIGN)) for w in cmd.split()]
        problems, err, dt = one(args, a.timeout)
        if not problems:
            clean += 1
            print(f"ok   {dt:5.1f} s  {cmd} :: {err.splitlines()[0][:150]}", flush=True)
        elif why:
            kept += 1
            print(f"kept {dt:5.1f} s  {cmd} :: {', '.join(problems)} ({why})", flush=True)
        else:
            bad += 1
            print(f"BAD  {dt:5.1f} s  {cmd} :: {', '.join(problems)} :: {err[-300:]!r}", flush=True)
    print(f"{clean} of {clean + bad + kept} tries clean, {kept} kept on purpose, {bad} not clean")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
