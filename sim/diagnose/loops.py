"""The loop each firmware closes, one axis at a time, as predict.py's closed loop takes it (docs/steps.md,
"Predicted and measured"): the controller's gains and filters (sim/logs/controller.py read them) and the
mixer from that controller's output to the reader's motor command P (0-255), per rotor in the log's order.

Every firmware's output u acts on rotor i as dP_i = R m_i u: m_i the mixer's coefficient (the project's
frame: roll drives the rotors on the left, +y; pitch the rear ones, -x; yaw the clockwise ones, -spin), R
the P units one unit of m_i u moves. The sources (function names where no line could be had: the snapshots
of PX4-Autopilot, ardupilot and inav are over the fetch limit, read through the file index):

- Betaflight 3.1: predict.py's own (mixer.c of v3.1.5): m = the quad X's +-1, R = 255.
- PX4 (control allocation, 1.13 on): src/modules/control_allocator/ControlAllocation/
  ControlAllocationPseudoInverse.cpp at 089afb0: the mix is the pseudo-inverse of the rotors' effectiveness
  (roll -CT py, pitch CT px, yaw CT KM, thrust -CT: ActuatorEffectivenessRotors), its roll and pitch
  columns divided by one scale, max over the two of sqrt(|col|^2 / (n_nonzero / 2)), its yaw column by its
  largest entry (updateControlAllocationMatrixScale, normalizeControlAllocationMatrix); the torque comes
  from the rate controller in those normalised units (mc_rate_control, RateControl::update: P, I on the
  error, D on the angular acceleration, P, I, D times MC_*RATE_K, FF on the setpoint apart); actuator_motors is the
  allocation's 0-1, the reader's P = 255 x it: R = 255. Before the control allocation (no CA_ROTOR*) the
  mixer files' normalisation is not read: named.
- ArduPilot: libraries/AP_Motors/AP_MotorsMatrix.cpp (normalise_rpy_factors: the roll, pitch and yaw
  factors scaled to a largest magnitude of 0.5, alike in the file's old and current versions in the index;
  output_armed_stabilizing, read at 0001fe6: thrust_i = throttle + roll_in roll_factor_i + ...), then
  AP_MotorsMulticopter's thrust-to-actuator linearisation (MOT_THST_EXPO e:
  thrust = (1 - e) a + e a^2, so da/dthrust = 1 / (1 - e + 2 e a)) and the spin range (P / 255 = MOT_SPIN_MIN
  + (MOT_SPIN_MAX - MOT_SPIN_MIN) a over the reader's MOT_PWM_MIN..MAX): R = 255 (SPIN_MAX - SPIN_MIN) /
  (1 - e + 2 e a) at the flight's median command. The PIDs (AC_PID::update_all): the target through FLTT,
  the error through FLTE, P and I on it, D its derivative through FLTD, FF on the filtered target.
- INAV: src/main/flight/mixer.c at 30ec1fe (mixTable: rpyMix = (pitch m.pitch + roll m.roll - yaw m.yaw)
  mixerScale, mixerScale 1, motor = rpyMix + throttle in the motor's own units): the PID sum acts in the
  logged motor units; controller.py converts INAV's gains to shares of the logged motorOutput range, so
  m = mixerQuadX's +-1 and R = 255. D on the measurement (pid.c dTermProcess) through dterm_lpf_hz of
  dterm_lpf_type (filter.h's lowpassFilterType_e), yaw's P through yaw_lpf_hz; its FF (the setpoint's
  derivative on a multirotor, FP_PID_RATE_D_FF_MULTIPLIER) not modelled.
- flightctl (the attitude loop, eq. 24 on the angles): u in N, eq. 25's mixer (+-1 per rotor: motor 1
  -u_theta + u_psi, 2 u_phi - u_psi, 3 u_theta + u_psi, 4 -u_phi - u_psi; flightctl/control/mixer.py) and
  eq. 26 inverted, P = h2 + sqrt(f / h1): R = dP/df = 1 / (2 h1 (P - h2)) at the median command, h1, h2 the
  parameter file's (the controller's own); the D term on the estimator's rate (the gyro, through tau_rate's
  EMA where set), the response the estimator's angle.
"""
from __future__ import annotations

import math

import numpy as np

