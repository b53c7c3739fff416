"""Worker processes for the sweeps (Monte Carlo, the batched simulator, diagnose's pairs).

Ctrl-C reaches every process of the terminal's process group. The workers ignore it and leave it to
the parent, whose KeyboardInterrupt ends them at once (terminated, their queued jobs cancelled):
one line from the command (flightctl/cli.py), no traceback from each worker, no wait for the jobs
already running. A parent that ends without that chance (killed outright, as pytest-xdist ends a
worker that does not stop) takes its workers with it on Linux (the kernel's parent-death signal,
prctl(2) PR_SET_PDEATHSIG): no orphan runs on. `run_all` hands each result back as it finishes, for
an honest progress line.
"""
from __future__ import annotations

import os
import signal
import sys
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from contextlib import contextmanager
from typing import Callable, Iterable, Iterator


PR_SET_PDEATHSIG = 1          # linux/prctl.h


def _die_with(parent: int) -> None:
    """Linux: SIGTERM to this process when the thread that started it ends (the pool's owner, which
    starts every worker at its first job); at once if the parent is gone already."""
    if not sys.platform.startswith("linux"):
        return
    import ctypes
    try:
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, int(signal.SIGTERM))
    except (OSError, AttributeError):
        return
    if os.getppid() != parent:    # it ended before the call above
        os._exit(1)


def _worker_init(parent, initializer, initargs) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _die_with(parent)
    if initializer is not None:
        initializer(*initargs)


def terminate(pool: ProcessPoolExecutor) -> None:
    """End the pool's processes now, whatever they are doing."""
    processes = list((getattr(pool, "_processes", None) or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for p in processes:
        if p.is_alive():
            p.terminate()
    for p in processes:
        p.join(2.0)


@contextmanager
def workers(n: int, initializer=None, initargs=()) -> Iterator[ProcessPoolExecutor]:
    """A process pool of `n` workers that is terminated, not waited for, when the block is left by
    an exception (Ctrl-C included)."""
    pool = ProcessPoolExecutor(max_workers=max(1, n), initializer=_worker_init,
                               initargs=(os.getpid(), initializer, initargs))
    try:
        yield pool
    except BaseException:
        terminate(pool)
        raise
    pool.shutdown(wait=True)


def run_all(fn: Callable, jobs: Iterable, n: int, done: Callable | None = None, poll_s: float | None = None,
            polled: Callable | None = None) -> list:
    """`fn(job)` for every job in `n` worker processes; the results in the jobs' order. `done(k,
    result)` is called in this process as job k finishes (in the order they finish); `polled()` every
    `poll_s` while waiting."""
    jobs = list(jobs)
    results: list = [None] * len(jobs)
    with workers(n) as pool:
        pending = {pool.submit(fn, job): k for k, job in enumerate(jobs)}
        while pending:
            finished, _ = wait(pending, timeout=poll_s, return_when=FIRST_COMPLETED)
            for f in finished:
                k = pending.pop(f)
                results[k] = f.result()
                if done is not None:
                    done(k, results[k])
            if polled is not None:
                polled()
    return results
