"""The layers import one way (docs/architecture.md): the onboard package `flightctl/` imports nothing
from the simulator, the analysis tools or the bench/HIL code, not even lazily inside a function;
the distribution installs everything under the `flightctl` name, and the Pi-only libraries only
with the `pi` extra."""
from __future__ import annotations

import ast
import email
import shutil
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import pytest

from helpers.without import PI_LIBRARIES, run_without
from helpers.paths import ROOT

ONBOARD = ROOT / "flightctl"
UPWARD = ("flightctl.sim", "flightctl.hil", "sim", "hil")
# the folders that install as packages, and the import name of each folder
PACKAGE_ROOTS = {"flightctl": "flightctl", "sim": "flightctl.sim", "hil": "flightctl.hil"}


def imported_modules(path: Path, text: str | None = None) -> list[tuple[int, str]]:
    """(line, absolute module name) of every import in a file, at any depth (functions, try blocks);
    `from a import b` yields both a and a.b (b may be a module)."""
    package = ".".join(path.relative_to(ROOT).parent.parts)
    found = []
    text = path.read_text() if text is None else text
    for node in ast.walk(ast.parse(text, str(path))):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:                               # relative: from its package, level - 1 up
                parts = package.split(".")
                base = ".".join(parts[:len(parts) - node.level + 1])
                module = f"{base}.{node.module}" if node.module else base
            else:
                module = node.module
            found.append((node.lineno, module))
            found += [(node.lineno, f"{module}.{alias.name}") for alias in node.names]
    return found


def upward(module: str) -> bool:
    return any(module == u or module.startswith(u + ".") for u in UPWARD)


def test_the_onboard_package_imports_nothing_above_it():
    files = sorted(ONBOARD.rglob("*.py"))
    assert len(files) > 20
    bad = [f"{path.relative_to(ROOT)}:{line}: {module}" for path in files
           for line, module in imported_modules(path) if upward(module)]
    assert bad == []


def test_the_import_check_sees_lazy_relative_and_aliased_imports():
    text = ("def f():\n    from flightctl.sim.flights.run import fly\n"
            "def g():\n    try:\n        import hil.bench as b\n    except ImportError:\n        pass\n"
            "from .. import sim\n"
            "from flightctl import boards, simulate\n")
    found = imported_modules(ROOT / "flightctl" / "control" / "probe.py", text)     # a file that is not there
    assert sorted((line, m) for line, m in found if upward(m)) == [
        (2, "flightctl.sim.flights.run"), (2, "flightctl.sim.flights.run.fly"), (5, "hil.bench"), (8, "flightctl.sim")]
    assert (9, "flightctl.boards") in found and not upward("flightctl.simulate")


# The simulator's own floors (docs/architecture.md, "The simulator's floors"), bottom first: a module imports
# from its own floor and the floors below, never above, at any depth (lazy imports too).
SIM_FLOORS = (("progress", "plots", "checkout", "docs", "engine"),   # the tools every floor uses
              ("world",),                                             # the plant, the simulated devices, the board
              ("causes",),                                            # the effects of the model, one module each
              ("world.board",),                                       # the simulated board: the world with its effects
              ("logs", "identify"),                                   # other autopilots' logs read; the bench fits
              ("diagnose",),                                          # a log's model identified and judged
              ("flights",),                                           # one flight and its metrics
              ("analysis",),                                          # the linearised loops
              ("sweeps",),                                            # many flights at once: the batch, tune, Monte Carlo
              ("cli", "paramscli"))                                   # the commands
# The seams crossed upward by design, each named with its reason:
SEAMS = {
    # sim/world/compiled.py compiles the causes' own wrench functions into the plant's step (one source each)
    ("world.compiled", "causes"),
    # a cause module holds its diagnose Candidate beside its Effect: the candidate contract and what it fits on
    ("causes", "diagnose.candidate"), ("causes", "diagnose.data"), ("causes", "diagnose.dataset"),
    ("causes", "diagnose.scoring"), ("causes", "diagnose.rotorspeed"),
}


def sim_floor(name: str) -> int | None:
    """The floor of a module (dotted, below flightctl.sim): its longest entry in SIM_FLOORS."""
    best = None
    for i, floor in enumerate(SIM_FLOORS):
        for entry in floor:
            if (name == entry or name.startswith(entry + ".")) and (best is None or len(entry) > len(best[1])):
                best = (i, entry)
    return None if best is None else best[0]