AP_DEFAULTS = {"MOT_THST_EXPO": 0.65, "MOT_SPIN_MIN": 0.15, "MOT_SPIN_MAX": 0.95}   # AP_MotorsMulticopter.cpp defaults
# INAV's lowpassFilterType_e (src/main/common/filter.h): the header's dterm_lpf_type
INAV_LPF = {0: "pt1", 1: "biquad", 2: "pt2", 3: "pt3"}
FLIGHTCTL_MIX = {"x": (0.0, 1.0, 0.0, -1.0), "y": (-1.0, 0.0, 1.0, 0.0), "z": (1.0, -1.0, 1.0, -1.0)}   # eq. 25


def _v(d: dict | None):
    return None if not d else d.get("value")


def _direction(declared, axis: str) -> np.ndarray:
    """The project-frame direction each rotor moves the axis by (roll +y, pitch -x, yaw -spin)."""
    return {"x": np.array(declared.y, float), "y": -np.array(declared.x, float),
            "z": -np.array(declared.spin, float)}[axis]


def px4_mix(declared, axis: str) -> np.ndarray:
    """PX4's normalised pseudo-inverse column of `axis` (the module's PX4 item)."""
    n = len(declared.x)
    km = np.abs(np.array(declared.yaw_factor, float)) * np.array(declared.spin, float)
    E = np.vstack([np.array(declared.y, float), -np.array(declared.x, float), -km, -np.ones(n)])
    M = np.linalg.pinv(E)                           # n x 4: roll, pitch, yaw, thrust
    nz = lambda c: max(int(np.sum(np.abs(c) > 1e-3)), 1)
    rp = max(math.sqrt(np.sum(M[:, j] ** 2) / (nz(M[:, j]) / 2.0)) for j in (0, 1))
    col = {"x": M[:, 0] / rp, "y": M[:, 1] / rp, "z": M[:, 2] / np.max(np.abs(M[:, 2]))}[axis]
    col[np.abs(col) < 1e-3] = 0.0
    return col


def ardupilot_mix(declared, axis: str) -> np.ndarray:
    d = _direction(declared, axis)
    if axis == "z":
        d = d * np.abs(np.array(declared.yaw_factor, float))
    return 0.5 * d / np.max(np.abs(d))


def bf_mix(declared, axis: str) -> np.ndarray:
    d = _direction(declared, axis)
    return d / np.max(np.abs(d))


