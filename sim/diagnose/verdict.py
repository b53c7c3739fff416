"""The verdict of diagnose: the base model (this project's airframe with a parameter file's effects, or
one identified from the flight of another vehicle), every candidate of the registry run on the data
set and judged by its held-out gain, and the chain of causes: the strongest significant candidate is
named and folded into the model, the others are refitted on top of it, until none is significant.
The JSON report of docs/measured-data.md (docs/diagnose.md, "Significance", "Every cause" and "A base
model with effects"; docs/real-flights.md)."""
from __future__ import annotations

import copy
import math
import sys
from dataclasses import dataclass, field

import numpy as np

from flightctl.errors import InputError
from flightctl.logfile import Table
from flightctl.params import Airframe, EffectSpec
from flightctl.sim.causes import CAUSES, lookalikes, make, times_actuation, twin
from flightctl.sim.causes.battery_sag import pack_range
from flightctl.sim.diagnose.basemodel import YAW_UNKNOWN, LayoutContradicted, identify, yaw_identified
from flightctl.sim.diagnose.rates import faster, motor_rate, sensor_rate
from flightctl.sim.diagnose.candidate import Result, columns_of
from flightctl.sim.diagnose.data import MIN_AIRBORNE_S, MIN_STRETCH_S, Layout, load_file
from flightctl.sim.diagnose.dataset import (CHANNELS, DYNAMIC_MIN_HZ, LOWPASS_HZ, N_BLOCKS, OFFSET, UNITS, Change,
                                                     DataSet, Vehicle)
from flightctl.sim.diagnose.rotorspeed import rotor_gain_check, rotor_speed_lag, timing_agreement
from flightctl.sim.diagnose.scoring import (DM_CHANNEL_WINDOW_S, DM_WINDOW_S, MIN_CHANNEL_GAIN, MIN_GAIN,
                                                     T_CHANNEL, T_CRIT, geomean, heldout_linear, significance)
from flightctl.sim.diagnose.static import StaticOnly, static_tier, tier_why
from flightctl.sim.diagnose.static.centre import one as centre_of_mass

# Each cause's module declares its twin (one physical effect modelled two ways: once one is in the chain
# the other is not tried), whether it times the actuation, and its look-alikes: which one of a cause and
# its look-alike a chain names is settled with its other causes in the model (`_swap`): beside an
# unmodelled cause that also moves acc_z, that channel can mislead the first round (docs/diagnose.md,
# "Two lags at once"). `sim.causes.twin`, `times_actuation` and `lookalikes` read those declarations.

METRIC = ("geometric mean over 6 channels of the held-out RMSE of the one-loop-period equation error: "
          "angular acceleration p, q, r (rad/s^2, differenced gyro) and specific force x, y, z (m/s^2, "
          "accelerometer, one bias each), both sides low-passed at {lowpass:g} Hz; held out by "
          f"{N_BLOCKS}-block cross-validation over the airborne data")


def say(*args) -> None:
    print("diagnose:", *args, file=sys.stderr, flush=True)


def _num(x, digits=5):
    """A JSON-safe number: non-finite values become None."""
    x = float(x)
    return round(x, digits) if math.isfinite(x) else None


@dataclass
class Round:
    """One step of the chain: the model so far (`base`, held out) and every candidate judged on top."""
    base: Result
    results: list[Result]                  # judged candidates, best first
    not_judged: list[dict]
    significant: dict[str, str]            # cause -> why significant: "all channels" or the one channel
    named: Result | None = None

    @property
    def not_physical(self) -> list[Result]:
        """The candidates that fit significantly but whose size is not physical (not named)."""
        return [r for r in self.results if r.not_physical and r.note is None and r.significance.named_by()]

    def candidates(self) -> list[dict]:
        out = []
        for r in self.results:
            s = r.significance
            out.append({"cause": r.cause, "parameters": r.parameters, "gain": _num(r.gain),
                        "rmse_extended": _num(geomean(r.score.rmse()), 6),
                        "t_stat": _num(r.t_stat, 2), "significant": r.cause in self.significant,
                        "significant_in": self.significant.get(r.cause),
                        "not_physical": r.not_physical,
                        "channels": {c: {"gain": _num(g), "t": _num(t, 2)}
                                     for c, g, t in zip(CHANNELS, s.channel_gain, s.channel_t)},
                        "block_gains": [_num(g, 4) for g in s.block_gain]})
        return out


