"""The blackbox header's scales read and applied (sim/logs/bbfields.py, as Betaflight's Blackbox Explorer
applies them): `gyro.scale` (Cleanflight and Betaflight before 3.1 log the gyro's raw counts: a 2016
Cleanflight log read without it has its gyro 16.4 times too large), `acc_1G`, `vbatscale` and
`currentMeter` (ADC counts before Betaflight 3.1). No public Cleanflight log with a license for tests was
found (docs/log-import.md): a real Betaflight 4.2 log (LOG00037.BFL, ../shared/data/real/flights) has its
header rewritten with scales drawn at random, as an older firmware would write them over the same counts,
and every stream must come out scaled as that header says."""
from __future__ import annotations

import struct

import numpy as np
import pytest

from flightctl.sim.logs import each_log
from helpers.real import FLIGHTS, need

pytest.importorskip("orangebox")


def _header(data: bytes, name: str, value: str) -> bytes:
    """`H name:...` set to value (the line replaced, or added after the product line)."""
    lines = data.split(b"\n")
    key = f"H {name}:".encode()
    for i, line in enumerate(lines):
        if line.startswith(key):
            lines[i] = key + value.encode()
            return b"\n".join(lines)
    raise AssertionError(name)


def _rename(data: bytes, old: str, new: str) -> bytes:
    assert f"\nH {old}:".encode() in data
    return data.replace(f"\nH {old}:".encode(), f"\nH {new}:".encode(), 1)


@pytest.mark.parametrize("seed", [2016, 35])
def test_a_header_with_an_old_firmwares_scales_is_applied(tmp_path, seed):
    src = need(FLIGHTS / "betaflight" / "LOG00037.BFL")
    data = src.read_bytes()
    (e0,) = each_log(str(src))
    t0 = e0.table
    rng = np.random.default_rng(seed)
    lsb = float(rng.uniform(4.0, 70.0))                   # counts per deg/s (an MPU-6050 at 2000 deg/s: 16.4)
    scale = struct.unpack("<f", struct.pack("<f", 1.0 / lsb))[0]
    one_g = int(rng.integers(256, 8192))
    vdiv = int(rng.integers(80, 160))
    offset, per10a = int(rng.integers(-200, 200)), int(rng.integers(100, 800))
    old = _rename(data, "gyro_scale", "gyro.scale")       # Cleanflight's and Betaflight 2-3.0's names
    old = _header(old, "gyro.scale", f"0x{struct.unpack('<I', struct.pack('<f', scale))[0]:08x}")
    old = _header(old, "acc_1G", str(one_g))
    old = _rename(old, "vbat_scale", "vbatscale")
    old = _header(old, "vbatscale", str(vdiv))
    old = _rename(old, "currentSensor", "currentMeter")
    old = _header(old, "currentMeter", f"{offset},{per10a}")
    fw = t0.meta["firmware"]
    old = old.replace(fw.encode(), fw.replace("4.2.", "3.0.").encode(), 1)   # counts, not volts and amps
    path = tmp_path / "old.bfl"
    path.write_bytes(old)
    (e,) = each_log(str(path))
    t = e.table
    assert t["t"].size == t0["t"].size
    for a in "xyz":        # the same counts: 1 deg/s was one count, now 1 / lsb deg/s
        np.testing.assert_allclose(t[f"gyro_{a}"], t0[f"gyro_{a}"] * scale, rtol=2e-5, atol=1e-8)
        np.testing.assert_allclose(t[f"acc_{a}"], t0[f"acc_{a}"] * 2048.0 / one_g, rtol=2e-5, atol=1e-8)
    assert "gyro.scale" not in t0.meta["gyro_source"] and "deg/s per count" in t.meta["gyro_source"]
    # the battery: each 0.01 V count now an ADC count through the divider vbatscale / 10
    counts = t0["battery_v"] / 0.01
    volts = counts * 3.3 * vdiv / 10.0 / 4095.0
    ok = np.isfinite(t0["battery_v"]) & (volts > 0.5)
    np.testing.assert_allclose(t["battery_v"][ok], volts[ok], rtol=2e-5)
    # the current: each 0.01 A count an ADC count, (mV - offset) x 10 / (mV per 10 A)
    counts = t0["current"] / 0.01
    amps = (counts * 3300.0 / 4095.0 - offset) * 10.0 / per10a
    ok = np.isfinite(t0["current"])
    assert ok.sum() > 1000
    np.testing.assert_allclose(t["current"][ok], amps[ok], rtol=2e-5, atol=1e-5)
