"""Every number and figure of the README and docs/ is written by a command (scripts/docs.py knows
each block and figure, and the command that writes it): the blocks are where the registry says, every
marker in the docs is registered, and re-running a command gives what the file holds. The quick
blocks are re-run here; the long ones, and the figures, under `-m slow` (the pairs of diagnose take
about 40 min on two cores). The benchmark's speed figures are the machine's: only their form is checked."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

from script import load

ROOT = Path(__file__).resolve().parents[1]


DOCS = load("docs", "docs_registry")
QUICK = [b for b in DOCS.BLOCKS if b.minutes < 1 and not b.measured]
LONG = [b for b in DOCS.BLOCKS if b.minutes >= 1 and not b.measured]


def test_every_block_is_in_its_file_once_and_every_marker_is_registered():
    for b in DOCS.BLOCKS:
        DOCS.current(b)                                   # raises unless there once, in order
    known = {m for b in DOCS.BLOCKS for m in (b.begin, b.end)}
    inside = {c for b in DOCS.BLOCKS for c in re.findall(r"<!--.*?-->", DOCS.current(b))}
    for page in [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]:
        for comment in re.findall(r"<!--.*?-->", page.read_text()):
            assert comment in known | inside, f"{page.name}: {comment} is not a block of scripts/docs.py"
    for f in DOCS.FIGURES:
        assert all((ROOT / name).is_file() for name in f.files), f.id


def test_every_block_and_figure_has_its_own_id():
    """`scripts/docs.py --write` and `--check` pick by id: a figure named like a block hid the block
    from both (the motor-loss block of docs/safety.md was never rewritten)."""
    ids = [x.id for x in DOCS.BLOCKS + DOCS.FIGURES]
    assert len(ids) == len(set(ids)), sorted(i for i in ids if ids.count(i) > 1)
    assert {x.id for x in DOCS.pick([], quick=False)} == set(ids)


@pytest.mark.parametrize("b", QUICK, ids=[b.id for b in QUICK])
def test_a_quick_block_is_what_its_command_writes_now(b):
    assert DOCS.fresh(b) == DOCS.current(b), f"python scripts/docs.py --write {b.id}"


@pytest.mark.slow
@pytest.mark.parametrize("b", LONG, ids=[b.id for b in LONG])
def test_a_long_block_is_what_its_command_writes_now(b):
    assert DOCS.fresh(b) == DOCS.current(b), f"python scripts/docs.py --write {b.id}"


@pytest.mark.slow
@pytest.mark.parametrize("f", DOCS.FIGURES, ids=[f.id for f in DOCS.FIGURES])
def test_a_figure_is_what_its_command_draws_now(f, tmp_path):
    for new, old in zip(DOCS.draw(f, tmp_path), f.files):
        assert DOCS.same_picture(new, ROOT / old), f"python scripts/docs.py --write {f.id}"


MEASURED = [b for b in DOCS.BLOCKS if b.measured]


@pytest.mark.parametrize("b", MEASURED, ids=[b.id for b in MEASURED])
def test_a_measured_block_is_its_scripts_output_with_its_date_and_machine(b):
    text = DOCS.current(b)
    assert DOCS.measured_form(b, text) == []
    # the form check can fail: a hand-edited number outside the table, a row with a column missing
    assert DOCS.measured_form(b, "it runs 35x real time\n" + text) != []
    lines = text.splitlines()
    short = "|".join(lines[-1].split("|")[:-2]) + "|"
    assert DOCS.measured_form(b, "\n".join(lines[:-1] + [short])) != []


def test_a_picture_that_differs_is_told_from_one_that_does_not(tmp_path):
    import numpy as np
    from PIL import Image
    rng = np.random.default_rng(7)
    base = rng.integers(0, 256, (60, 80, 3), dtype=np.uint8)
    moved = base.copy()
    moved[: 1 + int(rng.integers(10, 20)), :] ^= 0xFF        # a band of rows redrawn
    for name, image in (("a.png", base), ("b.png", base), ("c.png", moved)):
        Image.fromarray(image).save(tmp_path / name)
    assert DOCS.same_picture(tmp_path / "a.png", tmp_path / "b.png")
    assert not DOCS.same_picture(tmp_path / "a.png", tmp_path / "c.png")
