"""Issue 36: a PWM channel of the RP1 is not fresh when the ESC driver exports it. pwm-rp1.c has no
.get_state and unexport does not reset a channel, so it keeps what its last user left; 6.6 refuses any
state with period 0 or a duty cycle longer than the period, the 6.12 kernels check disabled states only
(6.11's rule) or enabled ones only (6.16's fix, backported) (tests/helpers/fakes/sysfs_pwm.py, from the Raspberry
Pi kernel's sysfs.c, core.c and pwm-rp1.c). The driver's
start (flightctl/drivers/pwm_sysfs.py) from any state either kernel can hold; its set-up errors one line
naming the file; the chip and udev's permission waited for at boot."""
from __future__ import annotations

import errno
import random

import pytest

from helpers.fakes.sysfs_pwm import RP1_PWM0, RP1_PWM1, RULES, ZERO, FakePwmSysfs, holdable
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


def test_the_kernels_rules(tmp_path):
    fakes = {rule: FakePwmSysfs(tmp_path / rule, rule=rule) for rule in RULES}
    for fake in fakes.values():
        fake.write(fake.dirs[RP1_PWM0] / "export", "0")

    def store(rule, what, value):
        return refused(fakes[rule], fakes[rule].channel(RP1_PWM0, 0) / what, value)

    # a channel that never had a period cannot even be disabled on 6.6; the later kernels let an invalid
    # state follow an invalid one (6.11: the zeros are invalid; 6.16: a disabled state is never invalid)
    assert [store(rule, "enable", "0") for rule in RULES] == [errno.EINVAL, None, None]
    assert [store(rule, "duty_cycle", "5000") for rule in RULES] == [errno.EINVAL, None, None]
    assert store("6.16", "enable", "1") == errno.EINVAL            # enabled: checked (period 0)
    assert store("6.11", "enable", "1") is None                    # enabled: not checked, applied
    assert fakes["6.11"].output(RP1_PWM0, 0) is None               # period 0: no pulses
    assert store("6.11", "enable", "0") == errno.EINVAL            # valid to invalid: refused, stuck enabled
    for rule in RULES:
        assert store(rule, "period", "1000000") is None
        assert store(rule, "enable", "1") is None
    assert [store(rule, "duty_cycle", "2000000") for rule in RULES] == [errno.EINVAL, None, errno.EINVAL]
    assert fakes["6.11"].state(RP1_PWM0, 0)["duty_cycle"] == 2_000_000   # enabled, longer than its period
    assert [store(rule, "enable", "0") for rule in RULES] == [None, errno.EINVAL, None]
    assert [store(rule, "duty_cycle", "3000000") for rule in ("6.6", "6.16")] == [errno.EINVAL, None]


@pytest.mark.parametrize("rule", RULES)
def test_the_issue_case_a_held_duty_above_our_period_refuses_a_period_first_start(tmp_path, rule):
    """What a period-first start met: a servo's 2.5 ms pulse left enabled; 2227171 ns < 2.5 ms."""
    fake = FakePwmSysfs(tmp_path, rule=rule)
    servo = dict(period=20_000_000, duty_cycle=2_500_000, enable=1)
    fake.retain(RP1_PWM0, 3, **servo)
    fake.write(fake.dirs[RP1_PWM0] / "export", "3")
    period_first = refused(fake, fake.channel(RP1_PWM0, 3) / "period", str(PERIOD_NS))
    assert period_first == (None if rule == "6.11" else errno.EINVAL)    # 6.11 checks no enabled state
    fake.write(fake.dirs[RP1_PWM0] / "unexport", "3")
    for c in (0, 3):
        fake.retain(RP1_PWM0, c, **servo)          # the servo's state again (6.11 applied the write above)
    esc = esc_on(fake)
    esc.start()
    assert fake.on_times_us() == STOPPED and esc.output_problems() == []
    for c in (0, 3):
        writes = [(p.rsplit("/", 1)[1], v) for p, v, err in fake.stores if p.startswith(f"pwmchip2/pwm{c}/") and not err]
        assert writes[-5:] == [("enable", "0"), ("duty_cycle", str(STOP_NS)), ("period", str(PERIOD_NS)),
                               ("polarity", "normal"), ("enable", "1")]
    esc.close()


def test_an_enabled_channel_6_11_let_through_without_a_valid_period_is_mended_while_enabled(tmp_path):
    """6.11 checks no enabled state: a channel left enabled with its duty cycle above its period (or no
    period) cannot be disabled first there (EINVAL); the start sets duty cycle and period while enabled."""
    fake = FakePwmSysfs(tmp_path, rule="6.11")
    for c, (period, duty) in enumerate([(1_000_000, 2_000_000), (0, 0), (0, 3_000_000), (500_000, 400_000)]):
        fake.retain(RP1_PWM0, c, period=period, duty_cycle=duty, enable=1, polarity="inversed")
    esc = esc_on(fake)
    esc.start()
    assert fake.on_times_us() == STOPPED and [s for s in fake.stores if s[2]] == []
    for c in range(3):
        writes = [(p.rsplit("/", 1)[1], v) for p, v, err in fake.stores if p.startswith(f"pwmchip2/pwm{c}/")]
        assert writes == [("duty_cycle", str(STOP_NS)), ("period", str(PERIOD_NS)), ("polarity", "normal"),
                          ("enable", "1")]
    esc.close()


def draw_state(rng: random.Random, rule: str) -> dict:
    """A state a channel can be left in under `rule`: never used since boot, or what a last user left."""
    while True:
        if rng.random() < 0.1:
            return dict(ZERO)
        period = rng.choice([0, rng.randrange(1, 50_000_001), PERIOD_NS, rng.randrange(1000, 3_000_000)])
        state = {"period": period, "duty_cycle": rng.randrange(0, 2 * max(period, STOP_NS) + 2),
                 "enable": rng.randrange(2), "polarity": rng.choice(["normal", "inversed"])}
        if holdable(state, rule):
            return state


@pytest.mark.parametrize("rule", RULES)
def test_start_takes_any_state_each_kernel_can_hold_to_the_stop_pulse(tmp_path, rule):
    rng = random.Random(36)
    fake = FakePwmSysfs(tmp_path, rule=rule)
    esc = esc_on(fake)
    for _ in range(80):
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