def sim_up_imports() -> list[str]:
    bad = []
    for path in sorted((ROOT / "sim").rglob("*.py")):
        rel = path.relative_to(ROOT / "sim").with_suffix("")
        here = ".".join(p for p in rel.parts if p != "__init__")
        for line, module in imported_modules(path):
            if not module.startswith("flightctl.sim."):
                continue
            there = module.removeprefix("flightctl.sim.")
            a, b = sim_floor(here), sim_floor(there)
            assert a is not None and b is not None, (here, there)
            if b > a and not any(here.startswith(s) and there.startswith(t) for s, t in SEAMS):
                bad.append(f"sim/{rel}.py:{line}: {here} (floor {a}) imports {there} (floor {b})")
    return bad


def test_the_simulators_floors_import_downward_only():
    assert {p.name.removesuffix(".py") for p in (ROOT / "sim").iterdir()
            if p.name != "__init__.py" and (p.suffix == ".py" or (p / "__init__.py").exists())} == \
        {n for floor in SIM_FLOORS for n in floor if "." not in n}, "a folder or module of sim/ on no floor"
    assert sim_up_imports() == []


def package_folders() -> set[str]:
    names = set()
    for folder, name in PACKAGE_ROOTS.items():
        for init in (ROOT / folder).rglob("__init__.py"):
            rel = init.parent.relative_to(ROOT / folder).parts
            names.add(".".join((name,) + rel))
    return names


def test_pyprojects_package_list_is_the_package_folders():
    setup = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    listed, folders = set(setup["packages"]), package_folders()
    assert (sorted(folders - listed), sorted(listed - folders)) == ([], []), "(not listed, listed but absent)"
    assert setup["package-dir"] == {name: folder for folder, name in PACKAGE_ROOTS.items() if folder != name}
    # a folder of modules without __init__.py would not be installed at all
    for folder in PACKAGE_ROOTS:
        for py in (ROOT / folder).rglob("*.py"):
            if "__pycache__" not in py.parts:
                assert (py.parent / "__init__.py").exists(), py.relative_to(ROOT)


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    """The distribution as `pip install .` would install it, built once from a copy of the tree."""
    src = tmp_path_factory.mktemp("src")
    for name in ("pyproject.toml", "README.md"):
        shutil.copy(ROOT / name, src / name)
    for folder in PACKAGE_ROOTS:
        shutil.copytree(ROOT / folder, src / folder, ignore=shutil.ignore_patterns("__pycache__"))
    out = tmp_path_factory.mktemp("wheel")
    r = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "--no-index", "-q",
                        "-w", str(out), str(src)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    (path,) = out.glob("flightctl-*.whl")
    return path


def test_the_wheel_installs_only_the_flightctl_name(wheel):
    names = zipfile.ZipFile(wheel).namelist()
    top = {n.split("/")[0] for n in names}
    assert {t for t in top if not t.endswith(".dist-info")} == {"flightctl"}     # no top-level sim/ or hil/
    for module in ("flightctl/sim/flights/run.py", "flightctl/sim/world/board.py", "flightctl/hil/bench.py",
                   "flightctl/boards/pi.toml", "flightctl/plans/__init__.py", "flightctl/sim/world/loop_lateness/busy.json"):
        assert module in names
    (info,) = [n for n in names if n.endswith(".dist-info/top_level.txt")] or [None]
    if info:
        assert zipfile.ZipFile(wheel).read(info).decode().split() == ["flightctl"]


def test_the_pi_libraries_come_only_with_an_extra(wheel):
    archive = zipfile.ZipFile(wheel)
    (meta,) = [n for n in archive.namelist() if n.endswith(".dist-info/METADATA")]
    requires = email.message_from_bytes(archive.read(meta)).get_all("Requires-Dist")
    plain = [r for r in requires if "extra ==" not in r]
    assert plain and not [r for r in plain if r.split(">")[0].split("=")[0].split(";")[0].strip() in PI_LIBRARIES]
    pi_extra = [r for r in requires if 'extra == "pi"' in r]
    for library in PI_LIBRARIES:
        assert any(r.startswith(library) for r in pi_extra), library
    assert any(r.startswith("spidev") for r in requires if "extra ==" in r) and \
        not any(r.startswith("spidev") and 'extra == "pi"' not in r and 'extra == "pi5"' not in r
                for r in requires)                                                  # Linux-only: the Pi extras alone
    pi5_extra = [r for r in requires if 'extra == "pi5"' in r]
    for library in ("gpiod", "spidev", "smbus2"):
        assert any(r.startswith(library) for r in pi5_extra), library
    assert not any(r.startswith("pigpio") for r in pi5_extra)                      # pigpio does not run on a Pi 5


def test_the_simulator_runs_without_the_pi_libraries(tmp_path):
    r = run_without(PI_LIBRARIES, ["sim", "step_roll", "--log", "f.csv", "--no-plot", "--quiet"], tmp_path)
    assert r.returncode == 0, r.stderr[-2000:]
