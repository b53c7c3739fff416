"""The systemd units (checked by `systemd-analyze verify` where it exists) with each board's drop-in (the
pigpio board's on a Pi 3/4, the pi5 board's on a Pi 5), the Pi install script (run with --dry-run for
both boards; shellcheck where it exists) and the Pi 5's overlay (compiled by dtc where it exists)."""
from __future__ import annotations

import configparser
import shutil
import subprocess
from pathlib import Path

import pytest
from helpers.paths import ROOT

UNIT = ROOT / "systemd" / "flightctl.service"
DROPIN = ROOT / "systemd" / "pigpiod.service.d" / "flightctl.conf"
PIGPIO = ROOT / "systemd" / "flightctl.service.d" / "pigpio.conf"
PI5 = ROOT / "systemd" / "flightctl.service.d" / "pi5.conf"
INSTALL = ROOT / "scripts" / "install-pi.sh"
OVERLAY = ROOT / "scripts" / "flightctl-pwm-pi5-overlay.dts"


def unit_entries(*paths: Path) -> dict[str, list[str]]:
    """key -> values in order (systemd keys repeat), from every section of the unit and its drop-ins."""
    entries: dict[str, list[str]] = {}
    for line in "\n".join(p.read_text() for p in paths).splitlines():
        line = line.strip()
        if line and not line.startswith(("#", "[")) and "=" in line:
            key, _, value = line.partition("=")
            entries.setdefault(key, []).append(value)
    return entries


def test_service_unit_has_the_lifecycle_the_design_needs():
    u = unit_entries(UNIT)
    assert u["Type"] == ["notify"] and u["NotifyAccess"] == ["main"]
    assert "Requires" not in u and "JoinsNamespaceOf" not in u       # pigpiod only with the pigpio board
    p = unit_entries(UNIT, PIGPIO)
    assert p["Requires"] == ["pigpiod.service"] and p["After"] == ["pigpiod.service"]
    assert "Requires" not in unit_entries(UNIT, PI5)
    assert u["KillMode"] == ["process"]                 # signals to the controller only: its dead-man outlives it
    assert int(u["WatchdogSec"][0]) >= 1
    assert u["User"] == ["flightctl"] and u["SupplementaryGroups"] == ["gpio spi i2c"]
    assert u["CPUSchedulingPolicy"] == ["fifo"] and "LimitRTPRIO" in u
    assert u["Restart"] == ["on-failure"] and u["RestartPreventExitStatus"] == ["3"]
    assert "--plan-queue" in u["ExecStart"][0] and "--plan " not in u["ExecStart"][0]   # arms only on a queued plan
    assert "--board auto" in u["ExecStart"][0]           # pi5 on a Raspberry Pi 5, pi elsewhere
    assert u["ExecStopPost"] == ["/opt/flightctl/venv/bin/flightctl run --board auto --stop-motors"]
    # parses as an INI file too (no stray syntax)
    configparser.ConfigParser(strict=False, interpolation=None).read_string(UNIT.read_text())


def test_pigpiod_dropin_binds_localhost_only():
    d = unit_entries(DROPIN)
    assert d["ExecStart"][0] == ""                     # reset, then replaced
    assert " -l" in d["ExecStart"][1] and d["ExecStart"][1].startswith("/usr/bin/pigpiod")


