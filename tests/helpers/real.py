"""The shared real data (../shared/data/real/flights, never copied here) for the tests: where it is,
and the rule that CI never skips a real-data test (the environment variable CI set: a missing folder
fails); and the rewriting of a real log's CSV that hides an effect in it (the hidden-effect tests)."""
from __future__ import annotations

import os
from pathlib import Path

import pytest

FLIGHTS = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "real" / "flights"
INDIFLIGHT = FLIGHTS / "indiflight"


def need(path: Path) -> Path:
    """The path, or a skip outside CI (a failure in CI) when the shared data are not there."""
    if not path.exists():
        if os.environ.get("CI"):
            pytest.fail(f"{path}: the shared real data are missing in CI")
        pytest.skip(f"{path}: the shared real data are not on this machine")
    return path


def rows_and_header(csv_text: str) -> tuple[list[str], list[str], list[list[str]]]:
    """(metadata lines, header names, rows as cells) of a flight-log CSV."""
    lines = csv_text.splitlines()
    head = next(i for i, line in enumerate(lines) if not line.startswith("#"))
    return lines[:head], lines[head].split(","), [line.split(",") for line in lines[head + 1:]]


def write(meta: list[str], names: list[str], rows: list[list[str]], path: Path) -> Path:
    path.write_text("\n".join(meta + [",".join(names)] + [",".join(r) for r in rows]) + "\n")
    return path


def delay_fit(report: dict) -> float:
    """The actuation delay the first round fitted (named or not)."""
    return next(c for c in report["candidates"] if c["cause"] == "actuation_delay")["parameters"]["delay"]


def delayed(names: list[str], rows: list[list[str]], shift: int) -> None:
    """Each row logs the command of the row `shift` later: the motors act after the log says."""
    for j in (names.index(f"P{i}") for i in range(1, 5)):
        cells = [r[j] for r in rows]
        for r, v in zip(rows, cells[shift:] + cells[-1:] * shift):
            r[j] = v
