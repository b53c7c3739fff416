"""The Pi 5's ESC driver (flightctl/drivers/pwm_sysfs.py) against the fake sysfs PWM tree, which enforces
the kernel's rules on every write (tests/helpers/fakes/sysfs_pwm.py): export, period before duty cycle, the
pulses it puts on the channels, the read-back that catches another process, the release at close and
at ExecStopPost, and the dead-man process when the controller stalls (tests/onboard/drivers/test_pwm_deadman.py: killed)."""
from __future__ import annotations

import errno
import random
import time

import pytest

from helpers.fakes.sysfs_pwm import RP1_PWM0, RP1_PWM1, FakePwmSysfs
from flightctl.drivers.pulses import OUTPUT_CHECK_S, EscError
from flightctl.drivers.pwm_sysfs import SysfsPwmEsc, find_chip, release
from flightctl.hal import ArmingRefused

PINS = (12, 13, 18, 19)
PERIOD_NS = 2227171          # round(1e9 / 449)


def esc_on(fake: FakePwmSysfs, **kw) -> SysfsPwmEsc:
    kw.setdefault("deadman_ms", 0)
    return SysfsPwmEsc(RP1_PWM0, (0, 1, 2, 3), pins=PINS, root=str(fake.root), fs=fake, **kw)


@pytest.fixture
def fake(tmp_path):
    return FakePwmSysfs(tmp_path)


def test_the_fake_kernel_keeps_the_rules_the_driver_relies_on(fake):
    chip = fake.dirs[RP1_PWM0]
    fake.write(chip / "export", "1")
    ch = chip / "pwm1"
    with pytest.raises(OSError) as e:
        fake.write(ch / "duty_cycle", "1000000")           # no period yet
    assert e.value.errno == errno.EINVAL
    with pytest.raises(OSError) as e:
        fake.write(ch / "enable", "1")                     # nor can it be enabled without one
    assert e.value.errno == errno.EINVAL
    fake.write(ch / "period", str(PERIOD_NS))
    with pytest.raises(OSError) as e:
        fake.write(ch / "duty_cycle", str(PERIOD_NS + 1))  # longer than the period
    assert e.value.errno == errno.EINVAL
    assert fake.state(RP1_PWM0, 1) == {"period": PERIOD_NS, "duty_cycle": 0, "enable": 0, "polarity": "normal"}
    with pytest.raises(OSError) as e:
        fake.write(chip / "export", "1")                   # exported twice
    assert e.value.errno == errno.EBUSY
    with pytest.raises(OSError) as e:
        fake.write(fake.dirs[RP1_PWM1] / "export", "3")    # the fan's channel: a kernel driver holds it
    assert e.value.errno == errno.EBUSY
    with pytest.raises(OSError) as e:
        fake.write(chip / "export", "4")                   # npwm is 4
    assert e.value.errno == errno.ENODEV


@pytest.mark.parametrize("numbering", [{2: (RP1_PWM0, 4), 6: (RP1_PWM1, 4)}, {0: (RP1_PWM0, 4), 1: (RP1_PWM1, 4)},
                                       {0: ("107d517a80.pwm", 2), 3: (RP1_PWM1, 4), 5: (RP1_PWM0, 4)}],
                         ids=["kernel 6.6", "kernel 6.12", "three chips"])
def test_the_chip_is_found_by_its_device_whatever_the_kernel_numbered_it(tmp_path, numbering):
    fake = FakePwmSysfs(tmp_path, chips=numbering)
    n = next(k for k, (dev, _) in numbering.items() if dev == RP1_PWM0)
    assert find_chip(str(fake.root), RP1_PWM0) == str(fake.root / f"pwmchip{n}")
    esc = esc_on(fake)
    esc.start()
    assert fake.exported() == [0, 1, 2, 3]
    esc.close()


