"""Derive the as-flown terms of the paper's vehicle from first principles and write the shipped
parameter file `flightctl/vehicles/paper-as-flown.toml` (`--params paper-as-flown`).

    python scripts/as_flown.py            # print the derivation and rewrite the file

Every number below carries its provenance; docs/as-flown.md explains the physics. Where a source
fixes a value, the file carries it; where it leaves a span, the file carries the span (`range.NAME`),
drawn by the Monte Carlo, and a nominal value in it for a single flight: the middle of the span (in
its logarithm where the span is drawn so), never a value chosen because a flight passes.
"""
from __future__ import annotations

import dataclasses
import math
from pathlib import Path

from flightctl.params import EffectSpec, Filters, Params, Sensors, dumps

RHO = 1.225                 # kg/m^3, ISA sea level (the UIUC data's density)
BLADES = 2
CHORD_75 = 0.024            # m, chord at 0.75 R of a 12-inch two-blade multirotor propeller (DJI 1238 class)
LIFT_SLOPE = 5.7            # 1/rad, 2-D thin-aerofoil 2 pi less the usual 3-D/low-Reynolds loss
KV = 920.0                  # RPM/V: a ~900 KV 12-inch-class motor on 4S (hover near 40 % throttle)
R_PHASE = 0.10              # ohm, winding plus ESC of that motor class
J_BLADE_MODEL = 1.0e-4      # kg m^2, a 13 g two-blade 12-inch propeller as a rod (m R^2 / 3) plus the bell
J_RANGE = (0.8e-4, 2.66838e-4)   # kg m^2: a tapered blade and the bell (0.8-1.3e-4, the blade model 1.0e-4) to
#                                  Table 2's disk model, the upper end
ESC_HZ = 449.0              # the ESC's input frame rate (paper, sec. 4.4.1): a command waits 0 to 1/449 s
N_BLADES = 2
TAU_RANGE = (0.020, None)   # s: fast ESCs and small rotors (INDIflight's 20 ms bench); the top is derived below
LOOP_EXEC = 2.068e-3        # s: the paper's main loop (sec. 4.2, fig. 10): SPI read first, PWM sent last
# propeller coefficients (static, two-blade 10-13 inch propellers): T = CT rho n^2 D^4, P = CP rho n^3 D^5
# (UIUC Propeller Database, Brandt, Deters, Ananda, Dantsker and Selig, vol. 1-3: static CT 0.08-0.12 and
# CP / CT 0.35-0.55 for slow-flyer and multirotor propellers of this size)
CT_RANGE = (0.05, 0.12)     # the bottom is the reference default's c1 (CT 0.055): a hover near 5000 RPM
CP_OVER_CT = (0.33, 0.66)   # g1 = tau / f = (CP / CT) D / (2 pi)
DIAMETER = 0.3048           # m, 12-inch
NO_LOAD_A = (0.0, 0.4)      # A: no-load current of a ~900 KV motor of this class (its friction and iron loss)
ESC_PULSE_S = (1.0e-3, 1.2e-3)   # s: an RC ESC's input runs 1.0-2.0 ms; its motor starts at 1.0-1.2 ms
ESC_FULL_S = 2.0e-3         # s: full throttle
LOADED = 0.8                # the loaded motor turns at ~80 % of KV x V
K_OVER_M = (0.3, 0.6)       # 1/s: rotor drag over mass measured on quadrotors (docs/as-flown.md)
TAU_TILT_AIR = 8192 / 450.0 # s, the in-flight accelerometer correction: 8192 dt, long beside M/k (docs/estimator.md)
RATE_SPAN = (1, 128)        # loop periods: the D term's rate filter, from none to the text's 128 dt (Table 5)


