"""The measured step responses of this project's `excite` flight (simulated, its attitude loop) and of the
shipped real logs (docs/steps.md): one row per log, loop and axis,
the numbers of `flightctl diagnose`'s `steps` (sim/diagnose/steps.py) or the reason the log
cannot show one; `--out PNG` draws the figure of the logs that show one.

    python scripts/steps_table.py [--out docs/steps.png]
"""
from __future__ import annotations

import argparse
import contextlib
import io
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FLIGHTS = ROOT / ".." / "shared" / "data" / "real" / "flights"
LOGS = (("betaflight/LOG00037.BFL", FLIGHTS, 1), ("betaflight/btfl_002.bbl", FLIGHTS, 1),
        ("px4/quadrotor_local.ulg", FLIGHTS, 1), ("ardupilot/log171.bin", ROOT / "tests" / "data", 1),
        ("inav/blackbox_log_2026-02-21_145057.TXT", FLIGHTS, 2), ("indiflight/LOG00230.BFL", FLIGHTS, 1))
AXIS = {"x": "roll", "y": "pitch", "z": "yaw"}


def _ms(e: dict, key: str) -> str:
    v, (lo, hi) = e[key]["value"], e[key]["spread"]
    return "-" if v is None else f"{1e3 * v:.0f} ({'-' if lo is None else f'{1e3 * lo:.0f}'}-{'-' if hi is None else f'{1e3 * hi:.0f}'})"


def rows(reports: list[tuple[str, dict]]) -> list[list[str]]:
    out = []
    for name, rep in reports:
        for loop in ("rate", "attitude"):
            part = rep.get(loop)
            if part is None:
                continue
            if "why" in part:
                out.append([name, loop, "all", "", "", "", "", "", part["why"]])
                continue
            for a in "xyz":
                e = part[a]
                if "why" in e:
                    out.append([name, loop, AXIS[a], "", "", "", "", "", e["why"].split("; fly next time")[0]])
                    continue
                o, (olo, ohi) = e["overshoot"]["value"], e["overshoot"]["spread"]
                out.append([name, loop, AXIS[a], _ms(e, "delay_s"), _ms(e, "rise_s"),
                            "-" if o is None else f"{100 * o:.0f} ({100 * olo:.0f}-{100 * ohi:.0f})", _ms(e, "settling_s"),
                            f"{e['windows']} of {e['windows_in_air']}, to {e['coherent_to_hz']:g} Hz",
                            "rise at the band's limit: an upper bound" if e["limited_by_band"] else ""])
    return out


def main(argv: list[str]) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", help="the figure (PNG) of the logs that show a step")
    args = p.parse_args(argv)
    from flightctl.sim.docs import table
    from flightctl.sim.diagnose import steps
    from flightctl.sim.logs import read_foreign
    import tempfile
    from flightctl.cli import main as flightctl
    from flightctl.logfile import read_flight_log
    reports, curves = [], []
    with tempfile.TemporaryDirectory() as tmp:      # this project's own flight: its attitude loop (eq. 24)
        log = Path(tmp) / "excite.csv"
        with contextlib.redirect_stdout(io.StringIO()):     # its step metrics: not this table's
            flightctl(["sim", "excite", "--log", str(log), "--no-plot", "--quiet"])     # 1: it touches down fast
        own = read_flight_log(log, min_rows=10)
    rep, c = steps.measure(own)
    reports.append(("flightctl sim excite", rep))
    if c:
        curves.append((dict(rep, file="flightctl sim excite"), c))
    for rel, folder, index in LOGS:
        table_ = read_foreign(str(folder / rel))[index - 1]
        rep, c = steps.measure(table_)
        name = rel.split("/", 1)[1] + (f" log {index}" if index > 1 else "")
        reports.append((name, rep))
        if c:
            curves.append((rep, c))
    header = ["log", "loop", "axis", "delay ms", "rise 10-90 % ms", "overshoot %", "settling ms",
              "windows with input, coherent", "why not"]
    print("\n".join(table(header, rows(reports))))
    if args.out:
        from flightctl.sim.plots import save
        save(steps.figure(curves), args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