def test_start_puts_the_stop_pulse_at_449_hz_on_four_channels_and_close_releases_them(fake):
    esc = esc_on(fake)
    esc.start()
    for c in range(4):
        assert fake.state(RP1_PWM0, c) == {"period": PERIOD_NS, "duty_cycle": 1_000_000, "enable": 1,
                                           "polarity": "normal"}
        period, high = fake.output(RP1_PWM0, c)
        assert 1 / period == pytest.approx(449.0, abs=0.01) and high == pytest.approx(1000e-6, abs=20e-9)
    # the order of the writes is the kernel's: the period before the duty cycle, enabled last
    writes = [path.split("/", 1)[1] for path, _, err in fake.stores if path.startswith("pwmchip2/pwm0/")]
    assert writes == ["pwm0/period", "pwm0/duty_cycle", "pwm0/polarity", "pwm0/enable"]
    esc.close()
    esc.close()                                           # safe twice
    assert fake.exported() == [] and all(err == "" for _, _, err in fake.stores)


def test_write_sends_each_command_as_the_pigpio_board_would_rounded_to_1_us(fake):
    rng = random.Random(29)
    esc = esc_on(fake)
    esc.arm()
    for _ in range(50):
        counts = [rng.randrange(0, 40001) for _ in range(4)]
        esc.write(counts)
        want = [min(max(round(c / 40000 * PERIOD_NS / 1000), 1000), 2100) for c in counts]
        assert [fake.state(RP1_PWM0, c)["duty_cycle"] for c in range(4)] == [w * 1000 for w in want]
    writes = esc.writes
    esc.write(counts)                                      # the same command: nothing written
    assert esc.writes == writes
    esc.close()


def test_a_channel_exported_by_another_process_is_a_refusal_that_names_it(fake):
    fake.write(fake.dirs[RP1_PWM0] / "export", "2")
    esc = esc_on(fake)
    with pytest.raises(EscError, match=r"motor 3 \(GPIO 18, pwmchip2 channel 2\) is already exported"):
        esc.start()
    assert fake.exported() == [2]                          # the other's channel is left alone, ours released


def test_a_channel_a_kernel_driver_holds_is_a_refusal(tmp_path):
    fake = FakePwmSysfs(tmp_path, kernel_held={(RP1_PWM0, 1): "pwm-fan"})
    with pytest.raises(EscError, match=r"motor 2 \(GPIO 13, pwmchip2 channel 1\) is held by a kernel driver"):
        esc_on(fake).start()
    assert fake.exported() == []


def test_the_channel_files_are_waited_for_until_udev_gives_them_to_group_gpio(fake):
    fake.udev_delay_s = 0.05                                # udev's rule runs on the export's event
    t0 = time.monotonic()
    esc = esc_on(fake)
    esc.start()
    assert time.monotonic() - t0 >= 0.05 and fake.on_times_us() == {c: 1000.0 for c in range(4)}
    esc.close()


@pytest.mark.parametrize("what, message", [("chip", r"motor 1 .* cannot be exported: \S*/pwmchip2/export: Permission denied"),
                                           ("channel", r"cannot open .*/pwm0/period \(Permission denied\)")])
def test_without_the_udev_rule_the_start_says_what_is_missing(fake, what, message):
    if what == "chip":
        fake.chip_writable = False
    else:
        fake.udev_delay_s = None
    esc = esc_on(fake)
    esc._sleep = lambda s: time.sleep(0)                    # no need to wait the 2 s out for real
    esc._clock = iter(range(0, 100)).__next__               # each look at the clock: a second later
    with pytest.raises(EscError, match=message + ".*group gpio and the udev rule"):
        esc.start()
    assert fake.exported() == []


def test_no_pwm_chip_says_which_chips_there_are(tmp_path):
    fake = FakePwmSysfs(tmp_path, chips={0: ("107d517a80.pwm", 2)})
    with pytest.raises(EscError, match=r"PWM chip 1f00098000.pwm not found .* pwmchip0 \(107d517a80.pwm\).*overlay"):
        esc_on(fake).start()


def test_another_process_writing_a_channel_in_flight_stops_the_loop_within_the_check_period(fake):
    now = [0.0]                                            # the loop's clock: one period per write
    esc = esc_on(fake, clock=lambda: now[0])
    esc.arm()
    esc.write([24000] * 4)
    t0 = now[0]
    fake.write(fake.channel(RP1_PWM0, 1) / "duty_cycle", "1900000")
    with pytest.raises(EscError, match=r"motor 2 .*duty_cycle reads 1900000.*another process"):
        while now[0] - t0 < 1.0:
            now[0] += 1 / 450
            esc.write([24000] * 4)                         # an unchanged command: nothing else would look
    assert now[0] - t0 <= OUTPUT_CHECK_S + 1 / 450
    esc.stop()
    assert fake.state(RP1_PWM0, 1)["duty_cycle"] == 1_000_000
    esc.close()


