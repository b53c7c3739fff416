"""The firmware's rate controller as it flew, read from the log's own settings (docs/steps.md, "The
controller"): per axis the gains (P, I, D, feed-forward) in physical units where the firmware's scaling
was read in its source, the gyro's and the D term's filters, and the loop rate. A setting the log does
not hold, or whose scaling was not read in the firmware's source, is named in `unread`, never guessed.

Physical units: the controller's output is the mixer's command as a share of its range (1 = full), its
input the rate error in rad/s: P in 1/(rad/s), I in 1/rad (per rad/s of error per s), D in s/rad.

- Betaflight (blackbox header; src/main/flight/, the same constants in v3.1.0, 3.5.0, 4.2.0 and 4.5.2;
  lines of 4.5.2): pid_init.c:274-276 Kp = PTERM_SCALE P, Ki = ITERM_SCALE I, Kd = DTERM_SCALE D with
  pid.h:44-46 PTERM_SCALE 0.032029, ITERM_SCALE 0.244381, DTERM_SCALE 0.000529; pid.c:973 P = Kp
  errorRate (deg/s), pid.c:992 I += Ki dT errorRate, pid.c:1026-1027 D = Kd d(gyro)/dt (deg/s^2); mixer.c:623
  the sum over PID_MIXER_SCALING (pid.h:32, 1000) is the mixer's share. Feed-forward (pid.c:1081, F =
  Kf pidSetpointDelta) acts on a setpoint change whose unit changed across versions (rc.c): its raw
  weight is given, not converted. The loop: 1e6 / (looptime pid_process_denom) Hz (blackbox.c:1399,
  looptime the gyro's sample period in us).
- PX4 (parameters; src/modules/mc_rate_control/MulticopterRateControl.cpp, parameters_updated()): the
  gains are MC_*RATE_K times MC_*RATE_P/I/D (the ideal form), feed-forward MC_*RATE_FF apart, on rad/s to
  a normalised torque (already physical); IMU_GYRO_CUTOFF and IMU_DGYRO_CUTOFF the gyro's and the D
  term's low-pass (Hz), IMU_GYRO_RATEMAX the loop's rate.
- ArduPilot (parameters; libraries/AC_AttitudeControl/AC_AttitudeControl_Multi.cpp, rate_controller_run():
  the rate PIDs take rad/s and give the motors' roll, pitch, yaw in -1..1): ATC_RAT_RLL/PIT/YAW_P, _I, _D,
  _FF as they are; _FLTD the D term's low-pass, INS_GYRO_FILTER the gyro's (Hz), SCHED_LOOP_RATE the loop.
- INAV, INDIflight, Cleanflight, Betaflight before 3.1 (blackbox header): their gains' scaling was not read in
  their source: raw values, named unread.
- flightctl (the log's parameter file, `# params:`): eq. 24's PIDs close the attitude loop on the angles
  (N/rad, N/(rad s), N s/rad: docs/conventions.md); the loop rate `loop_hz`, the D term's rate EMA `tau_rate`.
"""
from __future__ import annotations

import json
import math

from flightctl.errors import InputError

DEG_PER_RAD = 180.0 / math.pi
AXES = ("x", "y", "z")
# Betaflight's constants (src/main/flight/pid.h:32, 44-46 at 4.5.2; the same since v3.1.0)
BF_MIXER = 1000.0
BF_SCALE = {"kp": 0.032029, "ki": 0.244381, "kd": 0.000529}
BF_UNITS = {"kp": "1/(rad/s)", "ki": "1/rad", "kd": "s/rad"}
# INAV's (src/main/flight/pid.h at 30ec1fe: FP_PID_RATE_P/I/D_MULTIPLIER; pid.c updatePIDCoefficients: kP = P / 31,
# kI = I / 4, kD = D / 1905, on the rate error in deg/s, giving the PID sum in the motor's own units, which
# mixer.c's mixTable adds to the throttle: over the header's motorOutput range, a share of the logged range)
INAV_SCALE = {"kp": 31.0, "ki": 4.0, "kd": 1905.0}
BF_SOURCE = {"kp": "pid_init.c:274, pid.h:44 PTERM_SCALE", "ki": "pid_init.c:275, pid.h:45 ITERM_SCALE",
             "kd": "pid_init.c:276, pid.h:46 DTERM_SCALE"}


