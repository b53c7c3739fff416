"""A fake of the kernel's sysfs PWM interface (/sys/class/pwm) for the Pi 5's ESC driver
(flightctl/drivers/pwm_sysfs.py), FUSE-free: a real directory laid out as the kernel lays it out, and
the kernel's rules enforced on the system calls that reach it through this object (`open`, `pwrite`,
`pread`, `close`: the `fs` the driver is given), as the kernel enforces them in its sysfs store functions.

The tree (as on a Raspberry Pi 5 with the PWM overlay, kernel 6.6):

    BASE/sys/devices/platform/axi/1000120000.pcie/1f00098000.pwm/pwm/pwmchip2/{export,unexport,npwm,device}
    BASE/sys/class/pwm/pwmchip2 -> ../../devices/.../1f00098000.pwm/pwm/pwmchip2
    ...pwmchip2/pwm0/{period,duty_cycle,enable,polarity}   (after `echo 0 > export`)

The rules, from the Raspberry Pi kernel's drivers/pwm/sysfs.c (6.6; merged into core.c later) and core.c,
and the RP1's driver drivers/pwm/pwm-rp1.c (raspberrypi/linux):
- export: a number (EINVAL otherwise), below npwm (ENODEV), a channel not already exported or held by a
  kernel driver (EBUSY; the fan's channel 3 of the second RP1 chip is `cooling_fan`'s). unexport: ENODEV
  unless exported.
- A channel's state is the kernel's `struct pwm_device` of the chip, which outlives its export: pwm-rp1
  has no `.get_state`, so `pwm_device_request()` leaves `pwm->state` as the last user left it, and
  unexport (`pwm_put()`) does not reset it. A re-exported channel shows the period, duty cycle, enable
  and polarity of its last user (zeros only the first time since boot). Its pin: `rp1_pwm_free()` (at
  unexport) clears the channel's mode bits (no pulses); `rp1_pwm_request()` (at export) writes the default
  control word back: trailing-edge mode, normal polarity. The global enable bit is never touched by
  either, so a channel left enabled carries its old pulses again from the moment it is re-exported (at
  normal polarity, whatever `polarity` reads), until the next store applies a state. `retain()` sets
  what a last user left; `output()` is what the pin carries.
- period, duty_cycle (ns, unsigned), enable (0 or 1), polarity (normal or inversed): each store builds
  the whole new state from the current one and applies it; when the new state equals the current one,
  nothing is applied (core.c). Which states are refused depends on the kernel (`rule`):
  "6.6": `__pwm_apply()` (raspberrypi/linux core.c of the 6.6 line) refuses (EINVAL, state unchanged)
    any state with period 0 or duty_cycle > period, enabled or not: a duty cycle before a period is
    EINVAL, and so is disabling a channel whose period is still 0;
  "6.11": `pwm_state_valid()` as 6.11-rc1 brought it, up to 6.12.y before the fix below was backported:
    it tests `state->enabled` the wrong way round, so an enabled state is never checked and a disabled
    one needs period > 0 and duty_cycle <= period; a store from an invalid state to another invalid one
    is stored, not applied (no EINVAL);
  "6.16": the same after "pwm: Fix invalid state detection" (9ee124caae1b, 6.16-rc6, backported to the
    stable kernels): a disabled state is not checked, an enabled one needs period > 0 and duty_cycle <=
    period; invalid to invalid is stored, not applied.
  The Raspberry Pi 5's 6.12 kernels have the "6.11" rule or the "6.16" one, depending on their stable
  release; `holdable()` is what a channel can be left in under each.
- a store writes the value the kernel would show (`%d\\n`); reads show it. `output(chip, channel)`: the
  RP1's 50 MHz clock rounds period and duty to 20 ns.
The kernel's own state (what survives an unexport, the pins' polarity) is kept in BASE/sys/.fake-kernel/, so that
another process's `attach` sees the same kernel.

Permissions are those of a process in group gpio: the chip's files writable (udev's rule at boot), a
new channel's files writable `udev_delay_s` after its export (udev's rule on the export's event; None:
no rule, EACCES for good). `add_chip` makes a chip appear late (its driver probing after the service
started). What it does not model: the RP1 latching a new duty at the end of the running period (the
world reads the latest value), a write from another process that bypasses this object (the dead-man
process writes the real files with `os.pwrite`, unchecked; it writes only the stop pulse, a valid value),
and the kernel's own locking beyond one lock for the whole tree. An "other process" in the tests writes
through this same object.
"""
from __future__ import annotations

