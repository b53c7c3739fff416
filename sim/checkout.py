"""Where the checkout is: the working tree a command runs in, never the installed package's folder
(an installed `flightctl` lives in site-packages, far from the repository and from `../shared`)."""
from __future__ import annotations

from pathlib import Path


def checkout(start: Path | None = None) -> Path | None:
    """The folder holding pyproject.toml and flightctl/, found by walking up from `start` (default:
    the current directory), or None outside a checkout."""
    here = (start or Path.cwd()).resolve()
    for d in (here, *here.parents):
        if (d / "pyproject.toml").is_file() and (d / "flightctl").is_dir():
            return d
    return None


def shared_real_data() -> Path | None:
    """../shared/data/real beside the checkout (the measured data of others), or None."""
    root = checkout()
    return None if root is None else (root.parent / "shared" / "data" / "real").resolve()