def parts(ctrl: dict, meta: dict, axis: str, declared) -> tuple[dict | None, list[str]]:
    """The loop of one axis for PX4, ArduPilot, INAV and flightctl: (gains, filters, the mix `m` and `R` as
    a function of the median command, or None; what is not modelled, or why not first)."""
    fw = ctrl.get("firmware")
    g = ctrl.get("axes", {}).get(axis, {})
    if any(_v(g.get(k)) is None for k in ("kp", "ki", "kd")):
        return None, [f"the {fw} controller's gains of this axis are not in the log or not in physical units "
                      f"(controller.py: {', '.join(ctrl.get('unread', [])) or 'unread'}): the loop cannot be closed"]
    loop = _v(ctrl.get("loop_hz"))
    if not loop:
        return None, [f"the loop rate is not in the log ({fw}: controller.py's unread)"]
    flt = ctrl.get("filters", {})
    p = {"kp": _v(g["kp"]), "ki": _v(g["ki"]), "kd": _v(g["kd"]), "kf": _v(g.get("kf")) or 0.0, "c": 0.0,
         "loop_hz": float(loop), "d_lowpass_hz": 0.0, "d_filter": "biquad", "p_lowpass_hz": 0.0,
         "target_lowpass_hz": 0.0, "error_lowpass_hz": 0.0, "d_on_raw_gyro": False, "loop": "rate"}
    missing = ["the mix's saturation and desaturation (airmode)", "the battery compensation of the mix"]
    if fw == "px4":
        if not ctrl.get("rotors_from_ca", False):
            return None, ["PX4 without the control allocation's rotors (CA_ROTOR*): its mixer's normalisation is not "
                          "read here (the mixer files before 1.13)"]
        if not str(meta.get("command", "")).startswith("P = 255 actuator_motors"):
            missing.append("the thrust curve THR_MDL_FAC between actuator_motors and the outputs the log gives")
        p.update(d_lowpass_hz=_v(flt.get("dterm_lowpass_hz")) or 0.0, d_on_raw_gyro=True)
        if declared is not None:
            p["mix"] = px4_mix(declared, axis).tolist()
        p["R"] = 255.0
        hz = _v(flt.get("gyro_lowpass_hz"))
        p["gyro_loop_chain"] = f"biquad {hz:g}" if hz else "none"   # math::LowPassFilter2p (vehicle_angular_velocity)
        missing += ["the gyro's notch filters", "TPA (MC_*RATE_TPA where set)"]
    elif fw == "ardupilot":
        pp = ctrl.get("motors", {})
        e, lo, hi = (float(pp.get(k, AP_DEFAULTS[k])) for k in ("MOT_THST_EXPO", "MOT_SPIN_MIN", "MOT_SPIN_MAX"))
        for k in ("MOT_THST_EXPO", "MOT_SPIN_MIN", "MOT_SPIN_MAX"):
            if k not in pp:
                missing.append(f"{k} (not in the log: ArduPilot's default {AP_DEFAULTS[k]:g} taken)")
        p.update(c=1.0, d_lowpass_hz=_v(g.get("fltd_hz")) or 0.0, d_filter="pt1",
                 target_lowpass_hz=_v(g.get("fltt_hz")) or 0.0, error_lowpass_hz=_v(g.get("flte_hz")) or 0.0)
        if declared is not None:
            p["mix"] = ardupilot_mix(declared, axis).tolist()
        hz = _v(flt.get("gyro_lowpass_hz"))
        p["gyro_loop_chain"] = f"biquad {hz:g}" if hz else "none"   # INS_GYRO_FILTER: LowPassFilter2p (AP_InertialSensor)

        def R(pm, e=e, lo=lo, hi=hi):
            a = min(max((pm / 255.0 - lo) / max(hi - lo, 1e-6), 0.0), 1.0)
            return 255.0 * (hi - lo) / (1.0 - e + 2.0 * e * a)
        p["R"] = R
        missing += ["the slew-rate limiter (SMAX) and the PID's own limits", "the gyro's notch filters"]
    elif fw == "inav":
        kind = (flt.get("dterm_lowpass_type") or {}).get("raw")
        p.update(d_lowpass_hz=_v(flt.get("dterm_lowpass_hz")) or 0.0, kf=0.0, d_filter=INAV_LPF.get(kind, "pt1"))
        if axis == "z":       # pid.c pTermProcess: yaw's P through a pt1 at yaw_lpf_hz (0: off)
            p["p_lowpass_hz"] = _v(flt.get("yaw_lowpass_hz")) or 0.0
        if declared is not None:
            p["mix"] = bf_mix(declared, axis).tolist()
        p["R"] = 255.0
        missing += ["INAV's control-derivative feed-forward (FF on the setpoint's change)", "TPA",
                    "the D low-pass's type " + (f"{INAV_LPF[kind]} (dterm_lpf_type {kind}), with Betaflight's pt2/pt3 "
                                                "cut-off correction taken" if kind in INAV_LPF else
                                                "(dterm_lpf_type not in the header: a pt1 taken)")]
    elif fw == "flightctl":
        h1, h2 = (_v(ctrl.get("thrust_curve", {}).get(k)) for k in ("h1", "h2"))
        if h1 is None or h2 is None:
            return None, ["the thrust curve h1, h2 is not in the log's parameter file"]
        tau = _v(flt.get("tau_rate_s")) or 0.0
        p.update(loop="attitude", tau_rate_hz=1.0 / (2.0 * math.pi * tau) if tau > 0 else 0.0)
        p.update(loop="attitude", tau_rate_s=_v(flt.get("tau_rate_s")) or 0.0)
        p["mix"] = list(FLIGHTCTL_MIX[axis])
        p["R"] = lambda pm, h1=h1, h2=h2: 1.0 / (2.0 * h1 * max(pm - h2, 1.0))
        missing = ["the PIDs' output limit (Table 3) and the mixer's clipping", "the estimator's accelerometer "
                   "correction (the estimate taken as the gyro's integral)"]
    else:
        return None, [f"the mix from {fw or 'this log'}'s controller output to the motor commands is not read here: "
                      "the loop cannot be closed"]
    return p, missing
