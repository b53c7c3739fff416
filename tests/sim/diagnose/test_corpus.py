"""`flightctl diagnose --corpus` on the engine (sim/engine.py, Dask): each log's row in the results
table as it finishes, a run stopped by Ctrl-C and started again skips the logs already done, a log that
kills its worker is its own row and the others finish, and a command killed outright leaves no
workers. The corpus: five of tests/data/ardupilot's logs (each read and judged in a worker; nan.log
takes seconds, the others less than one)."""
from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytest.importorskip("distributed")

from flightctl.sim.diagnose.corpus import CRASH_ENV  # noqa: E402
from helpers.script import load  # noqa: E402
from helpers.paths import DATA

descendants = load("fleet_scale").descendants      # the processes under a pid (from /proc)

EXAMPLES = DATA / "ardupilot"
LOGS = ("backend_log_80k.bin", "mechanical_fail.log", "nan.log", "tradheli_brownout.log", "underpowered.log")
WAIT_S = 600.0           # a bound on a stuck command only (a busy machine), never a judged time


@pytest.fixture
def corpus(tmp_path) -> Path:
    folder = tmp_path / "logs"
    folder.mkdir()
    for name in LOGS:
        shutil.copy(EXAMPLES / name, folder / name)
    return folder


def command(folder: Path, out: Path, *extra: str, env: dict | None = None) -> subprocess.Popen:
    """`flightctl diagnose --corpus` as its own process group (Ctrl-C reaches the group, as a terminal's)."""
    return subprocess.Popen([sys.executable, "-P", "-m", "flightctl.cli", "diagnose", "--corpus", str(folder), "--json",
                             str(out), *extra], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True, env={**os.environ, **(env or {})})


def rows(results: Path) -> list[dict]:
    return [json.loads(line) for line in results.read_text().splitlines()] if results.exists() else []


def wait_for_rows(p: subprocess.Popen, results: Path, n: int) -> None:
    start = time.monotonic()
    while len(rows(results)) < n:
        assert p.poll() is None, f"the command ended ({p.returncode}) before {n} rows: {p.communicate()}"
        assert time.monotonic() - start < WAIT_S, "no row written"
        time.sleep(0.05)


def alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def test_a_run_stopped_by_ctrl_c_resumes_without_running_the_done_logs_again(corpus, tmp_path):
    out = tmp_path / "rows.json"
    results = tmp_path / "rows.results.jsonl"
    for attempt in range(3):       # a busy machine may pause this test until the run has finished: again
        p = command(corpus, out, "--jobs", "1", "--quiet")
        wait_for_rows(p, results, 1)
        os.killpg(p.pid, signal.SIGINT)
        _, err = p.communicate(timeout=WAIT_S)
        if not (p.returncode == 0 and len(rows(results)) == len(LOGS)):
            break
        out.unlink()
        results.unlink()
        shutil.rmtree(tmp_path / "rows.results.reports", ignore_errors=True)
    assert p.returncode == 130 and err.strip() == "flightctl diagnose: interrupted", err
    assert not out.exists()
    first = rows(results)
    assert 1 <= len(first) < len(LOGS)
    assert len({r["log"] for r in first}) == len(first)

    again = command(corpus, out, "--jobs", "1")
    _, err = again.communicate(timeout=WAIT_S)
    assert again.returncode == 0, err
    done_first = {r["log"] for r in first}
    assert f"{len(first)} logs already in {results}, not run again" in err
    ran = {line.split("] ", 1)[1].split(":")[0] for line in err.splitlines() if line.startswith("diagnose --corpus [")}
    assert ran == set(LOGS) - done_first, err                   # only the rest was run
    second = rows(results)
    assert second[:len(first)] == first                         # the first run's rows kept as they were
    assert sorted(r["log"] for r in second) == sorted(LOGS)     # each log once
    logs = json.loads(out.read_text())["logs"]
    assert [entry["log"] for entry in logs] == sorted(LOGS)
    by_log = {r["log"]: r for r in second}
    for entry in logs:                                          # the report is the results table's, read back
        r = by_log[entry["log"]]
        assert entry["status"] == r["status"] and (entry["refused"] or None) == r["reason"]
        if r["report"]:
            assert entry["report"] == json.loads(Path(r["report"]).read_text())


def test_a_log_that_kills_its_worker_is_recorded_and_the_rest_finish(corpus, tmp_path):
    out = tmp_path / "rows.json"
    victim = LOGS[3]
    p = command(corpus, out, "--jobs", "2", "--quiet", env={CRASH_ENV: victim})
    _, err = p.communicate(timeout=WAIT_S)
    assert p.returncode == 0, err
    got = {r["log"]: r for r in rows(tmp_path / "rows.results.jsonl")}
    assert sorted(got) == sorted(LOGS)
    assert got[victim]["status"] == "failed" and got[victim]["reason"].startswith("worker died"), got[victim]
    assert all(r["status"] != "failed" for name, r in got.items() if name != victim), got
    # the same logs without the crash: the same rows but the victim's
    clean = tmp_path / "clean.json"
    q = command(corpus, clean, "--jobs", "2", "--quiet")
    assert q.communicate(timeout=WAIT_S) and q.returncode == 0
    again = {r["log"]: r for r in rows(tmp_path / "clean.results.jsonl")}
    assert again[victim]["status"] != "failed"
    assert all((again[n]["status"], again[n]["reason"]) == (got[n]["status"], got[n]["reason"])
               for n in LOGS if n != victim)


