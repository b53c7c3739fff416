"""The fleet report (`flightctl diagnose --corpus DIR --fleet REPORT`): from the results table's rows,
the vehicles (`grouping`), each one's series tested for a change as findings (`trends`, Holm-corrected
over every finding of the fleet), what each vehicle's logs name on their own (`carried`, beside the trend
test), written as tables (REPORT/fleet.md), as JSON (REPORT/fleet.json) and a figure per vehicle
(REPORT/vehicle-N.png, `figure`).

A vehicle's motor shares sum to four: a motor that weakens takes a larger share (through its command)
and the three others a smaller one each, so the four series of a vehicle are one finding (FINDINGS): the
motor whose share changed most (the largest LR) is named, and the others that moved with it (an LR past
the onset set's bound, their onset in its set) are said beside it. A change is
named only when Holm's correction keeps it (trends.ALPHA family-wise) and its size passes a physical
check: for a motor, the thrust it gives for its command after the change against before (from its
share's ratio, `share_scale`) within motor_weak.SCALE_RANGE (a motor still able to hold its share of
the hover); for the battery, a resistance after the change within the static tier's R_CELL times the
cell count the logs declare (or 14 cells, the most this project reads, when they declare none).
"""
from __future__ import annotations

import json
from pathlib import Path

from flightctl.sim.diagnose.fleet.grouping import Vehicle, group
from flightctl.sim.diagnose.fleet.trends import ALPHA, DRAWS, LR_SET, MIN_FLIGHTS, Change, Fit, calibrate, correct

HINGED = ("battery_ohm", "vibration")       # may rise gradually: step and hinge both tried
MOST_CELLS = 14
LABEL = {"share_1": "motor 1's share of the hover thrust", "share_2": "motor 2's share of the hover thrust",
         "share_3": "motor 3's share of the hover thrust", "share_4": "motor 4's share of the hover thrust",
         "battery_ohm": "battery internal resistance (ohm)", "vibration": "vibration level (m/s^2)",
         "timing_s": "the commands' timing (s, the dynamic tier's)"}


def _series(v: Vehicle, name: str) -> tuple[list[int], list[float], list[float | None]]:
    at, y, se = [], [], []
    for i, row in enumerate(v.flights):
        f = (row.get("figures") or {}).get(name)
        if f is not None:
            at.append(i)
            y.append(f[0])
            se.append(f[1] if f[1] is not None else float("nan"))
    return at, y, se


def _check(name: str, c: Change, v: Vehicle) -> tuple[bool, str]:
    from flightctl.sim.causes.motor_weak import SCALE_RANGE
    from flightctl.sim.diagnose.static.battery import R_CELL
    if name.startswith("share_"):
        scale = share_scale(c.after / c.before) if c.before > 0 and c.after > 0 else float("inf")
        ok = SCALE_RANGE[0] <= scale <= SCALE_RANGE[1]
        return ok, (f"its thrust for its command about {scale:.3f} of before (from its share's ratio), within "
                    f"{SCALE_RANGE[0]:g}-{SCALE_RANGE[1]:g}: " + ("passed" if ok else "failed"))
    if name == "battery_ohm":
        cells = [int((r.get("meta") or {}).get("battery_cells") or 0) for r in v.flights]
        n = max(cells) if any(cells) else MOST_CELLS
        lo, hi = R_CELL[0] * n, R_CELL[1] * n
        ok = lo < c.after < hi
        return ok, (f"{1e3 * c.after:.1f} mOhm after it, within {1e3 * lo:.1f}-{1e3 * hi:.0f} mOhm ({n} cells x "
                    f"{1e3 * R_CELL[0]:g}-{1e3 * R_CELL[1]:g}): " + ("passed" if ok else "failed"))
    return True, "no physical bound (a level, not a cause)"


FINDINGS = (("motors", ("share_1", "share_2", "share_3", "share_4")), ("battery", ("battery_ohm",)),
            ("vibration", ("vibration",)), ("timing", ("timing_s",)))


def share_scale(ratio: float) -> float:
    """A motor's thrust for its command after a change against before, from its share's ratio after to
    before, its three siblings unchanged: the shares are of the commands' thrusts, mean one (followed.py), and
    a motor giving k of its thrust is commanded 1/k of it, so its share goes from 1 to (1/k) / ((1/k + 3) / 4)
    = 4 / (1 + 3 k): k = (4 / ratio - 1) / 3."""
    return (4.0 / ratio - 1.0) / 3.0


