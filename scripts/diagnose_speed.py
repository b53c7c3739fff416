"""`flightctl diagnose`'s CPU past the reading, this checkout's code against another commit's, side by
side: `python scripts/diagnose_speed.py --against REV [--rounds N] [--markdown] [LOG ...]`.

Each log is read once, here, as the command reads it (`read_logs`), and kept in a temporary file; then,
round after round, a child process on REV's code (scripts/revision.py) and one on this checkout's run
the command's own `main` on it (`--json`, `--quiet`), its reading answered from that file, and each
says the CPU seconds (`time.process_time`: user and system, one BLAS thread) from the command's start
to its report written. The two alternate, so that what other work on a shared machine takes from them
falls on both alike; the figure of each side is its median over the rounds, beside the smallest and
largest. The reading (a third-party decoder, the same code on both sides: the logs are read once) is
left out; scripts/benchmark.py measures it with the rest. The two reports are compared key for key
(`runtime_s` aside): the change is a speed-up only where they are equal.

The default logs: better_tune.BBL (tests/data/pid-analyzer, Betaflight, 129.5 s at 1 kHz), log171.bin
(tests/data/ardupilot, an ArduPilot DataFlash log) and quadrotor_local.ulg (the shared data's PX4 ULog).
"""
from __future__ import annotations

import argparse
import datetime
import json
import os
import pickle
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from flightctl.blas import ONE_THREAD  # noqa: E402
from flightctl.errors import InputError  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
LOGS = (ROOT / "tests" / "data" / "pid-analyzer" / "better_tune.BBL", ROOT / "tests" / "data" / "ardupilot" / "log171.bin",
        ROOT / ".." / "shared" / "data" / "real" / "flights" / "px4" / "quadrotor_local.ulg")
STAMP = ("Measured by `python scripts/diagnose_speed.py --markdown` on {date}: {machine}; CPU seconds of "
         "`flightctl diagnose` past the reading, the two codes alternating in child processes.")
HEADER = ("| log | CPU on the code of `--against` (s: median, smallest-largest) | on this code (s) | change | the two reports |",
          "|---|---|---|---|---|")


def _inner(log: str, tables: str, out: str) -> None:
    """(the child) The command's main on `log`, its tables from the pickle `tables`; prints its CPU seconds."""
    import contextlib
    import io
    import time
    from flightctl.sim.diagnose import cli
    with open(tables, "rb") as f:
        kept = pickle.load(f)
    cli.read_logs = lambda paths, index, progress: kept if paths == [log] else []
    start = time.process_time()
    with contextlib.redirect_stdout(io.StringIO()):
        rc = cli.main([log, "--json", out, "--quiet"])
    print(f"{rc} {time.process_time() - start:.3f}")


def _run(log: str, tables: str, out: str, path: str | None) -> float:
    env = {**os.environ, **ONE_THREAD}
    env.pop("PYTHONPATH", None)
    if path is not None:
        env["PYTHONPATH"] = path
    r = subprocess.run([sys.executable, os.path.abspath(__file__), "--inner", log, tables, out], env=env,
                       check=True, stdout=subprocess.PIPE, text=True)
    rc, cpu = r.stdout.split()[-2:]
    if rc != "0":
        raise RuntimeError(f"diagnose of {log} exited {rc}")
    return float(cpu)


def differences(a, b, where: str = "") -> list[str]:
    """The keys at which two reports differ (`runtime_s` aside)."""
    if isinstance(a, dict) and isinstance(b, dict):
        out = [f"{where}/{k}" for k in set(a) ^ set(b)]
        for k in a.keys() & b.keys():
            if k != "runtime_s":
                out += differences(a[k], b[k], f"{where}/{k}")
        return out
    if isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            return [where]
        return [d for i, (x, y) in enumerate(zip(a, b)) for d in differences(x, y, f"{where}[{i}]")]
    return [] if a == b or (a != a and b != b) else [where]


def compare(log: Path, rev_path: str, rounds: int) -> dict:
    """Both codes' CPU seconds over `rounds` alternating rounds on one log, and their reports' differences."""
    from flightctl.sim.diagnose.cli import read_logs
    with tempfile.TemporaryDirectory() as tmp:
        tables = os.path.join(tmp, "tables.pkl")
        with open(tables, "wb") as f:
            pickle.dump(read_logs([str(log)], None, lambda *a: None), f)
        then, now = [], []
        for _ in range(rounds):
            then.append(_run(str(log), tables, os.path.join(tmp, "then.json"), rev_path))
            now.append(_run(str(log), tables, os.path.join(tmp, "now.json"), None))
        with open(os.path.join(tmp, "then.json")) as f, open(os.path.join(tmp, "now.json")) as g:
            diff = differences(json.load(f), json.load(g))
    return {"log": log.name, "then": then, "now": now, "differences": sorted(diff)}


def row(r: dict) -> str:
    m0, m1 = statistics.median(r["then"]), statistics.median(r["now"])
    d = r["differences"]
    same = "equal key for key (runtime_s aside)" if not d else f"{len(d)} keys differ: " + ", ".join(d[:4])
    return (f"| {r['log']} | {m0:.1f} ({min(r['then']):.1f}-{max(r['then']):.1f}) | {m1:.1f} "
            f"({min(r['now']):.1f}-{max(r['now']):.1f}) | {100.0 * (m1 / m0 - 1.0):+.0f} % | {same} |")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("logs", nargs="*", help="the logs (default: better_tune.BBL, log171.bin, quadrotor_local.ulg)")
    ap.add_argument("--against", metavar="REV", help="the commit whose code to set beside this one (required)")
    ap.add_argument("--rounds", type=int, default=3, help="alternating rounds of each log (default 3)")
    ap.add_argument("--markdown", action="store_true", help="print docs/diagnose.md's block: the date, the machine, a table")
    ap.add_argument("--inner", nargs=3, help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.inner:
        _inner(*a.inner)
        return 0
    import revision
    logs = [Path(p) for p in a.logs] or list(LOGS)
    with tempfile.TemporaryDirectory() as tmp:
        try:
            if a.against is None:
                raise InputError("--against REV: name the commit whose code to set beside this one")
            if a.rounds < 1:
                raise InputError(f"--rounds {a.rounds}: at least 1")
            for log in logs:
                if not log.is_file():
                    raise InputError(f"{log}: no such log")
            path = revision.package(a.against, tmp)
        except InputError as e:
            print(f"diagnose_speed: {e}", file=sys.stderr)
            return 2
        results = [compare(log, path, a.rounds) for log in logs]
    lines = [*HEADER, *map(row, results)]
    if a.markdown:
        from benchmark import machine
        where = f"{machine()}; `--against {a.against}`, the code of {revision.day(a.against)}, {a.rounds} rounds"
        lines = [STAMP.format(date=datetime.date.today().isoformat(), machine=where), ""] + lines
    else:
        lines.insert(0, f"--against {a.against} ({revision.day(a.against)})")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
