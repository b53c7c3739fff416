"""The plan queue of `flightctl run --plan-queue DIR`: which queued plan may fly, and what is refused.

A plan file dropped into the queue is looked at only once it is PLAN_SETTLE_S old (a copy in
progress is not read half-written). Then, in order of age, each plan is:
- checked before anything else: a regular file (a named pipe, a device or a link is never opened,
  so nothing can hang the service), read and validated by the plan reader (flightctl/plans/plan.py), its
  name usable as part of a log file name; any failure of the reader, whatever it raises, is one line;
- refused when stale: written before this service started (queued while it was down: "a restart can
  never re-arm" holds for any queue), or older than `max_age_s` (a plan that could not be claimed in
  time, e.g. behind a read-only log directory, must not fly whenever the directory comes back);
- claimed by renaming it into the log directory (atomic: a plan flies at most once).
A refused plan is moved aside into DIR/refused/ with a one-line DIR/refused/<file>.reason, and the
same line goes to the journal; the service keeps running. What cannot be done (the queue or the log
directory not writable) is said in the journal once per plan and state, while the plan waits.
"""
from __future__ import annotations

import logging
import os
import re
import stat
import time
from datetime import datetime, timezone
from pathlib import Path

from flightctl.errors import InputError
from flightctl.plans.plan import Plan, read_plan_file

PLAN_SETTLE_S = 0.5          # a plan file must be this old before it is looked at (a copy in progress)
PLAN_MAX_AGE_RANGE_S = (1.0, 86400.0)   # --plan-max-age: from a second to a day
PLAN_MAX_AGE_S = 60.0        # default: a plan not claimed within this time of being written is refused
PLAN_FUTURE_S = 5.0          # a plan written further in the future than this: the clock is wrong
MAX_PLAN_BYTES = 1 << 20     # a plan file is a few hundred bytes
NAME = re.compile(r"[A-Za-z0-9_.+-]{1,64}")   # a plan's name becomes part of its log file names
REFUSED = "refused"

log = logging.getLogger("flightctl.run")


def stamp() -> str:
    return datetime.now(timezone.utc).strftime("%Y%m%dT%H%M%SZ")


def new_path(directory: Path, kind: str, suffix: str) -> Path:
    """DIR/<kind>-<UTC time>[-k]-<suffix>, a name not taken yet."""
    directory.mkdir(parents=True, exist_ok=True)
    s = stamp()
    for k in range(1000):
        p = directory / f"{kind}-{s}{'-%d' % k if k else ''}-{suffix}"
        if not os.path.lexists(p):
            return p
    raise OSError(f"{directory}: cannot name a new {kind} file")


def _when(t: float) -> str:
    return datetime.fromtimestamp(t, timezone.utc).strftime("%Y-%m-%d %H:%M:%S UTC")


def validate(path: Path) -> Plan:
    """The plan in `path`, or InputError with one line: never opens a non-regular file."""
    st = os.lstat(path)
    if not stat.S_ISREG(st.st_mode):
        raise InputError(f"{path.name}: not a regular file (a named pipe, device, link or directory)")
    if st.st_size > MAX_PLAN_BYTES:
        raise InputError(f"{path.name}: {st.st_size} bytes, a plan file is at most {MAX_PLAN_BYTES}")
    try:
        plan = read_plan_file(path)
    except InputError:
        raise
    except (Exception, RecursionError) as e:       # the reader's own failure: still one line
        raise InputError(f"{path.name}: unreadable plan ({str(e)[:120] or 'its reader failed'})") from None
    return check_name(plan, path.name)


def check_name(plan: Plan, where: str) -> Plan:
    """InputError unless the plan's name can be part of a log file name."""
    if not NAME.fullmatch(plan.name):
        shown = plan.name if len(plan.name) <= 40 else plan.name[:40] + "..."
        raise InputError(f"{where}: name {shown!r} ({len(plan.name)} characters): 1 to 64 letters, "
                         "digits, '_', '.', '+' or '-' are needed (it names the log files)")
    return plan


