"""A cache folder that only its user can write: the one definition both disk caches use (numba's
compiled simulator, sim/world/compiled.py; the two-rotor landing's gain schedule,
control/spin_design.py), and the user's flightctl cache of JSON results by key (`user_folder`,
`cached_json`).

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

import json
import os
import stat
import sys
from pathlib import Path
from typing import Callable

from flightctl.errors import InputError

from flightctl.files import write_atomic


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


_SAID: set[str] = set()   # the caches whose passed-over folder has been said


def user_folder(what: str) -> Path | None:
    """The first of FLIGHTCTL_CACHE, $XDG_CACHE_HOME/flightctl, ~/.cache/flightctl that is a folder only
    this user can write (another user's could hold planted results), made where absent; None where
    none is (the work is then done at each start). A folder passed over as another user's is said once
    per cache (`what` names it) on stderr; one that cannot be made, no home, is no news."""
    given = os.environ.get("FLIGHTCTL_CACHE")
    home = os.path.expanduser("~")
    base = os.environ.get("XDG_CACHE_HOME") or (os.path.join(home, ".cache") if home != "~" else "")
    candidates = ([Path(given)] if given else []) + ([Path(base) / "flightctl"] if base else [])
    folder, passed = own_folder(candidates, "FLIGHTCTL_CACHE" if given else None)
    if what not in _SAID and any(REFUSED in why for why in passed):
        _SAID.add(what)
        where = f"it is kept in {folder}" if folder is not None else "it is computed at each start"
        print(f"flightctl: {what}: {'; '.join(passed)}: {where}", file=sys.stderr)
    return folder


def cached_json(name: str, inputs: list, compute: Callable[[], dict], what: str) -> dict:
    """The result of `compute()` for `inputs`: read from the user's cache folder's file `name` where it
    holds the same inputs, else computed and written there (atomically, with its "inputs"; a folder
    that cannot be written is no error: the result is then computed at each start)."""
    folder = user_folder(what)
    path = folder / name if folder is not None else None
    s = None
    if path is not None:
        try:
            s = json.loads(path.read_text())
            if s.get("inputs") != inputs:
                s = None
        except (OSError, ValueError):
            s = None
    if s is None:
        s = compute()
        s["inputs"] = inputs
        if path is not None:
            try:
                write_atomic(path, json.dumps(s))
            except (OSError, InputError):
                pass
    return s