@dataclass
class Diagnosis:
    rounds: list[Round]
    ds: DataSet                      # the data set of the first round (the base model alone)
    notes: list[str]
    carried: list[dict]              # the parameter file's effects in the base model
    lowpass_hz: float = LOWPASS_HZ
    final: dict[str, Result] = field(default_factory=dict)   # the chain's causes, each refitted on top of the others
    rotor_speed_check: dict | None = None
    rotor_gain_check: dict | None = None
    validation: dict | None = field(default=None)
    static: dict | None = None       # the static tier's findings (flightctl.sim.diagnose.static), None if not reached

    # the first round is the contract's top level: the strongest cause and every candidate
    @property
    def first(self) -> Round:
        return self.rounds[0]

    @property
    def base(self) -> Result:
        return self.first.base

    @property
    def results(self) -> list[Result]:
        return self.first.results

    @property
    def not_judged(self) -> list[dict]:
        return self.first.not_judged

    @property
    def significant(self) -> dict[str, str]:
        return self.first.significant

    @property
    def steps(self) -> list[Round]:
        """The rounds whose named cause survived the backfit, in the chain's order."""
        return [r for r in self.rounds if r.named is not None and r.named.cause in self.final]

    @property
    def chain(self) -> list[Result]:
        """The chain of causes: each named on top of the causes before it (its gain, its residual)."""
        return [r.named for r in self.steps]

    @property
    def cause(self) -> str:
        return self.chain[0].cause if self.chain else "none"

    @property
    def parameters(self) -> dict:
        return self.final[self.cause].parameters if self.chain else {}

    @property
    def rmse_base(self) -> float:
        return geomean(self.steps[0].base.score.rmse() if self.chain else self.base.score.rmse())

    @property
    def rmse_extended(self) -> float:
        return geomean(self.chain[0].score.rmse()) if self.chain else self.rmse_base

    @property
    def gain(self) -> float:
        return self.chain[0].gain if self.chain else 0.0

    def gyro_timing(self) -> tuple[str, float] | None:
        """(cause, s): the timing the gyro gives: the chain's timing cause, else the timing candidate
        with the best held-out gain."""
        for c, r in self.final.items():
            if times_actuation(c):
                return c, float(next(iter(r.parameters.values())))
        timing = [r for r in self.results if times_actuation(r.cause)]
        if not timing:
            return None
        r = max(timing, key=lambda r: r.gain)
        return r.cause, float(next(iter(r.parameters.values())))

    def report(self) -> dict:
        """The JSON report: the keys of docs/measured-data.md, then the project's extras."""
        base_rmse = self.base.score.rmse()
        ext_rmse = self.chain[0].score.rmse() if self.chain else base_rmse
        causes = []
        for rnd in self.steps:
            r, last = rnd.named, self.final[rnd.named.cause]
            causes.append({"cause": r.cause, "parameters": last.parameters, "gain": _num(r.gain),
                           "t_stat": _num(r.t_stat, 2), "significant_in": rnd.significant[r.cause],
                           "rmse_before": _num(geomean(rnd.base.score.rmse()), 6),
                           "rmse_after": _num(geomean(r.score.rmse()), 6),
                           "parameters_in_order": r.parameters, "gain_last": _num(last.gain)})
        v = self.ds.vehicle
        out = {
            "cause": self.cause,
            "parameters": self.parameters,
            "rmse_base": _num(self.rmse_base, 6),
            "rmse_extended": _num(self.rmse_extended, 6),
            "gain": _num(self.gain),
            "metric": METRIC.format(lowpass=self.lowpass_hz),
            "candidates": self.first.candidates(),
            "causes": causes,
            "not_judged": self.not_judged,
            "rounds": [{"candidates": [{"cause": c["cause"], "parameters": c["parameters"], "gain": c["gain"],
                                        "significant": c["significant"]} for c in rnd.candidates()],
                        "not_judged": rnd.not_judged} for rnd in self.rounds[1:]],
            "channels": {c: {"unit": u, "rmse_base": _num(b, 6), "rmse_extended": _num(e, 6)}
                         for c, u, b, e in zip(CHANNELS, UNITS, base_rmse, ext_rmse)},
            "significance": {"min_gain": MIN_GAIN, "t_crit": T_CRIT, "blocks": N_BLOCKS,
                             "window_s": DM_WINDOW_S, "min_channel_gain": _num(MIN_CHANNEL_GAIN, 4),
                             "t_channel": T_CHANNEL, "channel_window_s": DM_CHANNEL_WINDOW_S},
            "base_model": ({"identified": True, "what": "identified from the flight (docs/real-flights.md); "
                            "the candidates' parameters are per unit mass (kg), inertia (kg m^2) and arm length",
                            **v.identification} if v.identified else
                           {"identified": False, "what": "this project's airframe (docs/conventions.md or --params)"}),
            "data": {"files": [f.path for f in self.ds.files], "airborne_s": round(self.ds.seconds, 2),
                     "lowpass_hz": self.lowpass_hz, "base_effects": self.carried,
                     "battery_v": (None if (v := pack_range(self.ds.files)) is None else [round(x, 2) for x in v]),
                     "gyro_noise": gyro_noise(self.ds.files)},
            "notes": list(dict.fromkeys(self.notes)),   # a note said twice (two passes) once
            "tier": "dynamic", "tier_why": tier_why(self.static), "static": self.static,
        }
        out["centre_of_mass"] = centre_of_mass(out["base_model"], self.static, self.rotor_gain_check)
        seen = set()
        out["not_physical"] = []
        for rnd in self.rounds:
            for r in rnd.not_physical:
                if r.cause not in seen:
                    seen.add(r.cause)
                    out["not_physical"].append({"cause": r.cause, "parameters": r.parameters, "gain": _num(r.gain),
                                                "why": r.not_physical})
        out["physical_checks"] = {c.name: c.candidate.physical_check for c in CAUSES.values() if c.candidate.physical_check}
        if self.rotor_speed_check is not None:
            out["rotor_speed_check"] = {**self.rotor_speed_check,
                                        "agreement": timing_agreement(self.rotor_speed_check, self.gyro_timing())}
        if self.rotor_gain_check is not None:
            out["rotor_gain_check"] = self.rotor_gain_check
        if self.validation is not None:
            out["validation"] = self.validation
        return out


