"""One BLAS thread: the one definition every user of it shares (the two-rotor gain schedule,
control/spin_design.py; `flightctl diagnose`; the parallel engine's workers, sim/engine.py; the
timing scripts).

The numerical work here is small matrices (5x5 LQR problems, a diagnosis' fits), on which OpenBLAS's
thread pool costs more than the work (docs/diagnose.md, "One BLAS thread"; the schedule's cost with
one thread: README's speed table, scripts/benchmark.py). Two ways, for the two moments:
- `ONE_THREAD` / `one_thread_environment()`: the environment that makes BLAS start one thread, for a
  process before numpy is imported (a command's entry point) or for child processes;
- `OneBlasThread`: within it, the OpenBLAS libraries already loaded run one thread (Linux; elsewhere,
  or without OpenBLAS, nothing changes).
Imports nothing numerical at module level: it is imported before numpy.
"""
from __future__ import annotations

import os

ONE_THREAD = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
_BLAS_NAMES = ("openblas", "scipy_openblas")   # + _set_num_threads, or + _set_num_threads64_ (64-bit ints)


def one_thread_environment() -> None:
    """Set `ONE_THREAD` in this process' environment (before numpy is imported, so that OpenBLAS
    starts no thread pool; its children inherit it)."""
    os.environ.update(ONE_THREAD)


class OneBlasThread:
    """Within it, OpenBLAS (numpy's and scipy's, found among the process' loaded libraries) runs one
    thread; the thread counts it found are restored on leaving."""

    def __enter__(self):
        import ctypes
        import numpy  # noqa: F401  (their libraries loaded, to be found)
        import scipy.linalg  # noqa: F401
        self.restore = []
        try:
            with open("/proc/self/maps") as f:
                paths = {line.split()[-1] for line in f if "openblas" in line.lower() and "/" in line}
        except OSError:
            return self
        for path in paths:
            try:
                lib = ctypes.CDLL(path)
            except OSError:
                continue
            for base in _BLAS_NAMES:
                get = getattr(lib, base + "_get_num_threads", None) or getattr(lib, base + "_get_num_threads64_", None)
                put = getattr(lib, base + "_set_num_threads", None) or getattr(lib, base + "_set_num_threads64_", None)
                if get is not None and put is not None:
                    self.restore.append((put, get()))
                    put(1)
                    break
        return self

    def __exit__(self, *exc):
        for put, n in self.restore:
            put(n)
        return False
