"""The static tier of `flightctl diagnose` (docs/measured-data.md, "Tiers"; docs/diagnose.md, "Static tier"):
what a flight logged at 5 Hz or more answers without following the vehicle's motion, for any log whose
attitude, motor outputs and battery were logged (ArduPilot's default logging: IMU 25 Hz, RCOU 10 Hz).

One module per finding, each importing only those before it: `curve` (the thrust curve the commands are
read through, and which one), `blocks` (the hover rows and their blocks: jackknife and drift), `hover`
(hover throttle and thrust margin, each motor's share and its drift, centre of mass against weak motor
against yaw trim), `battery` (sag and internal resistance), `vibration` (VIBE and clips, or the
accelerometer's spread in hover), `pinned` (a motor at full command while the vehicle tips toward it).
Every finding carries its size, its uncertainty and its physical check. This module runs them on the logs
diagnose has read (`static_tier`) and holds the report of a log that reached the static tier only (`StaticOnly`)."""
from __future__ import annotations

import numpy as np

from flightctl.sim.diagnose.data import BARO_CLIMB_M
from flightctl.sim.diagnose.rates import faster
from flightctl.sim.diagnose.static.battery import battery
from flightctl.sim.diagnose.static.blocks import MIN_HOVER_S, Blocks, body_z_force, hover_mask
from flightctl.sim.diagnose.static.centre import centre_text, from_speeds, one as centre_of_mass
from flightctl.sim.diagnose.static.curve import of_log, speed_curve
from flightctl.sim.diagnose.static.hover import pattern, shares, speed_gains, throttle
from flightctl.sim.diagnose.static.pinned import motor_at_full
from flightctl.sim.diagnose.static.vibration import VIBE_COLUMNS, vibration

STATIC_MIN_HZ = 5.0           # the attitude and the motor outputs at this rate or more (docs/measured-data.md)
STATIC_COLUMNS = VIBE_COLUMNS  # the columns the static tier reads beside the contract's and `current`
WHAT = ("the static tier: what the flight's hover and battery show at any rate of 5 Hz or more (hover throttle and "
        "thrust margin, each motor's share of the hover thrust and its drift, centre of mass against weak motor "
        "against yaw trim, battery sag and internal resistance, vibration, a motor at full command while the vehicle "
        "tips toward it), each with its size, its block-jackknife "
        "standard error and its physical check")


def _rate(table, key: str, t: np.ndarray) -> float:
    try:
        return float(table.meta[key])
    except (KeyError, ValueError):
        return 1.0 / float(np.median(np.diff(t)))


def static_tier(tables, files, a, progress=lambda *x: None) -> dict | None:
    """The static findings of the airborne logs `files` (diagnose's `_files`, read from `tables`), or
    None when they answer none of them (too slow, maybe never a flight by the barometer, no hover, no
    battery, no vibration logged)."""
    by_path = {t.path: t for t in tables}
    tabs = [by_path[f.path] for f in files]
    rates = {"sensors_hz": round(min(_rate(t, "rate_hz", f.t) for t, f in zip(tabs, files)), 1),
             "motors_hz": round(min(_rate(t, "motor_rate_hz", f.t) for t, f in zip(tabs, files)), 1)}
    if min(rates.values()) < STATIC_MIN_HZ:
        progress(f"static tier: not reached (rates {rates}: {STATIC_MIN_HZ:g} Hz or more needed)")
        return None
    if all(f.baro_climb is not None and f.baro_climb < BARO_CLIMB_M for f in files):
        progress(f"static tier: not reached (the barometer rose less than {BARO_CLIMB_M:g} m while the motors ran: "
                 "maybe never a flight)")
        return None
    layout = files[0].layout
    line = speed_curve(files)
    curve = of_log(tabs[0], a, files[0].foreign, line)
    masks = [hover_mask(f) for f in files]
    hv = Blocks(files, masks)
    air = Blocks(files, [f.airborne for f in files])
    out = {"what": WHAT, "rates": rates, "hover_s": round(hv.seconds, 1), "airborne_s": round(air.seconds, 1),
           "thrust_curve": curve.source, "layout": {"x": list(layout.x), "y": list(layout.y), "spin": list(layout.spin),
                                                    "unit": layout.unit, "source": layout.source},
           "not_judged": {}}
    if hv.enough and hv.seconds >= MIN_HOVER_S:
        c = hv.rows([curve.thrust(f.P) for f in files])
        force = [body_z_force(f) for f in files]
        out["hover"] = throttle(hv, c, hv.rows([f.P for f in files]), hv.rows([z for z, _ in force])[0], curve)
        out["hover"]["acc_z_source"] = "; ".join(dict.fromkeys(w for _, w in force))
        out["motors"], m, _ = shares(hv, c)
        out["pattern"] = pattern(hv, m, layout, speed_gains(files, hv, line), from_speeds(files, hv, layout))
        progress(f"static tier: hover {hv.seconds:.1f} s, thrust share {out['hover']['thrust_share']}, "
                 f"motor shares {out['motors']['share']}, pattern: {out['pattern']['verdict']}")
    else:
        why = (f"{hv.seconds:.1f} s of hover (airborne, all motors running below full command, body rates under "
               f"0.5 rad/s, specific force within 25 % of g): at least {MIN_HOVER_S:g} s needed")
        for k in ("hover", "motors", "pattern"):
            out["not_judged"][k] = why
    bat = battery(files, [t["current"] if "current" in t else None for t in tabs])
    if bat is None:
        out["not_judged"]["battery"] = "no battery voltage in the log"
    else:
        out["battery"] = bat
        r = bat.get("resistance")
        progress("static tier: battery " + (f"R = {1e3 * r['ohm']:.1f} +- {1e3 * r['stderr']:.2g} mOhm" if r else
                                            f"{bat['v_range']} V, " + bat["without_current"].split(":")[0]))
    vib = vibration(tabs, files, air if air.enough else None, hv)
    if vib is None:
        out["not_judged"]["vibration"] = ("neither VIBE nor enough hover to measure the accelerometer's spread" if
                                          all(f.imu for f in files) else "neither VIBE nor an accelerometer in the log")
    else:
        out["vibration"] = vib
    out["motor_at_full"] = full = motor_at_full(files, tabs, rates["motors_hz"], faster(tabs))
    progress(f"static tier: motor at full command: {full['verdict']}")
    if not any(k in out for k in ("hover", "battery", "vibration")) and not full["spans"]:
        return None
    return _finite(out)


