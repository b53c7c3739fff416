"""Issue 49: a disk cache (numba's compiled simulator, the two-rotor landing's gains) is kept only in a
folder that only its user can write (flightctl/cachedir.py), so that no other user can plant what
flightctl loads. The planted folders are another user's (root's) and the process that must refuse
them runs as `nobody`: root passes every permission check, so the refusal is seen as a user sees it."""
from __future__ import annotations

import json
import os
import shutil
import stat
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

from flightctl import cachedir
from flightctl.cachedir import REFUSED, not_own_folder, own_folder
from flightctl.control import spin_design
from flightctl.params import load

NOBODY = 65534


def test_a_folder_is_made_for_its_user_alone_and_any_other_is_refused(tmp_path):
    made = tmp_path / "new" / "cache"
    assert not_own_folder(made) is None
    st = os.lstat(made)
    assert stat.S_IMODE(st.st_mode) == 0o700 and st.st_uid == os.geteuid()
    open_to_all = tmp_path / "open"
    open_to_all.mkdir()
    open_to_all.chmod(0o777)
    assert "can be written by other users (mode 777)" in not_own_folder(open_to_all)
    link = tmp_path / "link"
    link.symlink_to(made)                     # a link to a good folder is still a link
    assert "symbolic link" in not_own_folder(link)
    theirs = tmp_path / "theirs"
    theirs.mkdir(mode=0o700)
    os.chown(theirs, NOBODY if os.geteuid() != NOBODY else 0, -1)
    assert f"owned by another user (uid {os.lstat(theirs).st_uid}" in not_own_folder(theirs)
    (tmp_path / "a-file").write_text("")
    assert "cannot be made" in not_own_folder(tmp_path / "a-file" / "below")
    assert "is not a folder" in not_own_folder(tmp_path / "a-file")
    folder, passed = own_folder([open_to_all, tmp_path / "a-file" / "below", made], given="SOME_VARIABLE")
    assert folder == made and len(passed) == 2
    assert passed[0].startswith(f"{open_to_all} (SOME_VARIABLE) can be written") and passed[0].endswith(REFUSED)
    assert own_folder([open_to_all, link]) == (None, [f"{open_to_all} {not_own_folder(open_to_all)}",
                                                     f"{link} {not_own_folder(link)}"])


def test_the_landing_gains_are_never_read_from_another_users_folder(tmp_path, monkeypatch, capsys):
    """FLIGHTCTL_CACHE names a folder another user owns, holding a schedule under the right name with
    gains of its own: it is not read (it would fly the two-rotor landing), said once, and the schedule
    goes to the user's cache folder instead."""
    d = spin_design.design_inputs(load(None))
    planted = tmp_path / "planted"
    planted.mkdir()
    forged = {"inputs": list(d), "rates": [123.0], "forged": True}
    (planted / f"spin-{spin_design.key(d)}.json").write_text(json.dumps(forged))
    os.chown(planted, NOBODY, -1)
    monkeypatch.setenv("FLIGHTCTL_CACHE", str(planted))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    monkeypatch.setattr(spin_design, "_MEMORY", {})
    monkeypatch.setattr(cachedir, "_SAID", set())
    s = spin_design.load(d)
    assert "forged" not in s and s["rates"][0] == spin_design.R_LO
    assert list((tmp_path / "xdg" / "flightctl").glob("spin-*.json"))
    monkeypatch.setattr(spin_design, "_MEMORY", {})
    spin_design.load(d)                       # read back from the user's own folder, not said again
    said = [line for line in capsys.readouterr().err.splitlines() if "gain cache" in line]
    assert len(said) == 1 and f"{planted} (FLIGHTCTL_CACHE) is owned by another user" in said[0], said
    assert f"kept in {tmp_path / 'xdg' / 'flightctl'}" in said[0]


# --- numba's cache, chosen by a process running as nobody --------------------------------------------
CHILD = """
import json, os, sys
from flightctl.sim.world import compiled
compiled.enabled()
print(json.dumps({"cache": compiled.CACHE, "folder": os.environ.get("NUMBA_CACHE_DIR"), "uid": os.geteuid()}))
"""

# The interpreter lives under root's home (mode 0700): a mount namespace of the child's own makes that
# home traversable for it (a tmpfs over /root with the interpreter's tree bound back in), then the
# child drops to nobody. Nothing outside the namespace changes.
AS_NOBODY = """set -e
stage=$(mktemp -d)
mount --bind /root/.pyenv "$stage"
mount -t tmpfs -o mode=0755 tmpfs /root
mkdir /root/.pyenv
mount --move "$stage" /root/.pyenv
cd /
exec setpriv --reuid={uid} --regid={uid} --clear-groups "$@"
"""