def test_a_killed_command_leaves_no_workers(corpus, tmp_path):
    """Dask's worker process exits when its parent's pipe closes (distributed/process.py): SIGKILL on
    the command, nothing of it left running."""
    p = command(corpus, tmp_path / "rows.json", "--jobs", "2", "--quiet")
    wait_for_rows(p, tmp_path / "rows.results.jsonl", 1)
    workers = descendants(p.pid)            # the fork server, its two workers, the resource tracker
    assert len(workers) >= 3, workers
    p.kill()
    p.wait()
    start = time.monotonic()
    while any(alive(w) for w in workers):
        assert time.monotonic() - start < WAIT_S, [w for w in workers if alive(w)]
        time.sleep(0.1)


def test_without_dask_the_work_runs_here_and_says_how_to_get_the_engine(monkeypatch, capsys):
    from flightctl.sim import engine
    monkeypatch.setitem(sys.modules, "distributed", None)      # as if the fleet extra were not installed
    monkeypatch.setattr(engine, "_hinted", [False])
    monkeypatch.setattr(engine, "_said", {"quiet": False})   # an earlier --quiet command in this process unsays it
    seen = []
    assert engine.run(str.upper, ["a", "b", "c"], 2, lambda k, r: seen.append((k, r))) == ["A", "B", "C"]
    assert engine.run(str.lower, ["D"], 2) == ["d"]
    assert seen == [(0, "A"), (1, "B"), (2, "C")]
    err = capsys.readouterr().err
    assert err.count("pip install '.[fleet]'") == 1, err