class PlanQueue:
    def __init__(self, queue: Path, log_dir: Path, started: float | None = None,
                 max_age_s: float = PLAN_MAX_AGE_S, clock=time.time):
        self.queue, self.log_dir = Path(queue), Path(log_dir)
        self.clock = clock
        self.started = clock() if started is None else started
        self.max_age_s = max_age_s
        self._said: dict[str, str] = {}     # plan file -> the last waiting message said about it
        self.refused: list[tuple[str, str]] = []   # (file, reason), for the service's status line

    def open(self) -> None:
        """Create the queue if needed; say so in the journal when it cannot work."""
        try:
            self.queue.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            log.error("plan queue %s cannot be created (%s): no plan can be flown", self.queue, e.strerror)
            return
        if not os.access(self.queue, os.W_OK | os.X_OK):
            log.error("plan queue %s is not writable by this service: plans cannot be claimed or moved aside",
                      self.queue)

    def take(self) -> tuple[Plan, Path] | None:
        """The next plan that may fly, claimed into the log directory (plan, claimed file); None if none."""
        now = self.clock()
        try:
            entries = [e for e in os.scandir(self.queue) if e.name.endswith(".toml")]
        except OSError as e:
            self._say(str(self.queue), f"plan queue {self.queue} cannot be read ({e.strerror})")
            return None
        found = []
        for e in entries:
            try:
                mtime = e.stat(follow_symlinks=False).st_mtime
            except OSError:
                continue                     # taken away meanwhile
            if now - mtime >= PLAN_SETTLE_S or mtime - now > PLAN_FUTURE_S:
                found.append((mtime, e.name))
        for mtime, name in sorted(found):
            path = self.queue / name
            try:
                plan = validate(path)
            except FileNotFoundError:
                continue
            except (InputError, OSError) as e:
                self.refuse(path, str(e) if isinstance(e, InputError) else f"{name}: cannot read ({e.strerror})")
                continue
            if mtime < self.started:
                self.refuse(path, f"{name}: stale: written {_when(mtime)}, before this service started "
                                  f"({_when(self.started)}): a plan is flown only if queued while the service runs")
                continue
            if mtime - now > PLAN_FUTURE_S:
                self.refuse(path, f"{name}: written {mtime - now:.0f} s in the future: the clock is wrong")
                continue
            if now - mtime > self.max_age_s:
                self.refuse(path, f"{name}: stale: written {now - mtime:.0f} s ago, plans older than "
                                  f"{self.max_age_s:g} s are not flown")
                continue
            claimed = self._claim(path, plan)
            if claimed is not None:
                return plan, claimed
        return None

    def _claim(self, path: Path, plan: Plan) -> Path | None:
        try:
            target = new_path(self.log_dir, "plan", f"{plan.name}.toml")
            os.rename(path, target)
        except FileNotFoundError:
            return None                       # taken away meanwhile
        except OSError as e:
            if os.access(self.queue, os.W_OK | os.X_OK):
                where = f"log directory {self.log_dir}"
            else:
                where = f"plan queue {self.queue}"
            self._say(path.name, f"plan {path.name} waits: {where} is not writable ({e.strerror}); it is "
                                 f"refused if not claimed within {self.max_age_s:g} s of being written")
            return None
        self._said.pop(path.name, None)
        log.info("plan %s claimed as %s", path.name, target)
        return target

    def refuse(self, path: Path, reason: str) -> None:
        """Move `path` aside into QUEUE/refused/ with the one-line reason beside it; say it once."""
        reason = " ".join(reason.split())
        try:
            aside = self.queue / REFUSED
            aside.mkdir(exist_ok=True)
            target = new_path(aside, "plan", path.name)
            os.rename(path, target)
        except FileNotFoundError:
            return
        except OSError as e:
            self._say(path.name, f"plan refused: {reason}; it cannot be moved aside into {self.queue / REFUSED} "
                                 f"({e.strerror}): the plan queue must be writable by this service")
            return
        try:
            target.with_name(target.name + ".reason").write_text(reason + "\n")
        except OSError:
            pass                              # the journal has it
        self._said.pop(path.name, None)
        self.refused.append((path.name, reason))
        log.error("plan refused, moved to %s: %s", target, reason)

    def _say(self, key: str, message: str) -> None:
        """Log `message` once for `key` until it changes (the queue is polled twice a second)."""
        if self._said.get(key) != message:
            self._said[key] = message
            log.error("%s", message)
