"""Vibration in the static tier.

Where the log has ArduPilot's VIBE (`vibe_x`, `vibe_y`, `vibe_z`: the standard deviation of the primary
accelerometer about its slow part, m/s^2, and `clip`: the count of accelerometer samples at the
sensor's limit, summed over the IMUs, cumulative), their levels in the air against ArduPilot's own
guidance (https://ardupilot.org/copter/docs/common-measuring-vibration.html: below 30 m/s^2 normally
acceptable, above 60 nearly always a problem for position and altitude hold; clipping ideally zero,
fewer than 100 likely fine, a count that keeps rising a serious vibration problem). Otherwise the
accelerometer's spread in hover about its 1 s moving mean, per axis, at the log's rate: what the IMU's
own low-pass and the logging rate leave of the vibration, a floor of it, not ArduPilot's VIBE.
Means with their block-jackknife standard errors (`blocks.Blocks`).
"""
from __future__ import annotations

import numpy as np

from flightctl.sim.diagnose.static.blocks import Blocks, moving_mean

VIBE_COLUMNS = ("vibe_x", "vibe_y", "vibe_z", "clip")
ACCEPTABLE, PROBLEM = 30.0, 60.0     # m/s^2: ArduPilot's guidance (the module's docstring)
CLIPS_OK = 100
MOVING_S = 1.0


def _level(peak: float) -> str:
    if peak < ACCEPTABLE:
        return f"below {ACCEPTABLE:g} m/s^2: normally acceptable"
    if peak < PROBLEM:
        return f"{ACCEPTABLE:g}-{PROBLEM:g} m/s^2: may give position and altitude hold problems"
    return f"above {PROBLEM:g} m/s^2: nearly always gives position and altitude hold problems"


def vibration(tables, files, airborne: Blocks | None, hover: Blocks | None) -> dict | None:
    """{source, level per axis with its standard error, clips, check} (the module's docstring)."""
    if all(all(c in t for c in VIBE_COLUMNS[:3]) and np.isfinite(t["vibe_x"]).any() for t in tables) and airborne:
        v = airborne.rows([np.vstack([t[c] for c in VIBE_COLUMNS[:3]]) for t in tables])
        m = airborne.means(v)
        mean, sd, _ = airborne.jackknife(m, lambda x: x)
        p95 = np.nanpercentile(v, 95, axis=1)
        clips = []
        for t in tables:
            c = t["clip"] if "clip" in t else np.full(len(t["t"]), np.nan)
            c = c[np.isfinite(c)]
            clips.append(float(c[-1] - c[0]) if c.size else 0.0)
        clip = int(round(sum(clips)))
        peak = float(np.max(p95))
        return {"source": "VIBE (ArduPilot: the accelerometer's standard deviation, m/s^2) in the air",
                "mean": {a: round(float(x), 2) for a, x in zip("xyz", mean)},
                "stderr": {a: float(f"{e:.2g}") for a, e in zip("xyz", sd)},
                "p95": {a: round(float(x), 2) for a, x in zip("xyz", p95)},
                "clips": clip,
                "check": (f"the 95th percentile's largest axis {peak:.1f} m/s^2, {_level(peak)}; {clip} accelerometer "
                          "clips in the log" + (" (fewer than 100: likely fine)" if clip < CLIPS_OK else
                                                ": many, a vibration problem to fix")),
                "acceptable": bool(peak < PROBLEM and clip < CLIPS_OK),
                "physical": _physical(v, tables)}
    if hover is None or not hover.enough or not all(f.imu for f in hover.files):
        return None
    spread = []
    for f in hover.files:
        spread.append((f.acc - moving_mean(f.t, f.acc, MOVING_S)) ** 2)
    m = hover.means(hover.rows(spread))
    rms, sd, _ = hover.jackknife(m, np.sqrt)
    fs = 1.0 / hover.dt
    return {"source": (f"the accelerometer's spread in hover about its {MOVING_S:g} s moving mean at the log's "
                       f"{fs:.0f} Hz (no VIBE in the log): what the IMU's low-pass and the rate leave, a floor of "
                       "the vibration"),
            "mean": {a: round(float(x), 3) for a, x in zip("xyz", rms)},
            "stderr": {a: float(f"{e:.2g}") for a, e in zip("xyz", sd)},
            "p95": None, "clips": None,
            "check": f"largest axis {float(rms.max()):.2f} m/s^2 rms over {hover.seconds:.0f} s of hover",
            "acceptable": None, "physical": "a spread of measured accelerations, finite and non-negative: passed"}


def _physical(v: np.ndarray, tables) -> str:
    """VIBE levels finite and non-negative, each clip count never falling."""
    ok = bool(np.all(v[np.isfinite(v)] >= 0))
    for t in tables:
        c = t["clip"][np.isfinite(t["clip"])] if "clip" in t else np.array([])
        ok &= bool(np.all(np.diff(c) >= 0))
    return "levels non-negative, clip counts never falling: " + ("passed" if ok else "failed")
