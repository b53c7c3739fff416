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
    for step in ("raspi-config nonint do_spi 0", "raspi-config nonint do_i2c 0",
                 "--groups gpio,spi,i2c flightctl", f"python3 -m venv {tmp_path / 'opt'}/venv",
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