def build(rows: list[dict], mapping: dict[str, str] | None = None, draws: int = DRAWS) -> dict:
    """The fleet report as JSON (the module's docstring) of the results table's rows."""
    vehicles = group(rows, mapping)
    found = []                              # (vehicle index, finding, {series: (at, y, se, Fit)})
    for vi, v in enumerate(vehicles):
        for what, names in FINDINGS:
            fits = {}
            for name in names:
                at, y, se = _series(v, name)
                if at:
                    fits[name] = (at, y, se, Fit(y, se, hinge=name in HINGED))
            found.append((vi, what, fits))
    tested = []
    for _, _, fits in found:
        live = [f for *_, f in fits.values() if f.change is not None]
        t = None
        if live:
            t = Finding(*calibrate(live, draws))
            for f in live:
                f.change.p, f.change.draws = t.p, t.draws
        tested.append(t)
    named = correct(tested)
    for (_, _, fits), t in zip(found, tested):
        for *_, f in fits.values():
            if f.change is not None:
                f.change.p_adjusted = t.p_adjusted
    out = {"alpha": ALPHA, "draws": draws, "series_tested": sum(f.change is not None for *_, fits in found
                                                              for *_, f in fits.values()),
           "findings_tested": sum(t is not None for t in tested),
           "method": "per series: step (and, for the battery and the vibration, hinge) models with the flights' standard "
                     "errors and a spread between flights, the largest likelihood ratio over the split points; per finding "
                     "(a vehicle's four motor shares are one), the largest of its series', its p-value from series drawn "
                     "from the no-change fit with the flights' own errors and spread (a parametric bootstrap); Holm's "
                     "correction over every finding of the fleet (sim/diagnose/fleet/trends.py)",
           "vehicles": [], "changes": [], "per_log": []}
    for vi, v in enumerate(vehicles):
        series, tests = {}, {}
        for (wi, what, fits), t, ok in zip(found, tested, named):
            if wi != vi:
                continue
            tests[what] = None if t is None else {"p": t.p, "p_adjusted": t.p_adjusted, "draws": t.draws,
                                                  "named": bool(ok), "series": list(fits)}
            for name, (at, y, se, f) in fits.items():
                c = f.change
                series[name] = {"flight": at, "value": y, "stderr": [None if e != e else e for e in se],
                                "test": None if c is None else {**vars(c), "onset_flight": at[c.onset],
                                                                "onset_set_flights": [at[c.onset_set[0]], at[c.onset_set[1]]]},
                                "significant": bool(ok)}
        needs = next(((r.get("figures") or {}).get("timing_needs") for r in v.flights
                      if (r.get("figures") or {}).get("timing_needs")), None)
        per_log = carried(v)
        out["vehicles"].append({"vehicle": v.name, "identity": v.source, "order": v.order,
                                "flights": [{"index": i, "log": r["log"], "status": r["status"], "reason": r.get("reason"),
                                             "start_utc": (r.get("meta") or {}).get("start_utc")}
                                            for i, r in enumerate(v.flights)],
                                "series": series, "findings": tests, "per_log": per_log,
                                "timing": None if "timing_s" in series else needs})
        changes = _findings(v, series, tests)
        out["changes"] += changes
        for p in per_log:
            trend = next((c for c in changes if c["finding"] == p["finding"]), None)
            p["trend"] = _beside(p["finding"], trend, tests, series)
            out["per_log"].append({"vehicle": v.name, **p})
    return out


def _beside(finding: str, trend: dict | None, tests: dict, series: dict) -> str:
    """What the trend test says of the finding a per-log cause sits beside."""
    if trend:
        return f"the trend test names {trend['what']} from flight {trend['onset_flight'] + 1}"
    if tests.get(finding):
        return f"the trend test does not name it (its finding's Holm-adjusted p = {tests[finding]['p_adjusted']:.2g})"
    names = dict(FINDINGS).get(finding, ())
    if any(n in series for n in names):
        return f"the trend test does not name it (too few flights to test: fewer than {MIN_FLIGHTS})"
    return "no trend series follows it in these logs"


class Finding:
    """A finding's p-value (`calibrate`) and, set by `correct`, its Holm-adjusted one."""

    def __init__(self, p: float, draws: int):
        self.p, self.draws, self.p_adjusted = p, draws, 1.0