def derive(params: Params = Params()) -> dict:
    a = params.airframe
    frame = 1.0 / a.esc_pwm_hz                      # s: one ESC frame, the pulse's period (P = 255: all of it)
    p_of = lambda pulse: 255.0 * pulse / frame      # the command value of a pulse width (eq. 26's P)
    B = a.M * a.g / 4                               # hover thrust per rotor (eq. 25's base)
    A = math.pi * a.rotor_radius ** 2
    v_h = math.sqrt(B / (2 * RHO * A))              # momentum theory, hover induced velocity
    omega_h = math.sqrt(B / a.c1)                   # eq. 27 at hover
    tip = omega_h * a.rotor_radius
    lam_h = v_h / tip
    sigma = BLADES * CHORD_75 / (math.pi * a.rotor_radius)
    a_sigma = LIFT_SLOPE * sigma
    # blade-element momentum theory, axial climb at fixed pitch and speed (Johnson, Helicopter
    # Theory, sec. 2-4; Padfield, Helicopter Flight Dynamics, heave damping):
    # dC_T/d(lambda_c) = 2 a sigma lambda_h / (16 lambda_h + a sigma), dT/dV = rho A (Omega R) dC_T/d(lambda_c)
    k_inflow = RHO * A * tip * 2 * a_sigma * lam_h / (16 * lam_h + a_sigma)
    k_inflow_max = 2 * RHO * A * v_h                # the same with a rigid thrust-pitch law (a sigma -> inf)
    # momentum drag: the rotor turns the free stream's horizontal momentum, mass flow rho A v_h
    k_drag = 4 * RHO * A * v_h
    # open-loop motor: J dW/dt = Kt (V - Ke W)/R - Q(W), linearised at hover
    ke = 60.0 / (2 * math.pi * KV)
    q_h = a.g1 * B + a.g2                           # eq. 28 at hover
    damping = ke * ke / R_PHASE + 2 * q_h / omega_h
    # a rigid rotor's hub moment from a body rate p: blade elements at (r, psi) meet the air p r sin psi
    # faster, lift -rho a c Omega r^2 p sin psi / 2 dr, arm r sin psi; averaged over psi, N_b blades:
    # -N_b rho a c Omega R^4 p / 16 per rotor (sim/causes/rotor_inflow.py)
    hub = 4 * N_BLADES * RHO * LIFT_SLOPE * CHORD_75 * omega_h * a.rotor_radius ** 4 / 16
    # eq. 27 from the thrust coefficient: f = CT rho (w / 2 pi)^2 D^4, c1 = CT rho D^4 / (4 pi^2)
    c1_per_ct = RHO * DIAMETER ** 4 / (4 * math.pi ** 2)
    # eq. 26: its dead zone h2 is the ESC's start, its gain h1 the thrust at full throttle over (P_full - h2)^2
    h2_range = tuple(p_of(t) for t in ESC_PULSE_S)
    p_full = p_of(ESC_FULL_S)
    w_max = KV * a.battery_nominal_v * LOADED * 2 * math.pi / 60
    f_full = tuple(ct * c1_per_ct * w_max ** 2 for ct in CT_RANGE)        # the thrust ceiling's span
    h1_range = (f_full[0] / (p_full - h2_range[0]) ** 2, f_full[1] / (p_full - h2_range[1]) ** 2)
    kt = ke                                         # N m/A = V s/rad for a brushless motor
    return {"M": a.M, "B": B, "v_h": v_h, "omega_h": omega_h, "lambda_h": lam_h, "sigma": sigma,
            "k_inflow": k_inflow, "k_inflow_max": k_inflow_max, "k_drag": k_drag, "M_over_k": a.M / k_drag,
            "tau_open_table2_Jp": a.Jp / damping, "tau_open_blade_J": J_BLADE_MODEL / damping,
            "tau_coast_blade_J": J_BLADE_MODEL / (2 * q_h / omega_h), "tau_coast_table2_Jp": a.Jp / (2 * q_h / omega_h),
            "hub": hub, "c1_range": tuple(ct * c1_per_ct for ct in CT_RANGE), "ct_default": a.c1 / c1_per_ct,
            "g1_range": tuple(r * DIAMETER / (2 * math.pi) for r in CP_OVER_CT),
            "g2_range": tuple(i * kt for i in NO_LOAD_A), "h2_range": h2_range, "h1_range": h1_range,
            "p_full": p_full, "f_full": f_full, "w_max": w_max, "f_full_nominal": a.h1 * (p_full - a.h2) ** 2,
            "p_hover": a.h2 + math.sqrt(B / a.h1), "p_mixer_top": a.h2 + math.sqrt(2 * B / a.h1),
            "esc_frame": frame, "dt": 1.0 / a.loop_hz, **sensors_derived(a, omega_h)}


