"""A cache folder that only its user can write: the one definition both disk caches use (numba's
compiled simulator, sim/world/compiled.py; the two-rotor landing's gain schedule,
control/spin_design.py).

A cache is loaded as the process' own work: compiled machine code, or gains the vehicle flies on.
A folder another user owns or can write lets that user plant what this process then loads (a
predictable name in the shared temporary folder is the easy case), so a folder is trusted only when
it is this user's: made with mode 0700 where it is absent (`os.mkdir` applies the umask, which only
takes bits away), then checked with `os.lstat`, never following a link: a real folder, not a
symbolic link, owned by `os.geteuid()`, no write bit for group or others, and writable (a read-only
mount is passed over as a folder that cannot take the cache). What lies inside it is then reachable
only through it. Where no candidate passes, the cache is not used: the work is done afresh.
"""
from __future__ import annotations

import os
import stat
from pathlib import Path


REFUSED = ": refused, another user could have planted its contents"   # the end of a reason that is a refusal


def not_own_folder(path: str | os.PathLike) -> str | None:
    """Make `path` a folder only this user can write, or say why it is not one: None when it is
    (created with mode 0700 where absent, its missing parents as the umask gives them); otherwise
    the reason, the end of a sentence that begins with the path."""
    path = os.fspath(path)
    try:
        parent = os.path.dirname(os.path.abspath(path))
        if not os.path.isdir(parent):
            os.makedirs(parent)
        os.mkdir(path, 0o700)
    except OSError as e:
        if not (isinstance(e, FileExistsError) and e.filename == path):
            return f"cannot be made ({e.strerror or e})"
    try:
        st = os.lstat(path)
    except OSError as e:
        return f"cannot be read ({e.strerror or e})"
    if stat.S_ISLNK(st.st_mode):
        return "is a symbolic link" + REFUSED
    if not stat.S_ISDIR(st.st_mode):
        return "is not a folder"
    if hasattr(os, "geteuid") and st.st_uid != os.geteuid():
        return f"is owned by another user (uid {st.st_uid}; this process runs as {os.geteuid()})" + REFUSED
    if st.st_mode & (stat.S_IWGRP | stat.S_IWOTH):
        return f"can be written by other users (mode {stat.S_IMODE(st.st_mode):o})" + REFUSED
    if not os.access(path, os.W_OK | os.X_OK):
        return "cannot be written"
    return None


def own_folder(candidates, given: str | None = None) -> tuple[Path | None, list[str]]:
    """The first of `candidates` that is a folder only this user can write (`not_own_folder`), and
    why each before it was passed over ("PATH REASON"; `given`: the name of the environment variable
    the first candidate came from, said with it). (None, reasons) when none passes."""
    passed = []
    for i, c in enumerate(candidates):
        why = not_own_folder(c)
        if why is None:
            return Path(c), passed
        passed.append(f"{c} ({given}) {why}" if given and i == 0 else f"{c} {why}")
    return None, passed