@pytest.mark.skipif(shutil.which("systemd-analyze") is None, reason="systemd-analyze not installed")
@pytest.mark.parametrize("board_dropin", [PIGPIO, PI5], ids=["pi", "pi5"])
def test_units_pass_systemd_analyze_verify(tmp_path, board_dropin):
    # the executables do not exist here: point them at /bin/true; a stub pigpiod.service for Requires=
    (tmp_path / "flightctl.service.d").mkdir()
    (tmp_path / "flightctl.service.d" / board_dropin.name).write_text(board_dropin.read_text())
    unit = tmp_path / "flightctl.service"
    unit.write_text(UNIT.read_text().replace("/opt/flightctl/venv/bin/flightctl", "/bin/true"))
    (tmp_path / "pigpiod.service").write_text("[Unit]\nDescription=stub\n[Service]\nType=forking\n"
                                              "ExecStart=/usr/bin/pigpiod\n")
    dropin = tmp_path / "pigpiod.service.d"
    dropin.mkdir()
    (dropin / "flightctl.conf").write_text(DROPIN.read_text().replace("/usr/bin/pigpiod", "/bin/true"))
    env = {"SYSTEMD_UNIT_PATH": f"{tmp_path}:", "PATH": "/usr/bin:/bin", "SYSTEMD_LOG_LEVEL": "info"}
    for name in ("flightctl.service", "pigpiod.service"):
        r = subprocess.run(["systemd-analyze", "verify", str(tmp_path / name)], env=env, capture_output=True,
                           text=True, timeout=60)
        problems = [l for l in (r.stdout + r.stderr).splitlines()
                    if any(w in l for w in ("Unknown", "Failed", "failed", "Invalid", "bad-setting", "not found"))]
        assert r.returncode == 0 and not problems, r.stdout + r.stderr