# --- the IMU in flight: what the paper's filter tuning says of its gyro (sec. 4.4.4, Table 5) ---
EMA_STOP, EMA_FAILED = 128, 64   # loop periods: tau_EMA was doubled until p and q varied within 0.01 rad/s
TUNED = 0.01                     # rad/s
PEAK = 3.0                       # "within 0.01" read as the swing of the filtered rate: about 3 sigma
GYRO_LINE = (0.005, 0.1)         # rad/s per rotor at hover: the frame's 1/rev rocking (derived below) to a
#                                  resonant arm's tenfold of it
ACCEL_LINE = (0.25, 2.5)         # m/s^2 per rotor at hover: a 1.5 g mm imbalance to ArduPilot's "good" levels
HARMONIC2, HARMONIC3 = (0.2, 1.0), (0.0, 0.5)
IMBALANCE = 3e-6                 # kg m: a balanced 12-inch propeller with its bell (docs/estimator.md)
HUB_HEIGHT = 0.04                # m: the rotor hubs above the centre of mass (motor mounts over the frame)


def ema_pass(n: float) -> float:
    """The standard deviation an EMA of time constant n loop periods (eq. 39) passes of white noise:
    sqrt(alpha / (2 - alpha))."""
    alpha = 1.0 - math.exp(-1.0 / n)
    return math.sqrt(alpha / (2.0 - alpha))


def sensors_derived(a, omega_h: float) -> dict:
    """The gyro's broadband noise from Table 5's tuning, and the frame's rocking under a rotor's
    imbalance at the hover speed omega_h (rad/s, `derive`'s)."""
    force = IMBALANCE * omega_h ** 2                 # N, rotating at 1/rev
    rock = force * HUB_HEIGHT / (a.Jxx * omega_h)    # rad/s: the rigid frame's roll rate at 1/rev
    # the force F at the hub (l, 0, h) turning in the x-y plane: r x F = (-h F_y, h F_x, l F_y), so
    # Euler's equations rock the rigid frame by F h / (Jxx w) in roll and F l / (Jzz w) in yaw
    yaw_lines = a.l * a.Jxx / (HUB_HEIGHT * a.Jzz)
    # the filtered rate stayed within 0.01 at 128 periods, not at 64: as an rms, the raw rms lies in
    # (0.01 / pass(64), 0.01 / pass(128)]; as a swing of 3 sigma, in the same over 3
    rms = (TUNED / ema_pass(EMA_FAILED), TUNED / ema_pass(EMA_STOP))
    return {"ema_pass_64": ema_pass(EMA_FAILED), "ema_pass_128": ema_pass(EMA_STOP), "broadband_rms": rms,
            "broadband_peak": (rms[0] / PEAK, rms[1] / PEAK), "imbalance_force": force, "rigid_rock": rock,
            "yaw_lines": yaw_lines}


