"""Every number and figure of the README and docs/ is written by a command (scripts/docs.py knows
each block and figure, and the command that writes it): the blocks are where the registry says, every
marker in the docs is registered, and re-running a command gives what the file holds. The quick
blocks are re-run here; the long ones, and the figures, under `-m slow` (the pairs of diagnose take
about 40 min on two cores). The benchmark's speed figures are the machine's: only their form is checked."""
from __future__ import annotations

import re

import pytest

from helpers.script import load
from helpers.paths import ROOT



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


def _reads(command: tuple[str, ...]) -> list[str]:
    """The arguments of a command that name a file of the checkout; each must be read, not written."""
    return [a for a in command[1:] if "{" not in a and (ROOT / a).is_file()]


@pytest.mark.parametrize("x", DOCS.BLOCKS + DOCS.FIGURES, ids=[x.id for x in DOCS.BLOCKS + DOCS.FIGURES])
def test_no_command_names_a_tracked_file_but_as_its_input(x):
    """A command writes into {tmp}, {doc} or {dir} (a copy when checking), never into the checkout:
    `--check open-question-as-flown-table` once named docs/open-question-as-flown.png as its --out.
    A file of the checkout is the script itself or follows --from."""
    args = list(x.command)
    for a in _reads(x.command):
        i = args.index(a)
        assert i == 1 and a.startswith("scripts/") or args[i - 1] == "--from", f"{x.id}: {args[i - 1]} {a}"


def test_checking_a_block_leaves_the_checkout_as_it_was():
    docs = sorted((ROOT / "docs").iterdir())
    before = {p: p.read_bytes() for p in docs if p.is_file()}
    assert DOCS.main(["--check", "open-question-as-flown-table", "open-question-table"]) == 0
    assert sorted((ROOT / "docs").iterdir()) == docs
    assert all(p.read_bytes() == data for p, data in before.items())


def test_quick_leaves_out_every_paper_flight():
    """A paper flight is 86 s flown: over a minute with numba compiling afresh or without numba on a busy
    machine, so --list does not call it 0.1 min and --quick leaves it out."""
    flying = [x for x in DOCS.BLOCKS + DOCS.FIGURES if "sim" in x.command and "paper" in x.command]
    assert len(flying) >= 2
    assert all(x.minutes > 1 for x in flying), [(x.id, x.minutes) for x in flying]
    assert not set(DOCS.pick([], quick=True)) & set(flying)
    same_script = {x.command[1]: x.minutes for x in DOCS.BLOCKS if x.command[1].startswith("scripts/")}
    for f in DOCS.FIGURES:                      # a figure drawn by a block's script costs what the block costs
        if f.command[1] in same_script:
            assert f.minutes >= same_script[f.command[1]], f.id
