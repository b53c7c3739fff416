"""The static tier of `flightctl diagnose` (docs/diagnose.md, "Static tier") on every real log the project
reads: tests/data/ardupilot and the shared real flights (../shared/data/real/flights), each log of a file
of many on its own. One row per log: what the static tier found (hover throttle and thrust margin, each
motor's share of the hover thrust, the pattern's verdict, the pack's internal resistance, a motor at full
command while the vehicle tips toward it, the vibration),
each with its standard error, or why it was not reached. The static tier alone runs here (on the logs as
diagnose reads them, at their full rate); `flightctl diagnose` runs the dynamic tier beside it.

    python scripts/static_tier.py [--doc docs/diagnose.md]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from flightctl.errors import InputError
from flightctl.params import Airframe
from flightctl.sim.docs import marked, publish, table
from flightctl.sim.diagnose.data import MIN_STRETCH_S, load_file
from flightctl.sim.diagnose.static import static_tier
from flightctl.sim.diagnose.corpus import find_logs
from flightctl.sim.logs import each_log, reason

ROOT = Path(__file__).resolve().parents[1]
FOLDERS = (ROOT / "tests" / "data" / "ardupilot", ROOT / ".." / "shared" / "data" / "real" / "flights")
COLUMNS = ("log", "rates (sensors, motors)", "hover", "motor shares of the hover thrust", "pattern",
           "internal resistance", "motor at full command", "vibration")


def _pm(v, e, scale=1.0, digits=3) -> str:
    return f"{scale * v:.{digits}g} ± {scale * e:.2g}"


def row(name: str, st: dict | None, why: str | None) -> list[str]:
    if st is None:
        return [name, "", "", "", "", "", "", f"not reached: {why}"]
    cells = [name, f"{st['rates']['sensors_hz']:g}, {st['rates']['motors_hz']:g} Hz"]
    if h := st.get("hover"):
        cells.append(f"{_pm(h['thrust_share'], h['thrust_share_stderr'], 100)} % of full thrust, T/W "
                     f"{_pm(h['thrust_to_weight'], h['thrust_to_weight_stderr'])} ({st['hover_s']:.0f} s)")
        m = st["motors"]
        cells.append(", ".join(_pm(v, e) for v, e in zip(m["share"], m["stderr"]))
                     + (f"; motor {', '.join(map(str, m['drifting']))} drifting" if m["drifting"] else ""))
        p = st["pattern"]
        com, yaw = p["com"], p["yaw_trim"]
        cells.append(f"{p['verdict']}: centre of mass ({_pm(com['dx'], com['stderr'][0], digits=2)}, "
                     f"{_pm(com['dy'], com['stderr'][1], digits=2)}) {com['unit']}, CCW - CW "
                     f"{_pm(yaw['ccw_minus_cw'], yaw['stderr'], 100, 2)} %"
                     + (f"; rotor speeds: {p['rotor_speeds']['verdict']}" if p["rotor_speeds"] else ""))
    else:
        cells += ["not judged", "", ""]
    b = st.get("battery")
    r = b.get("resistance") if b else None
    cells.append(f"{_pm(r['ohm'], r['stderr'], 1e3)} mΩ, check " + ("passed" if r["passed"] else "failed")
                 if r else ("no current" if b else "no battery"))
    cells.append(_full(st["motor_at_full"]))
    v = st.get("vibration")
    cells.append(("VIBE " if v["clips"] is not None else "acc spread ") + "/".join(f"{v['mean'][a]:.2g}" for a in "xyz")
                 + " m/s²" + (f", {v['clips']} clips" if v["clips"] is not None else "") if v else "")
    return cells


def _full(full: dict) -> str:
    """The motor at full command: the motor named, from when, for how long (in how many samples below 20 Hz), and
    how many spans followed."""
    s = next((x for x in full["spans"] if x["motor"] == full["named"] and not x["tumbling"]), None)
    if s is None:
        return "none" if not full["spans"] else f"none named ({len(full['spans'])} spans, all while tumbling)"
    held = f"{s['held_s']:.1f} s" if s["long"] else f"{s['samples']} samples of {full['motor_hz']:g} Hz"
    later = [x for x in full["spans"] if x is not s]
    return (f"motor {s['motor']} from {s['start_s']:.2f} s ({held}), toward it {s['toward_deg']:.0f}°"
            + (f"; {len(later)} later spans, {sum(x['tumbling'] for x in later)} while tumbling" if later else ""))


def logs() -> list[Path]:
    return [p for folder in FOLDERS for p in find_logs(folder) if p.suffix.lower() != ".csv"]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--doc", help="write the table between the file's 'static tier' markers")
    args = p.parse_args(argv)
    a = Airframe()
    rows = []
    for path in logs():
        name = path.relative_to(path.parents[1]).as_posix()
        try:
            entries = each_log(str(path))
        except InputError as e:
            rows.append(row(name, None, reason(str(e), str(path))))
            continue
        for e in entries:
            label = name if len(entries) == 1 else f"{name} #{e.index}"
            if e.table is None:
                if len(entries) == 1 or e.seconds >= 2.0:      # a header-only log of a file of many: left out
                    rows.append(row(label, None, e.reason))
                continue
            try:
                fd = load_file(e.table, a)
            except InputError as err:
                rows.append(row(label, None, reason(str(err), str(path))))
                continue
            if fd.airborne.sum() * float(np.median(np.diff(fd.t))) < MIN_STRETCH_S:
                rows.append(row(label, None, "no airborne data"))
                continue
            st = static_tier([e.table], [fd], a)
            rows.append(row(label, st, "the static tier answers nothing here (too slow, or never a flight)"))
    publish("\n".join(table(COLUMNS, [[c.replace("|", "/") for c in r] for r in rows])), args.doc, *marked("static tier"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