def as_flown(d: dict) -> Params:
    src_in = (f"theory: blade-element momentum, dT/dV at hover = {d['k_inflow']:.3f} N s/m per rotor "
              f"(v_h {d['v_h']:.2f} m/s, solidity {d['sigma']:.3f}, lift slope {LIFT_SLOPE}/rad; "
              f"rigid-pitch bound {d['k_inflow_max']:.2f}); scripts/as_flown.py")
    src_in += "; range: BEMT -30 % (lift slope, solidity) to the rigid-pitch bound"
    tau_hi_nominal = d["tau_open_blade_J"]
    tau_mid = round(0.5 * (TAU_RANGE[0] + tau_hi_nominal), 3)
    src_md = (f"not measured on this vehicle: the nominal {tau_mid * 1e3:.0f} ms is the middle of its range at the "
              f"nominal Jp ({TAU_RANGE[0] * 1e3:.0f}-{tau_hi_nominal * 1e3:.0f} ms), not a choice. Range: "
              f"{TAU_RANGE[0] * 1e3:.0f} ms (fast ESCs; INDIflight's 5-inch rotors: 20 ms bench, 26 ms in "
              f"flight) to the open-loop estimate Jp/(Kt Ke/R + 2Q/W) of {d['tau_open_table2_Jp']:.3f} s with "
              f"Table 2's Jp ({d['tau_open_blade_J']:.3f} s with a blade-model Jp; 170 ms measured for a "
              f"9.4-inch propeller); measure it with the bench step profile. The Monte Carlo moves the "
              f"top with the drawn Jp (at a given motor torque the time constant is proportional to Jp)")
    src_dr = (f"theory: momentum (ram) drag 4 rho A v_h = {d['k_drag']:.2f} N s/m (M/k = {d['M_over_k']:.2f} s), "
              f"an upper estimate; measured quadrotors give k/M = {K_OVER_M[0]:g}-{K_OVER_M[1]:g} 1/s "
              f"({K_OVER_M[0] * d['M']:.2f}-{K_OVER_M[1] * d['M']:.2f} N s/m here): the range runs from there "
              f"to the momentum value")
    src_md += (f"; tau_down (the rotor slowing down) is not carried: the effect then takes tau's drawn value for it, "
               f"the same as tau for an ESC that brakes (the E600's sine-wave drive is taken to: not measured); one "
               f"that does not lets it coast on its drag, "
               f"Jp/(2Q/W) = {d['tau_coast_blade_J']:.2f}-{d['tau_coast_table2_Jp']:.2f} s, outside the range drawn")
    src_dr += ("; yaw: it acts at the rotors, so it damps yaw, k l^2 r for four; the paper's yaw-drag rig spun "
               "the vehicle on rotors 1 and 3 with 2 and 4 off, so eq. 6's gamma1 holds the running pair's share: "
               "the file adds the other pair's, (k / 2) l^2, range 0 to k l^2 at the largest k")
    src_in += (f"; hub: a rigid rotor's hub moment N_b rho a c Omega R^4 / 16 per rotor, {d['hub']:.4f} N m s/rad "
               f"for four (an upper estimate: flapping relieves it; range down to 0)")
    a0 = Params().airframe
    src_md += (f"; p_full: the ESC's full throttle, {ESC_FULL_S * 1e3:.1f} ms of its {d['esc_frame'] * 1e3:.3f} ms frame "
               f"(P = {d['p_full']:.1f}): an RC ESC's input runs 1.0-2.0 ms and a longer pulse is full throttle, so "
               f"eq. 26's thrust stops rising there, at h1 (p_full - h2)^2, {d['f_full_nominal']:.1f} N at the reference "
               f"default, ranged through the draws of h1 and h2 (h1's range is derived from this ceiling over c1's span, "
               f"{d['f_full'][0]:.1f}-{d['f_full'][1]:.1f} N); eq. 26 to P = 255 would give "
               f"{a0.h1 * (255 - a0.h2) ** 2:.1f} N")
    period = 1.0 / ESC_HZ
    delay_hi = LOOP_EXEC + 2 * period
    src_delay = (f"the delay chain from the IMU read to the rotor, each link a span, the nominal their middles: the "
                 f"Pi's compute, 0 to {LOOP_EXEC * 1e3:.2f} ms (the paper's loop, sec. 4.2 and fig. 10, reads the "
                 f"IMU first and sends the PWM last; the simulated loop applies its command at once); the ESC's "
                 f"unsynchronised {ESC_HZ:g} Hz input, 0 to {period * 1e3:.2f} ms for the next frame; the ESC's "
                 f"own input handling, 0 to one frame (not measured); range: 0 to their sum. The gyro's and accelerometer's DLPF delays "
                 f"(2.9 and 1.9 ms) are the simulated chip's (sim/world/imu.py), declared in its logs for diagnose")
    dt = d["dt"]
    filters = dataclasses.replace(Filters(), tau_tilt_air=TAU_TILT_AIR, tau_rate=round(math.sqrt(RATE_SPAN[0] * RATE_SPAN[1]) * dt, 6))
    k_in, k_dr, hub = round(d["k_inflow"], 4), round(d["k_drag"], 3), round(d["hub"], 4)
    tau_hi = round(d["tau_open_table2_Jp"], 3)
    l2 = Params().airframe.l ** 2
    bb, line, accel = d["broadband_rms"], GYRO_LINE, ACCEL_LINE
    bb_span = (round(d["broadband_peak"][0], 4), round(bb[1], 4))
    geo = lambda span: round(math.sqrt(span[0] * span[1]), 4)   # the middle of a span in its logarithm
    mid = lambda span: round(0.5 * (span[0] + span[1]), 4)
    sensors = Sensors(accel_vibration=0.5, gyro_vibration=geo(line), harmonic2=mid(HARMONIC2),
                      harmonic3=mid(HARMONIC3), gyro_broadband=geo(bb_span), yaw_share=0.6,
                      yaw_lines=round(d["yaw_lines"], 2))
    a0 = Params().airframe
    ranged = {"Jp": J_RANGE, "h1": d["h1_range"], "h2": d["h2_range"], "c1": (min(d["c1_range"][0], a0.c1), d["c1_range"][1]),
              "g1": d["g1_range"], "g2": d["g2_range"]}
    spans = tuple((k, float(f"{lo:.4g}"), float(f"{hi:.4g}")) for k, (lo, hi) in ranged.items())
    table_ranges = (("filters", "tau_rate", round(RATE_SPAN[0] * dt, 6), round(RATE_SPAN[1] * dt, 6)),
                    ("sensors", "accel_vibration", *ACCEL_LINE), ("sensors", "gyro_vibration", *line),
                    ("sensors", "harmonic2", *HARMONIC2), ("sensors", "harmonic3", *HARMONIC3),
                    ("sensors", "gyro_broadband", *bb_span))
    return Params(airframe=dataclasses.replace(a0, Jp=J_BLADE_MODEL), filters=filters, sensors=sensors,
                  ranges=spans, table_ranges=table_ranges, effects=(
        EffectSpec("rotor_inflow", (("k", k_in), ("hub", hub)), src_in,
                   (("k", round(0.7 * k_in, 4), round(d["k_inflow_max"], 4)), ("hub", 0.0, hub))),
        EffectSpec("motor_dynamics", (("tau", tau_mid), ("p_full", round(d["p_full"], 2))), src_md,
                   (("tau", TAU_RANGE[0], tau_hi),)),
        EffectSpec("rotor_drag", (("k", k_dr), ("yaw", round(0.5 * k_dr * l2, 5))), src_dr,
                   (("k", round(K_OVER_M[0] * d['M'], 3), k_dr), ("yaw", 0.0, round(k_dr * l2, 5)))),
        EffectSpec("actuation_delay", (("delay", round(0.5 * delay_hi, 6)),), src_delay,
                   (("delay", 0.0, round(delay_hi, 6)),))))


