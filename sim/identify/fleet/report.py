"""The fleet report (`flightctl diagnose --corpus DIR --fleet REPORT`): from the results table's rows,
the vehicles (`grouping`), each one's series tested for a change (`trends`, Holm-corrected over every
series of the fleet), and what changed written as a table (REPORT/fleet.md), as JSON (REPORT/fleet.json)
and a figure per vehicle (REPORT/vehicle-N.png, `figure`).

A vehicle's motor shares sum to four: a motor that weakens takes a larger share (through its command)
and the three others a smaller one each, so the four series of a vehicle are one finding: the motor
whose share changed most significantly is named, and the others' changes are said beside it. A change is
named only when Holm's correction keeps it (trends.ALPHA family-wise) and its size passes a physical
check: for a motor, the thrust it gives for its command after the change against before (about the
inverse of its share's ratio) within motor_weak.SCALE_RANGE (a motor still able to hold its share of
the hover); for the battery, a resistance after the change within the static tier's R_CELL times the
cell count the logs declare (or 14 cells, the most this project reads, when they declare none).
"""
from __future__ import annotations

import json
from pathlib import Path

from flightctl.sim.identify.fleet.figures import SERIES
from flightctl.sim.identify.fleet.grouping import Vehicle, group
from flightctl.sim.identify.fleet.trends import ALPHA, PERMUTATIONS, Change, correct, test

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
    from flightctl.sim.identify.static.battery import R_CELL
    if name.startswith("share_"):
        scale = c.before / c.after if c.after > 0 else float("inf")
        ok = SCALE_RANGE[0] <= scale <= SCALE_RANGE[1]
        return ok, (f"its thrust for its command about {scale:.3f} of before (the shares' ratio), within "
                    f"{SCALE_RANGE[0]:g}-{SCALE_RANGE[1]:g}: " + ("passed" if ok else "failed"))
    if name == "battery_ohm":
        cells = [int((r.get("meta") or {}).get("battery_cells") or 0) for r in v.flights]
        n = max(cells) if any(cells) else MOST_CELLS
        lo, hi = R_CELL[0] * n, R_CELL[1] * n
        ok = lo < c.after < hi
        return ok, (f"{1e3 * c.after:.1f} mOhm after it, within {1e3 * lo:.1f}-{1e3 * hi:.0f} mOhm ({n} cells x "
                    f"{1e3 * R_CELL[0]:g}-{1e3 * R_CELL[1]:g}): " + ("passed" if ok else "failed"))
    return True, "no physical bound (a level, not a cause)"


def build(rows: list[dict], mapping: dict[str, str] | None = None, permutations: int = PERMUTATIONS) -> dict:
    """The fleet report as JSON (the module's docstring) of the results table's rows."""
    vehicles = group(rows, mapping)
    tests, changes = [], []
    for vi, v in enumerate(vehicles):
        for name in SERIES:
            at, y, se = _series(v, name)
            c = test(y, se, hinge=name in HINGED, permutations=permutations) if at else None
            tests.append((vi, name, at, y, se))
            changes.append(c)
    named = correct(changes)
    out = {"alpha": ALPHA, "permutations": permutations, "series_tested": sum(c is not None for c in changes),
           "method": "per series: step (and, for the battery and the vibration, hinge) models with the flights' standard "
                     "errors and a spread between flights, the largest likelihood ratio over the split points, its p-value "
                     "from the flights in random orders (a permutation test), Holm's correction over every series of the fleet "
                     "(sim/identify/fleet/trends.py)", "vehicles": [], "changes": []}
    for vi, v in enumerate(vehicles):
        series = {}
        for (wi, name, at, y, se), c, ok in zip(tests, changes, named):
            if wi != vi or not at:
                continue
            series[name] = {"flight": at, "value": y, "stderr": [None if s != s else s for s in se],
                            "test": None if c is None else {**vars(c), "onset_flight": at[c.onset],
                                                            "onset_set_flights": [at[c.onset_set[0]], at[c.onset_set[1]]]},
                            "significant": bool(ok)}
        needs = next(((r.get("figures") or {}).get("timing_needs") for r in v.flights
                      if (r.get("figures") or {}).get("timing_needs")), None)
        out["vehicles"].append({"vehicle": v.name, "identity": v.source, "order": v.order,
                                "flights": [{"index": i, "log": r["log"], "status": r["status"],
                                             "start_utc": (r.get("meta") or {}).get("start_utc")}
                                            for i, r in enumerate(v.flights)],
                                "series": series, "timing": None if "timing_s" in series else needs})
        out["changes"] += _findings(v, series)
    return out


def _findings(v: Vehicle, series: dict) -> list[dict]:
    found = []
    shares = [(n, s) for n, s in series.items() if n.startswith("share_") and s["significant"]]
    if shares:
        name, s = max(shares, key=lambda ns: ns[1]["test"]["lr"])
        found.append(_finding(v, name, s, [n for n, _ in shares if n != name]))
    for name, s in series.items():
        if not name.startswith("share_") and s["significant"]:
            found.append(_finding(v, name, s, []))
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


def markdown(rep: dict) -> str:
    """The report's table of what changed, then each vehicle's flights and what was tested."""
    L = ["# Fleet report", "", f"{len(rep['vehicles'])} vehicles, {rep['series_tested']} series tested; a change is named "
         f"when its Holm-adjusted p-value is below {rep['alpha']:g} (family-wise over the fleet) and its size passes its "
         f"physical check; flights are counted from 1 in each vehicle's order (fleet.json counts from 0). "
         f"Method: {rep['method']}; {rep['permutations']} permutations.", "",
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
    else:
        L.append("Nothing changed on any vehicle beyond what the flights' own scatter explains.")
    for k, v in enumerate(rep["vehicles"], start=1):
        L += ["", f"## Vehicle {k}: {v['vehicle']}", "",
              f"{len(v['flights'])} flights; which logs are its: {v['identity']}; their order: {v['order']}; figure: "
              f"vehicle-{k}.png.", ""]
        for name, s in v["series"].items():
            t = s["test"]
            L.append(f"- {LABEL[name]}: {len(s['flight'])} flights; " + (
                "too few to test" if t is None else
                f"best split at flight {t['onset_flight'] + 1} ({t['shape']}), LR {t['lr']:.1f}, p = {t['p']:.2g} "
                f"(Holm {t['p_adjusted']:.2g}){': named' if s['significant'] else ''}"))
        if v["timing"]:
            L.append(f"- timing: not followed: {v['timing']}")
    return "\n".join(L) + "\n"


def write(rep: dict, folder: Path) -> None:
    """fleet.md, fleet.json and a figure per vehicle into `folder` (made)."""
    from flightctl.errors import write_atomic
    from flightctl.sim.identify.fleet.figure import draw
    folder.mkdir(parents=True, exist_ok=True)
    write_atomic(folder / "fleet.json", json.dumps(rep, indent=1, allow_nan=False) + "\n")
    write_atomic(folder / "fleet.md", markdown(rep))
    for k, v in enumerate(rep["vehicles"], start=1):
        draw(v, [c for c in rep["changes"] if c["vehicle"] == v["vehicle"]], folder / f"vehicle-{k}.png")