# The gyro's noise is reported from its part above this frequency: far above the rigid body's motion that
# the prediction models (the 12 Hz low-pass), below the Nyquist frequency of the slowest log it is given for.
GYRO_NOISE_HZ = 60.0


def gyro_noise(files) -> dict | None:
    """The logged gyro's noise in flight, per axis (rad/s): the rms of its part above GYRO_NOISE_HZ
    (a zero-phase 4th-order Butterworth high-pass over each file, taken on the airborne rows), and that
    as white noise per read (over the share of the band above the cut). Not a cause (docs/diagnose.md,
    "More noise is not a cause here"): a level to set beside the parameter file's `[sensors]`. None for
    logs slower than 2.5 times the cut."""
    from scipy import signal
    high, white = [], []
    for f in files:
        fs = 1.0 / float(np.median(np.diff(f.t)))
        if fs < 2.5 * GYRO_NOISE_HZ or not f.airborne.any():
            continue
        sos = signal.butter(4, GYRO_NOISE_HZ, btype="highpass", fs=fs, output="sos")
        g = np.nan_to_num(f.gyro - np.nanmean(f.gyro, axis=1, keepdims=True))
        h = signal.sosfiltfilt(sos, g, axis=1)[:, f.airborne]
        high.append(h)
        white.append(h / math.sqrt(1.0 - 2.0 * GYRO_NOISE_HZ / fs))
    if not high:
        return None
    rms = lambda parts: [round(float(v), 5) for v in np.sqrt(np.mean(np.concatenate(parts, axis=1) ** 2, axis=1))]
    return {"above_hz": GYRO_NOISE_HZ, "rms": dict(zip("pqr", rms(high))), "white_per_read": dict(zip("pqr", rms(white)))}


def _files(tables: list[Table], a: Airframe, notes: list[str], progress):
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
        what = (f"too short to judge: {total:.1f} s of airborne data (motors running, off the ground), "
                f"at least {MIN_AIRBORNE_S:g} s needed")
        if len(tables) == 1:
            tables[0].fail(what)
        raise InputError(f"{', '.join(t.path for t in tables)}: {what}")
    return files


