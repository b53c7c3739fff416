"""The simulated MPU-9250 read after a gap (a stalled or late loop): its gyro is the vehicle's rate with
the chip's noise, not a word at full scale. The frame's broadband noise is high-passed per read with a gain
that keeps its rms per read (sim/world/imu.py, `chip_frame`); a read many periods after the last has a
gain of about 1/a, and the filter's state, held in the last read's gain, is rescaled to the new one. Before
that, a 50-100 ms stall in the air left the state some hundreds of times too large, the next read's gyro at
full scale, the driver refusing it as an impossible jump, and a bank flown into the stall crashed.
The stall's time and length are drawn from a seeded generator; the flight is told only the fault."""
from __future__ import annotations

import csv
import random

from flightctl.cli import main as cli_main

MAX_RATE_JUMP = 1.0     # rad/s between two reads 2.2 ms apart: a banking vehicle's rate moves by a few hundredths


def test_the_gyro_after_a_stall_in_the_air_is_the_rate_not_full_scale(tmp_path, capsys):
    rng = random.Random(4909)
    at, ms = round(rng.uniform(7.9, 8.1), 3), round(rng.uniform(50.0, 100.0), 1)   # into step_roll's bank at 8 s
    log = tmp_path / "f.csv"
    code = cli_main(["sim", "step_roll", "--params", "paper-as-flown", "--log", str(log), "--no-plot",
                     "--fault", f"cpu_stall:at={at},ms={ms}"])
    out = capsys.readouterr().out
    assert code == 0, out
    assert "loop stalled" in out
    assert "impossible jump" not in out and "IMU saturated" not in out, out
    rows = [r for r in csv.DictReader(line for line in open(log) if not line.startswith("#"))]
    t = [float(r["t"]) for r in rows]
    gap = next(i for i in range(1, len(t)) if t[i] - t[i - 1] > 0.9 * ms / 1000.0)
    for axis in ("gyro_x", "gyro_y", "gyro_z"):
        g = [float(r[axis]) for r in rows[gap - 1:gap + 30]]
        jumps = [abs(b - a) for a, b in zip(g[1:], g[2:])]     # the reads after the gap, each against the last
        assert max(jumps) < MAX_RATE_JUMP, (axis, at, ms, max(jumps))
