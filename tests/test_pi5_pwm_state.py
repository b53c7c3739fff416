"""Issue 36: a PWM channel of the RP1 is not fresh when the ESC driver exports it. pwm-rp1.c has no
.get_state and unexport does not reset a channel, so it keeps what its last user left; 6.6 refuses any
state with period 0 or a duty cycle longer than the period, 6.12 checks enabled states only
(tests/fakes/sysfs_pwm.py, from the Raspberry Pi kernel's sysfs.c, core.c and pwm-rp1.c). The driver's
start (flightctl/drivers/pwm_sysfs.py) from any state either kernel can hold; its set-up errors one line
naming the file; the chip and udev's permission waited for at boot."""
from __future__ import annotations

import errno
import random

import pytest

from fakes.sysfs_pwm import RP1_PWM0, RP1_PWM1, RULES, FakePwmSysfs, valid
from flightctl.drivers.pulses import EscError
from flightctl.drivers.pwm_sysfs import CHIP_WAIT_S, SysfsPwmEsc

PERIOD_NS, STOP_NS = 2227171, 1_000_000
STOPPED = {c: 1000.0 for c in range(4)}


def esc_on(fake: FakePwmSysfs, **kw) -> SysfsPwmEsc:
    kw.setdefault("deadman_ms", 0)
    return SysfsPwmEsc(RP1_PWM0, (0, 1, 2, 3), pins=(12, 13, 18, 19), root=str(fake.root), fs=fake, **kw)


def refused(fake: FakePwmSysfs, path, value: str) -> int | None:
    try:
        fake.write(path, value)
    except OSError as e:
        return e.errno
    return None


@pytest.mark.parametrize("rule", RULES)
def test_a_channel_keeps_its_state_across_unexport_and_export_and_its_old_pulses_come_back(tmp_path, rule):
    fake = FakePwmSysfs(tmp_path, rule=rule)
    chip = fake.dirs[RP1_PWM0]
    fake.write(chip / "export", "2")
    for what, value in (("period", "20000000"), ("duty_cycle", "1500000"), ("polarity", "inversed"), ("enable", "1")):
        fake.write(chip / "pwm2" / what, value)
    assert fake.output(RP1_PWM0, 2) == pytest.approx((0.02, 0.0185))       # inversed: high for the rest
    fake.write(chip / "unexport", "2")
    assert fake.output(RP1_PWM0, 2) is None                                 # rp1_pwm_free(): mode cleared
    fake.write(chip / "export", "2")
    assert fake.state(RP1_PWM0, 2) == {"period": 20_000_000, "duty_cycle": 1_500_000, "enable": 1,
                                       "polarity": "inversed"}
    # rp1_pwm_request() put the default control word back (normal polarity), the enable bit stayed set
    assert fake.output(RP1_PWM0, 2) == pytest.approx((0.02, 0.0015))
    assert FakePwmSysfs.attach(tmp_path).state(RP1_PWM0, 2)["period"] == 20_000_000   # another process sees it


def test_the_two_kernels_rules(tmp_path):
    old, new = FakePwmSysfs(tmp_path / "6.6", rule="6.6"), FakePwmSysfs(tmp_path / "6.12", rule="6.12")
    for fake in (old, new):
        fake.write(fake.dirs[RP1_PWM0] / "export", "0")
    ch = lambda f: f.channel(RP1_PWM0, 0)                                   # noqa: E731
    # a channel that never had a period cannot even be disabled on 6.6; 6.12 does not check a disabled state
    assert refused(old, ch(old) / "enable", "0") == errno.EINVAL and refused(new, ch(new) / "enable", "0") is None
    assert refused(old, ch(old) / "duty_cycle", "5000") == errno.EINVAL
    assert refused(new, ch(new) / "duty_cycle", "5000") is None            # invalid to invalid: stored
    assert refused(new, ch(new) / "enable", "1") == errno.EINVAL           # ... but never enabled so
    for fake in (old, new):
        assert refused(fake, ch(fake) / "period", "1000000") is None
        assert refused(fake, ch(fake) / "enable", "1") is None
        assert refused(fake, ch(fake) / "duty_cycle", "2000000") == errno.EINVAL   # enabled: checked by both
    assert refused(old, ch(old) / "enable", "0") is None
    assert refused(old, ch(old) / "duty_cycle", "2000000") == errno.EINVAL
    assert refused(new, ch(new) / "enable", "0") is None
    assert refused(new, ch(new) / "duty_cycle", "2000000") is None


