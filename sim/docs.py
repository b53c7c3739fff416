"""The generated blocks of the README and docs/: text between a begin and an end marker (HTML comments,
invisible on GitHub) that a command writes, never a hand. One definition of finding and replacing a
block, for every writer (`flightctl sim faults --doc`, `flightctl identify real-data`, the scripts/);
scripts/docs.py knows every block and the command that writes it, rewrites them all, and
tests/project/test_docs.py re-runs them.
"""
from __future__ import annotations

from pathlib import Path

from flightctl.files import read_text, write_atomic


def marked(name: str) -> tuple[str, str]:
    """The begin and end markers of the block `name`: `<!-- NAME: begin -->`, `<!-- NAME: end -->`."""
    return f"<!-- {name}: begin -->", f"<!-- {name}: end -->"


def table(header, rows) -> list[str]:
    """A Markdown table's lines: the header's cells, its rule, then each row's cells (strings)."""
    return ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)] + ["| " + " | ".join(r) + " |" for r in rows]


def block(text: str, begin: str, end: str) -> str | None:
    """The text between the line `begin` and the line `end` (without them), None when they are not
    both there, once each and in that order."""
    if text.count(begin) != 1 or text.count(end) != 1 or text.index(begin) > text.index(end):
        return None
    inner = text.split(begin, 1)[1].split(end, 1)[0]
    return inner.removeprefix("\n").removesuffix("\n")


def replace(text: str, begin: str, end: str, body: str) -> str | None:
    """`text` with the block between `begin` and `end` replaced by `body` (None: no such block)."""
    if block(text, begin, end) is None:
        return None
    head, rest = text.split(begin, 1)
    tail = rest.split(end, 1)[1]
    return f"{head}{begin}\n{body.rstrip(chr(10))}\n{end}{tail}"


def write_block(path: str | Path, begin: str, end: str, body: str) -> bool:
    """Replace the block in the file `path` (written whole, never half); False when it has none."""
    new = replace(read_text(path), begin, end, body)
    if new is None:
        return False
    write_atomic(path, new)
    return True


def write_or_exit(path: str | Path, begin: str, end: str, body: str) -> None:
    """`write_block` for a script: SystemExit naming the markers when the file has none."""
    if not write_block(path, begin, end, body):
        raise SystemExit(f"{path}: no {begin} ... {end} markers")


def publish(text: str, doc: str | Path | None, begin: str, end: str) -> None:
    """A script's block: print `text`, and with `doc` write it between the markers of that file
    (`write_or_exit`)."""
    print(text)
    if doc:
        write_or_exit(doc, begin, end, text)