def _entry(raw, value, unit, source) -> dict:
    return {"raw": raw, "value": None if value is None else round(float(value), 8), "unit": unit, "source": source}


def _first(h: dict, names: tuple[str, ...]):
    for n in names:
        if n in h:
            return n, h[n]
    return None, None


def blackbox(h: dict, kind: str, convert: bool) -> dict:
    """The controller of a blackbox header (orangebox's dict) of firmware `kind`; its gains in physical units
    when `convert` (Betaflight from 3.1, whose constants these are), else raw and named unread."""
    out = {"firmware": kind, "axes": {}, "filters": {}, "unread": []}
    ff_name, ff = _first(h, ("ff_weight", "feedforward_weight"))
    span = None
    if kind == "inav":
        mo = h.get("motorOutput")
        span = float(mo[1]) - float(mo[0]) if isinstance(mo, (list, tuple)) and len(mo) >= 2 else None
        if not span:
            out["unread"].append("motorOutput (not in the header): INAV's gains cannot be put in shares of the motor range")
    for j, (a, key) in enumerate(zip(AXES, ("rollPID", "pitchPID", "yawPID"))):
        pid = h.get(key)
        if not isinstance(pid, (list, tuple)) or len(pid) < 3:
            out["unread"].append(f"{key} (not in the header)")
            continue
        axis = {}
        for k, raw in zip(("kp", "ki", "kd"), pid[:3]):
            if span:
                axis[k] = _entry(raw, float(raw) / INAV_SCALE[k] * DEG_PER_RAD / span, BF_UNITS[k],
                                 f"header {key} / {INAV_SCALE[k]:g} (INAV pid.h FP_PID_RATE_*_MULTIPLIER, pid.c "
                                 f"updatePIDCoefficients) over motorOutput's {span:g} (mixer.c mixTable)")
                continue
            value = float(raw) * BF_SCALE[k] / BF_MIXER * DEG_PER_RAD if convert else None
            axis[k] = _entry(raw, value, BF_UNITS[k] if convert else "raw",
                             f"header {key}; " + (BF_SOURCE[k] + ", over PID_MIXER_SCALING (pid.h:32)" if convert
                                                  else f"{kind}'s scaling not read in its source"))
        raw_f = ff[j] if isinstance(ff, (list, tuple)) and len(ff) > j else (pid[3] if len(pid) > 3 else None)
        if raw_f is not None:
            axis["kf"] = _entry(raw_f, None, "raw", f"header {ff_name or key}: pid.c:1081, a setpoint change's unit "
                                                   "that varies by version: not converted")
        out["axes"][a] = axis
    if not convert and not span:
        out["unread"].append(f"the gains' physical scaling ({kind}'s source not read here: raw values)")
    if ff_name is None and not any("kf" in v for v in out["axes"].values()):
        out["unread"].append("feed-forward (no ff_weight or feedforward_weight in the header)")
    if "dtermSetpointWeight" in h:      # Betaflight 3.1: D on (c setpoint - gyro), pid.c:163, 272-276 of v3.1.5
        out["d_setpoint_weight"] = _entry([h["dtermSetpointWeight"], h.get("setpointRelaxRatio")],
                                          float(h["dtermSetpointWeight"]) / 100.0 if convert else None, "-",
                                          "header dtermSetpointWeight / 100 (raw: it, setpointRelaxRatio): the D term on "
                                          "c setpoint - gyro, pid.c:163, 272-276 of v3.1.5 (c relaxed by the stick's "
                                          "deflection when setpointRelaxRatio is under 100)")
    looptime, denom = h.get("looptime"), h.get("pid_process_denom", 1 if kind == "inav" else None)
    if looptime and denom:
        out["loop_hz"] = _entry([looptime, denom], 1e6 / (float(looptime) * float(denom)), "Hz",
                                "1e6 / (header looptime x pid_process_denom): blackbox.c:1399")
    else:
        out["unread"].append("the loop rate (looptime or pid_process_denom not in the header)")
    for what, names in (("gyro_lowpass_hz", ("gyro_lpf1_static_hz", "gyro_lowpass_hz", "gyro_lpf_hz")),
                        ("gyro_lowpass2_hz", ("gyro_lpf2_static_hz", "gyro_lowpass2_hz")),
                        ("dterm_lowpass_hz", ("dterm_lpf1_static_hz", "dterm_lowpass_hz", "dterm_lpf_hz")),
                        ("dterm_lowpass2_hz", ("dterm_lpf2_static_hz", "dterm_lowpass2_hz")),
                        ("dterm_lowpass_dyn_hz", ("dterm_lpf1_dyn_hz", "dterm_lowpass_dyn_hz")),
                        ("yaw_lowpass_hz", ("yaw_lowpass_hz", "yaw_lpf_hz")),
                        ("gyro_lowpass_type", ("gyro_lpf1_type", "gyro_lowpass_type")),
                        ("dterm_lowpass_type", ("dterm_lpf1_type", "dterm_filter_type", "dterm_lpf_type"))):
        name, v = _first(h, names)
        if name is None:
            out["unread"].append(what)
        elif what.endswith("_type"):
            out["filters"][what] = _entry(v, None, "the firmware's enumeration", f"header {name} (its values vary by version)")
        else:
            scalar = isinstance(v, (int, float))
            out["filters"][what] = _entry(v, float(v) if scalar else None, "Hz", f"header {name} (0: off)")
    return out


