"""A script of scripts/ imported as a module, for the tests that check what it writes."""
from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def load(stem: str, name: str | None = None):
    """scripts/STEM.py as the module `name` (default: STEM), registered in sys.modules (its dataclasses
    look their module up there)."""
    spec = importlib.util.spec_from_file_location(name or stem, ROOT / "scripts" / f"{stem}.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod
    spec.loader.exec_module(mod)
    return mod