def _as_nobody(env: dict) -> tuple[dict, list[str]]:
    """The child's choice of cache folder and its stderr lines about it."""
    r = subprocess.run(["unshare", "-m", "sh", "-c", AS_NOBODY.format(uid=NOBODY), "sh", sys.executable, "-B", "-c", CHILD],
                       capture_output=True, text=True, timeout=120, env=env)
    if r.returncode != 0 and "flightctl" not in r.stderr:
        pytest.skip(f"no mount namespace or setpriv here: {r.stderr.strip()}")
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout), [line for line in r.stderr.splitlines() if "compiled simulator's cache" in line]


needs_root = pytest.mark.skipif(os.geteuid() != 0 or not shutil.which("unshare") or not shutil.which("setpriv")
                                or not str(Path(sys.executable).resolve()).startswith("/root/.pyenv/"),
                                reason="needs root, unshare, setpriv and this interpreter under /root/.pyenv")


@pytest.fixture
def shared_tmp():
    """A temporary folder every user can write, as /tmp is (sticky, mode 1777)."""
    folder = tempfile.mkdtemp(prefix="flightctl-shared-", dir="/tmp")
    os.chmod(folder, 0o1777)
    yield Path(folder)
    shutil.rmtree(folder)


def _env(shared: Path, **extra) -> dict:
    env = {k: v for k, v in os.environ.items()
           if k not in ("NUMBA_CACHE_DIR", "XDG_CACHE_HOME", "FLIGHTCTL_CACHE_SAID", "FLIGHTCTL_JIT")}
    return {**env, "TMPDIR": str(shared), "HOME": "/nonexistent", **extra}


def _predictable(shared: Path) -> Path:
    from flightctl.sim.world import compiled
    return shared / compiled.cache_candidates(compiled.source_digest(), uid=NOBODY)[-1].name


@needs_root
@pytest.mark.parametrize("plant", ["open folder", "link", "given"])
def test_a_cache_folder_planted_by_another_user_is_refused(shared_tmp, plant):
    """Root plants the folder at the temporary folder's predictable name, writable by anyone (so the
    old check, "takes a new file", passed it), or a link there to such a folder, or gives it as
    NUMBA_CACHE_DIR; with a file of 'compiled code' in it. The child, as nobody, does not use it:
    it has no other folder of its own (no home; the package is root's), so it compiles afresh,
    saying so once, naming the planted folder; the folder is as planted."""
    target = shared_tmp / "planted"
    target.mkdir()
    target.chmod(0o777)
    (target / "flightctl.index").write_bytes(b"planted")
    predictable = _predictable(shared_tmp)
    env = _env(shared_tmp)
    if plant == "open folder":
        target.rename(predictable)
        target = predictable
    elif plant == "link":
        predictable.symlink_to(target)
    else:
        env["NUMBA_CACHE_DIR"] = str(target)
    got, said = _as_nobody(env)
    assert got["uid"] == NOBODY
    assert len(said) == 1, said
    named = predictable if plant == "link" else target
    assert f"{named}{' (NUMBA_CACHE_DIR)' if plant == 'given' else ''} " in said[0] and REFUSED in said[0], said
    if plant == "given":        # the predictable folder is free: the child makes its own there
        assert got["cache"] and got["folder"] == str(predictable)
        assert os.lstat(predictable).st_uid == NOBODY
    else:
        assert got == {"cache": False, "folder": None, "uid": NOBODY} and "compiles afresh" in said[0]
    assert [p.name for p in target.iterdir()] == ["flightctl.index"]
    assert (target / "flightctl.index").read_bytes() == b"planted"


@needs_root
def test_the_users_own_cache_folder_is_made_for_it_alone(shared_tmp):
    """Nothing planted: the child, as nobody, makes the predictable folder itself, mode 0700, and
    keeps the cache there; said once (the package's folder and the home it cannot use)."""
    got, said = _as_nobody(_env(shared_tmp))
    predictable = _predictable(shared_tmp)
    assert got == {"cache": True, "folder": str(predictable), "uid": NOBODY}
    st = os.lstat(predictable)
    assert st.st_uid == NOBODY and stat.S_IMODE(st.st_mode) == 0o700
    assert len(said) == 1 and f"is in {predictable}" in said[0], said