def carried(v: Vehicle) -> list[dict]:
    """What the vehicle's logs name on their own (figures.named), one entry per cause (and motor): the
    flights that name it, in the vehicle's order, and its parameter's values there."""
    by: dict[tuple, dict] = {}
    for i, row in enumerate(v.flights):
        for c in (row.get("figures") or {}).get("named") or []:
            par = c.get("parameters") or {}
            motor = int(par["motor"]) if par.get("motor") is not None else None
            key = (c["cause"], motor)
            e = by.setdefault(key, {"cause": c["cause"], "motor": motor, "flights": [], "logs": [], "parameters": [],
                                    "what": f"motor {motor} weak" if c["cause"] == "motor_weak" and motor else c["cause"],
                                    "finding": _finding_of(c["cause"])})
            if i not in e["flights"]:
                e["flights"].append(i)
                e["logs"].append(row["log"])
                e["parameters"].append({k: x for k, x in par.items() if k != "motor"})
    out = list(by.values())
    for e in out:
        e["first_flight"], e["first_log"] = e["flights"][0], e["logs"][0]
        e["of"] = sum(r["status"] == "diagnosed" for r in v.flights)       # of the flights diagnosed
    return sorted(out, key=lambda e: (e["first_flight"], e["what"]))


def _finding_of(cause: str) -> str:
    """The trend finding a per-log cause sits beside."""
    return {"motor_weak": "motors", "battery_sag": "battery", "actuation_delay": "timing", "motor_lag": "timing",
            "motor_dynamics": "timing", "gyro_lag": "timing"}.get(cause, cause)


def _findings(v: Vehicle, series: dict, tests: dict) -> list[dict]:
    found = []
    for what, names in FINDINGS:
        t = tests.get(what)
        if not t or not t["named"]:
            continue
        live = [(n, series[n]) for n in names if n in series and series[n]["test"]]
        name, s = max(live, key=lambda ns: ns[1]["test"]["lr"])
        lo, hi = s["test"]["onset_set_flights"]
        also = [n for n, o in live if n != name and o["test"]["lr"] > LR_SET and lo <= o["test"]["onset_flight"] <= hi]
        found.append({"finding": what, **_finding(v, name, s, also)})
    return [f for f in found if f["physical"]["passed"]]


def _finding(v: Vehicle, name: str, s: dict, also: list[str]) -> dict:
    t = s["test"]
    c = Change(**{k: t[k] for k in Change.__dataclass_fields__})
    ok, why = _check(name, c, v)
    k = t["onset_flight"]
    what = (f"motor {name[-1]}" if name.startswith("share_") else {"battery_ohm": "battery", "vibration": "vibration",
                                                                   "timing_s": "timing"}[name])
    return {"vehicle": v.name, "what": what, "series": name, "label": LABEL[name], "shape": t["shape"],
            "onset_flight": k, "onset_log": v.flights[k]["log"], "flights": len(v.flights),
            "onset_set_flights": t["onset_set_flights"], "before": t["before"], "after": t["after"],
            "size": t["size"], "size_se": t["size_se"], "p": t["p"], "p_adjusted": t["p_adjusted"],
            "with_it": also, "physical": {"passed": ok, "check": why}}


def _num(name: str, x: float, digits: str = ".4g") -> str:
    k, unit = {"battery_ohm": (1e3, " mOhm"), "timing_s": (1e3, " ms")}.get(name, (1.0, ""))
    return f"{k * x:{digits}}{unit}"


def _per_log_row(p: dict) -> str:
    flights = ", ".join(str(i + 1) for i in p["flights"])
    keys = sorted({k for par in p["parameters"] for k, x in par.items() if isinstance(x, (int, float))})
    size = "; ".join(f"{k} {_span([par[k] for par in p['parameters'] if isinstance(par.get(k), (int, float))])}"
                     for k in keys)
    return (f"| {p['vehicle']} | {p['what']} | {len(p['flights'])} of {p['of']}: {flights} | {p['first_log']} (flight "
            f"{p['first_flight'] + 1}) | {size} | {p['trend']} |")


def _logs(v: dict) -> str:
    """How many logs a vehicle has, how many were diagnosed, and why the others were not."""
    n, done = len(v["flights"]), sum(f["status"] == "diagnosed" for f in v["flights"])
    out = f"{n} log{'s' if n != 1 else ''}, {done} diagnosed"
    why: dict[str, int] = {}
    for f in v["flights"]:
        if f["status"] != "diagnosed":
            key = (f.get("reason") or f["status"]).split(":")[0]
            why[key] = why.get(key, 0) + 1
    return out + (" (not: " + "; ".join(f"{k}, {c}" for k, c in why.items()) + ")" if why else "")


def _span(xs: list[float]) -> str:
    lo, hi = min(xs), max(xs)
    return f"{lo:.3g}" if f"{lo:.3g}" == f"{hi:.3g}" else f"{lo:.3g}-{hi:.3g}"


