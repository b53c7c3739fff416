"""The figures of one log that the fleet report follows across flights, taken from its diagnosis (the
static tier, sim/identify/static/, and the dynamic tier where it ran), each with its standard error:

- `share_1`..`share_4`: each motor's share of the hover thrust (the four's mean is 1; static/hover.py,
  block-jackknife errors);
- `battery_ohm`: the pack's internal resistance (static/battery.py, block-jackknife error), where the
  log has the current and the fit passed its physical checks;
- `vibration`: the vibration level, the length of the per-axis means (x, y, z; static/vibration.py:
  ArduPilot's VIBE or the accelerometer's spread in hover), its error by the delta method;
- `timing_s`: the commands' timing the dynamic tier identified the vehicle at (base_model.timing), where
  the log was fast enough for it; no standard error (the trend test then takes the flights' own scatter).

Also the rates the log was written at, and what the dynamic tier needs (`timing_needs`), so that the
report can say why a vehicle has no timing series. Every value is a plain float or None (JSON)."""
from __future__ import annotations

import math

SERIES = ("share_1", "share_2", "share_3", "share_4", "battery_ohm", "vibration", "timing_s")


def _pair(v, e) -> list | None:
    if v is None or not math.isfinite(float(v)):
        return None
    return [float(v), float(e) if e is not None and math.isfinite(float(e)) else None]


def figures(report: dict | None) -> dict:
    """{series: [value, stderr] or None, "rates": {...} or None, "tier": ...} of one log's report."""
    from flightctl.sim.identify.diagnose.dataset import DYNAMIC_MIN_HZ
    out = {k: None for k in SERIES}
    if not report:
        return {**out, "rates": None, "tier": None, "timing_needs": None}
    st = report.get("static") or {}
    m = st.get("motors")
    if m:
        for i, (s, e) in enumerate(zip(m["share"], m["stderr"])):
            if i < 4:
                out[f"share_{i + 1}"] = _pair(s, e)
    r = (st.get("battery") or {}).get("resistance")
    if r and r.get("passed"):
        out["battery_ohm"] = _pair(r["ohm"], r["stderr"])
    v = st.get("vibration")
    if v:
        mean = [v["mean"][a] for a in "xyz"]
        sd = [v["stderr"][a] or 0.0 for a in "xyz"]
        if all(x is not None for x in mean):
            size = math.sqrt(sum(x * x for x in mean))
            err = math.sqrt(sum((x * e) ** 2 for x, e in zip(mean, sd))) / size if size > 0 else 0.0
            out["vibration"] = _pair(size, err)
    timing = (report.get("base_model") or {}).get("timing")
    if report.get("tier") != "static" and timing:
        out["timing_s"] = _pair(timing["value"], None)
    needs = None if out["timing_s"] else (f"the dynamic tier needs the gyro and accelerometer at {DYNAMIC_MIN_HZ:g} Hz or more"
                                          + (f" (this log: {st['rates']['sensors_hz']:g} Hz)" if st.get("rates") else ""))
    return {**out, "rates": st.get("rates"), "tier": report.get("tier", "dynamic"), "timing_needs": needs}
