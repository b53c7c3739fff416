"""A schema entry: a dataclass field with its unit, range and what it is, and the check of a value
against it. The one definition the parameter files (params.py) and the board files
(boards/boardfile.py) share; each adds its own metadata (a parameter's source, a log-uniform range).
"""
from __future__ import annotations

import dataclasses

from flightctl.errors import InputError, number


def entry(default, unit: str, lo, hi, doc: str = "", **more) -> dataclasses.Field:
    """One schema entry, stored as dataclass field metadata (unit, lo, hi, doc and `more`); a default
    of dataclasses.MISSING: none, the file must give it."""
    return dataclasses.field(default=default, metadata=dict(unit=unit, lo=lo, hi=hi, doc=doc, **more))


def check_range(where: str, value, meta, shown: str | None = None) -> None:
    """Refuse `value` outside the entry's [lo, hi] (or not a finite number), in one line naming `where`,
    the value (`shown` for one that is not a finite number, else its first characters) and its unit."""
    if number(value) is None or not meta["lo"] <= value <= meta["hi"]:
        if number(value) is not None:
            shown = f"{value:g}"
        elif shown is None:
            shown = f"{str(value)[:37]}..."
        unit = f" {meta['unit']}" if meta["unit"] else ""
        raise InputError(f"{where}: {shown}{unit} is out of range [{meta['lo']:g}, {meta['hi']:g}]")