def _vehicle(files, a: Airframe, given: bool, lowpass_hz: float, speeds, notes: list[str], progress,
             slow: str | None = None) -> Vehicle:
    """The base model: a foreign vehicle's identified from the flight unless a parameter file is
    given; this project's airframe otherwise."""
    foreign = [f.foreign for f in files]
    if any(foreign) and not all(foreign):
        raise InputError("the logs mix this project's vehicle with another one: diagnose them apart")
    if not all(foreign):
        return Vehicle.known(a, files[0].layout)
    if given:
        lay = files[0].layout
        scale = a.l if lay.unit == "arm" else 1.0
        layout = Layout(tuple(v * scale for v in lay.x), tuple(v * scale for v in lay.y), lay.spin, "m", lay.source)
        notes.append("base model: the parameter file's airframe with the log's rotor layout (arm = l)")
        return Vehicle.known(a, layout)
    vehicle, more = identify(files, lowpass_hz, progress, speeds, slow)
    notes += [f"base model: {n}" for n in more]
    return vehicle


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


def _round(ds: DataSet, skip: set[str], static_only: str | None, notes: list[str], progress, label: str) -> tuple[Round, dict]:
    """Every candidate not in `skip` fitted and judged on top of the data set's base model."""
    base = Result("none", {}, heldout_linear(ds, ds.r_base, columns_of(Change(None, ds.base_free))), ds.r_base)
    results, not_judged, judged = [], [], {}
    for c in CAUSES.values():
        if c.name in skip:
            continue
        cand = c.candidate(ds)
        why = cand.why_not()
        if why is None and static_only and cand.dynamic:
            why = static_only
        if why is None and cand.needs_yaw and ds.vehicle.identified and not yaw_identified(ds.vehicle):
            why = f"{YAW_UNKNOWN}: too little yaw in the flight to tell its effectiveness from zero"
        if why is None and cand.needs_accelerometer and not any(f.accel for f in ds.files):
            why = "no accelerometer in the log: the drag on the accelerometer is not answered (its gain would be 0, not a verdict)"
        if why is not None:
            not_judged.append({"cause": cand.cause, "why": why})
            progress(f"{label}{cand.cause}: not judged ({why})")
            continue
        r = cand.run()
        r.significance = significance(r.score, base.score, ds.fs_flat)
        r.explanatory = cand.explanatory()
        r.not_physical = cand.physical(r)
        results.append(r)
        judged[r.cause] = cand
        progress(f"{label}{cand.cause}: {r.parameters} held-out gain {r.gain:+.4f} (t = {r.t_stat:.1f})"
                 + (f"; not physical: {r.not_physical}" if r.not_physical else ""))
    results.sort(key=lambda r: -r.gain)
    significant = {}
    for r in results:
        by = r.significance.named_by()
        why = judged[r.cause].not_named(r) if by else None
        if why:
            notes.append(why)
        elif by and r.not_physical:
            r.note = None
            notes.append(f"{r.cause} {r.parameters} fits (held-out gain {r.gain:.3f}), but not physical: {r.not_physical}")
        elif by:
            significant[r.cause] = by
    rnd = Round(base, results, not_judged, significant)
    rnd.named = next((r for r in results if r.cause in significant), None)
    return rnd, judged


def quad_only(files) -> None:
    """InputError (the dynamic tier refused, the static tier answers) for a layout of other than four
    rotors: the dynamic tier's per-rotor parts are written for four (`DataSet.thrust_columns`, the hover
    gains and the rotor speeds' checks of basemodel.identify and rotorspeed, the per-motor causes'
    candidates), while its torques (`DataSet.predict_file`: eq. 25's sums over the layout) are not."""
    n = len(files[0].layout.x)
    if n != 4:
        raise InputError(f"{files[0].path}: the dynamic tier's model is a quadrotor's (its per-rotor thrust columns, hover gains and "
                         f"per-motor causes are written for four rotors): {n} rotors ({files[0].layout.source})")