import errno
import json
import os
import shutil
import threading
import time
from pathlib import Path

RP1_PWM0, RP1_PWM1 = "1f00098000.pwm", "1f0009c000.pwm"
PARENT = "sys/devices/platform/axi/1000120000.pcie"
CLOCK_NS = 20       # the RP1's PWM clock: 50 MHz
ATTRS = ("period", "duty_cycle", "enable", "polarity")
ZERO = {"period": 0, "duty_cycle": 0, "enable": 0, "polarity": "normal"}
RULES = ("6.6", "6.11", "6.16")


def strict(state: dict) -> bool:
    return state["period"] > 0 and state["duty_cycle"] <= state["period"]


def valid(state: dict, rule: str) -> bool:
    """Whether the kernel applies `state` (the rules above)."""
    if rule == "6.11" and state["enable"]:
        return True
    if rule == "6.16" and not state["enable"]:
        return True
    return strict(state)


def holdable(state: dict, rule: str) -> bool:
    """Whether a channel can be left in `state` under `rule`: never used since boot, applied, or (6.11,
    6.16) reached by stores from one invalid state to another, starting from the zeros."""
    if state == ZERO or valid(state, rule):
        return True
    return rule == "6.11"                 # the zeros are invalid there: every invalid state is reachable


class FakePwmSysfs:
    def __init__(self, base: Path, chips: dict[int, tuple[str, int]] | None = None,
                 kernel_held: dict[tuple[str, int], str] | None = None, rule: str = "6.6"):
        """`chips`: pwmchip number -> (device, npwm); the default is a 6.6 kernel's numbering, the RP1's
        PWM0 at pwmchip2 and PWM1 (the fan's) at pwmchip6. `kernel_held`: (device, channel) -> the kernel
        consumer holding it. `rule`: the kernel whose validity rule the stores follow (RULES)."""
        if rule not in RULES:
            raise ValueError(f"rule: one of {RULES}")
        self._setup(base, kernel_held)
        self.rule = rule
        self.kdir.mkdir(parents=True, exist_ok=True)
        (self.kdir / "rule").write_text(rule)
        self.root.mkdir(parents=True, exist_ok=True)
        for n, (device, npwm) in (chips if chips is not None else {2: (RP1_PWM0, 4), 6: (RP1_PWM1, 4)}).items():
            self.add_chip(n, device, npwm)

    def _setup(self, base, kernel_held) -> None:
        self.base = Path(base)
        self.root = self.base / "sys" / "class" / "pwm"
        self.kdir = self.base / "sys" / ".fake-kernel"     # not a kernel file: the fake kernel's memory
        self.kernel_held = kernel_held if kernel_held is not None else {(RP1_PWM1, 3): "cooling_fan"}
        self.lock = threading.RLock()
        self._paths: dict[int, Path] = {}     # open fd -> path
        self._files: dict[Path, int] = {}     # the kernel's own handle on each channel attribute
        # permissions, for a process that is not root: the chip's files are the gpio group's (udev at
        # boot) unless `chip_writable` is False; a new channel's files become so `udev_delay_s` after
        # the export (udev's "change" event), never if it is None (no udev rule)
        self.chip_writable, self.udev_delay_s = True, 0.0
        self.clock_off = False                # the RP1's PWM clock not running: every apply is EINVAL
        self._exported_at: dict[Path, float] = {}
        self.chips: dict[int, tuple[str, int]] = {}
        self.dirs: dict[str, Path] = {}
        self.stores: list[tuple[str, str, str]] = []     # (path relative to the root, value, errno name or "")

    def add_chip(self, n: int, device: str, npwm: int) -> Path:
        """The chip's driver probes: pwmchipN appears (at boot, or late)."""
        dev = self.base / PARENT / device
        chip = dev / "pwm" / f"pwmchip{n}"
        chip.mkdir(parents=True)
        (chip / "npwm").write_text(f"{npwm}\n")
        for name in ("export", "unexport"):
            (chip / name).write_text("")
        (chip / "device").symlink_to(os.path.relpath(dev, chip))
        (self.root / f"pwmchip{n}").symlink_to(os.path.relpath(chip, self.root))
        self.chips[n], self.dirs[device] = (device, npwm), chip
        return chip

    @classmethod
    def attach(cls, base: Path, kernel_held: dict[tuple[str, int], str] | None = None) -> "FakePwmSysfs":
        """The same tree seen from another process (its state is the files'): what it exported stays."""
        self = cls.__new__(cls)
        self._setup(base, kernel_held)
        self.rule = (self.kdir / "rule").read_text()
        for link in sorted(self.root.iterdir()):
            chip = Path(os.path.realpath(link))
            device = os.path.basename(os.path.realpath(chip / "device"))
            self.chips[int(link.name[7:])] = (device, int((chip / "npwm").read_text()))
            self.dirs[device] = chip
            for ch in chip.glob("pwm[0-9]*"):
                for f in ATTRS:
                    self._files[ch / f] = os.open(ch / f, os.O_RDWR)
        return self

    # --- the kernel's memory: what outlives an export, and the pin's polarity ---------------------
    def _kernel_path(self, device: str) -> Path:
        return self.kdir / f"{device}.json"

    def _kernel(self, device: str) -> dict:
        p = self._kernel_path(device)
        return json.loads(p.read_text()) if p.exists() else {}

    def _remember(self, device: str, c: int, **what) -> None:
        k = self._kernel(device)
        k.setdefault(str(c), {}).update(what)
        self._kernel_path(device).write_text(json.dumps(k))

    def retain(self, device: str, c: int, period: int, duty_cycle: int, enable: int = 0,
               polarity: str = "normal") -> None:
        """What the channel's last user left (it is not exported now): a state this kernel could hold."""
        state = {"period": period, "duty_cycle": duty_cycle, "enable": enable, "polarity": polarity}
        if not holdable(state, self.rule):
            raise ValueError(f"kernel {self.rule} never holds {state}")
        with self.lock:
            if self.channel(device, c).exists():
                raise ValueError(f"{device} channel {c} is exported")
            self._remember(device, c, state=state, hw_polarity=polarity)

    def retained(self, device: str, c: int) -> dict:
        return dict(self._kernel(device).get(str(c), {}).get("state", ZERO))

    # --- the system calls ------------------------------------------------------------------------
    def open(self, path, flags: int, mode: int = 0o777) -> int:
        p = Path(os.path.realpath(path))
        if not p.exists():
            raise FileNotFoundError(errno.ENOENT, os.strerror(errno.ENOENT), str(path))
        if flags & (os.O_WRONLY | os.O_RDWR) and not self._writable(p):
            raise PermissionError(errno.EACCES, os.strerror(errno.EACCES), str(path))
        fd = os.open(p, flags & ~os.O_CREAT & ~os.O_TRUNC)
        with self.lock:
            self._paths[fd] = p
        return fd

    def _writable(self, p: Path) -> bool:
        if p.name in ("export", "unexport"):
            return self.chip_writable
        exported = self._exported_at.get(p.parent)
        if exported is None or self.udev_delay_s is None:
            return exported is None
        return time.monotonic() >= exported + self.udev_delay_s

    def close(self, fd: int) -> None:
        with self.lock:
            self._paths.pop(fd, None)
        os.close(fd)

    def pread(self, fd: int, n: int, offset: int) -> bytes:
        with self.lock:
            p = self._paths[fd]
            if not p.exists():
                raise OSError(errno.ENODEV, os.strerror(errno.ENODEV), str(p))     # its channel was unexported
            return os.pread(fd, n, offset)

    def pwrite(self, fd: int, data: bytes, offset: int) -> int:
        """A sysfs store: the whole buffer, whatever the offset (sysfs ignores it)."""
        with self.lock:
            p = self._paths[fd]
            try:
                self._store(p, bytes(data).decode(errors="replace"))
            except OSError as e:
                self.stores.append((self._rel(p), bytes(data).decode(errors="replace").strip(), errno.errorcode[e.errno]))
                raise
            self.stores.append((self._rel(p), bytes(data).decode(errors="replace").strip(), ""))
            return len(data)

    def write(self, path, value: str) -> None:
        """What `echo VALUE > PATH` does in another process: through the same kernel."""
        fd = self.open(path, os.O_WRONLY)
        try:
            self.pwrite(fd, value.encode(), 0)
        finally:
            self.close(fd)

    # --- the kernel's store functions ------------------------------------------------------------
    def _rel(self, p: Path) -> str:
        return str(p).split("/pwm/", 1)[-1]

    @staticmethod
    def _fail(code: int, p: Path):
        raise OSError(code, os.strerror(code), str(p))

    def _chip_of(self, p: Path) -> tuple[Path, str, int]:
        chip = p.parent if p.parent.name.startswith("pwmchip") else p.parent.parent
        device = os.path.basename(os.path.realpath(chip / "device"))
        return chip, device, int((chip / "npwm").read_text())

    def _store(self, p: Path, text: str) -> None:
        if not p.exists():
            self._fail(errno.ENODEV, p)
        name = p.name
        if name in ("export", "unexport"):
            chip, device, npwm = self._chip_of(p)
            try:
                c = int(text.strip(), 0)
            except ValueError:
                self._fail(errno.EINVAL, p)
            if not 0 <= c < npwm:
                self._fail(errno.ENODEV, p)
            d = chip / f"pwm{c}"
            if name == "export":
                if d.exists() or (device, c) in self.kernel_held:
                    self._fail(errno.EBUSY, p)
                d.mkdir()
                self._exported_at[d] = time.monotonic()
                kept = self.retained(device, c)             # no .get_state: pwm->state as last left
                for f in ATTRS:
                    self._files[d / f] = os.open(d / f, os.O_RDWR | os.O_CREAT, 0o660)
                    self._put(d / f, str(kept[f]))
                self._remember(device, c, hw_polarity="normal")   # rp1_pwm_request(): the default control word
            else:
                if not d.exists():
                    self._fail(errno.ENODEV, p)
                self._remember(device, c, state=self._state(d))   # pwm_put(): the state stays
                for f in ATTRS:
                    os.close(self._files.pop(d / f))
                shutil.rmtree(d)
            return
        if name not in ATTRS:
            self._fail(errno.EIO, p)            # a read-only attribute (npwm): no store function
        old = self._state(p.parent)
        state = dict(old)
        value = text.strip()
        if name == "polarity":
            if value not in ("normal", "inversed"):
                self._fail(errno.EINVAL, p)
            state[name] = value
        else:
            try:
                v = int(value, 0)
            except ValueError:
                self._fail(errno.EINVAL, p)
            if v < 0 or (name == "enable" and v not in (0, 1)):
                self._fail(errno.EINVAL, p)
            state[name] = v
        if not valid(state, self.rule) and (self.rule == "6.6" or valid(old, self.rule)):
            self._fail(errno.EINVAL, p)         # refused: the state stays as it was
        if self.clock_off and state != old and valid(state, self.rule):
            self._fail(errno.EINVAL, p)         # rp1_pwm_apply(): "failed to get clock rate"
        self._put(p, str(state[name]))
        if state != old and valid(state, self.rule):      # applied: the pin follows
            _, device, _ = self._chip_of(p)
            self._remember(device, int(p.parent.name[3:]), hw_polarity=state["polarity"])

    def _put(self, p: Path, value: str) -> None:
        fd, data = self._files[p], (value + "\n").encode()
        os.pwrite(fd, data, 0)
        os.ftruncate(fd, len(data))

    def _state(self, channel: Path) -> dict:
        s = {f: os.pread(self._files[channel / f], 64, 0).decode().strip() for f in ATTRS}
        return {"period": int(s["period"]), "duty_cycle": int(s["duty_cycle"]), "enable": int(s["enable"]),
                "polarity": s["polarity"]}

    # --- test-facing views -----------------------------------------------------------------------
    def channel(self, device: str, c: int) -> Path:
        return self.dirs[device] / f"pwm{c}"

    def exported(self, device: str = RP1_PWM0) -> list[int]:
        return sorted(int(d.name[3:]) for d in self.dirs[device].iterdir() if d.name.startswith("pwm") and d.is_dir())

    def state(self, device: str, c: int) -> dict | None:
        d = self.channel(device, c)
        with self.lock:
            return self._state(d) if d.exists() else None

    def output(self, device: str, c: int) -> tuple[float, float] | None:
        """What the pin carries: (period, high time) in s as the RP1 makes them (20 ns ticks), or None
        for no pulses (not exported: rp1_pwm_free() cleared its mode; disabled: the line is low)."""
        s = self.state(device, c)
        if s is None or not s["enable"] or not s["period"]:
            return None
        period = round(s["period"] / CLOCK_NS) * CLOCK_NS * 1e-9
        high = round(min(s["duty_cycle"], s["period"]) / CLOCK_NS) * CLOCK_NS * 1e-9
        inversed = self._kernel(device).get(str(c), {}).get("hw_polarity", "normal") == "inversed"
        return (period, period - high) if inversed else (period, high)

    def on_times_us(self, device: str = RP1_PWM0, channels=(0, 1, 2, 3)) -> dict[int, float | None]:
        out = {}
        for c in channels:
            o = self.output(device, c)
            out[c] = None if o is None else round(o[1] * 1e6, 3)
        return out
