"""The identification's imports run one way: the figures import the fits, the fits never import the
figures (the command line calls both), and every figure is drawn in the one style of
`flightctl.sim.plots` (matplotlib's `Figure`, never pyplot and its global state)."""
from __future__ import annotations

import ast
from pathlib import Path
from helpers.paths import ROOT

IDENTIFY = ROOT / "sim" / "identify"
FIGURES = {"flightctl.sim.identify.plots", "flightctl.sim.identify.realplots", "flightctl.sim.plots"}
FITS = ("fits.py", "propeller.py", "yaw_drag.py", "inertia.py", "realdata.py")


def imports(path: Path) -> set[str]:
    """Every module a file imports, at any depth (lazy imports in functions too); `from a import b`
    gives a and a.b."""
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module:
            out |= {node.module} | {f"{node.module}.{alias.name}" for alias in node.names}
    return out


def test_the_fits_never_import_their_figures():
    for name in FITS:
        drawn = imports(IDENTIFY / name) & FIGURES
        assert not drawn, f"{name} imports {drawn}"
        assert not any(m.startswith("matplotlib") for m in imports(IDENTIFY / name)), name


def test_the_figures_import_the_fits_they_draw():
    assert "flightctl.sim.identify.propeller" in imports(IDENTIFY / "plots.py")
    assert "flightctl.sim.identify.realdata" in imports(IDENTIFY / "realplots.py")


def test_no_figure_is_drawn_through_pyplot():
    sources = [p for folder in ("flightctl", "sim", "hil", "scripts") for p in (ROOT / folder).rglob("*.py")]
    assert len(sources) > 20
    users = [str(p.relative_to(ROOT)) for p in sources
             if any(m.startswith("matplotlib.pyplot") or m == "matplotlib" for m in imports(p))]
    assert users == []