def test_install_script_dry_run_prints_every_step_and_changes_nothing(tmp_path):
    r = subprocess.run(["bash", str(INSTALL), "--dry-run", "--prefix", str(tmp_path / "opt")],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    out = r.stdout
    if shutil.which("raspi-config") is None:         # never planned where it does not exist
        assert "raspi-config nonint" not in out and "raspi-config not found" in r.stderr
    else:
        assert "raspi-config nonint do_spi 0" in out or "ok: SPI enabled" in out
    for step in ("--groups gpio,spi,i2c flightctl", f"python3 -m venv {tmp_path / 'opt'}/venv",
                 f"{tmp_path / 'opt'}/venv/bin/pip install", "/etc/systemd/system/flightctl.service",
                 "/etc/systemd/system/pigpiod.service.d/flightctl.conf", "systemctl daemon-reload",
                 "systemctl enable flightctl.service", "dry run: nothing was changed"):
        assert step in out, step
    assert "pigpio" in out or "ok: packages" in out
    # spidev builds from source on the Pi (no aarch64/armhf wheel): a compiler and Python's headers
    assert {"build-essential", "python3-dev", "pigpio"} <= set(out.split("packages: ", 1)[1].split("\n", 1)[0].split())
    assert "board: pi (" in out and "[pi]" in out and "flightctl.service.d/pigpio.conf" in out
    assert "flightctl-pwm-pi5" not in out and "pi5.conf" not in out
    assert not (tmp_path / "opt").exists()


def test_install_script_dry_run_on_a_pi5_installs_the_overlay_the_udev_rule_and_no_pigpio(tmp_path):
    r = subprocess.run(["bash", str(INSTALL), "--dry-run", "--board", "pi5", "--prefix", str(tmp_path / "opt")],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    out = r.stdout
    for step in ("board: pi5", "flightctl-pwm-pi5.dtbo", "dtoverlay=flightctl-pwm-pi5",
                 "/etc/udev/rules.d/90-flightctl-pwm.rules", "udevadm trigger --subsystem-match=pwm",
                 "--groups gpio,spi,i2c flightctl", f"{ROOT}[pi5]", "/etc/systemd/system/flightctl.service.d/pi5.conf",
                 "systemctl enable flightctl.service", "dry run: nothing was changed"):
        assert step in out, step
    assert "pigpio" not in out.replace("pigpio.conf", "") and "[pi]" not in out
    assert {"build-essential", "python3-dev"} <= set(out.split("packages: ", 1)[1].split("\n", 1)[0].split())
    assert not (tmp_path / "opt").exists()
    r = subprocess.run(["bash", str(INSTALL), "--dry-run", "--board", "pi4"], capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "--board pi4: pi (Raspberry Pi 3/4) or pi5" in r.stderr


@pytest.mark.skipif(shutil.which("dtc") is None, reason="dtc (device-tree-compiler) not installed")
def test_the_pi5_overlay_compiles_and_muxes_the_four_esc_pins_to_pwm0(tmp_path):
    dtbo = tmp_path / "o.dtbo"
    r = subprocess.run(["dtc", "-@", "-q", "-I", "dts", "-O", "dtb", "-o", str(dtbo), str(OVERLAY)],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    back = subprocess.run(["dtc", "-q", "-I", "dtb", "-O", "dts", str(dtbo)], capture_output=True, text=True,
                          timeout=60).stdout
    assert 'pins = "gpio12\\0gpio13\\0gpio18\\0gpio19"' in back and 'function = "pwm0"' in back
    assert "rp1_gpio = " in back and "rp1_pwm0 = " in back and 'status = "okay"' in back


def test_install_script_refuses_unknown_options():
    r = subprocess.run(["bash", str(INSTALL), "--frobnicate"], capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "unknown option" in r.stderr


@pytest.mark.skipif(shutil.which("shellcheck") is None, reason="shellcheck not installed")
def test_install_script_passes_shellcheck():
    r = subprocess.run(["shellcheck", str(INSTALL)], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stdout


def test_install_script_carries_the_prefix_into_the_unit(tmp_path):
    fake_src = tmp_path / "src"
    (fake_src / "systemd" / "pigpiod.service.d").mkdir(parents=True)
    (fake_src / "pyproject.toml").write_text("")
    (fake_src / "systemd" / "flightctl.service").write_text(UNIT.read_text())
    (fake_src / "systemd" / "pigpiod.service.d" / "flightctl.conf").write_text(DROPIN.read_text())
    (fake_src / "systemd" / "flightctl.service.d").mkdir()
    (fake_src / "systemd" / "flightctl.service.d" / "pigpio.conf").write_text(PIGPIO.read_text())
    script = INSTALL.read_text().replace("UNIT_DIR=/etc/systemd/system", f"UNIT_DIR={tmp_path / 'units'}")
    (tmp_path / "install.sh").write_text(script)
    # run only the unit step for real: everything before it is a dry run of the same script
    text = script.split("# 5. systemd units")[1].split('if [ "$UNITS_CHANGED"')[0]
    head = script.split("# 1. packages")[0].replace('if [ "$DRY_RUN" = 0 ] && [ "$(id -u)" != 0 ]', "if false")
    (tmp_path / "units.sh").write_text(head + text)
    r = subprocess.run(["bash", str(tmp_path / "units.sh"), "--prefix", "/srv/fc", "--source", str(fake_src),
                        "--board", "pi"],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    unit = (tmp_path / "units" / "flightctl.service").read_text()
    assert "/srv/fc/venv/bin/flightctl run" in unit and "/opt/flightctl" not in unit


def test_service_unit_is_hardened_and_shares_only_pigpiod_network():
    u, d = unit_entries(UNIT, PIGPIO), unit_entries(DROPIN)
    assert u["PrivateNetwork"] == ["yes"] and d["PrivateNetwork"] == ["yes"]
    assert u["JoinsNamespaceOf"] == ["pigpiod.service"]
    assert " -f" in d["ExecStart"][1]                    # no world-writable /dev/pigpio pipe
    assert u["CapabilityBoundingSet"] == [""] and u["DevicePolicy"] == ["closed"]
    assert {v.split()[0] for v in u["DeviceAllow"]} >= {"/dev/spidev0.0", "/dev/i2c-1", "/dev/gpiomem"}
    p5 = unit_entries(UNIT, PI5)                         # the Pi 5: the GPIO chips, sysfs PWM writable, no pigpiod
    assert {v.split()[0] for v in p5["DeviceAllow"]} == {"/dev/spidev0.0", "/dev/i2c-1", "char-gpiochip"}
    assert p5["ProtectKernelTunables"][-1] == "no" and p5["User"] == ["flightctl"]
    assert "gpio" in p5["SupplementaryGroups"][0].split()
    assert u["IPAddressDeny"] == ["any"] and "RestrictAddressFamilies" in u
    assert u["SystemCallFilter"][0] == "@system-service"
    assert all(u[k] == ["yes"] for k in ("ProtectKernelTunables", "ProtectKernelModules", "ProtectKernelLogs"))


@pytest.mark.skipif(shutil.which("systemd-analyze") is None, reason="systemd-analyze not installed")
@pytest.mark.parametrize("board_dropin", [PIGPIO, PI5], ids=["pi", "pi5"])
def test_systemd_analyze_security_rates_the_unit_3_or_better(tmp_path, board_dropin):
    unit = tmp_path / "flightctl.service"
    text = UNIT.read_text().replace("/opt/flightctl/venv/bin/flightctl", "/bin/true")
    service = [line for line in board_dropin.read_text().split("[Service]")[1].splitlines()
               if line and not line.startswith("#")]
    for line in service:                                  # the drop-in's [Service] settings, as systemd merges them
        text = "\n".join(l for l in text.splitlines() if l.split("=")[0] != line.split("=")[0] or l.startswith("DeviceAllow"))
    unit.write_text(text.replace("[Service]\n", "[Service]\n" + "\n".join(service) + "\n", 1))
    r = subprocess.run(["systemd-analyze", "security", "--offline=yes", str(unit)], capture_output=True,
                       text=True, timeout=60)
    if "--offline" in r.stderr and "unrecognized" in r.stderr:
        pytest.skip("this systemd-analyze cannot rate a unit file offline")
    line = [l for l in r.stdout.splitlines() if "Overall exposure level" in l][0]
    assert float(line.split(":")[1].split()[0]) <= 3.0, line


def test_the_start_timeout_covers_the_boot_waits_of_the_pi5_board():
    """At boot the Pi 5 board waits, bounded, for the PWM chip and udev's permission on its export, for
    each channel's files, for the dead-man to start and for the GPIO chip; the unit's TimeoutStartSec
    must leave as much again for the imports and the pre-arm checks. A refusal after those waits is
    exit 3, which the unit does not restart (no overlay: restarting will not help)."""
    from flightctl.boards.pi5 import GPIO_WAIT_S
    from flightctl.drivers.pwm_sysfs import CHIP_WAIT_S, DEADMAN_START_S, EXPORT_WAIT_S
    from flightctl.service.run import EXIT_REFUSED

    waits = CHIP_WAIT_S + 4 * EXPORT_WAIT_S + DEADMAN_START_S + GPIO_WAIT_S
    u = unit_entries(UNIT)
    assert 2 * waits <= float(u["TimeoutStartSec"][0])
    assert u["RestartPreventExitStatus"] == [str(EXIT_REFUSED)] and u["Restart"] == ["on-failure"]


def test_the_pigpio_boards_socket_is_one_the_units_sandbox_lets_through():
    """The pigpio client connects to the board file's host (socket.create_connection, pigpio.py): every
    address it resolves to must be of a family RestrictAddressFamilies= allows (an AF_INET6 ::1 would be
    EAFNOSUPPORT) and inside IPAddressAllow=localhost, on the loopback both units share."""
    import ipaddress
    import socket

    from flightctl.boards.pi import load_board

    u, d = unit_entries(UNIT, PIGPIO), unit_entries(DROPIN)
    families = set(u["RestrictAddressFamilies"][0].split())
    assert u["IPAddressAllow"] == ["localhost"] and d["IPAddressAllow"] == ["localhost"]
    pig = load_board().pigpio
    infos = socket.getaddrinfo(pig.host, pig.port, type=socket.SOCK_STREAM)
    assert infos
    for family, *_, address in infos:
        assert family.name in families, (pig.host, family.name, families)
        assert ipaddress.ip_address(address[0]).is_loopback, address
    assert " -l" in d["ExecStart"][1]                    # pigpiod listens on localhost: what the client reaches