def diagnose(tables: list[Table], a: Airframe, progress=say, effects: tuple[EffectSpec, ...] = (),
             params_given: bool = False, accepted=None) -> Diagnosis:
    """Every candidate of `flightctl.sim.causes` fitted and scored on the logs, on top of the base
    model (with `effects`, a parameter file's `[[effect]]` tables), and the chain of causes.
    `accepted()` is called once the logs are judged usable and the base model stands (what can
    refuse the logs has been asked)."""
    for e in effects:
        make(e.cause, **dict(e.parameters))     # the registry's checks (known cause, names, ranges) first
    notes: list[str] = []
    files = _files(tables, a, notes, progress)
    try:
        quad_only(files)
        sensor_rate(tables, files)
        lowpass, static_only, slow = LOWPASS_HZ, None, None
        rate = motor_rate(tables)
        if rate is not None and rate < DYNAMIC_MIN_HZ:
            lowpass = rate / 4.0
            static_only = (f"the motor outputs were logged at {rate:.1f} Hz: a lag or a delay of tens of ms needs "
                           f"them at {DYNAMIC_MIN_HZ:g} Hz or more")
            notes.append(f"{static_only}; only static effects are judged, on data low-passed at {lowpass:.2g} Hz")
            slow = (f"its motor commands were logged at {rate:.1f} Hz, held between samples that miss what the motors "
                    f"did in between" + faster(tables))
        speeds = rotor_speed_lag(files)
        vehicle = _vehicle(files, a, params_given or bool(effects), lowpass, speeds, notes, progress, slow)
    except InputError as e:     # the dynamic tier refused: the static tier's report, if it answers anything,
        if isinstance(e, LayoutContradicted):   # unless the data contradict the layout: refused whole
            raise
        return StaticOnly.instead_of(e, tables, files, a, notes, progress, accepted)
    ds = DataSet(files, vehicle, lowpass)
    ds.rotor_speeds = speeds
    gain_check = None
    if vehicle.identified:
        hover = vehicle.identification["hover_gain"]
        gain_check = rotor_gain_check(hover["value"], hover["stderr"], files[0].layout, speeds)
        progress(f"rotor gains: {gain_check['verdict']}: {gain_check['why']}")
    progress(f"{ds.seconds:.1f} s airborne ({ds.n} samples kept at {ds.fs_flat:.0f} Hz), {N_BLOCKS} blocks")
    if accepted is not None:
        accepted()
    carried = carry(ds, effects, notes, progress)
    rounds, skip = [], set()
    first = ds
    while True:
        label = f"[cause {len(rounds) + 1}] " if rounds else ""
        rnd, _ = _round(ds, skip, static_only, notes, progress, label)
        rounds.append(rnd)
        r = rnd.named
        if r is None:
            break
        progress(f"cause {len(rounds)}: {r.cause} {r.parameters}, held-out gain {r.gain:.3f}; folded into the model")
        skip |= {r.cause, twin(r.cause) or r.cause}
        ds = _folded(first, [(r.named.cause, r.named.parameters) for r in rounds])
    final = _backfit(first, [(r.named.cause, r.named.parameters) for r in rounds if r.named is not None],
                     notes, progress, alone={r.cause: r for r in rounds[0].results})
    if any(c not in {r.named.cause for r in rounds if r.named is not None} for c in final):
        rounds = _rechain(first, rounds[0], final, static_only, notes, progress)
    return Diagnosis(rounds, first, notes, carried, lowpass, final=final, rotor_speed_check=speeds,
                     rotor_gain_check=gain_check, static=static_tier(tables, files, a, progress))


