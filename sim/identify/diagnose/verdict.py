"""The verdict of diagnose: carry the parameter file's effects into the base model, run every
candidate of the registry on the data set, judge each one's held-out gain, name the best significant
one or `none`, and write the JSON report of measured-data.md (docs/diagnose.md, "Significance" and
"A base model with effects")."""
from __future__ import annotations

import math
import sys
from dataclasses import dataclass

import numpy as np

from flightctl.errors import InputError
from flightctl.logfile import Table
from flightctl.params import Airframe, EffectSpec
from flightctl.sim.causes import CAUSES, make
from flightctl.sim.identify.diagnose.candidate import Result
from flightctl.sim.identify.diagnose.data import MIN_STRETCH_S, Z_AIRBORNE, load_file
from flightctl.sim.identify.diagnose.dataset import CHANNELS, LOWPASS_HZ, N_BLOCKS, UNITS, DataSet
from flightctl.sim.identify.diagnose.scoring import (DM_CHANNEL_WINDOW_S, DM_WINDOW_S, MIN_CHANNEL_GAIN, MIN_GAIN,
                                                     T_CHANNEL, T_CRIT, geomean, heldout, significance)

MIN_AIRBORNE_S = 1.0     # s of airborne data needed in total to judge anything

METRIC = ("geometric mean over 6 channels of the held-out RMSE of the one-loop-period equation error: "
          "angular acceleration p, q, r (rad/s^2, differenced gyro) and specific force x, y, z (m/s^2, "
          f"accelerometer, one bias each), both sides low-passed at {LOWPASS_HZ:g} Hz; held out by "
          f"{N_BLOCKS}-block cross-validation over the airborne data")


def say(*args) -> None:
    print("diagnose:", *args, file=sys.stderr, flush=True)


def _num(x, digits=5):
    """A JSON-safe number: non-finite values become None."""
    x = float(x)
    return round(x, digits) if math.isfinite(x) else None


@dataclass
class Diagnosis:
    cause: str
    parameters: dict
    rmse_base: float
    rmse_extended: float
    gain: float
    metric: str
    results: list[Result]            # judged candidates, best first
    not_judged: list[dict]
    base: Result
    ds: DataSet
    notes: list[str]
    significant: dict[str, str]      # cause -> why significant: "all channels" or the one channel
    carried: list[dict]              # the parameter file's effects in the base model

    def report(self) -> dict:
        """The JSON report: the keys of measured-data.md, then the project's extras."""
        cands = []
        for r in self.results:
            s = r.significance
            cands.append({"cause": r.cause, "parameters": r.parameters, "gain": _num(r.gain),
                          "rmse_extended": _num(geomean(r.score.rmse()), 6),
                          "t_stat": _num(r.t_stat, 2), "significant": r.cause in self.significant,
                          "significant_in": self.significant.get(r.cause),
                          "channels": {c: {"gain": _num(g), "t": _num(t, 2)}
                                       for c, g, t in zip(CHANNELS, s.channel_gain, s.channel_t)},
                          "block_gains": [_num(g, 4) for g in s.block_gain]})
        base_rmse = self.base.score.rmse()
        best = next((r for r in self.results if r.cause == self.cause), None)
        ext_rmse = best.score.rmse() if best is not None else base_rmse
        return {
            "cause": self.cause,
            "parameters": self.parameters,
            "rmse_base": _num(self.rmse_base, 6),
            "rmse_extended": _num(self.rmse_extended, 6),
            "gain": _num(self.gain),
            "metric": self.metric,
            "candidates": cands,
            "not_judged": self.not_judged,
            "channels": {c: {"unit": u, "rmse_base": _num(b, 6), "rmse_extended": _num(e, 6)}
                         for c, u, b, e in zip(CHANNELS, UNITS, base_rmse, ext_rmse)},
            "significance": {"min_gain": MIN_GAIN, "t_crit": T_CRIT, "blocks": N_BLOCKS,
                             "window_s": DM_WINDOW_S, "min_channel_gain": _num(MIN_CHANNEL_GAIN, 4),
                             "t_channel": T_CHANNEL, "channel_window_s": DM_CHANNEL_WINDOW_S},
            "data": {"files": [f.path for f in self.ds.files], "airborne_s": round(self.ds.seconds, 2),
                     "lowpass_hz": LOWPASS_HZ, "base_effects": self.carried},
            "notes": self.notes,
        }


