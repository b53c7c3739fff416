"""The figures of one log that the fleet report follows across flights, taken from its diagnosis (the
static tier, sim/diagnose/static/, and the dynamic tier where it ran), each with its standard error:

- `share_1`..`share_4`: each motor's share of the hover thrust (the four's mean is 1; static/hover.py,
  block-jackknife errors);
- `battery_ohm`: the pack's internal resistance (static/battery.py, block-jackknife error), where the
  log has the current and the fit passed its physical checks;
- `vibration`: the vibration level, the length of the per-axis means (x, y, z; static/vibration.py:
  ArduPilot's VIBE or the accelerometer's spread in hover), its error by the delta method;
- `timing_s`: the commands' timing the dynamic tier identified the vehicle at (base_model.timing), where
  the log was fast enough for it; no standard error (the trend test then takes the flights' own scatter).

Also the causes the log's own diagnosis names (`named`: the dynamic tier's chain, each with its
parameters, and the static tier's pattern of the shares where it names a weak motor, with its thrust
scale), which the fleet report carries up beside its trend tests; the rates the log was written at; and
why the log gives no timing (`timing_needs`: the dynamic tier's own reason when it did not run, with the
log's own figures; or that it ran on this project's airframe, which has no timing to identify), so that
the report can say why a vehicle has no timing series. Every value is a plain float or None (JSON)."""
from __future__ import annotations

import math

SERIES = ("share_1", "share_2", "share_3", "share_4", "battery_ohm", "vibration", "timing_s")


def _pair(v, e) -> list | None:
    if v is None or not math.isfinite(float(v)):
        return None
    return [float(v), float(e) if e is not None and math.isfinite(float(e)) else None]


def figures(report: dict | None) -> dict:
    """{series: [value, stderr] or None, "rates": {...} or None, "tier": ...} of one log's report."""
    out = {k: None for k in SERIES}
    if not report:
        return {**out, "rates": None, "tier": None, "timing_needs": None, "named": []}
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
    return {**out, "rates": st.get("rates"), "tier": report.get("tier", "dynamic"),
            "timing_needs": None if out["timing_s"] else _no_timing(report), "named": named(report)}


def _no_timing(report: dict) -> str:
    """Why a log gives no timing: the reason its diagnosis gave, never a rate it met."""
    if report.get("tier") == "static":
        why = report.get("tier_why") or "the dynamic tier did not run"
        return why.removeprefix("the dynamic tier did not run: ")
    if not (report.get("base_model") or {}).get("identified", True):
        return ("the dynamic tier ran on this project's airframe (its timing is the model's, not identified from the "
                "flight): a timing the log contradicts is a cause its own diagnosis names (actuation_delay, motor_lag)")
    return "the dynamic tier identified no timing from this flight"


def named(report: dict) -> list[dict]:
    """The causes a log's diagnosis names: {"cause", "parameters", "tier"} each (the module's docstring)."""
    out = [{"cause": c["cause"], "parameters": {k: _plain(v) for k, v in (c.get("parameters") or {}).items()},
            "tier": "dynamic"} for c in report.get("causes") or [] if c.get("cause") not in (None, "none")]
    p = ((report.get("static") or {}).get("pattern") or {})
    verdict = p.get("verdict") or ""
    if verdict.startswith("weak motor ") and not any(c["cause"] == "motor_weak" for c in out):
        fit = next((h for h in p.get("hypotheses") or [] if h["hypothesis"] == verdict), {})
        out.append({"cause": "motor_weak", "parameters": {"motor": int(verdict.split()[-1]),
                                                          "scale": _plain(fit.get("thrust_scale"))}, "tier": "static"})
    return out


def _plain(v):
    try:
        return float(v) if not isinstance(v, (int, str)) and v is not None else v
    except (TypeError, ValueError):
        return str(v)