def validate(d: Diagnosis, tables: list[Table], a: Airframe, progress=say) -> dict:
    """The model as fitted by the diagnosis (its base model, the parameter file's effects and the
    chain's causes at their parameters, nothing refitted but each accelerometer's bias) predicting
    other flights of the same vehicle: the RMSE of the base model and of the model with the causes,
    and the gain (the metric of the report, on data no fit has seen)."""
    notes: list[str] = []
    files = _files(tables, a, notes, progress)
    if any(f.foreign != d.ds.files[0].foreign for f in files):
        raise InputError("--validate: the validation logs are not of the diagnosed vehicle's kind")
    ds = DataSet(files, d.ds.vehicle, d.lowpass_hz)
    for e in d.carried:
        ds.carry(e["cause"], e["parameters"], CAUSES[e["cause"]].candidate(ds).predict(e["parameters"]))
    chain = [(c, r.parameters) for c, r in d.final.items()]
    folded = _folded(ds, chain)

    def rmse(r):
        r = r - np.where(OFFSET, r.mean(axis=1), 0.0)[:, None]
        return np.sqrt(np.mean(r * r, axis=1))

    rb, re = rmse(ds.r_base), rmse(folded.r_base)
    progress(f"validation: RMSE {geomean(rb):.4g} (base) -> {geomean(re):.4g} (with {', '.join(c for c, _ in chain) or 'no cause'})")
    return {"files": [f.path for f in files], "airborne_s": round(ds.seconds, 2), "causes": [c for c, _ in chain],
            "rmse_base": _num(geomean(rb), 6), "rmse_extended": _num(geomean(re), 6),
            "gain": _num(1.0 - geomean(re) / geomean(rb)),
            "channels": {c: {"rmse_base": _num(b, 6), "rmse_extended": _num(e, 6)}
                         for c, b, e in zip(CHANNELS, rb, re)},
            "notes": notes}


def _folded(ds: DataSet, causes) -> DataSet:
    """A copy of the data set with `causes` ((cause, parameters)) folded into its base model: those
    that change the rotors' thrusts first, in their order, then those that add to the prediction
    (computed on the final thrusts), as the plant composes them (`flightctl.sim.world.model.Effect`)."""
    causes = sorted(causes, key=lambda c: not CAUSES[c[0]].candidate.changes_thrust)
    for cause, parameters in causes:
        ds = copy.copy(ds)
        ds.carried, ds.carried_parameters, ds.extra_free = dict(ds.carried), dict(ds.carried_parameters), list(ds.extra_free)
        CAUSES[cause].candidate(ds).fold(parameters)
    return ds


def _on_top(ds0: DataSet, chain: list[tuple[str, dict]], i: int) -> Result:
    """Cause i of the chain refitted on top of all the others at their parameters, and judged there."""
    ds = _folded(ds0, chain[:i] + chain[i + 1:])
    cand = CAUSES[chain[i][0]].candidate(ds)
    base = heldout_linear(ds, ds.r_base, columns_of(Change(None, ds.base_free)))
    r = cand.run()
    r.significance = significance(r.score, base, ds.fs_flat)
    r.explanatory = cand.explanatory()
    return _judged(r, cand)


def _judged(r: Result, cand) -> Result:
    """A copy of `r` with its note of the backfit: why it is not named (not significant, the
    candidate's own reason, not physical), or None."""
    r = copy.copy(r)
    r.not_physical = cand.physical(r)
    r.note = ((cand.not_named(r) or (f"not physical: {r.not_physical}" if r.not_physical else None))
              if r.significance.named_by() else "not significant")
    return r


def _refit(ds0: DataSet, chain: list[tuple[str, dict]], passes: int) -> tuple[list, list[Result]]:
    """Each cause refitted on top of the others, in turn (Gauss-Seidel: the latest parameters of the
    others), `passes` times: (the chain with its new parameters, each one's last Result)."""
    chain, results = list(chain), [None] * len(chain)
    for _ in range(passes):
        for i, (cause, _) in enumerate(chain):
            results[i] = _on_top(ds0, chain, i)
            chain[i] = (cause, results[i].parameters)
    return chain, results