def sources(d: dict) -> dict[str, str]:
    """Where each value of the file comes from, and its span (the file's `range.NAME`)."""
    a = Params().airframe
    dt = d["dt"]
    bb, peak = d["broadband_rms"], d["broadband_peak"]
    return {
        "Jp": (f"one rotor inertia for tau, the reaction torque and eq. 7-9: a 13 g 12-inch propeller as a "
               f"rod (m R^2 / 3) plus the bell, {J_BLADE_MODEL:.1e}; range (range.Jp, drawn) {J_RANGE[0]:.1e} "
               f"(a tapered blade: 0.8-1.3e-4 with the bell) to Table 2's disk model {J_RANGE[1]:.3e}, which gives the "
               f"open-loop tau of {d['tau_open_table2_Jp']:.3f} s at the top of tau's range "
               f"({d['tau_open_blade_J']:.3f} s with this Jp: a draw's tau is at most 0.192 s x Jp / 2.668e-4)"),
        "h2": (f"eq. 26's dead zone is the ESC's start: an RC ESC's input runs 1.0-2.0 ms and its motor starts at "
               f"{ESC_PULSE_S[0] * 1e3:.1f}-{ESC_PULSE_S[1] * 1e3:.1f} ms, P = 255 x pulse / ({d['esc_frame'] * 1e3:.3f} ms "
               f"at {a.esc_pwm_hz:g} Hz) = {d['h2_range'][0]:.1f}-{d['h2_range'][1]:.1f}; the reference default 120 "
               f"(1.05 ms) in it. Identified on the paper's bench: the Monte Carlo gives the drawn value to the "
               f"controller (eq. 26 inverted) as to the plant"),
        "h1": (f"eq. 26's gain from the thrust ceiling at full throttle (2.0 ms, P = {d['p_full']:.0f}): "
               f"c1 w_max^2 with w_max = {KV:g} KV x {a.battery_nominal_v:g} V x {LOADED:g} loaded = {d['w_max']:.0f} rad/s "
               f"over c1's span gives {d['f_full'][0]:.1f}-{d['f_full'][1]:.1f} N, h1 = f / (P_full - h2)^2; the reference "
               f"default 1.49e-3 ({d['f_full_nominal']:.1f} N at full throttle, hover at P = {d['p_hover']:.0f}) in it. "
               f"The mixer's cap 2B (Table 3) is P = {d['p_mixer_top']:.0f} at the default, below full throttle in "
               f"every draw; the two-rotor mode (flightctl/control/spin.py) goes up to the ceiling (motor_dynamics' p_full); "
               f"identified on the bench as h2"),
        "c1": (f"eq. 27 from the static thrust coefficient, c1 = CT rho D^4 / (4 pi^2): CT {CT_RANGE[0]:g}-{CT_RANGE[1]:g} "
               f"(UIUC Propeller Database, static tests of two-blade 10-13 inch propellers, 0.08-0.12; the reference "
               f"default's {d['ct_default']:.3f}, a hover near 5000 RPM, at the bottom)"),
        "g1": (f"eq. 28's slope tau / f = (CP / CT) D / (2 pi): CP / CT {CP_OVER_CT[0]:g}-{CP_OVER_CT[1]:g} for static "
               f"two-blade propellers of this size (UIUC Propeller Database) gives {d['g1_range'][0]:.4f}-"
               f"{d['g1_range'][1]:.4f} N m/N; the reference default 0.02 in it"),
        "g2": (f"eq. 28's offset: the motor's friction and iron-loss torque, its no-load current "
               f"{NO_LOAD_A[0]:g}-{NO_LOAD_A[1]:g} A times Kt = {60 / (2 * math.pi * KV):.4f} N m/A ({KV:g} KV); "
               f"the reference default 0.002 in it. It cancels in eq. 25's yaw sum while every rotor turns"),
        "tau_rate": (f"the D term's rate path, which the paper leaves open: its text puts the 128 dt EMA of Table 5 on "
                     f"p, q, r before the fusion and differentiates the fused angle (eq. 24), which with this model's "
                     f"loop crashes both gain sets (docs/estimator.md), while the vehicle flew; so the span runs from "
                     f"one loop period (the gyro almost as the chip gives it) to the text's 128 dt, drawn in its "
                     f"logarithm as the paper tuned (powers of two of dt); nominal {math.sqrt(RATE_SPAN[0] * RATE_SPAN[1]):.1f} dt, "
                     f"the middle in the logarithm"),
        "gyro_broadband": (f"paper, sec. 4.4.4 and Table 5: tau_EMA was doubled until p and q varied within 0.01 rad/s "
                           f"and stopped at 128 dt; an EMA of 64 dt passes {d['ema_pass_64'] * 100:.1f} % of white noise, "
                           f"of 128 dt {d['ema_pass_128'] * 100:.2f} %, so the raw rate's rms was "
                           f"{bb[0]:.3f}-{bb[1]:.3f} rad/s if 'within 0.01' is the filtered rms, {peak[0]:.3f}-{peak[1]:.3f} "
                           f"if it is the filtered swing (3 sigma): range {peak[0]:.3f}-{bb[1]:.3f}, the nominal its middle "
                           f"in the logarithm. The MPU-9250's own 0.003 rad/s (PS 3.1) is the rest: what the tuning saw "
                           f"in flight was the frame and the airflow, in proportion to the thrust here"),
        "gyro_vibration": (f"each rotor's 1/rev rocking of the frame: a {IMBALANCE * 1e6:g} g mm imbalance at hover speed "
                           f"is {d['imbalance_force']:.2f} N rotating {HUB_HEIGHT * 100:g} cm above the centre of mass, "
                           f"{d['rigid_rock']:.4f} rad/s of roll for a rigid frame; an arm in resonance multiplies it up "
                           f"to tenfold: range {GYRO_LINE[0]:g}-{GYRO_LINE[1]:g} rad/s, the nominal the middle in the logarithm. "
                           f"After the 128 dt EMA an 87 Hz line keeps under 1 %: the tuning above did not see it"),
        "accel_vibration": (f"the 1/rev imbalance force over the mass, 0.5 m/s^2 per rotor at {IMBALANCE * 1e6:g} g mm "
                            f"(docs/estimator.md); range {ACCEL_LINE[0]:g} (1.5 g mm) to {ACCEL_LINE[1]:g} m/s^2 (four "
                            f"rotors then give 3.5 m/s^2 rms per axis, within ArduPilot's 'good' vibration levels, "
                            f"under 15 m/s^2)"),
        "harmonic2": ("the 2/rev line over the 1/rev: a two-blade propeller's blade passing over its arm; multirotor "
                      "gyro and accelerometer spectra show lines at the rotor frequency and its harmonics, the 2nd "
                      "next to the 1st (ArduPilot, harmonic notch filtering); range 0.2-1, nominal its middle"),
        "harmonic3": "the 3/rev line over the 1/rev, as the 2/rev: range 0-0.5, nominal its middle",
        "yaw_share": ("paper, sec. 4.4.4: r within 0.006 rad/s where p and q were within 0.01, with the same EMA: "
                      "the broadband noise's yaw share"),
        "yaw_lines": (f"the rotor lines' yaw share, a rigid body's: a rotor's imbalance force F at the hub (l, 0, h) "
                      f"turning in the x-y plane makes the torque r x F = (-h F_y, h F_x, l F_y), which rocks the "
                      f"frame by F h / (Jxx w) in roll and F l / (Jzz w) in yaw (Euler's equations): l Jxx / (h Jzz) "
                      f"= {d['yaw_lines']:.2f} with Table 2's inertias and the hubs {HUB_HEIGHT * 100:g} cm above the "
                      f"centre of mass"),
    }


def main() -> None:
    import argparse
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default=str(Path(__file__).resolve().parents[1] / "flightctl" / "vehicles" /
                                         "paper-as-flown.toml"),
                    help="the parameter file to write (default: the checkout's flightctl/vehicles/paper-as-flown.toml, "
                         "never the installed package's)")
    args = ap.parse_args()
    d = derive()
    for k, v in d.items():
        shown = "-".join(f"{x:.4g}" for x in v) if isinstance(v, tuple) else f"{v:.4g}"
        print(f"{k:>20} = {shown}")
    path = Path(args.out)
    text = ("# The paper's vehicle as flown: the reference airframe (conventions.md) plus the terms its\n"
            "# model lacks, each with its provenance. Written by scripts/as_flown.py; do not edit by hand.\n"
            + dumps(as_flown(d), sources(d), tables=("filters", "sensors")))
    path.write_text(text)
    print(f"-> {Path(path).relative_to(Path.cwd()) if path.is_relative_to(Path.cwd()) else path}")


if __name__ == "__main__":
    main()