@pytest.mark.parametrize("what, value, seen", [("duty_cycle", "1500000", "duty_cycle reads 1500000"),
                                               ("period", "2500000", "period reads 2500000"),
                                               ("enable", "0", "enable reads 0"),
                                               ("polarity", "inversed", "polarity reads inversed")])
def test_a_change_while_disarmed_is_seen_the_stop_pulse_put_back_and_arming_refused(fake, what, value, seen):
    esc = esc_on(fake)
    esc.start()
    assert esc.output_problems() == []
    fake.write(fake.channel(RP1_PWM0, 3) / what, value)
    with pytest.raises(EscError, match=seen):
        esc.check_output()
    assert fake.state(RP1_PWM0, 3)["duty_cycle"] == 1_000_000
    if what == "duty_cycle":
        assert esc.output_problems() == []                 # the stop pulse is back
    else:
        with pytest.raises(ArmingRefused, match=seen):
            esc.arm()
    esc.close()


def test_release_frees_what_a_dead_controller_left_and_leaves_free_channels_alone(fake):
    chip = fake.dirs[RP1_PWM0]
    for c in (0, 1, 3):                                    # a dead controller's channels, motors running
        fake.write(chip / "export", str(c))
        for what, value in (("period", PERIOD_NS), ("duty_cycle", 1_800_000), ("enable", 1)):
            fake.write(chip / f"pwm{c}" / what, str(value))
    n = len(fake.stores)
    assert release(str(fake.root), RP1_PWM0, (0, 1, 2, 3), fs=fake) == ["pwm0", "pwm1", "pwm3"]
    assert fake.exported() == []
    done = [(p, v) for p, v, err in fake.stores[n:] if not err]
    for c in (0, 1, 3):                                    # the stop pulse, then disabled, then unexported
        mine = [(p, v) for p, v in done if p.startswith(f"pwmchip2/pwm{c}/") or (p.endswith("unexport") and v == str(c))]
        assert mine == [(f"pwmchip2/pwm{c}/duty_cycle", "1000000"), (f"pwmchip2/pwm{c}/enable", "0"),
                        ("pwmchip2/unexport", str(c))]
    assert release(str(fake.root), RP1_PWM0, (0, 1, 2, 3), fs=fake) == []


# --- the dead-man process ------------------------------------------------------------------------
def wait_for(predicate, timeout: float) -> float:
    t0 = time.monotonic()
    while not predicate():
        if time.monotonic() - t0 > timeout:
            raise AssertionError("not within %.2f s" % timeout)
        time.sleep(0.002)
    return time.monotonic() - t0


def test_the_dead_man_stops_the_motors_when_the_loop_stalls_and_the_next_write_says_so(fake):
    esc = esc_on(fake, deadman_ms=100)
    esc.start()
    esc.arm()
    end = time.monotonic() + 0.3
    while time.monotonic() < end:                          # writes keep it quiet
        esc.write([34000] * 4)
        time.sleep(0.002)
    assert fake.state(RP1_PWM0, 0)["duty_cycle"] > 1_000_000
    # waited for, however busy the machine; never before the dead-man's 100 ms (less the last write's sleep)
    stopped_after = wait_for(lambda: all(fake.state(RP1_PWM0, c)["duty_cycle"] == 1_000_000 for c in range(4)), 60.0)
    assert 0.08 < stopped_after, stopped_after
    time.sleep(0.05)
    with pytest.raises(EscError, match="the ESC dead-man stopped the motors: no command reached it for 100 ms"):
        esc.write([34000] * 4)
    esc.close()
    assert fake.exported() == []


def test_the_dead_man_is_quiet_while_disarmed_and_ends_with_close(fake):
    esc = esc_on(fake, deadman_ms=50)
    esc.start()
    esc.arm()
    esc.write([30000] * 4)
    esc.stop()
    time.sleep(0.2)                                        # disarmed: no countdown, nothing written by it
    assert esc._deadman.poll() is None
    proc = esc._deadman
    esc.close()
    assert proc.poll() is not None