def _params(p: dict, names: dict[str, tuple[str, str, str]], out: dict) -> None:
    for what, (name, unit, source) in names.items():
        if name in p:
            out["filters" if what != "loop_hz" else "loop"][what] = _entry(p[name], float(p[name]), unit, source)
        else:
            out["unread"].append(f"{what} ({name} not in the log's parameters)")


def px4(p: dict) -> dict:
    out = {"firmware": "px4", "axes": {}, "filters": {}, "loop": {}, "unread": []}
    src = "MulticopterRateControl.cpp parameters_updated()"
    for a, name in zip(AXES, ("ROLL", "PITCH", "YAW")):
        pre = f"MC_{name}RATE_"
        if f"{pre}P" not in p:
            out["unread"].append(f"{pre}P/I/D/FF/K (not in the log's parameters)")
            continue
        k = float(p.get(f"{pre}K", 1.0))
        axis = {}
        for g, unit in (("P", "1/(rad/s)"), ("I", "1/rad"), ("D", "s/rad")):
            if f"{pre}{g}" in p:
                axis[f"k{g.lower()}"] = _entry(p[f"{pre}{g}"], k * float(p[f"{pre}{g}"]), unit,
                                               f"{pre}K x {pre}{g}: {src}")
        if f"{pre}FF" in p:
            axis["kf"] = _entry(p[f"{pre}FF"], float(p[f"{pre}FF"]), "1/(rad/s) of the rate setpoint", f"{pre}FF: {src}")
        out["axes"][a] = axis
    _params(p, {"gyro_lowpass_hz": ("IMU_GYRO_CUTOFF", "Hz", "IMU_GYRO_CUTOFF"),
                "dterm_lowpass_hz": ("IMU_DGYRO_CUTOFF", "Hz", "IMU_DGYRO_CUTOFF (the angular acceleration the D term takes)"),
                "loop_hz": ("IMU_GYRO_RATEMAX", "Hz", "IMU_GYRO_RATEMAX (the rate loop runs on each gyro sample)")}, out)
    out["loop_hz"] = out.pop("loop").get("loop_hz")
    out["rotors_from_ca"] = "CA_ROTOR_COUNT" in p     # the control allocation's pseudo-inverse mixes (loops.py)
    return out


