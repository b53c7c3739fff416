"""The engine behind the sweeps (the Monte Carlo, the batched simulator, `tune --robust`, diagnose's
corpus and pairs): Dask's distributed scheduler when the `fleet` extra is installed, else the same
work in this process, one item at a time (said once, with how to get the parallel engine).

With Dask: a local cluster by default (`distributed.LocalCluster`: worker processes under a nanny,
one thread and one BLAS thread each, as many as asked or the machine's cores), kept for the
command's life so that each worker compiles the plant once; or an existing cluster, by `use(address)`
(`--scheduler tcp://HOST:8786`) or Dask's own setting (`DASK_SCHEDULER_ADDRESS`, the config key
`scheduler-address`: https://docs.dask.org/en/stable/configuration.html). Its dashboard's address is
printed when there is one.

Ctrl-C: the command's one line and exit 130 (flightctl/cli.py). The local workers are ended at once
(their processes killed, not waited for); a remote cluster's tasks are cancelled. A killed command
leaves no workers either: Dask's worker process exits as soon as its parent's pipe closes
(distributed/process.py, `AsyncProcess._immediate_exit_when_closed`; tests/test_engine.py kills a
command with SIGKILL and checks).

A worker that dies (a log that crashes it) fails its item with `WorkerDied`, not the run's other
items: `run(..., died=...)` records it; without `died` it is raised. The local cluster marks an
item bad on its first death (`allowed-failures` 0, one item per worker thread at a time), so that
the item that killed the worker is the one blamed and is not flown again.
"""
from __future__ import annotations

import atexit
import logging
import os
import sys
from typing import Callable, Iterable

HINT = ("one item at a time in this process; for the parallel engine (Dask): pip install '.[fleet]' in the "
        "flightctl checkout")

_address: str | None = None         # `use(address)`: an existing cluster's scheduler
_engine: dict = {}                  # the client (and local cluster) kept for the command's life
_hinted = [False]
_said = {"quiet": False}            # `use(..., quiet=True)`: the engine's lines unsaid (--quiet)


class WorkerDied(RuntimeError):
    """The worker process running an item ended (killed, crashed) before the item did."""


def available() -> bool:
    try:
        import distributed  # noqa: F401
    except ImportError:
        return False
    return True


def use(address: str | None, quiet: bool = False) -> None:
    """Run on the cluster whose scheduler is at `address` (None: Dask's own setting, else a local one);
    `quiet`: the engine says nothing on stderr."""
    global _address
    _said["quiet"] = quiet
    if address and not available():
        from flightctl.errors import InputError
        raise InputError(f"--scheduler {address}: Dask is not installed (pip install '.[fleet]' in the flightctl checkout)")
    if address != _address:
        close()
    _address = address


def scheduler() -> str | None:
    """The address of the cluster to run on: `use`'s, else Dask's config/environment, else None (local)."""
    if _address:
        return _address
    if not available():
        return None
    import dask
    return dask.config.get("scheduler-address", None)


def _client(workers: int):
    """The Dask client, made on first use and kept (a local cluster of `workers` processes)."""
    address = scheduler()
    key = (address, None if address else workers)
    if _engine.get("key") == key:
        return _engine["client"]
    close()
    import dask
    from distributed import Client, LocalCluster
    quiet = logging.CRITICAL            # the worker deaths and shut-down chatter are ours to say
    if address:
        client = Client(address, set_as_default=False)
        cluster = None
    else:
        with dask.config.set({"distributed.scheduler.allowed-failures": 0,
                              "distributed.scheduler.worker-saturation": 1.0,
                              "distributed.nanny.pre-spawn-environ.OPENBLAS_NUM_THREADS": 1,
                              "distributed.nanny.pre-spawn-environ.OMP_NUM_THREADS": 1,
                              "distributed.nanny.pre-spawn-environ.MKL_NUM_THREADS": 1}):
            cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                   dashboard_address=":0", silence_logs=quiet)
        client = Client(cluster, set_as_default=False)
    for name in ("distributed", "distributed.nanny", "distributed.scheduler", "distributed.worker"):
        logging.getLogger(name).setLevel(quiet)
    _engine.update(key=key, client=client, cluster=cluster)
    link = _dashboard(client, cluster)
    where = address or f"a local cluster of {workers} worker{'s' * (workers != 1)}"
    if not _said["quiet"]:
        print(f"engine: Dask, {where}" + (f"; dashboard {link}" if link else ""), file=sys.stderr, flush=True)
    return client


def _dashboard(client, cluster) -> str | None:
    if cluster is not None:
        try:
            import bokeh  # noqa: F401   (Dask serves its dashboard only with bokeh)
        except ImportError:
            return None
    try:
        return client.dashboard_link if "dashboard" in client.scheduler_info().get("services", {}) else None
    except Exception:
        return None


def close(now: bool = False) -> None:
    """End the client and the local cluster: `now` kills the local workers without waiting (Ctrl-C)."""
    client, cluster = _engine.pop("client", None), _engine.pop("cluster", None)
    _engine.clear()
    if client is None:
        return
    if now and cluster is not None:
        for nanny in list(cluster.workers.values()):
            proc = getattr(getattr(nanny, "process", None), "process", None)
            pid = getattr(proc, "pid", None)
            if pid:
                try:
                    os.kill(pid, 9)
                except OSError:
                    pass
    try:
        client.close(timeout=5)
        if cluster is not None:
            cluster.close(timeout=5)
    except Exception:
        pass


atexit.register(close)


def run(fn: Callable, jobs: Iterable, workers: int | None = None, done: Callable | None = None,
        died: Callable | None = None, isolate: bool = False) -> list:
    """`fn(job)` for every job; the results in the jobs' order. `done(k, result)` is called in this
    process as job k finishes (in the order they finish). `died(k, WorkerDied)` -> the result of a
    job whose worker died (without it, the death is raised). `workers`: the local cluster's processes
    (None: the cores); one worker and no cluster address runs in this process unless `isolate`."""
    jobs = list(jobs)
    n = max(1, workers or os.cpu_count() or 1)
    if not jobs:
        return []
    if not available() or (n == 1 and not isolate and scheduler() is None):
        if not available() and not _hinted[0] and not _said["quiet"]:
            _hinted[0] = True
            print(f"engine: {HINT}", file=sys.stderr, flush=True)
        return _serial(fn, jobs, done)
    from distributed import as_completed
    from distributed.scheduler import KilledWorker
    client = _client(n)
    try:
        futures = client.map(fn, jobs, pure=False)
        index = {f.key: k for k, f in enumerate(futures)}
        results: list = [None] * len(jobs)
        for f in as_completed(futures, loop=client.loop):
            k = index[f.key]
            try:
                results[k] = f.result()
            except KilledWorker as e:
                if died is None:
                    raise WorkerDied(f"the worker running item {k} died") from e
                results[k] = died(k, WorkerDied("worker died: its process ended while running this item"))
            if done is not None:
                done(k, results[k])
            f.release()
        return results
    except BaseException:
        close(now=True)
        raise


def _serial(fn, jobs, done) -> list:
    results = []
    for k, job in enumerate(jobs):
        results.append(fn(job))
        if done is not None:
            done(k, results[-1])
    return results


def add_flag(p, what: str) -> None:
    """The `--scheduler ADDRESS` option of a command whose `what` runs on the engine."""
    p.add_argument("--scheduler", metavar="tcp://HOST:8786",
                   help=f"{what}: on the Dask cluster whose scheduler is there (default: Dask's "
                        "DASK_SCHEDULER_ADDRESS, else a local cluster of the cores; docs/fleet.md)")