@pytest.mark.parametrize("rule", RULES)
def test_the_issue_case_a_held_duty_above_our_period_refuses_a_period_first_start(tmp_path, rule):
    """What a period-first start met: a servo's 2.5 ms pulse left enabled; 2227171 ns < 2.5 ms."""
    fake = FakePwmSysfs(tmp_path, rule=rule)
    fake.retain(RP1_PWM0, 0, period=20_000_000, duty_cycle=2_500_000, enable=1)
    fake.write(fake.dirs[RP1_PWM0] / "export", "0")
    assert refused(fake, fake.channel(RP1_PWM0, 0) / "period", str(PERIOD_NS)) == errno.EINVAL
    fake.write(fake.dirs[RP1_PWM0] / "unexport", "0")
    esc = esc_on(fake)
    esc.start()
    assert fake.on_times_us() == STOPPED and esc.output_problems() == []
    writes = [(p.rsplit("/", 1)[1], v) for p, v, err in fake.stores if p.startswith("pwmchip2/pwm0/")]
    assert writes[-5:] == [("enable", "0"), ("duty_cycle", str(STOP_NS)), ("period", str(PERIOD_NS)),
                           ("polarity", "normal"), ("enable", "1")]
    esc.close()


def draw_state(rng: random.Random, rule: str) -> dict:
    """A state the kernel can hold: a fresh channel, or what a last user left, valid under `rule`."""
    while True:
        if rng.random() < 0.15:
            return {"period": 0, "duty_cycle": 0, "enable": 0, "polarity": "normal"}
        period = rng.choice([rng.randrange(1, 50_000_001), PERIOD_NS, rng.randrange(1000, 3_000_000)])
        state = {"period": period, "duty_cycle": rng.randrange(0, 2 * period + 2), "enable": rng.randrange(2),
                 "polarity": rng.choice(["normal", "inversed"])}
        if rule == "6.12" and not state["enable"] and rng.random() < 0.2:
            state["period"] = 0                      # 6.12 may store an invalid disabled state
        if valid(state, rule):
            return state


@pytest.mark.parametrize("rule", RULES)
def test_start_takes_any_state_either_kernel_can_hold_to_the_stop_pulse(tmp_path, rule):
    rng = random.Random(36)
    fake = FakePwmSysfs(tmp_path, rule=rule)
    esc = esc_on(fake)
    for _ in range(60):
        held = {c: draw_state(rng, rule) for c in range(4)}
        for c, state in held.items():
            fake.retain(RP1_PWM0, c, **state)
        n = len(fake.stores)
        esc.start()
        assert [s for s in fake.stores[n:] if s[2]] == [], held            # no write refused
        assert fake.on_times_us() == STOPPED, held
        assert all(fake.output(RP1_PWM0, c)[0] == pytest.approx(1 / 449.0, rel=1e-5) for c in range(4))
        assert esc.output_problems() == []
        esc.close()
        assert fake.exported() == [] and fake.on_times_us() == {c: None for c in range(4)}


def test_a_write_the_kernel_refuses_at_set_up_is_one_line_naming_the_file(tmp_path):
    """The RP1's PWM clock not running: rp1_pwm_apply() refuses every state (EINVAL)."""
    fake = FakePwmSysfs(tmp_path)
    fake.clock_off = True
    with pytest.raises(EscError) as e:
        esc_on(fake).start()
    message = str(e.value)
    assert "\n" not in message and message.startswith(str(fake.root / "pwmchip2" / "pwm0" / "period"))
    assert "writing 2227171 failed (Invalid argument)" in message and "held period 0" in message
    assert fake.exported() == []                                            # released again


class Boot:
    """The clock and sleep of a boot: each sleep advances the clock; `events` happen at given sleeps."""

    def __init__(self, events: dict):
        self.t, self.sleeps, self.events = 0.0, 0, events

    def clock(self) -> float:
        return self.t

    def sleep(self, s: float) -> None:
        self.t += s
        self.sleeps += 1
        if self.sleeps in self.events:
            self.events[self.sleeps]()


def test_at_boot_the_chip_and_udevs_permission_are_waited_for(tmp_path):
    fake = FakePwmSysfs(tmp_path, chips={6: (RP1_PWM1, 4)})             # the RP1's PWM0 not probed yet
    fake.chip_writable = False                                            # nor its export given to gpio

    def probed():
        fake.add_chip(2, RP1_PWM0, 4)

    boot = Boot({7: probed, 12: lambda: setattr(fake, "chip_writable", True)})
    esc = esc_on(fake, clock=boot.clock, sleep=boot.sleep)
    esc.start()
    assert boot.sleeps >= 12 and fake.on_times_us() == STOPPED
    esc.close()


def test_a_chip_that_never_comes_is_a_refusal_after_the_bounded_wait(tmp_path):
    fake = FakePwmSysfs(tmp_path, chips={6: (RP1_PWM1, 4)})
    boot = Boot({})
    with pytest.raises(EscError, match=rf"PWM chip 1f00098000.pwm not found .*overlay.*waited {CHIP_WAIT_S:g} s"):
        esc_on(fake, clock=boot.clock, sleep=boot.sleep).start()
    assert CHIP_WAIT_S <= boot.t <= CHIP_WAIT_S + 0.2