def ardupilot(p: dict) -> dict:
    out = {"firmware": "ardupilot", "axes": {}, "filters": {}, "loop": {}, "unread": []}
    src = "AC_AttitudeControl_Multi.cpp rate_controller_run()"
    for a, name in zip(AXES, ("RLL", "PIT", "YAW")):
        pre = f"ATC_RAT_{name}_"
        if f"{pre}P" not in p:
            out["unread"].append(f"{pre}P/I/D/FF (not in the log's parameters: ArduCopter before 3.4 names them RATE_*)")
            continue
        axis = {}
        for g, unit in (("P", "1/(rad/s)"), ("I", "1/rad"), ("D", "s/rad"), ("FF", "1/(rad/s) of the rate target")):
            if f"{pre}{g}" in p:
                axis["kf" if g == "FF" else f"k{g.lower()}"] = _entry(p[f"{pre}{g}"], float(p[f"{pre}{g}"]), unit,
                                                                      f"{pre}{g}: {src}")
        for f in ("FLTD", "FLTT", "FLTE"):
            if f"{pre}{f}" in p:
                axis[f.lower() + "_hz"] = _entry(p[f"{pre}{f}"], float(p[f"{pre}{f}"]), "Hz", f"{pre}{f} (0: off)")
        out["axes"][a] = axis
    _params(p, {"gyro_lowpass_hz": ("INS_GYRO_FILTER", "Hz", "INS_GYRO_FILTER"),
                "loop_hz": ("SCHED_LOOP_RATE", "Hz", "SCHED_LOOP_RATE")}, out)
    out["loop_hz"] = out.pop("loop").get("loop_hz")
    # the motors' thrust linearisation and spin range (AP_MotorsMulticopter; loops.py's R)
    out["motors"] = {k: float(p[k]) for k in ("MOT_THST_EXPO", "MOT_SPIN_MIN", "MOT_SPIN_MAX") if k in p}
    return out


def flightctl(flat: dict[str, float]) -> dict:
    """This project's controller from the log's parameter file (`flat_parameters`)."""
    out = {"firmware": "flightctl", "loop": "attitude (eq. 24 on the angles)", "axes": {}, "filters": {}, "unread": []}
    for a, name in zip(AXES, ("phi", "theta", "psi")):
        out["axes"][a] = {f"k{g}": _entry(flat[f"gains.k{g}_{name}"], flat[f"gains.k{g}_{name}"], unit,
                                          f"[gains] k{g}_{name} (eq. 24, Table 6 by default)")
                          for g, unit in (("p", "N/rad"), ("i", "N/(rad s)"), ("d", "N s/rad"))}
    out["loop_hz"] = _entry(flat["loop_hz"], flat["loop_hz"], "Hz", "[airframe] loop_hz")
    out["filters"]["tau_rate_s"] = _entry(flat["filters.tau_rate"], flat["filters.tau_rate"], "s",
                                          "[filters] tau_rate: the EMA on the rates the D term takes (0: none)")
    out["thrust_curve"] = {k: _entry(flat[k], flat[k], unit, f"[airframe] {k}: eq. 26, the mixer's inverse")
                           for k, unit in (("h1", "N"), ("h2", "P units"))}
    return out


def encode(c: dict) -> str:
    """The `# controller:` line a reader writes (one line of JSON)."""
    return json.dumps(c, separators=(",", ":"))


def of_table(table) -> dict:
    """The controller of a flight-log table: a foreign log's `# controller:` line, this project's log's parameter
    file, or what is missing."""
    if "controller" in table.meta:
        try:
            return json.loads(table.meta["controller"])
        except ValueError:
            table.fail("# controller: not the JSON a reader writes")
    from flightctl.sim.logs.export import flat_parameters
    try:
        flat = flat_parameters(table.meta, table.path)
    except InputError:
        flat = {}
    if not flat:
        return {"unread": ["the controller: the log holds no '# controller:' line and no parameter file ('# params:')"]}
    return flightctl(flat)


def _value(v: dict) -> str:
    return f"raw {v['raw']}" if v["value"] is None else f"{v['value']:.4g} {v['unit']}"


def text(controllers: list[dict]) -> str:
    """The controllers' lines of diagnose's printed report."""
    L = []
    for c in controllers:
        axes = []
        for a, name in zip(AXES, ("roll", "pitch", "yaw")):
            g = c.get("axes", {}).get(a)
            if g:
                axes.append(name + " " + " ".join(f"{k[1:].upper()} {_value(v)}" for k, v in g.items()
                                                 if k in ("kp", "ki", "kd", "kf")))
        loop = c.get("loop_hz")
        L.append(f"  controller ({c.get('firmware', 'unknown')}): " + ("; ".join(axes) or "no gains")
                 + (f"; loop {loop['value']:.0f} Hz" if loop and loop.get("value") else "")
                 + (f"; unread: {', '.join(c['unread'])}" if c.get("unread") else ""))
    return "\n".join(L) + ("\n" if L else "")
