"""The tree passes `ruff check` with pyproject's rules ([tool.ruff]: syntax errors, undefined names,
statements out of place, lines over 140 characters): a new one fails here, in CI (the `test` extra installs ruff), with the
file, line and rule of each."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from helpers.paths import ROOT


def ruff() -> list[str]:
    found = shutil.which("ruff", path=os.pathsep.join([str(Path(sys.executable).parent), os.environ.get("PATH", "")]))
    if found is None:
        if os.environ.get("CI"):
            pytest.fail("ruff is not installed: the `test` extra installs it")
        pytest.skip("ruff is not installed (pip install ruff, or the `test` extra)")
    return [found]


def test_the_tree_passes_ruff_check():
    r = subprocess.run(ruff() + ["check", "--no-cache", "--output-format", "concise", "."], cwd=ROOT,
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stdout + r.stderr


def test_the_check_sees_an_undefined_name(tmp_path):
    """The rules are the project's (its pyproject), and they catch what they are for."""
    bad = tmp_path / "bad.py"
    bad.write_text("def f():\n    return undefined_name\n")
    r = subprocess.run(ruff() + ["check", "--no-cache", "--config", str(ROOT / "pyproject.toml"), str(bad)],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 1 and "F821" in r.stdout, r.stdout + r.stderr