def markdown(rep: dict) -> str:
    """The report's table of what changed (the trend tests'), what the logs name on their own, then each
    vehicle's flights and what was tested."""
    L = ["# Fleet report", "", f"{len(rep['vehicles'])} vehicles, {rep['series_tested']} series in "
         f"{rep['findings_tested']} findings tested (a vehicle's four motor shares are one finding); a change is named "
         f"when its finding's Holm-adjusted p-value is below {rep['alpha']:g} (family-wise over the fleet's findings) and "
         f"its size passes its physical check; flights are counted from 1 in each vehicle's order (fleet.json counts from "
         f"0). Method: {rep['method']}; up to {rep['draws']} bootstrap series a finding.", "",
         "## What changed", ""]
    if rep["changes"]:
        L += ["| vehicle | what | from flight (log, its index in the vehicle's order) | onset's 95 % set | change | how sure | check |",
              "|---|---|---|---|---|---|---|"]
        for c in rep["changes"]:
            n = c["series"]
            size = (f"{_num(n, c['before'])} -> {_num(n, c['after'])} (step {_num(n, c['size'])} +- {_num(n, c['size_se'], '.2g')})"
                    if c["shape"] == "step" else
                    f"{_num(n, c['before'])} -> {_num(n, c['after'])} (a rise of {_num(n, c['size'])} +- "
                    f"{_num(n, c['size_se'], '.2g')} a flight)")
            also = f"; with it: {', '.join(a.replace('share_', 'motor ') for a in c['with_it'])}" if c["with_it"] else ""
            L.append(f"| {c['vehicle']} | {c['what']}: {c['label']}{also} | {c['onset_log']} (flight {c['onset_flight'] + 1} of "
                     f"{c['flights']}) | flights {c['onset_set_flights'][0] + 1}-{c['onset_set_flights'][1] + 1} | {size} | "
                     f"p = {c['p']:.2g}, Holm-adjusted {c['p_adjusted']:.2g} | {c['physical']['check']} |")
    elif rep["per_log"]:
        L.append("No trend test names a change beyond what the flights' own scatter explains; the logs name causes "
                 "on their own (below).")
    elif not rep["findings_tested"]:
        L.append(f"No finding could be tested: no vehicle has {MIN_FLIGHTS} diagnosed flights or more; no log names a cause.")
    else:
        L.append("Nothing changed on any vehicle beyond what the flights' own scatter explains, and no log names a cause.")
    L += ["", "## What the logs name on their own", ""]
    if rep["per_log"]:
        L += ["| vehicle | what | flights that name it (of those diagnosed) | first (log, flight) | its figures there "
              "| beside the trend test |",
              "|---|---|---|---|---|---|"]
        L += [_per_log_row(p) for p in rep["per_log"]]
    else:
        L.append("No log's own diagnosis names a cause.")
    for k, v in enumerate(rep["vehicles"], start=1):
        L += ["", f"## Vehicle {k}: {v['vehicle']}", "",
              f"{_logs(v)}; which logs are its: {v['identity']}; their order: {v['order']}; figure: "
              f"vehicle-{k}.png.", ""]
        for name, s in v["series"].items():
            t = s["test"]
            L.append(f"- {LABEL[name]}: {len(s['flight'])} flights; " + (
                f"too few to test (fewer than {MIN_FLIGHTS})" if t is None else
                f"best split at flight {t['onset_flight'] + 1} ({t['shape']}), LR {t['lr']:.1f}"))
        for what, t in v["findings"].items():
            if t is not None:
                L.append(f"- finding {what} ({', '.join(t['series'])}): p = {t['p']:.2g} ({t['draws']} bootstrap series), "
                         f"Holm {t['p_adjusted']:.2g}{': named' if t['named'] else ''}")
        for p in v["per_log"]:
            L.append(f"- the logs name {p['what']} in {len(p['flights'])} of {p['of']} diagnosed flights, from flight "
                     f"{p['first_flight'] + 1}; {p['trend']}")
        if v["timing"]:
            L.append(f"- timing: not followed: {v['timing']}")
    return "\n".join(L) + "\n"


def write(rep: dict, folder: Path) -> None:
    """fleet.md, fleet.json and a figure per vehicle into `folder` (made)."""
    from flightctl.files import write_atomic
    from flightctl.sim.diagnose.fleet.drawing import draw
    folder.mkdir(parents=True, exist_ok=True)
    write_atomic(folder / "fleet.json", json.dumps(rep, indent=1, allow_nan=False) + "\n")
    write_atomic(folder / "fleet.md", markdown(rep))
    for k, v in enumerate(rep["vehicles"], start=1):
        draw(v, [c for c in rep["changes"] if c["vehicle"] == v["vehicle"]], folder / f"vehicle-{k}.png")
