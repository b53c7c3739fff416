"""Gains from a log where the truth is known (docs/tune.md, "Two tunes of one vehicle"): PID-Analyzer's CS110 flown
with two tunes (tests/data/pid-analyzer), gains from each log checked on the other (`fromlog.against`), and the
step each set of gains is predicted to give on the other log's windows beside what that tune measured there.

    python scripts/fromlog_cs110.py
"""
from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CS110 = ROOT / "tests" / "data" / "pid-analyzer"
PAIRS = (("example_smooth_tune.BBL", "better_tune.BBL"), ("better_tune.BBL", "example_smooth_tune.BBL"))
AXIS = {"x": "roll", "y": "pitch", "z": "yaw"}


def _ms(x) -> str:
    return "-" if x is None else f"{1e3 * x:.0f}"


def markdown(name1: str, name2: str, res: dict) -> list[str]:
    """The pair's rows: per axis the check and the gains from the log, then the predicted steps on the second log."""
    rep = res["report"]
    L = []
    for a, e in rep["axes"].items():
        if "refused" in e:
            L.append(f"| {name1} | {name2} | {AXIS[a]} | no gains: {e['refused'].split(': ', 1)[-1].split(' (the gain')[0]} "
                     "| | | | |")
            continue
        nw, lg = e["new"], e["logged"]
        fig = lambda s: (f"PM {s['pm_deg']['worst']:.0f}, GM {s['gm_db']['worst']:.1f} dB, Ms {s['ms']['worst']:.2f}, "
                         f"overshoot {100 * s['overshoot']['worst']:.0f} %")
        x = res["axes"][a]
        pred = x["predicted_on_second"]
        own = pred["second tune's gains"]
        what = "recommended" if e["recommended"] else "nearest (none meets the targets)"
        L.append(f"| {name1} | {name2} | {AXIS[a]} | {what}: "
                 + ", ".join(f"{k[1].upper()} x{v:.3g}" for k, v in nw["factors"].items()) + " (the second tune: "
                 + ", ".join(f"{k[1].upper()} x{v:.3g}" for k, v in x["second_over_first"].items())
                 + f") | logged, worst of {rep['draws']}: {fig(lg)}; new: {fig(nw)} | "
                 + "; ".join(f"{n}: {p['step_error']:.3f} (delay {_ms(p['delay_s']['predicted'])}, rise "
                             f"{_ms(p['rise_s']['predicted'])} ms)" for n, p in pred.items())
                 + f" | measured: delay {_ms(own['delay_s']['measured'])}, rise {_ms(own['rise_s']['measured'])} ms | "
                 + (e.get("extrapolated") or "within the band the check saw").split(": its timing")[0] + " |")
    return L


def main(argv: list[str]) -> int:
    from flightctl import params as paramfile
    from flightctl.sim.logs import read_foreign
    from flightctl.sim.sweeps import fromlog
    a = paramfile.load(None).airframe
    tables = {n: read_foreign(str(CS110 / n))[0] for n in {p for pair in PAIRS for p in pair}}
    rows = []
    for n1, n2 in PAIRS:
        rows += markdown(n1, n2, fromlog.against(tables[n1], tables[n2], a, fromlog.Targets()))
    print(f"`flightctl tune --from-log LOG --check-on LOG2` on the CS110 pair, {fromlog.DRAWS} drawn models an axis, "
          "seed 0, the default targets; predicted step errors on LOG2's windows:\n")
    print("| gains from | checked on | axis | gains (factors on the logged) | margins over the models | "
          "predicted on the second log: step error (delay, rise) | the second tune measured | where the margins are read |")
    print("|---|---|---|---|---|---|---|---|")
    print("\n".join(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
