"""The engine behind the sweeps (the Monte Carlo, the batched simulator, `tune --robust`, diagnose's
corpus and pairs): Dask's distributed scheduler when the `fleet` extra is installed, else the same
work in this process, one item at a time (said once, with how to get the parallel engine).

With Dask: a local cluster by default (`distributed.LocalCluster`: worker processes under a nanny,
one thread and one BLAS thread each, as many as asked or the machine's cores), kept for the
command's life so that each worker compiles the plant once; or an existing cluster, by `use(address)`
(`--scheduler tcp://HOST:8786`) or Dask's own setting (`DASK_SCHEDULER_ADDRESS`, the config key
`scheduler-address`: https://docs.dask.org/en/stable/configuration.html). Its dashboard's address is
printed when there is one.

Ctrl-C: the command's one line and exit 130 (flightctl/cli.py), whenever it comes. The local workers
ignore it (`_workers_deaf_to_ctrl_c`) and are ended at once by this process (killed, not waited
for); a Ctrl-C while they start is raised once they are up; a remote cluster's tasks are cancelled.
A killed command leaves no workers either: Dask's worker process exits as soon as its nanny's pipe
closes (distributed/process.py, `AsyncProcess._immediate_exit_when_closed`), and the fork server
when this process's does (tests/sim/diagnose/test_corpus.py kills a command with SIGKILL and checks).

A worker that dies (a log that crashes it) fails its item with `WorkerDied`, not the run's other
items: `run(..., died=...)` records it; without `died` it is raised. The local cluster marks an
item bad on its first death (`allowed-failures` 0, one item per worker thread at a time), so that
the item that killed the worker is the one blamed and is not flown again.
"""
from __future__ import annotations

import atexit
import logging
import os
import signal
import sys
import threading
from contextlib import contextmanager
from typing import Callable, Iterable

from flightctl.blas import ONE_THREAD   # BLAS, per worker

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
    quiet = logging.CRITICAL            # the worker deaths and shut-down chatter are ours to say
    import dask
    from distributed import Client, LocalCluster
    if address:
        from distributed.comm.addressing import parse_address, parse_host_port
        from distributed.comm.registry import get_backend
        try:
            scheme, where = parse_address(address)
            get_backend(scheme)                             # a known scheme and (tcp, tls) a port,
            if scheme in ("tcp", "tls"):                    # before a client is made of it
                parse_host_port(where)
            client = Client(address, set_as_default=False)
        except (OSError, ValueError, TypeError) as e:       # refused, timed out, not an address
            from flightctl.errors import InputError
            raise InputError(f"--scheduler {address}: no Dask scheduler answers there ({type(e).__name__}: "
                             f"{str(e).splitlines()[0] if str(e) else ''})") from None
        cluster = None
    else:
        _workers_deaf_to_ctrl_c()
        with _ctrl_c_deferred(), dask.config.set({"distributed.worker.multiprocessing-method": "forkserver",
                              "distributed.scheduler.allowed-failures": 0,
                              "distributed.scheduler.worker-saturation": 1.0,
                              # the worker's statistical profiler samples each task's stack every 10 ms
                              # (distributed.yaml `worker.profile`), CPU taken from the task itself
                              "distributed.worker.profile.enabled": False,
                              **{f"distributed.nanny.pre-spawn-environ.{k}": 1 for k in ONE_THREAD},
                              # Dask's default MALLOC_TRIM_THRESHOLD_ = 65536 (distributed.yaml) fixes glibc's
                              # trim and mmap thresholds, so every array over 128 KiB is mapped and unmapped
                              # anew: diagnose took twice the CPU (better_tune.BBL 65 s against 33 s), in the
                              # workers and in every later child of this process, which the nanny's
                              # os.environ.update leaks it into (nanny.py). None unsets it (_get_env_variables).
                              "distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None}):
            cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                   dashboard_address=":0", silence_logs=quiet)
            client = Client(cluster, set_as_default=False)
            _engine.update(key=key, client=client, cluster=cluster)
    _engine.update(key=key, client=client, cluster=cluster)
    for name in ("distributed", "distributed.nanny", "distributed.scheduler", "distributed.worker"):
        logging.getLogger(name).setLevel(quiet)
    link = _dashboard(client, cluster)
    where = address or f"a local cluster of {workers} worker{'s' * (workers != 1)}"
    if not _said["quiet"]:
        print(f"engine: Dask, {where}" + (f"; dashboard {link}" if link else ""), file=sys.stderr, flush=True)
    return client


def _workers_deaf_to_ctrl_c() -> None:
    """Ctrl-C reaches the terminal's whole process group; the workers leave it to this process, which
    ends them (`close(now=True)`), as the pool before them did. The local workers are forked from
    multiprocessing's fork server (Dask's `multiprocessing-method` forkserver), started here with SIGINT
    ignored: an ignored signal stays ignored across fork and exec, Python then installs no handler of
    its own, and the server hands its children the handlers it started with (signal(7); CPython's
    multiprocessing/forkserver.py). This process ignores Ctrl-C only while the server starts. The
    server ends when this process does (its pipe from here closes).
    A Ctrl-C pressed in that moment is not lost: SIGINT is also blocked here meanwhile (this process
    has one thread then), and the kernel keeps a blocked signal pending even while it is ignored
    (kernel/signal.c, sig_ignored: "Blocked signals are never ignored"); it is delivered to the
    restored handler when unblocked. The server inherits the block, harmless in a process deaf to it.
    The resource tracker is started first, outside that moment: the fork server's start starts it
    too, and its start unblocks SIGINT after spawning it (CPython's multiprocessing/resource_tracker.py,
    `ensure_running`, bpo-33613), which would deliver and drop, while ignored, a Ctrl-C pressed before
    and lose any pressed after, until the mask is restored (1 in 4 runs of the test beside two CPU hogs).
    The tracker ignores Ctrl-C itself (its `main`); one pressed while it starts reaches this process's
    handler as any Ctrl-C does."""
    if threading.current_thread() is not threading.main_thread():
        return
    from multiprocessing import forkserver, resource_tracker
    resource_tracker.ensure_running()
    saved = {k: os.environ.get(k) for k in ONE_THREAD}
    os.environ.update(ONE_THREAD)             # the server's environment is its children's
    mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    handler = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        forkserver.ensure_running()
    finally:
        signal.signal(signal.SIGINT, handler)
        signal.pthread_sigmask(signal.SIG_SETMASK, mask)      # a Ctrl-C meanwhile: raised now
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


@contextmanager
def _ctrl_c_deferred():
    """A Ctrl-C while the local cluster starts is raised once it is up (and then ended at once by
    `run`), not inside Dask's start-up, whose half-made workers would each say so with a traceback."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    pressed = []
    previous = signal.signal(signal.SIGINT, lambda signum, frame: pressed.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
    if pressed:
        raise KeyboardInterrupt


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
    try:
        client = _client(n)
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