def _dataset(tables: list[Table], a: Airframe, notes: list[str], progress) -> DataSet:
    """The airborne data of every log; a log without any is noted and left out."""
    files = []
    for tab in tables:
        fd = load_file(tab, a)
        sec = fd.airborne.sum() / (1.0 / float(np.median(np.diff(fd.t))))
        progress(f"{tab.path}: {fd.t[-1] - fd.t[0]:.1f} s logged, {sec:.1f} s airborne")
        notes += [f"{tab.path}: {n}" for n in fd.notes]
        if sec < MIN_STRETCH_S:
            notes.append(f"{tab.path}: no usable airborne data (motors off or on the ground): not used")
            continue
        files.append(fd)
    total = sum(f.airborne.sum() * float(np.median(np.diff(f.t))) for f in files)
    if total < MIN_AIRBORNE_S:
        what = (f"too short to judge: {total:.1f} s of airborne data (motors running, above "
                f"{Z_AIRBORNE:g} m), at least {MIN_AIRBORNE_S:g} s needed")
        if len(tables) == 1:
            tables[0].fail(what)
        raise InputError(f"{', '.join(t.path for t in tables)}: {what}")
    return DataSet(files, a)


def carry(ds: DataSet, effects: tuple[EffectSpec, ...], notes: list[str], progress) -> list[dict]:
    """Put each effect of the parameter file into the base model at its given parameters, through its
    candidate's own prediction (`Candidate.predict`), in the file's order; one whose prediction the
    logs cannot give is left out with a note. Returns the carried effects for the report."""
    carried = []
    for e in effects:
        parameters = dict(e.parameters)
        cand = CAUSES[e.cause].candidate(ds)
        why = cand.why_not_carried()
        if why is not None:
            notes.append(f"base model: {e.cause} {parameters} of the parameter file left out ({why})")
            progress(f"base model: {e.cause} left out ({why})")
            continue
        ds.carry(e.cause, parameters, cand.predict(parameters))
        carried.append({"cause": e.cause, "parameters": parameters})
        progress(f"base model carries {e.cause} {parameters}")
    return carried


def diagnose(tables: list[Table], a: Airframe, progress=say, effects: tuple[EffectSpec, ...] = ()) -> Diagnosis:
    """Every candidate of `flightctl.sim.causes` fitted and scored on the logs, on top of the base
    model with `effects` (a parameter file's `[[effect]]` tables); the verdict."""
    for e in effects:
        make(e.cause, **dict(e.parameters))     # the registry's checks (known cause, names, ranges) first
    notes: list[str] = []
    ds = _dataset(tables, a, notes, progress)
    progress(f"{ds.n} samples airborne ({ds.seconds:.1f} s), {N_BLOCKS} blocks")
    carried = carry(ds, effects, notes, progress)
    base = Result("none", {}, heldout(ds, lambda train: ds.r_base), ds.r_base)
    results, not_judged, judged = [], [], {}
    for c in CAUSES.values():
        cand = c.candidate(ds)
        why = cand.why_not()
        if why is not None:
            not_judged.append({"cause": cand.cause, "why": why})
            progress(f"{cand.cause}: not judged ({why})")
            continue
        r = cand.run()
        r.significance = significance(r.score, base.score, ds.fs)
        r.explanatory = cand.explanatory()
        results.append(r)
        judged[r.cause] = cand
        progress(f"{cand.cause}: {r.parameters} held-out gain {r.gain:+.4f} (t = {r.t_stat:.1f})")
    results.sort(key=lambda r: -r.gain)
    significant = {}
    for r in results:
        by = r.significance.named_by()
        why = judged[r.cause].not_named(r) if by else None
        if why:
            notes.append(why)
        elif by:
            significant[r.cause] = by
    rb = geomean(base.score.rmse())
    best = next((r for r in results if r.cause in significant), None)
    if best is None:
        cause, params, re, gain = "none", {}, rb, 0.0
    else:
        cause, params, re, gain = best.cause, best.parameters, geomean(best.score.rmse()), best.gain
    return Diagnosis(cause, params, rb, re, gain, METRIC, results, not_judged, base, ds, notes, significant,
                     carried)