def _swap(ds0: DataSet, chain: list[tuple[str, dict]], results: list[Result], tried: set, notes: list[str],
          progress) -> list[tuple[str, dict]] | None:
    """The chain with one cause replaced by a look-alike (its module's `lookalikes`) that, refitted jointly with the
    others, predicts the held-out data better (the metric: the geometric mean over the channels of the
    held-out RMSE, the cause refitted per fold on top of the others) and is named there (significant,
    physical); None if no look-alike does. The first round judged each look-alike on the base model
    alone, where a cause not yet in the model can hide the channel that tells them apart: a rotor lag's
    `acc_z` beside an unmodelled `rotor_inflow`, whose damping of the climb speed is in antiphase
    with the lag's in the altitude loop. A chain of causes already tried is not tried again."""
    causes = {c for c, _ in chain}
    for i, (cause, _) in enumerate(chain):
        best, swapped = results[i], None
        for alt in lookalikes(cause):
            trial = chain[:i] + [(alt, {})] + chain[i + 1:]
            key = tuple(c for c, _ in trial)
            if alt in causes or twin(alt) in causes or key in tried:
                continue
            tried.add(key)
            trial[i] = (alt, _on_top(ds0, trial, i).parameters)
            trial, rs = _refit(ds0, trial, 2)
            progress(f"{alt} in place of {cause}, refitted with the other causes: {trial[i][1]}, held-out RMSE "
                     f"{geomean(rs[i].score.rmse()):.4g} against {geomean(best.score.rmse()):.4g}")
            if rs[i].note is None and geomean(rs[i].score.rmse()) < geomean(best.score.rmse()):
                best, swapped = rs[i], trial
        if swapped is not None:
            notes.append(f"{cause} was named first, but with the other causes in the model its look-alike "
                         f"{best.cause} predicts the held-out data better (RMSE {geomean(best.score.rmse()):.4g} "
                         f"against {geomean(results[i].score.rmse()):.4g}): named instead")
            progress(f"{best.cause} named in place of {cause}")
            return swapped
    return None


def _rechain(ds0: DataSet, first: Round, final: dict[str, Result], static_only: str | None, notes: list[str],
             progress) -> list[Round]:
    """The forward chain again, of the backfit's causes in their order, after a look-alike was swapped
    in (`_swap`): each round judges every candidate on top of the causes before it and names the
    chain's next cause, so that each entry's gain and RMSE are over the model with the ones before it.
    A cause swapped in that was not significant in its own round is reported with its significance on
    top of all the others, where it was judged."""
    rounds, skip, ds, chain = [], set(), ds0, []
    for k, cause in enumerate(final):
        rnd = first if k == 0 else _round(ds, skip, static_only, notes, progress, f"[cause {k + 1}] ")[0]
        rnd.named = next(r for r in rnd.results if r.cause == cause)
        rnd.significant.setdefault(cause, final[cause].significance.named_by())
        rounds.append(rnd)
        skip |= {cause, twin(cause) or cause}
        chain.append((cause, rnd.named.parameters))
        ds = _folded(ds0, chain)
    last, _ = _round(ds, skip, static_only, notes, progress, f"[cause {len(final) + 1}] ")
    last.named = None
    return rounds + [last]


def _backfit(ds0: DataSet, chain: list[tuple[str, dict]], notes: list[str], progress,
             alone: dict[str, Result] | None = None) -> dict[str, Result]:
    """The chain refitted jointly (each cause on top of all the others, twice over), then each cause
    tested on top of the others refitted without it: one that is then not significant is dropped (a
    cause named early can take up part of one named later, and a small one can stand in for the
    bias that leaves); then each cause with a look-alike is tried against it, both refitted with the
    others (`_swap`). Returns {cause: its Result on top of the others}, in chain order. `alone`: each
    cause's Result on the base model alone (the first round), which is a chain of one's, not run again."""
    if not chain:
        return {}
    tried = {tuple(c for c, _ in chain)}
    while True:
        chain, results = _refit(ds0, chain, 2 if len(chain) > 1 else 0)
        if len(chain) == 1:
            cause = chain[0][0]
            if alone and cause in alone:
                return {cause: _judged(alone[cause], CAUSES[cause].candidate(ds0))}
            return {cause: _on_top(ds0, chain, 0)}
        for r in results:
            progress(f"{r.cause} on top of the other causes: {r.parameters}, held-out gain {r.gain:.3f}")
        dropped = None
        for i in sorted(range(len(chain)), key=lambda k: results[k].gain):
            others, _ = _refit(ds0, chain[:i] + chain[i + 1:], 1)
            r = _on_top(ds0, others[:i] + [chain[i]] + others[i:], i)
            if r.note:
                dropped = chain[i][0]
                break
        if dropped is None:
            swapped = _swap(ds0, chain, results, tried, notes, progress)
            if swapped is None:
                return {cause: r for (cause, _), r in zip(chain, results)}
            chain = swapped
            continue
        notes.append(f"{dropped}: named in the chain, but not significant once the other causes are refitted "
                     "without it: dropped")
        progress(f"{dropped}: not significant once the others are refitted without it: dropped from the chain")
        chain = [c for c in chain if c[0] != dropped]
