"""The README's comparison table is what scripts/paper_comparison.py prints: every row is recomputed
under `-m slow`; the default run recomputes a few rows drawn at random (seeded) and checks the rest of
the table's shape."""
from __future__ import annotations


import numpy as np
import pytest

from helpers.script import load
from helpers.paths import ROOT



def _script():
    return load("paper_comparison")


def _readme_rows(header: str) -> list[str]:
    lines = (ROOT / "README.md").read_text().splitlines()
    first = header.splitlines()[0]
    i = lines.index(first)
    assert lines[i + 1] == header.splitlines()[1]
    rows = []
    for line in lines[i + 2:]:
        if not line.startswith("|"):
            break
        rows.append(line)
    return rows


def test_the_readme_table_has_one_row_per_case_in_order():
    pc = _script()
    rows = _readme_rows(pc.HEADER)
    assert len(rows) == len(pc.CASES)
    for line, (model, gains, path, _) in zip(rows, pc.CASES):
        assert line.startswith(f"| {model} | {gains} | {path} | ")


def _check(pc, indices, tmp_path):
    rows = _readme_rows(pc.HEADER)
    for i in indices:
        assert pc.row(*pc.CASES[i], tmp_path) == rows[i], pc.CASES[i]


def test_sampled_readme_rows_are_what_the_script_prints(tmp_path):
    pc = _script()
    rng = np.random.default_rng(2026)
    _check(pc, rng.choice(len(pc.CASES), size=3, replace=False), tmp_path)


@pytest.mark.slow
def test_every_readme_row_is_what_the_script_prints(tmp_path):
    pc = _script()
    _check(pc, range(len(pc.CASES)), tmp_path)
