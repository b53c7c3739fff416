"""The fleet's scale, measured (issue 38, item 5; docs/fleet.md, "Scale"): `flightctl diagnose --corpus`
run as a user runs it (its own process, the engine's local Dask cluster) on a simulated fleet's logs
(sim/sweeps/fleet_flown.py: ArduCopter DataFlash at ArduPilot's default rates, 22 s flights, each its own
seed), timed by the wall clock, its workers' memory read from the kernel.

    python scripts/fleet_scale.py [--logs 1000] [--sample 100] [--doc docs/fleet.md]

- logs per hour on 1 and on 2 workers (the same `--sample` logs; their ratio is the scaling, the
  engine's start-up included, as a user pays it);
- the whole `--logs` corpus end to end on the machine's cores: its wall time, its rows (every log
  one), the workers' and the command's peak resident memory (VmHWM of /proc/PID/status, read every
  0.2 s from each process under the command until it ends: each worker's high-water mark);
- on paper, what 10,000 logs need on a cluster of N machines of C cores, from a line through the two
  2-worker runs (the sample's and the whole corpus's wall times): its slope is what a log costs a worker,
  its intercept the start-up (the cluster's, the workers' imports); the command's own CPU a log is
  serial (it hashes each log, writes its row, keeps the table, and on the local cluster runs Dask's
  scheduler, whose cost docs.dask.org's "Dask Best Practices" puts at "somewhere between 200us and 1ms"
  a task): 10,000 logs take the start-up plus the larger of the workers' share and the serial part.
  Memory: C workers' peak a machine, and the command's, on a line through its two 2-worker peaks.

The figures are this machine's on the day; the block says when and where (tests/project/test_docs.py checks
the block's form, never its numbers)."""
from __future__ import annotations

import argparse
import math
import os
import platform
import subprocess
import sys
import tempfile
import threading
import time
from datetime import date
from pathlib import Path

import numpy as np

BEGIN, END = "<!-- fleet-scale:begin -->", "<!-- fleet-scale:end -->"
FLIGHT_S = 22.0                 # each simulated flight, from arming (sim/sweeps/fleet_flown.py's shortest plan)
CLUSTERS = ((1, 2), (1, 8), (4, 8), (16, 8))      # (machines, cores each) for the estimate


def peak_kib(pid: int) -> int:
    """The process's peak resident memory (VmHWM), KiB; 0 once it is gone."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1])
    except OSError:
        pass
    return 0


def descendants(pid: int) -> list[int]:
    """The processes under `pid`: its children, theirs, ... (from /proc's parent links; tests/sim/diagnose/test_corpus.py
    uses it too)."""
    parent = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                parent[int(entry.name)] = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
            except (OSError, IndexError, ValueError):
                continue
    out, frontier = [], [pid]
    while frontier:
        frontier = [p for p, pp in parent.items() if pp in frontier]
        out += frontier
    return out


def cpu_s(pid: int) -> float:
    """The process's own CPU time (utime + stime of /proc/PID/stat), s; 0 once it is gone."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return 0.0


