"""The systemd units (checked by `systemd-analyze verify` where it exists) and the Pi install script
(run with --dry-run; shellcheck where it exists)."""
from __future__ import annotations

import configparser
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
UNIT = ROOT / "systemd" / "flightctl.service"
DROPIN = ROOT / "systemd" / "pigpiod.service.d" / "flightctl.conf"
INSTALL = ROOT / "scripts" / "install-pi.sh"


def unit_entries(path: Path) -> dict[str, list[str]]:
    """key -> values in order (systemd keys repeat), from every section."""
    entries: dict[str, list[str]] = {}
    for line in path.read_text().splitlines():
        line = line.strip()
        if line and not line.startswith(("#", "[")) and "=" in line:
            key, _, value = line.partition("=")
            entries.setdefault(key, []).append(value)
    return entries


def test_service_unit_has_the_lifecycle_the_design_needs():
    u = unit_entries(UNIT)
    assert u["Type"] == ["notify"] and u["NotifyAccess"] == ["main"]
    assert u["Requires"] == ["pigpiod.service"] and u["After"] == ["pigpiod.service"]
    assert int(u["WatchdogSec"][0]) >= 1
    assert u["User"] == ["flightctl"] and u["SupplementaryGroups"] == ["gpio spi i2c"]
    assert u["CPUSchedulingPolicy"] == ["fifo"] and "LimitRTPRIO" in u
    assert u["Restart"] == ["on-failure"] and u["RestartPreventExitStatus"] == ["3"]
    assert "--plan-queue" in u["ExecStart"][0] and "--plan " not in u["ExecStart"][0]   # arms only on a queued plan
    assert u["ExecStopPost"] == ["/opt/flightctl/venv/bin/flightctl run --board pi --stop-motors"]
    # parses as an INI file too (no stray syntax)
    configparser.ConfigParser(strict=False, interpolation=None).read_string(UNIT.read_text())


def test_pigpiod_dropin_binds_localhost_only():
    d = unit_entries(DROPIN)
    assert d["ExecStart"][0] == ""                     # reset, then replaced
    assert " -l" in d["ExecStart"][1] and d["ExecStart"][1].startswith("/usr/bin/pigpiod")


@pytest.mark.skipif(shutil.which("systemd-analyze") is None, reason="systemd-analyze not installed")
def test_units_pass_systemd_analyze_verify(tmp_path):
    # the executables do not exist here: point them at /bin/true; a stub pigpiod.service for Requires=
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
    assert not (tmp_path / "opt").exists()


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
    script = INSTALL.read_text().replace("UNIT_DIR=/etc/systemd/system", f"UNIT_DIR={tmp_path / 'units'}")
    (tmp_path / "install.sh").write_text(script)
    # run only the unit step for real: everything before it is a dry run of the same script
    text = script.split("# 5. systemd units")[1].split('if [ "$UNITS_CHANGED"')[0]
    head = script.split("# 1. packages")[0].replace('if [ "$DRY_RUN" = 0 ] && [ "$(id -u)" != 0 ]', "if false")
    (tmp_path / "units.sh").write_text(head + text)
    r = subprocess.run(["bash", str(tmp_path / "units.sh"), "--prefix", "/srv/fc", "--source", str(fake_src)],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    unit = (tmp_path / "units" / "flightctl.service").read_text()
    assert "/srv/fc/venv/bin/flightctl run" in unit and "/opt/flightctl" not in unit


def test_service_unit_is_hardened_and_shares_only_pigpiod_network():
    u, d = unit_entries(UNIT), unit_entries(DROPIN)
    assert u["PrivateNetwork"] == ["yes"] and d["PrivateNetwork"] == ["yes"]
    assert u["JoinsNamespaceOf"] == ["pigpiod.service"]
    assert " -f" in d["ExecStart"][1]                    # no world-writable /dev/pigpio pipe
    assert u["CapabilityBoundingSet"] == [""] and u["DevicePolicy"] == ["closed"]
    assert {v.split()[0] for v in u["DeviceAllow"]} >= {"/dev/spidev0.0", "/dev/i2c-1", "/dev/gpiomem"}
    assert u["IPAddressDeny"] == ["any"] and "RestrictAddressFamilies" in u
    assert u["SystemCallFilter"][0] == "@system-service"
    assert all(u[k] == ["yes"] for k in ("ProtectKernelTunables", "ProtectKernelModules", "ProtectKernelLogs"))


@pytest.mark.skipif(shutil.which("systemd-analyze") is None, reason="systemd-analyze not installed")
def test_systemd_analyze_security_rates_the_unit_3_or_better(tmp_path):
    unit = tmp_path / "flightctl.service"
    unit.write_text(UNIT.read_text().replace("/opt/flightctl/venv/bin/flightctl", "/bin/true"))
    r = subprocess.run(["systemd-analyze", "security", "--offline=yes", str(unit)], capture_output=True,
                       text=True, timeout=60)
    if "--offline" in r.stderr and "unrecognized" in r.stderr:
        pytest.skip("this systemd-analyze cannot rate a unit file offline")
    line = [l for l in r.stdout.splitlines() if "Overall exposure level" in l][0]
    assert float(line.split(":")[1].split()[0]) <= 3.0, line
