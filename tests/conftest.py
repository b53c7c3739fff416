"""The test run's one piece of set-up: numba compiles the simulated world once per run, before any test
starts (issue 39), not inside a timed fixture of whichever test flies first.

numba's on-disk cache (sim/world/compiled.py) is filled here, in the process that runs the tests or,
under pytest-xdist, in the controller once every worker has collected and before any test is handed
out: the workers then load the compiled code (about 2 s) instead of each compiling it at once on a
busy machine (tens of seconds to minutes, inside pytest-timeout's 240 s of test_dataflash's simulated
flights and test_analyze's step predictions). The plant and the IMU chip's registers are compiled for
every run; the batched simulator's loop (half a minute) only when a collected test file uses the
sweeps. With the cache already filled this costs about 2 s; with numba absent or FLIGHTCTL_JIT=0, nothing.

The tests of a file whose fixtures live for the whole file (a simulated fleet diagnosed, a real log read)
run on one worker (pytest-xdist's `--dist loadgroup`, pyproject.toml): with xdist's default `load` the
file's tests are spread over the workers and each worker builds the same fixture again.
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

import pytest

SWEEPS = ("sweeps", "--batch", "monte_carlo", "montecarlo")    # words of a test file that flies the batch


def warm(files, say=lambda text: print(text, file=sys.stderr)) -> None:
    """Compile (or load from numba's cache) what the tests in `files` will fly, in this process."""
    from flightctl.sim.world import compiled
    if not compiled.enabled():
        return
    start = time.perf_counter()
    from flightctl.sim.world import imu
    compiled.functions()                 # the plant: called once with the flight's argument types
    imu.chip_frame_compiled()
    batch = any(word in Path(f).read_text(errors="replace") for f in set(files) if Path(f).is_file() for word in SWEEPS)
    if batch:
        from flightctl.params import load
        from flightctl.sim.flights.scenarios import SCENARIOS
        from flightctl.sim.sweeps.batch import simulate
        from flightctl.sim.sweeps.montecarlo import draw
        params = load("paper-as-flown")
        simulate(params, SCENARIOS["paper"]().plan, 2, draw(params, 2, 0), until=0.01, workers=1)
    say(f"conftest: the simulated world{' and the batched simulator' if batch else ''} compiled or loaded from "
        f"numba's cache in {time.perf_counter() - start:.1f} s, before the tests")


def pytest_collection_modifyitems(config, items):
    """One xdist group per file whose tests share a fixture of module or session scope (see above)."""
    for item in items:
        defs = getattr(getattr(item, "_fixtureinfo", None), "name2fixturedefs", {})
        if any(d.scope in ("module", "session", "package") for ds in defs.values() for d in ds
               if not d.argname.startswith(("tmp_path_factory", "worker_id", "testrun_uid"))
               and "_pytest" not in (getattr(d.func, "__module__", "") or "")):
            item.add_marker(pytest.mark.xdist_group(item.path.stem))


def _files(ids) -> list[str]:
    return [i.split("::", 1)[0] for i in ids]


_warmed = False


def _warm_once(config, files) -> None:
    global _warmed
    if _warmed or config.option.collectonly:
        return
    _warmed = True
    reporter = config.pluginmanager.get_plugin("terminalreporter")
    warm(files, *([reporter.write_line] if reporter is not None else []))


def pytest_collection_finish(session):
    """Without xdist (`-n 0`), or in an xdist worker (which leaves it to the controller)."""
    if not hasattr(session.config, "workerinput") and session.items and not getattr(session.config.option, "numprocesses", None):
        _warm_once(session.config, [str(item.path) for item in session.items])


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_node_collection_finished(node, ids):
    """The controller, as the first worker reports its collection: the tests wait for this."""
    _warm_once(node.config, [str(Path(node.config.rootpath) / f) for f in _files(ids)])