def comm(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
    except OSError:
        return ""


def corpus_run(folder: Path, workers: int, out: Path) -> dict:
    """`flightctl diagnose --corpus folder --json out --jobs workers`, timed; the peak memory of the
    command and of each worker process under it (the Dask workers: not the fork server or the nanny)."""
    cmd = [sys.executable, "-P", "-m", "flightctl.cli", "diagnose", "--corpus", str(folder), "--json", str(out),
           "--jobs", str(workers), "--quiet"]
    start = time.perf_counter()
    p = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    peaks: dict[int, tuple[int, str]] = {}
    cpu = [0.0]                        # the command's own CPU (not its children's), s
    stop = threading.Event()

    def watch() -> None:
        while not stop.is_set():
            for pid in [p.pid] + descendants(p.pid):
                kib = peak_kib(pid)
                if pid == p.pid:
                    cpu[0] = max(cpu[0], cpu_s(pid))
                if kib:
                    peaks[pid] = (max(kib, peaks.get(pid, (0, ""))[0]), peaks.get(pid, (0, comm(pid)))[1] or comm(pid))
            stop.wait(0.2)
    w = threading.Thread(target=watch, daemon=True)
    w.start()
    _, err = p.communicate()
    wall = time.perf_counter() - start
    stop.set()
    w.join()
    if p.returncode != 0:
        raise SystemExit(f"fleet_scale: {' '.join(cmd)} exited {p.returncode}: {err.strip()[-400:]}")
    import json
    rows = json.loads(out.read_text())["logs"]
    # a Dask worker is forked from multiprocessing's fork server (its command line names the server)
    workers_kib = [k for pid, (k, c) in peaks.items() if pid != p.pid and "forkserver" in c]
    return {"wall_s": wall, "rows": len(rows), "diagnosed": sum(r["status"] == "diagnosed" for r in rows),
            "logs_per_h": len(rows) / wall * 3600.0, "command_cpu_s": cpu[0],
            "tiers": sorted({f"{r['status']}" + (f" ({r['report']['tier']} tier)" if r.get("report") else "")
                         for r in rows}),
            "main_mib": peaks.get(p.pid, (0, ""))[0] / 1024.0,
            "worker_mib": max(workers_kib) / 1024.0 if workers_kib else float("nan"),
            "workers_seen": len(workers_kib)}


def simulate(folder: Path, logs: int, seed: int) -> float:
    """`logs` short flights (40 a vehicle) into `folder`; the seconds it took."""
    from flightctl.sim.sweeps.fleet_flown import simulate_fleet
    start = time.perf_counter()
    vehicles = math.ceil(logs / 40)
    simulate_fleet(folder, np.random.default_rng(seed), vehicles=vehicles, flights=40, seconds=FLIGHT_S,
                   progress=lambda text: print(f"fleet_scale: {text}", file=sys.stderr, flush=True))
    extra = sorted(folder.iterdir())[logs:]
    for f in extra:                        # exactly `logs` of them
        f.unlink()
    return time.perf_counter() - start


def subset(folder: Path, into: Path, n: int) -> Path:
    into.mkdir(parents=True, exist_ok=True)
    for f in sorted(folder.iterdir())[:n]:
        (into / f.name).symlink_to(f)
    return into


def measure(logs: int, sample: int, seed: int) -> dict:
    tmp = Path(tempfile.mkdtemp(prefix="fleet-scale-"))
    corpus = tmp / "logs"
    sim_s = simulate(corpus, logs, seed)
    part = subset(corpus, tmp / "sample", sample)
    out = {"logs": logs, "sample": sample, "sim_s": sim_s, "cores": os.cpu_count() or 1,
           "by_workers": {w: corpus_run(part, w, tmp / f"sample{w}.json") for w in (1, 2)}}
    out["all"] = corpus_run(corpus, out["cores"], tmp / "all.json")
    return out


HEADER = ("| run | logs | wall time | logs per hour | peak memory: a worker / the command |", "|---|---|---|---|---|")
STAMP = "Measured by `python scripts/fleet_scale.py` on {date}: {machine}."


def markdown(m: dict) -> str:
    """The block (scripts/docs.py's measured form: the stamp, a blank line, one table)."""
    one, two, full = m["by_workers"][1], m["by_workers"][2], m["all"]
    slope = (full["wall_s"] - two["wall_s"]) / (full["rows"] - two["rows"])      # s of wall a log, 2 workers
    per_log, startup = slope * 2, two["wall_s"] - slope * two["rows"]             # worker-s a log; s
    grows = (full["main_mib"] - two["main_mib"]) / (full["rows"] - two["rows"])   # the command's MiB a log
    serial = full["command_cpu_s"] / full["rows"]     # s a log, one at a time (the local scheduler in it)
    machine = (f"{platform.machine()}, {m['cores']} cores, Python {platform.python_version()}; {m['logs']:,} simulated "
               f"{FLIGHT_S:g} s flights (ArduCopter DataFlash at the default rates, made in {m['sim_s']:.0f} s), "
               f"{full['diagnosed']:,} of them diagnosed ({full['rows']:,} rows: {', '.join(full['tiers'])})")
    lines = [STAMP.format(date=date.today().isoformat(), machine=machine), "", *HEADER]
    for w, r in ((1, one), (2, two)):
        lines.append(f"| {w} worker{'s' * (w > 1)} | {r['rows']} | {r['wall_s']:.0f} s | {r['logs_per_h']:,.0f} | "
                     f"{r['worker_mib']:.0f} / {r['main_mib']:.0f} MiB |")
    lines.append(f"| 2 workers against 1 | - | - | {two['logs_per_h'] / one['logs_per_h']:.2f}x | - |")
    lines.append(f"| the whole corpus, {m['cores']} workers | {full['rows']:,} | {full['wall_s']:.0f} s | "
                 f"{full['logs_per_h']:,.0f} | {full['worker_mib']:.0f} / {full['main_mib']:.0f} MiB |")
    for machines, cores in CLUSTERS:
        n = machines * cores
        t = startup + 10000 * max(per_log / n, serial)
        lines.append(f"| on paper: {machines} machine{'s' * (machines > 1)} x {cores} cores ({per_log:.3f} worker-s "
                     f"a log, {startup:.1f} s start-up, {serial * 1e3:.1f} ms a log serial) | 10,000 | {t / 60:.1f} min | "
                     f"{10000 / t * 3600:,.0f} | {cores * full['worker_mib'] / 1024:.1f} GiB a machine; the command "
                     f"{two['main_mib'] + grows * (10000 - two['rows']):.0f} MiB |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--logs", type=int, default=1000, help="the corpus's logs (default 1000)")
    ap.add_argument("--sample", type=int, default=100, help="the logs timed on 1 and 2 workers (default 100)")
    ap.add_argument("--seed", type=int, default=38)
    ap.add_argument("--doc", help="write the block into this Markdown file (between its markers)")
    a = ap.parse_args(argv)
    if a.logs < 13 or not 1 <= a.sample <= a.logs:
        ap.error("--logs at least 13 and --sample between 1 and --logs")
    text = markdown(measure(a.logs, a.sample, a.seed))
    from flightctl.sim.docs import publish
    publish(text, a.doc, BEGIN, END)
    return 0


if __name__ == "__main__":
    sys.exit(main())