def _finite(x):
    """The findings with every non-finite number as None (the report is strict JSON)."""
    if isinstance(x, dict):
        return {k: _finite(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_finite(v) for v in x]
    if isinstance(x, (float, np.floating)):
        return float(x) if np.isfinite(x) else None
    return x


def tier_why(static: dict | None) -> str:
    """The report's `tier_why` of a log that reached the dynamic tier."""
    return ("the gyro, accelerometer and motor outputs were logged fast enough for the dynamic tier; "
            + ("the static tier too (`static`)" if static else "the static tier answered nothing here (`notes`)"))


class StaticOnly:
    """The diagnosis of a log that reached the static tier only: the contract's keys (cause "none", no
    candidates, the dynamic tier's refusal as the reason), the static findings under `static`."""
    cause = "none"
    parameters: dict = {}

    def __init__(self, files, static: dict, notes: list[str], why: str):
        self.files, self.static, self.notes, self.why = files, static, notes, why

    @classmethod
    def instead_of(cls, e: Exception, tables, files, a, notes: list[str], progress, accepted=None) -> "StaticOnly":
        """The static tier's report in place of the dynamic tier's refusal `e`; `e` raised again when
        the static tier answers nothing (the log answers no question)."""
        static = static_tier(tables, files, a, progress)
        if static is None:
            raise e
        if accepted is not None:
            accepted()
        return cls(files, static, notes, str(e).split(": ", 1)[-1])

    def report(self) -> dict:
        from flightctl.sim.causes.battery_sag import pack_range
        v = pack_range(self.files)
        return {"cause": "none", "parameters": {}, "rmse_base": None, "rmse_extended": None, "gain": None,
                "metric": "none: the dynamic tier did not run (`tier_why`)", "candidates": [], "causes": [],
                "not_judged": [{"cause": "every candidate", "why": self.why}], "not_physical": [],
                "tier": "static", "tier_why": f"the dynamic tier did not run: {self.why}",
                "base_model": {"identified": False, "what": "none: the dynamic tier did not run"},
                "data": {"files": [f.path for f in self.files],
                         "airborne_s": round(sum(f.airborne.sum() * float(np.median(np.diff(f.t))) for f in self.files), 2),
                         "battery_v": None if v is None else [round(x, 2) for x in v]},
                "static": self.static, "centre_of_mass": centre_of_mass(None, self.static),
                "notes": list(dict.fromkeys(self.notes))}


def text(st: dict) -> str:
    """The static findings as the text report's lines."""
    L = [f"  static tier ({st['hover_s']:.1f} s of hover in {st['airborne_s']:.1f} s airborne; sensors "
         f"{st['rates']['sensors_hz']:g} Hz, motors {st['rates']['motors_hz']:g} Hz; thrust curve: {st['thrust_curve']}):"]
    L.append(f"    frame: {st['layout']['source']}")
    h = st.get("hover")
    if h:
        L.append(f"    hover: command {h['command']:.3f} +- {h['command_stderr']:.2g} of the range, thrust "
                 f"{100 * h['thrust_share']:.1f} +- {100 * h['thrust_share_stderr']:.2g} % of full, thrust-to-weight "
                 f"{h['thrust_to_weight']} +- {h['thrust_to_weight_stderr']}; {h['check']}")
        m = st["motors"]
        L.append("    motor shares of the hover thrust: " + ", ".join(
            f"{i + 1}: {s:.3f} +- {e:.2g} (drift {d:+.4f} +- {de:.2g}/min)" for i, (s, e, d, de) in
            enumerate(zip(m["share"], m["stderr"], m["drift_per_min"], m["drift_stderr_per_min"])))
            + (f"; drifting: motor {', '.join(map(str, m['drifting']))}" if m["drifting"] else "; none drifts"))
        p = st["pattern"]
        L.append(f"    pattern: {p['verdict']}: {p['why']}")
        if p["rotor_speeds"]:
            L.append(f"    with the rotor speeds: {p['rotor_speeds']['verdict']}: {p['rotor_speeds']['why']}")
            if c := p["rotor_speeds"].get("com"):
                L.append(f"    centre of mass by the rotor speeds (Omega^2 in hover): ({c['dx']:+.4f} +- {c['stderr'][0]:.2g}, "
                         f"{c['dy']:+.4f} +- {c['stderr'][1]:.2g}) {c['unit']}")
        else:
            L.append(f"    {p['without_speeds']}")
    b = st.get("battery")
    if b:
        r = b.get("resistance")
        line = f"    battery: {b['v_range'][0]:.2f}-{b['v_range'][1]:.2f} V" + (f" ({b['cells']} cells)" if b["cells"] else "")
        if r:
            line += (f"; internal resistance {1e3 * r['ohm']:.1f} +- {1e3 * r['stderr']:.2g} mOhm, E0 {r['E0']:.2f} V, "
                     f"sag {r['sag_at_max_v']:.2f} V at {r['current_max_a']:.0f} A; {r['check']}")
        else:
            line += f"; {b['without_current']}"
        L.append(line)
    v = st.get("vibration")
    if v:
        L.append(f"    vibration ({v['source']}): " + ", ".join(f"{a} {v['mean'][a]:.3g} +- {v['stderr'][a]:.2g}"
                                                             for a in "xyz") + f" m/s^2; {v['check']}")
    if full := st.get("motor_at_full"):
        L.append(f"    motor at full command: {full['verdict']}" + (f"; {full['rate']}" if full["rate"] else ""))
    for k, why in st["not_judged"].items():
        L.append(f"    {k}: not judged: {why}")
    return "\n".join(L)


def summary(st: dict) -> str:
    """One line of the static findings (the corpus table's cell)."""
    out = []
    if h := st.get("hover"):
        out.append(f"hover {100 * h['thrust_share']:.0f} % of full thrust (T/W {h['thrust_to_weight']})")
        m = st["motors"]
        out.append("shares " + "/".join(f"{v:.2f}" for v in m["share"])
                   + (f", motor {', '.join(map(str, m['drifting']))} drifting" if m["drifting"] else ""))
        out.append(f"pattern: {st['pattern']['verdict']}")
    if b := st.get("battery"):
        r = b.get("resistance")
        out.append(f"R {1e3 * r['ohm']:.1f} +- {1e3 * r['stderr']:.2g} mOhm" + ("" if r["passed"] else " (check failed)")
                   if r else f"battery {b['v_range'][0]:.1f}-{b['v_range'][1]:.1f} V, " + b["without_current"].split(":")[0])
    if v := st.get("vibration"):
        out.append(("VIBE" if v["clips"] is not None else "acc spread") + " "
                   + "/".join(f"{v['mean'][a]:.3g}" for a in "xyz") + " m/s^2"
                   + (f", {v['clips']} clips" if v["clips"] is not None else ""))
    if (full := st.get("motor_at_full")) and full["named"]:
        s = next(x for x in full["spans"] if x["motor"] == full["named"] and not x["tumbling"])
        out.append(f"motor {s['motor']} at full command from {s['start_s']:.1f} s while it tipped toward it (lost?)")
    return "; ".join(out)


def static_text(rep: dict) -> str:
    """The text report of a log that reached the static tier only."""
    L = [f"flightctl diagnose: {', '.join(rep['data']['files'])}", f"  tier: static ({rep['tier_why']})",
         text(rep["static"])]
    if rep.get("centre_of_mass"):
        L.append(centre_text(rep["centre_of_mass"]))
    L.append("  verdict: none (no dynamic chain ran)")
    L += [f"  note: {n}" for n in rep["notes"]]
    return "\n".join(L) + "\n"