def free_port() -> int:
    import socket
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_a_cluster_started_apart_is_used_by_its_address(corpus, tmp_path):
    """A scheduler and a worker started as a cluster's would be (Dask's own `dask scheduler` and
    `dask worker`), the command pointed at it by DASK_SCHEDULER_ADDRESS: the scheduler ran the logs,
    and the rows are the local cluster's."""
    address = f"tcp://127.0.0.1:{free_port()}"
    dask = Path(sys.executable).parent / "dask"
    worker_log = tmp_path / "worker.log"
    procs = [subprocess.Popen([str(dask), "scheduler", "--host", "127.0.0.1", "--port", address.rsplit(":", 1)[1],
                               "--no-dashboard"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
    try:
        procs.append(subprocess.Popen([str(dask), "worker", address, "--nthreads", "1", "--nworkers", "1",
                                       "--no-dashboard"], stdout=subprocess.DEVNULL, stderr=open(worker_log, "w")))
        p = command(corpus, tmp_path / "remote.json", "--quiet", env={"DASK_SCHEDULER_ADDRESS": address})
        _, err = p.communicate(timeout=WAIT_S)
        assert p.returncode == 0, err
        from distributed import Client
        with Client(address, timeout=60) as client:     # what the scheduler ran: the corpus's logs
            ran = client.run_on_scheduler(lambda dask_scheduler: {
                prefix: dict(tp.all_durations) for prefix, tp in dask_scheduler.task_prefixes.items()})
        assert ran.get("run_one", {}).get("compute", 0.0) > 0.0, ran     # computed there
        local = command(corpus, tmp_path / "local.json", "--jobs", "2", "--quiet")
        assert local.communicate(timeout=WAIT_S) and local.returncode == 0
    finally:
        for q in reversed(procs):
            q.terminate()
            q.wait(timeout=WAIT_S)
    remote = json.loads((tmp_path / "remote.json").read_text())["logs"]
    assert remote == json.loads((tmp_path / "local.json").read_text())["logs"]
    assert [entry["log"] for entry in remote] == sorted(LOGS)
    assert "Registered to" in worker_log.read_text() and address in worker_log.read_text()


def test_ctrl_c_while_the_local_cluster_starts_is_one_line_and_ends_everything(corpus, tmp_path):
    """Ctrl-C as soon as the engine has begun to start its workers (its fork server is there): the
    command's one line, exit 130, none of the half-started workers' tracebacks, nothing left running."""
    p = command(corpus, tmp_path / "rows.json", "--jobs", "2", "--quiet")
    start = time.monotonic()
    while not descendants(p.pid):
        assert p.poll() is None and time.monotonic() - start < WAIT_S
        time.sleep(0.01)
    group = descendants(p.pid)
    os.killpg(p.pid, signal.SIGINT)
    _, err = p.communicate(timeout=WAIT_S)
    assert p.returncode == 130 and err.strip() == "flightctl diagnose: interrupted", err
    start = time.monotonic()
    while any(alive(w) for w in group + descendants(p.pid)):
        assert time.monotonic() - start < WAIT_S
        time.sleep(0.1)
    assert not (tmp_path / "rows.json").exists()


def test_the_monte_carlo_on_the_engine_is_the_in_process_one_draw_for_draw():
    """The same draws, seeds and verdicts whether the flights run on two Dask workers or one after
    the other in this process (the full path, and the batched simulator's vehicles split over workers)."""
    from flightctl.sim.sweeps import montecarlo
    seed = int(__import__("numpy").random.default_rng(38).integers(0, 1000))
    assert montecarlo.run("paper-as-flown", "step_roll", 2, seed=seed, jobs=2) == \
        montecarlo.run("paper-as-flown", "step_roll", 2, seed=seed, jobs=1)
    assert montecarlo.run_batch("paper-as-flown", "step_roll", 4, seed=seed, workers=2) == \
        montecarlo.run_batch("paper-as-flown", "step_roll", 4, seed=seed, workers=1)


def test_the_local_workers_run_with_one_blas_thread_and_glibc_s_own_memory_thresholds():
    """The local cluster's workers get one BLAS thread each, and not Dask's MALLOC_TRIM_THRESHOLD_, which
    maps and unmaps every array over 128 KiB anew (diagnose of better_tune.BBL took 65 s of CPU with it,
    33 s without); nor does this process, into which Dask's nanny writes its variables (and from which
    every later child, a log diagnosed or a command the benchmark times, would inherit it)."""
    from flightctl.sim import engine
    assert "MALLOC_TRIM_THRESHOLD_" not in os.environ
    names = ["MALLOC_TRIM_THRESHOLD_", "OPENBLAS_NUM_THREADS"] * 2
    assert engine.run(os.getenv, names, 2, isolate=True) == [None, "1"] * 2
    assert "MALLOC_TRIM_THRESHOLD_" not in os.environ


@pytest.mark.parametrize("address", ["tcp://127.0.0.1:{port}", "127.0.0.1", "udp://127.0.0.1:{port}"])
def test_a_scheduler_that_does_not_answer_is_one_line_and_nothing_written(corpus, tmp_path, address):
    address = address.format(port=free_port())             # nothing listens there, or not an address
    p = command(corpus, tmp_path / "rows.json", "--scheduler", address, "--quiet",
                env={"DASK_DISTRIBUTED__COMM__TIMEOUTS__CONNECT": "2s"})
    _, err = p.communicate(timeout=WAIT_S)
    assert p.returncode == 2, err
    assert len(err.strip().splitlines()) == 1 and f"--scheduler {address}: no Dask scheduler answers there" in err
    assert sorted(x.name for x in tmp_path.iterdir()) == ["logs"]


def test_a_results_row_of_other_code_is_not_reused(tmp_path, monkeypatch):
    """A row is reused only by the code that wrote it: the same log judged by other readers or another
    diagnosis (another digest of their sources) is diagnosed again, not read back."""
    from flightctl.sim.diagnose import results as res
    from flightctl.sim.diagnose.corpus import Row
    log = tmp_path / "a.csv"
    log.write_text("t,P1\n0,1\n")
    table = res.Results(tmp_path / "r.results.jsonl")
    row = Row(log="a.csv", path=str(log), index=None, status="refused", reason="too short to judge")
    table.write(row)
    assert table.key(row) in table.done()
    monkeypatch.setattr(res, "code_digest", lambda: "another-version")
    assert res.Results(table.path).done() == {}
    log.write_text("t,P1\n0,2\n")                                  # and a log rewritten is not the same log
    assert res.Results(table.path).key(row) != table.key(row)


def test_a_corpus_with_a_results_table_holds_no_report_in_memory_and_its_json_reads_them_back(corpus, tmp_path):
    """Each finished log's report goes to the results table's folder and leaves the row (a corpus of
    thousands is not held until the end); the table's cells and `--json`'s reports are still the logs'."""
    from flightctl.sim.diagnose.corpus import corpus as run_corpus, corpus_json, table
    rows = run_corpus(corpus, 2, results=tmp_path / "r.jsonl")
    diagnosed = [r for r in rows if r.status == "diagnosed"]
    assert diagnosed and all(r.report is None and Path(r.report_file).is_file() for r in diagnosed)
    text = table(rows)
    assert all(r.log in text for r in rows)
    logs = json.loads("".join(corpus_json([str(corpus)], rows)))["logs"]
    assert [e["log"] for e in logs] == sorted(LOGS)
    for e, r in zip(logs, rows):
        assert e["report"] == (json.loads(Path(r.report_file).read_text()) if r.report_file else None)
        assert (e["report"] is not None) == (r.status == "diagnosed")
