"""Another commit's code beside this checkout's, for the scripts that count or time the two side by side
(scripts/batch_profile.py's and scripts/diagnose_speed.py's `--against REV`): the commit's flightctl,
sim and hil trees exported by `git archive` into a folder and laid out as the install lays them out
(pyproject.toml's package-dir), so that a child process with that folder on PYTHONPATH imports them
in place of the installed package."""
from __future__ import annotations

import os
import subprocess

from flightctl.errors import InputError

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def package(rev: str, folder: str) -> str:
    """`folder`, holding commit `rev`'s flightctl with its sim and hil inside; InputError for a commit
    git does not know (or no git checkout here)."""
    try:
        git = subprocess.run(["git", "-C", ROOT, "archive", rev, "flightctl", "sim", "hil"], capture_output=True)
    except OSError as e:
        raise InputError(f"--against {rev}: git: {e.strerror}") from None
    if git.returncode:
        said = git.stderr.decode(errors="replace").strip().splitlines() or ["not a commit"]
        raise InputError(f"--against {rev}: {said[-1]}")
    subprocess.run(["tar", "-x", "-C", folder], input=git.stdout, check=True)
    for sub in ("sim", "hil"):
        os.rename(os.path.join(folder, sub), os.path.join(folder, "flightctl", sub))
    return folder


def day(rev: str) -> str:
    """The commit's date (YYYY-MM-DD)."""
    return subprocess.run(["git", "-C", ROOT, "show", "-s", "--format=%cs", rev], capture_output=True,
                          text=True).stdout.strip()
